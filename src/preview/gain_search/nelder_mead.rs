//! The paper's C2 baseline (docs/gain_search.md): Nelder–Mead (argmin) over a coarse gain
//! schedule, warm-started, solving C1 at every vertex. Bounds are kept by evaluating at the clamped point plus a
//! quadratic penalty on the excursion, so the simplex is steered back inside.

use std::cell::RefCell;

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;

use super::{Eq26, GainSearchInputs, KnotSchedule, SolveStats};
use crate::preview::PreviewError;

struct Objective<'a, 'b> {
    problem: RefCell<&'a mut Eq26>,
    knots: &'a KnotSchedule,
    inp: &'a GainSearchInputs<'b>,
    clamped: RefCell<Vec<f64>>,
    error: RefCell<Option<PreviewError>>,
}

impl CostFunction for Objective<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let mut clamped = self.clamped.borrow_mut();
        let mut excursion = 0.0;
        for (j, (c, v)) in clamped.iter_mut().zip(p).enumerate() {
            let (lo, hi) = (self.knots.lower(j), self.knots.upper(j));
            *c = v.clamp(lo, hi);
            excursion += ((v - *c) / (hi - lo)).powi(2);
        }
        match self
            .problem
            .borrow_mut()
            .evaluate(self.knots, &clamped, self.inp)
        {
            Ok(cost) => Ok(cost * (1.0 + excursion)),
            Err(e) => {
                *self.error.borrow_mut() = Some(e);
                Ok(f64::INFINITY)
            }
        }
    }
}

pub fn solve(
    problem: &mut Eq26,
    knots: &KnotSchedule,
    theta: &mut [f64],
    inp: &GainSearchInputs,
    max_iterations: usize,
    tolerance: f64,
) -> Result<SolveStats, PreviewError> {
    let n = knots.dim();
    // Warm-started simplex: θ and one vertex per coordinate, a tenth of the range inward.
    let mut simplex = vec![theta.to_vec()];
    for j in 0..n {
        let mut v = theta.to_vec();
        let delta = 0.1 * (knots.upper(j) - knots.lower(j));
        v[j] = if v[j] + delta <= knots.upper(j) {
            v[j] + delta
        } else {
            v[j] - delta
        };
        simplex.push(v);
    }
    let start_cost = problem.evaluate(knots, theta, inp)?;
    let objective = Objective {
        problem: RefCell::new(&mut *problem),
        knots,
        inp,
        clamped: RefCell::new(vec![0.0; n]),
        error: RefCell::new(None),
    };
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(tolerance * start_cost.max(f64::MIN_POSITIVE))
        .map_err(|e| PreviewError::Qp(format!("Nelder–Mead setup: {e}")))?;
    let result = Executor::new(objective, solver)
        .configure(|s| s.max_iters(max_iterations as u64))
        .run()
        .map_err(|e| PreviewError::Qp(format!("Nelder–Mead: {e}")))?;
    let state = result.state();
    let iterations = state.get_iter() as usize;
    let improved = state
        .get_best_param()
        .filter(|_| state.get_best_cost() < start_cost)
        .cloned();
    drop(result);
    if let Some(best) = improved {
        for (j, (t, b)) in theta.iter_mut().zip(best).enumerate() {
            *t = b.clamp(knots.lower(j), knots.upper(j));
        }
    }
    // The clamped best point's own cost (and the workspace left at it).
    let cost = problem.evaluate(knots, theta, inp)?;
    Ok(SolveStats { cost, iterations })
}
