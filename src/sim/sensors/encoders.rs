//! The joint encoders: quantised positions, velocities from the drives with white noise.

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use super::channel::invalid_sizes;
use super::model::{SensorModel, Truth};
use crate::channels::{MAX_DOF, SENSOR_JOINTS, StateMsg};

/// The joint encoders' model (the base's six coordinates are not joints).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Counts per turn = 2^bits: positions are rounded to 2π / 2^bits (0: not quantised).
    pub bits: u32,
    /// σ of the white noise of a joint velocity from the drive (rad/s).
    pub velocity_noise: f64,
}

/// Writes the joints of `q` (past the base's 7 coordinates) and `v` (past its 6), and
/// `stamps[SENSOR_JOINTS]` (sampled now). Draws one normal per joint velocity.
pub(super) struct JointEncoders {
    settings: EncoderConfig,
}

impl JointEncoders {
    pub(super) fn new(settings: &EncoderConfig) -> Self {
        Self {
            settings: *settings,
        }
    }
}

impl SensorModel for JointEncoders {
    fn invalid(&self) -> Option<(String, String)> {
        let s = &self.settings;
        if s.bits > 32 {
            return Some((
                "encoders.bits".into(),
                format!("at most 32, got {}", s.bits),
            ));
        }
        invalid_sizes("encoders", &[("velocity_noise", s.velocity_noise)])
    }

    /// Nothing drawn: encoders have no constant error here.
    fn reset(&mut self, _rng: &mut ChaCha8Rng) {}

    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        let s = &self.settings;
        let (nq, nv) = (m.nq as usize, m.nv as usize);
        let q_step = if s.bits > 0 {
            std::f64::consts::TAU / (1u64 << s.bits) as f64
        } else {
            0.0
        };
        if q_step > 0.0 {
            for q in m.q.iter_mut().take(nq.min(MAX_DOF)).skip(7) {
                *q = (*q / q_step).round() * q_step;
            }
        }
        for v in m.v.iter_mut().take(nv.min(MAX_DOF)).skip(6) {
            let n: f64 = StandardNormal.sample(rng);
            *v += s.velocity_noise * n;
        }
        m.stamps[SENSOR_JOINTS] = truth.time;
    }
}
