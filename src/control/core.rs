//! One control tick, without IPC: robot state and force forecast in, joint torques out.
//!
//! Per tick: kinematics, CoM and the hand's M_e from the model; the hand previewer and C0/C1
//! with the latest gain schedule; the whole-body QP. Allocation-free after construction. The
//! mathematics, and the choices below: docs/preview_control.md, docs/hand_previewer.md,
//! docs/whole_body_qp.md.
//!
//! Choices, written down:
//! - The preview runs on its own grid (period T of `[preview]`, 5 ms) from the measured CoM
//!   position and velocity every control tick (1 kHz); the cart-table acceleration state is the
//!   acceleration commanded at the previous tick (the model's own state, not a noisy estimate).
//! - The CoM acceleration sent to the QP is the plan's acceleration one control period ahead,
//!   ẍ + u·dt; the CoM height is held by a PD.
//! - The ZMP reference and the hand set-point are latched at the first tick: the feet midpoint
//!   (plus the scenario's offset) and the hand's initial position (holding the door closed).
//!   The feet midpoint and the support then follow the sole corners through a low-pass
//!   (`controller.support_follow`), so that creeping feet do not leave the reference behind.
//! - C1 and C2 preview the forecast as corrected by the measured hand force
//!   ([`ForecastCorrector`], on by default); the CoM observer ([`ComObserver`], off by default)
//!   adds the push nothing forecasts, for C0 too (docs/forecast_correction.md).

use nalgebra::{DVector, Matrix3, Vector3};

use super::com_observer::ComObserver;
use super::forecast_correction::{CorrectionEstimate, ForecastCorrector};
use super::forecast_window::ForecastWindow;
use super::gain_thread::StampedSchedule;
use super::viability::ViabilityGuard;
use super::wrist_tare::{WristTare, task_time};
use crate::channels::{MAX_DOF, STATE_FLAG_BASE_UNMEASURED, STATE_FLAG_HOLD, StateMsg};
use crate::config::{Config, ControllerKind, EstimatorMode};
use crate::dynamics::{
    Data, DynamicsError, Model, OpSpaceWorkspace, ReferenceFrame, center_of_mass_velocity,
    frame_velocity,
};
use crate::estimation::{BaseEstimate, BaseEstimator, EstimatorCounts, EstimatorError};
use crate::preview::{
    AxisState, GainSchedule, HandPreviewer, HandState, PreviewError, PreviewPlan, ZmpPreview,
};
use crate::robot::Robot;
use crate::wbc::{FallbackReason, WbcCommand, WbcStatus, WholeBodyController};

/// Errors of a tick: the state message does not fit the model.
#[derive(Debug, Clone, thiserror::Error)]
pub enum TickError {
    #[error(
        "state has nq = {nq}, nv = {nv}; the model needs {model_nq}, {model_nv} (a state holds at most {MAX_DOF} each)"
    )]
    Dimensions {
        nq: u32,
        nv: u32,
        model_nq: usize,
        model_nv: usize,
    },
    #[error("state is not finite")]
    NotFinite,
    #[error(
        "the plant runs another robot (robot hash {plant:016x}, this controller's {mine:016x}): start both with the same --robot"
    )]
    Robot { plant: u64, mine: u64 },
    #[error("dynamics: {0}")]
    Dynamics(#[from] DynamicsError),
    #[error("base estimator: {0}")]
    Estimator(#[from] EstimatorError),
    #[error(
        "the plant does not measure its floating base (its states carry STATE_FLAG_BASE_UNMEASURED) and controller.estimator.mode = \"off\": set it to \"auto\" (or run `upc controller --sensing realistic`)"
    )]
    BaseUnmeasured,
}

/// What one tick produced, for logging and the summary.
#[derive(Debug, Clone, Copy, Default)]
pub struct TickRecord {
    pub time: f64,
    pub com: [f64; 3],
    pub com_vel: [f64; 3],
    pub com_acc_cmd: [f64; 3],
    pub zmp_ref: [f64; 2],
    /// ZMP the preview predicts for the next preview step.
    pub zmp_pred: [f64; 2],
    /// Measured ZMP: the state's, or the base estimator's from the foot wrenches when it runs.
    pub zmp_meas: [f64; 2],
    pub hand_pos: [f64; 3],
    pub hand_err: f64,
    pub kp: f64,
    pub kd: f64,
    /// F_dis forecast at the first preview step and the hand force forecast there.
    pub f_dis: [f64; 3],
    pub f_ext: [f64; 3],
    pub wbc_solved: bool,
    pub wbc_iterations: u32,
    pub wbc_time: f64,
    /// The preview fell back to C0 this tick (invalid disturbance forecast).
    pub preview_fallback: bool,
    pub schedule_age: f64,
    /// Support rectangle (latched at the first tick, then following the feet), [[x_min, x_max],
    /// [y_min, y_max]] (world frame), so that logs can draw the ZMP against it.
    pub support: [[f64; 2]; 2],
    /// The hand force measured this tick, and the forecast as received for the first preview
    /// step (`f_ext` is the forecast the previewer used: corrected, when the correction is on).
    pub f_meas: [f64; 3],
    pub f_raw: [f64; 3],
    /// The forecast correction's estimate (κ̂, τ̂, d̂; default when off or C0).
    pub correction: CorrectionEstimate,
    /// The CoM observer's force (N, x and y; zero when off).
    pub f_obs: [f64; 2],
    /// The capture-point guard's scale of the forecast's unmeasured part (x, y; 1 when off or
    /// not fading) and the capture point under the measured force (m; NaN when off).
    pub viability_scale: [f64; 2],
    pub capture_point: [f64; 2],
    /// The robot is fallen: this tick held joint damping, without preview or QP.
    pub fallen: bool,
    /// The base estimator's estimate, when it ran this tick.
    pub base: Option<BaseEstimate>,
}

/// The controller's state between ticks.
pub struct ControllerCore {
    pub model: Model,
    data: Data,
    op: OpSpaceWorkspace,
    wbc: WholeBodyController,
    zmp: ZmpPreview,
    previewer: HandPreviewer,
    pub kind: ControllerKind,
    hand_frame: usize,
    /// Content hash of the robot this controller was built for (0: not checked).
    robot_hash: u64,
    horizon: usize,
    period: f64,
    dt: f64,
    height_gains: [f64; 2],
    /// Feed the measured hand force to the whole-body QP (`controller.hand_force_feedback`).
    force_feedback: bool,
    /// `hand.stiffness = "decoupled"`: the projector P = e eᵀ onto the held object's free
    /// direction (from its apparent mass, [`Self::with_held_mass`]); `None`: eq. (17) as is.
    hand_free_dir: Option<Matrix3<f64>>,
    decoupled_stiffness: bool,
    /// The wrist sensor's offset, removed from every measured hand force used.
    tare: WristTare,
    q: DVector<f64>,
    v: DVector<f64>,
    zmp_ref: Vec<[f64; 2]>,
    hand_desired: Vec<HandState>,
    f_ext: Vec<[f64; 3]>,
    nominal: GainSchedule,
    schedule: GainSchedule,
    plan: PreviewPlan,
    /// The cart-table state the last tick solved from (to roll its plan out on demand).
    last_x: [AxisState; 2],
    com_acc_cmd: Vector3<f64>,
    hand_acc_cmd: Vector3<f64>,
    latched: Option<Latched>,
    zmp_offset: [f64; 2],
    /// The forecast corrected by the measured hand force (C1, C2), when on.
    correction: Option<ForecastCorrector>,
    /// The capture-point guard on the forecast's unmeasured part (C1, C2 with the correction).
    viability: Option<ViabilityGuard>,
    /// The CoM disturbance observer, when on, and the total CoM disturbance horizon it adds to.
    observer: Option<ComObserver>,
    f_dis_total: Vec<[f64; 3]>,
    /// Ticks where the disturbance forecast was invalid and C0 ran instead.
    pub preview_fallbacks: u64,
    /// The fall detector: the drop (fraction of the latched CoM height) that means a fall
    /// (0: off), the joint damping held then, whether the robot is fallen in this session, the
    /// falls detected and the ticks held fallen.
    fall_drop: f64,
    /// Time constant (s) of the support's following of the feet; 0: latched.
    support_follow: f64,
    fallen_damping: f64,
    fallen: bool,
    pub falls: u64,
    pub fallen_ticks: u64,
    /// The floating-base estimator and when it runs (`controller.estimator`).
    estimator: BaseEstimator,
    estimator_mode: EstimatorMode,
    /// The estimator ran on the last state.
    estimating: bool,
    pub last: TickRecord,
}

#[derive(Debug, Clone, Copy)]
struct Latched {
    zmp_center: [f64; 2],
    /// Axis-aligned support rectangle of the sole corners, [[x_min, x_max], [y_min, y_max]].
    support: [[f64; 2]; 2],
    com_height: f64,
    hand_target: Vector3<f64>,
}

impl ControllerCore {
    /// The controller of `robot`: its model (whole-body dynamics), its reduced models
    /// ([`Robot::reduced`]: the preview's cart-table) and its frames.
    pub fn new(
        robot: &Robot,
        config: &Config,
        kind: ControllerKind,
        control_period: f64,
        height_gains: [f64; 2],
        zmp_offset: [f64; 2],
    ) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        // One gravity for the controller: the cart-table's, the forecast window's weight and
        // the whole-body dynamics' (RNEA, the QP) are all `robot.gravity` of the config.
        let mut model = robot.model.clone();
        model.gravity = nalgebra::Vector3::new(0.0, 0.0, -config.robot.gravity);
        let p = &config.preview;
        let n = p.horizon;
        // The reduced model's parameters have one home, the robot's (computed from its model),
        // read alike by the preview, the observer and C2's search; the whole-body QP uses the
        // model's inertia.
        let cart = robot.reduced().cart_table(p.period, config.robot.gravity);
        let frames = robot.frames();
        let op = OpSpaceWorkspace::new(&model, &frames.hand_chain_root, &frames.hand)?;
        let wbc = WholeBodyController::new(&model, &config.wbc, &frames)?;
        let hand_frame = model.frame_id(&frames.hand)?;
        let nominal = GainSchedule::constant(n, config.hand.kp, config.nominal_kd(config.hand.kp));
        let cc = &config.controller;
        let correction =
            (cc.forecast_correction.enabled && kind != ControllerKind::C0).then(|| {
                let weight = cart.mass * cart.gravity;
                ForecastCorrector::new(cc.forecast_correction, p.period, control_period, weight)
            });
        let viability = (correction.is_some() && cc.viability.enabled)
            .then(|| ViabilityGuard::new(cc.viability, cart.mass, cart.gravity, cart.com_height));
        let observer = cc.com_observer.enabled.then(|| {
            ComObserver::new(
                cc.com_observer,
                cart.mass,
                cart.gravity,
                cart.com_height,
                control_period,
            )
        });
        let estimator = BaseEstimator::new(
            &model,
            wbc.contact_frames(),
            cart.mass * cart.gravity,
            control_period,
            robot.imu_frame,
            cc.estimator,
        );
        Ok(Self {
            data: Data::new(&model),
            q: DVector::zeros(model.nq),
            v: DVector::zeros(model.nv),
            op,
            wbc,
            zmp: ZmpPreview::new(cart, p.q_e, p.r, n, crate::config::LqSolverKind::Riccati),
            previewer: HandPreviewer::new(p.period, Matrix3::identity(), n)?,
            kind,
            hand_frame,
            robot_hash: 0,
            horizon: n,
            period: p.period,
            dt: control_period,
            height_gains,
            force_feedback: config.controller.hand_force_feedback,
            hand_free_dir: None,
            decoupled_stiffness: config.hand.stiffness == crate::config::HandStiffness::Decoupled,
            tare: WristTare::new(config.controller.wrist_tare),
            zmp_ref: vec![[0.0; 2]; n],
            hand_desired: vec![HandState::default(); n],
            f_ext: vec![[0.0; 3]; n],
            schedule: nominal.clone(),
            nominal,
            plan: PreviewPlan::with_capacity(n),
            last_x: [Vector3::zeros(); 2],
            com_acc_cmd: Vector3::zeros(),
            hand_acc_cmd: Vector3::zeros(),
            latched: None,
            zmp_offset,
            correction,
            viability,
            observer,
            f_dis_total: vec![[0.0; 3]; n],
            preview_fallbacks: 0,
            fall_drop: config.controller.fall_drop,
            support_follow: config.controller.support_follow,
            fallen_damping: config.wbc.fallback_damping,
            fallen: false,
            falls: 0,
            fallen_ticks: 0,
            estimator,
            estimator_mode: cc.estimator.mode,
            estimating: false,
            last: TickRecord::default(),
            model,
        })
    }

    /// Refuse states whose `robot_hash` announces another robot than `hash`
    /// ([`crate::robot::Robot::hash`]).
    pub fn with_robot_hash(mut self, hash: u64) -> Self {
        self.robot_hash = hash;
        self
    }

    /// The held object's apparent mass at the hand (world, kg; [`crate::sim::scene::PlacedDoor::apparent_mass`]),
    /// taken out of the measured hand force by the forecast correction (FC-1).
    pub fn with_held_mass(mut self, held_mass: Matrix3<f64>) -> Self {
        let rows = [0, 1, 2].map(|r| [0, 1, 2].map(|c| held_mass[(r, c)]));
        self.correction = self.correction.map(|c| c.with_held_mass(rows));
        // A door's apparent mass is m e eᵀ: its trace is m, and it over m projects onto e.
        let m = held_mass.trace();
        self.hand_free_dir =
            (m.is_finite() && m > 0.0 && self.decoupled_stiffness).then(|| held_mass / m);
        self
    }

    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The whole-body controller's counters (solves, torque-limited ticks, fallbacks).
    pub fn wbc_counters(&self) -> crate::wbc::WbcCounters {
        self.wbc.counters()
    }

    /// The support rectangle (latched at the first tick, then following the feet),
    /// [[x_min, x_max], [y_min, y_max]].
    pub fn support(&self) -> Option<[[f64; 2]; 2]> {
        self.latched.map(|l| l.support)
    }

    /// Forget the latched references and the commands carried between ticks, so the next tick
    /// latches again from its state as a first tick does: for a restarted simulator, whose robot
    /// starts over from its initial posture. The whole-body QP's posture reference (its root
    /// orientation is the base-orientation target) is latched again too. Allocation-free.
    pub fn reset(&mut self) {
        self.latched = None;
        self.fallen = false;
        self.wbc.reset();
        self.com_acc_cmd = Vector3::zeros();
        self.hand_acc_cmd = Vector3::zeros();
        self.tare.reset();
        self.last_x = [Vector3::zeros(); 2];
        self.last = TickRecord::default();
        if let Some(c) = self.correction.as_mut() {
            c.reset();
        }
        if let Some(o) = self.observer.as_mut() {
            o.reset();
        }
        if let Some(g) = self.viability.as_mut() {
            g.reset();
        }
        self.estimator.reset();
    }

    /// The wrist sensor's tare (its offset, its refusals).
    pub fn wrist_tare(&self) -> &WristTare {
        &self.tare
    }

    /// The base estimator's counters (`None` when it never ran).
    pub fn estimator_counts(&self) -> Option<EstimatorCounts> {
        (self.estimator.counts.ticks > 0).then_some(self.estimator.counts)
    }

    /// The capture-point guard's counters (`None` when it is off).
    pub fn viability_counts(&self) -> Option<super::viability::ViabilityCounts> {
        self.viability.as_ref().map(|g| g.counts)
    }

    /// The forecast correction's counters (`None` when it is off).
    pub fn correction_counts(&self) -> Option<super::forecast_correction::CorrectionCounts> {
        self.correction.as_ref().map(|c| c.counts)
    }

    /// Roll out the last tick's predicted horizon and copy it into a log record.
    pub fn fill_plan(&mut self, out: &mut super::logger::PlanLog) {
        self.zmp.plan(&self.last_x, &mut self.plan);
        out.time = self.last.time;
        out.com_height = self.latched.map_or(0.0, |l| l.com_height);
        for i in 0..self.horizon.min(out.zmp.len()) {
            out.zmp[i] = [self.plan.zmp[0][i] as f32, self.plan.zmp[1][i] as f32];
            out.com[i] = [self.plan.com[0][i][0] as f32, self.plan.com[1][i][0] as f32];
            out.kp[i] = self.schedule.kp[i] as f32;
            out.f_dis[i] = if self.kind == ControllerKind::C0 {
                0.0
            } else {
                self.previewer
                    .disturbance()
                    .get(i)
                    .map_or(0.0, |f| f[0] as f32)
            };
        }
    }

    /// The CoM and hand state of the last tick, the M_e and the forecast, as C2's snapshot.
    pub fn snapshot(&self, out: &mut super::gain_thread::GainSnapshot, seq: u64) {
        out.time = self.last.time;
        out.seq = seq;
        out.com = [0, 1]
            .map(|a| Vector3::new(self.last.com[a], self.last.com_vel[a], self.com_acc_cmd[a]));
        out.hand = HandState {
            pos: Vector3::from(self.last.hand_pos),
            vel: self.hand_vel(),
            acc: self.hand_acc_cmd,
        };
        out.m_e = *self.previewer.effective_mass();
        out.zmp_ref.copy_from_slice(&self.zmp_ref);
        out.hand_desired.copy_from_slice(&self.hand_desired);
        out.f_ext.copy_from_slice(&self.f_ext);
        out.applied = [self.last.kp, self.last.kd];
    }

    fn hand_vel(&self) -> Vector3<f64> {
        frame_velocity(
            &self.model,
            &self.data,
            self.hand_frame,
            ReferenceFrame::LocalWorldAligned,
        )
        .lin
    }

    /// One tick: read the state → model quantities → horizon inputs (forecast corrected,
    /// observer) → gain schedule → preview (C0 / C1 on the CoM) → whole-body QP → record.
    /// `tau` receives the actuated torques (length nv − 6). Returns the WBC status.
    pub fn tick(
        &mut self,
        state: &StateMsg,
        forecast: &ForecastWindow,
        c2: Option<&StampedSchedule>,
        tau: &mut [f64],
    ) -> Result<WbcStatus, TickError> {
        self.read_state(state)?;
        let t = state.time;
        // Model quantities: CoM (with velocity), hand placement and velocity, M_e.
        let (com, vcom) = center_of_mass_velocity(&self.model, &mut self.data, &self.q, &self.v)?;
        let hand = HandState {
            pos: self.data.o_m_f[self.hand_frame].trans,
            vel: self.hand_vel(),
            acc: self.hand_acc_cmd,
        };
        let latched = self.latch(com.z, hand.pos);
        if self.detect_fall(t, latched.com_height - com.z, latched.com_height) {
            return Ok(self.hold_fallen(state, [com, vcom], &hand, &latched, tau));
        }
        let m_e = *self.op.compute(&self.model, &mut self.data, &self.q)?;
        let m_e_ok = self.previewer.set_effective_mass(m_e).is_ok();

        let held = state.flags & STATE_FLAG_HOLD != 0;
        let f_meas = self.tare.apply(
            task_time(t, state.scenario_hash, state.scenario_start),
            state.hand_force,
            forecast.at(t),
            hand.vel.norm(),
            held,
            self.dt,
        );
        let zref = self.horizon_inputs(t, &latched, forecast, f_meas, hand.vel.into());
        if let (Some(g), Some(c)) = (self.viability.as_mut(), self.correction.as_ref()) {
            let push = c.measured_push();
            g.apply(
                t,
                [com.x, com.y],
                [vcom.x, vcom.y],
                latched.support,
                push,
                &mut self.f_ext,
            );
        }
        let zmp_meas = self.measured_zmp(state);
        let f_obs = self.observe([com.x, com.y], [vcom.x, vcom.y], zmp_meas);
        let age = self.take_schedule(t, c2);
        let x: [AxisState; 2] = [0, 1].map(|a| Vector3::new(com[a], vcom[a], self.com_acc_cmd[a]));
        let (u, fallback) = self.preview(&x, &hand, m_e_ok, f_obs);
        for a in 0..2 {
            self.com_acc_cmd[a] += u[a] * self.dt;
        }
        let [kpz, kdz] = self.height_gains;
        self.com_acc_cmd.z = kpz * (latched.com_height - com.z) - kdz * vcom.z;
        let (status, iterations, wbc_time) = self.whole_body(f_meas, &latched, &hand, m_e_ok, tau);

        // The ZMP one preview step ahead, for the logs: O(1). The whole plan is rolled out
        // only when a log record asks for it (`fill_plan`), off the per-tick path.
        let zmp_pred = self.zmp.next_zmp(&x, u);
        self.last_x = x;
        let f_dis = if self.kind == ControllerKind::C0 {
            [0.0; 3]
        } else {
            self.previewer
                .disturbance()
                .first()
                .copied()
                .unwrap_or([0.0; 3])
        };
        let (kp, kd) = (self.schedule.kp[0], self.schedule.kd[0]);
        self.last = TickRecord {
            time: t,
            com: com.into(),
            com_vel: vcom.into(),
            com_acc_cmd: self.com_acc_cmd.into(),
            zmp_ref: zref,
            zmp_pred,
            zmp_meas,
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            kp,
            kd,
            f_dis,
            f_ext: self.f_ext[0],
            wbc_solved: status == WbcStatus::Solved,
            wbc_iterations: iterations,
            wbc_time,
            preview_fallback: fallback,
            schedule_age: age,
            support: latched.support,
            f_meas,
            f_raw: forecast.at(t + self.period),
            correction: self
                .correction
                .as_ref()
                .map(|c| *c.estimate())
                .unwrap_or_default(),
            f_obs,
            viability_scale: self.viability.as_ref().map_or([1.0; 2], |g| g.last_scale),
            capture_point: self
                .viability
                .as_ref()
                .map_or([f64::NAN; 2], |g| g.last_capture),
            fallen: false,
            base: self.estimating.then_some(self.estimator.last),
        };
        Ok(status)
    }

    /// Whether the robot is fallen: its CoM `drop` (m) below the height latched at the
    /// session's start is more than `fall_drop` of that height. Once fallen, fallen until the
    /// plant restarts ([`Self::reset`]): a fallen humanoid does not stand up by itself, and its
    /// QP (contacts that no longer hold) is mostly infeasible and costly to try.
    fn detect_fall(&mut self, t: f64, drop: f64, height: f64) -> bool {
        if !self.fallen && self.fall_drop > 0.0 && drop > self.fall_drop * height {
            self.fallen = true;
            self.falls += 1;
            tracing::error!(
                "the robot has fallen at t = {t:.3} s (CoM {:.0} mm below its height of {:.0} mm): \
                 joint damping, no balance control, until the plant restarts",
                drop * 1e3,
                height * 1e3
            );
        }
        self.fallen
    }

    /// A fallen robot's tick: joint damping toward rest (`wbc.fallback_damping`), no preview,
    /// no QP; the record keeps what was measured.
    fn hold_fallen(
        &mut self,
        state: &StateMsg,
        [com, vcom]: [Vector3<f64>; 2],
        hand: &HandState,
        latched: &Latched,
        tau: &mut [f64],
    ) -> WbcStatus {
        self.fallen_ticks += 1;
        for (t, v) in tau.iter_mut().zip(self.v.iter().skip(6)) {
            *t = -self.fallen_damping * v;
        }
        self.last = TickRecord {
            time: state.time,
            com: com.into(),
            com_vel: vcom.into(),
            zmp_meas: self.measured_zmp(state),
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            support: latched.support,
            f_meas: {
                let b = self.tare.offset();
                [0, 1, 2].map(|k| state.hand_force[k] - b[k])
            },
            fallen: true,
            base: self.estimating.then_some(self.estimator.last),
            viability_scale: [1.0; 2],
            capture_point: [f64::NAN; 2],
            ..TickRecord::default()
        };
        WbcStatus::Fallback(FallbackReason::Fallen)
    }

    /// Checks the state against the model (sizes, robot, finiteness) and copies q and v.
    fn read_state(&mut self, state: &StateMsg) -> Result<(), TickError> {
        let (nq, nv) = (self.model.nq, self.model.nv);
        // The message's arrays hold MAX_DOF values: a size beyond them is refused before any
        // slice by it (a model larger than the message would otherwise match it).
        let fits = |n: u32| n as usize <= MAX_DOF;
        if !fits(state.nq) || !fits(state.nv) || state.nq as usize != nq || state.nv as usize != nv
        {
            return Err(TickError::Dimensions {
                nq: state.nq,
                nv: state.nv,
                model_nq: nq,
                model_nv: nv,
            });
        }
        if state.robot_hash != 0 && self.robot_hash != 0 && state.robot_hash != self.robot_hash {
            return Err(TickError::Robot {
                plant: state.robot_hash,
                mine: self.robot_hash,
            });
        }
        let unmeasured = state.flags & STATE_FLAG_BASE_UNMEASURED != 0;
        self.estimating = match self.estimator_mode {
            EstimatorMode::On => true,
            EstimatorMode::Auto => unmeasured,
            EstimatorMode::Off if unmeasured => return Err(TickError::BaseUnmeasured),
            EstimatorMode::Off => false,
        };
        // An estimated base is NaN in the state: its coordinates are checked once estimated.
        let (base_q, base_v) = if self.estimating { (7, 6) } else { (0, 0) };
        if !state.q[base_q..nq]
            .iter()
            .chain(&state.v[base_v..nv])
            .all(|x| x.is_finite())
        {
            return Err(TickError::NotFinite);
        }
        self.q.as_mut_slice().copy_from_slice(&state.q[..nq]);
        self.v.as_mut_slice().copy_from_slice(&state.v[..nv]);
        if self.estimating {
            self.estimator.update(state, &mut self.q, &mut self.v)?;
        }
        Ok(())
    }

    /// The measured centre of pressure: from the foot wrenches at the estimated soles when the
    /// base is estimated (as a robot computes it), the state's otherwise.
    fn measured_zmp(&self, state: &StateMsg) -> [f64; 2] {
        match self.estimator.cop {
            Some(cop) if self.estimating => cop,
            _ => state.zmp,
        }
    }

    /// The support rectangle of the sole corners where the state puts them,
    /// [[x_min, x_max], [y_min, y_max]], and the corners' centroid (the feet centre; the sole
    /// frames' midpoint on robots whose sole frame is off the sole's centre).
    fn support_now(&self) -> ([[f64; 2]; 2], [f64; 2]) {
        let mut support = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
        let mut centre = [0.0; 2];
        let corners = self.wbc.contact_frames();
        for f in corners {
            let p = self.data.o_m_f[f].trans;
            for a in 0..2 {
                support[a] = [support[a][0].min(p[a]), support[a][1].max(p[a])];
                centre[a] += p[a] / corners.len() as f64;
            }
        }
        (support, centre)
    }

    /// The references latched at the first tick of a session: the support and the ZMP
    /// reference's centre, the CoM height, the hand target. The support and the centre then
    /// follow the corners as measured (`controller.support_follow`): a foot that creeps or slips
    /// takes the reference with it, where a latched one would be left behind at the support's
    /// edge (MuJoCo's feet creep ~0.2 mm a push; an hour of pushes moves them by centimetres).
    fn latch(&mut self, com_height: f64, hand_pos: Vector3<f64>) -> Latched {
        let (support, centre) = self.support_now();
        let alpha = if self.support_follow > 0.0 {
            (self.dt / self.support_follow).min(1.0)
        } else {
            0.0
        };
        let l = self.latched.get_or_insert(Latched {
            zmp_center: centre,
            support,
            com_height,
            hand_target: hand_pos,
        });
        for a in 0..2 {
            l.zmp_center[a] += alpha * (centre[a] - l.zmp_center[a]);
            for b in 0..2 {
                l.support[a][b] += alpha * (support[a][b] - l.support[a][b]);
            }
        }
        *l
    }

    /// The horizon's inputs at t + (i+1)·T: ZMP reference, hand set-point and the hand force
    /// (the forecast, corrected by the measured force `f_meas` with the hand moving at
    /// `hand_vel`). Returns the ZMP reference.
    fn horizon_inputs(
        &mut self,
        t: f64,
        latched: &Latched,
        forecast: &ForecastWindow,
        f_meas: [f64; 3],
        hand_vel: [f64; 3],
    ) -> [f64; 2] {
        let zref = [
            latched.zmp_center[0] + self.zmp_offset[0],
            latched.zmp_center[1] + self.zmp_offset[1],
        ];
        let target = HandState {
            pos: latched.hand_target,
            ..Default::default()
        };
        for i in 0..self.horizon {
            self.zmp_ref[i] = zref;
            self.hand_desired[i] = target;
        }
        // The hand force over the horizon: the forecast, corrected by the measured force.
        match self.correction.as_mut() {
            Some(c) => {
                c.update(t, forecast, Some(f_meas), hand_vel);
                c.fill(t, self.period, forecast, &mut self.f_ext);
            }
            None => {
                for i in 0..self.horizon {
                    self.f_ext[i] = forecast.at(t + (i + 1) as f64 * self.period);
                }
            }
        }
        zref
    }

    /// The CoM observer, against the disturbance the preview modelled at the last tick.
    fn observe(&mut self, com: [f64; 2], vcom: [f64; 2], zmp: [f64; 2]) -> [f64; 2] {
        match self.observer.as_mut() {
            Some(o) => {
                let known = if self.kind == ControllerKind::C0 {
                    [0.0; 2]
                } else {
                    [self.last.f_dis[0], self.last.f_dis[1]]
                };
                o.update(com, vcom, zmp, known);
                o.force()
            }
            None => [0.0; 2],
        }
    }

    /// The gain schedule: C2's, shifted to now, or the nominal one. Returns C2's age (s).
    fn take_schedule(&mut self, t: f64, c2: Option<&StampedSchedule>) -> f64 {
        let mut age = 0.0;
        match c2.filter(|s| s.seq > 0 && self.kind == ControllerKind::C2) {
            Some(s) => {
                age = t - s.time;
                let shift = (age / self.period).round().max(0.0) as usize;
                let n = self.horizon;
                for i in 0..n {
                    let j = (i + shift).min(n - 1);
                    self.schedule.kp[i] = s.schedule.kp[j];
                    self.schedule.kd[i] = s.schedule.kd[j];
                }
            }
            None => {
                self.schedule.kp.copy_from_slice(&self.nominal.kp);
                self.schedule.kd.copy_from_slice(&self.nominal.kd);
            }
        }

        age
    }

    /// C0 / C1 on the CoM: the jerk u of each axis, and whether C1 fell back to C0.
    fn preview(
        &mut self,
        x: &[AxisState; 2],
        hand: &HandState,
        m_e_ok: bool,
        f_obs: [f64; 2],
    ) -> ([f64; 2], bool) {
        let mut fallback = false;
        let observed = self.observer.as_ref().map(|o| {
            let decay = (-self.period / o.settings().decay).exp();
            (f_obs, decay)
        });
        // Σ: F_dis (C1, C2; zero for C0) plus the observer's force decaying over the horizon.
        let add_observed =
            |base: &[[f64; 3]], out: &mut [[f64; 3]], (f, decay): ([f64; 2], f64)| {
                let mut w = 1.0;
                for (i, o) in out.iter_mut().enumerate() {
                    w *= decay;
                    let b = base.get(i).copied().unwrap_or([0.0; 3]);
                    *o = [b[0] + f[0] * w, b[1] + f[1] * w, b[2]];
                }
            };
        let u = match self.kind {
            ControllerKind::C0 => match observed {
                Some(obs) => {
                    add_observed(&[], &mut self.f_dis_total, obs);
                    self.zmp
                        .solve_c1(x, &self.zmp_ref, &self.f_dis_total)
                        .or_else(|_| self.zmp.solve_c0(x, &self.zmp_ref))
                }
                None => self.zmp.solve_c0(x, &self.zmp_ref),
            },
            ControllerKind::C1 | ControllerKind::C2 => {
                let r: Result<[f64; 2], PreviewError> = if m_e_ok {
                    self.previewer
                        .predict(
                            hand,
                            &self.hand_desired,
                            &self.schedule,
                            &self.f_ext,
                            self.horizon,
                        )
                        .and_then(|()| match observed {
                            Some(obs) => {
                                add_observed(
                                    self.previewer.disturbance(),
                                    &mut self.f_dis_total,
                                    obs,
                                );
                                self.zmp.solve_c1(x, &self.zmp_ref, &self.f_dis_total)
                            }
                            None => {
                                self.zmp
                                    .solve_c1(x, &self.zmp_ref, self.previewer.disturbance())
                            }
                        })
                } else {
                    Err(PreviewError::EffectiveMassNotSpd)
                };
                r.or_else(|_| {
                    fallback = true;
                    self.zmp.solve_c0(x, &self.zmp_ref)
                })
            }
        };
        // solve_c0 only fails on non-finite state, excluded above; keep the last command then.
        let u = u.unwrap_or([0.0; 2]);
        if fallback {
            self.preview_fallbacks += 1;
        }
        (u, fallback)
    }

    /// The whole-body QP for the tick's CoM acceleration and hand impedance law; the torques in
    /// `tau`. Returns the status, the solver's iterations and the QP's time (s).
    fn whole_body(
        &mut self,
        f_meas: [f64; 3],
        latched: &Latched,
        hand: &HandState,
        m_e_ok: bool,
        tau: &mut [f64],
    ) -> (WbcStatus, u32, f64) {
        let (kp, kd) = (self.schedule.kp[0], self.schedule.kd[0]);
        // The measured hand force, when fed back: the QP's equations of motion account for it
        // and the hand task asks for the impedance law's own response to it, eq. (23):
        // M_e ẍ = F_ext + M_e ẍ_cmd, i.e. ẍ = ẍ_cmd + M_e⁻¹ F_ext. Without it the QP ignores the
        // force, which then folds the arm's lightest joints instead of acting through M_e.
        let f_hand = Vector3::from(f_meas);
        // Only a force the tare vouches for (not while it is taken, nor after a refused one).
        let fed_back =
            self.force_feedback && self.tare.trusted() && f_hand.iter().all(|x| x.is_finite());
        let f_hand = if fed_back { f_hand } else { Vector3::zeros() };
        let acc_ext = if m_e_ok {
            self.op.lambda_inv * f_hand
        } else {
            Vector3::zeros()
        };
        let law = (latched.hand_target - hand.pos) * kp - hand.vel * kd;
        // `hand.stiffness = "decoupled"`: the arm's force M_d ẍ_law with M_d = P M_e P + Q M_e Q
        // instead of M_e ẍ_law, i.e. ẍ = M_e⁻¹ M_d ẍ_law; the QP's own law is corrected through
        // its acceleration feed-forward.
        let coupling = match self.hand_free_dir {
            Some(p) if m_e_ok => {
                let q = Matrix3::identity() - p;
                let m_e = self.op.m_e;
                self.op.lambda_inv * (p * m_e * p + q * m_e * q) * law - law
            }
            _ => Vector3::zeros(),
        };
        self.hand_acc_cmd = law + coupling + acc_ext;

        // Whole-body QP.
        let cmd = WbcCommand {
            com_acc: self.com_acc_cmd,
            hand_pos_des: latched.hand_target,
            hand_vel_des: Vector3::zeros(),
            hand_acc_des: acc_ext + coupling,
            kp,
            kd,
            hand_force: f_hand,
            posture_ref: None,
        };
        let out = self
            .wbc
            .solve(&self.model, &mut self.data, &self.q, &self.v, &cmd);
        let n = out.tau.len().min(tau.len());
        tau[..n].copy_from_slice(&out.tau.as_slice()[..n]);
        (out.status, out.iterations, out.tick_time.as_secs_f64())
    }
}
