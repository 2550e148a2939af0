//! Each drive's torque estimate, for a robot that has them (its description's `[sensors]`
//! `joint_torques`; docs/sensing.md, "Motor torque estimates").
//!
//! The model of a torque estimated from a motor's current, per joint, of effort limit τ_max:
//!
//!   τ̂ = q_r( τ + f_c τ_max tanh(q̇ / v_s) + b_v q̇ + σ τ_max n ),  n ~ N(0, 1)        (MT-1)
//!
//! published `latency` steps late. The current measures the torque the motor makes, which is
//! the joint's torque plus what the gearbox's friction takes (Coulomb f_c τ_max, smoothed over
//! v_s, and viscous b_v): the estimate is biased by the friction, signed by the velocity.
//! σ τ_max is the current sensing's noise; q_r rounds to the resolution.

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use super::channel::{Transport, invalid_sizes};
use super::model::{SensorModel, Stream, Truth};
use crate::channels::{MAX_DOF, StateMsg};

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

/// For a robot with torque estimates, writes `joint_torques` (which holds the torques applied
/// over the step) as MT-1 estimates them from the true velocities, delayed; the base's entries
/// stay NaN. Draws one normal per actuated joint a step from a stream of its own
/// ([`Stream::Drives`]: the other sensors' draws are what they were without it); nothing at
/// reset.
pub(super) struct DriveTorques {
    settings: MotorTorqueConfig,
    /// The robot estimates its drives' torques.
    measured: bool,
    /// Each velocity coordinate's effort limit (N·m; the base's and unlimited joints' 0: their
    /// estimates carry the viscous term and the resolution only).
    effort: Vec<f64>,
    /// The estimates' latency (plant steps, whatever the publishing rate).
    delay: Transport<MAX_DOF>,
}

impl DriveTorques {
    /// MT-1 with `settings` on drives of effort limits `effort`, if the robot `measured` them.
    pub(super) fn new(settings: &MotorTorqueConfig, measured: bool, effort: Vec<f64>) -> Self {
        Self {
            settings: *settings,
            measured,
            effort,
            delay: Transport::new(settings.latency.min(MAX_DELAY)),
        }
    }
}

impl SensorModel for DriveTorques {
    fn invalid(&self) -> Option<(String, String)> {
        let c = &self.settings;
        let sizes = [
            ("noise", c.noise),
            ("friction", c.friction),
            ("viscous", c.viscous),
            ("resolution", c.resolution),
        ];
        if let Some(invalid) = invalid_sizes("motor_torques", &sizes) {
            return Some(invalid);
        }
        if !(c.friction_velocity.is_finite() && c.friction_velocity > 0.0) {
            return Some((
                "motor_torques.friction_velocity".into(),
                format!("must be > 0, got {}", c.friction_velocity),
            ));
        }
        if c.latency > MAX_DELAY {
            return Some((
                "motor_torques.latency".into(),
                format!("at most {MAX_DELAY} steps, got {}", c.latency),
            ));
        }
        None
    }

    fn stream(&self) -> Stream {
        Stream::Drives
    }

    /// Nothing delayed yet; nothing drawn.
    fn reset(&mut self, _rng: &mut ChaCha8Rng) {
        self.delay.reset();
    }

    /// MT-1 on each actuated joint, delayed.
    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        if !self.measured {
            return;
        }
        let c = self.settings;
        let nv = (m.nv as usize).min(MAX_DOF);
        let mut now = [f64::NAN; MAX_DOF];
        for k in 0..nv {
            let tau = m.joint_torques[k];
            if !tau.is_finite() {
                continue;
            }
            let (e, v) = (
                self.effort.get(k).copied().unwrap_or(0.0),
                truth.velocity[k],
            );
            let n: f64 = StandardNormal.sample(rng);
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
