//! The robot's own bus: upc drives a Unitree G1 through the low-level DDS interface of its
//! firmware, reading joint and IMU state from `rt/lowstate` and writing per-joint PD + feedforward
//! targets to `rt/lowcmd` (docs/bus.md).
//!
//! - [`unitree_hg`]: the wire format (messages, their CDR encoding, Unitree's CRC), pure Rust;
//! - [`dds`]: the DDS transport (rustdds), confined to one interface;
//! - [`participant`]: `upc bus`, the plant on upc's contract and the controller on the bus,
//!   with the robot's safety (hold, hand-over, damping, clamps, refusals);
//! - [`sim_robot`]: `upc sim --bus unitree`, upc's plant speaking as a G1 (tests, demos);
//! - [`motors`]: motor slots ↔ joints; [`lab`]: upc's own topic of what a lab measures beside
//!   the robot; [`ros2`]: the joints and the hand's wrench as ROS 2 messages;
//!   [`config`]: `config/bus.toml`.

pub mod config;
pub mod dds;
pub mod lab;
pub mod motors;
pub mod participant;
pub mod ros2;
pub mod sim_robot;
pub mod unitree_hg;

pub use config::BusConfig;
