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
//! factorisation took most of the tick. H and S are
//! factored by Cholesky (both are symmetric positive definite when the regularisation is
//! positive and the two soles' constraints are independent of the floating-base rows); a
//! failed factorisation is reported and the caller solves the full problem instead.
//!
//! Torque limits are not condensed: they bound `M_a q̈ + h_a − J_c,aᵀ f`, q̈ and f together,
//! and fixing q̈ to the inner optimum `q̈(f)` would shrink the feasible set (a tick at its limits
//! then came out infeasible where the full problem is not). The caller checks the limits at
//! this problem's optimum, which is the full problem's when none is violated (dropping
//! inactive constraints does not move a convex optimum), and otherwise solves the full one.

use std::time::Duration;

use clarabel::solver::{DefaultSettings, SupportedConeT};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Vector3, Vector6};

use super::dense::{Cholesky, dot};
use super::outcome::{FallbackReason, N_CONTACTS, WbcCounters};
use super::pattern::Pattern;
use super::qp::QpInstance;
use super::tasks::PointTask;

/// Number of contact force variables.
const NF: usize = 3 * N_CONTACTS;
/// Rows of C: 6 floating-base rows of the equations of motion, 6 per sole.
const NC: usize = 18;
/// Variables of the reduced QP: the forces and the base wrench error δ (6, see `reduce`).
const NY: usize = NF + 6;
/// Rows of the reduced QP: `Bᵀ f − δ = y*` (6), then the cones (24).
const ROW_SOC: usize = 6;
const N_ROWS: usize = ROW_SOC + NF;
/// Active-set rounds tried before clarabel decides (see `active_set_optimum`).
const ACTIVE_SET_ROUNDS: usize = 4;

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
    /// Try the active-set solve before clarabel (`wbc.active_set`).
    pub active_set: bool,
}

/// The reduced QP of one tick as clarabel receives it, `min ½ xᵀPx + qᵀx` s.t. `A x + s = b`,
/// s in `zero` equality rows then `soc` second-order cones of dimension 3, for comparing solvers
/// offline (`benches/wbc.rs`, `scripts/qp_compare.py`). Dense, row-major; x = [f / force_unit
/// (24); δ (6)].
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

/// Why the condensed problem could not be solved (the caller then solves the full problem,
/// except for solver failures, which it reports as they are).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CondensedError {
    /// H or S is not numerically positive definite.
    Factorisation,
    Solver(FallbackReason),
}

pub(crate) struct CondensedQp {
    nv: usize,
    /// Unit of the force variables handed to clarabel (N): a corner's share of the weight. In
    /// newtons the forces are 10–100× the other variables and clarabel needed 9 iterations
    /// (p50, perturbed states) instead of 7.
    force_unit: f64,
    /// H, then its Cholesky factor L (lower triangle).
    h: Cholesky,
    /// Cᵀ, then W = L⁻¹ Cᵀ (nv × 18).
    w: DMatrix<f64>,
    /// S = Wᵀ W, then its Cholesky factor (18 × 18).
    s: Cholesky,
    /// X = S⁻¹[:, 0..6] (18 × 6).
    x6: DMatrix<f64>,
    /// B = J_c,u (24 × 6).
    b: DMatrix<f64>,
    /// X_u⁻¹, from `force_qp`'s factor of X_u, for the active-set solve (y* is `bd[..6]`).
    xu_inv: Matrix6<f64>,
    /// u = −H⁻¹ g, then q̈.
    u: DVector<f64>,
    /// ρ, then S⁻¹ ρ; and the 18-vector combining it with the forces.
    rho: DVector<f64>,
    z: DVector<f64>,
    /// W z, then H⁻¹ Cᵀ z (nv).
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
            h: Cholesky::new(nv),
            w: DMatrix::zeros(nv, NC),
            s: Cholesky::new(NC),
            x6: DMatrix::zeros(NC, 6),
            b: DMatrix::zeros(NF, 6),
            xu_inv: Matrix6::zeros(),
            u: DVector::zeros(nv),
            rho: DVector::zeros(NC),
            z: DVector::zeros(NC),
            tmp: DVector::zeros(nv),
            pd: DMatrix::zeros(NY, NY),
            qd: vec![0.0; NY],
            ad: DMatrix::zeros(N_ROWS, NY),
            bd: vec![0.0; N_ROWS],
            p_val: vec![0.0; p_pattern.nnz()],
            p_pattern,
            qp,
            x: vec![0.0; nv + NF],
        }
    }

    /// The last reduced QP (allocates: offline use).
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

    /// Solves the tick's problem without the torque limits. `Ok(almost_solved)` leaves
    /// `[q̈; f]` in [`Self::x`].
    pub(crate) fn solve(
        &mut self,
        pb: &Problem,
        settings: &DefaultSettings<f64>,
        reuse: bool,
        counters: &mut WbcCounters,
        iterations: &mut u32,
        solve_time: &mut Duration,
    ) -> Result<bool, CondensedError> {
        self.reduce(pb)?;
        if let Some(f) = pb.active_set.then(|| self.active_set_optimum(pb)).flatten() {
            counters.active_set += 1;
            self.recover(&f);
            return Ok(false);
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
        self.recover(&f);
        Ok(almost)
    }

    /// Builds the reduced QP's P, q, cone rows from the tick's data (see the module docs): the
    /// unconstrained optimum in q̈, the equality rows' Schur complement, then the QP in f.
    fn reduce(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        self.unconstrained(pb)?;
        self.schur_complement(pb)?;
        self.force_qp(pb)
    }

    /// H (factored in place into L) and `u = −H⁻¹ g`: the optimum of the q̈ cost terms alone.
    fn unconstrained(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        let nv = self.nv;
        // H = D + Σ w JᵀJ, lower triangle (all the Cholesky reads): per task, down contiguous
        // columns of H (a task's Jacobian is 3 × nv, column-major).
        {
            let h = self.h.l.as_mut_slice();
            h.fill(0.0);
            for t in pb.tasks {
                let (j, w) = (t.jac.as_slice(), t.weight);
                for c in 0..nv {
                    let jc = &j[3 * c..3 * c + 3];
                    let (a0, a1, a2) = (w * jc[0], w * jc[1], w * jc[2]);
                    let col = &mut h[c * nv + c..(c + 1) * nv];
                    for (x, jr) in col.iter_mut().zip(j[3 * c..].chunks_exact(3)) {
                        *x += a0 * jr[0] + a1 * jr[1] + a2 * jr[2];
                    }
                }
            }
            for c in 0..nv {
                h[c + c * nv] += pb.diag[c];
            }
        }
        // g = d − Σ w Jᵀ r, u = −H⁻¹ g.
        for i in 0..nv {
            self.u[i] = -pb.lin[i];
        }
        for t in pb.tasks {
            let (j, r, w) = (&t.jac, &t.target, t.weight);
            for c in 0..nv {
                self.u[c] += w * (j[(0, c)] * r[0] + j[(1, c)] * r[1] + j[(2, c)] * r[2]);
            }
        }
        if !self.h.factor() {
            return Err(CondensedError::Factorisation);
        }
        self.h.solve(self.u.as_mut_slice());
        Ok(())
    }

    /// Of the equality rows `C q̈ = d₀ + E f` at the unconstrained optimum: ρ = d₀ − C u,
    /// W = L⁻¹ Cᵀ, S = Wᵀ W (factored in place), then S⁻¹ ρ and X = S⁻¹[:, 0..6].
    fn schur_complement(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        let nv = self.nv;
        // Cᵀ = [M[:, 0..6], J_sᵀ] (M symmetric), d₀ = [−h_u; b_s].
        for c in 0..6 {
            for i in 0..nv {
                self.w[(i, c)] = pb.m[(i, c)];
            }
            self.rho[c] = -pb.h[c];
        }
        for r in 0..12 {
            for i in 0..nv {
                self.w[(i, 6 + r)] = pb.jfeet[(r, i)];
            }
            self.rho[6 + r] = pb.b_feet[r];
        }
        // ρ = d₀ − C u.
        self.rho.gemv_tr(-1.0, &self.w, &self.u, 1.0);
        // W = L⁻¹ Cᵀ, S = Wᵀ W = C H⁻¹ Cᵀ.
        self.h.solve_lower(self.w.as_mut_slice());
        // S = Wᵀ W, lower triangle.
        for c in 0..NC {
            let wc = &self.w.as_slice()[c * nv..(c + 1) * nv];
            for r in c..NC {
                let wr = &self.w.as_slice()[r * nv..(r + 1) * nv];
                self.s.l[(r, c)] = dot(wr, wc);
            }
        }
        if !self.s.factor() {
            return Err(CondensedError::Factorisation);
        }
        // S⁻¹ ρ and X = S⁻¹[:, 0..6].
        self.s.solve(self.rho.as_mut_slice());
        self.x6.fill(0.0);
        for k in 0..6 {
            self.x6[(k, k)] = 1.0;
        }
        self.s.solve(self.x6.as_mut_slice());
        Ok(())
    }

    /// The QP in the forces handed to clarabel: P, the rows `Bᵀ f − δ = y*` and the friction
    /// cones, scaled by the force unit.
    fn force_qp(&mut self, pb: &Problem) -> Result<(), CondensedError> {
        // B = J_c,u. The cost ½ fᵀ (B X_u Bᵀ + w_f I) f + ((S⁻¹ρ)_u)ᵀ Bᵀ f is, up to a
        // constant, ½ δᵀ X_u δ + ½ w_f ‖f‖² with δ = Bᵀ f − y*, y* = −X_u⁻¹ (S⁻¹ρ)_u: the
        // contacts' wrench on the base against the one the tasks ask for. Written so (δ as 6
        // more variables, rows Bᵀ f − δ = y*), P is diagonal but for X_u, the KKT factor stays
        // sparse, and the objective is on the scale of the task errors: with the linear term
        // instead, its value (≈ 10⁵ here) made clarabel's relative gap tolerance 10⁵× looser
        // on the forces than in the full problem.
        let fu = self.force_unit;
        let mut xu = Matrix6::zeros();
        for r in 0..6 {
            for c in 0..6 {
                xu[(r, c)] = self.x6[(r, c)];
            }
        }
        let rho_u = Vector6::new(
            self.rho[0],
            self.rho[1],
            self.rho[2],
            self.rho[3],
            self.rho[4],
            self.rho[5],
        );
        let xu_factor = xu.cholesky().ok_or(CondensedError::Factorisation)?;
        let y_star = -xu_factor.solve(&rho_u);
        self.xu_inv = xu_factor.inverse();
        for k in 0..NF {
            for c in 0..6 {
                self.b[(k, c)] = pb.jc[(k, c)];
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

    /// The reduced QP's exact optimum when no friction cone is active on its boundary: every
    /// corner either inside its cone or unloaded (f = 0, the cone's apex). For a set U of
    /// unloaded corners, the optimum of ½ w_f ‖f‖² + ½ δᵀ X_u δ on `Bᵀ f − δ = y*` with those
    /// forces zero is `f_k = b_k z` for the loaded corners (b_k: B's rows of corner k) with
    /// `(w_f X_u⁻¹ + Σ_loaded b_kᵀ b_k) z = y*`, and its multipliers are X_u δ = −w_f z, so an
    /// unloaded corner's is `λ_k = −w_f b_k z`. The KKT conditions of the convex QP, loaded
    /// forces in their cones and unloaded corners' λ_k in the dual cone (λ_n ≥ μ ‖λ_t‖), make it
    /// the optimum. U starts empty; corners pulling (f_n < 0) are unloaded and corners whose λ
    /// leaves the dual cone loaded again, for a few rounds. `None` when a cone is active on its
    /// boundary (a corner at its friction limit) or the rounds do not settle: clarabel decides.
    fn active_set_optimum(&self, pb: &Problem) -> Option<[f64; NF]> {
        if pb.w_force <= 0.0 || pb.w_force.is_nan() {
            return None;
        }
        let base = self.xu_inv * pb.w_force;
        let y_star = Vector6::from_column_slice(&self.bd[..ROW_SOC]);
        let mut unloaded = [false; N_CONTACTS];
        let mut f = [0.0; NF];
        for _ in 0..ACTIVE_SET_ROUNDS {
            let mut m = base;
            for k in (0..NF).filter(|k| !unloaded[k / 3]) {
                for r in 0..6 {
                    for c in 0..6 {
                        m[(r, c)] += self.b[(k, r)] * self.b[(k, c)];
                    }
                }
            }
            let z = m.cholesky()?.solve(&y_star);
            let (mut changed, mut at_friction_limit) = (false, false);
            for c in 0..N_CONTACTS {
                let rot = &pb.foot_rot[c / 4];
                // b_c z: the corner's force if loaded; −λ_c / w_f if unloaded.
                let bz =
                    Vector3::from_fn(|a, _| (0..6).map(|j| self.b[(3 * c + a, j)] * z[j]).sum());
                let (n, t) = (
                    rot.column(2).dot(&bz),
                    rot.column(0).dot(&bz).hypot(rot.column(1).dot(&bz)),
                );
                if unloaded[c] {
                    // λ = −w_f b_c z must satisfy λ_n ≥ μ ‖λ_t‖.
                    if -n < pb.friction * t {
                        unloaded[c] = false;
                        changed = true;
                    }
                } else if n < 0.0 {
                    unloaded[c] = true;
                    changed = true;
                } else {
                    at_friction_limit |= pb.friction * n < t;
                }
                for a in 0..3 {
                    f[3 * c + a] = if unloaded[c] { 0.0 } else { bz[a] };
                }
            }
            // A friction limit is judged once the set of unloaded corners has settled: unloading
            // a pulling corner moves the others' forces.
            if !changed {
                let finite = f.iter().all(|x| x.is_finite());
                return (finite && !at_friction_limit).then_some(f);
            }
        }
        None
    }

    /// `x = [q̈(f); f]` with `q̈(f) = u + H⁻¹Cᵀ (S⁻¹ρ + X Bᵀ f)`.
    fn recover(&mut self, f: &[f64; NF]) {
        let nv = self.nv;
        self.z.copy_from(&self.rho);
        for c in 0..6 {
            let btf: f64 = (0..NF).map(|k| self.b[(k, c)] * f[k]).sum();
            for r in 0..NC {
                self.z[r] += self.x6[(r, c)] * btf;
            }
        }
        self.tmp.gemv(1.0, &self.w, &self.z, 0.0);
        self.h.solve_upper(self.tmp.as_mut_slice());
        for i in 0..nv {
            self.x[i] = self.u[i] + self.tmp[i];
        }
        self.x[nv..].copy_from_slice(f);
    }
}
