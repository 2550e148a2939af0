//! The floating base as a robot publishes it: not measured, unless a motion-capture system
//! stands in for the sensor (`mocap`).

use rand_chacha::ChaCha8Rng;

use super::model::{SensorModel, Truth};
use crate::channels::{STATE_FLAG_BASE_UNMEASURED, StateMsg};

/// Without `mocap`, writes NaN into the base's `q[..7]` and `v[..6]` and sets
/// `STATE_FLAG_BASE_UNMEASURED` in `flags`; with it, leaves the true base. Draws nothing.
pub(super) struct UnmeasuredBase {
    mocap: bool,
}

impl UnmeasuredBase {
    /// `mocap`: `sim.sensors.mocap`.
    pub(super) fn new(mocap: bool) -> Self {
        Self { mocap }
    }
}

impl SensorModel for UnmeasuredBase {
    /// A flag: nothing to check.
    fn invalid(&self) -> Option<(String, String)> {
        None
    }

    fn reset(&mut self, _rng: &mut ChaCha8Rng) {}

    fn apply(&mut self, _truth: &Truth, m: &mut StateMsg, _rng: &mut ChaCha8Rng) {
        if !self.mocap {
            m.q[..7].fill(f64::NAN);
            m.v[..6].fill(f64::NAN);
            m.flags |= STATE_FLAG_BASE_UNMEASURED;
        }
    }
}
