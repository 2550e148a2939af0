//! The seam every sensor model plugs into: [`SensorModel`], the truth it reads ([`Truth`]) and
//! the counters it keeps ([`SensorCounts`]). The models depend on this file, the runtime
//! (`mod.rs`) on them: no file depends back on the runtime.

use rand_chacha::ChaCha8Rng;

use crate::channels::StateMsg;

/// One kind of sensor: what it makes of the truth at each step. Its doc comment names the
/// fields of [`StateMsg`] it writes, and what it draws from the run's generator.
pub(super) trait SensorModel {
    /// Its settings under `[sim.sensors]`.
    type Settings;
    /// The model with `settings`, allocated once; [`SensorModel::reset`] starts a run.
    fn new(settings: &Self::Settings) -> Self;
    /// The start of a run: its constant errors (bias signs, the attitude filter's tilt) drawn
    /// from `rng`, its delay line empty, nothing published yet.
    fn reset(&mut self, rng: &mut ChaCha8Rng);
    /// Writes its fields of `m` as published at this step, from the truth (`truth`, and those
    /// fields as the engine filled them), its noise drawn from `rng`; counts what it lost.
    fn apply(
        &mut self,
        truth: &Truth,
        m: &mut StateMsg,
        rng: &mut ChaCha8Rng,
        counts: &mut SensorCounts,
    );
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
}

impl Truth<'_> {
    /// The time of a sample that left `latency` steps ago.
    pub(super) fn stamp(&self, latency: usize) -> f64 {
        self.time - latency as f64 * self.dt
    }
}

/// Counters of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SensorCounts {
    /// Samples lost (the previous one published again): wrist, sole corners, the feet's
    /// six-axis sensors and IMU.
    pub wrist_dropouts: u64,
    pub sole_dropouts: u64,
    pub foot_ft_dropouts: u64,
    pub imu_dropouts: u64,
    /// Samples of a mounted IMU whose frame could not be placed in the state (it does not fit
    /// the model, or its kinematics failed): published as NaN, which the estimator refuses.
    pub imu_mount_failures: u64,
}
