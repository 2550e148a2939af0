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
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Matrix6, Vector3, Vector6};

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
/// Newton steps of the cone solve before clarabel decides (see `cone_optimum`); on the default
/// run it takes 2 a tick on average (`wbc_cone_steps`).
const NEWTON_STEPS: usize = 30;
/// The cone solve's stop: the equality's residual (N, N·m) relative to 1 + |y*|∞.
const NEWTON_TOLERANCE: f64 = 1e-10;
/// Armijo's sufficient decrease, and the shortest step before giving up.
const ARMIJO: f64 = 1e-4;
const MIN_STEP: f64 = 1e-10;

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
    /// Try the cone solve before clarabel (`wbc.active_set`).
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
    /// B = J_c,u (24 × 6), by corner: b_k, its 3 rows of corner k.
    bk: [Matrix3x6<f64>; N_CONTACTS],
    /// X_u⁻¹, from `force_qp`'s factor of X_u, for the cone solve (y* is `bd[..6]`).
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
            bk: [Matrix3x6::zeros(); N_CONTACTS],
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
        let started = std::time::Instant::now();
        let cone = pb.active_set.then(|| self.cone_optimum(pb));
        *solve_time += started.elapsed();
        counters.cone_unsettled += u64::from(matches!(cone, Some(None)));
        if let Some(Some((f, steps))) = cone {
            counters.active_set += 1;
            counters.cone_steps += steps as u64;
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
                self.bk[k / 3][(k % 3, c)] = pb.jc[(k, c)];
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

    /// The reduced QP's exact optimum by a semismooth Newton method on its dual
    /// (docs/whole_body_qp.md, "The cone solve"). With ν = w_f z the multiplier of
    /// `Bᵀ f − δ = y*`, the forces minimising the Lagrangian are f_k = Π_k(b_k z) (b_k: B's rows
    /// of corner k, Π_k the projection onto its friction cone) and δ = −w_f X_u⁻¹ z, so the dual
    /// is the minimisation of the convex, C¹
    ///
    /// ```text
    /// ψ(z) = ½ w_f zᵀ X_u⁻¹ z − zᵀ y* + ½ Σ_k ‖Π_k(b_k z)‖²,
    /// ∇ψ(z) = w_f X_u⁻¹ z − y* + Σ_k b_kᵀ Π_k(b_k z) = −(Bᵀ f − δ − y*),
    /// ```
    ///
    /// whose zero is the optimum: f in its cones by construction, complementarity by the
    /// projection (Moreau), and ∇ψ the residual of the one equality. Newton steps with the
    /// generalised Hessian `w_f X_u⁻¹ + Σ_k b_kᵀ J_k b_k` (J_k: Π_k's Jacobian, I inside the
    /// cone, 0 for an unloaded corner, a rank-2 matrix for a corner sliding on the boundary)
    /// and an Armijo backtracking on ψ. From z = 0 the first step is the all-loaded solution of
    /// the former active-set solve. `None` when the steps do not settle within
    /// [`NEWTON_STEPS`] (clarabel decides).
    fn cone_optimum(&self, pb: &Problem) -> Option<([f64; NF], usize)> {
        // Both positive (NaN is not).
        let positive = |x: f64| x > 0.0;
        if !positive(pb.w_force) || !positive(pb.friction) {
            return None;
        }
        let cones: [Cone; N_CONTACTS] = std::array::from_fn(|c| Cone {
            rot: &pb.foot_rot[c / 4],
            mu: pb.friction,
        });
        let y_star = Vector6::from_column_slice(&self.bd[..ROW_SOC]);
        let (f, _, steps) = cone_newton(&self.bk, &(self.xu_inv * pb.w_force), &y_star, &cones)?;
        let mut out = [0.0; NF];
        for (c, fc) in f.iter().enumerate() {
            out[3 * c..3 * c + 3].copy_from_slice(fc.as_slice());
        }
        Some((out, steps))
    }

    /// `x = [q̈(f); f]` with `q̈(f) = u + H⁻¹Cᵀ (S⁻¹ρ + X Bᵀ f)`.
    fn recover(&mut self, f: &[f64; NF]) {
        let nv = self.nv;
        self.z.copy_from(&self.rho);
        let mut btf = Vector6::zeros();
        for (b, fc) in self.bk.iter().zip(f.chunks_exact(3)) {
            btf += b.transpose() * Vector3::from_column_slice(fc);
        }
        for c in 0..6 {
            for r in 0..NC {
                self.z[r] += self.x6[(r, c)] * btf[c];
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

/// The semismooth Newton iteration of [`CondensedQp::cone_optimum`]: minimises ψ for
/// `base` = w_f X_u⁻¹; the forces, the dual z and the steps taken.
fn cone_newton(
    bk: &[Matrix3x6<f64>; N_CONTACTS],
    base: &Matrix6<f64>,
    y_star: &Vector6<f64>,
    cones: &[Cone; N_CONTACTS],
) -> Option<([Vector3<f64>; N_CONTACTS], Vector6<f64>, usize)> {
    let tol = NEWTON_TOLERANCE * (1.0 + y_star.amax());
    // ψ and the forces at z.
    let psi = |z: &Vector6<f64>, f: &mut [Vector3<f64>; N_CONTACTS]| {
        let mut v = 0.5 * z.dot(&(base * z)) - z.dot(y_star);
        for (c, fc) in f.iter_mut().enumerate() {
            *fc = cones[c].project(&(bk[c] * z));
            v += 0.5 * fc.norm_squared();
        }
        v
    };
    let mut z = Vector6::zeros();
    let mut f = [Vector3::zeros(); N_CONTACTS];
    let mut value = psi(&z, &mut f);
    for step in 0..NEWTON_STEPS {
        let mut grad = base * z - y_star;
        for (b, fc) in bk.iter().zip(&f) {
            grad += b.transpose() * fc;
        }
        if !grad.iter().all(|g| g.is_finite()) {
            return None;
        }
        if grad.amax() <= tol {
            return Some((f, z, step));
        }
        let mut hess = *base;
        for (b, cone) in bk.iter().zip(cones) {
            // At z = 0 every corner counts as loaded (J = I): the first step is the all-loaded
            // solution.
            let jac = if step == 0 {
                Some(Matrix3::identity())
            } else {
                cone.jacobian(&(b * z))
            };
            if let Some(j) = jac {
                hess += b.transpose() * (j * b);
            }
        }
        let dz = -hess.cholesky()?.solve(&grad);
        let slope = grad.dot(&dz);
        let mut t = 1.0;
        let mut trial_f = [Vector3::zeros(); N_CONTACTS];
        loop {
            let trial = z + dz * t;
            let v = psi(&trial, &mut trial_f);
            // Near the optimum ψ's decrease falls below its rounding (|ψ| ≈ 10⁴ here, the
            // decrease 10⁻¹²) while the gradient still shrinks quadratically: a step that changes
            // ψ by no more than its rounding is taken, and the gradient decides.
            let rounding = 1e-13 * value.abs().max(1.0);
            if v <= value + ARMIJO * t * slope || (t == 1.0 && (v - value).abs() <= rounding) {
                z = trial;
                value = v;
                f = trial_f;
                break;
            }
            t *= 0.5;
            if t < MIN_STEP {
                return None;
            }
        }
    }
    None
}

/// A corner's friction cone `‖f_t‖ ≤ μ f_n`, the sole's z axis its normal.
struct Cone<'a> {
    rot: &'a Matrix3<f64>,
    mu: f64,
}

/// Where a vector lies against a cone: inside, in the polar cone (projected to the apex), or
/// between (projected onto the boundary ray in its plane with the normal).
enum Piece {
    Inside,
    Apex,
    /// Tangential direction (unit, sole axes), its length, and the projection's normal force.
    Boundary {
        dir: [f64; 2],
        r: f64,
        a: f64,
    },
}

impl Cone<'_> {
    fn piece(&self, v: &Vector3<f64>) -> Piece {
        let l = self.rot.transpose() * v;
        let (r, n) = (l.x.hypot(l.y), l.z);
        if r <= self.mu * n {
            Piece::Inside
        } else if self.mu * r <= -n {
            Piece::Apex
        } else {
            // The boundary ray (μ x̂, 1): the projection is its direction times
            // (μ r + n) / (1 + μ²).
            Piece::Boundary {
                dir: [l.x / r, l.y / r],
                r,
                a: (self.mu * r + n) / (1.0 + self.mu * self.mu),
            }
        }
    }

    /// The Euclidean projection of `v` (world axes) onto the cone.
    fn project(&self, v: &Vector3<f64>) -> Vector3<f64> {
        match self.piece(v) {
            Piece::Inside => *v,
            Piece::Apex => Vector3::zeros(),
            Piece::Boundary { dir, a, .. } => {
                self.rot * Vector3::new(a * self.mu * dir[0], a * self.mu * dir[1], a)
            }
        }
    }

    /// The projection's Jacobian at `v` (world axes); `None` where it is zero (the apex).
    /// On the boundary piece, in sole axes: `w wᵀ / (1 + μ²) + (a μ / r) (I₂ − x̂ x̂ᵀ)` with
    /// `w = (μ x̂, 1)`.
    fn jacobian(&self, v: &Vector3<f64>) -> Option<Matrix3<f64>> {
        match self.piece(v) {
            Piece::Inside => Some(Matrix3::identity()),
            Piece::Apex => None,
            Piece::Boundary { dir, r, a } => {
                let mu = self.mu;
                let w = Vector3::new(mu * dir[0], mu * dir[1], 1.0);
                let mut j = w * w.transpose() / (1.0 + mu * mu);
                let k = a * mu / r;
                for p in 0..2 {
                    for q in 0..2 {
                        let delta = if p == q { 1.0 } else { 0.0 };
                        j[(p, q)] += k * (delta - dir[p] * dir[q]);
                    }
                }
                Some(self.rot * j * self.rot.transpose())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tilted() -> Matrix3<f64> {
        *nalgebra::Rotation3::from_euler_angles(0.2, -0.1, 0.7).matrix()
    }

    /// The projection is the nearest point of the cone: its residual lies in the polar cone and
    /// is orthogonal to it (Moreau), on each piece.
    #[test]
    fn the_cone_projection_is_moreaus() {
        let rot = tilted();
        let cone = Cone { rot: &rot, mu: 0.6 };
        let mut pieces = [0; 3];
        for i in 0..200 {
            let x = i as f64;
            let v = Vector3::new((1.3 * x).sin(), (0.7 * x).cos(), 3.0 * (0.37 * x).sin()) * 10.0;
            pieces[match cone.piece(&v) {
                Piece::Inside => 0,
                Piece::Apex => 1,
                Piece::Boundary { .. } => 2,
            }] += 1;
            let p = cone.project(&v);
            let l = rot.transpose() * p;
            assert!(l.x.hypot(l.y) <= 0.6 * l.z + 1e-12);
            let res = v - p;
            assert!(res.dot(&p).abs() < 1e-10, "{v:?}");
            // The polar cone: −res in the cone of aperture 1/μ.
            let lr = rot.transpose() * -res;
            assert!(lr.x.hypot(lr.y) <= lr.z / 0.6 + 1e-10 || res.norm() < 1e-12);
        }
        assert!(pieces.iter().all(|&n| n > 10), "{pieces:?}");
    }

    /// The Newton solve's optimum is certified by a zero duality gap: its forces lie in their
    /// cones, and the primal cost ½ w_f ‖f‖² + ½ δᵀ X_u δ (δ = Bᵀ f − y*) equals the dual's
    /// −w_f ψ(z), which bounds every feasible cost from below. Over problems that load every
    /// corner, unload some and slide some on their cones' boundaries.
    #[test]
    fn the_cone_solve_closes_the_duality_gap() {
        let rot = [tilted(), Matrix3::identity()];
        let mu = 0.5;
        let cones: [Cone; N_CONTACTS] = std::array::from_fn(|c| Cone {
            rot: &rot[c / 4],
            mu,
        });
        let w_f = 1e-3;
        let mut seen = [0; 3];
        for trial in 0..60 {
            let x = trial as f64;
            let wave = |k: f64| (x * 0.77 + k * 1.31).sin();
            // Corners on a 0.2 × 0.1 m rectangle per foot, feet 0.2 m apart: b_k maps the dual
            // wrench z (force, moment) to the corner, as B = J_c,u does.
            let mut bk = [Matrix3x6::zeros(); N_CONTACTS];
            for (c, b) in bk.iter_mut().enumerate() {
                let p = Vector3::new(
                    if c % 2 == 0 { 0.1 } else { -0.1 },
                    if c % 4 < 2 { 0.05 } else { -0.05 } + if c < 4 { 0.1 } else { -0.1 },
                    -0.8,
                );
                b.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&Matrix3::identity());
                b.fixed_view_mut::<3, 3>(0, 3).copy_from(&-p.cross_matrix());
            }
            let a = Matrix6::from_fn(|r, c| wave((r * 6 + c) as f64));
            let xu = a * a.transpose() * 0.01 + Matrix6::identity() * 1e-3;
            let y_star = Vector6::new(
                60.0 * wave(40.0),
                60.0 * wave(41.0),
                300.0 + 100.0 * wave(42.0),
                20.0 * wave(43.0),
                20.0 * wave(44.0),
                5.0 * wave(45.0),
            );
            let base = xu.try_inverse().unwrap() * w_f;
            let (f, z, _) = cone_newton(&bk, &base, &y_star, &cones).expect("converges");
            let mut btf = Vector6::zeros();
            let mut primal = 0.0;
            for (c, fc) in f.iter().enumerate() {
                let l = rot[c / 4].transpose() * fc;
                assert!(l.x.hypot(l.y) <= mu * l.z * (1.0 + 1e-12) + 1e-12);
                seen[match cones[c].piece(&(bk[c] * z)) {
                    Piece::Inside => 0,
                    Piece::Apex => 1,
                    Piece::Boundary { .. } => 2,
                }] += 1;
                btf += bk[c].transpose() * fc;
                primal += 0.5 * w_f * fc.norm_squared();
            }
            let delta = btf - y_star;
            primal += 0.5 * delta.dot(&(xu * delta));
            let mut psi = 0.5 * z.dot(&(base * z)) - z.dot(&y_star);
            for c in 0..N_CONTACTS {
                psi += 0.5 * cones[c].project(&(bk[c] * z)).norm_squared();
            }
            let dual = -w_f * psi;
            assert!(
                (primal - dual).abs() <= 1e-9 * primal.abs().max(1.0),
                "trial {trial}: primal {primal}, dual {dual}"
            );
        }
        assert!(seen.iter().all(|&n| n > 20), "{seen:?}");
    }

    /// The Jacobian against central differences of the projection, off the pieces' seams.
    #[test]
    fn the_cone_projections_jacobian_is_its_derivative() {
        let rot = tilted();
        let cone = Cone { rot: &rot, mu: 0.6 };
        let h = 1e-6;
        for i in 0..200 {
            let x = i as f64;
            let v = Vector3::new((1.1 * x).cos(), (0.9 * x).sin(), (0.53 * x).cos()) * 5.0;
            let j = cone.jacobian(&v).unwrap_or_else(Matrix3::zeros);
            for k in 0..3 {
                let mut e = Vector3::zeros();
                e[k] = h;
                let fd = (cone.project(&(v + e)) - cone.project(&(v - e))) / (2.0 * h);
                assert!(
                    (fd - j.column(k)).amax() < 1e-6,
                    "{v:?}: {fd:?} vs {:?}",
                    j.column(k)
                );
            }
        }
    }
}
