//! The condensed horizon (Wieber; docs/preview_control.md, eq. (5), (9), (12), (15)) and its
//! closed-form solve: the O(N³) reference against which the Riccati solver is tested and
//! benchmarked. Allocates; not for the tick path.

use faer::{Mat, Side};
use nalgebra::{Matrix3, Vector3};

use super::CartTable;

/// P_x (N×3) and P_u (N×N) of eq. (5), in their time-varying form of eq. (12): row i uses the
/// output row c_i = [1, 0, c2_i].
pub struct CondensedHorizon {
    pub px: Mat<f64>,
    pub pu: Mat<f64>,
    /// PC-T's last-state cost: P_tail, A^N and Φ = [A^{N−1} B, …, B] (x_N = A^N x₀ + Φ u).
    tail: Option<(Matrix3<f64>, Matrix3<f64>, Mat<f64>)>,
}

impl CondensedHorizon {
    /// eq. (5) / (12): P_x[i] = c_i Aⁱ = [1, iT, i²T²/2 + c2_i];
    /// P_u[i][j] = c_i A^{i−j} B = (1 + 3(i−j) + 3(i−j)²) T³/6 + c2_i T for j ≤ i (1-based).
    /// `tail`: PC-T's P_tail ([`CartTable::infinite_tail`]), or none (the paper's finite
    /// horizon).
    pub fn build(model: &CartTable, c2: &[f64], tail: Option<&Matrix3<f64>>) -> Self {
        let n = c2.len();
        let t = model.period;
        let px = Mat::from_fn(n, 3, |i, col| {
            let k = (i + 1) as f64;
            match col {
                0 => 1.0,
                1 => k * t,
                _ => k * k * t * t / 2.0 + c2[i],
            }
        });
        let pu = Mat::from_fn(n, n, |i, j| {
            if j > i {
                return 0.0;
            }
            let m = (i - j) as f64;
            (1.0 + 3.0 * m + 3.0 * m * m) * t * t * t / 6.0 + c2[i] * t
        });
        let tail = tail.map(|p| {
            let (a, b) = (model.a(), model.b());
            let mut phi = Mat::zeros(3, n);
            let mut col = b;
            for j in (0..n).rev() {
                for r in 0..3 {
                    phi[(r, j)] = col[r];
                }
                col = a * col;
            }
            (*p, a.pow(n as u32), phi)
        });
        Self { px, pu, tail }
    }

    /// eq. (9) / (15): û = −(P_uᵀP_u + (R/Q_e) I)⁻¹ P_uᵀ (P_x x̂ − t), for both axes at once;
    /// with PC-T, Φᵀ P_tail Φ / Q_e joins the normal matrix and Φᵀ P_tail (A^N x̂ − x̄_N) / Q_e
    /// the gradient (x̄_N = [t_N, 0, 0]). Returns the whole input horizon per axis, or None if
    /// the normal matrix is not SPD.
    pub fn solve(
        &self,
        q_e: f64,
        r: f64,
        x0: [&Vector3<f64>; 2],
        targets: [&[f64]; 2],
    ) -> Option<[Vec<f64>; 2]> {
        let n = self.pu.nrows();
        let mut normal = self.pu.transpose() * &self.pu;
        for i in 0..n {
            normal[(i, i)] += r / q_e;
        }
        if let Some((p, _, phi)) = &self.tail {
            let pm = Mat::from_fn(3, 3, |i, j| p[(i, j)] / q_e);
            normal += phi.transpose() * &pm * phi;
        }
        let llt = normal.llt(Side::Lower).ok()?;
        let mut rhs = Mat::<f64>::zeros(n, 2);
        for axis in 0..2 {
            let x = x0[axis];
            let err = Mat::from_fn(n, 1, |i, _| {
                self.px[(i, 0)] * x[0] + self.px[(i, 1)] * x[1] + self.px[(i, 2)] * x[2]
                    - targets[axis][i]
            });
            let mut g = self.pu.transpose() * &err;
            if let Some((p, an, phi)) = &self.tail {
                let dx = an * x - Vector3::new(targets[axis][n - 1], 0.0, 0.0);
                let w = p * dx / q_e;
                g += phi.transpose() * Mat::from_fn(3, 1, |i, _| w[i]);
            }
            for i in 0..n {
                rhs[(i, axis)] = -g[(i, 0)];
            }
        }
        let u = faer::linalg::solvers::Solve::solve(&llt, &rhs);
        Some([
            (0..n).map(|i| u[(i, 0)]).collect(),
            (0..n).map(|i| u[(i, 1)]).collect(),
        ])
    }
}
