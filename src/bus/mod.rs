//! The robot's own bus: upc drives a Unitree G1 through the low-level DDS interface of its
//! firmware, reading joint and IMU state from `rt/lowstate` and writing per-joint PD + feedforward
//! targets to `rt/lowcmd` (docs/bus.md).
//!
//! - [`unitree_hg`]: the wire format (messages, their CDR encoding, Unitree's CRC), pure Rust;
//! - [`dds`]: the DDS transport (rustdds), confined to one interface;
//! - [`participant`]: `upc bus`, the plant on upc's contract and the controller on the bus,
//!   its DDS and contract endpoints and its loop; [`drive`]: the robot's safety (hold,
//!   hand-over, brace, damping, clamps, refusals) as a state machine on the caller's clock;
//!   what it shares with
//!   upc's own plants (the command gate, the plant run's announcement, the foot wrenches) is
//!   the contract's plant side, [`crate::plant`];
//! - [`motors`]: motor slots ↔ joints; [`lab`]: upc's own topic of what a lab measures beside
//!   the robot; [`ros2`]: the joints and the hand's wrench as ROS 2 messages;
//!   [`config`]: `config/bus.toml`; [`summary`]: `bus.json`.
//!
//! upc's plants speaking as a G1 on this bus (`upc sim --bus unitree`) are plants: they live
//! with them (`src/sim/bus_robot.rs`) and use the wire types from here; nothing here uses the
//! simulator.

pub mod config;
pub mod dds;
pub mod drive;
pub mod lab;
pub mod motors;
pub mod participant;
pub mod ros2;
pub mod summary;
pub mod unitree_hg;

pub use config::BusConfig;
