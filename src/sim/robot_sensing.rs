//! What the robot measures (its description's `[sensors]`), on `realistic` sensing: the groups
//! it lacks are published as NaN (a G1 has no foot or wrist force sensor), and each drive's
//! torque estimate goes through its own model (docs/sensing.md, "Motor torque estimates").
//!
//! The model of a torque estimated from a motor's current, per joint, of effort limit τ_max:
//!
//!   τ̂ = q_r( τ + f_c τ_max tanh(q̇ / v_s) + b_v q̇ + σ τ_max n ),  n ~ N(0, 1)        (MT-1)
//!
//! published `latency` steps late. The current measures the torque the motor makes, which is
//! the joint's torque plus what the gearbox's friction takes (Coulomb f_c τ_max, smoothed over
//! v_s, and viscous b_v): the estimate is biased by the friction, signed by the velocity.
//! σ τ_max is the current sensing's noise; q_r rounds to the resolution.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use crate::channels::{MAX_DOF, N_CONTACTS, StateMsg};
use crate::robot::{FootSensors, SensorSpec};
use crate::sim::sensors::Transport;

/// `[sim.sensors.motor_torques]`: MT-1's sizes.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorTorqueConfig {
    /// σ: white noise, a fraction of each joint's effort limit.
    pub noise: f64,
    /// f_c: Coulomb friction of the gearbox, a fraction of the effort limit.
    pub friction: f64,
    /// v_s (rad/s): the velocity over which the friction changes sign.
    pub friction_velocity: f64,
    /// b_v (N·m·s/rad): viscous friction.
    pub viscous: f64,
    /// q_r (N·m): resolution (0: not rounded).
    pub resolution: f64,
    /// Delay in plant steps (at most [`MAX_DELAY`]).
    pub latency: usize,
}

/// Longest delay of the torque estimates modelled (steps).
pub const MAX_DELAY: usize = 8;

impl MotorTorqueConfig {
    /// The first invalid field, as (key under `sim.sensors.motor_torques`, message).
    pub fn invalid(&self) -> Option<(String, String)> {
        for (key, v) in [
            ("noise", self.noise),
            ("friction", self.friction),
            ("viscous", self.viscous),
            ("resolution", self.resolution),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((key.into(), format!("must be ≥ 0, got {v}")));
            }
        }
        if !(self.friction_velocity.is_finite() && self.friction_velocity > 0.0) {
            return Some((
                "friction_velocity".into(),
                format!("must be > 0, got {}", self.friction_velocity),
            ));
        }
        if self.latency > MAX_DELAY {
            return Some((
                "latency".into(),
                format!("at most {MAX_DELAY} steps, got {}", self.latency),
            ));
        }
        None
    }
}

/// The plant's model of what its robot measures.
pub struct RobotSensing {
    spec: SensorSpec,
    realistic: bool,
    cfg: MotorTorqueConfig,
    /// Each velocity coordinate's effort limit (N·m; the base's and unlimited joints' 0: their
    /// estimates carry the viscous term and the resolution only).
    effort: Vec<f64>,
    rng: ChaCha8Rng,
    /// The true joint velocities of the step (before the encoders' noise).
    velocity: [f64; MAX_DOF],
    /// The estimates' latency (plant steps, whatever the publishing rate).
    delay: Transport<MAX_DOF>,
}

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
        // A stream of its own: the other sensors' draws are what they were without it.
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(2);
        Self {
            spec,
            realistic,
            cfg,
            effort,
            rng,
            velocity: [0.0; MAX_DOF],
            delay: Transport::new(cfg.latency.min(MAX_DELAY)),
        }
    }

    /// Keep the step's true joint velocities (call before the encoders' models).
    pub fn take_truth(&mut self, m: &StateMsg) {
        self.velocity = m.v;
    }

    /// A new plant session: nothing delayed yet.
    pub fn reset(&mut self) {
        self.delay.reset();
    }

    /// On `realistic`: the torque estimates by MT-1 (or NaN without them) and NaN for every
    /// group the robot does not measure. `m.joint_torques` holds the applied torques.
    pub fn apply(&mut self, m: &mut StateMsg) {
        if !self.realistic {
            return;
        }
        let nv = (m.nv as usize).min(MAX_DOF);
        if self.spec.joint_torques {
            self.estimate(m, nv);
        } else {
            m.joint_torques.fill(f64::NAN);
        }
        if self.spec.feet == Some(FootSensors::None) {
            m.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
            m.foot_wrenches = [[f64::NAN; 6]; 2];
            m.zmp = [f64::NAN; 2];
        }
        if !self.spec.wrist {
            m.hand_force = [f64::NAN; 3];
        }
    }

    /// MT-1 on each actuated joint (the base's entries stay NaN), delayed.
    fn estimate(&mut self, m: &mut StateMsg, nv: usize) {
        let c = self.cfg;
        let mut now = [f64::NAN; MAX_DOF];
        for k in 0..nv {
            let tau = m.joint_torques[k];
            if !tau.is_finite() {
                continue;
            }
            let (e, v) = (self.effort.get(k).copied().unwrap_or(0.0), self.velocity[k]);
            let n: f64 = StandardNormal.sample(&mut self.rng);
            let raw = tau
                + c.friction * e * (v / c.friction_velocity).tanh()
                + c.viscous * v
                + c.noise * e * n;
            now[k] = if c.resolution > 0.0 {
                (raw / c.resolution).round() * c.resolution
            } else {
                raw
            };
        }
        // Until `latency` steps have passed, the oldest estimate there is.
        self.delay.pass(m.step, &mut now, 1.0, 0.0);
        m.joint_torques = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
