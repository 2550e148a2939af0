//! What the robot's sensors make of the plant's truth (`[sim.sensors]`, docs/sensing.md): the
//! state a plant publishes passes through these models before it leaves, as a robot's SDK would
//! hand it over. Ground truth keeps going out on its own channel.
//!
//! Modelled: joint encoders (quantised positions; velocities from the drives with white noise),
//! the wrist force sensor and the sole forces (white noise, a constant bias, a bias drifting as
//! a random walk, resolution, latency in steps, dropped samples holding the previous one), an
//! IMU on the base or where the robot's description mounts it (gyro and accelerometer with
//! noise densities, biases and bias drift; the orientation of its own attitude filter with a
//! tilt error and a drifting yaw). The feet are
//! measured either at the sole's corners (`feet = "corners"`: each corner a force sensor, the
//! foot wrenches their sum in the sole's frame) or by one six-axis force/torque sensor per foot
//! (`feet = "six_axis"`: the true wrench measured, the corners not published). Unless `mocap`,
//! the floating base is not published: a robot does not measure it.
//!
//! The sensor block (IMU, foot wrenches, sample times) is filled from the truth on `truth` too,
//! so an estimator can run on exact sensors.
//!
//! Reproducible: one seeded generator per plant run, drawn in a fixed order every step, so a
//! lockstep rerun publishes the same bytes. Allocation-free after [`Sensors::new`].

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::channels::{
    MAX_DOF, N_CONTACTS, SENSOR_FEET, SENSOR_HAND, SENSOR_IMU, SENSOR_JOINTS,
    STATE_FLAG_BASE_UNMEASURED, StateMsg,
};
use crate::dynamics::{Data, Model, ReferenceFrame, forward_kinematics_velocity, frame_velocity};

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

/// The joint encoders' model (the base's six coordinates are not joints).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Counts per turn = 2^bits: positions are rounded to 2π / 2^bits (0: not quantised).
    pub bits: u32,
    /// σ of the white noise of a joint velocity from the drive (rad/s).
    pub velocity_noise: f64,
}

/// The IMU's model (mounted on the base, aligned with it). Densities as data sheets give them:
/// a sample's σ is density / √dt.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuConfig {
    /// Gyro rate noise density (rad/s/√Hz).
    pub gyro_noise_density: f64,
    /// Gyro bias per axis left after calibration (rad/s; signs from the seed) and its random
    /// walk (rad/s/√s).
    pub gyro_bias: f64,
    pub gyro_bias_drift: f64,
    /// Accelerometer noise density (m/s²/√Hz).
    pub accel_noise_density: f64,
    /// Accelerometer bias per axis (m/s²) and its random walk (m/s²/√s).
    pub accel_bias: f64,
    pub accel_bias_drift: f64,
    /// The attitude filter's constant roll and pitch error (rad; signs from the seed), its white
    /// orientation noise per axis (rad) and its yaw random walk (rad/√s: no magnetometer).
    pub tilt_error: f64,
    pub orientation_noise: f64,
    pub yaw_drift: f64,
    /// Delay in plant steps, and the probability that a sample is lost.
    pub latency: usize,
    pub dropout: f64,
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

/// A delay line of `latency + 1` samples of N values, and the sample last published: what a
/// fieldbus does to a sensor's samples (late, sometimes lost).
#[derive(Debug, Clone)]
struct Transport<const N: usize> {
    line: Vec<[f64; N]>,
    last: [f64; N],
    primed: bool,
}

impl<const N: usize> Transport<N> {
    fn new(latency: usize) -> Self {
        Self {
            line: vec![[0.0; N]; latency + 1],
            last: [0.0; N],
            primed: false,
        }
    }

    /// Writes step `step`'s sample `x`, replaces it with the one published at that step, and
    /// returns whether the sample was lost (`u`: a uniform draw, lost when below `dropout`).
    fn pass(&mut self, step: u64, x: &mut [f64; N], u: f64, dropout: f64) -> bool {
        // Write this step's sample, read the one `latency` steps old (the oldest written so far
        // while the line fills).
        let len = self.line.len() as u64;
        self.line[(step % len) as usize] = *x;
        let old = (step + 1).saturating_sub(len);
        let delayed = self.line[(old % len) as usize];
        let lost = self.primed && u < dropout;
        if !lost {
            self.last = delayed;
        }
        self.primed = true;
        *x = self.last;
        lost
    }
}

/// One three-axis force channel: its bias and its transport.
#[derive(Debug, Clone)]
struct ForceChannel {
    bias: [f64; 3],
    transport: Transport<3>,
}

impl ForceChannel {
    fn new(s: &ForceSensorConfig, rng: &mut ChaCha8Rng) -> Self {
        let bias = [0; 3].map(|_| {
            let u: f64 = StandardNormal.sample(rng);
            s.bias * u.signum()
        });
        Self {
            bias,
            transport: Transport::new(s.latency),
        }
    }

    /// The sample published at `step` for the true force `f`: returns whether it was lost.
    fn measure(
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

/// One six-axis force/torque channel: its biases (force, then moment) and its transport.
#[derive(Debug, Clone)]
struct WrenchChannel {
    bias: [f64; 6],
    transport: Transport<6>,
}

impl WrenchChannel {
    fn new(s: &WrenchSensorConfig, rng: &mut ChaCha8Rng) -> Self {
        let (f, m) = (signed_bias(s.bias, rng), signed_bias(s.moment_bias, rng));
        Self {
            bias: [f[0], f[1], f[2], m[0], m[1], m[2]],
            transport: Transport::new(s.latency),
        }
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

/// A bias of `size` per axis with signs drawn from `rng`.
fn signed_bias(size: f64, rng: &mut ChaCha8Rng) -> [f64; 3] {
    [0; 3].map(|_| {
        let u: f64 = StandardNormal.sample(rng);
        size * u.signum()
    })
}

/// The IMU: its biases, the attitude filter's error and the transport of its ten values
/// (orientation xyzw, angular velocity, specific force).
#[derive(Debug, Clone)]
struct ImuChannel {
    gyro_bias: [f64; 3],
    accel_bias: [f64; 3],
    /// Roll and pitch error of the attitude filter (constant) and its yaw error (a walk).
    tilt: [f64; 2],
    yaw: f64,
    transport: Transport<10>,
}

impl ImuChannel {
    fn new(c: &ImuConfig, rng: &mut ChaCha8Rng) -> Self {
        let gyro_bias = signed_bias(c.gyro_bias, rng);
        let accel_bias = signed_bias(c.accel_bias, rng);
        let t = signed_bias(c.tilt_error, rng);
        Self {
            gyro_bias,
            accel_bias,
            tilt: [t[0], t[1]],
            yaw: 0.0,
            transport: Transport::new(c.latency),
        }
    }

    /// Measures the true sample `x` (orientation, angular velocity, specific force) in place;
    /// returns whether it was lost.
    fn measure(
        &mut self,
        c: &ImuConfig,
        step: u64,
        dt: f64,
        rng: &mut ChaCha8Rng,
        x: &mut [f64; 10],
    ) -> bool {
        let mut n = || -> f64 { StandardNormal.sample(rng) };
        let (sg, sa) = (
            c.gyro_noise_density / dt.sqrt(),
            c.accel_noise_density / dt.sqrt(),
        );
        let (wg, wa) = (
            c.gyro_bias_drift * dt.sqrt(),
            c.accel_bias_drift * dt.sqrt(),
        );
        for k in 0..3 {
            self.gyro_bias[k] += wg * n();
            self.accel_bias[k] += wa * n();
            x[4 + k] += self.gyro_bias[k] + sg * n();
            x[7 + k] += self.accel_bias[k] + sa * n();
        }
        // The attitude filter's error, a small rotation about the world's axes applied to the
        // true orientation.
        self.yaw += c.yaw_drift * dt.sqrt() * n();
        let e = Vector3::new(
            self.tilt[0] + c.orientation_noise * n(),
            self.tilt[1] + c.orientation_noise * n(),
            self.yaw + c.orientation_noise * n(),
        );
        let truth = UnitQuaternion::from_quaternion(Quaternion::new(x[3], x[0], x[1], x[2]));
        let r = UnitQuaternion::from_scaled_axis(e) * truth;
        x[..4].copy_from_slice(&[r.i, r.j, r.k, r.w]);
        let u: f64 = rng.random();
        self.transport.pass(step, x, u, c.dropout)
    }
}

/// What an accelerometer reads, from its point's world velocity over successive states: the specific force R^T (a + g ẑ), a by finite difference (0 on the first state).
#[derive(Debug, Clone, Copy, Default)]
struct SpecificForce {
    last: Option<(u64, Vector3<f64>)>,
    acc: Vector3<f64>,
}

impl SpecificForce {
    fn update(&mut self, step: u64, dt: f64, vel: Vector3<f64>) -> Vector3<f64> {
        match self.last {
            Some((s, v)) if s < step => self.acc = (vel - v) / ((step - s) as f64 * dt),
            Some(_) => {}
            None => self.acc = Vector3::zeros(),
        }
        self.last = Some((step, vel));
        self.acc
    }
}

/// Where the IMU sits when not on the base ([`crate::robot::Robot::imu_frame`]): the robot's
/// model and workspace to place it from the state, allocated once.
pub struct ImuMount {
    model: Model,
    data: Data,
    frame: usize,
    q: nalgebra::DVector<f64>,
    v: nalgebra::DVector<f64>,
}

impl ImuMount {
    /// The IMU on frame `frame` of `model` (the plant's robot, whose coordinates the state
    /// carries).
    pub fn new(model: &Model, frame: usize) -> Self {
        Self {
            model: model.clone(),
            data: Data::new(model),
            frame,
            q: nalgebra::DVector::zeros(model.nq),
            v: nalgebra::DVector::zeros(model.nv),
        }
    }

    /// The frame's orientation (world), angular velocity and origin's velocity (world axes) in
    /// the state `m`; `None` when the state does not fit the model.
    fn place(&mut self, m: &StateMsg) -> Option<(UnitQuaternion<f64>, Vector3<f64>, Vector3<f64>)> {
        let (nq, nv) = (self.model.nq, self.model.nv);
        if m.nq as usize != nq || m.nv as usize != nv || nq > MAX_DOF {
            return None;
        }
        self.q.as_mut_slice().copy_from_slice(&m.q[..nq]);
        self.v.as_mut_slice().copy_from_slice(&m.v[..nv]);
        forward_kinematics_velocity(&self.model, &mut self.data, &self.q, &self.v).ok()?;
        let rot = self.data.o_m_f[self.frame].rot;
        let r =
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(rot));
        let t = frame_velocity(
            &self.model,
            &self.data,
            self.frame,
            ReferenceFrame::LocalWorldAligned,
        );
        Some((r, t.ang, t.lin))
    }
}

/// The sensor models of one plant run (the sensor block alone on `truth`).
pub struct Sensors {
    cfg: SensorsConfig,
    /// The models are on (`realistic`).
    models: bool,
    gravity: f64,
    rng: ChaCha8Rng,
    wrist: ForceChannel,
    soles: Vec<ForceChannel>,
    feet: [WrenchChannel; 2],
    imu: ImuChannel,
    /// The IMU's place when not on the base.
    mount: Option<ImuMount>,
    specific_force: SpecificForce,
    /// Sample times of the IMU, feet and hand as last published.
    stamps: [f64; 4],
    pub counts: SensorCounts,
}

impl Sensors {
    /// The sensors of a plant with gravity `gravity` (m/s²), its IMU on the base or at `mount`.
    pub fn new(cfg: &SensorsConfig, gravity: f64, mount: Option<ImuMount>) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let wrist = ForceChannel::new(&cfg.wrist, &mut rng);
        let soles = (0..N_CONTACTS)
            .map(|_| ForceChannel::new(&cfg.soles, &mut rng))
            .collect();
        let imu = ImuChannel::new(&cfg.imu, &mut rng);
        // The feet's six-axis biases come from a stream of their own: the corner and IMU draws
        // of every seed stay what they were before these sensors existed.
        let mut feet_rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        feet_rng.set_stream(1);
        let feet = [0; 2].map(|_| WrenchChannel::new(&cfg.foot_ft, &mut feet_rng));
        Self {
            cfg: *cfg,
            models: cfg.sensing == Sensing::Realistic,
            gravity,
            rng,
            wrist,
            soles,
            feet,
            imu,
            mount,
            specific_force: SpecificForce::default(),
            stamps: [0.0; 4],
            counts: SensorCounts::default(),
        }
    }

    /// Whether the models are on.
    pub fn realistic(&self) -> bool {
        self.models
    }

    /// Fills the sensor block of the true state in `m` and, on `realistic`, turns the state into
    /// what the sensors say, at plant step `m.step` of period `dt`; `contact_points`: the sole
    /// corners (world), for the foot wrenches and the centre of pressure of the measured forces.
    pub fn apply(&mut self, m: &mut StateMsg, dt: f64, contact_points: &[[f64; 3]]) {
        let imu_truth = self.imu_truth(m, dt);
        let (t, step) = (m.time, m.step);
        if !self.models {
            publish_imu(m, &imu_truth);
            fill_foot_wrenches(m, contact_points);
            m.stamps = [t; 4];
            return;
        }
        let cfg = self.cfg;
        // Joints: the configuration past the base's 7 coordinates, the velocity past its 6.
        let (nq, nv) = (m.nq as usize, m.nv as usize);
        let q_step = if cfg.encoders.bits > 0 {
            std::f64::consts::TAU / (1u64 << cfg.encoders.bits) as f64
        } else {
            0.0
        };
        if q_step > 0.0 {
            for q in m.q.iter_mut().take(nq.min(MAX_DOF)).skip(7) {
                *q = (*q / q_step).round() * q_step;
            }
        }
        for v in m.v.iter_mut().take(nv.min(MAX_DOF)).skip(6) {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            *v += cfg.encoders.velocity_noise * n;
        }
        let late = |latency: usize| t - latency as f64 * dt;
        if self
            .wrist
            .measure(&cfg.wrist, step, dt, &mut self.rng, &mut m.hand_force)
        {
            self.counts.wrist_dropouts += 1;
        } else {
            self.stamps[SENSOR_HAND] = late(cfg.wrist.latency);
        }
        match cfg.feet {
            FootSensing::Corners => {
                let mut lost = 0;
                for (ch, f) in self.soles.iter_mut().zip(m.contact_forces.iter_mut()) {
                    if ch.measure(&cfg.soles, step, dt, &mut self.rng, f) {
                        lost += 1;
                    }
                }
                self.counts.sole_dropouts += lost;
                // The feet's stamp is the newest sample's: a corner lost holds its previous one.
                if lost < N_CONTACTS as u64 {
                    self.stamps[SENSOR_FEET] = late(cfg.soles.latency);
                }
            }
            FootSensing::SixAxis => {
                fill_foot_wrenches(m, contact_points);
                let mut lost = 0;
                for (ch, w) in self.feet.iter_mut().zip(m.foot_wrenches.iter_mut()) {
                    if ch.measure(&cfg.foot_ft, step, dt, &mut self.rng, w) {
                        lost += 1;
                    }
                }
                self.counts.foot_ft_dropouts += lost;
                if lost < 2 {
                    self.stamps[SENSOR_FEET] = late(cfg.foot_ft.latency);
                }
                // No corner is measured.
                m.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
            }
        }
        let mut imu = imu_truth;
        if self
            .imu
            .measure(&cfg.imu, step, dt, &mut self.rng, &mut imu)
        {
            self.counts.imu_dropouts += 1;
        } else {
            self.stamps[SENSOR_IMU] = late(cfg.imu.latency);
        }
        publish_imu(m, &imu);
        self.stamps[SENSOR_JOINTS] = t;
        m.stamps = self.stamps;
        // The centre of pressure of the measured loads (flat ground), as the robot computes it;
        // where they carry no weight, the previous one stays.
        let cop = match cfg.feet {
            FootSensing::Corners => {
                fill_foot_wrenches(m, contact_points);
                let loads = (m.contact_forces.iter().zip(contact_points))
                    .map(|(f, p)| (f[2], [p[0], p[1]]));
                super::physics::centre_of_pressure(loads).1
            }
            FootSensing::SixAxis => wrenches_cop(&m.foot_wrenches, contact_points),
        };
        if let Some(cop) = cop {
            m.zmp = cop;
        }
        if !cfg.mocap {
            m.q[..7].fill(f64::NAN);
            m.v[..6].fill(f64::NAN);
            m.flags |= STATE_FLAG_BASE_UNMEASURED;
        }
    }

    /// The true IMU sample: orientation xyzw, angular velocity and specific force in the IMU's
    /// frame (the base's, or the mount's).
    fn imu_truth(&mut self, m: &StateMsg, dt: f64) -> [f64; 10] {
        let g = Vector3::new(0.0, 0.0, self.gravity);
        if let Some(mount) = self.mount.as_mut() {
            // Not the base's reading instead: an IMU read at the wrong place is a wrong sensor.
            let Some((r, omega, vel)) = mount.place(m) else {
                self.counts.imu_mount_failures += 1;
                return [f64::NAN; 10];
            };
            let a = self.specific_force.update(m.step, dt, vel);
            let (w, f) = (r.inverse() * omega, r.inverse() * (a + g));
            return [r.i, r.j, r.k, r.w, w.x, w.y, w.z, f.x, f.y, f.z];
        }
        let r = UnitQuaternion::from_quaternion(Quaternion::new(m.q[6], m.q[3], m.q[4], m.q[5]));
        let v_world = r * Vector3::new(m.v[0], m.v[1], m.v[2]);
        let a = self.specific_force.update(m.step, dt, v_world);
        let f = r.inverse() * (a + g);
        [
            m.q[3], m.q[4], m.q[5], m.q[6], m.v[3], m.v[4], m.v[5], f.x, f.y, f.z,
        ]
    }
}

/// The IMU sample `x` (orientation xyzw, angular velocity, specific force) into the state.
fn publish_imu(m: &mut StateMsg, x: &[f64; 10]) {
    m.imu_orientation.copy_from_slice(&x[..4]);
    m.imu_angular_velocity.copy_from_slice(&x[4..7]);
    m.imu_linear_acceleration.copy_from_slice(&x[7..]);
}

/// Foot `foot`'s sole (its corners' centroid, and its frame: x from the heel's to the toes'
/// midpoint, z the normal) from the corner points (world); corner order per foot: front-left,
/// front-right, rear-left, rear-right.
fn sole(points: &[[f64; 3]], foot: usize) -> (Vector3<f64>, nalgebra::Matrix3<f64>) {
    let p = |i: usize| Vector3::from(points.get(4 * foot + i).copied().unwrap_or_default());
    let centre = (p(0) + p(1) + p(2) + p(3)) / 4.0;
    (centre, crate::robot::sole_frame(p(0), p(1), p(2), p(3)))
}

/// Below this total load (N) the feet are in the air for the centre of pressure: unloaded
/// six-axis sensors read their biases, whose moments over a few newtons put a "CoP" anywhere.
const FEET_LOADED: f64 = 20.0;

/// The centre of pressure (world x, y; flat ground) of the two feet's wrenches, each in its
/// sole's frame about the sole's centre; `None` when they carry less than [`FEET_LOADED`]. A
/// foot's share is its moment plus its force at its centre, so a lightly loaded foot adds its
/// sensor's error over the total load, not over its own (as the base estimator computes it).
fn wrenches_cop(wrenches: &[[f64; 6]; 2], points: &[[f64; 3]]) -> Option<[f64; 2]> {
    let (mut load, mut sum) = (0.0, Vector3::zeros());
    for (foot, w) in wrenches.iter().enumerate() {
        let (centre, r) = sole(points, foot);
        // On the sole: f_z · (x, y) = (−τ_y, τ_x).
        load += w[2];
        sum += w[2] * centre + r * Vector3::new(-w[4], w[3], 0.0);
    }
    let cop = [sum.x / load, sum.y / load];
    (load > FEET_LOADED && cop.iter().all(|c| c.is_finite())).then_some(cop)
}

/// Each foot's wrench from its four corner forces (`m.contact_forces`, world) at `points`: in
/// the sole frame, about the corners' centroid ([`sole`]).
fn fill_foot_wrenches(m: &mut StateMsg, points: &[[f64; 3]]) {
    for foot in 0..2 {
        let k = 4 * foot;
        let p = |i: usize| Vector3::from(points.get(k + i).copied().unwrap_or_default());
        let f = |i: usize| Vector3::from(m.contact_forces[k + i]);
        let (centre, sole) = sole(points, foot);
        let (x, y, z) = (sole.column(0), sole.column(1), sole.column(2));
        let (mut force, mut moment) = (Vector3::zeros(), Vector3::zeros());
        for i in 0..4 {
            force += f(i);
            moment += (p(i) - centre).cross(&f(i));
        }
        let w = [
            x.dot(&force),
            y.dot(&force),
            z.dot(&force),
            x.dot(&moment),
            y.dot(&moment),
            z.dot(&moment),
        ];
        // A degenerate sole (points not given) publishes zeros rather than NaN.
        m.foot_wrenches[foot] = if w.iter().all(|c| c.is_finite()) {
            w
        } else {
            [0.0; 6]
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> SensorsConfig {
        let force = ForceSensorConfig {
            noise: 0.5,
            bias: 2.0,
            drift: 0.0,
            resolution: 0.0,
            latency: 0,
            dropout: 0.0,
        };
        SensorsConfig {
            sensing: Sensing::Realistic,
            seed: 7,
            mocap: true,
            encoders: EncoderConfig {
                bits: 12,
                velocity_noise: 0.01,
            },
            imu: ImuConfig {
                gyro_noise_density: 2.4e-4,
                gyro_bias: 1e-3,
                gyro_bias_drift: 0.0,
                accel_noise_density: 1.7e-3,
                accel_bias: 0.02,
                accel_bias_drift: 0.0,
                tilt_error: 3.5e-3,
                orientation_noise: 0.0,
                yaw_drift: 0.0,
                latency: 0,
                dropout: 0.0,
            },
            wrist: force,
            feet: FootSensing::Corners,
            soles: force,
            foot_ft: WrenchSensorConfig {
                noise: 0.3,
                bias: 2.0,
                drift: 0.0,
                resolution: 0.0,
                moment_noise: 0.01,
                moment_bias: 0.1,
                moment_drift: 0.0,
                moment_resolution: 0.0,
                latency: 0,
                dropout: 0.0,
            },
            motor_torques: crate::sim::robot_sensing::MotorTorqueConfig {
                noise: 0.0,
                friction: 0.0,
                friction_velocity: 0.05,
                viscous: 0.0,
                resolution: 0.0,
                latency: 0,
            },
        }
    }

    fn state(t_step: u64, hand: [f64; 3]) -> Box<StateMsg> {
        let mut m: Box<StateMsg> = Box::default();
        m.step = t_step;
        m.nq = 10;
        m.nv = 9;
        m.q[6] = 1.0;
        m.q[7] = 0.3;
        m.hand_force = hand;
        m
    }

    /// Statistics of the wrist over many samples: the mean is the truth plus the bias
    /// (±2 N per axis), the spread the noise's σ.
    #[test]
    fn a_force_sensor_has_its_bias_and_noise() {
        let mut s = Sensors::new(&cfg(), 9.81, None);
        let n = 20_000;
        let (mut sum, mut sum2) = ([0.0; 3], [0.0; 3]);
        for k in 0..n {
            let mut m = state(k, [-10.0, 0.0, 5.0]);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            for c in 0..3 {
                sum[c] += m.hand_force[c];
                sum2[c] += m.hand_force[c] * m.hand_force[c];
            }
        }
        for (c, truth) in [-10.0, 0.0, 5.0].into_iter().enumerate() {
            let mean = sum[c] / n as f64;
            let sd = (sum2[c] / n as f64 - mean * mean).sqrt();
            assert!(
                ((mean - truth).abs() - 2.0).abs() < 0.02,
                "axis {c}: mean {mean}"
            );
            assert!((sd - 0.5).abs() < 0.02, "axis {c}: σ {sd}");
        }
    }

    /// The bias's random walk: its spread over independent runs after T seconds is drift √T.
    #[test]
    fn the_bias_drifts_as_a_random_walk() {
        let mut c = cfg();
        (c.wrist.noise, c.wrist.bias, c.wrist.drift) = (0.0, 0.0, 0.1);
        let (runs, steps, dt) = (400, 1000, 1e-3);
        let mut sum2 = 0.0;
        for seed in 0..runs {
            c.seed = seed;
            let mut s = Sensors::new(&c, 9.81, None);
            let mut last = 0.0;
            for k in 0..steps {
                let mut m = state(k, [0.0; 3]);
                s.apply(&mut m, dt, &[[0.0; 3]; N_CONTACTS]);
                last = m.hand_force[0];
            }
            sum2 += last * last;
        }
        let sd = (sum2 / runs as f64).sqrt();
        let expected = 0.1 * (steps as f64 * dt).sqrt();
        assert!(
            (sd / expected - 1.0).abs() < 0.15,
            "{sd} against {expected}"
        );
    }

    /// A latency of L steps publishes, at step k, the sample of step k − L; a resolution rounds.
    #[test]
    fn latency_delays_and_resolution_rounds() {
        let mut c = cfg();
        (
            c.wrist.noise,
            c.wrist.bias,
            c.wrist.latency,
            c.wrist.resolution,
        ) = (0.0, 0.0, 3, 0.25);
        let mut s = Sensors::new(&c, 9.81, None);
        let mut out = Vec::new();
        for k in 0..10 {
            let mut m = state(k, [k as f64 + 0.1, 0.0, 0.0]);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            out.push(m.hand_force[0]);
        }
        assert_eq!(&out[3..], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            &out[..3],
            &[0.0, 0.0, 0.0],
            "the first sample until the line fills"
        );
    }

    /// Encoders: positions on the 2π / 2^bits grid, the base untouched; velocities noisy.
    #[test]
    fn encoders_quantise_joints_only() {
        let mut s = Sensors::new(&cfg(), 9.81, None);
        let mut m = state(0, [0.0; 3]);
        m.q[0] = 0.123456789;
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        let step = std::f64::consts::TAU / 4096.0;
        assert_eq!(m.q[0], 0.123456789, "the base is no joint");
        assert!((m.q[7] / step - (m.q[7] / step).round()).abs() < 1e-9);
        assert!((m.q[7] - 0.3).abs() <= step / 2.0);
        assert!(m.v[6] != 0.0 && m.v[6].abs() < 0.1, "{}", m.v[6]);
    }

    /// Dropouts hold the previous sample and are counted; the same seed gives the same bytes.
    #[test]
    fn dropouts_hold_and_a_seed_reproduces() {
        let mut c = cfg();
        c.wrist.dropout = 0.2;
        let run = |c: &SensorsConfig| {
            let mut s = Sensors::new(c, 9.81, None);
            let mut out = Vec::new();
            for k in 0..2000 {
                let mut m = state(k, [k as f64, 0.0, 0.0]);
                s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
                out.push(m.hand_force[0].to_bits());
            }
            (out, s.counts.wrist_dropouts)
        };
        let (a, lost) = run(&c);
        assert!((300..500).contains(&lost), "{lost} of 2000 lost at p = 0.2");
        assert_eq!(a, run(&c).0);
        c.seed += 1;
        assert_ne!(a, run(&c).0);
    }

    /// The centre of pressure follows the measured forces.
    #[test]
    fn the_centre_of_pressure_is_the_measured_forces() {
        let mut c = cfg();
        (c.soles.noise, c.soles.bias) = (0.0, 0.0);
        let mut s = Sensors::new(&c, 9.81, None);
        let mut m = state(0, [0.0; 3]);
        let mut points = [[0.0; 3]; N_CONTACTS];
        for (k, p) in points.iter_mut().enumerate() {
            *p = [k as f64 * 0.01, 0.1, 0.0];
            m.contact_forces[k] = [0.0, 0.0, if k < 2 { 10.0 } else { 0.0 }];
        }
        s.apply(&mut m, 1e-3, &points);
        assert!((m.zmp[0] - 0.005).abs() < 1e-12 && (m.zmp[1] - 0.1).abs() < 1e-12);
    }

    /// The IMU of a base at rest, tilted about x: its accelerometer reads g along the world's
    /// up in its own frame, plus its bias; its gyro reads its bias; its orientation is the truth
    /// turned by the attitude filter's tilt error. On `truth` it reads the truth exactly.
    #[test]
    fn an_imu_at_rest_reads_gravity_in_its_frame() {
        let tilt = 0.3_f64;
        let at = |k: u64| {
            let mut m = state(k, [0.0; 3]);
            let r = UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0);
            m.q[3..7].copy_from_slice(&[r.i, r.j, r.k, r.w]);
            m
        };
        let up = UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0).inverse() * Vector3::z() * 9.81;
        let mut c = cfg();
        let mut exact = c;
        exact.sensing = Sensing::Truth;
        let mut s = Sensors::new(&exact, 9.81, None);
        for k in 0..3 {
            let mut m = at(k);
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            for a in 0..3 {
                assert!((m.imu_linear_acceleration[a] - up[a]).abs() < 1e-12);
                assert_eq!(m.imu_angular_velocity[a], 0.0);
            }
            assert_eq!(m.stamps, [0.0; 4]);
        }
        (c.imu.gyro_noise_density, c.imu.accel_noise_density) = (0.0, 0.0);
        let mut s = Sensors::new(&c, 9.81, None);
        let mut m = at(5);
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        for a in 0..3 {
            let bias = m.imu_linear_acceleration[a] - up[a];
            assert!((bias.abs() - 0.02).abs() < 1e-12, "accel bias {bias}");
            assert!((m.imu_angular_velocity[a].abs() - 1e-3).abs() < 1e-12);
        }
        let o = m.imu_orientation;
        let meas = UnitQuaternion::from_quaternion(Quaternion::new(o[3], o[0], o[1], o[2]));
        let err =
            (meas * UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0).inverse()).scaled_axis();
        assert!((err.x.abs() - 3.5e-3).abs() < 1e-9 && (err.y.abs() - 3.5e-3).abs() < 1e-9);
        assert!(err.z.abs() < 1e-12, "no yaw drift configured: {err}");
    }

    /// A base accelerating at 2 m/s² along x: the accelerometer reads (2, 0, g) once it has two
    /// states to difference.
    #[test]
    fn the_accelerometer_reads_the_base_acceleration() {
        let mut c = cfg();
        c.sensing = Sensing::Truth;
        let mut s = Sensors::new(&c, 9.81, None);
        let mut read = [0.0; 3];
        for k in 0..5 {
            let mut m = state(k, [0.0; 3]);
            m.v[0] = 2.0 * k as f64 * 1e-3;
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            read = m.imu_linear_acceleration;
        }
        assert!(
            (read[0] - 2.0).abs() < 1e-9 && read[1].abs() < 1e-12,
            "{read:?}"
        );
        assert!((read[2] - 9.81).abs() < 1e-12);
    }

    /// A foot's wrench is its corners' forces in the sole frame about their centroid: a foot
    /// turned by 90° about z, loaded on its two front corners.
    #[test]
    fn a_foot_wrench_is_its_corners_in_the_sole_frame() {
        let mut c = cfg();
        c.sensing = Sensing::Truth;
        let mut s = Sensors::new(&c, 9.81, None);
        let mut m = state(0, [0.0; 3]);
        // Toes along +y: front-left (−x side), front-right, rear-left, rear-right; 0.2 × 0.1 m.
        let mut points = [[0.0; 3]; N_CONTACTS];
        points[..4].copy_from_slice(&[
            [-0.05, 0.1, 0.0],
            [0.05, 0.1, 0.0],
            [-0.05, -0.1, 0.0],
            [0.05, -0.1, 0.0],
        ]);
        m.contact_forces[0] = [1.0, 0.0, 50.0];
        m.contact_forces[1] = [1.0, 0.0, 50.0];
        s.apply(&mut m, 1e-3, &points);
        let w = m.foot_wrenches[0];
        // In the sole frame: x = world y, y = world −x, z = world z. The moment about the
        // centre, Σ p × f = (10, 0, −0.2) in the world: the load on the toes (CoP x = −τy / fz
        // = 0.1 m, the front edge).
        let expected = [0.0, -2.0, 100.0, 0.0, -10.0, -0.2];
        for (a, e) in w.iter().zip(expected) {
            assert!((a - e).abs() < 1e-12, "{w:?}");
        }
        assert_eq!(
            m.foot_wrenches[1], [0.0; 6],
            "a degenerate sole reads nothing"
        );
    }

    /// Two feet 0.2 × 0.1 m, toes along +x, 0.1 m either side of y = 0, and their corner
    /// forces: the left foot on its toes (CoP x = +0.1), the right flat with a sideways pull.
    fn two_feet(m: &mut StateMsg) -> [[f64; 3]; N_CONTACTS] {
        let mut points = [[0.0; 3]; N_CONTACTS];
        for (foot, y) in [(0, 0.1), (1, -0.1)] {
            let corners = [[0.1, 0.05], [0.1, -0.05], [-0.1, 0.05], [-0.1, -0.05]];
            for (i, [cx, cy]) in corners.into_iter().enumerate() {
                points[4 * foot + i] = [cx, y + cy, 0.0];
            }
        }
        for i in 0..2 {
            m.contact_forces[i] = [0.0, 0.0, 60.0];
        }
        for i in 4..8 {
            m.contact_forces[i] = [0.0, 2.0, 30.0];
        }
        points
    }

    /// A six-axis sensor per foot: over many samples its mean is the true wrench plus the bias
    /// (±2 N, ±0.1 N m per axis), its spread the configured σ; the corners are not published;
    /// without noise the CoP of its wrenches is the CoP of the true corner forces.
    #[test]
    fn a_six_axis_foot_sensor_measures_the_wrench() {
        let mut c = cfg();
        c.feet = FootSensing::SixAxis;
        let n = 20_000;
        let mut s = Sensors::new(&c, 9.81, None);
        let (mut sum, mut sum2) = ([0.0; 6], [0.0; 6]);
        let mut truth = [0.0; 6];
        for k in 0..n {
            let mut m = state(k, [0.0; 3]);
            let points = two_feet(&mut m);
            fill_foot_wrenches(&mut m, &points);
            truth = m.foot_wrenches[0];
            s.apply(&mut m, 1e-3, &points);
            assert!(m.contact_forces.iter().flatten().all(|f| f.is_nan()));
            for a in 0..6 {
                sum[a] += m.foot_wrenches[0][a];
                sum2[a] += m.foot_wrenches[0][a].powi(2);
            }
        }
        for a in 0..6 {
            let (bias, sigma) = if a < 3 { (2.0, 0.3) } else { (0.1, 0.01) };
            let mean = sum[a] / n as f64;
            let sd = (sum2[a] / n as f64 - mean * mean).sqrt();
            let off = (mean - truth[a]).abs();
            assert!(
                (off - bias).abs() < 0.02 * bias,
                "axis {a}: mean {mean} of {truth:?}"
            );
            assert!((sd / sigma - 1.0).abs() < 0.05, "axis {a}: σ {sd}");
        }
        // Exact sensors: the wrenches' CoP is the corners' (left 120 N at x = 0.1, y = 0.1;
        // right 120 N at x = 0, y = −0.1).
        let c = SensorsConfig {
            foot_ft: WrenchSensorConfig {
                bias: 0.0,
                noise: 0.0,
                moment_bias: 0.0,
                moment_noise: 0.0,
                ..c.foot_ft
            },
            ..c
        };
        let mut s = Sensors::new(&c, 9.81, None);
        let mut m = state(0, [0.0; 3]);
        let points = two_feet(&mut m);
        s.apply(&mut m, 1e-3, &points);
        assert!(
            (m.zmp[0] - 0.05).abs() < 1e-12 && m.zmp[1].abs() < 1e-12,
            "{:?}",
            m.zmp
        );
        assert_eq!(s.counts.foot_ft_dropouts, 0);
    }

    /// An IMU in the head of the embedded robot at home, its torso pitched by 0.2 rad (neck
    /// straight): at rest its accelerometer reads g tilted 0.2 rad from what one on the base
    /// reads, and its orientation is 0.2 rad from the base's.
    #[test]
    fn a_mounted_imu_reads_its_own_frame() {
        let robot = crate::robot::Robot::embedded_default().unwrap();
        let model = &robot.model;
        let mut c = cfg();
        c.sensing = Sensing::Truth;
        let read = |mount: Option<ImuMount>| {
            let mut s = Sensors::new(&c, 9.81, mount);
            let mut m: Box<StateMsg> = Box::default();
            (m.nq, m.nv) = (model.nq as u32, model.nv as u32);
            m.q[..model.nq].copy_from_slice(robot.home.as_slice());
            let torso = model.joints[model.joint_id("torso_pitch").unwrap()].idx_q;
            m.q[torso] = 0.2;
            s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            let o = m.imu_orientation;
            let r = UnitQuaternion::from_quaternion(Quaternion::new(o[3], o[0], o[1], o[2]));
            (r, Vector3::from(m.imu_linear_acceleration))
        };
        let head = model.frame_id("head").unwrap();
        let (r_base, f_base) = read(None);
        let (r_head, f_head) = read(Some(ImuMount::new(model, head)));
        assert!((f_head.norm() - 9.81).abs() < 1e-9, "at rest: {f_head}");
        assert!((f_head.angle(&f_base) - 0.2).abs() < 1e-9);
        assert!((r_head.angle_to(&r_base) - 0.2).abs() < 1e-9);
        // A state that does not fit the mount's model: no sample (NaN), counted.
        let mut s = Sensors::new(&c, 9.81, Some(ImuMount::new(model, head)));
        let mut m: Box<StateMsg> = Box::default();
        (m.nq, m.nv) = (model.nq as u32 - 1, model.nv as u32);
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        assert!(m.imu_orientation.iter().all(|x| x.is_nan()));
        assert_eq!(s.counts.imu_mount_failures, 1);
    }

    /// A setting out of range is named by its key.
    #[test]
    fn an_invalid_setting_is_named() {
        assert_eq!(cfg().invalid(), None);
        let mut c = cfg();
        c.foot_ft.moment_noise = -1.0;
        assert_eq!(c.invalid().unwrap().0, "foot_ft.moment_noise");
        let mut c = cfg();
        c.imu.dropout = 1.0;
        assert_eq!(c.invalid().unwrap().0, "imu.dropout");
        let mut c = cfg();
        c.soles.latency = MAX_LATENCY + 1;
        assert_eq!(c.invalid().unwrap().0, "soles.latency");
    }

    /// A robot does not measure its base: without `mocap` the base is NaN and the flag says so;
    /// stamps lag by the latency.
    #[test]
    fn without_mocap_the_base_is_not_published() {
        let mut c = cfg();
        (c.mocap, c.imu.latency, c.wrist.latency) = (false, 2, 1);
        let mut s = Sensors::new(&c, 9.81, None);
        let mut m = state(10, [0.0; 3]);
        m.time = 0.01;
        s.apply(&mut m, 1e-3, &[[0.0; 3]; N_CONTACTS]);
        assert!(m.q[..7].iter().chain(&m.v[..6]).all(|x| x.is_nan()));
        assert!(m.q[7].is_finite() && m.flags & STATE_FLAG_BASE_UNMEASURED != 0);
        assert!((m.stamps[SENSOR_IMU] - 0.008).abs() < 1e-12);
        assert!((m.stamps[SENSOR_HAND] - 0.009).abs() < 1e-12);
        assert_eq!(m.stamps[SENSOR_JOINTS], 0.01);
    }
}
