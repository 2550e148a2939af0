//! upc — unified preview control for humanoid balance under hand interaction.
//!
//! Layout (each module has one job):
//! - [`preview`]: the paper's reduced models and controllers (cart-table, C0/C1, hand previewer, C2).
//! - [`dynamics`]: rigid-body dynamics from URDF (Model / Data, RNEA, CRBA, ABA, Jacobians).
//! - [`scenario`]: hand force profiles (impacts, CSV) and the ZMP reference of a run.
//! - [`offline`]: the closed loop of the reduced models behind `upc preview`, with its metrics.
//! - [`report`]: `upc compare`'s report: figures and metrics tables of runs.
//! - [`config`]: TOML configuration with errors that name the offending key.
//! - [`wbc`]: the whole-body torque controller (LQP over q̈ and contact forces, clarabel).
//! - [`forecast`]: the reference force forecaster process.
//! - [`robot`]: robot descriptions: URDF, feet, hand, home posture, and what follows from them.
//! - [`sim`]: the simulator process (humanoid on the ground, door on a spherical joint).
//! - [`plant`]: the contract's plant side, shared by the simulator and a robot's bus (the
//!   command gate, the plant run's announcement, the foot wrenches of the sensor block).
//! - [`control`]: the control server's loop pieces (tick, its parts, C2 thread, logger, loop).
//! - [`estimation`]: the floating base from the IMU, the joints and the foot wrenches.
//! - [`capability`]: the largest push each controller withstands, swept (`upc capability`).
//! - [`logging`]: the processes' diagnostics (tracing), never blocking the real-time loop.
//! - [`realtime`]: real-time setup and loop latency statistics, shared by every process's loop.
//! - [`shutdown`]: SIGINT/SIGTERM handling shared by the processes.
//! - [`channels`]: the iceoryx2 channel contract shared by every process.
//! - [`bridge`]: the contract over Zenoh, for forecasters and viewers on other hosts.
//! - [`bus`]: upc on a robot's own DDS bus (the Unitree G1's `rt/lowstate`, `rt/lowcmd`).
//! - [`record`]: self-describing records (a value with its column's name, format and rerun path)
//!   for the CSVs and rerun logs.
//! - [`recording`]: where the rerun recordings go (`.rrd` files, a live viewer).

// Outside tests, no unwrap or expect: bad input is an error value with a message, and the
// real-time path never panics (each exception says why it cannot fail).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod bridge;
pub mod bus;
pub mod capability;
pub mod channels;
pub mod config;
pub mod control;
pub mod dynamics;
pub mod estimation;
pub mod forecast;
pub mod logging;
pub mod offline;
pub mod plant;
pub mod preview;
pub mod realtime;
pub mod record;
pub mod recording;
pub mod report;
pub mod robot;
pub mod scenario;
pub mod shutdown;
pub mod sim;
pub mod wbc;
