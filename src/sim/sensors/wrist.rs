//! The wrist's three-axis force sensor: the hand force as the robot measures it.

use rand_chacha::ChaCha8Rng;

use super::channel::{ForceChannel, ForceSensorConfig};
use super::model::{SensorModel, Truth};
use crate::channels::{SENSOR_HAND, StateMsg};

/// Writes `hand_force` (noise, bias and its drift, resolution, latency, dropouts) and
/// `stamps[SENSOR_HAND]` (the time of the sample published); counts `wrist_dropouts`. Draws
/// six normals and one uniform a step, three normals at reset.
pub(super) struct WristForce {
    settings: ForceSensorConfig,
    channel: ForceChannel,
    stamp: f64,
    dropouts: u64,
}

impl WristForce {
    pub(super) fn new(settings: &ForceSensorConfig) -> Self {
        Self {
            settings: *settings,
            channel: ForceChannel::new(settings),
            stamp: 0.0,
            dropouts: 0,
        }
    }
}

impl SensorModel for WristForce {
    fn invalid(&self) -> Option<(String, String)> {
        self.settings.invalid("wrist")
    }

    fn reset(&mut self, rng: &mut ChaCha8Rng) {
        self.channel.reset(&self.settings, rng);
        self.stamp = 0.0;
        self.dropouts = 0;
    }

    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        let s = &self.settings;
        if self
            .channel
            .measure(s, truth.step, truth.dt, rng, &mut m.hand_force)
        {
            self.dropouts += 1;
        } else {
            self.stamp = truth.stamp(s.latency);
        }
        m.stamps[SENSOR_HAND] = self.stamp;
    }

    fn counts(&self, report: &mut dyn FnMut(&'static str, u64)) {
        report("wrist_dropouts", self.dropouts);
    }
}
