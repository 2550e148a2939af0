//! The control server's loop over iceoryx2 (`upc controller`): lockstep (answer each state as
//! it arrives) or real time (absolute deadlines at `rate_hz`). Nothing on the loop's path
//! allocates, blocks on logging or on C2, or panics on bad input.
//!
//! Faults (see `services/FAULTS.md`):
//! - No fresh state for `state_timeout`: a stale period. In real time the loop keeps ticking and
//!   publishes joint damping torques flagged [`TORQUE_FLAG_FALLBACK`]; in lockstep it waits
//!   `reconnect_timeout` more for a simulator, then stops, unless the simulator's process is
//!   still alive (a starved plant on a loaded machine, a debugger): that one it waits for.
//! - A state whose step goes back: a restarted simulator. The core, the forecast window and the
//!   metrics' initial CoM height latch again from its first state, and control resumes.
//! - Forecasts are validated by [`ForecastWindow`]; without one the forecast decays to zero. A
//!   forecast of another scenario than the plant announces is counted and logged.
//! - C2 dead, failing or late: C1 runs with the nominal gains.
//!
//! Lockstep is reproducible (same build, config and machine architecture → the same bytes in
//! `controller.csv` and the summaries, timing figures aside): every input of tick k is a
//! function of simulated time. The loop waits (bounded) for the forecast window whose period
//! covers the state's time, takes C2's schedule exactly `c2_every` ticks after the snapshot it
//! answers, logs every tick record (no drops), and runs faer single-threaded. Real time stays
//! asynchronous: it never waits for the forecaster, C2 or the logger.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::forecast_intake::ForecastIntake;
use super::forecast_window::RejectionCounts;
use super::gain_thread::GainSolver;
use super::logger::{ControlLogger, TickLog};
use super::{ControllerCore, ForecastWindow, GainHandoff, LatencyHistogram, Ticker};
use crate::channels::{
    Bus, ChannelError, ForecastMsg, MAX_DOF, Notifier, Publisher, STATE_FLAG_HOLD, ServiceKind,
    StateMsg, TORQUE_FLAG_FALLBACK, TorqueMsg,
};
use crate::config::{Config, ControllerKind, LoopMode};
use crate::dynamics::Model;

/// A measured CoP closer than this to the support edge counts as at the edge (m).
const EDGE_BAND: f64 = 1e-3;

/// How to run, beyond the config.
#[derive(Debug, Clone)]
pub struct ServerOptions {
    pub prefix: String,
    /// Stop once the simulated time reaches this (s).
    pub duration: Option<f64>,
    pub rrd: Option<PathBuf>,
    pub recording_id: String,
    /// Stream the recording to this live rerun viewer too (gRPC proxy URL).
    pub live: Option<String>,
    /// The scenario's ZMP reference offset from the feet midpoint (m).
    pub zmp_offset: [f64; 2],
    /// Give up if no state arrives within this time of starting (s).
    pub startup_timeout: f64,
    /// Write every `log_every`-th tick record as CSV here (written by the logger thread).
    pub csv: Option<PathBuf>,
    /// Content hash of the scenario this controller was configured with (its ZMP reference and
    /// config layer): a plant announcing another one is reported.
    pub scenario_hash: Option<u64>,
    /// Content hash of the robot the model was built from ([`crate::robot::Robot::hash`]):
    /// states of a plant announcing another robot are refused. `None`: not checked.
    pub robot_hash: Option<u64>,
    /// The robot's name, for the summary.
    pub robot_name: String,
}

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
    #[serde(default)]
    pub wbc_condensation_failures: u64,
    pub preview_fallbacks: u64,
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
    pub realtime: super::realtime::RealtimeReport,
    pub stopped_by: String,
    /// The forecast correction (docs/forecast_correction.md); `None`: off (or C0).
    pub forecast_correction: Option<CorrectionSummary>,
}

/// What the forecast correction did over a run.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct CorrectionSummary {
    /// Times the measured hand force contradicted the forecast, and the plant time it did.
    pub contradictions: u64,
    pub contradicted_time: f64,
    /// κ̂: smallest, largest and last; τ̂ last (s); d̂ last (N).
    pub factor_min: f64,
    pub factor_max: f64,
    pub factor_last: f64,
    pub shift_last: f64,
    pub offset_last: [f64; 3],
    /// Estimations of κ̂, τ̂; ticks whose measured force was not finite.
    pub estimations: u64,
    pub bad_measurements: u64,
}

/// The damping torques [`send_damping`] publishes: `−damping · qd`, for state `step`.
struct DampingMsg<'a> {
    seq: u64,
    step: u64,
    session: u64,
    controller: u64,
    damping: f64,
    /// Joint rates of the last state (length: the actuated joints).
    qd: &'a [f64],
}

/// Publishes joint damping torques flagged [`TORQUE_FLAG_FALLBACK`] and wakes the plant.
fn send_damping(
    torques: &Publisher<TorqueMsg>,
    events: &Notifier,
    d: DampingMsg,
) -> Result<(), ChannelError> {
    torques.send_with(|m| {
        m.seq = d.seq;
        m.state_step = d.step;
        m.session = d.session;
        m.controller = d.controller;
        m.n = d.qd.len() as u32;
        m.flags = TORQUE_FLAG_FALLBACK;
        for (t, qd) in m.tau.iter_mut().zip(d.qd) {
            *t = -d.damping * qd;
        }
    })?;
    events.notify()
}

/// The result of an IPC step of the loop; on its failure, `safe` runs once first (it sends
/// damping torques when there is a state to damp: `Ok(true)`), and the step's error is returned
/// whatever `safe` gives.
fn or_safe_torques<T>(
    step: Result<T, ChannelError>,
    safe: impl FnOnce() -> Result<bool, ChannelError>,
) -> Result<T, ChannelError> {
    step.map_err(|e| {
        match safe() {
            Ok(true) => tracing::error!("IPC failed ({e}): damping torques sent, stopping"),
            Ok(false) => tracing::error!("IPC failed ({e}) before any state: stopping"),
            Err(e2) => tracing::error!(
                "IPC failed ({e}), and the damping torques could not be sent either ({e2}): \
                 stopping"
            ),
        }
        e
    })
}

/// Record why a lockstep run will not reproduce (the first reason only).
fn not_reproducible(reason: &mut Option<&'static str>, why: &'static str) {
    if reason.is_none() {
        *reason = Some(why);
        tracing::warn!("this run is not reproducible: {why}");
    }
}

pub fn run_server(
    config: &Config,
    model: Model,
    opts: &ServerOptions,
    stop: Arc<AtomicBool>,
) -> Result<ServerSummary, Box<dyn std::error::Error + Send + Sync>> {
    run_server_with(config, model, opts, stop, None)
}

/// [`run_server`] with C2's gain search replaced by `c2_solver` (when the controller is C2):
/// for tests that make C2 fail, panic or lag. Not reachable from the command line.
pub fn run_server_with(
    config: &Config,
    model: Model,
    opts: &ServerOptions,
    stop: Arc<AtomicBool>,
    c2_solver: Option<Box<dyn GainSolver>>,
) -> Result<ServerSummary, Box<dyn std::error::Error + Send + Sync>> {
    let cc = &config.controller;
    let kind = cc.kind;
    let dt = 1.0 / cc.rate_hz;
    let weight = model.total_mass() * config.robot.gravity;
    // Every state and torque message holds at most MAX_DOF values, and the loop slices its
    // buffers by the model's sizes: a larger model could never be served.
    if model.nq > MAX_DOF || model.nv > MAX_DOF {
        return Err(format!(
            "the model has nq = {}, nv = {}: the channels carry at most {MAX_DOF} each; lock \
             the joints the controller need not move (`locked` in the robot description)",
            model.nq, model.nv
        )
        .into());
    }
    let bus = Bus::open(&opts.prefix, "controller")?;
    let states = bus.subscriber::<StateMsg>()?;
    let state_events = bus.listener(ServiceKind::State)?;
    let torques = bus.publisher::<TorqueMsg>()?;
    let torque_events = bus.notifier(ServiceKind::Torques)?;
    let lockstep = cc.mode == LoopMode::Lockstep;
    // One thread for faer (C2's normal equations): parallel reductions may sum in another order
    // from one run to the next, and on two cores rayon's workers compete with the loop.
    faer::set_global_parallelism(faer::Par::Seq);
    let controller_id = crate::channels::new_run_id();

    let mut core = ControllerCore::new(
        model,
        config,
        kind,
        dt,
        [cc.com_height_kp, cc.com_height_kd],
        opts.zmp_offset,
    )?
    .with_robot_hash(opts.robot_hash.unwrap_or(0));
    let n_tau = core.model.nv - 6;
    let horizon_time = config.preview.horizon as f64 * config.preview.period;
    let mut intake = ForecastIntake::new(
        ForecastWindow::new(
            cc.forecast_max_age,
            cc.forecast_max_lead,
            cc.forecast_decay,
            weight,
        ),
        bus.subscriber::<ForecastMsg>()?,
        bus.listener(ServiceKind::Forecast)?,
        (
            (lockstep && cc.lockstep_forecast_wait > 0.0)
                .then(|| Duration::from_secs_f64(cc.lockstep_forecast_wait)),
            Duration::from_secs_f64(cc.lockstep_first_forecast_wait),
        ),
        cc.state_timeout,
        horizon_time,
    );
    let mut c2 = match (kind, c2_solver) {
        (ControllerKind::C2, Some(solver)) => Some(GainHandoff::spawn_with(config, solver)?),
        (ControllerKind::C2, None) => Some(GainHandoff::spawn(config)?),
        _ => None,
    };
    let logger = match &opts.rrd {
        Some(p) => {
            // Lockstep keeps every tick record (the CSV is part of what reruns reproduce), so its
            // logger must get CPU time when the machine is loaded: the normal class. In real time
            // its threads (ours and the rerun SDK's) run in the idle class, see `in_background`.
            let start = || {
                ControlLogger::start(
                    p,
                    opts.csv.as_deref(),
                    &opts.recording_id,
                    opts.live.as_deref(),
                    config.preview.horizon,
                    lockstep,
                )
            };
            Some(if lockstep {
                start()?
            } else {
                super::realtime::in_background(start)?
            })
        }
        None => None,
    };
    let rt = super::realtime::apply(&cc.realtime);
    let mut ticker =
        (cc.mode == LoopMode::Realtime).then(|| Ticker::new(Duration::from_secs_f64(dt)));

    let mut s = ServerSummary {
        controller: kind.name().into(),
        robot: opts.robot_name.clone(),
        robot_mass: weight / config.robot.gravity,
        mode: format!("{:?}", cc.mode).to_lowercase(),
        min_zmp_margin: f64::INFINITY,
        realtime: rt,
        ..Default::default()
    };
    let mut hist = LatencyHistogram::new();
    // The ticks since the last status line (a soak's tick p99 over time).
    let mut window = LatencyHistogram::new();
    let mut tau = [0.0; MAX_DOF];
    // Joint rates of the last fresh state, for the damping torques of a stale period.
    let mut last_qd = [0.0; MAX_DOF];
    let mut seq = 0u64;
    let mut last_step: Option<u64> = None;
    let mut session = 0u64;
    // Why the run will not reproduce, if it will not (no allocation on the loop: set at the end).
    let mut irreproducible: Option<&'static str> = if !lockstep {
        Some("real time: inputs arrive on wall-clock time")
    } else if kind == ControllerKind::C2 && cc.lockstep_c2_wait == 0.0 {
        Some("controller.lockstep_c2_wait = 0: C2's schedules reach the loop on its own timing")
    } else {
        None
    };
    // The plant's announced scenario: hash, and name for the summary.
    let mut plant_hash = 0u64;
    let mut plant_name = [0u8; crate::channels::SCENARIO_NAME_LEN];
    let mut mismatch_warned = 0u64;
    let mut last_time = 0.0;
    let started = Instant::now();
    let mut last_state_at = Instant::now();
    let mut stale = false;
    // Lockstep: when the plant's liveness was last checked, and whether a wait for a live but
    // silent plant was logged in this stale period.
    let mut liveness_checked: Option<Instant> = None;
    let mut waiting_for_live_plant = false;
    let status_every = Duration::from_secs_f64(cc.status_every);
    let mut next_status = Instant::now() + status_every;
    let (mut hand_sq, mut c2_solve_sum, mut c2_iter_sum, mut c2_seen) = (0.0, 0.0, 0.0, 0u64);
    let mut last_c2_seq = 0u64;
    let mut schedule_was_stale = false;
    let mut com_z0: Option<f64> = None;
    // An IPC step that fails ends the run: first, one attempt at damping torques for the last
    // state (flagged fallback), so the plant is not left with the last control torques.
    macro_rules! ipc {
        ($step:expr) => {
            or_safe_torques($step, || match last_step {
                Some(step) => {
                    seq += 1;
                    send_damping(
                        &torques,
                        &torque_events,
                        DampingMsg {
                            seq,
                            step,
                            session,
                            controller: controller_id,
                            damping: config.wbc.fallback_damping,
                            qd: &last_qd[..n_tau],
                        },
                    )
                    .map(|()| true)
                }
                None => Ok(false),
            })?
        };
    }

    s.stopped_by = loop {
        if stop.load(Ordering::Relaxed) {
            break "signal".into();
        }
        if !status_every.is_zero() && Instant::now() >= next_status {
            next_status += status_every;
            let (misses, overruns) = ticker.as_ref().map_or((0, 0), |t| (t.missed, t.overruns));
            tracing::info!(
                "status: ticks {} misses {misses} overruns {overruns} stale_periods {} \
                 reconnects {} t {:.3} window_tick_p99_us {:.0} window_tick_max_us {:.0}",
                s.ticks,
                s.stale_periods,
                s.reconnects,
                s.sim_time,
                window.quantile(0.99) * 1e6,
                window.max() * 1e6
            );
            window.reset();
        }
        match ticker.as_mut() {
            Some(t) => t.wait(),
            None => {
                ipc!(state_events.wait_until(
                    Duration::from_millis(20),
                    Duration::from_secs_f64(cc.ipc_spin_us * 1e-6),
                    || states.has_samples(),
                ));
            }
        }
        let received = ipc!(states.latest());
        // A new session, or a step that goes back, is a new plant run (a restarted simulator);
        // the same step again is the lockstep simulator re-sending a state it waits on.
        let restarted = matches!((&received, last_step),
            (Some(st), Some(l)) if st.step < l || (st.session != session && st.session != 0));
        let state = match received {
            Some(st) if restarted || last_step.is_none_or(|l| st.step > l) => st,
            repeated => {
                let Some(l) = last_step else {
                    if started.elapsed().as_secs_f64() > opts.startup_timeout {
                        return Err(format!(
                            "no state from the simulator on {}/state within {} s (is it \
                             running with this prefix, and from the same upc version? a plant of \
                             another contract version cannot open the services: see its log)",
                            opts.prefix, opts.startup_timeout
                        )
                        .into());
                    }
                    continue;
                };
                s.stale_states += u64::from(ticker.is_some() || repeated.is_some());
                let quiet = last_state_at.elapsed().as_secs_f64();
                if quiet <= cc.state_timeout {
                    continue;
                }
                if !stale {
                    stale = true;
                    s.stale_periods += 1;
                    match cc.mode {
                        LoopMode::Realtime => tracing::warn!(
                            "no state for {quiet:.3} s after step {l} (t = {last_time:.3} s): \
                             damping torques until a simulator publishes again"
                        ),
                        LoopMode::Lockstep => tracing::warn!(
                            "no state for {quiet:.3} s after step {l} (t = {last_time:.3} s): \
                             waiting {} s for a simulator",
                            cc.reconnect_timeout
                        ),
                    }
                }
                match cc.mode {
                    LoopMode::Lockstep => {
                        if quiet > cc.state_timeout + cc.reconnect_timeout
                            && liveness_checked
                                .is_none_or(|t| t.elapsed() >= Duration::from_millis(100))
                        {
                            // A lockstep run is a function of its inputs, not of wall time: a
                            // plant that is slow (starved, stopped in a debugger) is waited for;
                            // one whose process is gone ends the run.
                            liveness_checked = Some(Instant::now());
                            if !states.has_live_publisher() {
                                break "simulator stopped".into();
                            }
                            if !waiting_for_live_plant {
                                waiting_for_live_plant = true;
                                tracing::warn!(
                                    "no state for {quiet:.3} s, but the simulator's process is \
                                     alive: waiting for it"
                                );
                            }
                        }
                    }
                    LoopMode::Realtime => {
                        // No state to control from: joint damping on the last measured rates,
                        // flagged so the receiver knows these are not control torques.
                        let tick_start = Instant::now();
                        for (t, qd) in tau[..n_tau].iter_mut().zip(&last_qd[..n_tau]) {
                            *t = -config.wbc.fallback_damping * qd;
                        }
                        seq += 1;
                        ipc!(torques.send_with(|m| {
                            m.seq = seq;
                            m.state_step = l;
                            m.session = session;
                            m.controller = controller_id;
                            m.n = n_tau as u32;
                            m.flags = TORQUE_FLAG_FALLBACK;
                            m.compute_ns = tick_start.elapsed().as_nanos() as u64;
                            m.tau[..n_tau].copy_from_slice(&tau[..n_tau]);
                        }));
                        ipc!(torque_events.notify());
                        s.stale_ticks += 1;
                    }
                }
                continue;
            }
        };
        if last_step.is_some() {
            let gap = last_state_at.elapsed().as_secs_f64();
            s.longest_state_gap = s.longest_state_gap.max(gap);
            if restarted {
                // The new simulator's robot starts over: latch references, the forecast's time
                // line and the metrics' initial CoM height again from this state.
                s.reconnects += 1;
                s.ticks_since_reconnect = 0;
                core.reset();
                intake.restart(state.time);
                com_z0 = None;
                tracing::warn!(
                    "simulator restarted: step {} (t = {:.3} s) after step {} (t = {last_time:.3} \
                     s), {gap:.3} s without state; references re-latched, control resumes \
                     (reconnect {})",
                    state.step,
                    state.time,
                    last_step.unwrap_or(0),
                    s.reconnects
                );
            } else if stale {
                tracing::info!(
                    "state back at step {} after {gap:.3} s: control resumes",
                    state.step
                );
            }
        }
        stale = false;
        waiting_for_live_plant = false;
        last_step = Some(state.step);
        session = state.session;
        last_time = state.time;
        let tick_start = Instant::now();
        // Lockstep waits for the forecast and C2: not the tick's compute time.
        let mut waited = Duration::ZERO;
        let nv = (state.nv as usize).min(MAX_DOF);
        for (i, qd) in last_qd[..n_tau].iter_mut().enumerate() {
            *qd = state
                .v
                .get(6 + i)
                .copied()
                .filter(|v| v.is_finite() && 6 + i < nv)
                .unwrap_or(0.0);
        }

        // The newest forecast, validated; in lockstep, the one whose period covers this
        // state's time, waited for.
        let f = ipc!(intake.take(state.time, || stop.load(Ordering::Relaxed)));
        if let Some(w) = f.waited {
            s.forecast_waits += 1;
            waited += w;
        }
        s.forecast_wait_timeouts += u64::from(f.timed_out);
        s.forecast_first_wait_expired |= f.gave_up_first;
        if f.lost {
            s.forecast_lost = true;
            s.forecast_losses += 1;
        }
        if let Some(why) = f.not_reproducible {
            not_reproducible(&mut irreproducible, why);
        }
        if lockstep && f.accepted && cc.lockstep_forecast_wait == 0.0 {
            not_reproducible(
                &mut irreproducible,
                "controller.lockstep_forecast_wait = 0: the window a tick sees depends on timing",
            );
        }
        // Scenarios: the plant's against this controller's and the forecast's.
        if state.scenario_hash != plant_hash {
            plant_hash = state.scenario_hash;
            plant_name = state.scenario;
            if let Some(mine) = opts.scenario_hash
                && plant_hash != 0
                && mine != plant_hash
            {
                s.plant_scenario_mismatch = true;
                tracing::warn!(
                    "the plant plays `{}` (hash {plant_hash:016x}), this controller was started for \
                     another scenario (hash {mine:016x}): its ZMP reference and config may not fit",
                    state.scenario_name()
                );
            }
        }
        let fh = intake.window.scenario_hash();
        if f.accepted && fh != 0 && plant_hash != 0 && fh != plant_hash {
            s.forecast_scenario_mismatches += 1;
            if mismatch_warned != fh {
                mismatch_warned = fh;
                tracing::warn!(
                    "the forecast is of another scenario (hash {fh:016x}) than the plant plays \
                     (`{}`, {plant_hash:016x}): {} such windows so far",
                    state.scenario_name(),
                    s.forecast_scenario_mismatches
                );
            }
        }
        if state.flags & STATE_FLAG_HOLD != 0 {
            s.ticks_in_plant_hold += 1;
        }

        // C2's schedule for this tick (see `GainHandoff::take_for_tick`), unless older than the
        // horizon (or from before a restart).
        let with_c2 = c2.is_some();
        if let Some(h) = c2.as_mut() {
            let r = h.take_for_tick();
            if let Some(w) = r.waited_for {
                s.c2_waits += 1;
                waited += w;
            }
            if r.timed_out {
                s.c2_wait_timeouts += 1;
                tracing::warn!(
                    "C2 did not finish a search within {} s: its schedules apply when they come \
                     until it catches up",
                    cc.lockstep_c2_wait
                );
                not_reproducible(&mut irreproducible, "a lockstep wait for C2 timed out");
            }
        }
        let schedule = c2
            .as_ref()
            .map(|h| h.current())
            .filter(|sch| sch.seq > 0 && (0.0..=horizon_time).contains(&(state.time - sch.time)));
        let stale = with_c2 && schedule.is_none() && state.time > horizon_time;
        if stale && !schedule_was_stale {
            s.c2_stale_schedules += 1;
            tracing::warn!("C2 schedule missing or older than the horizon: nominal gains");
        }
        schedule_was_stale = stale;
        if let Some(sch) = schedule
            && sch.seq != last_c2_seq
        {
            last_c2_seq = sch.seq;
            c2_seen += 1;
            c2_solve_sum += sch.solve_time;
            c2_iter_sum += sch.iterations as f64;
            s.c2_solve_max_ms = s.c2_solve_max_ms.max(sch.solve_time * 1e3);
        }
        let c2_log =
            schedule.map(|sch| (sch.cost, sch.nominal_cost, sch.iterations, sch.solve_time));

        let mut flags = 0;
        match core.tick(&state, &intake.window, schedule, &mut tau[..n_tau]) {
            Ok(crate::wbc::WbcStatus::Solved) => {}
            Ok(_) => {
                s.wbc_fallbacks += 1;
                flags |= TORQUE_FLAG_FALLBACK;
            }
            Err(e) => {
                // Safe behaviour on a malformed state: joint damping toward rest.
                s.tick_errors += 1;
                if s.tick_errors.is_power_of_two() {
                    tracing::warn!(
                        "bad state at step {}: {e} ({} so far); damping torques",
                        state.step,
                        s.tick_errors
                    );
                }
                for (i, t) in tau[..n_tau].iter_mut().enumerate() {
                    let qd = state
                        .v
                        .get(6 + i)
                        .copied()
                        .filter(|v| v.is_finite())
                        .unwrap_or(0.0);
                    *t = -config.wbc.fallback_damping * qd;
                }
                flags |= TORQUE_FLAG_FALLBACK;
            }
        }
        seq += 1;
        ipc!(torques.send_with(|m| {
            m.seq = seq;
            m.state_step = state.step;
            m.session = state.session;
            m.controller = controller_id;
            m.n = n_tau as u32;
            m.flags = flags;
            m.compute_ns = tick_start.elapsed().saturating_sub(waited).as_nanos() as u64;
            m.tau[..n_tau].copy_from_slice(&tau[..n_tau]);
        }));
        ipc!(torque_events.notify());
        // Lockstep waits for the forecast or C2 are not the plant's silence.
        last_state_at = Instant::now();
        let tick_time = tick_start.elapsed().saturating_sub(waited);
        hist.record(tick_time);
        window.record(tick_time);
        s.ticks += 1;
        s.ticks_since_reconnect += 1;
        s.sim_time = state.time;

        if let Some(h) = c2.as_mut()
            && s.ticks.is_multiple_of(cc.c2_every as u64)
        {
            h.offer(|snap| core.snapshot(snap, seq));
        }
        // Metrics of the measured ZMP and the hand.
        let rec = core.last;
        if let Some(sup) = core.support() {
            let margin = (0..2)
                .map(|a| (rec.zmp_meas[a] - sup[a][0]).min(sup[a][1] - rec.zmp_meas[a]))
                .fold(f64::INFINITY, f64::min);
            s.min_zmp_margin = s.min_zmp_margin.min(margin);
            if margin < EDGE_BAND {
                s.time_at_support_edge += dt;
            }
        }
        let z0 = *com_z0.get_or_insert(rec.com[2]);
        s.com_height_drop = s.com_height_drop.max(z0 - rec.com[2]);
        let zerr = ((rec.zmp_meas[0] - rec.zmp_ref[0]).powi(2)
            + (rec.zmp_meas[1] - rec.zmp_ref[1]).powi(2))
        .sqrt();
        s.max_zmp_error = s.max_zmp_error.max(zerr);
        hand_sq += rec.hand_err * rec.hand_err;
        s.hand_peak_error = s.hand_peak_error.max(rec.hand_err);
        if let Some(l) = &logger {
            if s.ticks.is_multiple_of(cc.log_every as u64) {
                let (c2_cost, c2_nominal_cost, c2_iterations, c2_solve_time) =
                    c2_log.unwrap_or_default();
                l.tick(TickLog {
                    core: rec,
                    tick_time: tick_time.as_secs_f64(),
                    c2_cost,
                    c2_nominal_cost,
                    c2_iterations,
                    c2_solve_time,
                });
            }
            if s.ticks.is_multiple_of(10 * cc.log_every as u64) {
                l.plan(|p| core.fill_plan(p));
            }
        }
        if opts.duration.is_some_and(|d| state.time >= d - 0.5 * dt) {
            break "duration reached".into();
        }
    };

    s.tick_p50_us = hist.quantile(0.5) * 1e6;
    s.tick_p99_us = hist.quantile(0.99) * 1e6;
    s.tick_max_us = hist.max() * 1e6;
    if let Some(t) = &ticker {
        s.deadline_overruns = t.overruns;
        s.deadline_misses = t.missed;
    }
    s.preview_fallbacks = core.preview_fallbacks;
    s.forecast_correction = core.correction_counts().map(|c| {
        let e = core.last.correction;
        CorrectionSummary {
            contradictions: c.contradictions,
            contradicted_time: c.contradicted_time,
            factor_min: c.factor_min,
            factor_max: c.factor_max,
            factor_last: e.factor,
            shift_last: e.shift,
            offset_last: e.offset,
            estimations: c.estimations,
            bad_measurements: c.bad_measurements,
        }
    });
    let wc = core.wbc_counters();
    s.wbc_torque_limited_ticks = wc.torque_limited;
    s.wbc_condensation_failures = wc.condensation_failures;
    s.forecasts_accepted = intake.window.accepted;
    s.forecast_never_received = intake.window.accepted == 0;
    s.forecast_first_at = intake.first_at;
    s.forecasts_rejected = intake.window.rejected;
    s.forecasts_rejected_by = intake.window.rejections;
    s.forecaster_restarts = intake.window.restarts;
    s.reproducible = irreproducible.is_none();
    s.reproducibility = irreproducible.unwrap_or_default().into();
    s.plant_scenario = format!(
        "{} ({plant_hash:016x})",
        crate::channels::scenario_name(&plant_name)
    );
    if let Some(h) = &c2 {
        s.c2_solves = h.stats.solves.load(Ordering::Relaxed);
        s.c2_failures = h.stats.failures.load(Ordering::Relaxed);
        s.c2_panics = h.stats.panics.load(Ordering::Relaxed);
    }
    if c2_seen > 0 {
        s.c2_solve_mean_ms = c2_solve_sum / c2_seen as f64 * 1e3;
        s.c2_iterations_mean = c2_iter_sum / c2_seen as f64;
    }
    if s.ticks > 0 {
        s.hand_rms_error = (hand_sq / s.ticks as f64).sqrt();
    }
    if !s.min_zmp_margin.is_finite() {
        s.min_zmp_margin = 0.0;
    }
    if let Some(l) = logger {
        s.dropped_log_records = l.dropped.load(Ordering::Relaxed);
        l.finish();
    }
    s.dropped_log_lines = crate::logging::dropped_lines();
    drop(c2);
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn failure() -> ChannelError {
        ChannelError {
            what: "receive".into(),
            detail: "injected".into(),
        }
    }

    #[test]
    fn a_failed_ipc_step_sends_safe_torques_once_then_fails() {
        let mut calls = 0;
        let ok: Result<u32, ChannelError> = or_safe_torques(Ok(7), || {
            calls += 1;
            Ok(true)
        });
        assert_eq!(
            (ok.unwrap(), calls),
            (7, 0),
            "a step that works sends nothing more"
        );
        let e = or_safe_torques::<u32>(Err(failure()), || {
            calls += 1;
            Ok(true)
        })
        .unwrap_err();
        assert_eq!((e.detail.as_str(), calls), ("injected", 1));
        // The step's own error comes back even when the safe torques fail too.
        let e = or_safe_torques::<u32>(Err(failure()), || {
            calls += 1;
            Err(ChannelError {
                what: "send sample".into(),
                detail: "also down".into(),
            })
        })
        .unwrap_err();
        assert_eq!((e.detail.as_str(), calls), ("injected", 2));
    }

    /// Over real IPC: after a failed step, a torque subscriber on the prefix sees the damping
    /// torques of the last state, flagged fallback, and the failure is still returned.
    #[test]
    fn safe_torques_reach_a_subscriber_after_a_failed_step() {
        let prefix = format!("upc_test_safe_torques_{}", std::process::id());
        let bus = Bus::open(&prefix, "controller_test").expect("bus");
        let torques = bus.publisher::<TorqueMsg>().expect("pub");
        let events = bus.notifier(ServiceKind::Torques).expect("notifier");
        let plant = bus.subscriber::<TorqueMsg>().expect("sub");
        let qd = [0.5, -1.0, 2.0];
        let e = or_safe_torques::<()>(Err(failure()), || {
            send_damping(
                &torques,
                &events,
                DampingMsg {
                    seq: 9,
                    step: 41,
                    session: 3,
                    controller: 5,
                    damping: 2.0,
                    qd: &qd,
                },
            )
            .map(|()| true)
        })
        .unwrap_err();
        assert_eq!(e.detail, "injected");
        let m = plant.latest().expect("receive").expect("a torque message");
        assert_eq!(m.flags, TORQUE_FLAG_FALLBACK);
        assert_eq!((m.seq, m.state_step, m.session, m.n), (9, 41, 3, 3));
        assert_eq!(&m.tau[..3], &[-1.0, 2.0, -4.0]);
        assert!(m.tau[3..].iter().all(|&t| t == 0.0));
    }
}
