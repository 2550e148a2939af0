//! The robots of the registry packages, for tests that need them.

use upc::robot::{Robot, RobotError};

/// Robot `name`, or `None` (after printing why) when `scripts/setup.sh` could not install its
/// package.
pub fn installed(name: &str) -> Option<Robot> {
    match Robot::load(name) {
        Ok(r) => Some(r),
        Err(RobotError::Urdf { reason, .. }) if reason.contains("not installed") => {
            eprintln!("SKIPPED `{name}`: {reason}");
            None
        }
        Err(e) => panic!("{name}: {e}"),
    }
}
