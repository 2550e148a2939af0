//! Rigid-body dynamics from URDF (Model / Data split, as in Pinocchio).
//!
//! An immutable [`Model`] (built from URDF or programmatically) and a preallocated [`Data`]
//! workspace; one algorithm per file. Conventions:
//! - Spatial vectors are `[linear; angular]` (Pinocchio order); motions of a body are expressed
//!   in its local frame at its origin.
//! - Floating base (free-flyer, joint `root_joint`): `q = [p_world(3), quat xyzw(4), joints…]`,
//!   `v = [v_body_linear(3), ω_body(3), joint rates…]`, both root velocities in the root's local
//!   frame; `nq = nv + 1`; integration by the SE(3) exponential ([`integrate()`]).
//! - Frame Jacobians are 6×nv with rows `[linear; angular]`, either [`ReferenceFrame::Local`] or
//!   [`ReferenceFrame::LocalWorldAligned`] (world axes at the frame origin).
//! - Checked entry points take `DVector`s and return `Result<_, DynamicsError>`; the kernels
//!   behind them do not allocate.

pub mod aba;
pub mod com;
pub mod cop;
pub mod crba;
pub mod data;
pub mod error;
pub mod icub_like;
pub mod integrate;
pub mod jacobian;
pub mod joint;
pub mod kinematics;
pub mod model;
pub mod op_space;
pub mod rnea;
pub mod spatial;
pub mod urdf;

pub use aba::{aba, aba_with_external_forces};
pub use com::{center_of_mass, center_of_mass_velocity, jacobian_center_of_mass};
pub use cop::{Pressure, PressureLoad, center_of_pressure};
pub use crba::crba;
pub use data::Data;
pub use error::DynamicsError;
pub use integrate::{difference, integrate};
pub use jacobian::{compute_joint_jacobians, frame_jacobian, frame_jdot_v, get_frame_jacobian};
pub use joint::JointKind;
pub use kinematics::{
    ReferenceFrame, forward_kinematics, forward_kinematics_velocity, frame_velocity,
    update_frame_placements,
};
pub use model::{Frame, Joint, JointLimits, Model};
pub use op_space::OpSpaceWorkspace;
pub use rnea::{gravity_torques, nonlinear_effects, rnea};
pub use spatial::{Force, Inertia, Motion, SE3};
pub use urdf::{BaseJoint, ROOT_JOINT_NAME, UPRIGHT_BASE, parse_urdf, turn_root};
