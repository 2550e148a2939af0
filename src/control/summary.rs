//! What a control run reports: the controller's part of `summary.json` ([`ServerSummary`]).
//! Each piece of the loop reports its own counters as one value (the core's [`CoreInfo`], the
//! QP's [`WbcCounters`], the plant link's [`LinkCounts`], the forecast's [`ForecastCounts`], the
//! run's figures [`RunFigures`], ...); the summary only places them, under the keys their fields
//! name (flattened) or under `wbc` for the QP's.

use serde::{Deserialize, Serialize};

use super::forecast_window::RejectionCounts;
use super::plant_link::LinkCounts;
use crate::wbc::WbcCounters;

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
    /// The plant's announced scenario (name and hash) at the last state.
    pub plant_scenario: String,
    #[serde(flatten)]
    pub figures: RunFigures,
    #[serde(flatten)]
    pub deadlines: DeadlineCounts,
    #[serde(flatten)]
    pub link: LinkCounts,
    #[serde(flatten)]
    pub events: LoopEvents,
    #[serde(flatten)]
    pub core: CoreInfo,
    /// The whole-body QP's counters (solves, fallbacks, torque limits, the cone solve).
    pub wbc: WbcCounters,
    #[serde(flatten)]
    pub forecasts: ForecastCounts,
    #[serde(flatten)]
    pub c2: C2Counts,
    pub dropped_log_records: u64,
    /// Diagnostic lines (tracing, to stderr) the process dropped so far because stderr was not
    /// read fast enough (see [`crate::logging`]); the loop never waits on stderr.
    pub dropped_log_lines: u64,
    pub realtime: crate::realtime::RealtimeReport,
    pub stopped_by: String,
    /// The controller parts' entries, each under the part's own keys (`crate::control::part`):
    /// `forecast_correction`, `viability`, `base_estimation` (absent when off or never run),
    /// `wrench_observer`, `wrist_tare_offset`, `wrist_tare_refusals`.
    #[serde(flatten)]
    pub parts: serde_json::Map<String, serde_json::Value>,
}

/// The run's figures, tick by tick (`super::run_metrics::RunMetrics`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RunFigures {
    pub ticks: u64,
    /// Control ticks since the last reconnect (all ticks without one).
    pub ticks_since_reconnect: u64,
    pub sim_time: f64,
    pub tick_p50_us: f64,
    pub tick_p99_us: f64,
    pub tick_max_us: f64,
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
    pub c2_solve_mean_ms: f64,
    pub c2_solve_max_ms: f64,
    pub c2_iterations_mean: f64,
}

/// Real time: the ticker's overrun deadlines, and the deadlines they missed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DeadlineCounts {
    pub deadline_overruns: u64,
    pub deadline_misses: u64,
}

/// What happened to the loop, counted as it happened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LoopEvents {
    /// Real time: damping torques published (flagged fallback) while the state was stale.
    pub stale_ticks: u64,
    pub tick_errors: u64,
    pub wbc_fallbacks: u64,
    /// The forecast was lost at some point: no valid window for `state_timeout` and the
    /// current one no longer covering the horizon (it decays to zero).
    pub forecast_lost: bool,
    /// Times the forecast was lost.
    pub forecast_losses: u64,
    /// Lockstep: the wait for a forecaster's first window ended without one.
    pub forecast_first_wait_expired: bool,
    /// Accepted forecast windows whose scenario differs from the one the plant announces.
    pub forecast_scenario_mismatches: u64,
    /// The plant announced another scenario than this controller's `--scenario`.
    pub plant_scenario_mismatch: bool,
    /// Lockstep: ticks that waited for their forecast window / for C2, and waits that timed out.
    pub forecast_waits: u64,
    pub forecast_wait_timeouts: u64,
    pub c2_waits: u64,
    pub c2_wait_timeouts: u64,
    /// Ticks computed while the plant still held the robot itself (its start-up hold or a
    /// hand-over): the torques were blended in, not applied as such.
    pub ticks_in_plant_hold: u64,
    pub c2_stale_schedules: u64,
}

/// The forecast windows the controller took (`super::forecast_window::ForecastWindow`, and
/// the intake's first).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ForecastCounts {
    pub forecasts_accepted: u64,
    pub forecasts_rejected: u64,
    pub forecasts_rejected_by: RejectionCounts,
    /// Windows accepted from a forecaster that restarted (its seq went back).
    pub forecaster_restarts: u64,
    /// No forecast window was ever accepted (no forecaster, or none valid): the preview ran on
    /// the measured hand force alone, which is not a lost forecast.
    pub forecast_never_received: bool,
    /// Plant time (s) of the first window accepted in the last plant session (lockstep: the
    /// same for a forecaster started late, which the plant waited for).
    pub forecast_first_at: Option<f64>,
}

/// C2's thread: searches finished, failed, and panicked (caught).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct C2Counts {
    pub c2_solves: u64,
    pub c2_failures: u64,
    pub c2_panics: u64,
}

/// The core's counters, reported by name in `summary.json`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CoreInfo {
    /// Ticks where the disturbance forecast was invalid and C0 ran instead.
    pub preview_fallbacks: u64,
    /// Ticks the QP was given the held object's modelled force
    /// ([`super::held_object::held_object_force`]).
    pub hand_force_modelled_ticks: u64,
    /// Falls detected, and the ticks then held with joint damping.
    pub falls: u64,
    pub fallen_ticks: u64,
}
