//! What the robot's sensors make of the plant's truth (`[sim.sensors]`, docs/sensing.md): the
//! state a plant publishes passes through these models before it leaves, as a robot's SDK would
//! hand it over. Ground truth keeps going out on its own channel.
//!
//! Each kind of sensor is one part, a [`model::SensorModel`] in a file of its own, stating
//! which fields of the published state it writes:
//! - [`encoders`]: the joint encoders (quantised positions; velocities from the drives with
//!   white noise);
//! - [`wrist`]: the wrist's force sensor (white noise, a constant bias, a bias drifting as a
//!   random walk, resolution, latency in steps, dropped samples holding the previous one);
//! - the feet, measured either at the sole's corners ([`soles`], `feet = "corners"`: each corner
//!   a force sensor, the foot wrenches their sum in the sole's frame) or by one six-axis
//!   force/torque sensor per foot ([`foot_ft`], `feet = "six_axis"`: the true wrench measured,
//!   the corners not published); both publish the centre of pressure of what they measure;
//! - [`imu`]: an IMU on the base or where the robot's description mounts it (gyro and
//!   accelerometer with noise densities, biases and bias drift; the orientation of its own
//!   attitude filter with a tilt error and a drifting yaw);
//! - [`base`]: unless `mocap`, the floating base is not published: a robot does not measure it.
//!
//! The engines give the truth; [`Sensors`], the runtime, applies the declared models in turn.
//! The shared pieces: [`model`] (the seam: the trait, the truth a model reads, the counters),
//! [`channel`] (bias signs, the fieldbus's latency and dropouts, the three-axis force channel)
//! and [`feet`] (the soles' geometry and corner wrenches).
//!
//! The sensor block (IMU, foot wrenches, sample times) is filled from the truth on `truth` too,
//! so an estimator can run on exact sensors.
//!
//! Reproducible: one seeded generator per plant run, drawn in a fixed order every step (the
//! declared order), so a lockstep rerun publishes the same bytes. Allocation-free after
//! [`Sensors::new`].

mod base;
mod channel;
mod encoders;
mod feet;
mod foot_ft;
mod imu;
mod model;
mod soles;
mod wrist;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

pub use channel::ForceSensorConfig;
pub(crate) use channel::Transport;
pub use encoders::EncoderConfig;
pub use foot_ft::WrenchSensorConfig;
pub use imu::{ImuConfig, ImuMount};
pub use model::SensorCounts;

use crate::channels::StateMsg;

use base::UnmeasuredBase;
use encoders::JointEncoders;
use foot_ft::FootForceTorque;
use imu::{Imu, ImuTruth, publish_imu};
use model::{SensorModel, Truth};
use soles::SoleCorners;
use wrist::WristForce;

/// Truth or the sensor models (`sim.sensors.sensing`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Sensing {
    /// The plant's state as it is.
    Truth,
    /// Through the sensor models below.
    Realistic,
}

impl Sensing {
    pub fn name(self) -> &'static str {
        match self {
            Sensing::Truth => "truth",
            Sensing::Realistic => "realistic",
        }
    }
}

/// How the feet's loads are measured (`sim.sensors.feet`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FootSensing {
    /// A force sensor at each sole corner (the `soles` model); each foot's wrench is its
    /// corners' sum.
    Corners,
    /// One six-axis force/torque sensor per foot (the `foot_ft` model), as the iCub's and
    /// TALOS's ankles have; the corner forces are not measured (published as NaN).
    SixAxis,
}

/// `[sim.sensors]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorsConfig {
    pub sensing: Sensing,
    /// Seed of the run's generator.
    pub seed: u64,
    /// The floating base's pose and velocity are published as measured (a motion-capture
    /// system): with `false` (a robot) they are NaN and `STATE_FLAG_BASE_UNMEASURED` says so.
    /// Read on `realistic` only.
    pub mocap: bool,
    pub encoders: EncoderConfig,
    pub imu: ImuConfig,
    /// The wrist's force sensor (the hand force).
    pub wrist: ForceSensorConfig,
    /// How the feet are measured: at the corners (`soles`) or by a six-axis sensor (`foot_ft`).
    pub feet: FootSensing,
    /// Each sole corner's force (`feet = "corners"`).
    pub soles: ForceSensorConfig,
    /// Each foot's six-axis sensor (`feet = "six_axis"`), in the sole's frame.
    pub foot_ft: WrenchSensorConfig,
    /// Each drive's torque estimate, for a robot that has them (`super::robot_sensing`).
    pub motor_torques: super::robot_sensing::MotorTorqueConfig,
}

impl SensorsConfig {
    /// The first invalid field, as (key under `sim.sensors`, message).
    pub fn invalid(&self) -> Option<(String, String)> {
        let force = |s: &ForceSensorConfig| {
            [
                ("noise", s.noise),
                ("bias", s.bias),
                ("drift", s.drift),
                ("resolution", s.resolution),
            ]
        };
        let (w, i) = (&self.foot_ft, &self.imu);
        let channels: [Channel; 4] = [
            (
                "wrist",
                &force(&self.wrist),
                self.wrist.dropout,
                self.wrist.latency,
            ),
            (
                "soles",
                &force(&self.soles),
                self.soles.dropout,
                self.soles.latency,
            ),
            (
                "foot_ft",
                &[
                    ("noise", w.noise),
                    ("bias", w.bias),
                    ("drift", w.drift),
                    ("resolution", w.resolution),
                    ("moment_noise", w.moment_noise),
                    ("moment_bias", w.moment_bias),
                    ("moment_drift", w.moment_drift),
                    ("moment_resolution", w.moment_resolution),
                ],
                w.dropout,
                w.latency,
            ),
            (
                "imu",
                &[
                    ("gyro_noise_density", i.gyro_noise_density),
                    ("gyro_bias", i.gyro_bias),
                    ("gyro_bias_drift", i.gyro_bias_drift),
                    ("accel_noise_density", i.accel_noise_density),
                    ("accel_bias", i.accel_bias),
                    ("accel_bias_drift", i.accel_bias_drift),
                    ("tilt_error", i.tilt_error),
                    ("orientation_noise", i.orientation_noise),
                    ("yaw_drift", i.yaw_drift),
                ],
                i.dropout,
                i.latency,
            ),
        ];
        for (name, sizes, dropout, latency) in channels {
            if let Some((key, v)) = sizes.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
                return Some((format!("{name}.{key}"), format!("must be ≥ 0, got {v}")));
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
        }
        if let Some((key, why)) = self.motor_torques.invalid() {
            return Some((format!("motor_torques.{key}"), why));
        }
        let e = &self.encoders;
        if e.bits > 32 {
            return Some((
                "encoders.bits".into(),
                format!("at most 32, got {}", e.bits),
            ));
        }
        if !(e.velocity_noise.is_finite() && e.velocity_noise >= 0.0) {
            return Some((
                "encoders.velocity_noise".into(),
                format!("must be ≥ 0, got {}", e.velocity_noise),
            ));
        }
        None
    }
}

/// A sensor's settings for [`SensorsConfig::invalid`]: its name, its sizes that must be ≥ 0,
/// its dropout and its latency.
type Channel<'a> = (&'a str, &'a [(&'a str, f64)], f64, usize);

/// Longest latency modelled (steps).
pub const MAX_LATENCY: usize = 64;

/// The sensors of one plant run: the models declared below (the sensor block alone on
/// `truth`).
pub struct Sensors {
    cfg: SensorsConfig,
    /// The models are on (`realistic`).
    models: bool,
    rng: ChaCha8Rng,
    imu_truth: ImuTruth,
    encoders: JointEncoders,
    wrist: WristForce,
    soles: SoleCorners,
    foot_ft: FootForceTorque,
    imu: Imu,
    base: UnmeasuredBase,
    pub counts: SensorCounts,
}

impl Sensors {
    /// The sensors of a plant with gravity `gravity` (m/s²), its IMU on the base or at `mount`.
    pub fn new(cfg: &SensorsConfig, gravity: f64, mount: Option<ImuMount>) -> Self {
        let mut sensors = Self {
            cfg: *cfg,
            models: cfg.sensing == Sensing::Realistic,
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            imu_truth: ImuTruth::new(gravity, mount),
            encoders: JointEncoders::new(&cfg.encoders),
            wrist: WristForce::new(&cfg.wrist),
            soles: SoleCorners::new(&cfg.soles),
            foot_ft: FootForceTorque::new(&cfg.foot_ft),
            imu: Imu::new(&cfg.imu),
            base: UnmeasuredBase::new(&cfg.mocap),
            counts: SensorCounts::default(),
        };
        sensors.reset();
        sensors
    }

    /// The start of the run: the generator seeded, every model's constant errors drawn.
    fn reset(&mut self) {
        let rng = &mut self.rng;
        *rng = ChaCha8Rng::seed_from_u64(self.cfg.seed);
        self.imu_truth.reset();
        // In the order the seed's draws have always gone: the corners' biases are drawn however
        // the feet are measured, so the IMU's do not depend on it.
        self.encoders.reset(rng);
        self.wrist.reset(rng);
        self.soles.reset(rng);
        self.imu.reset(rng);
        self.base.reset(rng);
        // The six-axis feet's biases come from a stream of their own: the corner and IMU draws
        // of every seed stay what they were before these sensors existed.
        let mut feet_rng = ChaCha8Rng::seed_from_u64(self.cfg.seed);
        feet_rng.set_stream(1);
        self.foot_ft.reset(&mut feet_rng);
        self.counts = SensorCounts::default();
    }

    /// Whether the models are on.
    pub fn realistic(&self) -> bool {
        self.models
    }

    /// Fills the sensor block of the true state in `m` and, on `realistic`, turns the state into
    /// what the sensors say, at plant step `m.step` of period `dt`; `contact_points`: the sole
    /// corners (world), for the foot wrenches and the centre of pressure of the measured forces.
    pub fn apply(&mut self, m: &mut StateMsg, dt: f64, contact_points: &[[f64; 3]]) {
        let truth = Truth {
            step: m.step,
            time: m.time,
            dt,
            contact_points,
            imu: self.imu_truth.sample(m, dt, &mut self.counts),
        };
        if !self.models {
            publish_imu(m, &truth.imu);
            feet::fill_foot_wrenches(m, contact_points);
            m.stamps = [truth.time; 4];
            return;
        }
        let (t, rng, counts) = (&truth, &mut self.rng, &mut self.counts);
        // The declared sensors, in the order they draw from the generator.
        self.encoders.apply(t, m, rng, counts);
        self.wrist.apply(t, m, rng, counts);
        match self.cfg.feet {
            FootSensing::Corners => self.soles.apply(t, m, rng, counts),
            FootSensing::SixAxis => self.foot_ft.apply(t, m, rng, counts),
        }
        self.imu.apply(t, m, rng, counts);
        self.base.apply(t, m, rng, counts);
    }
}

#[cfg(test)]
mod tests;
