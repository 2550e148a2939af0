//! What a robot does not measure (its description's `[sensors]`): published as NaN, whatever the
//! models before made of it (a G1 has no foot or wrist force sensor).

use rand_chacha::ChaCha8Rng;

use super::model::{SensorModel, Truth};
use crate::channels::{N_CONTACTS, StateMsg};
use crate::robot::{FootSensors, SensorSpec};

/// For a robot measuring `spec`, writes NaN into `joint_torques` without torque estimates,
/// into `contact_forces`, `foot_wrenches` and `zmp` without foot sensors, and into
/// `hand_force` without a wrist sensor. Draws nothing.
pub(super) struct MissingSensors {
    /// What the robot measures (`None`: everything modelled).
    spec: Option<SensorSpec>,
}

impl MissingSensors {
    pub(super) fn new(spec: Option<SensorSpec>) -> Self {
        Self { spec }
    }
}

impl SensorModel for MissingSensors {
    /// The robot's description, checked when it is read.
    fn invalid(&self) -> Option<(String, String)> {
        None
    }

    fn reset(&mut self, _rng: &mut ChaCha8Rng) {}

    fn apply(&mut self, _truth: &Truth, m: &mut StateMsg, _rng: &mut ChaCha8Rng) {
        let Some(spec) = self.spec else {
            return;
        };
        if !spec.joint_torques {
            m.joint_torques.fill(f64::NAN);
        }
        if spec.feet == Some(FootSensors::None) {
            m.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
            m.foot_wrenches = [[f64::NAN; 6]; 2];
            m.zmp = [f64::NAN; 2];
        }
        if !spec.wrist {
            m.hand_force = [f64::NAN; 3];
        }
    }
}
