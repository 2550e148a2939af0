//! The project's iCub-like humanoid (`assets/icub_like/icub_like.urdf`): where it is and its
//! standing "home" posture.

use nalgebra::DVector;

use super::data::Data;
use super::error::DynamicsError;
use super::kinematics::forward_kinematics;
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

/// Standing home posture (radians; joints not listed are 0): knees slightly bent with flat
/// feet (hip pitch + ankle pitch = knee, all pitch axes chosen so that flexion is positive for
/// hip and knee), arms slightly abducted with elbows bent, the right hand in front of the body.
pub const HOME: &[(&str, f64)] = &[
    ("l_hip_pitch", 0.25),
    ("r_hip_pitch", 0.25),
    ("l_knee", 0.5),
    ("r_knee", 0.5),
    ("l_ankle_pitch", 0.25),
    ("r_ankle_pitch", 0.25),
    ("l_shoulder_pitch", -0.35),
    ("r_shoulder_pitch", -0.35),
    ("l_shoulder_roll", 0.35),
    ("r_shoulder_roll", 0.35),
    ("l_elbow", 0.8),
    ("r_elbow", 0.8),
];

/// Home configuration of `model` (the humanoid): [`HOME`] joint values and, for a floating
/// base, the root placed so that the soles lie flat on z = 0, centred on the world origin.
pub fn home_configuration(model: &Model) -> Result<DVector<f64>, DynamicsError> {
    let mut q = model.configuration(HOME)?;
    if model.has_floating_base() {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &q)?;
        let l = data.o_m_f[model.frame_id("l_sole")?].trans;
        let r = data.o_m_f[model.frame_id("r_sole")?].trans;
        let mid = 0.5 * (l + r);
        q[0] -= mid.x;
        q[1] -= mid.y;
        q[2] -= mid.z;
    }
    Ok(q)
}
