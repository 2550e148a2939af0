//! C2 (docs/gain_search.md, eq. (26)): the hand's impedance gains over the horizon as decision
//! variables, searched jointly with the CoM jerks. Two solvers behind one interface:
//! - [`GainSolverKind::GaussNewton`] (default): bounded Gauss–Newton with exact Jacobians
//!   through the LQ solve, warm-started from the previous schedule shifted in time;
//! - [`GainSolverKind::NelderMead`]: the paper's baseline, a simplex over fewer knots.
//!
//! Neither ends above the cost of the nominal constant gains (C1): the search starts from the
//! better of the warm start and the nominal schedule, and both solvers only accept descent.

mod box_qp;
mod cost;
mod gauss_newton;
mod nelder_mead;
mod schedule;

use std::time::{Duration, Instant};

pub use cost::{Eq26, Eq26Weights, GainSearchInputs};
pub use schedule::KnotSchedule;

use super::{GainSchedule, HandPreviewer, PreviewError, ZmpPreview};
use crate::config::{Config, GainSolverKind};
use crate::robot::ReducedModel;

/// What one solver run reports.
#[derive(Debug, Clone, Copy)]
pub struct SolveStats {
    pub cost: f64,
    pub iterations: usize,
}

/// The outcome of one gain search.
#[derive(Debug, Clone, Copy)]
pub struct GainSearchReport {
    pub solver: GainSolverKind,
    /// eq. (26) at the returned schedule.
    pub cost: f64,
    /// eq. (26) at the nominal constant gains (what C1 would pay).
    pub nominal_cost: f64,
    pub iterations: usize,
    /// Evaluations of eq. (26) (each a hand prediction plus a C1 solve).
    pub evaluations: usize,
    pub elapsed: Duration,
}

/// C2's gain search with its warm start.
pub struct GainSearch {
    problem: Eq26,
    knots: KnotSchedule,
    solver: GainSolverKind,
    nominal: [f64; 2],
    max_iterations: usize,
    tolerance: f64,
    theta: Vec<f64>,
    candidate: Vec<f64>,
    schedule: GainSchedule,
    warm: bool,
}

impl GainSearch {
    /// A gain search on `robot`'s reduced models configured from `config` (solver kind,
    /// weights, bounds, knots).
    pub fn from_config(config: &Config, robot: &ReducedModel) -> Result<Self, PreviewError> {
        Self::with_solver(config, robot, config.gain_search.solver)
    }

    /// The same with an explicit solver (to compare the two on one problem).
    pub fn with_solver(
        config: &Config,
        robot: &ReducedModel,
        solver: GainSolverKind,
    ) -> Result<Self, PreviewError> {
        let p = &config.preview;
        let g = &config.gain_search;
        let model = robot.cart_table(p.period, config.robot.gravity);
        // C2 evaluates many schedules: always the O(N) solver, whatever the C1 setting.
        let zmp = ZmpPreview::new(
            model,
            p.q_e,
            p.r,
            p.horizon,
            crate::config::LqSolverKind::Riccati,
        )
        .with_terminal_cost(p.terminal_cost);
        let hand = HandPreviewer::new(p.period, robot.effective_mass, p.horizon)?;
        let n_knots = match solver {
            GainSolverKind::GaussNewton => g.knots,
            GainSolverKind::NelderMead => g.nm_knots,
        };
        let knots = KnotSchedule::new(
            p.horizon,
            n_knots,
            config.hand.damping,
            config.hand.damping_ratio,
            g.kp_bounds,
            g.kd_bounds,
        );
        let weights = Eq26Weights {
            q_t: g.q_t,
            s: g.s,
            t_w: g.t_w,
        };
        let dim = knots.dim();
        let nominal = [config.hand.kp, config.nominal_kd(config.hand.kp)];
        let mut theta = vec![nominal[0]; dim];
        theta[knots.n_knots()..].fill(nominal[1]);
        Ok(Self {
            problem: Eq26::new(zmp, hand, weights, dim),
            knots,
            solver,
            nominal,
            max_iterations: match solver {
                GainSolverKind::GaussNewton => g.max_iterations,
                GainSolverKind::NelderMead => g.nm_max_iterations,
            },
            tolerance: g.tolerance,
            candidate: theta.clone(),
            theta,
            schedule: GainSchedule::constant(p.horizon, nominal[0], nominal[1]),
            warm: false,
        })
    }

    /// Update the hand's M_e (the whole-body controller recomputes it every tick).
    pub fn set_effective_mass(&mut self, m_e: nalgebra::Matrix3<f64>) -> Result<(), PreviewError> {
        self.problem.hand.set_effective_mass(m_e)
    }

    /// The held object's path the hand previewer keeps the hand on (HP-1, `HandPreviewer::set_held_path`).
    pub fn set_held_path(&mut self, path: Option<(nalgebra::Vector3<f64>, f64)>) {
        self.problem.hand.set_held_path(path);
    }

    /// Forget the previous solution: the next search starts from the nominal gains.
    pub fn reset(&mut self) {
        self.warm = false;
    }

    /// Search the gain schedule for this snapshot. `shift_steps` is the time elapsed since the
    /// previous search, in preview steps, to shift the warm start.
    pub fn search(
        &mut self,
        inp: &GainSearchInputs,
        shift_steps: usize,
    ) -> Result<GainSearchReport, PreviewError> {
        let start = Instant::now();
        self.problem.evaluations = 0;
        let dim = self.knots.dim();
        let m = self.knots.n_knots();
        // Nominal candidate.
        self.candidate[..m].fill(self.nominal[0]);
        self.candidate[m..dim].fill(self.nominal[1]);
        let nominal_cost = self.problem.evaluate(&self.knots, &self.candidate, inp)?;
        let mut best_cost = nominal_cost;
        if self.warm {
            self.knots
                .sample(&self.schedule, shift_steps, &mut self.theta);
            let warm_cost = self.problem.evaluate(&self.knots, &self.theta, inp)?;
            if warm_cost > nominal_cost {
                self.theta.copy_from_slice(&self.candidate);
            } else {
                best_cost = warm_cost;
            }
        } else {
            self.theta.copy_from_slice(&self.candidate);
        }
        let run = match self.solver {
            GainSolverKind::GaussNewton => gauss_newton::solve,
            GainSolverKind::NelderMead => nelder_mead::solve,
        };
        let stats = run(
            &mut self.problem,
            &self.knots,
            &mut self.theta,
            inp,
            self.max_iterations,
            self.tolerance,
        )?;
        debug_assert!(stats.cost <= best_cost * (1.0 + 1e-12));
        self.knots.expand(&self.theta, &mut self.schedule);
        self.warm = true;
        Ok(GainSearchReport {
            solver: self.solver,
            cost: stats.cost,
            nominal_cost,
            iterations: stats.iterations,
            evaluations: self.problem.evaluations,
            elapsed: start.elapsed(),
        })
    }

    /// The per-step schedule of the last search (samples at k+1…k+N).
    pub fn schedule(&self) -> &GainSchedule {
        &self.schedule
    }

    /// The eq. (26) workspace, to evaluate a given schedule (tests, reports).
    pub fn problem_mut(&mut self) -> (&mut Eq26, &KnotSchedule) {
        (&mut self.problem, &self.knots)
    }
}
