//! What a robot has beyond `[sim.sensors]`: its drives' torque estimates ([`super::drives`],
//! MT-1) and NaN for the groups it lacks ([`super::missing`]). Declared at the end of the
//! runtime's list ([`super::Sensors::with_robot`]); for the tests, also as a step of their own
//! after the applied torques (`RobotSensing`), with the same draws.

use super::drives::{DriveTorques, MotorTorqueConfig};
use super::missing::MissingSensors;
use super::model::Model;
#[cfg(test)]
use super::model::{Streams, Truth};
#[cfg(test)]
use crate::channels::{MAX_DOF, StateMsg};
use crate::robot::SensorSpec;

/// What of a robot its sensors' models need beyond `[sim.sensors]`.
#[derive(Debug, Clone)]
pub struct RobotSensors {
    /// What it measures (its description's `[sensors]`).
    pub spec: SensorSpec,
    /// Each velocity coordinate's effort limit (N·m; 0 for the base's and unlimited joints').
    pub effort: Vec<f64>,
}

/// The models of what `robot` has: its drives' torque estimates by MT-1 (`settings`) and NaN
/// for the groups it lacks (neither without a robot).
pub(super) fn robot_models(
    settings: &MotorTorqueConfig,
    robot: Option<RobotSensors>,
) -> [Model; 2] {
    let (spec, effort) = match robot {
        Some(r) => (Some(r.spec), r.effort),
        None => (None, Vec::new()),
    };
    let estimated = spec.is_some_and(|s| s.joint_torques);
    [
        Box::new(DriveTorques::new(settings, estimated, effort)),
        Box::new(MissingSensors::new(spec)),
    ]
}

/// What the robot measures and its drives' torque estimates, on `realistic` sensing (the tests'
/// form: MT-1 alone, and the list's equivalence).
#[cfg(test)]
pub struct RobotSensing {
    realistic: bool,
    streams: Streams,
    models: [Model; 2],
    /// The true velocities of the step (before the encoders' noise).
    velocity: [f64; MAX_DOF],
}

#[cfg(test)]
impl RobotSensing {
    /// For a robot measuring `spec`, on `realistic` sensing or not, whose velocity coordinates
    /// have the effort limits `effort`; `seed`: the run's.
    pub fn new(
        spec: SensorSpec,
        realistic: bool,
        cfg: MotorTorqueConfig,
        effort: Vec<f64>,
        seed: u64,
    ) -> Self {
        let robot = RobotSensors { spec, effort };
        let mut sensing = Self {
            realistic,
            streams: Streams::new(seed),
            models: robot_models(&cfg, Some(robot)),
            velocity: [0.0; MAX_DOF],
        };
        sensing.reset();
        sensing
    }

    /// Keep the step's true joint velocities (call before the encoders' models).
    pub fn take_truth(&mut self, m: &StateMsg) {
        self.velocity = m.v;
    }

    /// A new plant session: nothing delayed yet (the generators go on).
    pub fn reset(&mut self) {
        for model in &mut self.models {
            model.reset(self.streams.get(model.reset_stream()));
        }
    }

    /// On `realistic`: the torque estimates by MT-1 (or NaN without them) and NaN for every
    /// group the robot does not measure. `m.joint_torques` holds the applied torques.
    pub fn apply(&mut self, m: &mut StateMsg) {
        if !self.realistic {
            return;
        }
        // These models read the step and the true velocities only.
        let truth = Truth {
            step: m.step,
            time: m.time,
            dt: 0.0,
            contact_points: &[],
            imu: [f64::NAN; 10],
            velocity: self.velocity,
        };
        for model in &mut self.models {
            model.apply(&truth, m, self.streams.get(model.stream()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::FootSensors;

    fn cfg() -> MotorTorqueConfig {
        MotorTorqueConfig {
            noise: 0.0,
            friction: 0.02,
            friction_velocity: 0.05,
            viscous: 0.1,
            resolution: 0.0,
            latency: 2,
        }
    }

    fn spec() -> SensorSpec {
        SensorSpec {
            feet: Some(FootSensors::None),
            wrist: false,
            joint_torques: true,
        }
    }

    /// On a plant publishing every second step (a bus at 500 Hz on a 1 kHz plant) the latency
    /// is still in plant steps: three steps late reads the sample four steps old.
    #[test]
    fn the_latency_counts_plant_steps_at_any_publishing_rate() {
        let c = MotorTorqueConfig {
            friction: 0.0,
            viscous: 0.0,
            latency: 3,
            ..cfg()
        };
        let mut s = RobotSensing::new(spec(), true, c, vec![0.0, 50.0], 1);
        let mut out = Vec::new();
        for step in (0..12).step_by(2) {
            let mut m = StateMsg {
                nv: 2,
                step,
                ..Default::default()
            };
            m.joint_torques[1] = step as f64;
            s.take_truth(&m);
            s.apply(&mut m);
            out.push(m.joint_torques[1]);
        }
        assert_eq!(out, [0.0, 0.0, 0.0, 2.0, 4.0, 6.0]);
    }

    /// The estimate is the torque plus the friction the velocity signs, two steps late; the
    /// feet and the hand a G1 does not measure are NaN.
    #[test]
    fn torque_estimates_carry_the_friction_late_and_the_missing_sensors_are_nan() {
        let mut s = RobotSensing::new(spec(), true, cfg(), vec![0.0, 50.0], 1);
        let mut out = Vec::new();
        for step in 0..5 {
            let mut m = StateMsg {
                nv: 2,
                step,
                ..Default::default()
            };
            m.v[1] = 1.0;
            m.joint_torques[0] = f64::NAN;
            m.joint_torques[1] = step as f64;
            m.hand_force = [1.0; 3];
            s.take_truth(&m);
            s.apply(&mut m);
            assert!(m.joint_torques[0].is_nan());
            assert!(
                m.hand_force[0].is_nan() && m.zmp[0].is_nan() && m.foot_wrenches[1][2].is_nan()
            );
            out.push(m.joint_torques[1]);
        }
        let bias = 0.02 * 50.0 * (1.0f64 / 0.05).tanh() + 0.1;
        // Step 0 has nothing older; from step 2 on, the estimate of two steps before.
        assert!((out[0] - bias).abs() < 1e-12, "{out:?}");
        assert!((out[4] - (2.0 + bias)).abs() < 1e-12, "{out:?}");
        // Reversed, the friction opposes the other way.
        let mut m = StateMsg {
            nv: 2,
            ..Default::default()
        };
        m.v[1] = -1.0;
        let mut t = RobotSensing::new(
            spec(),
            true,
            MotorTorqueConfig {
                latency: 0,
                ..cfg()
            },
            vec![0.0, 50.0],
            1,
        );
        t.take_truth(&m);
        t.apply(&mut m);
        assert!((m.joint_torques[1] + bias).abs() < 1e-12);
    }

    /// On `truth` nothing is masked or modelled.
    #[test]
    fn truth_sensing_publishes_everything() {
        let mut s = RobotSensing::new(spec(), false, cfg(), vec![0.0, 50.0], 1);
        let mut m = StateMsg {
            hand_force: [1.0; 3],
            ..Default::default()
        };
        m.joint_torques[1] = 3.0;
        s.take_truth(&m);
        s.apply(&mut m);
        assert_eq!((m.hand_force[0], m.joint_torques[1]), (1.0, 3.0));
    }
}
