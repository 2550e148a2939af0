//! The whole-body QP condensed onto the contact forces: the same optimum as the full problem of
//! [`super::controller`], from a QP in the 24 corner forces alone.
//!
//! In the full problem every constraint but the friction cones and the torque limits is an
//! equality, and every cost term but the forces' regularisation is a quadratic in q̈:
//!
//! ```text
//! min_{q̈, f}  ½ q̈ᵀ H q̈ + gᵀ q̈ + ½ w_f ‖f‖²
//! s.t.        C q̈ = d₀ + E f,   C = [M_u; J_s],  d₀ = [−h_u; b_s],  E f = [J_c,uᵀ f; 0]
//!             f ∈ friction cones,  |τ(q̈, f)| ≤ τ_max
//! H = D + Σ_t w_t J_tᵀ J_t,  g = d − Σ_t w_t J_tᵀ r_t     (the point tasks t of `tasks.rs`)
//! ```
//!
//! (D, d: the diagonal posture / base-orientation / regularisation terms; the task residual
//! variables of the full problem are eliminated exactly.) For a fixed f the inner problem in q̈
//! is an equality-constrained least squares with the closed-form solution
//! `q̈(f) = u + H⁻¹Cᵀ S⁻¹ (ρ + E f)`, `u = −H⁻¹ g`, `S = C H⁻¹ Cᵀ`, `ρ = d₀ − C u`, and value
//! `½ (ρ + E f)ᵀ S⁻¹ (ρ + E f)` + const. Only the 6 floating-base rows of E are non-zero, so
//! with `B = J_c,u` (24 × 6, the corners' Jacobian columns of the base) and `X = S⁻¹[:, 0..6]`:
//!
//! ```text
//! min_f  ½ fᵀ (B X_u Bᵀ + w_f I) f + (B (S⁻¹ρ)_u)ᵀ f    s.t. f ∈ cones
//! ```
//!
//! a QP in the 24 forces, given to clarabel with `y = Bᵀ f` as 6 more variables (so P is
//! diagonal but for X_u, and the KKT factor stays sparse): 30 variables, 30 rows, against 68
//! variables and 112 rows with the dense M_u and torque rows in the full problem, whose
//! factorisation took most of the tick. H is the diagonal D plus the point tasks' rank 6, and
//! is factored as such in O(n r²) (`low_rank.rs`); S by a dense Cholesky. Both are symmetric
//! positive definite when the regularisation is positive and the two soles' constraints are
//! independent of the floating-base rows; a failed factorisation is reported and the caller
//! solves the full problem instead.
//!
//! Torque limits are held as equalities, not dropped. A limit active at the optimum,
//! `±(M_j q̈ + h_j − J_c,jᵀ f) = τ_max`, is one more row of `C q̈ = d₀ + E f` (C_j = M_j,
//! d₀_j = ±τ_max − h_j, E_j f = J_c,jᵀ f): q̈ stays free, so the optimum is the full problem's
//! exactly (fixing q̈ to the inner optimum and bounding the torque would shrink the feasible set).
//! Which limits are active is found by a primal-dual active set (`hold_limits`): from the last
//! tick's (else none), each round solves the problem with the held rows exactly (the cone
//! solve, whose dual then has one more dimension per held row), holds each limit the optimum
//! violates and releases each held one whose multiplier λ_j = (S⁻¹(ρ + E f))_j = ∂(optimal cost)/∂d₀_j has the wrong sign (the
//! optimum would move inside the bound). It stops at the KKT point of the problem with its
//! limits. More than [`MAX_LIMITS`] held, or no settled set within [`LIMIT_ROUNDS`], and the
//! full problem (clarabel) decides.

use std::time::{Duration, Instant};

use clarabel::solver::{DefaultSettings, SupportedConeT};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, SMatrix, SVector, Vector6};

use super::cone::{Cone, cone_newton};
use super::dense::{Cholesky, dot};
use super::low_rank::LowRankCholesky;
use super::outcome::{FallbackReason, N_CONTACTS, WbcCounters};
use super::pattern::Pattern;
use super::qp::QpInstance;
use super::tasks::{POINT_TASKS, PointTask};

/// Number of contact force variables.
const NF: usize = 3 * N_CONTACTS;
/// H's rank above its diagonal: 3 per point task.
const RANK: usize = 3 * POINT_TASKS;
/// Rows of C without limits: 6 floating-base rows of the equations of motion, 6 per sole.
const NC: usize = 18;
/// Variables of the reduced QP: the forces and the base wrench error δ (6, see `force_qp`).
const NY: usize = NF + 6;
/// Rows of the reduced QP: `Bᵀ f − δ = y*` (6), then the cones (24).
const ROW_SOC: usize = 6;
const N_ROWS: usize = ROW_SOC + NF;
/// Torque limits held at their bounds at most; a tick with more goes to the full problem. (A
/// robot pushed to its limits holds 1–3 on the default run.)
const MAX_LIMITS: usize = 6;
const NC_MAX: usize = NC + MAX_LIMITS;
/// The cone solve's dimension while limits are held: the 6 base rows and up to [`MAX_LIMITS`]
/// torque rows, padded (see `cone_newton`).
const ND: usize = 6 + MAX_LIMITS;
/// Rounds of the limits' active set before the full problem decides.
const LIMIT_ROUNDS: usize = 8;
/// A limit counts as violated beyond τ_max (1 + this), a held one as released when its
/// multiplier has the wrong sign beyond this times the largest multiplier: rounding alone must
/// not make the active set cycle.
const LIMIT_SLACK: f64 = 1e-9;

/// The data of one tick, as the controller assembled it (world axes, SI).
pub(crate) struct Problem<'a> {
    /// Joint-space mass matrix (full, symmetric) and bias `h` (hand force included).
    pub m: &'a DMatrix<f64>,
    pub h: &'a DVector<f64>,
    /// Corner Jacobians (24 × nv, linear rows, world-aligned) and sole Jacobians (12 × nv).
    pub jc: &'a DMatrix<f64>,
    pub jfeet: &'a DMatrix<f64>,
    /// Right-hand side of the sole rows `J_s q̈ = b_s`.
    pub b_feet: &'a [f64; 12],
    /// Diagonal Hessian and linear term of the q̈ cost terms (posture, base, regularisation).
    pub diag: &'a [f64],
    pub lin: &'a [f64],
    /// The point tasks `½ w ‖J q̈ − r‖²` (the task list's, in its order).
    pub tasks: &'a [PointTask],
    pub w_force: f64,
    pub friction: f64,
    /// Rotation of each sole (its z axis is the contact normal).
    pub foot_rot: [Matrix3<f64>; 2],
    /// The torque-limited dofs (velocity index) and their limits (N·m).
    pub limited: &'a [(usize, f64)],
    /// Try the cone solve (and hold the limits) before clarabel (`wbc.active_set`).
    pub active_set: bool,
}

/// The reduced QP of one tick as clarabel receives it, `min ½ xᵀPx + qᵀx` s.t. `A x + s = b`,
/// s in `zero` equality rows then `soc` second-order cones of dimension 3, for comparing solvers
/// offline (`benches/wbc.rs`, `scripts/qp_compare.py`). Dense, row-major; x = [f / force_unit
/// (24); δ (6)]. Without the torque limits.
#[derive(Debug, Clone)]
pub struct CondensedInstance {
    pub n: usize,
    pub m: usize,
    pub p: Vec<f64>,
    pub q: Vec<f64>,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub zero: usize,
    pub soc: usize,
    pub force_unit: f64,
}

/// Why the condensed problem could not decide the tick (the caller then solves the full
/// problem, except for solver failures, which it reports as they are).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CondensedError {
    /// H or S is not numerically positive definite.
    Factorisation,
    /// The torque limits were not settled: more than [`MAX_LIMITS`] active, an active set that
    /// did not settle, or clarabel's optimum (without limits) violates one.
    Limits,
    Solver(FallbackReason),
}

/// A tick the condensed problem decided.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Condensed {
    /// Clarabel's reduced accuracy (never for the cone solve).
    pub almost: bool,
    /// A torque limit was active at the optimum.
    pub limits: bool,
}

/// How the limits' active set ended.
enum Settled {
    Yes,
    /// The cone solve did not settle without limits held: clarabel decides.
    Unsettled,
    Limits,
}

pub(crate) struct CondensedQp {
    nv: usize,
    /// Unit of the force variables handed to clarabel (N): a corner's share of the weight. In
    /// newtons the forces are 10–100× the other variables and clarabel needed 9 iterations
    /// (p50, perturbed states) instead of 7.
    force_unit: f64,
    /// H = D + Σ w JᵀJ and its factor, in the reversed dof order (below).
    h: LowRankCholesky<RANK>,
    /// Cᵀ, then W = L⁻¹ Cᵀ (nv × (18 + held limits)), reversed order.
    w: DMatrix<f64>,
    /// The first row of each column of W that is not structurally zero.
    w_start: [usize; NC_MAX],
    /// S = C H⁻¹ Cᵀ of the 18 rows without limits (lower triangle), kept unfactored.
    s_base: DMatrix<f64>,
    /// S with k limits held, then its Cholesky factor, at index k.
    s: Vec<Cholesky>,
    /// ρ = d₀ − C u, and S⁻¹ρ (18 + k).
    rho: [f64; NC_MAX],
    s_rho: [f64; NC_MAX],
    /// X = S⁻¹ E_R: the columns of S⁻¹ of the rows the forces enter (the 6 base rows, then the
    /// held limits'), column-major with 18 + k rows.
    xr: [f64; NC_MAX * ND],
    /// The held limits: index into `Problem::limited`, and the bound's sign.
    held: [(usize, f64); MAX_LIMITS],
    n_held: usize,
    /// The last settled tick's held limits, where the next tick's active set starts: a robot
    /// at its limits stays there for a while, and each round saved is a cone solve.
    last_held: [(usize, f64); MAX_LIMITS],
    n_last: usize,
    /// Build the reduced QP (`force_qp`) on every tick, for [`Self::instance`]; otherwise
    /// only for the ticks clarabel solves.
    record: bool,
    /// u = −H⁻¹ g, reversed order.
    u: DVector<f64>,
    /// λ = S⁻¹(ρ + E f): the equality rows' multipliers (18 + k).
    lambda: DVector<f64>,
    /// W λ, then H⁻¹ Cᵀ λ (nv), reversed order.
    tmp: DVector<f64>,
    /// Dense scratch of the reduced QP: P, q, A, b.
    pd: DMatrix<f64>,
    qd: Vec<f64>,
    ad: DMatrix<f64>,
    bd: Vec<f64>,
    p_pattern: Pattern,
    p_val: Vec<f64>,
    qp: QpInstance,
    /// Solution [q̈; f].
    x: Vec<f64>,
    /// τ of every limited dof (indexed by dof) at `x`, as the active set's last round computed
    /// it; `torques_at_x`: whether that round's x is the solution left in `x`. The drives' τ
    /// reads them instead of computing them again (the same operations, the same bits).
    tau: Vec<f64>,
    torques_at_x: bool,
}

impl CondensedQp {
    /// `weight`: the robot's weight (N), which sets the forces' unit.
    pub(crate) fn new(nv: usize, weight: f64) -> Self {
        // P: w_f I on f, X_u (dense 6 × 6) on δ. With B X_u Bᵀ on f directly P would be a dense
        // 24 × 24 block: the auxiliary δ keeps clarabel's KKT factor sparse.
        let p_pattern = Pattern::from_mask(NY, NY, |r, c| r == c || (r >= NF && r <= c));
        let entry = |r: usize, c: usize| {
            if r < ROW_SOC {
                c < NF || c == NF + r
            } else {
                c < NF && (r - ROW_SOC) / 3 == c / 3
            }
        };
        let mut cones = vec![SupportedConeT::ZeroConeT(ROW_SOC)];
        cones.extend((0..N_CONTACTS).map(|_| SupportedConeT::SecondOrderConeT(3)));
        let qp = QpInstance::new(
            Pattern::from_mask(N_ROWS, NY, entry),
            (0..N_ROWS).collect(),
            cones,
        );
        Self {
            nv,
            force_unit: if weight > 0.0 && weight.is_finite() {
                weight / N_CONTACTS as f64
            } else {
                1.0
            },
            h: LowRankCholesky::new(nv),
            w: DMatrix::zeros(nv, NC_MAX),
            w_start: [0; NC_MAX],
            s_base: DMatrix::zeros(NC, NC),
            s: (0..=MAX_LIMITS).map(|k| Cholesky::new(NC + k)).collect(),
            rho: [0.0; NC_MAX],
            s_rho: [0.0; NC_MAX],
            xr: [0.0; NC_MAX * ND],
            held: [(0, 0.0); MAX_LIMITS],
            n_held: 0,
            last_held: [(0, 0.0); MAX_LIMITS],
            n_last: 0,
            record: false,
            u: DVector::zeros(nv),
            lambda: DVector::zeros(NC_MAX),
            tmp: DVector::zeros(nv),
            pd: DMatrix::zeros(NY, NY),
            qd: vec![0.0; NY],
            ad: DMatrix::zeros(N_ROWS, NY),
            bd: vec![0.0; N_ROWS],
            p_val: vec![0.0; p_pattern.nnz()],
            p_pattern,
            qp,
            x: vec![0.0; nv + NF],
            tau: vec![0.0; nv],
            torques_at_x: false,
        }
    }

    /// Build the reduced QP on every tick from now on, for [`Self::instance`] (offline use:
    /// each tick then starts its limits' active set from none).
    pub(crate) fn record(&mut self) {
        self.record = true;
    }

    /// The reduced QP of the last tick that built one (allocates: offline use).
    pub(crate) fn instance(&self) -> CondensedInstance {
        let row_major = |m: &DMatrix<f64>| m.transpose().as_slice().to_vec();
        CondensedInstance {
            n: NY,
            m: N_ROWS,
            p: row_major(&self.pd),
            q: self.qd.clone(),
            a: row_major(&self.ad),
            b: self.bd.clone(),
            zero: ROW_SOC,
            soc: N_CONTACTS,
            force_unit: self.force_unit,
        }
    }

    /// Forgets the last tick's held limits (a new session starts its active set from none).
    pub(crate) fn forget(&mut self) {
        self.n_last = 0;
    }

    /// Drops the clarabel solver (the next solve builds a fresh one).
    pub(crate) fn drop_solver(&mut self) {
        self.qp.solver = None;
    }

    pub(crate) fn has_solver(&self) -> bool {
        self.qp.solver.is_some()
    }

    /// The solution `[q̈ (nv); f (24)]` of the last successful [`Self::solve`].
    pub(crate) fn x(&self) -> &[f64] {
        &self.x
    }

    /// [`joint_torque`] of every limited dof at [`Self::x`] (indexed by dof), when the active
    /// set settled the last solve (`None` otherwise).
    pub(crate) fn limited_torques(&self) -> Option<&[f64]> {
        self.torques_at_x.then_some(&self.tau[..])
    }

    /// Solves the tick's problem with its torque limits: by the cone solve and the limits'
    /// active set, else by clarabel when no limit is active. The solution `[q̈; f]` is left in
    /// [`Self::x`].
    pub(crate) fn solve(
        &mut self,
        pb: &Problem,
        settings: &DefaultSettings<f64>,
        reuse: bool,
        counters: &mut WbcCounters,
        iterations: &mut u32,
        solve_time: &mut Duration,
    ) -> Result<Condensed, CondensedError> {
        self.torques_at_x = false;
        self.unconstrained(pb)?;
        self.schur_complement(pb)?;
        // The rows to start from: the last settled tick's held limits (a robot at its limits
        // stays there for a while, and each round saved is a cone solve), else none. None when
        // the tick's reduced QP is recorded: that is the problem without limits.
        let warm = pb.active_set
            && !self.record
            && self.last_held[..self.n_last]
                .iter()
                .all(|&(idx, _)| idx < pb.limited.len());
        self.n_held = if warm { self.n_last } else { 0 };
        self.held = self.last_held;
        if !self.hold_rows(pb) {
            if self.n_held == 0 {
                return Err(CondensedError::Factorisation);
            }
            self.n_held = 0;
            if !self.hold_rows(pb) {
                return Err(CondensedError::Factorisation);
            }
        }
        if self.record {
            self.force_qp(pb)?;
        }
        if pb.active_set {
            let started = Instant::now();
            let settled = self.hold_limits(pb, counters);
            *solve_time += started.elapsed();
            self.n_last = 0;
            match settled {
                Settled::Yes => {
                    // The last round's update_held computed every limited τ at this x.
                    self.torques_at_x = true;
                    let limits = self.n_held > 0;
                    self.last_held = self.held;
                    self.n_last = self.n_held;
                    counters.active_set += 1;
                    counters.limits_condensed += u64::from(limits);
                    return Ok(Condensed {
                        almost: false,
                        limits,
                    });
                }
                // No limit held (`hold_limits`): the rows are the reduced QP's.
                Settled::Unsettled => counters.cone_unsettled += 1,
                Settled::Limits => return Err(CondensedError::Limits),
            }
        }
        if !self.record {
            self.force_qp(pb)?;
        }
        let run = self.qp.run(
            &self.p_pattern,
            &self.p_val,
            &self.qd,
            &self.ad,
            &self.bd,
            settings,
            reuse,
            counters,
        );
        *iterations += self.qp.iterations();
        *solve_time += self.qp.solve_time();
        let almost = run.map_err(CondensedError::Solver)?;
        let x = self.qp.x();
        if x.len() != NY {
            return Err(CondensedError::Solver(FallbackReason::NonFiniteSolution));
        }
        let mut f = [0.0; NF];
        for (fk, xk) in f.iter_mut().zip(x) {
            *fk = xk * self.force_unit;
        }
        // Clarabel's problem holds no limit (`force_qp` at n_held = 0).
        self.n_held = 0;
        self.recover(pb, &f);
        let within = pb
            .limited
            .iter()
            .all(|&(dof, tmax)| joint_torque(pb.m, pb.h, pb.jc, &self.x, dof).abs() <= tmax);
        if !within {
            return Err(CondensedError::Limits);
        }
        Ok(Condensed {
            almost,
            limits: false,
        })
    }

    /// H (factored: `H = L D̄ Lᵀ`) and `u = −H⁻¹ g`: the optimum of the q̈ cost terms alone.
    ///
    /// H, u, W and the solves are in the reversed dof order (row i' is dof nv − 1 − i'). A
    /// sole's rows of C touch the base and its leg only, which come first in a depth-first
    /// model: reversed, its column of Cᵀ is zero down to the last 12–18 rows, and so is its
    /// column of W = L⁻¹ Cᵀ, whose substitution skips them, as do S's dot products.
    fn unconstrained(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        let nv = self.nv;
        // H = D + Σ w JᵀJ as its diagonal and the tasks' stacked Jacobian (`low_rank.rs`): row
        // i' is dof nv − 1 − i'.
        if pb.tasks.len() != POINT_TASKS {
            return Err(CondensedError::Factorisation);
        }
        for (i, d) in self.h.d.iter_mut().enumerate() {
            *d = pb.diag[nv - 1 - i];
        }
        for (t, task) in pb.tasks.iter().enumerate() {
            let j = task.jac.as_slice();
            self.h.w[3 * t..3 * t + 3].fill(task.weight);
            for c in 0..nv {
                self.h.v[nv - 1 - c][3 * t..3 * t + 3].copy_from_slice(&j[3 * c..3 * c + 3]);
            }
        }
        // g = d − Σ w Jᵀ r, u = −H⁻¹ g.
        for i in 0..nv {
            self.u[nv - 1 - i] = -pb.lin[i];
        }
        for t in pb.tasks {
            let (j, r, w) = (&t.jac, &t.target, t.weight);
            for c in 0..nv {
                self.u[nv - 1 - c] += w * (j[(0, c)] * r[0] + j[(1, c)] * r[1] + j[(2, c)] * r[2]);
            }
        }
        if !self.h.factor() {
            return Err(CondensedError::Factorisation);
        }
        self.h.solve(self.u.as_mut_slice());
        Ok(())
    }

    /// Of the 18 equality rows without limits, at the unconstrained optimum: ρ = d₀ − C u,
    /// W = L⁻¹ Cᵀ and S = Wᵀ W (lower triangle, kept unfactored for `hold_rows`).
    fn schur_complement(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        let nv = self.nv;
        // Cᵀ = [M[:, 0..6], J_sᵀ] (M symmetric), d₀ = [−h_u; b_s]; by slices (W's columns,
        // M's columns and J_s's rows 12 apart), reversed.
        let (w, u) = (self.w.as_mut_slice(), self.u.as_slice());
        let (m, jf) = (pb.m.as_slice(), pb.jfeet.as_slice());
        for c in 0..6 {
            let col = &mut w[c * nv..(c + 1) * nv];
            for (x, y) in col.iter_mut().zip(m[c * nv..(c + 1) * nv].iter().rev()) {
                *x = *y;
            }
            self.rho[c] = -pb.h[c];
        }
        for r in 0..12 {
            // Row r of J_s (12 × nv, column-major: entries 12 apart), reversed.
            let col = &mut w[(6 + r) * nv..(7 + r) * nv];
            for (i, x) in col.iter_mut().enumerate() {
                *x = jf[r + 12 * (nv - 1 - i)];
            }
            self.rho[6 + r] = pb.b_feet[r];
        }
        for (r, col) in w.chunks_exact_mut(nv).take(NC).enumerate() {
            // ρ = d₀ − C u; W = L⁻¹ Cᵀ below is zero where Cᵀ is zero above.
            self.rho[r] -= dot(col, u);
            self.w_start[r] = leading_zeros(col);
        }
        // All 18 columns in one pass: their recursions overlap (`low_rank.rs`).
        self.h
            .solve_lower_from(&mut w[..NC * nv], &self.w_start[..NC]);
        for c in 0..NC {
            for r in c..NC {
                self.s_base[(r, c)] = w_dot(&self.w, &self.w_start, r, c);
            }
        }
        if !self.s_base.as_slice().iter().all(|x| x.is_finite()) {
            return Err(CondensedError::Solver(FallbackReason::NonFiniteProblem));
        }
        Ok(())
    }

    /// The equality rows with the held limits (`self.held[..n_held]`): their rows of W and ρ,
    /// S's factor, S⁻¹ρ and X = S⁻¹ E_R. `false` when S is not positive definite.
    fn hold_rows(&mut self, pb: &Problem) -> bool {
        let (nv, k) = (self.nv, self.n_held);
        let n = NC + k;
        for (i, &(idx, sign)) in self.held[..k].iter().enumerate() {
            let (dof, tmax) = pb.limited[idx];
            // The row M_j (M symmetric: its column j), d₀_j = ±τ_max − h_j.
            let m_j = &pb.m.as_slice()[dof * nv..(dof + 1) * nv];
            let col = &mut self.w.as_mut_slice()[(NC + i) * nv..(NC + i + 1) * nv];
            for (x, m) in col.iter_mut().zip(m_j.iter().rev()) {
                *x = *m;
            }
            self.rho[NC + i] = sign * tmax - pb.h[dof] - dot(col, self.u.as_slice());
            self.w_start[NC + i] = leading_zeros(col);
            self.h.solve_lower(col);
        }
        let s = &mut self.s[k];
        for c in 0..NC {
            for r in c..NC {
                s.l[(r, c)] = self.s_base[(r, c)];
            }
        }
        for r in NC..n {
            for c in 0..=r {
                s.l[(r, c)] = w_dot(&self.w, &self.w_start, r, c);
            }
        }
        if !s.factor() {
            return false;
        }
        self.s_rho[..n].copy_from_slice(&self.rho[..n]);
        s.solve(&mut self.s_rho[..n]);
        let m = 6 + k;
        let xr = &mut self.xr[..n * m];
        xr.fill(0.0);
        for a in 0..m {
            xr[a * n + row_of(a)] = 1.0;
        }
        s.solve(xr);
        true
    }

    /// The limits' primal-dual active set (module docs), from the rows `solve` held: `Yes`
    /// leaves the solution in `self.x` with `self.held` the active limits.
    fn hold_limits(&mut self, pb: &Problem, counters: &mut WbcCounters) -> Settled {
        for round in 0..LIMIT_ROUNDS {
            if round > 0 && !self.hold_rows(pb) {
                return Settled::Limits;
            }
            let solved = if self.n_held == 0 {
                self.cone_solve::<6>(pb)
            } else {
                self.cone_solve::<ND>(pb)
            };
            let Some((f, steps)) = solved else {
                return if self.n_held == 0 {
                    Settled::Unsettled
                } else {
                    Settled::Limits
                };
            };
            counters.cone_steps += steps as u64;
            self.recover(pb, &f);
            match self.update_held(pb) {
                Some(false) => return Settled::Yes,
                Some(true) => {}
                None => return Settled::Limits,
            }
        }
        Settled::Limits
    }

    /// One round's change of the held limits: releases those whose multiplier has the wrong
    /// sign, holds those the solution violates. `Some(changed)`, `None` beyond [`MAX_LIMITS`].
    fn update_held(&mut self, pb: &Problem) -> Option<bool> {
        let k = self.n_held;
        let n = NC + k;
        let was = self.held;
        let slack = LIMIT_SLACK * self.lambda.rows(0, n).amax();
        let mut kept = 0;
        for i in 0..k {
            // ∂cost/∂τ_max = sign · λ: a held bound that does not hold the optimum back.
            let (_, sign) = was[i];
            if sign * self.lambda[NC + i] <= slack {
                self.held[kept] = was[i];
                kept += 1;
            }
        }
        let mut changed = kept < k;
        // Limits held this round are judged by their multipliers only: the solution sits on
        // their bounds, within rounding.
        for (idx, &(dof, tmax)) in pb.limited.iter().enumerate() {
            let tau = joint_torque(pb.m, pb.h, pb.jc, &self.x, dof);
            self.tau[dof] = tau;
            if was[..k].iter().any(|&(j, _)| j == idx) {
                continue;
            }
            if tau.abs() > tmax * (1.0 + LIMIT_SLACK) {
                if kept == MAX_LIMITS {
                    return None;
                }
                self.held[kept] = (idx, tau.signum());
                kept += 1;
                changed = true;
            }
        }
        self.n_held = kept;
        Some(changed)
    }

    /// The cone solve (`cone.rs`) on the rows held now, in D ≥ 6 + n_held dimensions; the
    /// forces and the Newton steps.
    fn cone_solve<const D: usize>(&self, pb: &Problem) -> Option<([f64; NF], usize)> {
        // Both positive (NaN is not).
        let positive = |x: f64| x > 0.0;
        if !positive(pb.w_force) || !positive(pb.friction) {
            return None;
        }
        let (k, n) = (self.n_held, NC + self.n_held);
        let m = 6 + k;
        // X_RR, padded with I (the padded rows' z then stays 0), and (S⁻¹ρ)_R.
        let mut x = SMatrix::<f64, D, D>::identity();
        let mut s_rho = SVector::<f64, D>::zeros();
        for b in 0..m {
            for a in 0..m {
                x[(a, b)] = self.xr[b * n + row_of(a)];
            }
            s_rho[b] = self.s_rho[row_of(b)];
        }
        let factor = x.cholesky()?;
        let y_star = -factor.solve(&s_rho);
        let base = factor.inverse() * pb.w_force;
        let bk: [SMatrix<f64, 3, D>; N_CONTACTS] = std::array::from_fn(|c| {
            SMatrix::from_fn(|i, a| {
                if a < m {
                    pb.jc[(3 * c + i, self.column_of(pb, a))]
                } else {
                    0.0
                }
            })
        });
        let cones: [Cone; N_CONTACTS] = std::array::from_fn(|c| Cone {
            rot: &pb.foot_rot[c / 4],
            mu: pb.friction,
        });
        let (f, _, steps) = cone_newton(&bk, &base, &y_star, &cones)?;
        let mut out = [0.0; NF];
        for (c, fc) in f.iter().enumerate() {
            out[3 * c..3 * c + 3].copy_from_slice(fc.as_slice());
        }
        Some((out, steps))
    }

    /// The dof whose Jacobian column is B's column `a` (the base's 6, then the held limits').
    fn column_of(&self, pb: &Problem, a: usize) -> usize {
        if a < 6 {
            a
        } else {
            pb.limited[self.held[a - 6].0].0
        }
    }

    /// The QP in the forces handed to clarabel (from `hold_rows` with no limit held): P, the
    /// rows `Bᵀ f − δ = y*` and the friction cones, scaled by the force unit.
    fn force_qp(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        // B = J_c,u. The cost ½ fᵀ (B X_u Bᵀ + w_f I) f + ((S⁻¹ρ)_u)ᵀ Bᵀ f is, up to a
        // constant, ½ δᵀ X_u δ + ½ w_f ‖f‖² with δ = Bᵀ f − y*, y* = −X_u⁻¹ (S⁻¹ρ)_u: the
        // contacts' wrench on the base against the one the tasks ask for. Written so (δ as 6
        // more variables, rows Bᵀ f − δ = y*), P is diagonal but for X_u, the KKT factor stays
        // sparse, and the objective is on the scale of the task errors: with the linear term
        // instead, its value (≈ 10⁵ here) made clarabel's relative gap tolerance 10⁵× looser
        // on the forces than in the full problem.
        let fu = self.force_unit;
        let xu = Matrix6::from_fn(|r, c| self.xr[c * NC + r]);
        let rho_u = Vector6::from_column_slice(&self.s_rho[..6]);
        let y_star = -xu
            .cholesky()
            .ok_or(CondensedError::Factorisation)?
            .solve(&rho_u);
        for k in 0..NF {
            for c in 0..6 {
                self.ad[(c, k)] = pb.jc[(k, c)] * fu;
            }
            self.pd[(k, k)] = pb.w_force * fu * fu;
        }
        for r in 0..6 {
            for c in 0..6 {
                self.pd[(NF + r, NF + c)] = xu[(r, c)];
            }
            self.ad[(r, NF + r)] = -1.0;
            self.bd[r] = y_star[r];
        }
        self.p_pattern.gather(&self.pd, &mut self.p_val);
        // Friction cones: s = (μ nᵀf, t₁ᵀf, t₂ᵀf) ∈ SOC(3), b = 0.
        for c in 0..N_CONTACTS {
            let rot = &pb.foot_rot[c / 4];
            let row = ROW_SOC + 3 * c;
            for a in 0..3 {
                self.ad[(row, 3 * c + a)] = -pb.friction * rot[(a, 2)] * fu;
                self.ad[(row + 1, 3 * c + a)] = -rot[(a, 0)] * fu;
                self.ad[(row + 2, 3 * c + a)] = -rot[(a, 1)] * fu;
            }
        }
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        if !(finite(&self.p_val) && finite(&self.bd) && finite(self.ad.as_slice())) {
            return Err(CondensedError::Solver(FallbackReason::NonFiniteProblem));
        }
        Ok(())
    }

    /// `x = [q̈(f); f]` with `q̈(f) = u + H⁻¹Cᵀ λ`, λ = S⁻¹ρ + X Bᵀ f, for the rows held now.
    fn recover(&mut self, pb: &Problem, f: &[f64; NF]) {
        let (nv, k) = (self.nv, self.n_held);
        let (n, m) = (NC + k, 6 + k);
        self.lambda.rows_mut(0, n).copy_from_slice(&self.s_rho[..n]);
        for a in 0..m {
            let col = self.column_of(pb, a);
            let btf: f64 = (0..NF).map(|j| pb.jc[(j, col)] * f[j]).sum();
            for (l, x) in self.lambda.iter_mut().zip(&self.xr[a * n..(a + 1) * n]) {
                *l += x * btf;
            }
        }
        self.tmp
            .gemv(1.0, &self.w.columns(0, n), &self.lambda.rows(0, n), 0.0);
        self.h.solve_upper(self.tmp.as_mut_slice());
        for i in 0..nv {
            self.x[i] = self.u[nv - 1 - i] + self.tmp[nv - 1 - i];
        }
        self.x[nv..].copy_from_slice(f);
    }
}

/// Columns r and c of W (`nv` rows, their first non-zero rows `start`) dotted, over the rows
/// where both can be non-zero.
fn w_dot(w: &DMatrix<f64>, start: &[usize], r: usize, c: usize) -> f64 {
    let (nv, w) = (w.nrows(), w.as_slice());
    let from = start[r].max(start[c]);
    dot(
        &w[r * nv + from..(r + 1) * nv],
        &w[c * nv + from..(c + 1) * nv],
    )
}

/// The number of zeros `col` starts with.
fn leading_zeros(col: &[f64]) -> usize {
    col.iter().position(|&x| x != 0.0).unwrap_or(col.len())
}

/// The row of C (and S) of the reduced problem's equality `a`: the 6 base rows, then the held
/// limits' rows after the soles'.
fn row_of(a: usize) -> usize {
    if a < 6 { a } else { NC + a - 6 }
}

/// `τ_d = M[d, :] q̈ + h_d − Σ J_c[:, d]ᵀ f` from a solution `x = [q̈, f, …]`.
pub(crate) fn joint_torque(
    m: &DMatrix<f64>,
    h: &DVector<f64>,
    jc: &DMatrix<f64>,
    x: &[f64],
    d: usize,
) -> f64 {
    let nv = m.ncols();
    // M symmetric: its row d is its (contiguous) column d; J_c's column d too (24 × nv,
    // column-major), dotted with the forces in four partial sums.
    let jc_d = &jc.as_slice()[d * NF..(d + 1) * NF];
    h[d] + dot(&m.as_slice()[d * nv..(d + 1) * nv], &x[..nv]) - dot(jc_d, &x[nv..nv + NF])
}
