//! What a sensor's samples go through on their way out, shared by the force, wrench and IMU
//! models: a constant bias with signs drawn from the seed, and the fieldbus's latency and
//! dropouts ([`Transport`]); and the three-axis force channel of the wrist and the sole corners.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

/// One three-axis force sensor's model (per axis).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSensorConfig {
    /// σ of the white noise of one sample (N).
    pub noise: f64,
    /// Magnitude of the constant bias per axis (N); its signs are drawn from the seed.
    pub bias: f64,
    /// Bias random walk (N/√s): after t seconds the bias has wandered by drift·√t (1σ).
    pub drift: f64,
    /// Resolution (N): samples are rounded to a multiple of it (0: none).
    pub resolution: f64,
    /// Delay in plant steps.
    pub latency: usize,
    /// Probability that a sample is lost (the previous one is published again).
    pub dropout: f64,
}

impl ForceSensorConfig {
    /// The first invalid field of the sensor keyed `name`, as (key under `sim.sensors`,
    /// message).
    pub(super) fn invalid(&self, name: &str) -> Option<(String, String)> {
        let sizes = [
            ("noise", self.noise),
            ("bias", self.bias),
            ("drift", self.drift),
            ("resolution", self.resolution),
        ];
        invalid_channel(name, &sizes, self.dropout, self.latency)
    }
}

/// Longest latency modelled (steps).
pub const MAX_LATENCY: usize = 64;

/// The first invalid setting of the sensor keyed `name`, as (key under `sim.sensors`,
/// message): a size (key, value) below 0, a dropout probability outside [0, 1), a latency
/// over [`MAX_LATENCY`].
pub(super) fn invalid_channel(
    name: &str,
    sizes: &[(&str, f64)],
    dropout: f64,
    latency: usize,
) -> Option<(String, String)> {
    if let Some(invalid) = invalid_sizes(name, sizes) {
        return Some(invalid);
    }
    if !(0.0..1.0).contains(&dropout) {
        return Some((
            format!("{name}.dropout"),
            format!("must be in [0, 1), got {dropout}"),
        ));
    }
    if latency > MAX_LATENCY {
        return Some((
            format!("{name}.latency"),
            format!("at most {MAX_LATENCY} steps, got {latency}"),
        ));
    }
    None
}

/// The first of the sizes (key, value) of the sensor keyed `name` that is not finite and ≥ 0.
pub(super) fn invalid_sizes(name: &str, sizes: &[(&str, f64)]) -> Option<(String, String)> {
    let (key, v) = sizes.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0))?;
    Some((format!("{name}.{key}"), format!("must be ≥ 0, got {v}")))
}

/// A delay line of the last `latency + 1` samples of N values, each with its plant step, and
/// the sample last published: what a fieldbus does to a sensor's samples (late, sometimes lost).
/// The latency counts plant steps whatever the rate the samples are taken at (a plant
/// publishing every second step reads the newest sample at least `latency` steps old).
#[derive(Debug, Clone)]
pub(super) struct Transport<const N: usize> {
    line: Vec<(u64, [f64; N])>,
    /// Where the newest sample is, and how many the line holds.
    head: usize,
    filled: usize,
    latency: u64,
    last: [f64; N],
    primed: bool,
}

impl<const N: usize> Transport<N> {
    /// A line of `latency` steps (at most [`MAX_LATENCY`]: a longer one is an invalid setting,
    /// refused before a run).
    pub(super) fn new(latency: usize) -> Self {
        let latency = latency.min(MAX_LATENCY);
        Self {
            line: vec![(0, [0.0; N]); latency + 1],
            head: latency,
            filled: 0,
            latency: latency as u64,
            last: [0.0; N],
            primed: false,
        }
    }

    /// Empty, as before the first sample (in place: no allocation).
    pub(super) fn reset(&mut self) {
        self.head = self.line.len() - 1;
        self.filled = 0;
        self.last = [0.0; N];
        self.primed = false;
    }

    /// Writes step `step`'s sample `x`, replaces it with the one published at that step, and
    /// returns whether the sample was lost (`u`: a uniform draw, lost when below `dropout`).
    pub(super) fn pass(&mut self, step: u64, x: &mut [f64; N], u: f64, dropout: f64) -> bool {
        let len = self.line.len();
        self.head = (self.head + 1) % len;
        self.line[self.head] = (step, *x);
        self.filled = (self.filled + 1).min(len);
        // The newest sample `latency` steps old or older; the oldest written while the line
        // fills.
        let mut delayed = (self.head + len - (self.filled - 1)) % len;
        for back in 0..self.filled {
            let i = (self.head + len - back) % len;
            if self.line[i].0 + self.latency <= step {
                delayed = i;
                break;
            }
        }
        let lost = self.primed && u < dropout;
        if !lost {
            self.last = self.line[delayed].1;
        }
        self.primed = true;
        *x = self.last;
        lost
    }
}

/// A bias of `size` per axis with signs drawn from `rng`.
pub(super) fn signed_bias(size: f64, rng: &mut ChaCha8Rng) -> [f64; 3] {
    [0; 3].map(|_| {
        let u: f64 = StandardNormal.sample(rng);
        size * u.signum()
    })
}

/// One three-axis force channel: its bias and its transport.
#[derive(Debug, Clone)]
pub(super) struct ForceChannel {
    bias: [f64; 3],
    transport: Transport<3>,
}

impl ForceChannel {
    pub(super) fn new(s: &ForceSensorConfig) -> Self {
        Self {
            bias: [0.0; 3],
            transport: Transport::new(s.latency),
        }
    }

    /// The start of a run: the bias's signs drawn from `rng` (three draws), nothing sent yet.
    pub(super) fn reset(&mut self, s: &ForceSensorConfig, rng: &mut ChaCha8Rng) {
        self.bias = signed_bias(s.bias, rng);
        self.transport.reset();
    }

    /// The sample published at `step` for the true force `f`: returns whether it was lost.
    pub(super) fn measure(
        &mut self,
        s: &ForceSensorConfig,
        step: u64,
        dt: f64,
        rng: &mut ChaCha8Rng,
        f: &mut [f64; 3],
    ) -> bool {
        let walk = s.drift * dt.sqrt();
        for c in 0..3 {
            let (n, w): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
            self.bias[c] += walk * w;
            let mut y = f[c] + self.bias[c] + s.noise * n;
            if s.resolution > 0.0 {
                y = (y / s.resolution).round() * s.resolution;
            }
            f[c] = y;
        }
        let u: f64 = rng.random();
        self.transport.pass(step, f, u, s.dropout)
    }
}
