//! The robots of the registry packages, for tests that need them.

use upc::robot::{Robot, RobotError};

/// Robot `name`, or `None` when its package is not installed: a failure under CI, a visible
/// skip elsewhere (`support::prereq`).
pub fn installed(name: &str) -> Option<Robot> {
    match Robot::load(name) {
        Ok(r) => Some(r),
        Err(RobotError::Urdf { reason, .. }) if reason.contains("not installed") => {
            super::prereq::missing(&format!("robot `{name}`: {reason}"), super::prereq::SETUP);
            None
        }
        Err(e) => panic!("{name}: {e}"),
    }
}
