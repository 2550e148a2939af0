//! The constraint solver of a time step: contacts with Coulomb friction, bilateral point
//! constraints (the hand–door spherical joint) and unilateral joint limits, all at the velocity
//! level (Moreau–Jean / Anitescu–Stewart time stepping).
//!
//! With `M = LᵀDL` factorised ([`LtdlFactor`]), the impulses `λ` solve
//!
//! ```text
//!   u = W λ + b,   W = J M⁻¹ Jᵀ + R,   b = J v* − u_target
//! ```
//!
//! where `v*` is the unconstrained end-of-step velocity and `u` the constraint velocity at the
//! end of the step, subject per block to:
//! - contact (rows n, t₁, t₂): `λ_n ≥ 0`, `u_n ≥ 0`, `λ_n u_n = 0`; `‖λ_t‖ ≤ μ λ_n` with
//!   `u_t = 0` inside the cone and `u_t` opposed to `λ_t` on its boundary (exact Coulomb, no
//!   Anitescu lift-off);
//! - bilateral (3 rows): `u = 0`;
//! - unilateral (1 row): `λ ≥ 0`, `u ≥ 0`, `λ u = 0`.
//!
//! `W` is built as the Gram matrix of `D^{-1/2} L⁻ᵀ Jᵀ` (one sparse triangular pass per row) and
//! `R = ε diag(W)` is a tiny regularisation that makes redundant contacts (four corners of a
//! rigid sole) well posed. First every row is assumed at zero velocity (all contacts sticking)
//! and `W λ = −b` solved directly; if that `λ` is admissible it is the solution
//! ([`ConstraintSystem::solve_all_stick`]: a robot standing still, where Gauss–Seidel converges
//! slowly). Otherwise the blocks are solved by projected block Gauss–Seidel, warm-started from
//! the previous step's impulses by the caller. Everything is preallocated: no allocation per
//! step.

use nalgebra::{DMatrix, DVector, Matrix3, Vector2, Vector3};

use super::factor::LtdlFactor;

/// Kind of a constraint block.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BlockKind {
    /// Unilateral contact with Coulomb friction μ: rows (normal, tangent 1, tangent 2).
    Contact { mu: f64 },
    /// Three bilateral rows (a spherical joint / point-to-point constraint).
    Bilateral3,
    /// One unilateral row (a joint limit).
    Unilateral,
}

impl BlockKind {
    pub fn dim(self) -> usize {
        match self {
            BlockKind::Contact { .. } | BlockKind::Bilateral3 => 3,
            BlockKind::Unilateral => 1,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Block {
    kind: BlockKind,
    row: usize,
    /// Inverse of the diagonal block of `W` (top-left `dim × dim` used).
    inv: Matrix3<f64>,
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverSettings {
    /// Gauss–Seidel sweeps at most.
    pub max_iterations: usize,
    /// Stop when no impulse changes by more than this in a sweep (N·s).
    pub tolerance: f64,
    /// Relative diagonal regularisation ε of `W`.
    pub regularisation: f64,
}

/// Result of [`ConstraintSystem::solve`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolveStats {
    /// Gauss–Seidel sweeps (0 when the direct all-stick solve was the solution).
    pub iterations: usize,
    /// The solution came from the direct all-stick solve.
    pub direct: bool,
    /// Largest impulse change in the last sweep (N·s).
    pub last_change: f64,
}

/// Preallocated constraint rows, Delassus matrix and impulses for up to `max_rows` rows.
#[derive(Clone, Debug)]
pub struct ConstraintSystem {
    nv: usize,
    max_rows: usize,
    rows: usize,
    blocks: Vec<Block>,
    /// `Jᵀ`: one column per constraint row (nv × max_rows).
    pub jt: DMatrix<f64>,
    xt: DMatrix<f64>,
    /// Delassus matrix `W` (top-left rows × rows valid after [`ConstraintSystem::assemble`]).
    pub w: DMatrix<f64>,
    /// `b = J v* − u_target`.
    pub bias: DVector<f64>,
    /// Impulses (N·s), one per row.
    pub lambda: DVector<f64>,
    /// Cholesky factor of `W` and right-hand side of the direct all-stick solve.
    chol: DMatrix<f64>,
    rhs: DVector<f64>,
}

impl ConstraintSystem {
    pub fn new(nv: usize, max_rows: usize) -> Self {
        Self {
            nv,
            max_rows,
            rows: 0,
            blocks: Vec::with_capacity(max_rows),
            jt: DMatrix::zeros(nv, max_rows),
            xt: DMatrix::zeros(nv, max_rows),
            w: DMatrix::zeros(max_rows, max_rows),
            bias: DVector::zeros(max_rows),
            lambda: DVector::zeros(max_rows),
            chol: DMatrix::zeros(max_rows, max_rows),
            rhs: DVector::zeros(max_rows),
        }
    }

    /// Rows in use.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Removes every block (keeps the storage).
    pub fn clear(&mut self) {
        self.rows = 0;
        self.blocks.clear();
    }

    /// Appends a block; returns its first row, or `None` when the capacity is exhausted. Its
    /// `Jᵀ` columns, bias and impulses are zeroed.
    pub fn push(&mut self, kind: BlockKind) -> Option<usize> {
        let d = kind.dim();
        if self.rows + d > self.max_rows {
            return None;
        }
        let row = self.rows;
        self.rows += d;
        for r in row..row + d {
            self.jt.column_mut(r).fill(0.0);
            self.bias[r] = 0.0;
            self.lambda[r] = 0.0;
        }
        self.blocks.push(Block {
            kind,
            row,
            inv: Matrix3::zeros(),
        });
        Some(row)
    }

    /// Builds `W = J M⁻¹ Jᵀ + ε diag` from the rows' `Jᵀ` and the factor of `M`, and inverts
    /// the diagonal blocks.
    pub fn assemble(&mut self, factor: &LtdlFactor, regularisation: f64) {
        let (m, nv) = (self.rows, self.nv);
        if m == 0 {
            return;
        }
        {
            let src = &self.jt.as_slice()[..m * nv];
            let dst = &mut self.xt.as_mut_slice()[..m * nv];
            dst.copy_from_slice(src);
            for r in 0..m {
                factor.half_solve(&mut dst[r * nv..(r + 1) * nv]);
            }
        }
        let xt = self.xt.columns(0, m);
        self.w.view_mut((0, 0), (m, m)).gemm_tr(1.0, &xt, &xt, 0.0);
        for r in 0..m {
            let d = self.w[(r, r)];
            self.w[(r, r)] = d + regularisation * d + 1e-14;
        }
        for b in &mut self.blocks {
            let r = b.row;
            b.inv = match b.kind {
                BlockKind::Unilateral => {
                    let mut i = Matrix3::zeros();
                    i[(0, 0)] = 1.0 / self.w[(r, r)];
                    i
                }
                _ => {
                    let blk: Matrix3<f64> = self.w.fixed_view::<3, 3>(r, r).into_owned();
                    blk.try_inverse()
                        .unwrap_or_else(|| Matrix3::from_diagonal(&blk.diagonal().map(|d| 1.0 / d)))
                }
            };
        }
    }

    #[inline]
    fn row_velocity(&self, r: usize) -> f64 {
        let m = self.rows;
        // W is symmetric: row r = column r (contiguous).
        let col = &self.w.as_slice()[r * self.max_rows..r * self.max_rows + m];
        let lam = &self.lambda.as_slice()[..m];
        let mut acc = self.bias[r];
        for k in 0..m {
            acc += col[k] * lam[k];
        }
        acc
    }

    /// The impulses: first the direct all-stick guess ([`ConstraintSystem::solve_all_stick`]);
    /// if it is not admissible, projected block Gauss–Seidel from the impulses currently in
    /// `lambda` (warm start).
    pub fn solve(&mut self, settings: &SolverSettings) -> SolveStats {
        let mut stats = SolveStats::default();
        if self.rows == 0 {
            return stats;
        }
        if self.solve_all_stick() {
            stats.direct = true;
            return stats;
        }
        self.gauss_seidel(settings)
    }

    /// Projected block Gauss–Seidel from the impulses in `lambda`.
    pub fn gauss_seidel(&mut self, settings: &SolverSettings) -> SolveStats {
        let mut stats = SolveStats::default();
        if self.rows == 0 {
            return stats;
        }
        for it in 0..settings.max_iterations.max(1) {
            let mut change: f64 = 0.0;
            for bi in 0..self.blocks.len() {
                let b = self.blocks[bi];
                let r = b.row;
                match b.kind {
                    BlockKind::Unilateral => {
                        let u = self.row_velocity(r);
                        let old = self.lambda[r];
                        let new = (old - b.inv[(0, 0)] * u).max(0.0);
                        change = change.max((new - old).abs());
                        self.lambda[r] = new;
                    }
                    BlockKind::Bilateral3 => {
                        let u = Vector3::new(
                            self.row_velocity(r),
                            self.row_velocity(r + 1),
                            self.row_velocity(r + 2),
                        );
                        let old =
                            Vector3::new(self.lambda[r], self.lambda[r + 1], self.lambda[r + 2]);
                        let new = old - b.inv * u;
                        change = change.max((new - old).amax());
                        self.lambda.fixed_rows_mut::<3>(r).copy_from(&new);
                    }
                    BlockKind::Contact { mu } => {
                        let u = Vector3::new(
                            self.row_velocity(r),
                            self.row_velocity(r + 1),
                            self.row_velocity(r + 2),
                        );
                        let old =
                            Vector3::new(self.lambda[r], self.lambda[r + 1], self.lambda[r + 2]);
                        let new = project_contact(&old, &u, &b.inv, &self.w, r, mu);
                        change = change.max((new - old).amax());
                        self.lambda.fixed_rows_mut::<3>(r).copy_from(&new);
                    }
                }
            }
            stats.iterations = it + 1;
            stats.last_change = change;
            if change <= settings.tolerance {
                break;
            }
        }
        stats
    }

    /// Every row at zero velocity (contacts sticking, limits engaged): `W λ = −b` by a dense
    /// Cholesky factorisation (`W` is positive definite thanks to `R`). If every contact impulse
    /// is then in its cone with `λ_n > 0` and every limit impulse `≥ 0`, `λ` satisfies all the
    /// complementarity conditions with `u = 0`: it is the solution (unique, `W` being positive
    /// definite) that Gauss–Seidel would only approach, and it is written to `lambda`.
    /// Otherwise `lambda` is left as it was and `false` returned. Why: under a rigid sole the
    /// load sharing between corners is nearly indeterminate (`W` conditioned like `1/ε`), so
    /// Gauss–Seidel converges slowly exactly in the common case of a robot standing still,
    /// where this single `m³/3` factorisation solves it exactly (the active-set guess of
    /// direct LCP methods, e.g. Júdice & Pires, or the "stick first" guess of Kaufman et al.).
    pub fn solve_all_stick(&mut self) -> bool {
        let m = self.rows;
        let c = &mut self.chol;
        // Lower Cholesky of W (top-left m × m), in place, column by column.
        for j in 0..m {
            let mut d = self.w[(j, j)];
            for k in 0..j {
                d -= c[(j, k)] * c[(j, k)];
            }
            if !(d > 0.0 && d.is_finite()) {
                return false;
            }
            let d = d.sqrt();
            c[(j, j)] = d;
            for i in j + 1..m {
                let mut s = self.w[(i, j)];
                for k in 0..j {
                    s -= c[(i, k)] * c[(j, k)];
                }
                c[(i, j)] = s / d;
            }
        }
        // Forward and back substitution of L Lᵀ x = −b.
        let x = &mut self.rhs;
        for i in 0..m {
            let mut s = -self.bias[i];
            for k in 0..i {
                s -= c[(i, k)] * x[k];
            }
            x[i] = s / c[(i, i)];
        }
        for i in (0..m).rev() {
            let mut s = x[i];
            for k in i + 1..m {
                s -= c[(k, i)] * x[k];
            }
            x[i] = s / c[(i, i)];
        }
        let admissible = self.blocks.iter().all(|b| {
            let r = b.row;
            match b.kind {
                BlockKind::Contact { mu } => {
                    x[r] > 0.0 && x[r + 1].hypot(x[r + 2]) <= mu * x[r] && x[r].is_finite()
                }
                BlockKind::Bilateral3 => x.rows(r, 3).iter().all(|v| v.is_finite()),
                BlockKind::Unilateral => x[r] >= 0.0 && x[r].is_finite(),
            }
        });
        if admissible {
            self.lambda.rows_mut(0, m).copy_from(&x.rows(0, m));
        }
        admissible
    }

    /// `out = Jᵀ λ` (generalised impulse), length nv.
    pub fn generalized_impulse(&self, out: &mut DVector<f64>) {
        let m = self.rows;
        out.gemv(1.0, &self.jt.columns(0, m), &self.lambda.rows(0, m), 0.0);
    }
}

/// One contact's Gauss–Seidel update. First the exact 3×3 sticking solution; if it leaves the
/// cone, the normal row is solved alone and the tangential impulse is moved against the
/// tangential velocity and clamped to the cone's boundary (maximal dissipation at the fixed point).
#[inline]
fn project_contact(
    old: &Vector3<f64>,
    u: &Vector3<f64>,
    inv: &Matrix3<f64>,
    w: &DMatrix<f64>,
    r: usize,
    mu: f64,
) -> Vector3<f64> {
    let cand = old - inv * u;
    if cand.x <= 0.0 {
        return Vector3::zeros();
    }
    let ct = Vector2::new(cand.y, cand.z);
    if ct.norm() <= mu * cand.x {
        return cand;
    }
    let wn = w[(r, r)];
    let ln = (old.x - u.x / wn).max(0.0);
    if ln == 0.0 {
        return Vector3::zeros();
    }
    let wt = w[(r + 1, r + 1)].max(w[(r + 2, r + 2)]);
    let mut t = Vector2::new(old.y - u.y / wt, old.z - u.z / wt);
    let lim = mu * ln;
    let nt = t.norm();
    if nt > lim {
        t *= lim / nt;
    }
    Vector3::new(ln, t.x, t.y)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point mass on the ground: one contact, identity mass matrix.
    fn point_mass(mu: f64, v_star: Vector3<f64>) -> (ConstraintSystem, Vector3<f64>) {
        let mut f = LtdlFactor::new(vec![None, None, None]).unwrap();
        f.matrix_mut().fill_with_identity();
        f.factor().unwrap();
        let mut s = ConstraintSystem::new(3, 3);
        let r = s.push(BlockKind::Contact { mu }).unwrap();
        // rows: normal z, tangents x, y.
        s.jt[(2, r)] = 1.0;
        s.jt[(0, r + 1)] = 1.0;
        s.jt[(1, r + 2)] = 1.0;
        s.bias[r] = v_star.z;
        s.bias[r + 1] = v_star.x;
        s.bias[r + 2] = v_star.y;
        s.assemble(&f, 0.0);
        s.solve(&SolverSettings {
            max_iterations: 100,
            tolerance: 1e-14,
            regularisation: 0.0,
        });
        let l = Vector3::new(s.lambda[r], s.lambda[r + 1], s.lambda[r + 2]);
        (s, l)
    }

    /// A free cube (mass 2, unit-ish inertia) resting on its 4 bottom corners, pushed sideways:
    /// the load sharing is statically indeterminate, resolved by the regularisation.
    fn resting_cube(push: f64, mu: f64, regularisation: f64) -> ConstraintSystem {
        // Dofs: linear x, y, z, angular x, y, z (a chain, so the tree factor is a dense one).
        let mut f =
            LtdlFactor::new(vec![None, Some(0), Some(1), Some(2), Some(3), Some(4)]).unwrap();
        let m = f.matrix_mut();
        m.fill(0.0);
        for (k, d) in [2.0, 2.0, 2.0, 0.03, 0.04, 0.05].iter().enumerate() {
            m[(k, k)] = *d;
        }
        f.factor().unwrap();
        let mut s = ConstraintSystem::new(6, 12);
        let v_star = Vector3::new(push, 0.0, -9.81e-3);
        for (px, py) in [(0.1, 0.1), (0.1, -0.1), (-0.1, 0.1), (-0.12, -0.1)] {
            let p = Vector3::new(px, py, -0.1);
            let r = s.push(BlockKind::Contact { mu }).unwrap();
            for (k, axis) in [Vector3::z(), Vector3::x(), Vector3::y()]
                .iter()
                .enumerate()
            {
                // u = axis · (v + ω × p) = axis · v + (p × axis) · ω.
                let a = p.cross(axis);
                for i in 0..3 {
                    s.jt[(i, r + k)] = axis[i];
                    s.jt[(3 + i, r + k)] = a[i];
                }
                s.bias[r + k] = axis.dot(&v_star);
            }
        }
        s.assemble(&f, regularisation);
        s
    }

    #[test]
    fn the_all_stick_solve_is_the_gauss_seidel_fixed_point() {
        let settings = SolverSettings {
            max_iterations: 200_000,
            tolerance: 1e-15,
            regularisation: 1e-3,
        };
        let mut direct = resting_cube(0.002, 0.8, settings.regularisation);
        let stats = direct.solve(&settings);
        assert!(stats.direct && stats.iterations == 0, "{stats:?}");
        let mut pgs = resting_cube(0.002, 0.8, settings.regularisation);
        let stats = pgs.gauss_seidel(&settings);
        assert!(stats.last_change <= 1e-15, "{stats:?}");
        let m = direct.rows();
        let err = (direct.lambda.rows(0, m) - pgs.lambda.rows(0, m)).amax();
        assert!(err < 1e-10, "direct vs Gauss–Seidel: {err:e}");
        // Pushed harder than friction allows: the guess is not admissible, Gauss–Seidel runs.
        let mut slide = resting_cube(0.5, 0.2, settings.regularisation);
        let stats = slide.solve(&settings);
        assert!(!stats.direct && stats.iterations > 0, "{stats:?}");
    }

    #[test]
    fn sticks_inside_and_slides_outside_the_cone() {
        // Falling at 1 m/s, sliding at 0.3 m/s: μ = 0.5 stops it (0.3 ≤ 0.5·1).
        let (_, l) = point_mass(0.5, Vector3::new(0.3, 0.0, -1.0));
        assert!((l - Vector3::new(1.0, -0.3, 0.0)).norm() < 1e-9, "{l}");
        // μ = 0.2 cannot: the friction saturates against the motion.
        let (_, l) = point_mass(0.2, Vector3::new(0.3, 0.0, -1.0));
        assert!((l.x - 1.0).abs() < 1e-9 && (l.y + 0.2).abs() < 1e-9, "{l}");
        // Separating: no impulse.
        let (_, l) = point_mass(0.5, Vector3::new(0.3, 0.0, 1.0));
        assert_eq!(l, Vector3::zeros());
    }
}
