//! The default C2 solver: bounded Gauss–Newton (Levenberg–Marquardt damped) on eq. (26)
//! (docs/gain_search.md) with the exact Jacobian through the LQ solve. Monotone: every accepted
//! step lowers the cost.

use nalgebra::DVector;

use super::box_qp::solve_box_qp;
use super::{Eq26, GainSearchInputs, KnotSchedule, SolveStats};
use crate::preview::PreviewError;

pub fn solve(
    problem: &mut Eq26,
    knots: &KnotSchedule,
    theta: &mut [f64],
    inp: &GainSearchInputs,
    max_iterations: usize,
    tolerance: f64,
) -> Result<SolveStats, PreviewError> {
    let n = knots.dim();
    let mut cost = problem.evaluate(knots, theta, inp)?;
    let mut mu: f64 = 1e-4;
    let mut iterations = 0;
    let mut trial = vec![0.0; n];
    let (mut lo, mut hi) = (DVector::zeros(n), DVector::zeros(n));
    'outer: while iterations < max_iterations {
        iterations += 1;
        problem.jacobian(knots, inp);
        let (h, g) = problem.normal_equations(n);
        for j in 0..n {
            lo[j] = knots.lower(j) - theta[j];
            hi[j] = knots.upper(j) - theta[j];
        }
        let scale = DVector::from_fn(n, |j, _| h[(j, j)].max(1e-12 * (1.0 + h.diagonal().max())));
        for _ in 0..12 {
            let mut damped = h.clone();
            for j in 0..n {
                damped[(j, j)] += mu * scale[j];
            }
            let step = solve_box_qp(&damped, &g, &lo, &hi);
            let predicted = -(g.dot(&step) + 0.5 * step.dot(&(&h * &step)));
            if predicted <= tolerance * 1e-3 * cost {
                break 'outer;
            }
            for j in 0..n {
                trial[j] = (theta[j] + step[j]).clamp(knots.lower(j), knots.upper(j));
            }
            let c = problem.evaluate(knots, &trial, inp)?;
            if c < cost {
                theta.copy_from_slice(&trial);
                let decrease = cost - c;
                cost = c;
                mu = (mu / 3.0).max(1e-12);
                if decrease <= tolerance * cost {
                    break 'outer;
                }
                continue 'outer;
            }
            mu *= 4.0;
        }
        break;
    }
    Ok(SolveStats { cost, iterations })
}
