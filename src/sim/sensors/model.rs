//! The seam every sensor model plugs into: [`SensorModel`], the truth it reads ([`Truth`]), the
//! generator it draws from ([`Stream`]) and the counters it reports ([`SensorCounts`]). The
//! models depend on this file, the runtime (`mod.rs`) on them: no file depends back on the
//! runtime.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::channels::{MAX_DOF, StateMsg};

/// One kind of sensor: what it makes of the truth at each step. Its doc comment names the
/// fields of [`StateMsg`] it writes, and what it draws from which [`Stream`]. Built once from
/// its settings under `[sim.sensors]` (allocating there, never after).
pub(super) trait SensorModel {
    /// Its settings' first invalid field, as (key under `sim.sensors`, message).
    fn invalid(&self) -> Option<(String, String)>;
    /// The generator [`SensorModel::apply`] draws from.
    fn stream(&self) -> Stream {
        Stream::Main
    }
    /// The generator [`SensorModel::reset`] draws from.
    fn reset_stream(&self) -> Stream {
        self.stream()
    }
    /// The start of a run: its constant errors (bias signs, the attitude filter's tilt) drawn
    /// from `rng`, its delay line empty, nothing published yet, its counters zero.
    fn reset(&mut self, rng: &mut ChaCha8Rng);
    /// Writes its fields of `m` as published at this step, from the truth (`truth`, and those
    /// fields as the engine filled them), its noise drawn from `rng`; counts what it lost.
    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng);
    /// Its counters, each by its name in the plant's summary (none by default).
    fn counts(&self, _report: &mut dyn FnMut(&'static str, u64)) {}
}

/// A declared model, as the runtime holds it.
pub(super) type Model = Box<dyn SensorModel + Send>;

/// The run's random generators, one seed and one stream each: a model given a stream of its own
/// leaves the draws of every other model as they were before it existed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stream {
    /// The declared models' draws, in the declared order.
    Main = 0,
    /// The six-axis feet's biases, drawn at reset.
    FeetBiases = 1,
    /// The drives' torque estimates (MT-1).
    Drives = 2,
}

/// The run's generators, one per [`Stream`].
pub(super) struct Streams([ChaCha8Rng; 3]);

impl Streams {
    /// Every stream of `seed` at its start.
    pub(super) fn new(seed: u64) -> Self {
        Self(
            [Stream::Main, Stream::FeetBiases, Stream::Drives].map(|stream| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                rng.set_stream(stream as u64);
                rng
            }),
        )
    }

    pub(super) fn get(&mut self, stream: Stream) -> &mut ChaCha8Rng {
        &mut self.0[stream as usize]
    }
}

/// The truth of one plant step that is not in the state's own fields, or that a sensor
/// before this one may have overwritten.
pub(super) struct Truth<'a> {
    pub(super) step: u64,
    /// Plant time (s) and period (s).
    pub(super) time: f64,
    pub(super) dt: f64,
    /// The sole corners (world), in the robot description's contact order.
    pub(super) contact_points: &'a [[f64; 3]],
    /// The IMU's true sample where it sits: orientation xyzw, angular velocity and specific
    /// force in its frame (taken before the encoders quantise the joints it is placed from).
    pub(super) imu: [f64; 10],
    /// The true velocities (before the encoders' noise).
    pub(super) velocity: [f64; MAX_DOF],
}

impl Truth<'_> {
    /// The time of a sample that left `latency` steps ago.
    pub(super) fn stamp(&self, latency: usize) -> f64 {
        self.time - latency as f64 * self.dt
    }
}

/// The counters of a run, each by its name in the plant's summary (`sim.json`'s
/// `sensor_counts`), in the order the models are declared.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SensorCounts(Vec<(&'static str, u64)>);

impl SensorCounts {
    pub(super) fn push(&mut self, name: &'static str, n: u64) {
        self.0.push((name, n));
    }

    /// The counter named `name`.
    pub fn get(&self, name: &str) -> Option<u64> {
        self.0.iter().find(|(k, _)| *k == name).map(|(_, n)| *n)
    }

    /// The counters' names, in order.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.0.iter().map(|(k, _)| *k)
    }
}

impl serde::Serialize for SensorCounts {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.0.iter().map(|(k, n)| (k, n)))
    }
}
