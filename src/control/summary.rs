//! What a control run reports: the controller's part of `summary.json` ([`ServerSummary`]),
//! filled by the loop (`server.rs`) and its figures ([`super::run_metrics::RunMetrics`]).

use serde::{Deserialize, Serialize};

use super::forecast_window::RejectionCounts;

/// What a run measured; written as the controller's part of `summary.json`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct ServerSummary {
    pub controller: String,
    /// The robot's name (its description) and total mass (kg).
    pub robot: String,
    pub robot_mass: f64,
    pub mode: String,
    /// Lockstep with every input a function of simulated time (see the module doc): a rerun
    /// gives the same bytes. `reproducibility` says why not, when not.
    pub reproducible: bool,
    pub reproducibility: String,
    pub ticks: u64,
    pub sim_time: f64,
    pub tick_p50_us: f64,
    pub tick_p99_us: f64,
    pub tick_max_us: f64,
    pub deadline_overruns: u64,
    pub deadline_misses: u64,
    /// Loop passes without a new state (real time) or with a repeated one.
    pub stale_states: u64,
    /// Times the state stopped for longer than `controller.state_timeout`.
    pub stale_periods: u64,
    /// Real time: damping torques published (flagged fallback) while the state was stale.
    pub stale_ticks: u64,
    /// Longest wall time between two fresh states (s).
    pub longest_state_gap: f64,
    /// Lockstep: answers sent again to a plant still sending the state they answer (a lost
    /// answer; 0 in a healthy run).
    #[serde(default)]
    pub lockstep_reanswers: u64,
    /// Restarted simulators the controller latched onto and resumed with.
    pub reconnects: u64,
    /// Control ticks since the last reconnect (all ticks without one).
    pub ticks_since_reconnect: u64,
    pub tick_errors: u64,
    pub wbc_fallbacks: u64,
    /// Ticks whose whole-body QP had a torque limit active, and ticks the condensed QP could
    /// not be formed (decided by the full one).
    #[serde(default)]
    pub wbc_torque_limited_ticks: u64,
    /// Of the torque-limited ticks, those the condensed QP settled by holding the active
    /// limits (the others went to the full problem).
    #[serde(default)]
    pub wbc_limits_condensed_ticks: u64,
    #[serde(default)]
    pub wbc_condensation_failures: u64,
    /// Ticks whose whole-body QP was solved by the cone solve, without clarabel
    /// (docs/whole_body_qp.md).
    #[serde(default)]
    pub wbc_active_set_ticks: u64,
    /// The cone solve's Newton steps over its ticks, and the ticks it left to clarabel.
    #[serde(default)]
    pub wbc_cone_steps: u64,
    #[serde(default)]
    pub wbc_cone_unsettled: u64,
    /// Ticks the torque limits made the QP infeasible: solved without them, torques saturated.
    #[serde(default)]
    pub wbc_limits_saturated_ticks: u64,
    pub preview_fallbacks: u64,
    /// Ticks whose whole-body QP was given the held object's modelled force
    /// (`controller.hand_force_feedback_from`, "modelled" or "auto" on an estimated force).
    #[serde(default)]
    pub hand_force_modelled_ticks: u64,
    /// Falls the controller detected (`controller.fall_drop`), and the ticks it then held joint
    /// damping without preview or QP (until the plant restarted).
    #[serde(default)]
    pub falls: u64,
    #[serde(default)]
    pub fallen_ticks: u64,
    pub forecasts_accepted: u64,
    pub forecasts_rejected: u64,
    pub forecasts_rejected_by: RejectionCounts,
    /// Windows accepted from a forecaster that restarted (its seq went back).
    pub forecaster_restarts: u64,
    /// The forecast was lost at some point: no valid window for `state_timeout` and the
    /// current one no longer covering the horizon (it decays to zero).
    pub forecast_lost: bool,
    /// Times the forecast was lost.
    pub forecast_losses: u64,
    /// No forecast window was ever accepted (no forecaster, or none valid): the preview ran on
    /// the measured hand force alone, which is not a lost forecast.
    pub forecast_never_received: bool,
    /// Plant time (s) of the first window accepted in the last plant session (lockstep: the
    /// same for a forecaster started late, which the plant waited for).
    pub forecast_first_at: Option<f64>,
    /// Lockstep: the wait for a forecaster's first window ended without one.
    pub forecast_first_wait_expired: bool,
    /// Accepted forecast windows whose scenario differs from the one the plant announces.
    pub forecast_scenario_mismatches: u64,
    /// The plant announced another scenario than this controller's `--scenario`.
    pub plant_scenario_mismatch: bool,
    /// The plant's announced scenario (name and hash) at the last state.
    pub plant_scenario: String,
    /// Lockstep: ticks that waited for their forecast window / for C2, and waits that timed out.
    pub forecast_waits: u64,
    pub forecast_wait_timeouts: u64,
    pub c2_waits: u64,
    pub c2_wait_timeouts: u64,
    /// Ticks computed while the plant still held the robot itself (its start-up hold or a
    /// hand-over): the torques were blended in, not applied as such.
    pub ticks_in_plant_hold: u64,
    pub c2_solves: u64,
    pub c2_failures: u64,
    pub c2_panics: u64,
    pub c2_stale_schedules: u64,
    pub c2_solve_mean_ms: f64,
    pub c2_solve_max_ms: f64,
    pub c2_iterations_mean: f64,
    /// Smallest distance of the measured ZMP (centre of pressure) to the support edge (m). The
    /// measured CoP cannot leave the support: where the model ZMP would, the CoP sits on the
    /// edge and the feet start to tip.
    pub min_zmp_margin: f64,
    /// Time the measured CoP spends within 1 mm of the support edge (s): the feet tipping.
    pub time_at_support_edge: f64,
    /// Largest drop of the CoM height below its initial height (m): a fall shows here.
    pub com_height_drop: f64,
    pub hand_rms_error: f64,
    pub hand_peak_error: f64,
    pub max_zmp_error: f64,
    pub dropped_log_records: u64,
    /// Diagnostic lines (tracing, to stderr) the process dropped so far because stderr was not
    /// read fast enough (see [`crate::logging`]); the loop never waits on stderr.
    #[serde(default)]
    pub dropped_log_lines: u64,
    pub realtime: crate::realtime::RealtimeReport,
    pub stopped_by: String,
    /// The controller parts' entries, each under the part's own keys
    /// (`crate::control::parts`): `forecast_correction`, `viability`, `estimator` (absent when
    /// off or never run), `wrist_tare_offset`, `wrist_tare_refusals`.
    #[serde(flatten)]
    pub parts: serde_json::Map<String, serde_json::Value>,
}
