//! The cone solve: the exact optimum of the condensed QP in the contact forces (`condensed.rs`)
//! by a semismooth Newton method on its dual, whose dimension is the number of equality rows
//! the forces enter (the 6 floating-base rows, and one per torque limit held at its bound).
//! Derived in docs/whole_body_qp.md ("The cone solve").

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::outcome::N_CONTACTS;

/// Newton steps before the caller gives up on the cone solve (clarabel or the full problem
/// then decides); on the default run it takes 2 a tick on average (`wbc_cone_steps`).
const NEWTON_STEPS: usize = 30;
/// The stop: the equality's residual (N, N·m) relative to 1 + |y*|∞.
const NEWTON_TOLERANCE: f64 = 1e-10;
/// Armijo's sufficient decrease, and the shortest step before giving up.
const ARMIJO: f64 = 1e-4;
const MIN_STEP: f64 = 1e-10;

/// The forces, the dual z and the Newton steps taken.
pub(crate) type ConeOptimum<const D: usize> = ([Vector3<f64>; N_CONTACTS], SVector<f64, D>, usize);

/// Minimises the dual of `min ½ w_f ‖f‖² + ½ δᵀ X δ` s.t. `Bᵀ f − δ = y*`, f in the cones:
///
/// ```text
/// ψ(z) = ½ zᵀ (w_f X⁻¹) z − zᵀ y* + ½ Σ_k ‖Π_k(b_k z)‖²,
/// ∇ψ(z) = w_f X⁻¹ z − y* + Σ_k b_kᵀ Π_k(b_k z) = −(Bᵀ f − δ − y*),
/// ```
///
/// (`base` = w_f X⁻¹, b_k: B's 3 rows of corner k, Π_k the projection onto its cone), convex
/// and C¹, whose zero is the optimum: f_k = Π_k(b_k z) in its cone by construction,
/// complementarity by the projection (Moreau), δ = −w_f X⁻¹ z, and ∇ψ the residual of the
/// equality. Newton steps with the generalised Hessian `w_f X⁻¹ + Σ_k b_kᵀ J_k b_k` (J_k: Π_k's
/// Jacobian, I inside the cone, 0 for an unloaded corner, a rank-2 matrix for a corner sliding
/// on the boundary) and an Armijo backtracking on ψ. From z = 0 the first step is the
/// all-loaded solution. `None` when the steps do not settle within [`NEWTON_STEPS`].
///
/// D is the number of equality rows; a problem with fewer may be padded (zero columns of B,
/// zero y*, base's unused block diagonal positive): its extra z stay zero.
pub(crate) fn cone_newton<const D: usize>(
    bk: &[SMatrix<f64, 3, D>; N_CONTACTS],
    base: &SMatrix<f64, D, D>,
    y_star: &SVector<f64, D>,
    cones: &[Cone; N_CONTACTS],
) -> Option<ConeOptimum<D>> {
    let tol = NEWTON_TOLERANCE * (1.0 + y_star.amax());
    // ψ and the forces at z.
    let psi = |z: &SVector<f64, D>, f: &mut [Vector3<f64>; N_CONTACTS]| {
        let mut v = 0.5 * z.dot(&(base * z)) - z.dot(y_star);
        for (c, fc) in f.iter_mut().enumerate() {
            *fc = cones[c].project(&(bk[c] * z));
            v += 0.5 * fc.norm_squared();
        }
        v
    };
    let mut z = SVector::<f64, D>::zeros();
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
pub(crate) struct Cone<'a> {
    pub(crate) rot: &'a Matrix3<f64>,
    pub(crate) mu: f64,
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
        // Not `hypot`: forces never come near its overflow guard, which cost 2 % of the C1 tick.
        let (r, n) = ((l.x * l.x + l.y * l.y).sqrt(), l.z);
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
    use nalgebra::{Matrix3x6, Matrix6, Vector6};

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
            // Padded to 8 rows (B's two more columns zero): the same forces, the extra dual
            // components zero.
            let bk8: [SMatrix<f64, 3, 8>; N_CONTACTS] = std::array::from_fn(|c| {
                let mut b = SMatrix::<f64, 3, 8>::zeros();
                b.fixed_view_mut::<3, 6>(0, 0).copy_from(&bk[c]);
                b
            });
            let mut base8 = SMatrix::<f64, 8, 8>::identity() * w_f;
            base8.fixed_view_mut::<6, 6>(0, 0).copy_from(&base);
            let mut y8 = SVector::<f64, 8>::zeros();
            y8.fixed_rows_mut::<6>(0).copy_from(&y_star);
            let (f8, z8, _) = cone_newton(&bk8, &base8, &y8, &cones).expect("converges");
            for (a, b) in f.iter().zip(&f8) {
                assert!((a - b).amax() <= 1e-9 * (1.0 + a.amax()), "{a:?} vs {b:?}");
            }
            assert_eq!((z8[6], z8[7]), (0.0, 0.0));
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
