//! The physics engine behind the plant runtime ([`super::process`]): upc's own [`super::World`] or
//! MuJoCo ([`super::mujoco::MujocoPlant`]). The runtime (command gate, supervisor, command
//! clock, lockstep and real-time loops, ground truth, summary) is written once against this.
//!
//! Conventions are the channel contract's (`services/CHANNELS.md`): `q` = base position,
//! quaternion x y z w, joints; `v` = base linear and angular velocity in the base frame, joint
//! rates; contact forces in the robot description's contact order, ground on robot, world frame.
//!
//! What the engines share lives here with the trait ([`SimError`], [`StepReport`], [`rebase`]),
//! so an engine's file depends on this one and never on another engine's.

use nalgebra::{DVector, Vector3};

use super::factor::NotPositiveDefinite;
use crate::dynamics::{DynamicsError, Model, SE3};

/// Which engine a plant runs (`upc sim --plant`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Engine {
    /// upc's own simulator ([`super::World`]).
    #[default]
    Upc,
    /// MuJoCo, through its C library.
    Mujoco,
}

/// Errors of building or stepping an engine (upc's [`super::World`], MuJoCo).
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum SimError {
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    #[error("torque vector has length {got}, the robot has {expected} actuated joints")]
    TorqueLength { expected: usize, got: usize },
    #[error("{what} is not finite at index {index}")]
    NonFinite { what: &'static str, index: usize },
    #[error(transparent)]
    Singular(#[from] NotPositiveDefinite),
    #[error("the state diverged (non-finite velocity at dof {0}); the step was not applied")]
    Diverged(usize),
    #[error("invalid scene: {0}")]
    Scene(String),
    /// The physics engine gave up (MuJoCo's own divergence warnings).
    #[error("{0}")]
    Engine(String),
}

/// What one step did (all plain values; no allocation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Steps done so far (this step included) and simulated time after it.
    pub step: u64,
    pub time: f64,
    /// Gauss–Seidel sweeps of the constraint solver (0 when the direct all-stick solve was the
    /// solution, or without constraints).
    pub solver_iterations: u32,
    /// Largest impulse change in the solver's last sweep (N·s).
    pub solver_change: f64,
    /// Contacts carrying load and joint limits engaged.
    pub active_contacts: u32,
    pub active_limits: u32,
    /// Deepest penetration below the plane after the step (m, ≥ 0).
    pub max_penetration: f64,
    /// Fastest tangential speed of a loaded contact point at the end of the step (m/s).
    pub max_slip_speed: f64,
    /// Hand–handle distance after the step (m); 0 without a door.
    pub loop_error: f64,
    /// Centre of pressure of the contact forces on the plane (world x, y), if any load.
    pub zmp: Option<[f64; 2]>,
    /// Sum of the normal contact forces (N).
    pub total_normal_force: f64,
    /// Force of the door (or of the push) on the hand (N, world).
    pub hand_force: [f64; 3],
    /// Hinge torque applied (N·m).
    pub door_torque: f64,
    /// Robot centre of mass after the step (m, world).
    pub com: [f64; 3],
}

/// One physics engine as the plant runtime steps it.
pub trait Physics {
    /// Which engine (`upc`, `mujoco`), for logs and summaries.
    fn engine(&self) -> &'static str;
    /// The robot as upc models it: the supervisor's hold and the recording's link poses.
    fn robot(&self) -> &Model;
    fn q(&self) -> &DVector<f64>;
    fn v(&self) -> &DVector<f64>;
    fn time(&self) -> f64;
    fn steps(&self) -> u64;
    /// Torques [`Physics::step`] expects.
    fn n_actuated(&self) -> usize;
    /// Contact forces of the last step (N, world; ground on robot).
    fn contact_forces(&self) -> &[Vector3<f64>];
    /// The last step's report (that of the initial state before any step).
    fn last_report(&self) -> &StepReport;
    /// Where those forces applied (m, world).
    fn contact_points(&self) -> &[Vector3<f64>];
    /// Hinge angle and rate of the door (0 without one).
    fn door_angle(&self) -> f64;
    fn door_velocity(&self) -> f64;
    /// The door as upc models it (placed in the world), if the scene has one.
    fn door_model(&self) -> Option<&Model>;
    /// The scenario time at which the hinge torque of a step is sampled: `t` itself, or `t`
    /// on the step grid for an engine whose clock accumulates rounding.
    fn sample_time(&self, t: f64) -> f64 {
        t
    }
    /// A force applied at a robot frame until changed (`sim.push = "hand"`).
    fn set_push(&mut self, frame: usize, force: Vector3<f64>) -> Result<(), SimError>;
    /// One step under joint torques `tau` and the door's hinge torque.
    fn step(&mut self, tau: &DVector<f64>, door_torque: f64) -> Result<StepReport, SimError>;
    /// World placements of every robot frame at the current state.
    fn robot_frame_placements(&mut self) -> &[SE3];
    /// World placements of every door frame at the current state.
    fn door_frame_placements(&mut self) -> Option<&[SE3]>;
}

/// Places a fixed-base model's root at `base` (its joints and frames on the world).
pub(crate) fn rebase(model: &mut Model, base: &SE3) {
    for j in model.joints.iter_mut().filter(|j| j.parent.is_none()) {
        j.placement = base.compose(&j.placement);
    }
    for f in model.frames.iter_mut().filter(|f| f.parent.is_none()) {
        f.placement = base.compose(&f.placement);
    }
}
