//! The contract's plant side: what a process that publishes the robot's state on upc's contract
//! and takes its torques needs, whatever produces the robot — upc's simulator ([`crate::sim`])
//! or a robot on its own bus ([`crate::bus`]). Both depend on this module, it on neither.
//!
//! - [`command`]: the gate that judges which torque messages may drive the robot;
//! - [`info`]: the plant run's announcement in every state (session, scenario, flags);
//! - [`feet`]: the soles' geometry and the foot wrenches of the state's sensor block, from the
//!   sole corners' forces.

pub mod command;
pub mod feet;
pub mod info;

pub use command::{CommandGate, CommandOrigin, CommandStats, Rejection, validate_command};
pub use info::PlantInfo;
