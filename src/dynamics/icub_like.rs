//! The project's iCub-like humanoid (`assets/icub_like/icub_like.urdf`) and the door: where they
//! are. Its home posture, feet and hand are in its robot description
//! (`config/robots/icub_like.toml`, [`crate::robot::Robot`]).

use super::error::DynamicsError;
use super::model::Model;
use super::urdf::BaseJoint;

/// Path of the humanoid URDF relative to the repository root.
pub const URDF_PATH: &str = "assets/icub_like/icub_like.urdf";

/// Path of the door URDF relative to the repository root.
pub const DOOR_URDF_PATH: &str = "assets/door/door.urdf";

/// Absolute path of the humanoid URDF in this source tree.
pub fn urdf_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(URDF_PATH)
}

/// Absolute path of the door URDF in this source tree.
pub fn door_urdf_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(DOOR_URDF_PATH)
}

/// The humanoid URDF, embedded so the binaries run from any directory.
pub const URDF: &str = include_str!("../../assets/icub_like/icub_like.urdf");
/// The door URDF, embedded.
pub const DOOR_URDF: &str = include_str!("../../assets/door/door.urdf");

/// Loads the (embedded) humanoid with a floating base.
pub fn load() -> Result<Model, DynamicsError> {
    Model::from_urdf_str(URDF, BaseJoint::Floating)
}
