//! The floating-base estimator (docs/estimation.md): what a humanoid knows of its base without
//! a motion-capture system, from the sensor block of the state (services/CHANNELS.md) — the
//! IMU, the joint encoders and the foot wrenches.
//!
//! - Orientation and angular velocity: the IMU's (its attitude filter, its gyro).
//! - Position and linear velocity: a linear Kalman filter (eqs. EST-1 … EST-4) of
//!   x = [p_b, v_b, p_l, p_r] (world): the base and both feet, predicted with the accelerometer,
//!   corrected by each stance leg's kinematics (the foot relative to the base, the base velocity
//!   the leg implies when its foot stays put) and by the ground's height under a stance foot. A
//!   foot in the air has a free position; one on the ground creeps by `foot_drift` only.
//! - Stance from the foot wrenches' normal force; the centre of pressure from the foot wrenches
//!   at the estimated soles.
//! - Joint velocities through an optional first-order low-pass.
//!
//! Model / Data: the robot's model is immutable; the estimator owns its workspace (kinematics
//! with the base at the identity). Allocation-free after [`BaseEstimator::new`].

mod settings;
pub mod wrench_observer;

pub use settings::{EstimatorMode, EstimatorSettings};

use nalgebra::{DVector, Matrix3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};

use crate::dynamics::{
    Data, DynamicsError, Model, ReferenceFrame, forward_kinematics_velocity, frame_velocity,
};
use crate::robot::N_CONTACTS;
use crate::robot::RobotState;

const NX: usize = 12;

/// An IMU reading: orientation, angular velocity and specific force (IMU frame).
type ImuSample = (UnitQuaternion<f64>, Vector3<f64>, Vector3<f64>);
/// Rows per foot: its position relative to the base (3), the base velocity (3), its height (1).
const NZ_FOOT: usize = 7;
const NZ: usize = 2 * NZ_FOOT;
/// A variance that carries no information (a swing foot's velocity rows).
const UNINFORMATIVE: f64 = 1e6;
/// χ² (3 degrees of freedom, p = 0.001) of a stance foot's velocity innovation beyond which the
/// foot is taken to slip or rock this tick.
const VELOCITY_GATE: f64 = 16.3;

/// Why a tick has no estimate.
#[derive(Debug, Clone, thiserror::Error)]
pub enum EstimatorError {
    #[error("the IMU's last sample is {age:.3} s old (limit {limit} s): no base estimate")]
    ImuLost { age: f64, limit: f64 },
    #[error("the IMU's sample is not finite or not a rotation")]
    ImuInvalid,
    #[error("the joints or foot wrenches are not finite")]
    NotFinite,
    #[error(
        "the base estimate diverged ({ticks} ticks disagreeing with the stance legs' kinematics): restarted from the kinematics"
    )]
    Diverged { ticks: u32 },
    #[error("kinematics: {0}")]
    Dynamics(#[from] DynamicsError),
}

/// What the estimator counted over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct EstimatorCounts {
    pub ticks: u64,
    /// Ticks that ran on an IMU sample already used (a lost or late one).
    pub imu_repeats: u64,
    /// Ticks refused: the IMU lost past `imu_timeout`, or invalid.
    pub imu_lost: u64,
    /// Ticks whose normalised innovation passed `innovation_limit`.
    pub disagreeing: u64,
    /// Restarts after `divergence_ticks` disagreeing ticks in a row.
    pub divergences: u64,
    /// Stance changes (a foot landing or lifting off).
    pub stance_changes: u64,
    /// Ticks with no foot on the ground (no kinematic correction).
    pub no_stance: u64,
    /// Stance feet whose velocity was gated out (slipping or rocking), foot-ticks.
    pub slipping: u64,
    /// Largest normalised innovation seen.
    pub max_innovation: f64,
}

/// The last tick's estimate, for the logs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BaseEstimate {
    /// Base position and linear velocity (m, m/s; world).
    pub position: [f64; 3],
    pub velocity: [f64; 3],
    /// Roll, pitch, yaw (rad).
    pub rpy: [f64; 3],
    pub stance: [bool; 2],
    /// The tick's normalised innovation (χ²).
    pub innovation: f64,
}

/// Both feet's geometry at one tick (base frame, base at the identity): each sole's centre and
/// rotation, the contact point on the sole (sole frame, from its centre) and relative to the
/// base, that point's velocity, and whether a stance foot is flat on the floor (EST-5).
struct Feet {
    foot: [Vector3<f64>; 2],
    sole_rot: [Matrix3<f64>; 2],
    local: [Vector3<f64>; 2],
    point: [Vector3<f64>; 2],
    point_vel: [Vector3<f64>; 2],
    flat: [bool; 2],
}

/// A stance foot is flat (EST-5) while its CoP is within this fraction of its sole's half
/// size: a foot rocking on an edge is not.
const FLAT_COP: f64 = 0.8;

pub struct BaseEstimator {
    settings: EstimatorSettings,
    model: Model,
    data: Data,
    /// The configuration and velocity with the base at the identity (scratch).
    q: DVector<f64>,
    v: DVector<f64>,
    /// Sole corner frames per foot (front-left, front-right, rear-left, rear-right).
    corners: [[usize; 4]; 2],
    weight: f64,
    dt: f64,
    /// The IMU's frame when not on the base (its readings are moved to the base, EST-0).
    imu_frame: Option<usize>,
    x: SVector<f64, NX>,
    p: SMatrix<f64, NX, NX>,
    /// Filtered joint velocities.
    joint_v: DVector<f64>,
    started: bool,
    /// Plant time of the last state (the prediction's step is the time between states).
    last_time: f64,
    stance: [bool; 2],
    /// The IMU's tilt correction C (EST-5), in the world frame: R = C R_imu.
    tilt: UnitQuaternion<f64>,
    /// The gyro's bias (EST-6, base frame), its samples this session, and the last new IMU
    /// sample's orientation and stamp.
    gyro_bias: Vector3<f64>,
    bias_samples: u64,
    bias_from: Option<(UnitQuaternion<f64>, f64)>,
    /// C has been set this session (the first state sets it in full).
    levelled: bool,
    /// The last tick's stance and contact points (sole frame, from the sole's centre).
    stance_before: [bool; 2],
    local: [Vector3<f64>; 2],
    last_imu_stamp: f64,
    disagreeing_run: u32,
    /// The foot wrenches of this tick (measured, or estimated from the joint torques).
    feet: [[f64; 6]; 2],
    /// The centre of pressure of the last tick's foot wrenches (world x, y), when loaded.
    pub cop: Option<[f64; 2]>,
    pub counts: EstimatorCounts,
    pub last: BaseEstimate,
}

impl BaseEstimate {
    /// No estimate (NaN everywhere): a tick whose base was measured, in the logs.
    pub const UNKNOWN: BaseEstimate = BaseEstimate {
        position: [f64::NAN; 3],
        velocity: [f64::NAN; 3],
        rpy: [f64::NAN; 3],
        stance: [false; 2],
        innovation: f64::NAN,
    };
}

impl BaseEstimator {
    /// The estimator of `model` (a floating-base robot, its gravity along −z) whose sole corners
    /// are the frames `corners` (state order: four per foot, left first), weighing `weight` (N),
    /// ticking every `dt` (s), its IMU on the base or on frame `imu_frame`.
    pub fn new(
        model: &Model,
        corners: [usize; N_CONTACTS],
        weight: f64,
        dt: f64,
        imu_frame: Option<usize>,
        settings: EstimatorSettings,
    ) -> Self {
        let joints = model.nv.saturating_sub(6);
        let mut q = DVector::zeros(model.nq);
        if model.nq >= 7 {
            q[6] = 1.0;
        }
        Self {
            settings,
            data: Data::new(model),
            model: model.clone(),
            q,
            v: DVector::zeros(model.nv),
            corners: [
                [corners[0], corners[1], corners[2], corners[3]],
                [corners[4], corners[5], corners[6], corners[7]],
            ],
            weight,
            dt,
            imu_frame,
            x: SVector::zeros(),
            p: SMatrix::identity(),
            joint_v: DVector::zeros(joints),
            started: false,
            last_time: 0.0,
            stance: [false; 2],
            tilt: UnitQuaternion::identity(),
            levelled: false,
            gyro_bias: Vector3::zeros(),
            bias_samples: 0,
            bias_from: None,
            stance_before: [false; 2],
            local: [Vector3::zeros(); 2],
            last_imu_stamp: f64::NEG_INFINITY,
            disagreeing_run: 0,
            feet: [[0.0; 6]; 2],
            cop: None,
            counts: EstimatorCounts::default(),
            last: BaseEstimate::default(),
        }
    }

    /// Start again from the next state (a new plant session).
    pub fn reset(&mut self) {
        self.started = false;
        self.tilt = UnitQuaternion::identity();
        self.levelled = false;
        self.gyro_bias = Vector3::zeros();
        self.bias_samples = 0;
        self.bias_from = None;
        self.disagreeing_run = 0;
        self.last_imu_stamp = f64::NEG_INFINITY;
        self.cop = None;
    }

    /// Estimates the base of `state` into `q[..7]` and `v[..6]` (Pinocchio's convention: the
    /// linear velocity in the base frame) and filters the joint velocities `v[6..]`; `q` and `v`
    /// hold the state's joints already.
    pub fn update(
        &mut self,
        state: &RobotState,
        feet: &[[f64; 6]; 2],
        q: &mut DVector<f64>,
        v: &mut DVector<f64>,
    ) -> Result<(), EstimatorError> {
        self.counts.ticks += 1;
        self.feet = *feet;
        let (r, gyro, accel) = self.imu(state)?;
        let joints = v.len() - 6;
        if !(v
            .iter()
            .skip(6)
            .chain(q.iter().skip(7))
            .all(|x| x.is_finite())
            && self.feet.iter().flatten().all(|x| x.is_finite()))
        {
            return Err(EstimatorError::NotFinite);
        }
        self.leg_kinematics(q, v)?;
        let (r, gyro, accel) = match self.imu_frame {
            Some(f) => self.imu_to_base(f, r, gyro, accel),
            None => (r, gyro, accel),
        };
        let gyro = self.unbias(state.stamps.imu, r, gyro);
        // Stance from the normal force of each foot's wrench.
        let stance = [0, 1].map(|i| self.feet[i][2] > self.settings.contact_load * self.weight);
        let Feet {
            foot,
            sole_rot,
            local,
            point,
            point_vel,
            flat,
        } = self.feet(stance);
        if self.started && stance != self.stance {
            self.counts.stance_changes += 1;
        }
        self.stance = stance;
        if !stance[0] && !stance[1] {
            self.counts.no_stance += 1;
        }
        // The first state is levelled whatever its wrenches say (a sensor's latency may leave
        // them empty): the robot starts standing on its soles, as `start` takes it to.
        let flat = if self.started { flat } else { [true; 2] };
        let r = self.level(r, &flat, &sole_rot);
        let rot = *r.to_rotation_matrix().matrix();
        // The contact points relative to the base (world axes) and the velocity of the base a
        // stance foot implies (eq. EST-3).
        let rel = point.map(|p| rot * p);
        let centre = rot * (foot[0] + foot[1]) / 2.0;
        let base_vel = [0, 1].map(|i| -(rot * (gyro.cross(&point[i]) + point_vel[i])));
        let dt = state.time - self.last_time;
        self.last_time = state.time;
        if !self.started {
            self.start(&centre, &rel);
        } else {
            // The time between states, the nominal period when that is not a sane step.
            let dt = if dt > 0.0 && dt <= 0.1 { dt } else { self.dt };
            self.predict(&rot, accel, dt);
            // The foot's state is its point under the contact point: a CoP moving over the
            // sole (or a foot landing, its point leaving the sole's centre) moves that point
            // along the rigid foot, a known shift; the foot itself stays.
            for i in 0..2 {
                let shift = rot * sole_rot[i] * (local[i] - self.local[i]);
                let mut f = self.x.fixed_rows_mut::<3>(6 + 3 * i);
                f += shift;
            }
            let nis = self.correct(&rel, &base_vel);
            self.judge(nis, &centre, &rel)?;
        }
        self.local = local;
        self.stance_before = stance;
        // The outputs.
        let (p_b, v_b) = (self.x.fixed_rows::<3>(0), self.x.fixed_rows::<3>(3));
        let v_local = rot.transpose() * v_b;
        for k in 0..3 {
            q[k] = p_b[k];
            v[k] = v_local[k];
            v[3 + k] = gyro[k];
        }
        q[3] = r.i;
        q[4] = r.j;
        q[5] = r.k;
        q[6] = r.w;
        v.rows_mut(6, joints).copy_from(&self.joint_v);
        self.cop = self.centre_of_pressure(&rot, &foot, &sole_rot);
        let (roll, pitch, yaw) = r.euler_angles();
        self.last.position = [p_b[0], p_b[1], p_b[2]];
        self.last.velocity = [v_b[0], v_b[1], v_b[2]];
        self.last.rpy = [roll, pitch, yaw];
        self.last.stance = stance;
        Ok(())
    }

    /// Joint velocities through a first-order low-pass (its state starts on the first sample),
    /// then the legs' kinematics with the base at the identity: each foot's centre relative to
    /// the base and its velocity relative to the base (base frame).
    fn leg_kinematics(&mut self, q: &DVector<f64>, v: &DVector<f64>) -> Result<(), EstimatorError> {
        let joints = v.len() - 6;
        let cutoff = self.settings.joint_velocity_cutoff;
        let alpha = if cutoff > 0.0 && self.started {
            1.0 - (-std::f64::consts::TAU * cutoff * self.dt).exp()
        } else {
            1.0
        };
        for k in 0..joints {
            self.joint_v[k] += alpha * (v[6 + k] - self.joint_v[k]);
        }
        self.q
            .rows_mut(7, q.len() - 7)
            .copy_from(&q.rows(7, q.len() - 7));
        self.v.rows_mut(6, joints).copy_from(&self.joint_v);
        forward_kinematics_velocity(&self.model, &mut self.data, &self.q, &self.v)?;
        Ok(())
    }

    /// Each foot's geometry from the legs' kinematics (base at the identity) and its contact
    /// point from its wrench.
    fn feet(&self, stance: [bool; 2]) -> Feet {
        let mut foot = [Vector3::zeros(); 2];
        let mut sole_rot = [Matrix3::identity(); 2];
        let mut local = [Vector3::zeros(); 2];
        let mut point = [Vector3::zeros(); 2];
        let mut point_vel = [Vector3::zeros(); 2];
        // A stance foot whose CoP is well inside its sole: flat on the floor (EST-5).
        let mut flat = [false; 2];
        for (i, ids) in self.corners.iter().enumerate() {
            let c = |k: usize| self.data.o_m_f[ids[k]].trans;
            foot[i] = (c(0) + c(1) + c(2) + c(3)) / 4.0;
            sole_rot[i] = crate::robot::sole_frame(c(0), c(1), c(2), c(3));
            // The contact point: the foot's CoP from its wrench, inside its sole; the sole's
            // centre in the air. A foot rocking on an edge pivots about it: that point, not the
            // centre, stays put (EST-3) and on the floor (EST-4).
            if stance[i] {
                let w = &self.feet[i];
                let half = (0..4).fold(Vector3::zeros(), |h: Vector3<f64>, k| {
                    h.sup(&(sole_rot[i].transpose() * (c(k) - foot[i])).abs())
                });
                let cop = [-w[4] / w[2], w[3] / w[2]];
                local[i] = Vector3::new(
                    cop[0].clamp(-half.x, half.x),
                    cop[1].clamp(-half.y, half.y),
                    0.0,
                );
                flat[i] = cop[0].abs() < FLAT_COP * half.x && cop[1].abs() < FLAT_COP * half.y;
            }
            point[i] = foot[i] + sole_rot[i] * local[i];
            let m = frame_velocity(
                &self.model,
                &self.data,
                ids[0],
                ReferenceFrame::LocalWorldAligned,
            );
            // The velocity of the foot's material point there, relative to the base.
            point_vel[i] = m.lin + m.ang.cross(&(point[i] - c(0)));
        }
        Feet {
            foot,
            sole_rot,
            local,
            point,
            point_vel,
            flat,
        }
    }

    /// The IMU's orientation, angular velocity and specific force, checked.
    fn imu(&mut self, state: &RobotState) -> Result<ImuSample, EstimatorError> {
        let o = state.imu_orientation;
        let quat = Quaternion::new(o[3], o[0], o[1], o[2]);
        let (w, a) = (
            Vector3::from(state.imu_angular_velocity),
            Vector3::from(state.imu_linear_acceleration),
        );
        let finite = o
            .iter()
            .chain(w.iter())
            .chain(a.iter())
            .all(|x| x.is_finite());
        if !finite || (quat.norm() - 1.0).abs() > 1e-3 {
            self.counts.imu_lost += 1;
            return Err(EstimatorError::ImuInvalid);
        }
        let stamp = state.stamps.imu;
        let age = state.time - stamp;
        if age > self.settings.imu_timeout {
            self.counts.imu_lost += 1;
            return Err(EstimatorError::ImuLost {
                age,
                limit: self.settings.imu_timeout,
            });
        }
        if stamp <= self.last_imu_stamp {
            self.counts.imu_repeats += 1;
        }
        self.last_imu_stamp = stamp;
        Ok((UnitQuaternion::from_quaternion(quat), w, a))
    }

    /// An IMU sample at frame `f` moved to the base (eq. EST-0), after the kinematics with the
    /// base at the identity: R_b = R_i R_bi^T, ω_b = R_bi ω_i − ω_rel, and the base origin's
    /// specific force f_b = R_bi f_i − ω_b × (ω_b × p) − 2 ω_b × v_rel, with p, v_rel, ω_rel the
    /// frame's position and motion relative to the base (base axes). Left out: α_b × p and
    /// the frame's acceleration relative to the base, which no sensor gives; the legs' kinematic
    /// correction absorbs them.
    fn imu_to_base(
        &self,
        f: usize,
        r: UnitQuaternion<f64>,
        gyro: Vector3<f64>,
        accel: Vector3<f64>,
    ) -> ImuSample {
        let pose = &self.data.o_m_f[f];
        let r_bi = nalgebra::Rotation3::from_matrix_unchecked(pose.rot);
        let rel = frame_velocity(
            &self.model,
            &self.data,
            f,
            ReferenceFrame::LocalWorldAligned,
        );
        let w = r_bi * gyro - rel.ang;
        let a = r_bi * accel - w.cross(&w.cross(&pose.trans)) - 2.0 * w.cross(&rel.lin);
        (
            r * UnitQuaternion::from_rotation_matrix(&r_bi).inverse(),
            w,
            a,
        )
    }

    /// The gyro's angular velocity `gyro` (base frame) less its bias (EST-6). The attitude
    /// filter's orientation `r` is free of the gyro's bias; its rate ω_r = log(r_prevᵀ r) / Δt
    /// over a new IMU sample, against the gyro's, gives the bias:
    ///
    ///   b ← b + k (ω_gyro − ω_r − b),   k = max(Δt / `gyro_bias_time`, 1 / n)
    ///
    /// (n: new samples this session, a running mean at first). Differencing the attitude's
    /// noise telescopes in the mean: its error is the orientation noise over the time constant.
    /// Without it a 1e-3 rad/s bias times the legs' half-metre lever is a 0.5 mm/s velocity
    /// EST-3 reads as the base's: 30 s of standing drifted 6.5 mm (0.3 mm without the bias).
    fn unbias(&mut self, stamp: f64, r: UnitQuaternion<f64>, gyro: Vector3<f64>) -> Vector3<f64> {
        let t = self.settings.gyro_bias_time;
        if t <= 0.0 {
            return gyro;
        }
        if let Some((r0, s0)) = self.bias_from {
            let dt = stamp - s0;
            if dt > 0.0 {
                if dt <= self.settings.imu_timeout {
                    let rate = (r0.inverse() * r).scaled_axis() / dt;
                    self.bias_samples += 1;
                    let k = (dt / t).max(1.0 / self.bias_samples as f64);
                    self.gyro_bias += k * (gyro - rate - self.gyro_bias);
                }
                self.bias_from = Some((r, stamp));
            }
        } else {
            self.bias_from = Some((r, stamp));
        }
        gyro - self.gyro_bias
    }

    /// The IMU's orientation `r` (at the base) levelled by the soles (EST-5): with both feet
    /// flat, the floor's normal in the base frame is the soles' mean normal n_b, and the
    /// orientation R must carry it to the world's up. The tilt correction C (a rotation about a
    /// horizontal axis: yaw is left to the IMU) relaxes toward the one doing that at
    /// `tilt_time`, in full at the session's first state; R = C r. `tilt_time` = 0: r as given.
    fn level(
        &mut self,
        r: UnitQuaternion<f64>,
        flat: &[bool; 2],
        sole_rot: &[Matrix3<f64>; 2],
    ) -> UnitQuaternion<f64> {
        let t = self.settings.tilt_time;
        if t > 0.0 && flat[0] && flat[1] {
            let n_b = sole_rot[0].column(2) + sole_rot[1].column(2);
            if let Some(n_b) = n_b.try_normalize(1e-9) {
                let up = self.tilt * r * n_b;
                // The rotation carrying `up` to z, about the horizontal axis up × z.
                let axis = up.cross(&Vector3::z());
                let angle = axis.norm().atan2(up.z);
                let gain = if self.levelled {
                    1.0 - (-self.dt / t).exp()
                } else {
                    1.0
                };
                self.levelled = true;
                if let Some(axis) = nalgebra::Unit::try_new(axis, 1e-12) {
                    let c = UnitQuaternion::from_axis_angle(&axis, gain * angle) * self.tilt;
                    // Its swing only: small tilts about changing horizontal axes compose to a
                    // yaw (of the order of the tilt²), and the heading is the IMU's to give.
                    self.tilt =
                        UnitQuaternion::rotation_between(&Vector3::z(), &(c * Vector3::z()))
                            .unwrap_or(c);
                }
            }
        }
        self.tilt * r
    }

    /// The first estimate: the frame the plants start the robot in (`Robot`'s home) — the sole
    /// corners' centroid (`centre`, relative to the base) at the origin on the ground —, at
    /// rest; the feet at their contact points `rel`.
    fn start(&mut self, centre: &Vector3<f64>, rel: &[Vector3<f64>; 2]) {
        let p_b = -centre;
        self.x = SVector::zeros();
        self.x.fixed_rows_mut::<3>(0).copy_from(&p_b);
        for i in 0..2 {
            let f = p_b + rel[i];
            self.x.fixed_rows_mut::<3>(6 + 3 * i).copy_from(&f);
        }
        let s = self.settings;
        self.p = SMatrix::zeros();
        for k in 0..NX {
            self.p[(k, k)] = if (3..6).contains(&k) {
                (0.05_f64).powi(2)
            } else {
                s.kinematics_noise.powi(2)
            };
        }
        self.started = true;
        self.disagreeing_run = 0;
    }

    /// Prediction with the accelerometer (eq. EST-1): constant acceleration over the tick, the
    /// feet where they were.
    fn predict(&mut self, rot: &Matrix3<f64>, specific_force: Vector3<f64>, dt: f64) {
        let g = self.model.gravity;
        let a = rot * specific_force + g;
        for k in 0..3 {
            self.x[k] += self.x[3 + k] * dt + 0.5 * a[k] * dt * dt;
            self.x[3 + k] += a[k] * dt;
        }
        // P ← F P Fᵀ + Q with F = [[I, dt I, 0], [0, I, 0], [0, 0, I]], in place by blocks.
        let mut f = SMatrix::<f64, NX, NX>::identity();
        for k in 0..3 {
            f[(k, 3 + k)] = dt;
        }
        self.p = f * self.p * f.transpose();
        // Q: white acceleration on the base (the continuous model's discretisation), a walk on
        // each foot (free in the air).
        let s = self.settings;
        let qa = s.accel_noise * s.accel_noise;
        for k in 0..3 {
            self.p[(k, k)] += qa * dt.powi(3) / 3.0;
            self.p[(k, 3 + k)] += qa * dt * dt / 2.0;
            self.p[(3 + k, k)] += qa * dt * dt / 2.0;
            self.p[(3 + k, 3 + k)] += qa * dt;
            // A foot on the ground over the whole step (the last tick's stance and this one's)
            // creeps; one that was or is in the air is free.
            for i in 0..2 {
                let walk = if self.stance[i] && self.stance_before[i] {
                    s.foot_drift * s.foot_drift * dt
                } else {
                    1.0 * dt
                };
                self.p[(6 + 3 * i + k, 6 + 3 * i + k)] += walk;
            }
        }
    }

    /// Correction by the legs (eqs. EST-2 … EST-4); returns the normalised innovation of the
    /// stance rows.
    fn correct(&mut self, rel: &[Vector3<f64>; 2], base_vel: &[Vector3<f64>; 2]) -> f64 {
        let s = self.settings;
        // A stance foot whose velocity disagrees with the prediction beyond the gate slips or
        // rocks: its EST-3 rows say nothing this tick (the accelerometer and the other foot
        // carry the base), rather than drag the estimate with it.
        let mut still = self.stance;
        for i in 0..2 {
            let d2: f64 = (0..3)
                .map(|k| {
                    let y = base_vel[i][k] - self.x[3 + k];
                    y * y / (self.p[(3 + k, 3 + k)] + s.velocity_noise.powi(2))
                })
                .sum();
            if still[i] && d2 > VELOCITY_GATE {
                still[i] = false;
                self.counts.slipping += 1;
            }
        }
        let mut h = SMatrix::<f64, NZ, NX>::zeros();
        let mut z = SVector::<f64, NZ>::zeros();
        let mut r = SVector::<f64, NZ>::zeros();
        for i in 0..2 {
            let row = NZ_FOOT * i;
            let col = 6 + 3 * i;
            for k in 0..3 {
                // EST-2: p_foot − p_b = R fk(q).
                h[(row + k, col + k)] = 1.0;
                h[(row + k, k)] = -1.0;
                z[row + k] = rel[i][k];
                r[row + k] = s.kinematics_noise.powi(2);
                // EST-3: v_b = −R (ω × fk + J q̇) while the foot stays put.
                h[(row + 3 + k, 3 + k)] = 1.0;
                z[row + 3 + k] = base_vel[i][k];
                r[row + 3 + k] = if still[i] {
                    s.velocity_noise.powi(2)
                } else {
                    UNINFORMATIVE
                };
            }
            // EST-4: a stance foot is on the ground (z = 0, the frame's floor).
            h[(row + 6, col + 2)] = 1.0;
            r[row + 6] = if self.stance[i] {
                s.kinematics_noise.powi(2)
            } else {
                UNINFORMATIVE
            };
        }
        let innovation = z - h * self.x;
        let ph = self.p * h.transpose();
        let mut cov = h * ph;
        for k in 0..NZ {
            cov[(k, k)] += r[k];
        }
        let Some(chol) = cov.cholesky() else {
            // Not positive definite: a numerical failure; restart on the next tick.
            self.started = false;
            return f64::INFINITY;
        };
        let sol = chol.solve(&innovation);
        // The stance rows' share of the normalised innovation (a swing row's is ~0 anyway).
        let nis = innovation.dot(&sol);
        // K = P Hᵀ S⁻¹, from S Kᵀ = H P.
        let gain = chol.solve(&ph.transpose()).transpose();
        self.x += gain * innovation;
        // Joseph form: P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ, symmetric and positive.
        let ikh = SMatrix::<f64, NX, NX>::identity() - gain * h;
        let mut krk = gain;
        for k in 0..NZ {
            krk.column_mut(k).scale_mut(r[k]);
        }
        self.p = ikh * self.p * ikh.transpose() + krk * gain.transpose();
        nis
    }

    /// Counts a tick whose measurements disagree with the filter; restarts after a run of them.
    fn judge(
        &mut self,
        nis: f64,
        centre: &Vector3<f64>,
        rel: &[Vector3<f64>; 2],
    ) -> Result<(), EstimatorError> {
        self.last.innovation = nis;
        if nis.is_finite() {
            self.counts.max_innovation = self.counts.max_innovation.max(nis);
        }
        if nis <= self.settings.innovation_limit {
            self.disagreeing_run = 0;
            return Ok(());
        }
        self.counts.disagreeing += 1;
        self.disagreeing_run += 1;
        if self.disagreeing_run < self.settings.divergence_ticks {
            return Ok(());
        }
        // Restart from the kinematics where the base is now believed to be: its height from the
        // feet on the ground, its horizontal position kept.
        let ticks = self.disagreeing_run;
        let (x, y) = (self.x[0], self.x[1]);
        self.start(centre, rel);
        let shift = Vector3::new(x - self.x[0], y - self.x[1], 0.0);
        for b in [0, 6, 9] {
            let mut p = self.x.fixed_rows_mut::<3>(b);
            p += shift;
        }
        self.counts.divergences += 1;
        Err(EstimatorError::Diverged { ticks })
    }

    /// The centre of pressure of the foot wrenches at the soles as the estimate places them
    /// (`foot`: the soles' centres relative to the base; `None` while the feet carry less than
    /// `contact_load` of the weight). A foot's share is its moment about its centre plus its
    /// force at the centre, so a lightly loaded foot adds its sensor's noise over the total
    /// load, not over its own.
    fn centre_of_pressure(
        &self,
        rot: &Matrix3<f64>,
        foot: &[Vector3<f64>; 2],
        sole_rot: &[Matrix3<f64>; 2],
    ) -> Option<[f64; 2]> {
        let p_b = Vector3::new(self.x[0], self.x[1], self.x[2]);
        // The wrenches are finite here (checked on entry): `> 0` keeps what `<= 0` skipped.
        let loads = (0..2).filter(|&i| self.feet[i][2] > 0.0).map(|i| {
            let w = &self.feet[i];
            // On the sole: f_z · (x, y) = (−τ_y, τ_x).
            let moment = Vector3::new(-w[4], w[3], 0.0);
            crate::dynamics::PressureLoad {
                normal: w[2],
                at: p_b + rot * foot[i],
                moment: rot * sole_rot[i] * moment,
            }
        });
        let p = crate::dynamics::center_of_pressure(loads);
        (p.total > self.settings.contact_load * self.weight).then(|| p.point())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::{STATE_FLAG_BASE_UNMEASURED, StateMsg};
    use crate::robot::Robot;

    struct Bench {
        robot: Robot,
        est: BaseEstimator,
        state: Box<StateMsg>,
        q: DVector<f64>,
        v: DVector<f64>,
    }

    /// The embedded robot standing at home, its sensors exact: IMU at rest, each foot carrying
    /// half the weight.
    fn bench() -> Bench {
        let robot = Robot::embedded_default().unwrap();
        let model = &robot.model;
        let ids: [usize; N_CONTACTS] =
            std::array::from_fn(|k| model.frame_id(&robot.contacts[k]).unwrap());
        let weight = robot.derived.mass * 9.81;
        let est = BaseEstimator::new(model, ids, weight, 1e-3, None, EstimatorSettings::default());
        let mut state: Box<StateMsg> = Box::default();
        (state.nq, state.nv) = (model.nq as u32, model.nv as u32);
        state.q[..model.nq].copy_from_slice(robot.home.as_slice());
        state
            .imu_orientation
            .copy_from_slice(&robot.home.as_slice()[3..7]);
        let r = UnitQuaternion::from_quaternion(Quaternion::new(
            robot.home[6],
            robot.home[3],
            robot.home[4],
            robot.home[5],
        ));
        let up = r.inverse() * Vector3::new(0.0, 0.0, 9.81);
        state.imu_linear_acceleration = [up.x, up.y, up.z];
        state.foot_wrenches = [[0.0, 0.0, weight / 2.0, 0.0, 0.0, 0.0]; 2];
        state.flags = STATE_FLAG_BASE_UNMEASURED;
        let (q, v) = (robot.home.clone(), DVector::zeros(model.nv));
        Bench {
            robot,
            est,
            state,
            q,
            v,
        }
    }

    impl Bench {
        /// One tick at step `k` (1 ms each), every sensor sampled then; the joints of the
        /// state as they are.
        fn tick(&mut self, k: u64) -> Result<(), EstimatorError> {
            let t = k as f64 * 1e-3;
            self.tick_stamped(k, [t; 4])
        }

        /// One tick at step `k` whose sensors were sampled at `stamps`.
        fn tick_stamped(&mut self, k: u64, stamps: [f64; 4]) -> Result<(), EstimatorError> {
            self.state.step = k;
            self.state.time = k as f64 * 1e-3;
            self.state.stamps = stamps;
            let (nq, nv) = (self.q.len(), self.v.len());
            self.q.as_mut_slice().copy_from_slice(&self.state.q[..nq]);
            self.v.as_mut_slice().copy_from_slice(&self.state.v[..nv]);
            let mut sensed = RobotState::new(nq, nv);
            crate::control::contract::read_state(&self.state, 0, &mut sensed)
                .expect("the bench's state fits its robot");
            self.est
                .update(&sensed, &sensed.foot_wrenches, &mut self.q, &mut self.v)
        }

        /// The estimate's first `n` coordinates of the configuration are the home pose's.
        fn assert_at_home(&self, n: usize) {
            for i in 0..n {
                assert!(
                    (self.q[i] - self.robot.home[i]).abs() < 1e-6,
                    "q[{i}] {} vs {}",
                    self.q[i],
                    self.robot.home[i]
                );
            }
        }
    }

    /// An IMU in the head, beyond the torso's and the neck's joints, read where it is by the
    /// plant's sensor model (exact): moved back to the base (EST-0), the base's orientation is
    /// the truth at every tick and its angular velocity zero while the neck turns at 0.5 rad/s
    /// (what the gyro reads is the neck's); the estimate stays at home.
    #[test]
    fn an_imu_in_the_head_is_moved_to_the_base() {
        use crate::sim::sensors::{ImuMount, Sensing, Sensors};
        let mut b = bench();
        let model = b.robot.model.clone();
        let head = model.frame_id("head").unwrap();
        let ids: [usize; N_CONTACTS] =
            std::array::from_fn(|k| model.frame_id(&b.robot.contacts[k]).unwrap());
        let weight = b.robot.derived.mass * 9.81;
        b.est = BaseEstimator::new(
            &model,
            ids,
            weight,
            1e-3,
            Some(head),
            EstimatorSettings::default(),
        );
        let mut cfg = crate::sim::SimConfig::load(&[], &[]).unwrap().sensors;
        cfg.sensing = Sensing::Truth;
        let mut sensors = Sensors::new(&cfg, 9.81, Some(ImuMount::new(&model, head)));
        let joint = |name: &str| model.joints[model.joint_id(name).unwrap()].idx_q;
        let (torso, neck) = (joint("torso_pitch"), joint("neck_yaw"));
        let neck_v = model.joints[model.joint_id("neck_yaw").unwrap()].idx_v;
        b.state.q[torso] = 0.2;
        for k in 0..300u64 {
            b.state.q[neck] = 0.1 + 0.5 * k as f64 * 1e-3;
            b.state.v[neck_v] = 0.5;
            b.state.step = k;
            sensors.apply(&mut b.state, 1e-3, &[[0.0; 3]; N_CONTACTS]);
            b.state.foot_wrenches = [[0.0, 0.0, weight / 2.0, 0.0, 0.0, 0.0]; 2];
            b.state.flags = STATE_FLAG_BASE_UNMEASURED;
            let gyro = Vector3::from(b.state.imu_angular_velocity);
            assert!((gyro.norm() - 0.5).abs() < 1e-9, "the head turns: {gyro}");
            b.tick(k).unwrap();
            b.assert_at_home(3 + 4);
            assert!(b.v.rows(3, 3).norm() < 1e-9, "ω_b {}", b.v.rows(3, 3));
        }
        // The neck's own acceleration (centripetal at the IMU) is what EST-0 leaves out: the
        // base velocity it feeds stays small under the legs' correction.
        assert!(b.v.rows(0, 3).norm() < 5e-3, "v_b {}", b.v.rows(0, 3));
    }

    /// Standing still on exact sensors, the estimate is the plants' home pose (the frame's
    /// convention) and stays there, at rest.
    #[test]
    fn standing_still_on_exact_sensors_is_the_home_pose() {
        let mut b = bench();
        for k in 0..500 {
            b.tick(k).unwrap();
        }
        b.assert_at_home(7);
        assert!(b.v.rows(0, 6).norm() < 1e-9, "{}", b.v.rows(0, 6));
        assert_eq!(b.est.last.stance, [true, true]);
        assert!(b.est.counts.max_innovation < 1e-3, "{:?}", b.est.counts);
        // The centre of pressure of two equally loaded feet: between their centres.
        let cop = b.est.cop.unwrap();
        assert!(cop[0].abs() < 1e-6 && cop[1].abs() < 1e-6, "{cop:?}");
    }

    /// An attitude filter off by 2° in roll and pitch: two flat stance feet level it (EST-5)
    /// from the first state on, and a foot rocking on its edge does not.
    #[test]
    fn the_soles_level_a_tilted_imu() {
        let mut b = bench();
        let home = b.state.imu_orientation;
        let truth =
            UnitQuaternion::from_quaternion(Quaternion::new(home[3], home[0], home[1], home[2]));
        let off = UnitQuaternion::from_euler_angles(0.035, -0.035, 0.0) * truth;
        b.state.imu_orientation = [off.i, off.j, off.k, off.w];
        // The world's up in the base frame: the estimate's is the truth's. (A tilt about a
        // horizontal axis composed with the IMU's leaves a yaw of the order of the tilt², 6e-4
        // rad here, which the IMU's yaw drift dwarfs.)
        let up_in_base = |q: &DVector<f64>| {
            let r = UnitQuaternion::from_quaternion(Quaternion::new(q[6], q[3], q[4], q[5]));
            r.inverse() * Vector3::z()
        };
        let up = truth.inverse() * Vector3::z();
        for k in 0..10 {
            b.tick(k).unwrap();
            assert!(
                (up_in_base(&b.q) - up).norm() < 1e-9,
                "{}",
                up_in_base(&b.q)
            );
            assert!((b.q.rows(0, 3) - b.robot.home.rows(0, 3)).norm() < 1e-4);
        }
        // A CoP at a sole's toe: that foot is not flat, the correction holds; a further 1° of
        // the IMU then reads through.
        b.state.foot_wrenches[0][4] = -0.95 * 0.06 * b.state.foot_wrenches[0][2];
        let more = UnitQuaternion::from_euler_angles(0.0175, 0.0, 0.0) * off;
        b.state.imu_orientation = [more.i, more.j, more.k, more.w];
        for k in 10..20 {
            b.tick(k).unwrap();
            let err = (up_in_base(&b.q) - up).norm();
            assert!((err - 0.0175).abs() < 1e-3, "{err}");
        }
        let (roll, pitch, _) = b.est.tilt.euler_angles();
        assert!(
            (roll + 0.035).abs() < 2e-3 && (pitch - 0.035).abs() < 2e-3,
            "{roll} {pitch}"
        );
        // Off: the IMU's attitude as given.
        let mut b2 = bench();
        b2.est.settings.tilt_time = 0.0;
        b2.state.imu_orientation = [off.i, off.j, off.k, off.w];
        b2.tick(0).unwrap();
        let q =
            UnitQuaternion::from_quaternion(Quaternion::new(b2.q[6], b2.q[3], b2.q[4], b2.q[5]));
        assert!((q.angle_to(&truth) - off.angle_to(&truth)).abs() < 1e-9);
    }

    /// A gyro biased by 1e-3 rad/s per axis on a robot at rest (the attitude filter's
    /// orientation unbiased): the estimate's angular velocity loses the bias (EST-6) within the
    /// first samples, and the base stays put; off, the bias reads as a turning base.
    #[test]
    fn the_gyro_bias_is_taken_out_against_the_attitude() {
        for (time, tol) in [(10.0, 1e-9), (0.0, f64::INFINITY)] {
            let mut b = bench();
            b.est.settings.gyro_bias_time = time;
            b.state.imu_angular_velocity = [1e-3, -1e-3, 1e-3];
            for k in 0..1000 {
                b.tick(k).unwrap();
            }
            let w = b.v.rows(3, 3).norm();
            if time > 0.0 {
                assert!(w < tol, "ω_b {w}");
                assert!(b.v.rows(0, 3).norm() < 1e-6, "v_b {}", b.v.rows(0, 3));
                assert!((b.est.gyro_bias[1] + 1e-3).abs() < 1e-9);
            } else {
                assert!((w - 3f64.sqrt() * 1e-3).abs() < 1e-12, "ω_b {w}");
            }
        }
    }

    /// The centre of pressure wandering over two flat, still feet (a robot swaying its weight)
    /// moves their contact points along the soles, not the feet: the base stays where it is.
    #[test]
    fn a_cop_moving_over_still_feet_moves_nothing() {
        let mut b = bench();
        let fz = b.state.foot_wrenches[0][2];
        for k in 0..1000 {
            let x = 0.04 * (k as f64 * 0.01).sin();
            let y = 0.02 * (k as f64 * 0.013).cos();
            for w in b.state.foot_wrenches.iter_mut() {
                (w[3], w[4]) = (y * fz, -x * fz);
            }
            b.tick(k).unwrap();
        }
        b.assert_at_home(3);
        assert!(b.est.counts.max_innovation < 1e-3, "{:?}", b.est.counts);
    }

    /// The first state of a plant carries no contact force yet (nothing stepped): the feet
    /// load from the next one on, their CoP off their centres. The base stays at home.
    #[test]
    fn feet_loading_after_the_first_state_move_nothing() {
        let mut b = bench();
        let fz = b.state.foot_wrenches[0][2];
        b.state.foot_wrenches = [[0.0; 6]; 2];
        b.tick(0).unwrap();
        for w in b.state.foot_wrenches.iter_mut() {
            *w = [0.0, 0.0, fz, 0.01 * fz, 0.03 * fz, 0.0];
        }
        for k in 1..500 {
            b.tick(k).unwrap();
        }
        b.assert_at_home(3);
    }

    /// A lost IMU (its stamp too old) or an invalid one refuses the tick, counted; it resumes
    /// when the samples come back.
    #[test]
    fn a_lost_or_invalid_imu_refuses_the_tick() {
        let mut b = bench();
        b.tick(0).unwrap();
        // The IMU's last sample is 200 ms old.
        let e = b.tick_stamped(300, [0.3, 0.1, 0.3, 0.3]);
        assert!(matches!(e, Err(EstimatorError::ImuLost { .. })), "{e:?}");
        b.state.imu_orientation = [0.0; 4];
        assert!(matches!(b.tick(301), Err(EstimatorError::ImuInvalid)));
        assert_eq!(b.est.counts.imu_lost, 2);
        b.state
            .imu_orientation
            .copy_from_slice(&b.robot.home.as_slice()[3..7]);
        b.tick(302).unwrap();
    }

    /// A foot slipping: the left leg's joints move its foot 1 m/s relative to the base while
    /// the right leg and the IMU say the base is still. The disagreement is detected, and after
    /// `divergence_ticks` the estimate restarts (an error, counted, once per run of them).
    #[test]
    fn a_slipping_foot_is_detected_and_the_estimate_restarted() {
        let mut b = bench();
        for k in 0..20 {
            b.tick(k).unwrap();
        }
        // The first joint of the model after the base: a left-leg joint on the embedded robot
        // (checked: moving it moves the left foot only).
        let j = 7;
        let rate = 1.0;
        let mut diverged = None;
        let mut gated_at = None;
        for k in 20..800 {
            b.state.q[j] += rate * 1e-3;
            b.state.v[j - 1] = rate;
            let r = b.tick(k);
            if b.est.counts.slipping > 0 && gated_at.is_none() {
                gated_at = Some(k);
            }
            if let Err(e) = r {
                diverged = Some((k, e));
                break;
            }
        }
        let (k, e) = diverged.expect("a sliding foot was never detected");
        assert!(matches!(e, EstimatorError::Diverged { ticks: 50 }), "{e:?}");
        // The foot's velocity is gated out within a few ticks (the base keeps to the other
        // foot); its position drifts until the legs disagree, and 50 ticks after that the
        // estimate restarts.
        let gated_at = gated_at.expect("the sliding foot's velocity was never gated");
        assert!(gated_at < 20 + 20, "gated only after {} ms", gated_at - 20);
        assert!(k < 600, "diverged only after {} ms of sliding", k - 20);
        assert_eq!(b.est.counts.divergences, 1);
        assert_eq!(b.est.counts.disagreeing, 50);
        assert!(b.est.counts.max_innovation > EstimatorSettings::default().innovation_limit);
        // After the restart, with the joint still, the ticks agree again (the moved foot is
        // off the floor it is said to stand on: not a perfect agreement).
        b.state.v[j - 1] = 0.0;
        for k in k + 1..k + 51 {
            b.tick(k).unwrap();
        }
        let limit = EstimatorSettings::default().innovation_limit;
        assert!(b.est.last.innovation < limit, "{}", b.est.last.innovation);
    }
}
