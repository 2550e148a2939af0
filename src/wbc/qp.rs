//! One clarabel problem whose data is gathered each tick from a dense scratch through a fixed
//! sparsity [`Pattern`], with its solver kept between ticks (values updated in place).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};

use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::DMatrix;

use super::outcome::{FallbackReason, WbcCounters};
use super::pattern::Pattern;

/// One clarabel problem over the shared dense scratch: its rows, pattern, cones and solver.
pub(crate) struct QpInstance {
    rows: Vec<usize>,
    pub(crate) pattern: Pattern,
    a_val: Vec<f64>,
    b_val: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
    pub(crate) solver: Option<DefaultSolver<f64>>,
    /// Wall time of the last `solve` call. (Clarabel's own `solve_time` sums every timer it
    /// ever started, the solver's construction included: with a reused solver it reads the
    /// build's time plus the solve's.)
    last_solve: Duration,
}

impl QpInstance {
    pub(crate) fn new(pattern: Pattern, rows: Vec<usize>, cones: Vec<SupportedConeT<f64>>) -> Self {
        Self {
            a_val: vec![0.0; pattern.nnz()],
            b_val: vec![0.0; rows.len()],
            rows,
            pattern,
            cones,
            solver: None,
            last_solve: Duration::ZERO,
        }
    }

    /// Gathers A and b, updates the solver in place (or builds one), solves.
    /// `Ok(almost_solved)` on Solved / AlmostSolved.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run(
        &mut self,
        p_pattern: &Pattern,
        p_val: &Vec<f64>,
        q: &Vec<f64>,
        ad: &DMatrix<f64>,
        bd: &[f64],
        settings: &DefaultSettings<f64>,
        reuse: bool,
        counters: &mut WbcCounters,
    ) -> Result<bool, FallbackReason> {
        use FallbackReason::*;
        self.pattern.gather(ad, &mut self.a_val);
        for (b, &r) in self.b_val.iter_mut().zip(&self.rows) {
            *b = bd[r];
        }
        match self.solver.as_mut() {
            Some(s) if reuse => {
                let updated = s
                    .update_P(p_val)
                    .and_then(|_| s.update_A(&self.a_val))
                    .and_then(|_| s.update_q(q))
                    .and_then(|_| s.update_b(&self.b_val));
                if updated.is_err() {
                    self.solver = None;
                    return Err(SolverSetup);
                }
            }
            _ => {
                let pm = p_pattern.to_csc(p_val);
                let am = self.pattern.to_csc(&self.a_val);
                let s = DefaultSolver::new(&pm, q, &am, &self.b_val, &self.cones, settings.clone())
                    .map_err(|_| SolverSetup)?;
                counters.solver_builds += 1;
                self.solver = Some(s);
            }
        }
        let solver = self.solver.as_mut().ok_or(SolverSetup)?;
        let t0 = Instant::now();
        let solved = catch_unwind(AssertUnwindSafe(|| solver.solve()));
        self.last_solve = t0.elapsed();
        if solved.is_err() {
            self.solver = None;
            return Err(SolverPanic);
        }
        match solver.solution.status {
            SolverStatus::Solved => Ok(false),
            SolverStatus::AlmostSolved => Ok(true),
            s => Err(Solver(s)),
        }
    }

    pub(crate) fn x(&self) -> &[f64] {
        self.solver.as_ref().map_or(&[], |s| &s.solution.x)
    }
    pub(crate) fn iterations(&self) -> u32 {
        self.solver.as_ref().map_or(0, |s| s.solution.iterations)
    }
    pub(crate) fn solve_time(&self) -> Duration {
        self.last_solve
    }
}
