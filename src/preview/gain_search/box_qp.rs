//! A small dense box-constrained QP, min ½ δᵀHδ + gᵀδ s.t. lo ≤ δ ≤ hi, by a primal active set:
//! the Gauss–Newton subproblem of the gain search (a few dozen variables).

use nalgebra::{DMatrix, DVector};

/// Solve with H symmetric positive definite and lo ≤ 0 ≤ hi (δ = 0 feasible).
pub fn solve_box_qp(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> DVector<f64> {
    let n = g.len();
    let mut x = DVector::zeros(n);
    // 0 free, −1 at lower bound, +1 at upper bound.
    let mut state = vec![0i8; n];
    for _ in 0..(4 * n + 8) {
        let free: Vec<usize> = (0..n).filter(|&j| state[j] == 0).collect();
        // Minimise over the free variables with the others fixed at their bounds.
        let mut target = x.clone();
        if !free.is_empty() {
            let hff = DMatrix::from_fn(free.len(), free.len(), |a, b| h[(free[a], free[b])]);
            let rhs = DVector::from_fn(free.len(), |a, _| {
                let j = free[a];
                -(g[j]
                    + (0..n)
                        .filter(|&k| state[k] != 0)
                        .map(|k| h[(j, k)] * x[k])
                        .sum::<f64>())
            });
            let Some(chol) = hff.cholesky() else { return x };
            let sol = chol.solve(&rhs);
            for (a, &j) in free.iter().enumerate() {
                target[j] = sol[a];
            }
        }
        // Largest step toward the free minimiser that stays feasible.
        let mut step = 1.0;
        let mut blocking = None;
        for &j in &free {
            let d = target[j] - x[j];
            if d < 0.0 && target[j] < lo[j] {
                let s = (lo[j] - x[j]) / d;
                if s < step {
                    step = s;
                    blocking = Some((j, -1));
                }
            } else if d > 0.0 && target[j] > hi[j] {
                let s = (hi[j] - x[j]) / d;
                if s < step {
                    step = s;
                    blocking = Some((j, 1));
                }
            }
        }
        x += (&target - &x) * step.max(0.0);
        if let Some((j, side)) = blocking {
            x[j] = if side < 0 { lo[j] } else { hi[j] };
            state[j] = side;
            continue;
        }
        // At the free minimiser: release the bound whose multiplier has the wrong sign.
        let grad = h * &x + g;
        let release = (0..n)
            .filter(|&j| (state[j] < 0 && grad[j] < 0.0) || (state[j] > 0 && grad[j] > 0.0))
            .max_by(|&a, &b| grad[a].abs().total_cmp(&grad[b].abs()));
        match release {
            Some(j) => state[j] = 0,
            None => return x,
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unconstrained_and_clamped_minimisers() {
        let h = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]);
        let g = DVector::from_vec(vec![-2.0, -1.0]);
        let wide = DVector::from_vec(vec![10.0, 10.0]);
        let x = solve_box_qp(&h, &g, &(-&wide), &wide);
        let exact = h
            .clone()
            .cholesky()
            .map(|c| c.solve(&(-&g)))
            .unwrap_or_default();
        assert!((x - exact).norm() < 1e-12);
        // With δ_0 ≤ 0.2 the optimum sits on that bound and δ_1 re-optimises: (1 − 0.5·0.2)/1.
        let hi = DVector::from_vec(vec![0.2, 10.0]);
        let x = solve_box_qp(&h, &g, &(-&wide), &hi);
        assert!(
            (x[0] - 0.2).abs() < 1e-12 && (x[1] - 0.9).abs() < 1e-12,
            "{x}"
        );
    }
}
