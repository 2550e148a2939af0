//! The plant behind `upc sim`: one runtime over two physics engines. The humanoid on the
//! ground through its sole corners, the door joined to its right hand, stepped at a fixed `dt`
//! and exchanged with the controller over iceoryx2 (`crate::channels`).
//!
//! - [`process`]: the plant runtime (lockstep / real-time loops, state and ground truth out,
//!   torques in), written once over [`physics::Physics`]; the torque commands are judged by
//!   the contract's plant side ([`crate::plant`]); [`hold`]: the supervisor (hold, hand-over,
//!   damping) and the command clock; [`record`]: the rerun `.rrd` of the ground truth;
//!   [`truth_csv`]: its CSV (`sim.csv`); [`config`]: `config/sim.toml`.
//! - [`bus_robot`]: the same plants speaking as a Unitree G1 on its own DDS bus (`upc sim --bus
//!   unitree`, for `upc bus`), with the bus's wire types ([`crate::bus`]).
//! - upc's engine: [`world`], the physics, no IPC ([`World::step`]); [`contact`]: the
//!   constraint solver (Coulomb cones, spherical joint, joint limits; projected Gauss–Seidel);
//!   [`factor`]: the tree-sparse `LᵀDL` factorisation of the mass matrix; [`scene`]: the default
//!   scene (humanoid + door placed at the hand, hinge torque profile).
//! - MuJoCo's engine: [`mujoco`], the scene generated from the same robot and its plant through
//!   MuJoCo's C library.

pub mod bus_robot;
pub mod config;
pub mod contact;
pub mod factor;
pub mod hold;
pub mod mujoco;
pub mod physics;
pub mod process;
pub mod record;
pub mod scene;
pub mod sensors;
pub mod truth_csv;
pub mod world;

pub use config::{HoldConfig, HoldKind, Mode, Push, SimConfig};
pub use hold::{HoldStats, Phase, Supervisor};
pub use physics::{Engine, Physics, SimError, StepReport};
pub use scene::{DoorDrive, PlacedDoor, PosturePd, Scene, humanoid_scene, place_door, robot_scene};
pub use world::{DoorSpec, PhysicsParams, Plane, World, WorldSpec};
