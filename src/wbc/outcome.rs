//! What the whole-body QP's formulations share: the robot's contact count, and what a
//! tick's solve can end with and counts (the full problem in `controller.rs`, the condensed
//! one in `condensed.rs`, clarabel's wrapper in `qp.rs`).

use clarabel::solver::SolverStatus;

pub use crate::robot::N_CONTACTS;

/// Why a tick fell back to the safe torque.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FallbackReason {
    /// `q`, `v`, the command or the posture reference is malformed or non-finite.
    InvalidInput,
    /// The assembled QP data is not finite.
    NonFiniteProblem,
    /// Clarabel refused the problem data (construction or update error).
    SolverSetup,
    /// Clarabel ended with this status (not Solved / AlmostSolved).
    Solver(SolverStatus),
    /// The solver reported success but the solution is not finite.
    NonFiniteSolution,
    /// The solver panicked (caught; the solver is rebuilt by the next tick, which allocates).
    SolverPanic,
    /// The controller found the robot fallen (`controller.fall_drop`): joint damping, no QP.
    Fallen,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WbcStatus {
    /// The QP's solution (clarabel Solved or AlmostSolved).
    Solved,
    /// The fallback torque, for this reason.
    Fallback(FallbackReason),
}

/// Counters since construction (`summary.json`'s `wbc`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct WbcCounters {
    pub ticks: u64,
    /// Ticks whose QP was solved (including reduced-accuracy solutions).
    pub solved: u64,
    /// Of those, clarabel's AlmostSolved (reduced accuracy).
    pub almost_solved: u64,
    pub fallbacks: u64,
    pub consecutive_fallbacks: u64,
    /// Clarabel solvers built: at construction (up to 3: condensed, screening, full); any more
    /// were rebuilt by a tick after a panic or a refused update.
    pub solver_builds: u64,
    /// Ticks whose QP needed the torque-limit rows (a limit active at the optimum).
    pub torque_limited: u64,
    /// Of those, the ticks the condensed problem settled by holding the active limits
    /// (`condensed.rs`); the others went to the full problem.
    pub limits_condensed: u64,
    /// Ticks the condensed problem could not be formed (H or S not positive definite), decided
    /// by the full problem instead.
    pub condensation_failures: u64,
    /// Ticks the condensed problem's optimum was found without clarabel, by the cone solve
    /// (`cone.rs`), its torque limits held (`condensed.rs`).
    pub active_set: u64,
    /// Newton steps the cone solve took over those ticks, and the ticks it did not settle
    /// (left to clarabel).
    pub cone_steps: u64,
    pub cone_unsettled: u64,
    /// Ticks whose QP the torque limits made infeasible, solved without them and the torques
    /// saturated at the limits (docs/whole_body_qp.md, "Limits that cannot all hold").
    pub limits_saturated: u64,
}
