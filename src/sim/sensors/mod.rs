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
//! - [`base`]: unless `mocap`, the floating base is not published: a robot does not measure it;
//! - what the robot's description's `[sensors]` says it has ([`Sensors::with_robot`]): each
//!   drive's torque estimate ([`drives`], MT-1), and NaN for the groups it lacks ([`missing`]);
//!   [`robot`] declares them.
//!
//! The engines give the truth; [`Sensors`], the runtime, holds the declared models as one list
//! ([`declared`]) and applies, resets, checks and counts them by going through it: a new kind of
//! sensor is its file and one entry there. The shared pieces: [`model`] (the seam: the trait, the
//! truth a model reads, the generators, the counters), [`channel`] (bias signs, the fieldbus's
//! latency and dropouts, the three-axis force channel) and, below the plant, the soles' geometry
//! and corner wrenches ([`crate::plant::feet`]).
//!
//! The sensor block (IMU, foot wrenches, sample times) is filled from the truth on `truth` too,
//! so an estimator can run on exact sensors.
//!
//! Reproducible: one seed per plant run, its streams ([`model::Stream`]) drawn in a fixed order
//! every step (the declared order), so a lockstep rerun publishes the same bytes.
//! Allocation-free after [`Sensors::new`].

mod base;
mod channel;
mod drives;
mod encoders;
mod foot_ft;
mod imu;
mod missing;
mod model;
mod robot;
mod soles;
mod wrist;

pub use channel::{ForceSensorConfig, MAX_LATENCY};
pub use drives::{MAX_DELAY, MotorTorqueConfig};
pub use encoders::EncoderConfig;
pub use foot_ft::WrenchSensorConfig;
pub use imu::{ImuConfig, ImuMount};
pub use model::SensorCounts;
#[cfg(test)]
use robot::RobotSensing;
pub use robot::RobotSensors;

use serde::Deserialize;

use crate::channels::StateMsg;

use base::UnmeasuredBase;
use encoders::JointEncoders;
use foot_ft::FootForceTorque;
use imu::{Imu, ImuTruth, publish_imu};
use model::{Model, Streams, Truth};
use robot::robot_models;
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
    /// Each drive's torque estimate, for a robot that has them ([`drives`]).
    pub motor_torques: MotorTorqueConfig,
}

impl SensorsConfig {
    /// The first invalid field, as (key under `sim.sensors`, message): each declared model
    /// checks its own, in the declared order.
    pub fn invalid(&self) -> Option<(String, String)> {
        declared(self, None).iter().find_map(|m| m.invalid())
    }
}

/// The sensor models of a run with `cfg`, of `robot` if given (without: no torque estimate
/// modelled, nothing masked), in the order they draw from the main stream: the order must not
/// change, or a seed's runs stop publishing the same bytes. Models on a stream of their own
/// ([`model::Stream`]) may go anywhere.
fn declared(cfg: &SensorsConfig, robot: Option<RobotSensors>) -> Vec<Model> {
    let [drives, missing] = robot_models(&cfg.motor_torques, robot);
    vec![
        Box::new(JointEncoders::new(&cfg.encoders)),
        Box::new(WristForce::new(&cfg.wrist)),
        Box::new(SoleCorners::new(
            &cfg.soles,
            cfg.feet == FootSensing::Corners,
        )),
        Box::new(FootForceTorque::new(
            &cfg.foot_ft,
            cfg.feet == FootSensing::SixAxis,
        )),
        Box::new(Imu::new(&cfg.imu)),
        Box::new(UnmeasuredBase::new(cfg.mocap)),
        // What the robot has, last: they read the torques applied, and mask what came before.
        drives,
        missing,
    ]
}

/// The sensors of one plant run: the declared models (the sensor block alone on `truth`).
pub struct Sensors {
    seed: u64,
    /// The models are on (`realistic`).
    realistic: bool,
    streams: Streams,
    imu_truth: ImuTruth,
    models: Vec<Model>,
}

impl Sensors {
    /// The sensors of a plant with gravity `gravity` (m/s²), its IMU on the base or at `mount`;
    /// no robot's torque estimates or missing sensors ([`Sensors::with_robot`]).
    pub fn new(cfg: &SensorsConfig, gravity: f64, mount: Option<ImuMount>) -> Self {
        Self::build(cfg, gravity, mount, None)
    }

    /// [`Sensors::new`] for `robot`: its drives' torque estimates (MT-1) and NaN for the groups
    /// it lacks, on `realistic`. The state given to [`Sensors::apply`] holds the torques
    /// applied over the step in `joint_torques`.
    pub fn with_robot(
        cfg: &SensorsConfig,
        gravity: f64,
        mount: Option<ImuMount>,
        robot: RobotSensors,
    ) -> Self {
        Self::build(cfg, gravity, mount, Some(robot))
    }

    fn build(
        cfg: &SensorsConfig,
        gravity: f64,
        mount: Option<ImuMount>,
        robot: Option<RobotSensors>,
    ) -> Self {
        let mut sensors = Self {
            seed: cfg.seed,
            realistic: cfg.sensing == Sensing::Realistic,
            streams: Streams::new(cfg.seed),
            imu_truth: ImuTruth::new(gravity, mount),
            models: declared(cfg, robot),
        };
        sensors.reset();
        sensors
    }

    /// The start of the run: the generators seeded, every model's constant errors drawn (in the
    /// declared order), the counters zero.
    fn reset(&mut self) {
        self.streams = Streams::new(self.seed);
        self.imu_truth.reset();
        for model in &mut self.models {
            model.reset(self.streams.get(model.reset_stream()));
        }
    }

    /// Whether the models are on.
    pub fn realistic(&self) -> bool {
        self.realistic
    }

    /// The counters of the run so far, by name (for the plant's summary).
    pub fn counts(&self) -> SensorCounts {
        let mut counts = SensorCounts::default();
        for model in &self.models {
            model.counts(&mut |name, n| counts.push(name, n));
        }
        counts.push("imu_mount_failures", self.imu_truth.mount_failures);
        counts
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
            imu: self.imu_truth.sample(m, dt),
            velocity: m.v,
        };
        if !self.realistic {
            publish_imu(m, &truth.imu);
            crate::plant::feet::fill_foot_wrenches(m, contact_points);
            m.stamps = [truth.time; 4];
            return;
        }
        for model in &mut self.models {
            model.apply(&truth, m, self.streams.get(model.stream()));
        }
    }
}

#[cfg(test)]
mod tests;
