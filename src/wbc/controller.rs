//! The whole-body LQP (Salini, Padois, Bidaud 2011; docs/whole_body_qp.md, eq. (17)–(20)), solved
//! with clarabel each tick.
//!
//! Decision variables `z = [q̈ (nv); f (24); e_com (3); e_hand (3)]`: the generalised
//! accelerations (free-flyer part in the root's local frame, as `v`), the world-axes forces at
//! the 8 sole corners (4 per foot), and the residuals of the CoM and hand tasks. The joint
//! torques are eliminated through the actuated rows of the equations of motion,
//! `τ = M_a q̈ + h_a − J_c,aᵀ f`, and recovered from the solution.
//!
//! ```text
//! min ½ zᵀ P z + pᵀ z          (weighted tasks ½ w ‖A z − r‖², P diagonal, see below)
//! s.t. M_u q̈ − J_c,uᵀ f = −h_u                 floating-base rows of the EoM      (zero cone, 6)
//!      J_s q̈ = −J̇_s q̇ − k J_s q̇                each sole, 6-D, world-aligned       (zero cone, 12)
//!      J_com q̈ − e_com = a_com − J̇_com q̇        CoM task residual                  (zero cone, 3)
//!      J_h q̈ − e_hand = ẍ_cmd − J̇_h q̇           hand task residual                 (zero cone, 3)
//!      |M_a q̈ + h_a − J_c,aᵀ f| ≤ s τ_max      torque limits, both signs          (nonneg, 2·32)
//!      ‖(t₁ᵀf_i, t₂ᵀf_i)‖ ≤ μ nᵀ f_i            friction cones, exact               (SOC(3) × 8)
//! ```
//!
//! The tasks are data (`tasks.rs`: a list, and the layout of z and of the rows it implies), read
//! by this full formulation and the condensed one alike.
//!
//! Choices (the paper leaves them open; docs/whole_body_qp.md):
//! - Contacts: the non-accelerating condition is imposed on each sole as a rigid body (6 rows per
//!   foot) rather than on the 4 corners (12 rows per foot of rank 6): identical when the foot is
//!   at rest, and it spares the interior-point KKT system 12 redundant equalities. `k` (config
//!   `contact_damping`) is a Baumgarte-style velocity term that drives a slipping sole back to
//!   rest; there is no position term (the controller keeps no reference foot placement).
//! - Friction: exact second-order cones (clarabel `SecondOrderConeT(3)`) with the sole's z axis
//!   as normal; they imply the normal force is ≥ 0, so no separate rows are needed. (The paper
//!   linearised them; clarabel handles the true cone at the same cost.)
//! - Tasks (`½ w ‖A z − r‖²`; the CoM and hand tasks as `½ w ‖e‖²` on residual variables, which
//!   keeps P diagonal and the KKT factor sparse — with `w JᵀJ` in P it was nearly dense and the
//!   tick ≈ 5× slower): CoM acceleration `J_com q̈ + J̇_com q̇ = a_com` (world), hand
//!   operational-space acceleration `J_h q̈ + J̇_h q̇ = ẍ_cmd` (linear rows, world-aligned) with
//!   `ẍ_cmd = K_p (x_des − x) + K_d (ẋ_des − ẋ) + ẍ_des`, base orientation PD towards the posture
//!   reference's root orientation, joint posture PD, and regularisation of q̈ and f (strictly
//!   convex: the solution is unique).
//! - Formulation handed to clarabel (`wbc.formulation`): by default the problem **condensed**
//!   onto the 24 contact forces (`condensed.rs`: q̈ and the task residuals eliminated in
//!   closed form through the equality rows; 30 variables and 30 rows, H's diagonal-plus-rank-6
//!   factor and one 18 × 18 Cholesky per tick), which has the same optimum. Its exact optimum comes from the
//!   cone solve (`cone.rs`), the active torque limits held as equalities, and clarabel decides
//!   only the rare tick it does not settle; the **full** problem below stays as the reference
//!   (tests compare the two) and decides any tick whose condensation fails (H or S not positive
//!   definite) or whose limits the condensed problem does not settle.
//! - Reuse between ticks: the sparsity pattern is fixed from the model's structure (structural
//!   zeros included), presolve is off and zeros are not dropped. Every solver is built at
//!   construction ([`WholeBodyController::prepare`], from the problem at a posture with the
//!   joints mid-range), so ticks only push values with `update_P/q/A/b` and reuse the symbolic
//!   LDLᵀ analysis and that equilibration; no tick builds a solver (a build allocates). Clarabel
//!   is an interior-point method: it restarts from its own initial point every solve (no warm
//!   start); what carries over is the structure.
//! - Failure is never a panic: a solver status other than Solved / AlmostSolved, non-finite data
//!   or solution, or invalid input gives the fallback torque ([`WholeBodyController::fallback_torque`]:
//!   gravity compensation through the contacts with joint damping), a
//!   [`WbcStatus::Fallback`], a counter, and a rate-limited warning. The solvers are kept after
//!   a failure (clarabel 0.11 cannot re-equilibrate without a rebuild, which allocates): only a
//!   caught panic or a refused data update drops one, rebuilt by the next tick that needs it
//!   (allocating; counted in [`WbcCounters::solver_builds`]).
//!
//! Units: SI (m, s, N, N·m, rad). Forces and CoM / hand quantities are in world axes.

use std::time::{Duration, Instant};

use clarabel::solver::{DefaultSettings, SupportedConeT};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Quaternion, UnitQuaternion, Vector3, Vector6};

use super::com_bias::{com_drift_from_pass, drift_pass, frame_drift_from_pass};
use super::condensed::{
    Condensed, CondensedError, CondensedInstance, CondensedQp, Problem, joint_torque as torque,
};
pub use super::outcome::{FallbackReason, N_CONTACTS, WbcCounters, WbcStatus};
use super::pattern::Pattern;
use super::qp::QpInstance;
use super::tasks::{
    BASE_ORIENTATION, COM, Column, HAND, Layout, POSTURE, Point, TaskList, TaskWeights,
};
use crate::config::{WbcConfig, WbcFormulation};
use crate::dynamics::spatial::log3;
use crate::dynamics::{
    Data, DynamicsError, JointKind, Model, ReferenceFrame, compute_joint_jacobians, crba,
    forward_kinematics, get_frame_jacobian, gravity_torques, jacobian_center_of_mass,
    nonlinear_effects, update_frame_placements,
};
use crate::robot::{BodyFrames, CORNERS};

/// Warnings about fallbacks are emitted at most once per this many ticks.
const WARN_EVERY_TICKS: u64 = 1000;

/// Construction errors (the per-tick [`WholeBodyController::solve`] never fails).
#[derive(Debug, thiserror::Error)]
pub enum WbcError {
    #[error("whole-body controller: {0}")]
    Dynamics(#[from] DynamicsError),
    #[error("whole-body controller needs a free-flyer root joint")]
    NoFloatingBase,
    #[error(
        "joint '{0}' is not a 1-DoF joint: the QP's torque rows and posture task need 1-DoF joints"
    )]
    UnsupportedJoint(String),
    #[error("whole-body controller: clarabel refused the problem: {0}")]
    Solver(String),
}

/// What the control loop asks for this tick. World frame, SI units.
#[derive(Clone, Copy, Debug, Default)]
pub struct WbcCommand<'a> {
    /// Desired CoM acceleration (m/s², world): x/y from the preview controller's plan, z e.g. a
    /// PD on the CoM height.
    pub com_acc: Vector3<f64>,
    /// Hand set-point of the impedance law (m, m/s, m/s², world, at the hand frame origin).
    pub hand_pos_des: Vector3<f64>,
    pub hand_vel_des: Vector3<f64>,
    pub hand_acc_des: Vector3<f64>,
    /// Current impedance gains K_p (1/s²) and K_d (1/s) (from C2, or the fixed ones of C0/C1).
    pub kp: f64,
    pub kd: f64,
    /// Known external force on the hand (N, world; measured, e.g. a wrist force sensor): enters
    /// the equations of motion, so the torques account for it instead of letting it accelerate
    /// whatever joints are lightest. Zero when unknown.
    pub hand_force: Vector3<f64>,
    /// Posture reference (length nq; its root quaternion is the base-orientation target). `None`:
    /// the stored one ([`WholeBodyController::set_posture_reference`], else the first `q` after
    /// construction or [`WholeBodyController::reset`]).
    pub posture_ref: Option<&'a DVector<f64>>,
}

/// Which problem [`WholeBodyController::prepare`] makes a tick solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Path {
    /// The condensed problem (then the full one if a limit is violated).
    Condensed,
    /// The full problem, screened without its torque rows first.
    Relaxed,
    /// The full problem with its torque rows.
    Full,
}

/// Where the tick's kinematics put the soles (rotations), the hand (position) and the root
/// (rotation), world frame.
struct Pose {
    feet: [Matrix3<f64>; 2],
    hand: Vector3<f64>,
    root: Matrix3<f64>,
}

/// One tick's result. `tau` and `ddq` borrow the controller's buffers.
#[derive(Debug)]
pub struct WbcOutput<'a> {
    /// Actuated joint torques (N·m), length nv − 6, in velocity order of the joints.
    pub tau: &'a DVector<f64>,
    /// Generalised accelerations the QP predicts (length nv; zeros on a fallback).
    pub ddq: &'a DVector<f64>,
    /// Contact forces (N, world axes) at `<left foot>_fl, _fr, _rl, _rr, <right foot>_fl, …`.
    pub contact_forces: [Vector3<f64>; N_CONTACTS],
    pub status: WbcStatus,
    /// Build + solve wall time of the tick.
    pub tick_time: Duration,
    /// The QP solver's wall time: the cone solve's, clarabel's, or both's (zero on a fallback
    /// before solving).
    pub solve_time: Duration,
    /// Interior-point iterations (0 when not solved).
    pub iterations: u32,
}

/// Settings copied from [`WbcConfig`].
#[derive(Clone, Debug)]
struct Params {
    friction: f64,
    contact_damping: f64,
    w_reg_force: f64,
    base_kp: f64,
    base_kd: f64,
    posture_kp: f64,
    posture_kd: f64,
    fallback_damping: f64,
    reuse_solver: bool,
    formulation: WbcFormulation,
    active_set: bool,
}

impl Params {
    fn of(config: &WbcConfig) -> Self {
        Params {
            friction: config.friction,
            contact_damping: config.contact_damping,
            w_reg_force: config.w_reg_force,
            base_kp: config.base_kp,
            base_kd: config.base_kd,
            posture_kp: config.posture_kp,
            posture_kd: config.posture_kd,
            fallback_damping: config.fallback_damping,
            reuse_solver: config.reuse_solver,
            formulation: config.formulation,
            active_set: config.active_set,
        }
    }
}

/// The actuated joints as the QP sees them.
struct Actuation {
    /// Configuration index of each actuated dof.
    q_index: Vec<usize>,
    /// Effort limit of each actuated dof (∞ when unlimited).
    tau_max: DVector<f64>,
    /// Velocity indices of the joints with a torque row and their limits (N·m, scaled).
    limited: Vec<(usize, f64)>,
}

impl Actuation {
    /// Every joint after the free flyer must be 1-DoF (the torque rows and the posture task
    /// index them by one velocity).
    fn of(model: &Model, config: &WbcConfig) -> Result<Self, WbcError> {
        let na = model.nv - 6;
        let mut q_index = Vec::with_capacity(na);
        let mut tau_max = DVector::from_element(na, f64::INFINITY);
        let mut limited = Vec::new();
        for j in &model.joints[1..] {
            if j.nv() != 1 || j.nq() != 1 {
                return Err(WbcError::UnsupportedJoint(j.name.clone()));
            }
            q_index.push(j.idx_q);
            let e = j.limits.effort * config.torque_limit_scale;
            // An effort of 0 (URDF's "unspecified") or ∞ means no torque row.
            if e.is_finite() && e > 0.0 {
                limited.push((j.idx_v, e));
                tau_max[j.idx_v - 6] = e;
            }
        }
        Ok(Actuation {
            q_index,
            tau_max,
            limited,
        })
    }
}

/// Frame ids of the two soles, of their corners (`<foot>_<corner>`, left foot first, each in
/// [`CORNERS`] order) and of the hand.
fn frame_ids(
    model: &Model,
    frames: &BodyFrames,
) -> Result<([usize; 2], [usize; N_CONTACTS], usize), WbcError> {
    let foot_ids = [
        model.frame_id(&frames.feet[0])?,
        model.frame_id(&frames.feet[1])?,
    ];
    let mut corner_ids = [0; N_CONTACTS];
    for (k, foot) in frames.feet.iter().enumerate() {
        for (s, suffix) in CORNERS.iter().enumerate() {
            corner_ids[4 * k + s] = model.frame_id(&format!("{foot}_{suffix}"))?;
        }
    }
    let hand_id = model.frame_id(&frames.hand)?;
    Ok((foot_ids, corner_ids, hand_id))
}

/// The whole-body torque controller. See the module documentation for the problem.
pub struct WholeBodyController {
    /// The problem's shape, decided once from the model and the config.
    shape: Shape,
    /// Refilled every tick: the tasks' targets and Jacobians, the QP's matrices, the solvers.
    work: Workspace,
    /// What carries from one tick to the next (a plant session's; [`Self::reset`]).
    state: Carried,
    /// The last tick's torques, accelerations and contact forces.
    out: Outputs,
    /// Counters, and the last warning's tick.
    info: Info,
}

/// The problem's shape: the settings, the layout of its variables and rows, the frames and
/// joints it is written on. Fixed after construction.
struct Shape {
    p: Params,
    settings: DefaultSettings<f64>,
    nq: usize,
    /// Where the full problem's variables and rows are (from the task list, decided once).
    layout: Layout,
    corner_ids: [usize; N_CONTACTS],
    foot_ids: [usize; 2],
    /// The dofs that move each sole (its ancestors' velocity indices): the only columns where
    /// its Jacobian, and its corners', can be non-zero.
    foot_dofs: [Vec<usize>; 2],
    hand_id: usize,
    /// Velocity indices of the torque-limited joints and their limits (N·m, scaled).
    limited: Vec<(usize, f64)>,
    /// Effort limit of each actuated dof (∞ when unlimited), for clamping the fallback.
    tau_max: DVector<f64>,
    /// Configuration index of each actuated dof.
    q_index: Vec<usize>,
    /// P's pattern (diagonal).
    p_pattern: Pattern,
}

/// Per-tick workspace, preallocated.
struct Workspace {
    /// The tasks, their weights, Jacobians and targets (targets set each tick).
    tasks: TaskList,
    jtmp: DMatrix<f64>,
    jc: DMatrix<f64>,
    jfeet: DMatrix<f64>,
    h: DVector<f64>,
    pd: DMatrix<f64>,
    qd: Vec<f64>,
    ad: DMatrix<f64>,
    bd: Vec<f64>,
    p_val: Vec<f64>,
    /// The full QP, and the same QP without the torque rows (tried first, see `solve_qp`).
    full: QpInstance,
    relaxed: Option<QpInstance>,
    /// The same QP condensed onto the contact forces (see `condensed`).
    condensed: CondensedQp,
    /// Diagonal Hessian and linear term of the q̈ cost terms; right-hand side of the sole rows.
    diag: Vec<f64>,
    lin: Vec<f64>,
    b_feet: [f64; 12],
    /// Copy of the accepted solution, and whether it is the condensed solve's (whose limited
    /// τ the outputs then read: `CondensedQp::limited_torques`).
    x: Vec<f64>,
    x_from_condensed: bool,
}

/// What one tick leaves the next.
struct Carried {
    /// The last tick's optimum had a torque limit active (condensed formulation: see `solve`).
    limits_active: bool,
    /// The posture reference (length nq), meaningful when `posture_set`: stored by
    /// [`WholeBodyController::set_posture_reference`] or latched from the first `q` after
    /// construction or [`WholeBodyController::reset`]. Preallocated: latching copies.
    posture_ref: DVector<f64>,
    posture_set: bool,
    /// The last QP torque, for the fallback.
    last_tau: DVector<f64>,
}

/// The last tick's results.
struct Outputs {
    tau: DVector<f64>,
    ddq: DVector<f64>,
    forces: [Vector3<f64>; N_CONTACTS],
}

/// What the controller counted.
struct Info {
    counters: WbcCounters,
    last_warn_tick: Option<u64>,
}

impl WholeBodyController {
    /// Resolves `frames` (the contact, foot and hand frames), decides the fixed sparsity
    /// pattern, the cones and clarabel's settings, preallocates every buffer and builds the
    /// clarabel solvers ([`Self::prepare`] with every joint at the middle of its range, else at the neutral
    /// configuration), so that no tick allocates one.
    pub fn new(model: &Model, config: &WbcConfig, frames: &BodyFrames) -> Result<Self, WbcError> {
        if !model.has_floating_base() || model.joints[0].kind != JointKind::FreeFlyer {
            return Err(WbcError::NoFloatingBase);
        }
        let nv = model.nv;
        let na = nv - 6;
        let Actuation {
            q_index,
            tau_max,
            limited,
        } = Actuation::of(model, config)?;
        let (foot_ids, corner_ids, hand_id) = frame_ids(model, frames)?;

        let tasks = TaskList::new(
            nv,
            hand_id,
            TaskWeights {
                com: config.w_com,
                hand: config.w_hand,
                base_orientation: config.w_base_orientation,
                posture: config.w_posture,
                acceleration: config.w_reg_acceleration,
            },
        );
        let layout = Layout::new(nv, tasks.points.len(), limited.len());
        // P: diagonal (the joint tasks, the forces' regularisation, the residuals' weights).
        let p_pattern = Pattern::from_mask(layout.nz, layout.nz, |r, c| r == c);
        let a_pattern =
            constraint_pattern(model, &layout, &tasks, &foot_ids, &corner_ids, &limited);
        let (full, relaxed) = full_problems(&layout, a_pattern, limited.len());
        let settings = clarabel_settings(config);
        let condensed = CondensedQp::new(nv, model.total_mass() * model.gravity.norm());
        let work = Workspace {
            tasks,
            jtmp: DMatrix::zeros(6, nv),
            jc: DMatrix::zeros(3 * N_CONTACTS, nv),
            jfeet: DMatrix::zeros(12, nv),
            h: DVector::zeros(nv),
            pd: DMatrix::zeros(layout.nz, layout.nz),
            qd: vec![0.0; layout.nz],
            ad: DMatrix::zeros(layout.n_rows, layout.nz),
            bd: vec![0.0; layout.n_rows],
            p_val: vec![0.0; p_pattern.nnz()],
            full,
            relaxed,
            condensed,
            diag: vec![0.0; nv],
            lin: vec![0.0; nv],
            b_feet: [0.0; 12],
            x: vec![0.0; layout.nz],
            x_from_condensed: false,
        };
        let mut wbc = Self {
            shape: Shape {
                p: Params::of(config),
                settings,
                nq: model.nq,
                layout,
                corner_ids,
                foot_ids,
                foot_dofs: foot_ids
                    .map(|f| (0..nv).filter(|&d| moves_frame(model, d, f)).collect()),
                hand_id,
                limited,
                tau_max,
                q_index,
                p_pattern,
            },
            work,
            state: Carried {
                limits_active: false,
                posture_ref: model.neutral(),
                posture_set: false,
                last_tau: DVector::zeros(na),
            },
            out: Outputs {
                tau: DVector::zeros(na),
                ddq: DVector::zeros(nv),
                forces: [Vector3::zeros(); N_CONTACTS],
            },
            info: Info {
                counters: WbcCounters::default(),
                last_warn_tick: None,
            },
        };
        if wbc.shape.p.reuse_solver {
            wbc.prepare_at_construction(model);
        }
        Ok(wbc)
    }

    /// [`Self::prepare`] at the middle of every joint's range, else at the neutral
    /// configuration: straight legs (the neutral configuration of most humanoids) make the
    /// condensed problem singular.
    fn prepare_at_construction(&mut self, model: &Model) {
        let mut data = Data::new(model);
        let mut prepared = Err(WbcError::NoFloatingBase);
        for q in [mid_range(model), model.neutral()] {
            prepared = self.prepare(model, &mut data, &q);
            if prepared.is_ok() {
                break;
            }
        }
        if let Err(e) = prepared {
            // Not fatal: a solver missing here is built by the first tick that needs it
            // (counted in `solver_builds`).
            tracing::warn!("whole-body controller: {e}; the first ticks will build them");
        }
    }

    /// Builds every clarabel solver the configured formulation may use — the condensed one
    /// (formulation `condensed`), the full problem without its torque rows (the screening solve,
    /// when some joint has a torque limit) and the full problem — from the problem at posture `q`
    /// (v = 0, the hand held where it is, no CoM acceleration), so that no tick builds one (a
    /// build allocates: the CSC matrices, clarabel's KKT system). Their equilibration is that
    /// problem's. [`Self::new`] calls it (joints mid-range); call it again (before the loop) to
    /// equilibrate at a more typical posture. An error says which solver could not be built
    /// (e.g. the condensed one at a singular posture); the others are built. Counters other than
    /// `solver_builds`, and the posture reference, are left as they were.
    pub fn prepare(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
    ) -> Result<(), WbcError> {
        if model.nv != self.shape.layout.nv || model.nq != self.shape.nq {
            return Err(WbcError::Dynamics(DynamicsError::DimensionMismatch {
                what: "model (not the controller's)",
                expected: self.shape.layout.nv,
                got: model.nv,
            }));
        }
        forward_kinematics(model, data, q)?;
        let hand = data.o_m_f[self.shape.hand_id].trans;
        let v = DVector::zeros(self.shape.layout.nv);
        let posture = q.clone();
        let cmd = WbcCommand {
            hand_pos_des: hand,
            posture_ref: Some(&posture),
            ..WbcCommand::default()
        };
        let saved = self.info.counters;
        self.drop_solvers();
        let condensed = self.shape.p.formulation == WbcFormulation::Condensed;
        let mut results = Vec::new();
        for path in [Path::Condensed, Path::Relaxed, Path::Full] {
            if path == Path::Condensed && !condensed {
                continue;
            }
            let (mut t, mut it) = (Duration::ZERO, 0);
            // Whether it solves does not matter here: the solver is built either way (a
            // failed build is reported below).
            let r = self.try_solve(model, data, q, &v, &cmd, Some(path), &mut t, &mut it);
            results.push((path, r));
        }
        self.info.counters = WbcCounters {
            solver_builds: self.info.counters.solver_builds,
            ..saved
        };
        self.state.limits_active = false;
        self.out.tau.fill(0.0);
        self.out.ddq.fill(0.0);
        self.out.forces = [Vector3::zeros(); N_CONTACTS];
        let built = (!condensed || self.work.condensed.has_solver())
            && self
                .work
                .relaxed
                .as_ref()
                .is_none_or(|r| r.solver.is_some())
            && self.work.full.solver.is_some();
        if built || !self.shape.p.reuse_solver {
            Ok(())
        } else {
            Err(WbcError::Solver(format!(
                "could not build every solver at this posture (condensed {}, screening {}, \
                 full {}; solves: {results:?})",
                self.work.condensed.has_solver(),
                self.work
                    .relaxed
                    .as_ref()
                    .is_none_or(|r| r.solver.is_some()),
                self.work.full.solver.is_some()
            )))
        }
    }

    /// From now on every tick builds its condensed QP as clarabel would receive it (without
    /// the torque limits), for [`Self::condensed_instance`]; the cone solve alone does not need
    /// it. Offline use: each tick's limits' active set then starts from none.
    pub fn record_condensed_instances(&mut self) {
        self.work.condensed.record();
    }

    /// The condensed QP of the last tick that formed one, as clarabel receives it (allocates:
    /// for comparing solvers offline, never in the loop): every tick's after
    /// [`Self::record_condensed_instances`], else only those clarabel solved. `None` with the
    /// full formulation.
    pub fn condensed_instance(&self) -> Option<CondensedInstance> {
        (self.shape.p.formulation == WbcFormulation::Condensed)
            .then(|| self.work.condensed.instance())
    }

    /// Counters of ticks, solves and fallbacks since construction.
    pub fn counters(&self) -> WbcCounters {
        self.info.counters
    }

    /// Frame ids of the 8 contact points (order of [`WbcOutput::contact_forces`]).
    pub fn contact_frames(&self) -> [usize; N_CONTACTS] {
        self.shape.corner_ids
    }

    /// Contact forces of the last tick (QP or fallback), as in [`WbcOutput::contact_forces`].
    pub fn last_contact_forces(&self) -> &[Vector3<f64>; N_CONTACTS] {
        &self.out.forces
    }

    /// Frame ids of the two soles and of the hand.
    pub fn foot_frames(&self) -> [usize; 2] {
        self.shape.foot_ids
    }
    pub fn hand_frame(&self) -> usize {
        self.shape.hand_id
    }

    /// Effort limit used for each actuated dof (N·m; ∞ where the URDF gives none).
    pub fn torque_limits(&self) -> &DVector<f64> {
        &self.shape.tau_max
    }

    /// Sizes of the QP: (variables, constraint rows, nnz(P), nnz(A)).
    pub fn problem_size(&self) -> (usize, usize, usize, usize) {
        (
            self.shape.layout.nz,
            self.shape.layout.n_rows,
            self.shape.p_pattern.nnz(),
            self.work.full.pattern.nnz(),
        )
    }

    /// Stores the posture reference (length nq; its root quaternion is the base-orientation
    /// target).
    pub fn set_posture_reference(
        &mut self,
        model: &Model,
        q_ref: &DVector<f64>,
    ) -> Result<(), WbcError> {
        model.check_q(q_ref)?;
        if model.nq != self.shape.nq {
            return Err(WbcError::Dynamics(DynamicsError::DimensionMismatch {
                what: "model (not the controller's)",
                expected: self.shape.nq,
                got: model.nq,
            }));
        }
        self.state.posture_ref.copy_from(q_ref);
        self.state.posture_set = true;
        Ok(())
    }

    /// Forgets every reference and the state carried from tick to tick, so that the next tick
    /// starts as the first after construction: the posture reference (stored or latched; the
    /// next `q` is latched again, its root orientation the base-orientation target), the
    /// active-limit hint of the formulation choice and the last QP torque of the fallback. For a
    /// new plant session (a restarted simulator, whose robot may start from another posture).
    /// The solvers and counters are kept. Allocation-free.
    pub fn reset(&mut self) {
        self.state.posture_set = false;
        self.state.limits_active = false;
        self.work.condensed.forget();
        self.state.last_tau.fill(0.0);
    }

    /// One control tick: assemble and solve the QP at `(q, v)` for `cmd`. Never panics and never
    /// fails: on any problem it returns the fallback torque with [`WbcStatus::Fallback`].
    /// `data` is the caller's workspace for `model` (overwritten).
    pub fn solve(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
        v: &DVector<f64>,
        cmd: &WbcCommand,
    ) -> WbcOutput<'_> {
        let t0 = Instant::now();
        self.info.counters.ticks += 1;
        let mut solve_time = Duration::ZERO;
        let mut iterations = 0;
        let status = match self.try_solve(
            model,
            data,
            q,
            v,
            cmd,
            None,
            &mut solve_time,
            &mut iterations,
        ) {
            Ok(almost) => {
                self.info.counters.solved += 1;
                self.info.counters.almost_solved += u64::from(almost);
                self.info.counters.consecutive_fallbacks = 0;
                self.state.last_tau.copy_from(&self.out.tau);
                WbcStatus::Solved
            }
            Err(reason) => {
                self.info.counters.fallbacks += 1;
                self.info.counters.consecutive_fallbacks += 1;
                // The solvers are kept (no rebuild, no allocation in the loop): every tick
                // overwrites their data and clarabel restarts from its own initial point, so
                // only the equilibration of `prepare` carries over. A solver is dropped (and
                // rebuilt by the next tick, which allocates and counts in `solver_builds`) only
                // when clarabel panicked or refused an update (see `QpInstance::run`).
                self.apply_fallback(model, data, q, v);
                self.warn(reason);
                WbcStatus::Fallback(reason)
            }
        };
        WbcOutput {
            tau: &self.out.tau,
            ddq: &self.out.ddq,
            contact_forces: self.out.forces,
            status,
            tick_time: t0.elapsed(),
            solve_time,
            iterations,
        }
    }

    fn warn(&mut self, reason: FallbackReason) {
        let t = self.info.counters.ticks;
        if self
            .info
            .last_warn_tick
            .is_none_or(|last| t - last >= WARN_EVERY_TICKS)
        {
            self.info.last_warn_tick = Some(t);
            tracing::warn!(
                ?reason,
                fallbacks = self.info.counters.fallbacks,
                consecutive = self.info.counters.consecutive_fallbacks,
                ticks = t,
                "whole-body QP fell back to gravity compensation (warnings limited to one per {WARN_EVERY_TICKS} ticks)"
            );
        }
    }

    /// The QP path. `Ok(almost_solved)` leaves τ, q̈ and f in the output buffers. `forced`
    /// (for [`Self::prepare`]) takes the given path whatever the formulation and limits say.
    #[allow(clippy::too_many_arguments)]
    fn try_solve(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
        v: &DVector<f64>,
        cmd: &WbcCommand,
        forced: Option<Path>,
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Result<bool, FallbackReason> {
        self.check_input(model, v, cmd)?;
        let pose = self.dynamics(model, data, q, v, cmd)?;
        self.set_targets(q, v, cmd, &pose)?;
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        if !(finite(&self.work.diag) && finite(&self.work.lin) && finite(&self.work.b_feet)) {
            return Err(FallbackReason::NonFiniteProblem);
        }
        let almost = match self.solve_path(&data.m, &pose.feet, forced, solve_time, iterations) {
            // No torque within the limits keeps the soles on the ground with these forces
            // (a foot on its edge under a hard push asks its ankle for more than it has): the
            // drives saturate whatever is commanded, so command the optimum without the limits,
            // clamped below, rather than gravity compensation.
            Err(reason @ FallbackReason::Solver(status))
                if forced.is_none() && infeasible(status) && !self.shape.limited.is_empty() =>
            {
                let a = self
                    .solve_unlimited(&data.m, &pose.feet, solve_time, iterations)
                    .ok_or(reason)?;
                self.info.counters.limits_saturated += 1;
                a
            }
            other => other?,
        };

        // ---- Outputs: q̈, f, τ = M_a q̈ + h_a − J_c,aᵀ f. ----
        let (m, x, nv) = (&data.m, &self.work.x, self.shape.layout.nv);
        self.out.ddq.copy_from_slice(&x[..nv]);
        for c in 0..N_CONTACTS {
            self.out.forces[c] = Vector3::new(x[nv + 3 * c], x[nv + 3 * c + 1], x[nv + 3 * c + 2]);
        }
        // The limited dofs' τ as the condensed solve's active set left them, when x is its.
        let known = self
            .work
            .condensed
            .limited_torques()
            .filter(|_| self.work.x_from_condensed);
        for a in 0..nv - 6 {
            // A limit held at its bound gives τ on it within rounding, and the condensed check
            // lets the others exceed theirs by 1e-9 relative (`condensed.rs`): the drives get
            // the limit itself, never a hair above it.
            let lim = self.shape.tau_max[a];
            let t = match known {
                Some(t) if lim.is_finite() => t[6 + a],
                _ => torque(m, &self.work.h, &self.work.jc, x, 6 + a),
            };
            self.out.tau[a] = t.clamp(-lim, lim);
        }
        if !finite(self.out.tau.as_slice()) {
            return Err(FallbackReason::NonFiniteSolution);
        }
        Ok(almost)
    }

    /// Sizes, finiteness of the command and of `v`, and the posture reference's validity.
    fn check_input(
        &self,
        model: &Model,
        v: &DVector<f64>,
        cmd: &WbcCommand,
    ) -> Result<(), FallbackReason> {
        use FallbackReason::InvalidInput;
        if model.nv != self.shape.layout.nv || model.nq != self.shape.nq {
            return Err(InvalidInput);
        }
        let cmd_finite = [
            cmd.com_acc,
            cmd.hand_pos_des,
            cmd.hand_vel_des,
            cmd.hand_acc_des,
            cmd.hand_force,
        ]
        .iter()
        .all(|x| x.iter().all(|c| c.is_finite()))
            && cmd.kp.is_finite()
            && cmd.kd.is_finite();
        if !cmd_finite || model.check_v("v", v).is_err() {
            return Err(InvalidInput);
        }
        if let Some(r) = cmd.posture_ref {
            model.check_q(r).map_err(|_| InvalidInput)?;
        }
        Ok(())
    }

    /// Kinematics and dynamics at (q, v): M in `data.m`, the bias `h` (the known hand force
    /// included), the contact, sole and point-task Jacobians, each point task's drift `J̇ v`
    /// subtracted from its target, the soles' right-hand side.
    fn dynamics(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
        v: &DVector<f64>,
        cmd: &WbcCommand,
    ) -> Result<Pose, FallbackReason> {
        use FallbackReason::InvalidInput;
        // CRBA checks q and leaves the joint Jacobians.
        crba(model, data, q).map_err(|_| InvalidInput)?;
        if !self.state.posture_set && cmd.posture_ref.is_none() {
            // First tick after construction or a reset: latch (a copy, no allocation).
            self.state.posture_ref.copy_from(q);
            self.state.posture_set = true;
        }
        update_frame_placements(model, data);
        self.build_jacobians(model, data);
        let pose = Pose {
            feet: [
                data.o_m_f[self.shape.foot_ids[0]].rot,
                data.o_m_f[self.shape.foot_ids[1]].rot,
            ],
            hand: data.o_m_f[self.shape.hand_id].trans,
            root: data.o_m_i[0].rot,
        };
        jacobian_center_of_mass(model, data, q).map_err(|_| InvalidInput)?;
        // Drifts J̇ v of the soles and of every point task: one forward pass.
        drift_pass(model, data, q, v, self.shape.foot_ids[0]).map_err(|_| InvalidInput)?;
        for t in &mut self.work.tasks.points {
            let drift = match t.point {
                Point::Com => {
                    t.jac.copy_from(&data.jcom);
                    com_drift_from_pass(model, data)
                }
                Point::Frame(id) => frame_drift_from_pass(model, data, id).lin,
            };
            t.target = -drift;
        }
        let nv = self.shape.layout.nv;
        for foot in 0..2 {
            let drift = frame_drift_from_pass(model, data, self.shape.foot_ids[foot]).to_vector();
            // Soles at rest: J_s q̈ = −J̇_s v − k J_s v.
            for i in 0..6 {
                let jr = 6 * foot + i;
                // Over the dofs that move the sole: its Jacobian is zero on the others.
                let jv: f64 = self.shape.foot_dofs[foot]
                    .iter()
                    .map(|&c| self.work.jfeet[(jr, c)] * v[c])
                    .sum();
                self.work.b_feet[jr] = -drift[i] - self.shape.p.contact_damping * jv;
            }
        }
        // Bias h(q, v) last: RNEA overwrites data.v / data.a but not data.m.
        nonlinear_effects(model, data, q, v).map_err(|_| InvalidInput)?;
        self.work.h.copy_from(&data.tau);
        // A known hand force acts like a bias: M q̈ + (h − J_hᵀ F) = Sᵀτ + J_cᵀ f.
        let jh = &self.work.tasks.points[HAND].jac;
        for c in 0..nv {
            self.work.h[c] -= (0..3).map(|k| jh[(k, c)] * cmd.hand_force[k]).sum::<f64>();
        }
        Ok(pose)
    }

    /// The tasks' targets at (q, v) for `cmd` (the point tasks' drifts already in theirs, from
    /// [`Self::dynamics`]), and the joint tasks' diagonal terms.
    fn set_targets(
        &mut self,
        q: &DVector<f64>,
        v: &DVector<f64>,
        cmd: &WbcCommand,
        pose: &Pose,
    ) -> Result<(), FallbackReason> {
        let p = &self.shape.p;
        let tasks = &mut self.work.tasks;
        // CoM: the preview's acceleration. Hand, eq. (17): ẍ_cmd = K_p (x_des − x)
        // + K_d (ẋ_des − ẋ) + ẍ_des at the hand frame's origin; its task is eq. (18).
        tasks.points[COM].target += cmd.com_acc;
        let hand = &mut tasks.points[HAND];
        let hand_vel = mat3_mul_v(&hand.jac, v);
        hand.target += cmd.kp * (cmd.hand_pos_des - pose.hand)
            + cmd.kd * (cmd.hand_vel_des - hand_vel)
            + cmd.hand_acc_des;
        // Base orientation: world angular acceleration R ω̇_b (= R q̈[3..6] since d/dt(R ω_b) =
        // R ω̇_b) towards α = K_p log(R_ref Rᵀ) − K_d ω; in body axes the target is Rᵀ α.
        let q_ref = cmd
            .posture_ref
            .or(self.state.posture_set.then_some(&self.state.posture_ref))
            .ok_or(FallbackReason::InvalidInput)?;
        let quat = UnitQuaternion::from_quaternion(Quaternion::new(
            q_ref[6], q_ref[3], q_ref[4], q_ref[5],
        ));
        let r_ref = quat.to_rotation_matrix().into_inner();
        let root_rot = pose.root;
        let omega_b = Vector3::new(v[3], v[4], v[5]);
        let e_world = log3(&(r_ref * root_rot.transpose()));
        let target_b = p.base_kp * (root_rot.transpose() * e_world) - p.base_kd * omega_b;
        tasks.joints[BASE_ORIENTATION]
            .target
            .copy_from_slice(target_b.as_slice());
        // Posture PD on the joints.
        let posture = &mut tasks.joints[POSTURE].target;
        for (a, &qi) in self.shape.q_index.iter().enumerate() {
            posture[a] = p.posture_kp * (q_ref[qi] - q[qi]) - p.posture_kd * v[6 + a];
        }
        tasks.diagonal(&mut self.work.diag, &mut self.work.lin);
        if tasks.is_finite() {
            Ok(())
        } else {
            Err(FallbackReason::NonFiniteProblem)
        }
    }

    /// Solves the tick's problem into `self.work.x`: the condensed problem (the cone solve holding
    /// the active torque limits, or clarabel without them), unless the last tick had a torque
    /// limit active and only clarabel would solve it — a robot at its limits (pushed hard,
    /// falling) stays there for a while, and that screening solve would be wasted. When the
    /// condensed problem does not settle the limits, the full problem with its torque rows
    /// decides.
    fn solve_path(
        &mut self,
        m: &DMatrix<f64>,
        foot_rot: &[Matrix3<f64>; 2],
        forced: Option<Path>,
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Result<bool, FallbackReason> {
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        self.work.x_from_condensed = false;
        let use_condensed = match forced {
            Some(path) => path == Path::Condensed,
            // With the cone solve the screening costs the condensation and a few Newton steps
            // (tens of µs) against about 1 ms for the full problem: always worth trying.
            None => {
                self.shape.p.formulation == WbcFormulation::Condensed
                    && (self.shape.p.active_set || !self.state.limits_active)
            }
        };
        // Screen with the full problem without its torque rows first: after a condensed
        // problem that could not be formed, or as the formulation or `forced` says.
        let mut screen = match forced {
            _ if use_condensed => true,
            Some(path) => path == Path::Relaxed,
            None => self.shape.p.formulation == WbcFormulation::Full,
        };
        if use_condensed {
            // A forced path builds clarabel's solver (`prepare`): no shortcut then.
            let active_set = self.shape.p.active_set && forced.is_none();
            match self.solve_condensed(m, foot_rot, true, active_set, solve_time, iterations) {
                Ok(solved) => {
                    let x = self.work.condensed.x();
                    if finite(x) {
                        self.work.x[..x.len()].copy_from_slice(x);
                        self.work.x_from_condensed = true;
                        self.state.limits_active = solved.limits;
                        self.info.counters.torque_limited += u64::from(solved.limits);
                        return Ok(solved.almost);
                    }
                    screen = false;
                }
                // A torque limit the condensed problem did not settle: the full problem with
                // its torque rows.
                Err(CondensedError::Limits) => screen = false,
                // H or S not positive definite (e.g. a singular leg): the full problem, whose
                // interior-point KKT system is regularised, decides this tick.
                Err(CondensedError::Factorisation) => self.info.counters.condensation_failures += 1,
                Err(CondensedError::Solver(r)) => return Err(r),
            }
        }
        let almost = self.solve_full(m, foot_rot, screen, solve_time, iterations)?;
        // A limit counts as active within 0.1 % of it.
        self.state.limits_active = self.shape.limited.iter().any(|&(dof, tmax)| {
            torque(m, &self.work.h, &self.work.jc, &self.work.x, dof).abs() >= (1.0 - 1e-3) * tmax
        });
        Ok(almost)
    }

    /// The condensed problem without its torque limits (the same optimum as the full problem
    /// without its torque rows), for a tick the limits made infeasible: its clarabel status
    /// (`almost`), or `None` when it fails too (the tick then falls back for the first reason).
    fn solve_unlimited(
        &mut self,
        m: &DMatrix<f64>,
        foot_rot: &[Matrix3<f64>; 2],
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Option<bool> {
        let active_set = self.shape.p.active_set;
        let solved = self
            .solve_condensed(m, foot_rot, false, active_set, solve_time, iterations)
            .ok()?;
        let x = self.work.condensed.x();
        if !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        self.work.x[..x.len()].copy_from_slice(x);
        self.state.limits_active = true;
        Some(solved.almost)
    }

    /// The condensed problem of this tick, with its torque limits or without them.
    fn solve_condensed(
        &mut self,
        m: &DMatrix<f64>,
        foot_rot: &[Matrix3<f64>; 2],
        limits: bool,
        active_set: bool,
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Result<Condensed, CondensedError> {
        let pb = Problem {
            m,
            h: &self.work.h,
            jc: &self.work.jc,
            jfeet: &self.work.jfeet,
            b_feet: &self.work.b_feet,
            diag: &self.work.diag,
            lin: &self.work.lin,
            tasks: &self.work.tasks.points,
            w_force: self.shape.p.w_reg_force,
            friction: self.shape.p.friction,
            foot_rot: *foot_rot,
            limited: if limits { &self.shape.limited } else { &[] },
            active_set,
        };
        self.work.condensed.solve(
            &pb,
            &self.shape.settings,
            self.shape.p.reuse_solver,
            &mut self.info.counters,
            iterations,
            solve_time,
        )
    }

    /// The full problem (the reference formulation): assembles the dense P, q, A, b over
    /// `z = [q̈, f, e_com, e_hand]` and solves it, first without the torque rows when `screen`.
    /// `Ok(almost_solved)` leaves z in `self.work.x`.
    #[allow(clippy::too_many_arguments)]
    fn solve_full(
        &mut self,
        m: &DMatrix<f64>,
        foot_rot: &[Matrix3<f64>; 2],
        screen: bool,
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Result<bool, FallbackReason> {
        self.assemble_full(m, foot_rot)?;
        self.run_full(m, screen, solve_time, iterations)
    }

    /// The dense P, q, A, b of the full problem, in the [`Layout`] the task list decided.
    fn assemble_full(
        &mut self,
        m: &DMatrix<f64>,
        foot_rot: &[Matrix3<f64>; 2],
    ) -> Result<(), FallbackReason> {
        let l = self.shape.layout;
        let nv = l.nv;
        self.work.pd.fill(0.0);
        self.work.qd.fill(0.0);
        for d in 0..nv {
            self.work.pd[(d, d)] = self.work.diag[d];
            self.work.qd[d] = self.work.lin[d];
        }
        for d in l.force0..l.residual0 {
            self.work.pd[(d, d)] = self.shape.p.w_reg_force;
        }
        // Point tasks: weights on their residual variables (rows below).
        for (t, task) in self.work.tasks.points.iter().enumerate() {
            for k in 0..3 {
                let e = l.residual(t, k);
                self.work.pd[(e, e)] = task.weight;
            }
        }

        // ---- Constraints A z + s = b, s ∈ K. ----
        let ad = &mut self.work.ad;
        ad.fill(0.0);
        // Floating-base EoM rows: M_u q̈ − J_c,uᵀ f = −h_u.
        for r in 0..6 {
            for c in 0..nv {
                ad[(r, c)] = m[(r, c)];
            }
            for k in 0..3 * N_CONTACTS {
                ad[(r, nv + k)] = -self.work.jc[(k, r)];
            }
            self.work.bd[r] = -self.work.h[r];
        }
        // Soles at rest: J_s q̈ = b_s.
        for jr in 0..12 {
            let row = l.row_feet + jr;
            for c in 0..nv {
                ad[(row, c)] = self.work.jfeet[(jr, c)];
            }
            self.work.bd[row] = self.work.b_feet[jr];
        }
        // Point tasks' residuals: J q̈ − e = a* − J̇ v.
        for (t, task) in self.work.tasks.points.iter().enumerate() {
            for k in 0..3 {
                let row = l.row_task + 3 * t + k;
                for c in 0..nv {
                    ad[(row, c)] = task.jac[(k, c)];
                }
                ad[(row, l.residual(t, k))] = -1.0;
                self.work.bd[row] = task.target[k];
            }
        }
        // Torque limits: ±(M_a q̈ + h_a − J_c,aᵀ f) ≤ τ_max.
        for (k, &(dof, tmax)) in self.shape.limited.iter().enumerate() {
            let row = l.row_tau + 2 * k;
            for c in 0..nv {
                let x = m[(dof, c)];
                ad[(row, c)] = x;
                ad[(row + 1, c)] = -x;
            }
            for j in 0..3 * N_CONTACTS {
                let x = self.work.jc[(j, dof)];
                ad[(row, nv + j)] = -x;
                ad[(row + 1, nv + j)] = x;
            }
            self.work.bd[row] = tmax - self.work.h[dof];
            self.work.bd[row + 1] = tmax + self.work.h[dof];
        }
        // Friction cones: s = (μ nᵀf, t₁ᵀf, t₂ᵀf) ∈ SOC(3), b = 0.
        for c in 0..N_CONTACTS {
            let rot = &foot_rot[c / 4];
            let row = l.row_soc + 3 * c;
            for a in 0..3 {
                ad[(row, nv + 3 * c + a)] = -self.shape.p.friction * rot[(a, 2)];
                ad[(row + 1, nv + 3 * c + a)] = -rot[(a, 0)];
                ad[(row + 2, nv + 3 * c + a)] = -rot[(a, 1)];
            }
            self.work.bd[row] = 0.0;
            self.work.bd[row + 1] = 0.0;
            self.work.bd[row + 2] = 0.0;
        }

        self.shape
            .p_pattern
            .gather(&self.work.pd, &mut self.work.p_val);
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        if !(finite(&self.work.p_val)
            && finite(&self.work.qd)
            && finite(self.work.ad.as_slice())
            && finite(&self.work.bd))
        {
            return Err(FallbackReason::NonFiniteProblem);
        }
        Ok(())
    }

    /// Solves the assembled full problem into `self.work.x`, first without its torque rows when
    /// `screen`.
    fn run_full(
        &mut self,
        m: &DMatrix<f64>,
        screen: bool,
        solve_time: &mut Duration,
        iterations: &mut u32,
    ) -> Result<bool, FallbackReason> {
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        let nz = self.shape.layout.nz;
        // ---- Constraint screening: the QP without the torque rows is much cheaper
        // (its KKT factor is far sparser); when its optimum satisfies every torque limit it is
        // also the optimum of the full QP (dropping inactive constraints does not move the
        // optimum of a convex problem). Otherwise the full QP is solved. ----
        let mut almost = false;
        let mut accepted = false;
        if let Some(relaxed) = self.work.relaxed.as_mut().filter(|_| screen) {
            let run = relaxed.run(
                &self.shape.p_pattern,
                &self.work.p_val,
                &self.work.qd,
                &self.work.ad,
                &self.work.bd,
                &self.shape.settings,
                self.shape.p.reuse_solver,
                &mut self.info.counters,
            );
            *iterations += relaxed.iterations();
            *solve_time += relaxed.solve_time();
            if let Ok(a) = run {
                let x = relaxed.x();
                let within = self.shape.limited.iter().all(|&(dof, tmax)| {
                    let t = torque(m, &self.work.h, &self.work.jc, x, dof);
                    t.abs() <= tmax
                });
                if within && x.len() == nz && finite(x) {
                    self.work.x.copy_from_slice(x);
                    almost = a;
                    accepted = true;
                }
            }
        }
        if !accepted {
            self.info.counters.torque_limited += u64::from(self.work.relaxed.is_some());
            let run = self.work.full.run(
                &self.shape.p_pattern,
                &self.work.p_val,
                &self.work.qd,
                &self.work.ad,
                &self.work.bd,
                &self.shape.settings,
                self.shape.p.reuse_solver,
                &mut self.info.counters,
            );
            *iterations += self.work.full.iterations();
            *solve_time += self.work.full.solve_time();
            almost = run?;
            let x = self.work.full.x();
            if x.len() != nz || !finite(x) {
                return Err(FallbackReason::NonFiniteSolution);
            }
            self.work.x.copy_from_slice(x);
        }
        Ok(almost)
    }

    fn drop_solvers(&mut self) {
        self.work.condensed.drop_solver();
        self.work.full.solver = None;
        if let Some(r) = self.work.relaxed.as_mut() {
            r.solver = None;
        }
    }

    /// World-aligned Jacobians of the corners (linear rows), soles (6 rows) and hand (linear
    /// rows), from `data.j` and `data.o_m_f`.
    fn build_jacobians(&mut self, model: &Model, data: &Data) {
        let lwa = ReferenceFrame::LocalWorldAligned;
        for (k, &id) in self.shape.foot_ids.iter().enumerate() {
            // Frame ids and sizes were checked at construction: this cannot fail.
            let _ = get_frame_jacobian(model, data, id, lwa, &mut self.work.jtmp);
            self.work
                .jfeet
                .rows_mut(6 * k, 6)
                .copy_from(&self.work.jtmp);
        }
        for (c, &id) in self.shape.corner_ids.iter().enumerate() {
            let k = c / 4;
            if model.frames[id].parent != model.frames[self.shape.foot_ids[k]].parent {
                let _ = get_frame_jacobian(model, data, id, lwa, &mut self.work.jtmp);
                self.work
                    .jc
                    .rows_mut(3 * c, 3)
                    .copy_from(&self.work.jtmp.rows(0, 3));
                continue;
            }
            // On the sole's body: v_corner = v_sole + ω × r, r from the sole to the corner
            // (world axes), one cross product per column instead of a walk up the leg; only on
            // the dofs that move the sole (the others' columns stay the zeros they were made).
            let r = data.o_m_f[id].trans - data.o_m_f[self.shape.foot_ids[k]].trans;
            for &col in &self.shape.foot_dofs[k] {
                let j = self.work.jfeet.column(col);
                let v = Vector3::new(j[6 * k], j[6 * k + 1], j[6 * k + 2]);
                let w = Vector3::new(j[6 * k + 3], j[6 * k + 4], j[6 * k + 5]);
                self.work
                    .jc
                    .fixed_view_mut::<3, 1>(3 * c, col)
                    .copy_from(&(v + w.cross(&r)));
            }
        }
        for t in &mut self.work.tasks.points {
            if let Point::Frame(id) = t.point {
                let _ = get_frame_jacobian(model, data, id, lwa, &mut self.work.jtmp);
                t.jac.copy_from(&self.work.jtmp.rows(0, 3));
            }
        }
    }

    /// The safe torque, written to the output buffers: gravity compensation through the
    /// contacts plus joint damping, clamped to the effort limits.
    ///
    /// The 8 contact forces are the least-norm solution of the floating-base gravity rows
    /// `J_c,uᵀ f = g_u` (the weight shared evenly when standing symmetrically; friction cones
    /// are not enforced), and `τ = g_a − J_c,aᵀ f − D q̇_a`. Returns the torque, or an error when
    /// `(q, v)` are invalid (then the buffers are left as they were).
    pub fn fallback_torque(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
        v: &DVector<f64>,
    ) -> Result<&DVector<f64>, WbcError> {
        model.check_v("v", v)?;
        if model.nv != self.shape.layout.nv {
            return Err(WbcError::Dynamics(DynamicsError::DimensionMismatch {
                what: "model (not the controller's)",
                expected: self.shape.layout.nv,
                got: model.nv,
            }));
        }
        compute_joint_jacobians(model, data, q)?;
        self.build_jacobians(model, data);
        gravity_torques(model, data, q)?;
        let g = &data.tau;
        // f = Aᵀ (A Aᵀ)⁻¹ g_u with A = J_c,uᵀ (6 × 24).
        let mut aat = Matrix6::<f64>::zeros();
        for r in 0..6 {
            for s in 0..6 {
                let mut x = 0.0;
                for j in 0..3 * N_CONTACTS {
                    x += self.work.jc[(j, r)] * self.work.jc[(j, s)];
                }
                aat[(r, s)] = x;
            }
        }
        let gu = Vector6::new(g[0], g[1], g[2], g[3], g[4], g[5]);
        let y = aat
            .cholesky()
            .map(|ch| ch.solve(&gu))
            .ok_or(WbcError::Dynamics(DynamicsError::Singular(
                "contact Jacobian of the fallback",
            )))?;
        let mut f = [0.0; 3 * N_CONTACTS];
        for (j, fj) in f.iter_mut().enumerate() {
            *fj = (0..6).map(|r| self.work.jc[(j, r)] * y[r]).sum();
        }
        for a in 0..self.shape.layout.nv - 6 {
            let d = 6 + a;
            let mut t = g[d] - self.shape.p.fallback_damping * v[d];
            for (j, fj) in f.iter().enumerate() {
                t -= self.work.jc[(j, d)] * fj;
            }
            let lim = self.shape.tau_max[a];
            self.out.tau[a] = t.clamp(-lim, lim);
        }
        for c in 0..N_CONTACTS {
            self.out.forces[c] = Vector3::new(f[3 * c], f[3 * c + 1], f[3 * c + 2]);
        }
        self.out.ddq.fill(0.0);
        Ok(&self.out.tau)
    }

    /// Fallback for a failed tick: [`Self::fallback_torque`], or, if even that cannot be
    /// computed (invalid state), the last QP torque (zeros before any) with damping omitted.
    fn apply_fallback(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
        v: &DVector<f64>,
    ) {
        let ok = self.fallback_torque(model, data, q, v).is_ok()
            && self.out.tau.iter().all(|t| t.is_finite());
        if !ok {
            if self.state.last_tau.iter().all(|t| t.is_finite()) {
                self.out.tau.copy_from(&self.state.last_tau);
            } else {
                self.out.tau.fill(0.0);
            }
            self.out.ddq.fill(0.0);
            self.out.forces = [Vector3::zeros(); N_CONTACTS];
        }
    }
}

/// The full problem with its torque rows, and without them (the screening solve, when some
/// joint has a torque limit), over the same dense scratch.
fn full_problems(
    layout: &Layout,
    a_pattern: Pattern,
    limited: usize,
) -> (QpInstance, Option<QpInstance>) {
    let socs = || (0..N_CONTACTS).map(|_| SupportedConeT::SecondOrderConeT(3));
    let mut cones = vec![SupportedConeT::ZeroConeT(layout.row_tau)];
    if limited > 0 {
        cones.push(SupportedConeT::NonnegativeConeT(2 * limited));
    }
    cones.extend(socs());
    let relaxed = (limited > 0).then(|| {
        let rows: Vec<usize> = (0..layout.row_tau)
            .chain(layout.row_soc..layout.n_rows)
            .collect();
        let pattern = Pattern::from_mask_rows(layout.n_rows, &rows, layout.nz, |r, c| {
            a_pattern.contains(r, c)
        });
        let mut cones = vec![SupportedConeT::ZeroConeT(layout.row_tau)];
        cones.extend(socs());
        QpInstance::new(pattern, rows, cones)
    });
    let full = QpInstance::new(a_pattern, (0..layout.n_rows).collect(), cones);
    (full, relaxed)
}

/// Clarabel's settings for in-place data updates between ticks.
/// A status that says no point satisfies the constraints (within clarabel's tolerances).
fn infeasible(status: clarabel::solver::SolverStatus) -> bool {
    use clarabel::solver::SolverStatus::{AlmostPrimalInfeasible, PrimalInfeasible};
    matches!(status, PrimalInfeasible | AlmostPrimalInfeasible)
}

fn clarabel_settings(config: &WbcConfig) -> DefaultSettings<f64> {
    let tol = config.tolerance;
    DefaultSettings {
        verbose: false,
        max_iter: config.max_iterations,
        tol_gap_abs: tol,
        tol_gap_rel: tol,
        tol_feas: tol,
        // Data updates need the original structure: no presolve, structural zeros kept.
        presolve_enable: false,
        input_sparse_dropzeros: false,
        direct_kkt_solver: true,
        direct_solve_method: "qdldl".to_string(),
        // Iterative refinement of the KKT solves costs ≈ 35 % of the tick here and the
        // tests' accuracy checks (EoM residual, limits, cones) hold without it.
        iterative_refinement_enable: false,
        ..DefaultSettings::default()
    }
}

/// The full problem's constraint sparsity, from the model's structure (structural zeros
/// included, so the pattern never changes): a dof acts on a frame when its joint is on the
/// frame's path to the world, and two dofs couple in M when one's joint is the other's ancestor.
/// Whether dof `dof` moves frame `frame` (its joint is an ancestor of the frame's body): where
/// the frame's Jacobian can be non-zero.
fn moves_frame(model: &Model, dof: usize, frame: usize) -> bool {
    model.frames[frame]
        .parent
        .is_some_and(|p| model.is_ancestor(model.dof_joint[dof], p))
}

fn constraint_pattern(
    model: &Model,
    layout: &Layout,
    tasks: &TaskList,
    foot_ids: &[usize; 2],
    corner_ids: &[usize; N_CONTACTS],
    limited: &[(usize, f64)],
) -> Pattern {
    let supports = |dof: usize, frame: usize| moves_frame(model, dof, frame);
    let m_struct = |a: usize, b: usize| {
        let (ja, jb) = (model.dof_joint[a], model.dof_joint[b]);
        model.is_ancestor(ja, jb) || model.is_ancestor(jb, ja)
    };
    let l = *layout;
    Pattern::from_mask(l.n_rows, l.nz, |r, c| {
        let col = l.column(c);
        if r < l.row_feet {
            // Floating-base rows: M_u is dense, every contact acts on the base.
            !matches!(col, Column::Residual(_))
        } else if r < l.row_task {
            let foot = foot_ids[(r - l.row_feet) / 6];
            matches!(col, Column::Acceleration(d) if supports(d, foot))
        } else if r < l.row_tau {
            // A point task's rows: its Jacobian's columns, −1 on its residual.
            let i = r - l.row_task;
            match col {
                Column::Acceleration(d) => match tasks.points[i / 3].point {
                    Point::Com => true,
                    Point::Frame(f) => supports(d, f),
                },
                Column::Force(_) => false,
                Column::Residual(e) => e == i,
            }
        } else if r < l.row_soc {
            let dof = limited[(r - l.row_tau) / 2].0;
            match col {
                Column::Acceleration(d) => m_struct(dof, d),
                Column::Force(k) => supports(dof, corner_ids[k]),
                Column::Residual(_) => false,
            }
        } else {
            col == Column::Force((r - l.row_soc) / 3)
        }
    })
}

/// The neutral configuration with every bounded 1-DoF joint at the middle of its range.
fn mid_range(model: &Model) -> DVector<f64> {
    let mut q = model.neutral();
    for j in &model.joints {
        let (lo, hi) = (j.limits.lower, j.limits.upper);
        if j.nq() == 1 && lo.is_finite() && hi.is_finite() && lo < hi {
            q[j.idx_q] = 0.5 * (lo + hi);
        }
    }
    q
}

fn mat3_mul_v(j: &DMatrix<f64>, v: &DVector<f64>) -> Vector3<f64> {
    let mut out = Vector3::zeros();
    for c in 0..j.ncols() {
        for r in 0..3 {
            out[r] += j[(r, c)] * v[c];
        }
    }
    out
}

/// Joint damping toward rest, τ_i = −D q̇_i, within each drive's effort limit: the command of
/// every path that runs without the QP (a fallen robot, a bad or a stale state, a failing IPC
/// step), like every other command a drive gets. A rate that is not finite damps nothing; a
/// joint without a limit (∞, or none given) is not clamped.
pub fn damping_torques(damping: f64, qd: &[f64], limits: &[f64], tau: &mut [f64]) {
    for (i, t) in tau.iter_mut().enumerate() {
        let v = qd.get(i).copied().filter(|v| v.is_finite()).unwrap_or(0.0);
        let lim = limits.get(i).copied().unwrap_or(f64::INFINITY);
        *t = (-damping * v).clamp(-lim, lim);
    }
}

#[cfg(test)]
mod damping_tests {
    use super::damping_torques;

    #[test]
    fn damping_stays_within_each_drives_limit() {
        let qd = [2.0, -40.0, f64::NAN, 30.0, -1.0];
        let limits = [10.0, 5.0, 5.0, f64::INFINITY];
        let mut tau = [7.0; 5];
        damping_torques(0.5, &qd, &limits, &mut tau);
        // Within its limit: −D q̇; beyond it: the limit, with the sign of −D q̇; a rate that is
        // not finite: 0; no limit (∞ or none given): −D q̇ as it is.
        assert_eq!(tau, [-1.0, 5.0, 0.0, -15.0, 0.5]);
    }
}
