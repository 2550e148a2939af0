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
//! - Those, the base estimator and the wrist tare are the controller's parts (`super::parts`):
//!   the tick runs them at their stages; the state is read from the contract once
//!   (`super::contract`), and the tick and the parts work on the [`RobotState`].

use nalgebra::{Matrix3, Vector3};

use super::TickRecord;
use super::forecast_window::ForecastWindow;
use super::gain_thread::StampedSchedule;
use super::parts::{self, ControllerPart, PartSetup, Stage, TickFrame, TickInputs};
use crate::channels::{MAX_DOF, StateMsg};
use crate::config::{Config, ControllerKind, HandForceSource};
use crate::dynamics::{
    Data, DynamicsError, Model, OpSpaceWorkspace, ReferenceFrame, center_of_mass_velocity,
    frame_velocity,
};
use crate::estimation::EstimatorError;
use crate::preview::{
    AxisState, GainSchedule, HandPreviewer, HandState, PreviewError, PreviewPlan, ZmpPreview,
};
use crate::record::Record;
use crate::robot::{Robot, RobotState};
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
    /// Which hand force (`controller.hand_force_feedback_from`).
    force_source: HandForceSource,
    /// `hand.stiffness = "decoupled"`: the projector P = e eᵀ onto the held object's free
    /// direction (from its apparent mass, [`Self::with_held_mass`]); `None`: eq. (17) as is.
    hand_free_dir: Option<Matrix3<f64>>,
    /// The held object's apparent mass at the hand Λ (world, kg; zero: nothing held).
    held_mass: Matrix3<f64>,
    decoupled_stiffness: bool,
    /// `hand.held_path`: how the previewer (and C2's) keeps the hand on the held object's path
    /// (HP-1), and that path once known ([`Self::with_held_mass`]).
    held_path_mode: crate::config::HeldPath,
    held_path: Option<(Vector3<f64>, f64)>,
    /// The held object's free direction e, whatever `hand.held_path` (FC-0b).
    door_path: Option<Vector3<f64>>,
    /// The robot as measured this tick (read from the contract once), the tick's shared
    /// quantities and the parts that work on them (`super::parts`).
    sensed: RobotState,
    frame: TickFrame,
    parts: Vec<Box<dyn ControllerPart>>,
    zmp_ref: Vec<[f64; 2]>,
    hand_desired: Vec<HandState>,
    nominal: GainSchedule,
    schedule: GainSchedule,
    plan: PreviewPlan,
    /// The cart-table state the last tick solved from (to roll its plan out on demand).
    last_x: [AxisState; 2],
    com_acc_cmd: Vector3<f64>,
    hand_acc_cmd: Vector3<f64>,
    latched: Option<Latched>,
    zmp_offset: [f64; 2],
    f_dis_total: Vec<[f64; 3]>,
    /// Ticks where the disturbance forecast was invalid and C0 ran instead.
    pub preview_fallbacks: u64,
    /// Ticks the QP was given the held object's modelled force ([`held_object_force`]).
    pub hand_force_modelled_ticks: u64,
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
        let mut zmp = ZmpPreview::new(cart, p.q_e, p.r, n, crate::config::LqSolverKind::Riccati)
            .with_terminal_cost(p.terminal_cost);
        zmp.check_holds_the_com()?;
        let nominal = GainSchedule::constant(n, config.hand.kp, config.nominal_kd(config.hand.kp));
        let parts = parts::build_all(&PartSetup {
            robot,
            config,
            kind,
            model: &model,
            cart: &cart,
            dt: control_period,
            contact_frames: wbc.contact_frames(),
            imu_frame: robot.imu_frame,
        })?;
        Ok(Self {
            data: Data::new(&model),
            sensed: RobotState::new(model.nq, model.nv),
            frame: TickFrame::new(kind, model.nq, model.nv, n),
            parts,
            op,
            wbc,
            zmp,
            previewer: HandPreviewer::new(p.period, Matrix3::identity(), n)?,
            kind,
            hand_frame,
            robot_hash: 0,
            horizon: n,
            period: p.period,
            dt: control_period,
            height_gains,
            force_feedback: config.controller.hand_force_feedback,
            force_source: config.controller.hand_force_feedback_from,
            hand_free_dir: None,
            held_mass: Matrix3::zeros(),
            decoupled_stiffness: config.hand.stiffness == crate::config::HandStiffness::Decoupled,
            held_path_mode: config.hand.held_path,
            held_path: None,
            door_path: None,
            zmp_ref: vec![[0.0; 2]; n],
            hand_desired: vec![HandState::default(); n],
            schedule: nominal.clone(),
            nominal,
            plan: PreviewPlan::with_capacity(n),
            last_x: [Vector3::zeros(); 2],
            com_acc_cmd: Vector3::zeros(),
            hand_acc_cmd: Vector3::zeros(),
            latched: None,
            zmp_offset,
            f_dis_total: vec![[0.0; 3]; n],
            preview_fallbacks: 0,
            hand_force_modelled_ticks: 0,
            fall_drop: config.controller.fall_drop,
            support_follow: config.controller.support_follow,
            fallen_damping: config.wbc.fallback_damping,
            fallen: false,
            falls: 0,
            fallen_ticks: 0,
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
        for p in self.parts.iter_mut() {
            p.held_object(&rows);
        }
        // HP-1: the path e and, if asked, the object's mass along it (m e eᵀ's trace).
        use crate::config::HeldPath;
        let mass = match self.held_path_mode {
            HeldPath::PathInertia => held_mass.trace(),
            HeldPath::Path | HeldPath::Free => 0.0,
        };
        self.door_path = free_direction(&held_mass);
        self.held_path = self
            .door_path
            .filter(|_| self.held_path_mode != HeldPath::Free)
            .map(|e| (e, mass));
        self.previewer.set_held_path(self.held_path);
        // HF-1 inverts M_e + Λ each tick: a Λ with a non-finite entry is not held at all.
        self.held_mass = if held_mass.iter().all(|x| x.is_finite()) {
            held_mass
        } else {
            Matrix3::zeros()
        };
        // A door's apparent mass is m e eᵀ: its trace is m, and it over m projects onto e.
        let m = held_mass.trace();
        self.hand_free_dir =
            (m.is_finite() && m > 0.0 && self.decoupled_stiffness).then(|| held_mass / m);
        self
    }

    /// FC-0b for this controller's hand: [`felt_direction`] with K_e ∝ M_e (eq. (17)) or ∝ 1
    /// (`hand.stiffness = "decoupled"`), as far as the correction believes the forecast
    /// ([`believed_felt_direction`]); `None` without a held object or a usable M_e.
    pub fn felt_direction(&self) -> Option<[f64; 3]> {
        let e = self.door_path?;
        let shape = if self.decoupled_stiffness {
            Matrix3::identity()
        } else {
            *self.previewer.effective_mass()
        };
        let d = felt_direction(&e, &shape)?;
        let w = self
            .part::<super::forecast_correction::Correction>()
            .and_then(|c| c.corrector())
            .map_or(1.0, |c| c.estimate().weight);
        Some(believed_felt_direction(&e, &d, w).into())
    }

    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The whole-body controller's counters (solves, torque-limited ticks, fallbacks).
    pub fn wbc_counters(&self) -> crate::wbc::WbcCounters {
        self.wbc.counters()
    }

    /// Each actuated joint's effort limit (N·m; ∞ where the robot gives none).
    pub fn torque_limits(&self) -> &[f64] {
        self.wbc.torque_limits().as_slice()
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
        self.last_x = [Vector3::zeros(); 2];
        self.last = TickRecord::default();
        for p in self.parts.iter_mut() {
            p.reset();
        }
    }

    /// Add a part after those of `super::parts::PIPELINE` (a lab's own observer, without
    /// editing upc): it runs at its stage after theirs, and records and reports as they do.
    pub fn add_part(&mut self, part: Box<dyn ControllerPart>) {
        self.parts.push(part);
    }

    /// The part of type `T` (`super::parts::PIPELINE`), for tests and tools that look inside.
    pub fn part<T: 'static>(&self) -> Option<&T> {
        self.parts
            .iter()
            .find_map(|p| p.as_any().downcast_ref::<T>())
    }

    /// The last tick's values: the core's columns, then each part's, in pipeline order.
    pub fn record(&self, out: &mut Record) {
        self.last.record(out);
        for p in &self.parts {
            p.record(out);
        }
    }

    /// The parts' entries of `summary.json`.
    pub fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        for p in &self.parts {
            p.summarize(out);
        }
    }

    /// Roll out the last tick's predicted horizon and copy it into a log record.
    pub fn fill_plan(&mut self, out: &mut super::logger::PlanLog) {
        let planned = self.zmp.plan(&self.last_x, &mut self.plan);
        out.time = self.last.time;
        if !planned {
            // No solve yet: an empty plan, not the buffer's last one.
            out.zmp.fill([f32::NAN; 2]);
            out.com.fill([f32::NAN; 2]);
            return;
        }
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
        out.held_path = self.held_path;
        out.zmp_ref.copy_from_slice(&self.zmp_ref);
        out.hand_desired.copy_from_slice(&self.hand_desired);
        out.f_ext.copy_from_slice(&self.frame.f_ext);
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

    /// One tick: read the state → parts estimating the base → model quantities → parts on the
    /// measured forces and the horizon's → gain schedule → preview (C0 / C1 on the CoM) →
    /// whole-body QP → record. `tau` receives the actuated torques (length nv − 6). Returns the
    /// WBC status.
    pub fn tick(
        &mut self,
        state: &StateMsg,
        forecast: &ForecastWindow,
        c2: Option<&StampedSchedule>,
        tau: &mut [f64],
    ) -> Result<WbcStatus, TickError> {
        super::contract::read_state(state, self.robot_hash, &mut self.sensed)?;
        self.sense(forecast)?;
        let t = self.sensed.time;
        // Model quantities: CoM (with velocity), hand placement and velocity, M_e.
        let (q, v) = (&self.frame.q, &self.frame.v);
        let (com, vcom) = center_of_mass_velocity(&self.model, &mut self.data, q, v)?;
        let hand = HandState {
            pos: self.data.o_m_f[self.hand_frame].trans,
            vel: self.hand_vel(),
            acc: self.hand_acc_cmd,
        };
        let latched = self.latch(com.z, hand.pos);
        self.frame.com = com.into();
        self.frame.com_vel = vcom.into();
        self.frame.hand_vel = hand.vel.into();
        self.frame.support = latched.support;
        if self.detect_fall(t, latched.com_height - com.z, latched.com_height) {
            let inputs = TickInputs {
                sensed: &self.sensed,
                forecast,
            };
            parts::run_stage(&mut self.parts, Stage::Measure, &inputs, &mut self.frame)?;
            let status = self.hold_fallen([com, vcom], &hand, &latched, tau);
            self.keep_command(tau);
            return Ok(status);
        }
        let m_e = *self
            .op
            .compute(&self.model, &mut self.data, &self.frame.q)?;
        let m_e_ok = self.previewer.set_effective_mass(m_e).is_ok();
        let zref = self.horizon_references(&latched);
        self.frame.known_disturbance = [self.last.f_dis[0], self.last.f_dis[1]];
        let inputs = TickInputs {
            sensed: &self.sensed,
            forecast,
        };
        for stage in [Stage::Measure, Stage::Forecast, Stage::Disturbance] {
            parts::run_stage(&mut self.parts, stage, &inputs, &mut self.frame)?;
            if stage == Stage::Forecast && !self.frame.f_ext_filled {
                // Without a part correcting it, the horizon's hand force is the forecast's
                // (sampled only then: a correcting part fills all of it, and the Forecast
                // stage's other parts act on it only when one did, `TickFrame::f_ext`).
                for (i, f) in self.frame.f_ext.iter_mut().enumerate() {
                    *f = forecast.at(t + (i + 1) as f64 * self.period);
                }
            }
        }
        let age = self.take_schedule(t, c2);
        let x: [AxisState; 2] = [0, 1].map(|a| Vector3::new(com[a], vcom[a], self.com_acc_cmd[a]));
        let (u, fallback) = self.preview(&x, &hand, m_e_ok);
        for a in 0..2 {
            self.com_acc_cmd[a] += u[a] * self.dt;
        }
        let [kpz, kdz] = self.height_gains;
        self.com_acc_cmd.z = kpz * (latched.com_height - com.z) - kdz * vcom.z;
        let (status, iterations, wbc_time) = self.whole_body(&latched, &hand, m_e_ok, tau);

        // The ZMP one preview step ahead, for the logs: O(1). The whole plan is rolled out
        // only when a log record asks for it (`fill_plan`), off the per-tick path.
        let zmp_pred = self.zmp.next_zmp(&x, u);
        self.last_x = x;
        let (kp, kd) = (self.schedule.kp[0], self.schedule.kd[0]);
        self.last = TickRecord {
            time: t,
            com: com.into(),
            com_vel: vcom.into(),
            com_acc_cmd: self.com_acc_cmd.into(),
            zmp_ref: zref,
            zmp_pred,
            zmp_meas: self.frame.cop,
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            kp,
            kd,
            f_dis: self.first_disturbance(),
            f_ext: self.frame.f_ext[0],
            wbc_solved: status == WbcStatus::Solved,
            wbc_iterations: iterations,
            wbc_time,
            preview_fallback: fallback,
            schedule_age: age,
            support: latched.support,
            f_meas: self.frame.hand_force,
            f_raw: forecast.at(t + self.period),
            fallen: false,
        };
        self.keep_command(tau);
        Ok(status)
    }

    /// The tick's frame from the measured state, then the parts of [`Stage::Estimate`] (the
    /// floating base); refuses a state whose configuration or velocity is then not finite.
    fn sense(&mut self, forecast: &ForecastWindow) -> Result<(), TickError> {
        let (s, f) = (&self.sensed, &mut self.frame);
        f.t = s.time;
        f.dt = self.dt;
        f.period = self.period;
        f.q.copy_from(&s.q);
        f.v.copy_from(&s.v);
        f.estimate_base = false;
        f.cop = s.cop;
        f.foot_wrenches = s.foot_wrenches;
        f.hand_force = s.hand_force;
        f.hand_force_trusted = true;
        f.hand_force_lag = 0.0;
        f.hand_force_estimated = false;
        f.f_ext_filled = false;
        f.measured_push = None;
        f.com_force = [0.0; 2];
        f.com_force_decay = None;
        let inputs = TickInputs {
            sensed: &self.sensed,
            forecast,
        };
        parts::run_stage(&mut self.parts, Stage::Estimate, &inputs, &mut self.frame)?;
        let f = &self.frame;
        if !f.q.iter().chain(f.v.iter()).all(|x| x.is_finite()) {
            return Err(TickError::NotFinite);
        }
        Ok(())
    }

    /// F_dis at the first preview step (none for C0), for the record.
    fn first_disturbance(&self) -> [f64; 3] {
        if self.kind == ControllerKind::C0 {
            return [0.0; 3];
        }
        self.previewer
            .disturbance()
            .first()
            .copied()
            .unwrap_or([0.0; 3])
    }

    /// The torques commanded this tick, for the parts of the next (a robot without torque
    /// sensing knows what it asked for).
    fn keep_command(&mut self, tau: &[f64]) {
        let n = tau.len().min(self.frame.tau_commanded.len());
        self.frame.tau_commanded.as_mut_slice()[..n].copy_from_slice(&tau[..n]);
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
        [com, vcom]: [Vector3<f64>; 2],
        hand: &HandState,
        latched: &Latched,
        tau: &mut [f64],
    ) -> WbcStatus {
        self.fallen_ticks += 1;
        // Within the drives' limits as every other command: a falling robot's joints move fast
        // (a bus clamped these on a G1 that fell, `tests/bus.rs`).
        let qd = self.frame.v.as_slice().get(6..).unwrap_or(&[]);
        crate::wbc::damping_torques(self.fallen_damping, qd, self.torque_limits(), tau);
        self.last = TickRecord {
            time: self.sensed.time,
            com: com.into(),
            com_vel: vcom.into(),
            zmp_meas: self.frame.cop,
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            support: latched.support,
            f_meas: self.frame.hand_force,
            fallen: true,
            ..TickRecord::default()
        };
        WbcStatus::Fallback(FallbackReason::Fallen)
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

    /// The horizon's references at t + (i+1)·T: the ZMP reference and the hand set-point.
    /// Returns the ZMP reference.
    fn horizon_references(&mut self, latched: &Latched) -> [f64; 2] {
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
        zref
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
    fn preview(&mut self, x: &[AxisState; 2], hand: &HandState, m_e_ok: bool) -> ([f64; 2], bool) {
        let mut fallback = false;
        let observed = self
            .frame
            .com_force_decay
            .map(|decay| (self.frame.com_force, decay));
        // Σ: F_dis (C1, C2; zero for C0) plus the parts' CoM force decaying over the horizon.
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
                            &self.frame.f_ext,
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
        // The corrected force (FC-4's first sample): an estimate's drive friction, which moves
        // with the arm, then does not come back as force at the arm's own speed (negative
        // friction; docs/whole_body_qp.md, "The hand force fed back").
        // `"modelled"`: the same, less the held object's inertia at the hand's own acceleration
        // (below).
        let source = self.force_source.resolve(self.frame.hand_force_estimated);
        let corrected = source.from_correction() && self.frame.f_ext_filled;
        let f_hand = Vector3::from(if corrected {
            self.frame.f_ext[0]
        } else {
            self.frame.hand_force
        });
        // Only a force the parts vouch for (the wrist tare: not while it is taken, nor after a
        // refused one).
        let fed_back = self.force_feedback
            && self.frame.hand_force_trusted
            && f_hand.iter().all(|x| x.is_finite());
        let f_hand = if fed_back { f_hand } else { Vector3::zeros() };
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
        let f_hand = if source == HandForceSource::Modelled && corrected && fed_back && m_e_ok {
            self.hand_force_modelled_ticks += 1;
            held_object_force(&f_hand, &self.op.m_e, &self.held_mass, &(law + coupling))
        } else {
            f_hand
        };
        let acc_ext = if m_e_ok {
            self.op.lambda_inv * f_hand
        } else {
            Vector3::zeros()
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
        let out = self.wbc.solve(
            &self.model,
            &mut self.data,
            &self.frame.q,
            &self.frame.v,
            &cmd,
        );
        let n = out.tau.len().min(tau.len());
        tau[..n].copy_from_slice(&out.tau.as_slice()[..n]);
        (out.status, out.iterations, out.tick_time.as_secs_f64())
    }
}

/// The force a held object passes to the hand when it is pushed with `push` and the hand
/// follows eq. (23)'s impedance law (its acceleration `law`, arm's inertia `m_e`), the object's
/// apparent mass `held` riding on the hand (HF-1): F = P − Λ ẍ with M_e (ẍ − ẍ_law) = F, i.e.
/// (M_e + Λ) ẍ = P + M_e ẍ_law. The inertia term is the hand's commanded acceleration, not a
/// measured one: no lag and no velocity noise (docs/whole_body_qp.md, "The hand force fed
/// back"). `push` itself when M_e + Λ is singular.
pub fn held_object_force(
    push: &Vector3<f64>,
    m_e: &Matrix3<f64>,
    held: &Matrix3<f64>,
    law: &Vector3<f64>,
) -> Vector3<f64> {
    match (m_e + held).try_inverse() {
        Some(inv) => push - held * (inv * (push + m_e * law)),
        None => *push,
    }
}

/// The held object's free direction e (unit, its sign arbitrary) from its apparent mass at the
/// hand: a door's is m e eᵀ (`crate::sim::scene::PlacedDoor::apparent_mass`), so its largest
/// column is m e_k e. `None` when nothing is held (a zero or non-finite mass).
pub fn free_direction(held_mass: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let m = held_mass.trace();
    if !(m.is_finite() && m > 0.0) {
        return None;
    }
    let c = (0..3)
        .map(|k| held_mass.column(k).into_owned())
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
    Some(c.normalize())
}

/// Where a hand held by a stiffness of shape `k_e` feels a push along a door's path `e` (unit),
/// per newton along e: d = K_e e / (eᵀ K_e e) (FC-0b). Held on the path, the hand's error s e
/// pushes back along K_e e; the push balances its part along e (eᵀd = 1) and the hinge the rest.
/// `None` when eᵀ K_e e is not positive.
pub fn felt_direction(e: &Vector3<f64>, k_e: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let k = k_e * e;
    let s = e.dot(&k);
    (s.is_finite() && s > 0.0).then(|| k / s)
}

/// FC-0b as far as the forecast is believed: e + w (d − e), w the forecast's weight (FC-5).
/// The hinge's share across e is the forecast's claim, wrong whenever the forecast is; a
/// discounted forecast keeps it only in part (w = 0: FC-0's e; a non-finite w counts as 0).
/// eᵀ(e + w (d − e)) = 1 for every w: the push along the path is the forecast's.
pub fn believed_felt_direction(e: &Vector3<f64>, d: &Vector3<f64>, w: f64) -> Vector3<f64> {
    let w = if w.is_finite() {
        w.clamp(0.0, 1.0)
    } else {
        0.0
    };
    e + (d - e) * w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_discounted_forecast_keeps_the_hinges_share_only_as_far_as_it_is_believed() {
        let e = Vector3::new(0.995, 0.1, 0.0).normalize();
        let k_e = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 3.0);
        let d = felt_direction(&e, &k_e).unwrap();
        assert!((d - e).norm() > 0.05, "a share across e to keep: {d}");
        let at = |w| believed_felt_direction(&e, &d, w);
        assert!((at(1.0) - d).norm() < 1e-15);
        assert!((at(0.0) - e).norm() < 1e-15);
        assert!((at(0.25) - (e * 0.75 + d * 0.25)).norm() < 1e-15);
        for w in [-1.0, 0.0, 0.3, 0.7, 1.0, 2.0, f64::NAN, f64::INFINITY] {
            assert!((e.dot(&at(w)) - 1.0).abs() < 1e-12, "w {w}: {}", at(w));
        }
        assert!((at(2.0) - d).norm() < 1e-15);
        assert!((at(-1.0) - e).norm() < 1e-15);
        assert!((at(f64::NAN) - e).norm() < 1e-15);
    }

    #[test]
    fn a_held_doors_force_is_the_push_less_its_inertia_at_the_hands_acceleration() {
        // A door of 5 kg along e = x on an arm of 2 kg: a 14 N push with the law at rest moves
        // both, (2 + 5) ẍ = 14, so the door takes 5 · 2 = 10 N and passes 4 N.
        let m_e = Matrix3::identity() * 2.0;
        let e = Vector3::x();
        let held = e * e.transpose() * 5.0;
        let f = held_object_force(&(e * 14.0), &m_e, &held, &Vector3::zeros());
        assert!((f - e * 4.0).norm() < 1e-12, "{f}");
        // Across e the door takes nothing: the push passes whole.
        let side = Vector3::new(0.0, 3.0, -1.0);
        let f = held_object_force(&side, &m_e, &held, &Vector3::zeros());
        assert!((f - side).norm() < 1e-12, "{f}");
        // Any arm, door and law: the force and the hand's acceleration satisfy both equations.
        let m_e = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 3.0);
        let e = Vector3::new(0.99, 0.1, 0.0).normalize();
        let held = e * e.transpose() * 5.1;
        let (push, law) = (Vector3::new(-60.0, 8.0, 3.0), Vector3::new(0.4, -1.2, 0.7));
        let f = held_object_force(&push, &m_e, &held, &law);
        let acc = law + m_e.try_inverse().unwrap() * f;
        assert!((f - (push - held * acc)).norm() < 1e-9, "{f} {acc}");
        // Nothing held: the push itself.
        let f = held_object_force(&push, &m_e, &Matrix3::zeros(), &law);
        assert!((f - push).norm() < 1e-12, "{f}");
    }
}
