//! One control tick, without IPC: robot state and force forecast in, joint torques out.
//!
//! Per tick: kinematics, CoM and the hand's M_e from the model; the parts at their stages; the
//! hand previewer and C0/C1 with the latest gain schedule; the whole-body QP. Allocation-free
//! after construction. The mathematics, and the choices below: docs/preview_control.md,
//! docs/hand_previewer.md, docs/whole_body_qp.md.
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
//! - What the robot measures arrives as a [`RobotState`] (read from the contract at the
//!   process's edge, `super::contract`); the controller's parts (`super::parts`) refine it
//!   into the tick's frame (`super::frame`): the core runs them by stage and knows none by type.
//!
//! The core's pieces: its settings, its state between ticks, its workspace and its counters
//! (below); the references and the fall ([`latch`]); the preview ([`preview`]); the whole-body
//! QP's command ([`whole_body`]).

mod latch;
mod preview;
mod whole_body;

use super::TickRecord;
use super::forecast_window::ForecastWindow;
use super::frame::TickFrame;
use super::gain_thread::{GainSnapshot, StampedSchedule};
use super::held_object::{HeldObject, believed_felt_direction, felt_direction};
use super::logger::PlanLog;
use super::part::{BuildError, ControllerPart, PartSetup};
use super::parts as pipeline;
use super::summary::CoreInfo;
use super::tick::{Stage, TickError, TickInputs};
use crate::config::{Config, ControllerKind, HandForceSource};
use crate::dynamics::{
    Data, Model, OpSpaceWorkspace, ReferenceFrame, center_of_mass_velocity, frame_velocity,
};
use crate::preview::{AxisState, GainSchedule, HandPreviewer, HandState, PreviewPlan, ZmpPreview};
use crate::record::Record;
use crate::robot::{Robot, RobotState};
use crate::wbc::{WbcStatus, WholeBodyController};
use nalgebra::{Matrix3, Vector3};

use latch::Latched;

/// The controller's state between ticks, and what it runs on.
pub struct ControllerCore {
    /// The controller's model (the robot's, with the config's gravity).
    pub model: Model,
    settings: CoreSettings,
    state: CoreState,
    work: CoreWorkspace,
    info: CoreInfo,
    wbc: WholeBodyController,
    zmp: ZmpPreview,
    previewer: HandPreviewer,
    parts: Vec<Box<dyn ControllerPart>>,
    /// What the last tick produced.
    pub last: TickRecord,
}

/// What the core is built with; fixed after construction.
struct CoreSettings {
    kind: ControllerKind,
    hand_frame: usize,
    horizon: usize,
    /// Preview period T and control period (s).
    period: f64,
    dt: f64,
    /// The CoM height's PD gains.
    height_gains: [f64; 2],
    /// Feed the measured hand force to the whole-body QP (`controller.hand_force_feedback`),
    /// and which (`controller.hand_force_feedback_from`).
    force_feedback: bool,
    force_source: HandForceSource,
    /// The scenario's ZMP reference offset from the feet's centre (m).
    zmp_offset: [f64; 2],
    /// The fall detector: the drop (fraction of the latched CoM height) that means a fall (0:
    /// off), and the joint damping held then.
    fall_drop: f64,
    fallen_damping: f64,
    /// Time constant (s) of the support's following of the feet; 0: latched.
    support_follow: f64,
    /// The nominal gain schedule (C0, C1; C2's until its first schedule).
    nominal: GainSchedule,
    /// `hand.held_path` and `hand.stiffness = "decoupled"`: what a held object's path does to
    /// the previewer and the hand's stiffness; what the hand holds
    /// ([`ControllerCore::with_held_mass`]).
    held_path: crate::config::HeldPath,
    decoupled_stiffness: bool,
    held: HeldObject,
}

/// What carries from one tick to the next (a plant session's; [`ControllerCore::reset`]).
struct CoreState {
    latched: Option<Latched>,
    /// Fallen in this session.
    fallen: bool,
    /// The cart-table state the last tick solved from (to roll its plan out on demand).
    last_x: [AxisState; 2],
    com_acc_cmd: Vector3<f64>,
    hand_acc_cmd: Vector3<f64>,
}

/// Refilled every tick; preallocated once.
struct CoreWorkspace {
    data: Data,
    op: OpSpaceWorkspace,
    frame: TickFrame,
    zmp_ref: Vec<[f64; 2]>,
    hand_desired: Vec<HandState>,
    /// The gains of this tick's horizon (C2's shifted to now, or the nominal ones).
    schedule: GainSchedule,
    plan: PreviewPlan,
    f_dis_total: Vec<[f64; 3]>,
}

impl ControllerCore {
    /// The controller of `robot`: its model (whole-body dynamics), its reduced models
    /// ([`Robot::reduced`]: the preview's cart-table), its frames and the parts of
    /// `super::parts::PIPELINE`, each from its own table of `config`.
    pub fn new(
        robot: &Robot,
        config: &Config,
        kind: ControllerKind,
        control_period: f64,
        height_gains: [f64; 2],
        zmp_offset: [f64; 2],
    ) -> Result<Self, BuildError> {
        // One gravity for the controller: the cart-table's, the forecast window's weight and
        // the whole-body dynamics' (RNEA, the QP) are all `robot.gravity` of the config.
        let mut model = robot.model.clone();
        model.gravity = Vector3::new(0.0, 0.0, -config.robot.gravity);
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
        let setup = PartSetup {
            robot,
            kind,
            model: &model,
            cart: &cart,
            period: p.period,
            dt: control_period,
            contact_frames: wbc.contact_frames(),
            imu_frame: robot.imu_frame,
            qp_hand_force: config.controller.hand_force_feedback_from,
        };
        let parts = pipeline::build_all(&setup, &config.controller.parts)?;
        let cc = &config.controller;
        Ok(Self {
            settings: CoreSettings {
                kind,
                hand_frame,
                horizon: n,
                period: p.period,
                dt: control_period,
                height_gains,
                force_feedback: cc.hand_force_feedback,
                force_source: cc.hand_force_feedback_from,
                zmp_offset,
                fall_drop: cc.fall_drop,
                fallen_damping: config.wbc.fallback_damping,
                support_follow: cc.support_follow,
                nominal: nominal.clone(),
                held_path: config.hand.held_path,
                decoupled_stiffness: config.hand.stiffness
                    == crate::config::HandStiffness::Decoupled,
                held: HeldObject::NONE,
            },
            state: CoreState::default(),
            work: CoreWorkspace {
                data: Data::new(&model),
                op,
                frame: TickFrame::new(kind, model.nq, model.nv, n, 1),
                zmp_ref: vec![[0.0; 2]; n],
                hand_desired: vec![HandState::default(); n],
                schedule: nominal,
                plan: PreviewPlan::with_capacity(n),
                f_dis_total: vec![[0.0; 3]; n],
            },
            info: CoreInfo::default(),
            wbc,
            zmp,
            previewer: HandPreviewer::new(p.period, Matrix3::identity(), n)?,
            parts,
            last: TickRecord::default(),
            model,
        })
    }

    /// What the hand holds: its apparent mass at the hand (world, kg;
    /// [`crate::sim::scene::PlacedDoor::apparent_mass`]). The previewer keeps the hand on its
    /// path (HP-1), the parts find it in the frame (the forecast correction takes its inertia
    /// out of the measured hand force, FC-1).
    pub fn with_held_mass(mut self, held_mass: Matrix3<f64>) -> Self {
        let s = &mut self.settings;
        s.held = HeldObject::new(held_mass, s.held_path, s.decoupled_stiffness);
        self.previewer.set_held_path(s.held.path);
        for h in self.work.frame.hands_mut() {
            h.held_mass = s.held.rows();
        }
        self
    }
}

impl Default for CoreState {
    fn default() -> Self {
        Self {
            latched: None,
            fallen: false,
            last_x: [Vector3::zeros(); 2],
            com_acc_cmd: Vector3::zeros(),
            hand_acc_cmd: Vector3::zeros(),
        }
    }
}

impl ControllerCore {
    /// FC-0b for this controller's hand: [`felt_direction`] with K_e ∝ M_e (eq. (17)) or ∝ 1
    /// (`hand.stiffness = "decoupled"`), as far as the last tick believed the forecast (the
    /// weight its producer left in the frame, [`believed_felt_direction`]); `None` without a
    /// held object or a usable M_e.
    pub fn felt_direction(&self) -> Option<[f64; 3]> {
        let e = self.settings.held.free_dir?;
        let shape = if self.settings.decoupled_stiffness {
            Matrix3::identity()
        } else {
            *self.previewer.effective_mass()
        };
        let d = felt_direction(&e, &shape)?;
        let w = self.work.frame.hand().prediction.weight;
        Some(believed_felt_direction(&e, &d, w).into())
    }

    pub fn kind(&self) -> ControllerKind {
        self.settings.kind
    }

    pub fn horizon(&self) -> usize {
        self.settings.horizon
    }

    /// The core's counters.
    pub fn info(&self) -> CoreInfo {
        self.info
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
        self.state.latched.map(|l| l.support)
    }

    /// Forget the latched references and the commands carried between ticks, so the next tick
    /// latches again from its state as a first tick does: for a restarted simulator, whose robot
    /// starts over from its initial posture. The whole-body QP's posture reference (its root
    /// orientation is the base-orientation target) is latched again too. Allocation-free.
    pub fn reset(&mut self) {
        self.state = CoreState::default();
        self.wbc.reset();
        self.work.frame.reset_predictions();
        self.last = TickRecord::default();
        for p in self.parts.iter_mut() {
            p.reset();
        }
    }

    /// Add a part after those of `super::parts::PIPELINE` (a lab's own observer, without
    /// editing upc: `super::server::run_server_with`): it runs at its stage after theirs, and
    /// records and reports as they do.
    pub fn add_part(&mut self, part: Box<dyn ControllerPart>) {
        self.parts.push(part);
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
    pub fn fill_plan(&mut self, out: &mut PlanLog) {
        let w = &mut self.work;
        let planned = self.zmp.plan(&self.state.last_x, &mut w.plan);
        out.time = self.last.time;
        if !planned {
            // No solve yet: an empty plan, not the buffer's last one.
            out.zmp.fill([f32::NAN; 2]);
            out.com.fill([f32::NAN; 2]);
            return;
        }
        out.com_height = self.state.latched.map_or(0.0, |l| l.com_height);
        for i in 0..self.settings.horizon.min(out.zmp.len()) {
            out.zmp[i] = [w.plan.zmp[0][i] as f32, w.plan.zmp[1][i] as f32];
            out.com[i] = [w.plan.com[0][i][0] as f32, w.plan.com[1][i][0] as f32];
            out.kp[i] = w.schedule.kp[i] as f32;
            out.f_dis[i] = if self.settings.kind == ControllerKind::C0 {
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
    pub fn snapshot(&self, out: &mut GainSnapshot, seq: u64) {
        let (s, w) = (&self.state, &self.work);
        out.time = self.last.time;
        out.seq = seq;
        out.com =
            [0, 1].map(|a| Vector3::new(self.last.com[a], self.last.com_vel[a], s.com_acc_cmd[a]));
        out.hand = HandState {
            pos: Vector3::from(self.last.hand_pos),
            vel: self.hand_vel(),
            acc: s.hand_acc_cmd,
        };
        out.m_e = *self.previewer.effective_mass();
        out.held_path = self.settings.held.path;
        out.zmp_ref.copy_from_slice(&w.zmp_ref);
        out.hand_desired.copy_from_slice(&w.hand_desired);
        out.f_ext.copy_from_slice(w.frame.hand().horizon.samples());
        out.applied = [self.last.kp, self.last.kd];
    }

    fn hand_vel(&self) -> Vector3<f64> {
        frame_velocity(
            &self.model,
            &self.work.data,
            self.settings.hand_frame,
            ReferenceFrame::LocalWorldAligned,
        )
        .lin
    }

    /// One tick on the robot as measured: the parts estimating the base → model quantities →
    /// the parts on the measured forces, the horizon's and the CoM's → gain schedule → preview
    /// (C0 / C1 on the CoM) → whole-body QP → record. `tau` receives the actuated torques
    /// (length nv − 6). Returns the WBC status.
    pub fn tick(
        &mut self,
        sensed: &RobotState,
        forecast: &ForecastWindow,
        c2: Option<&StampedSchedule>,
        tau: &mut [f64],
    ) -> Result<WbcStatus, TickError> {
        self.sense(sensed, forecast)?;
        let t = sensed.time;
        let inputs = TickInputs { sensed, forecast };
        // Model quantities: CoM (with velocity), hand placement and velocity, M_e.
        let w = &mut self.work;
        let (q, v) = (w.frame.q.or(&sensed.q), w.frame.v.or(&sensed.v));
        let (com, vcom) = center_of_mass_velocity(&self.model, &mut w.data, q, v)?;
        let hand = HandState {
            pos: w.data.o_m_f[self.settings.hand_frame].trans,
            vel: self.hand_vel(),
            acc: self.state.hand_acc_cmd,
        };
        let latched = self.latch(com.z, hand.pos);
        let f = &mut self.work.frame;
        f.com = com.into();
        f.com_vel = vcom.into();
        f.hand_mut().vel = hand.vel.into();
        f.support = latched.support;
        if self.detect_fall(t, latched.com_height - com.z, latched.com_height) {
            let f = &mut self.work.frame;
            pipeline::run_stage(&mut self.parts, Stage::Measure, &inputs, f)?;
            let status = self.hold_fallen(sensed, [com, vcom], &hand, &latched, tau);
            self.keep_command(tau);
            return Ok(status);
        }
        let w = &mut self.work;
        let m_e = *w
            .op
            .compute(&self.model, &mut w.data, w.frame.q.or(&sensed.q))?;
        let m_e_ok = self.previewer.set_effective_mass(m_e).is_ok();
        let zref = self.horizon_references(&latched);
        self.run_measure_to_disturbance(&inputs)?;
        let age = self.take_schedule(t, c2);
        let x: [AxisState; 2] =
            [0, 1].map(|a| Vector3::new(com[a], vcom[a], self.state.com_acc_cmd[a]));
        let (u, fallback) = self.preview(&x, &hand, m_e_ok);
        for a in 0..2 {
            self.state.com_acc_cmd[a] += u[a] * self.settings.dt;
        }
        let [kpz, kdz] = self.settings.height_gains;
        self.state.com_acc_cmd.z = kpz * (latched.com_height - com.z) - kdz * vcom.z;
        let (status, iterations, wbc_time) = self.whole_body(sensed, &latched, &hand, m_e_ok, tau);
        // The ZMP one preview step ahead, for the logs: O(1). The whole plan is rolled out
        // only when a log record asks for it (`fill_plan`), off the per-tick path.
        let zmp_pred = self.zmp.next_zmp(&x, u);
        self.state.last_x = x;
        let ws = &self.work.schedule;
        let (kp, kd) = (ws.kp[0], ws.kd[0]);
        let f = &self.work.frame;
        let h = f.hand();
        self.last = TickRecord {
            time: t,
            com: com.into(),
            com_vel: vcom.into(),
            com_acc_cmd: self.state.com_acc_cmd.into(),
            zmp_ref: zref,
            zmp_pred,
            cop: *f.cop.or(&sensed.cop),
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            kp,
            kd,
            f_dis: self.first_disturbance(),
            f_ext: h.horizon.samples()[0],
            wbc_solved: status == WbcStatus::Solved,
            wbc_iterations: iterations,
            wbc_time,
            preview_fallback: fallback,
            schedule_age: age,
            support: latched.support,
            f_meas: h.force_used(&sensed.hand_force),
            f_raw: forecast.at(t + self.settings.period),
            fallen: false,
        };
        self.keep_command(tau);
        Ok(status)
    }

    /// The tick's frame started from the measured state, then the parts of
    /// [`Stage::Estimate`] (the floating base); refuses a state of other sizes than the model's,
    /// or whose configuration or velocity is then not finite.
    fn sense(&mut self, sensed: &RobotState, forecast: &ForecastWindow) -> Result<(), TickError> {
        let (nq, nv) = (self.model.nq, self.model.nv);
        if sensed.q.len() != nq || sensed.v.len() != nv || sensed.joint_torques.len() != nv {
            return Err(TickError::Dimensions {
                nq: sensed.q.len() as u32,
                nv: sensed.v.len() as u32,
                model_nq: nq,
                model_nv: nv,
            });
        }
        let s = &self.settings;
        let f = &mut self.work.frame;
        f.start(sensed.time, s.dt, s.period);
        let inputs = TickInputs { sensed, forecast };
        pipeline::run_stage(&mut self.parts, Stage::Estimate, &inputs, f)?;
        let (q, v) = (f.q.or(&sensed.q), f.v.or(&sensed.v));
        if !q.iter().chain(v.iter()).all(|x| x.is_finite()) {
            return Err(TickError::NotFinite);
        }
        Ok(())
    }

    /// The parts of the stages after the model's quantities, in order; after `Forecast`, the
    /// horizon's hand force sampled from the forecast as received where no part produced one.
    fn run_measure_to_disturbance(&mut self, inputs: &TickInputs) -> Result<(), TickError> {
        let (t, period) = (inputs.sensed.time, self.settings.period);
        let f = &mut self.work.frame;
        f.known_disturbance = [self.last.f_dis[0], self.last.f_dis[1]];
        for stage in [Stage::Measure, Stage::Forecast, Stage::Disturbance] {
            pipeline::run_stage(&mut self.parts, stage, inputs, f)?;
            if stage == Stage::Forecast {
                for h in f.hands_mut() {
                    h.horizon
                        .sample_forecast(|i| inputs.forecast.at(t + (i + 1) as f64 * period));
                }
            }
        }
        Ok(())
    }

    /// F_dis at the first preview step (none for C0), for the record.
    fn first_disturbance(&self) -> [f64; 3] {
        if self.settings.kind == ControllerKind::C0 {
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
        let c = &mut self.work.frame.tau_commanded;
        let n = tau.len().min(c.len());
        c.as_mut_slice()[..n].copy_from_slice(&tau[..n]);
    }
}
