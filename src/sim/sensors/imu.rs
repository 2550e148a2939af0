//! The IMU, on the base or where the robot's description mounts it: its true sample from the
//! plant's state ([`ImuTruth`]), and what the sensor makes of it ([`Imu`]: gyro and
//! accelerometer with noise densities, biases and bias drift; the orientation of its own
//! attitude filter with a tilt error and a drifting yaw).

use nalgebra::{DVector, Quaternion, Rotation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use super::channel::{Transport, invalid_channel, signed_bias};
use super::model::{SensorModel, Truth};
use crate::channels::{MAX_DOF, SENSOR_IMU, StateMsg};
use crate::dynamics::{Data, Model, ReferenceFrame, forward_kinematics_velocity, frame_velocity};

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

/// Writes `imu_orientation`, `imu_angular_velocity`, `imu_linear_acceleration` (the true
/// sample [`Truth::imu`] through biases, noise, the attitude filter's error, latency and
/// dropouts) and `stamps[SENSOR_IMU]`; counts `imu_dropouts`. Draws 16 normals and one uniform
/// a step, nine normals at reset (gyro bias, accelerometer bias, tilt).
pub(super) struct Imu {
    settings: ImuConfig,
    gyro_bias: [f64; 3],
    accel_bias: [f64; 3],
    /// Roll and pitch error of the attitude filter (constant) and its yaw error (a walk).
    tilt: [f64; 2],
    yaw: f64,
    /// Orientation xyzw, angular velocity, specific force.
    transport: Transport<10>,
    stamp: f64,
    /// The plant step of the last sample: the biases walk over the time since.
    last_step: Option<u64>,
    dropouts: u64,
}

impl Imu {
    pub(super) fn new(settings: &ImuConfig) -> Self {
        Self {
            settings: *settings,
            gyro_bias: [0.0; 3],
            accel_bias: [0.0; 3],
            tilt: [0.0; 2],
            yaw: 0.0,
            transport: Transport::new(settings.latency),
            stamp: 0.0,
            last_step: None,
            dropouts: 0,
        }
    }
}

impl SensorModel for Imu {
    fn invalid(&self) -> Option<(String, String)> {
        let i = &self.settings;
        let sizes = [
            ("gyro_noise_density", i.gyro_noise_density),
            ("gyro_bias", i.gyro_bias),
            ("gyro_bias_drift", i.gyro_bias_drift),
            ("accel_noise_density", i.accel_noise_density),
            ("accel_bias", i.accel_bias),
            ("accel_bias_drift", i.accel_bias_drift),
            ("tilt_error", i.tilt_error),
            ("orientation_noise", i.orientation_noise),
            ("yaw_drift", i.yaw_drift),
        ];
        invalid_channel("imu", &sizes, i.dropout, i.latency)
    }

    fn reset(&mut self, rng: &mut ChaCha8Rng) {
        let c = &self.settings;
        self.gyro_bias = signed_bias(c.gyro_bias, rng);
        self.accel_bias = signed_bias(c.accel_bias, rng);
        let t = signed_bias(c.tilt_error, rng);
        self.tilt = [t[0], t[1]];
        self.yaw = 0.0;
        self.transport.reset();
        self.stamp = 0.0;
        self.last_step = None;
        self.dropouts = 0;
    }

    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        let mut x = truth.imu;
        if self.measure(truth.step, truth.dt, rng, &mut x) {
            self.dropouts += 1;
        } else {
            self.stamp = truth.stamp(self.settings.latency);
        }
        publish_imu(m, &x);
        m.stamps[SENSOR_IMU] = self.stamp;
    }

    fn counts(&self, report: &mut dyn FnMut(&'static str, u64)) {
        report("imu_dropouts", self.dropouts);
    }
}

impl Imu {
    /// Measures the true sample `x` (orientation, angular velocity, specific force) in place;
    /// returns whether it was lost.
    fn measure(&mut self, step: u64, dt: f64, rng: &mut ChaCha8Rng, x: &mut [f64; 10]) -> bool {
        let c = &self.settings;
        let mut n = || -> f64 { StandardNormal.sample(rng) };
        let (sg, sa) = (
            c.gyro_noise_density / dt.sqrt(),
            c.accel_noise_density / dt.sqrt(),
        );
        // A plant publishing every few steps: the walks cover the steps between samples.
        let span = dt * self.last_step.map_or(1, |l| step.saturating_sub(l).max(1)) as f64;
        self.last_step = Some(step);
        let (wg, wa) = (
            c.gyro_bias_drift * span.sqrt(),
            c.accel_bias_drift * span.sqrt(),
        );
        for k in 0..3 {
            self.gyro_bias[k] += wg * n();
            self.accel_bias[k] += wa * n();
            x[4 + k] += self.gyro_bias[k] + sg * n();
            x[7 + k] += self.accel_bias[k] + sa * n();
        }
        // The attitude filter's error, a small rotation about the world's axes applied to the
        // true orientation.
        self.yaw += c.yaw_drift * span.sqrt() * n();
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

/// The IMU sample `x` (orientation xyzw, angular velocity, specific force) into the state.
pub(super) fn publish_imu(m: &mut StateMsg, x: &[f64; 10]) {
    m.imu_orientation.copy_from_slice(&x[..4]);
    m.imu_angular_velocity.copy_from_slice(&x[4..7]);
    m.imu_linear_acceleration.copy_from_slice(&x[7..]);
}

/// The IMU's true sample from the plant's state: where it sits (the base or a mount), and its
/// point's velocity over successive states for the accelerometer.
pub(super) struct ImuTruth {
    gravity: f64,
    /// The IMU's place when not on the base.
    mount: Option<ImuMount>,
    specific_force: SpecificForce,
    /// Samples of a mounted IMU whose frame could not be placed in the state (it does not fit
    /// the model, or its kinematics failed): published as NaN, which the estimator refuses.
    pub(super) mount_failures: u64,
}

impl ImuTruth {
    /// An IMU under gravity `gravity` (m/s²), on the base or at `mount`.
    pub(super) fn new(gravity: f64, mount: Option<ImuMount>) -> Self {
        Self {
            gravity,
            mount,
            specific_force: SpecificForce::default(),
            mount_failures: 0,
        }
    }

    /// No state seen yet (the first accelerometer sample reads gravity alone), no failure.
    pub(super) fn reset(&mut self) {
        self.specific_force = SpecificForce::default();
        self.mount_failures = 0;
    }

    /// The true IMU sample: orientation xyzw, angular velocity and specific force in the IMU's
    /// frame (the base's, or the mount's), from the true state `m`.
    pub(super) fn sample(&mut self, m: &StateMsg, dt: f64) -> [f64; 10] {
        let g = Vector3::new(0.0, 0.0, self.gravity);
        if let Some(mount) = self.mount.as_mut() {
            // Not the base's reading instead: an IMU read at the wrong place is a wrong sensor.
            let Some((r, omega, vel)) = mount.place(m) else {
                self.mount_failures += 1;
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
    q: DVector<f64>,
    v: DVector<f64>,
}

impl ImuMount {
    /// The IMU on frame `frame` of `model` (the plant's robot, whose coordinates the state
    /// carries).
    pub fn new(model: &Model, frame: usize) -> Self {
        Self {
            model: model.clone(),
            data: Data::new(model),
            frame,
            q: DVector::zeros(model.nq),
            v: DVector::zeros(model.nv),
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
        let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot));
        let t = frame_velocity(
            &self.model,
            &self.data,
            self.frame,
            ReferenceFrame::LocalWorldAligned,
        );
        Some((r, t.ang, t.lin))
    }
}
