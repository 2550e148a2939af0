//! MuJoCo as the plant's physics engine (`upc sim --plant mujoco`): [`scene`] generates the
//! MJCF and plant description from upc's robot, door and scenario; [`MujocoPlant`] steps it
//! through MuJoCo's C library (`ffi`, linked by `build.rs` from the `mujoco` wheel that
//! `scripts/setup.sh` installs) under the same plant runtime as upc's own simulator
//! ([`crate::sim::process`]).

#[cfg(upc_mujoco)]
mod ffi;
#[cfg(upc_mujoco)]
mod plant;
mod scene;

#[cfg(upc_mujoco)]
pub use plant::{MujocoPlant, SETTLE_TIME};
pub use scene::*;

/// Whether this build has the MuJoCo engine (MuJoCo was found when upc was built).
pub const AVAILABLE: bool = cfg!(upc_mujoco);

/// Why `--plant mujoco` cannot run in a build without it.
pub const UNAVAILABLE: &str = "this upc was built without MuJoCo: run scripts/setup.sh (it \
     installs the `mujoco` wheel, whose C library upc links), then build again";

/// MuJoCo's version (`None` in a build without it).
pub fn version() -> Option<String> {
    #[cfg(upc_mujoco)]
    return Some(ffi::version());
    #[cfg(not(upc_mujoco))]
    None
}
