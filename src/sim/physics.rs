//! The physics engine behind the plant runtime ([`super::process`]): upc's own [`World`] or
//! MuJoCo ([`super::mujoco::MujocoPlant`]). The runtime (command gate, supervisor, command
//! clock, lockstep and real-time loops, ground truth, summary) is written once against this.
//!
//! Conventions are the channel contract's (`services/CHANNELS.md`): `q` = base position,
//! quaternion x y z w, joints; `v` = base linear and angular velocity in the base frame, joint
//! rates; contact forces in the robot description's contact order, ground on robot, world frame.

use nalgebra::{DVector, Vector3};

use super::world::{SimError, StepReport, World};
use crate::dynamics::{Model, SE3};

/// Which engine a plant runs (`upc sim --plant`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Engine {
    /// upc's own simulator ([`World`]).
    #[default]
    Upc,
    /// MuJoCo, through its C library.
    Mujoco,
}

/// The centre of pressure on flat ground of vertical loads `(f_z, [x, y])`: the total load, the
/// CoP when anything is loaded, and the loaded points. A load ≤ 0 carries nothing. Shared by
/// the MuJoCo plant and the sensor models (which take it from the measured forces).
pub fn centre_of_pressure(
    loads: impl IntoIterator<Item = (f64, [f64; 2])>,
) -> (f64, Option<[f64; 2]>, u32) {
    let (mut total, mut cx, mut cy, mut active) = (0.0, 0.0, 0.0, 0u32);
    for (fz, p) in loads {
        if fz > 0.0 {
            total += fz;
            cx += fz * p[0];
            cy += fz * p[1];
            active += 1;
        }
    }
    (
        total,
        (active > 0).then(|| [cx / total, cy / total]),
        active,
    )
}

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

impl Physics for World {
    fn engine(&self) -> &'static str {
        "upc"
    }
    fn robot(&self) -> &Model {
        World::robot(self)
    }
    fn q(&self) -> &DVector<f64> {
        World::q(self)
    }
    fn v(&self) -> &DVector<f64> {
        World::v(self)
    }
    fn time(&self) -> f64 {
        World::time(self)
    }
    fn steps(&self) -> u64 {
        World::steps(self)
    }
    fn n_actuated(&self) -> usize {
        World::n_actuated(self)
    }
    fn contact_forces(&self) -> &[Vector3<f64>] {
        World::contact_forces(self)
    }
    fn contact_points(&self) -> &[Vector3<f64>] {
        World::contact_points(self)
    }
    fn last_report(&self) -> &StepReport {
        World::last_report(self)
    }
    fn door_angle(&self) -> f64 {
        World::door_angle(self)
    }
    fn door_velocity(&self) -> f64 {
        World::door_velocity(self)
    }
    fn door_model(&self) -> Option<&Model> {
        self.door().map(|(m, _)| m)
    }
    fn set_push(&mut self, frame: usize, force: Vector3<f64>) -> Result<(), SimError> {
        World::set_push(self, frame, force)
    }
    fn step(&mut self, tau: &DVector<f64>, door_torque: f64) -> Result<StepReport, SimError> {
        World::step(self, tau, door_torque)
    }
    fn robot_frame_placements(&mut self) -> &[SE3] {
        World::robot_frame_placements(self)
    }
    fn door_frame_placements(&mut self) -> Option<&[SE3]> {
        World::door_frame_placements(self)
    }
}
