//! The robot's torque estimates and missing sensors as a step of their own, at the path the bus
//! plant imports: their models live with the others in [`super::sensors`] (`drives.rs`,
//! `missing.rs`), where [`super::sensors::Sensors::with_robot`] declares them.

pub use super::sensors::{MAX_DELAY, MotorTorqueConfig, RobotSensing};
