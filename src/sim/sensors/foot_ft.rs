//! One six-axis force/torque sensor per foot (`feet = "six_axis"`), as the iCub's and TALOS's
//! ankles have: the true wrench measured, the corners not.

use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use super::channel::{Transport, invalid_channel, signed_bias};
use super::model::{SensorModel, Stream, Truth};
use crate::channels::{N_CONTACTS, SENSOR_FEET, StateMsg};
use crate::dynamics::{PressureLoad, center_of_pressure};
use crate::plant::feet::{fill_foot_wrenches, sole};

/// One six-axis force/torque sensor's model (per axis; forces in N, moments in N m).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WrenchSensorConfig {
    /// The force channels: σ of the white noise, the constant bias's size (signs from the
    /// seed), the bias random walk (N/√s) and the resolution (0: none).
    pub noise: f64,
    pub bias: f64,
    pub drift: f64,
    pub resolution: f64,
    /// The moment channels, likewise (N m, N m/√s).
    pub moment_noise: f64,
    pub moment_bias: f64,
    pub moment_drift: f64,
    pub moment_resolution: f64,
    /// Delay in plant steps, and the probability that a sample is lost.
    pub latency: usize,
    pub dropout: f64,
}

/// When the feet are measured by these sensors (`feet = "six_axis"`), writes `foot_wrenches`
/// (each foot's true wrench in its sole's frame, through noise, biases and their drift,
/// resolution, latency, dropouts), `contact_forces` (NaN: no corner is measured), `zmp` (the
/// measured wrenches' centre of pressure; where the feet carry less than [`FEET_LOADED`] the
/// plant's stays) and `stamps[SENSOR_FEET]`; counts `foot_ft_dropouts`.
/// Draws twelve normals and one uniform per foot a step; six normals per foot at reset, however
/// the feet are measured, from a stream of their own ([`Stream::FeetBiases`]: the corner and
/// IMU draws of every seed stay what they were before these sensors existed).
pub(super) struct FootForceTorque {
    settings: WrenchSensorConfig,
    /// The feet are measured by these sensors.
    measured: bool,
    feet: [WrenchChannel; 2],
    stamp: f64,
    dropouts: u64,
}

impl FootForceTorque {
    /// The feet's sensors with `settings`; `measured`: the feet are measured by them.
    pub(super) fn new(settings: &WrenchSensorConfig, measured: bool) -> Self {
        Self {
            settings: *settings,
            measured,
            feet: [0; 2].map(|_| WrenchChannel::new(settings)),
            stamp: 0.0,
            dropouts: 0,
        }
    }
}

impl SensorModel for FootForceTorque {
    fn invalid(&self) -> Option<(String, String)> {
        let w = &self.settings;
        let sizes = [
            ("noise", w.noise),
            ("bias", w.bias),
            ("drift", w.drift),
            ("resolution", w.resolution),
            ("moment_noise", w.moment_noise),
            ("moment_bias", w.moment_bias),
            ("moment_drift", w.moment_drift),
            ("moment_resolution", w.moment_resolution),
        ];
        invalid_channel("foot_ft", &sizes, w.dropout, w.latency)
    }

    fn reset_stream(&self) -> Stream {
        Stream::FeetBiases
    }

    fn reset(&mut self, rng: &mut ChaCha8Rng) {
        for foot in &mut self.feet {
            foot.reset(&self.settings, rng);
        }
        self.stamp = 0.0;
        self.dropouts = 0;
    }

    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        if !self.measured {
            return;
        }
        let s = &self.settings;
        fill_foot_wrenches(m, truth.contact_points);
        let mut lost = 0;
        for (ch, w) in self.feet.iter_mut().zip(m.foot_wrenches.iter_mut()) {
            if ch.measure(s, truth.step, truth.dt, rng, w) {
                lost += 1;
            }
        }
        self.dropouts += lost;
        if lost < 2 {
            self.stamp = truth.stamp(s.latency);
        }
        m.stamps[SENSOR_FEET] = self.stamp;
        // No corner is measured.
        m.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
        if let Some(cop) = wrenches_cop(&m.foot_wrenches, truth.contact_points) {
            m.zmp = cop;
        }
    }

    fn counts(&self, report: &mut dyn FnMut(&'static str, u64)) {
        report("foot_ft_dropouts", self.dropouts);
    }
}

/// One six-axis force/torque channel: its biases (force, then moment) and its transport.
#[derive(Debug, Clone)]
struct WrenchChannel {
    bias: [f64; 6],
    transport: Transport<6>,
}

impl WrenchChannel {
    fn new(s: &WrenchSensorConfig) -> Self {
        Self {
            bias: [0.0; 6],
            transport: Transport::new(s.latency),
        }
    }

    /// The start of a run: the force's then the moment's bias signs drawn from `rng`.
    fn reset(&mut self, s: &WrenchSensorConfig, rng: &mut ChaCha8Rng) {
        let (f, m) = (signed_bias(s.bias, rng), signed_bias(s.moment_bias, rng));
        self.bias = [f[0], f[1], f[2], m[0], m[1], m[2]];
        self.transport.reset();
    }

    /// The sample published at `step` for the true wrench `w` (force, moment): returns whether
    /// it was lost.
    fn measure(
        &mut self,
        s: &WrenchSensorConfig,
        step: u64,
        dt: f64,
        rng: &mut ChaCha8Rng,
        w: &mut [f64; 6],
    ) -> bool {
        for (c, y) in w.iter_mut().enumerate() {
            let (noise, drift, resolution) = if c < 3 {
                (s.noise, s.drift, s.resolution)
            } else {
                (s.moment_noise, s.moment_drift, s.moment_resolution)
            };
            let (n, d): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
            self.bias[c] += drift * dt.sqrt() * d;
            *y += self.bias[c] + noise * n;
            if resolution > 0.0 {
                *y = (*y / resolution).round() * resolution;
            }
        }
        let u: f64 = rng.random();
        self.transport.pass(step, w, u, s.dropout)
    }
}

/// Below this total load (N) the feet are in the air for the centre of pressure: unloaded
/// six-axis sensors read their biases, whose moments over a few newtons put a "CoP" anywhere.
const FEET_LOADED: f64 = 20.0;

/// The centre of pressure (world x, y; flat ground) of the two feet's wrenches, each in its
/// sole's frame about the sole's centre; `None` when they carry less than [`FEET_LOADED`]. A
/// foot's share is its moment plus its force at its centre, so a lightly loaded foot adds its
/// sensor's error over the total load, not over its own (as the base estimator computes it).
fn wrenches_cop(wrenches: &[[f64; 6]; 2], points: &[[f64; 3]]) -> Option<[f64; 2]> {
    let loads = wrenches.iter().enumerate().map(|(foot, w)| {
        let (centre, r) = sole(points, foot);
        // On the sole: f_z · (x, y) = (−τ_y, τ_x).
        PressureLoad {
            normal: w[2],
            at: centre,
            moment: r * Vector3::new(-w[4], w[3], 0.0),
        }
    });
    let p = center_of_pressure(loads);
    let cop = p.point();
    (p.total > FEET_LOADED && cop.iter().all(|c| c.is_finite())).then_some(cop)
}
