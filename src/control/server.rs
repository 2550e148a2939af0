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

use super::contract::read_state;
use super::forecast_intake::ForecastIntake;
use super::gain_thread::GainSolver;
use super::logger::{ControlLogger, TickLog};
pub use super::parts::forecast_correction::CorrectionSummary;
use super::plant_link::{LinkTimeouts, PlantLink, Verdict};
use super::run_metrics::RunMetrics;
use super::summary::LoopEvents;
pub use super::summary::ServerSummary;
use super::{ControllerCore, ControllerPart, ForecastWindow, GainHandoff, TickError, Ticker};
use crate::channels::{
    ChannelError, ContractNode, ForecastMsg, Listener, MAX_DOF, Notifier, Publisher, ServiceKind,
    StateMsg, Subscriber, TORQUE_FLAG_FALLBACK, TorqueMsg,
};
use crate::col;
use crate::config::{Config, ControllerKind, LoopMode};
use crate::record::{Column, Record};
use crate::robot::{ReducedModel, Robot, RobotState};
use crate::wbc::{FallbackReason, WbcStatus, damping_torques};

/// The phase lock's lead and step, as a fraction of the period: 1/8, well inside the grace
/// wait (`state_grace`, half a period by default).
const PHASE_STEP: u32 = 8;

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
    /// What the hand holds: its apparent mass at the hand (world, kg; zero: nothing), from the
    /// scene ([`crate::config::HeldObject`]).
    pub held_mass: nalgebra::Matrix3<f64>,
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
    /// The drives' effort limits.
    limits: &'a [f64],
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
        let n = d.qd.len().min(m.tau.len());
        m.n = n as u32;
        m.flags = TORQUE_FLAG_FALLBACK;
        damping_torques(d.damping, d.qd, d.limits, &mut m.tau[..n]);
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
    robot: &Robot,
    opts: &ServerOptions,
    stop: Arc<AtomicBool>,
) -> Result<ServerSummary, Box<dyn std::error::Error + Send + Sync>> {
    run_server_with(config, robot, opts, stop, Extensions::default())
}

/// What a program of its own adds to upc's controller, without editing upc (a lab's binary
/// that calls [`run_server_with`]; `examples/lab_part.rs`).
#[derive(Default)]
pub struct Extensions {
    /// Parts run after those of `super::parts::PIPELINE`, at their stages
    /// ([`ControllerCore::add_part`]): they record and report as upc's do.
    pub parts: Vec<Box<dyn ControllerPart>>,
    /// C2's gain search replaced (when the controller is C2): tests make C2 fail, panic or lag.
    pub c2_solver: Option<Box<dyn GainSolver>>,
}

/// [`run_server`] with `extensions`.
pub fn run_server_with(
    config: &Config,
    robot: &Robot,
    opts: &ServerOptions,
    stop: Arc<AtomicBool>,
    extensions: Extensions,
) -> Result<ServerSummary, Box<dyn std::error::Error + Send + Sync>> {
    ControlLoop::open(config, robot, opts, extensions)?.run(&stop)
}

/// The loop's iceoryx2 ports to the plant.
struct PlantPorts {
    states: Subscriber<StateMsg>,
    state_events: Listener,
    torques: Publisher<TorqueMsg>,
    torque_events: Notifier,
}

/// The plant's announced scenario, checked against this controller's and the forecast's.
struct ScenarioCheck {
    plant_hash: u64,
    plant_name: [u8; crate::channels::SCENARIO_NAME_LEN],
    warned_forecast: u64,
}

/// Everything the loop keeps between ticks. One pass: receive → classify ([`PlantLink`]) →
/// tick (forecast, C2's schedule, the core) → publish → record ([`RunMetrics`]) → log.
struct ControlLoop<'a> {
    config: &'a Config,
    opts: &'a ServerOptions,
    dt: f64,
    horizon_time: f64,
    ports: PlantPorts,
    core: ControllerCore,
    /// The robot as the last state measured it (the contract read once, at this edge), and the
    /// robot hash states must announce (0: not checked).
    sensed: RobotState,
    robot_hash: u64,
    intake: ForecastIntake,
    c2: Option<GainHandoff>,
    logger: Option<ControlLogger>,
    ticker: Option<Ticker>,
    link: PlantLink,
    metrics: RunMetrics,
    /// The run's identity in the summary (the counters are placed at the end), and the loop's
    /// events, counted as they happen.
    s: ServerSummary,
    events: LoopEvents,
    n_tau: usize,
    controller_id: u64,
    seq: u64,
    tau: [f64; MAX_DOF],
    /// The flags of the last answer (sent again with it to a plant that missed it).
    last_flags: u32,
    /// Joint rates of the last fresh state, for the damping torques of a stale period.
    last_qd: [f64; MAX_DOF],
    /// Why the run will not reproduce, if it will not (no allocation on the loop).
    irreproducible: Option<&'static str>,
    scenario: ScenarioCheck,
    schedule_was_stale: bool,
    status_every: Duration,
    next_status: Instant,
}

/// What one tick took from the forecast and C2.
#[derive(Default)]
struct Inputs {
    /// Lockstep waits for the forecast and C2: not the tick's compute time.
    waited: Duration,
    /// C2's schedule in use: cost, nominal cost, iterations, solve time (for the log).
    c2_log: Option<(f64, f64, u32, f64)>,
}

impl<'a> ControlLoop<'a> {
    fn open(
        config: &'a Config,
        robot: &Robot,
        opts: &'a ServerOptions,
        extensions: Extensions,
    ) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        let cc = &config.controller;
        let (kind, dt) = (cc.kind, 1.0 / cc.rate_hz);
        let lockstep = cc.mode == LoopMode::Lockstep;
        let (model, robot_mass) = (&robot.model, robot.derived.mass);
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
        let node = ContractNode::open(&opts.prefix, "controller")?;
        let ports = PlantPorts {
            states: node.subscriber::<StateMsg>()?,
            state_events: node.listener(ServiceKind::State)?,
            torques: node.publisher::<TorqueMsg>()?,
            torque_events: node.notifier(ServiceKind::Torques)?,
        };
        // One thread for faer (C2's normal equations): parallel reductions may sum in another
        // order from one run to the next, and on two cores rayon's workers compete with the loop.
        faer::set_global_parallelism(faer::Par::Seq);
        let mut core = ControllerCore::new(
            robot,
            config,
            kind,
            dt,
            [cc.com_height_kp, cc.com_height_kd],
            opts.zmp_offset,
        )?
        .with_held_mass(opts.held_mass);
        for part in extensions.parts {
            core.add_part(part);
        }
        let n_tau = core.model.nv - 6;
        let horizon_time = config.preview.horizon as f64 * config.preview.period;
        let free_dir = cc
            .forecast_on_free_direction
            .then(|| super::held_object::free_direction(&opts.held_mass))
            .flatten();
        let intake = forecast_intake(config, &node, robot_mass, horizon_time, free_dir)?;
        let c2 = start_c2(config, &robot.reduced(), extensions.c2_solver)?;
        let logger = start_logger(config, opts, &core)?;
        let status_every = Duration::from_secs_f64(cc.status_every);
        Ok(ControlLoop {
            config,
            opts,
            dt,
            horizon_time,
            ports,
            sensed: RobotState::new(model.nq, model.nv),
            robot_hash: opts.robot_hash.unwrap_or(0),
            core,
            intake,
            c2,
            logger,
            ticker: (!lockstep).then(|| Ticker::new(Duration::from_secs_f64(dt))),
            link: PlantLink::new(
                cc.mode,
                LinkTimeouts {
                    state: cc.state_timeout,
                    reconnect: cc.reconnect_timeout,
                    startup: opts.startup_timeout,
                },
            ),
            metrics: RunMetrics::new(dt),
            s: ServerSummary {
                controller: kind.name().into(),
                robot: opts.robot_name.clone(),
                robot_mass,
                mode: format!("{:?}", cc.mode).to_lowercase(),
                realtime: crate::realtime::apply(&cc.realtime),
                ..Default::default()
            },
            events: LoopEvents::default(),
            n_tau,
            controller_id: crate::channels::new_run_id(),
            seq: 0,
            tau: [0.0; MAX_DOF],
            last_flags: 0,
            last_qd: [0.0; MAX_DOF],
            irreproducible: initially_irreproducible(cc),
            scenario: ScenarioCheck {
                plant_hash: 0,
                plant_name: [0; crate::channels::SCENARIO_NAME_LEN],
                warned_forecast: 0,
            },
            schedule_was_stale: false,
            status_every,
            next_status: Instant::now() + status_every,
        })
    }

    fn run(
        mut self,
        stop: &AtomicBool,
    ) -> Result<ServerSummary, Box<dyn std::error::Error + Send + Sync>> {
        let stopped_by = loop {
            if stop.load(Ordering::Relaxed) {
                break "signal";
            }
            self.status_line();
            self.wait_for_state()?;
            let received = self.ports.states.latest();
            let received = self.or_safe_torques(received)?;
            let states = &self.ports.states;
            let verdict = self
                .link
                .classify(received.as_ref(), || states.has_live_publisher());
            let state = match (verdict, received) {
                (Verdict::Control { restarted }, Some(state)) => {
                    if restarted {
                        // The new plant's robot starts over: latch references, the forecast's
                        // time line and the initial CoM height again from this state.
                        self.core.reset();
                        self.intake.restart(state.time);
                        self.metrics.restart();
                    }
                    state
                }
                (Verdict::Damp { step }, _) => {
                    self.damp_stale(step)?;
                    continue;
                }
                (Verdict::Reanswer { step }, Some(state)) if state.step == step => {
                    self.publish(&state, self.last_flags, Duration::ZERO)?;
                    continue;
                }
                (Verdict::Gone, _) => break "simulator stopped",
                (Verdict::NeverStarted, _) => {
                    return Err(format!(
                        "no state from the simulator on {}/state within {} s (is it running \
                         with this prefix, and from the same upc version? a plant of another \
                         contract version cannot open the services: see its log)",
                        self.opts.prefix, self.opts.startup_timeout
                    )
                    .into());
                }
                _ => continue,
            };
            self.control(&state, stop)?;
            if self
                .opts
                .duration
                .is_some_and(|d| state.time >= d - 0.5 * self.dt)
            {
                break "duration reached";
            }
        };
        Ok(self.finish(stopped_by))
    }

    /// Real time: the ticker's next deadline. Lockstep: the plant's next state (bounded).
    fn wait_for_state(&mut self) -> Result<(), ChannelError> {
        let Some(t) = self.ticker.as_mut() else {
            let spin = Duration::from_secs_f64(self.config.controller.ipc_spin_us * 1e-6);
            let states = &self.ports.states;
            let woken = self
                .ports
                .state_events
                .wait_until(Duration::from_millis(20), spin, || states.has_samples());
            return self.or_safe_torques(woken).map(|_| ());
        };
        t.wait();
        // The plant's clock and this ticker run apart. When the plant publishes just after this
        // deadline, the state would wait a period and the next deadline's newer one would drop
        // it: measured, one stall that shifted the ticker's phase there cost 18 % of the states
        // for the rest of an hour. Waiting a part of the period for it runs the loop in step
        // with the plant's cycle, as a robot's controller runs on its bus cycle; a silent plant
        // costs only that wait before the stale-state handling.
        // The deadlines also follow the plant's cycle (a phase lock): a state already waiting
        // at a deadline moves the next one earlier, one that arrives in the wait puts the next
        // deadline just before the next state. The tick then starts as the state arrives: on a
        // robot's bus at 500 Hz, unlocked, the answer came up to a period after the state
        // (1.5 ms p50 in one run of two), which the bus cannot wait for.
        let grace = t.period().mul_f64(self.config.controller.state_grace);
        // A plant silent for two periods is not about to publish: no wait for it. Its process
        // may be gone, and iceoryx2's wait on a dead notifier's event overruns by ~8 ms (measured:
        // a SIGKILLed plant's controller ran at 124 Hz instead of 1 kHz); the ticker's own
        // deadlines keep the loop, and its damping, at its rate.
        let silent = self.link.quiet_at(Instant::now()) > 2.0 * t.period().as_secs_f64();
        if !grace.is_zero() && !silent {
            if self.ports.states.has_samples() {
                t.advance(t.period() / PHASE_STEP);
            } else {
                let states = &self.ports.states;
                let woken = self
                    .ports
                    .state_events
                    .wait_until(grace, Duration::ZERO, || states.has_samples());
                if matches!(woken, Ok(true)) {
                    t.lock_to(Instant::now(), t.period() / PHASE_STEP);
                }
                self.or_safe_torques(woken)?;
            }
        }
        Ok(())
    }

    /// One control tick from `state`: read at this edge into the robot as measured, inputs, the
    /// core, the torques out, the figures.
    fn control(&mut self, state: &StateMsg, stop: &AtomicBool) -> Result<(), ChannelError> {
        let tick_start = Instant::now();
        let read = read_state(state, self.robot_hash, &mut self.sensed);
        if read.is_ok() {
            // The joint rates of the last state read, for the damping of a silence or a fault.
            let v = self.sensed.v.as_slice().get(6..).unwrap_or(&[]);
            for (qd, v) in self.last_qd[..self.n_tau].iter_mut().zip(v) {
                *qd = if v.is_finite() { *v } else { 0.0 };
            }
        }
        let mut inputs = Inputs::default();
        let accepted = self.take_forecast(stop, &mut inputs)?;
        self.check_scenarios(state, accepted);
        if self.sensed.held {
            self.events.ticks_in_plant_hold += 1;
        }
        self.pick_up_c2(&mut inputs);
        let flags = self.compute(state.step, read, &mut inputs);
        self.publish(
            state,
            flags,
            tick_start.elapsed().saturating_sub(inputs.waited),
        )?;
        // Lockstep waits for the forecast or C2 are not the plant's silence.
        self.link.answered();
        let tick_time = tick_start.elapsed().saturating_sub(inputs.waited);
        self.metrics
            .tick(&self.core.last, self.core.support(), tick_time);
        // No search for a fallen robot: its schedule would never be used (nor waited for).
        if let Some(h) = self.c2.as_mut()
            && !self.core.last.fallen
            && self
                .metrics
                .ticks
                .is_multiple_of(self.config.controller.c2_every as u64)
        {
            let (core, seq) = (&self.core, self.seq);
            h.offer(|snap| core.snapshot(snap, seq));
        }
        self.record(tick_time, inputs.c2_log);
        Ok(())
    }

    /// The newest forecast, validated; in lockstep, the one whose period covers this state's
    /// time, waited for. Whether a window was accepted this tick.
    fn take_forecast(
        &mut self,
        stop: &AtomicBool,
        inputs: &mut Inputs,
    ) -> Result<bool, ChannelError> {
        let taken = self
            .intake
            .take(self.sensed.time, || stop.load(Ordering::Relaxed));
        let f = self.or_safe_torques(taken)?;
        if let Some(w) = f.waited {
            self.events.forecast_waits += 1;
            inputs.waited += w;
        }
        self.events.forecast_wait_timeouts += u64::from(f.timed_out);
        self.events.forecast_first_wait_expired |= f.gave_up_first;
        if f.lost {
            self.events.forecast_lost = true;
            self.events.forecast_losses += 1;
        }
        if let Some(why) = f.not_reproducible {
            not_reproducible(&mut self.irreproducible, why);
        }
        let cc = &self.config.controller;
        if cc.mode == LoopMode::Lockstep && f.accepted && cc.lockstep_forecast_wait == 0.0 {
            not_reproducible(
                &mut self.irreproducible,
                "controller.lockstep_forecast_wait = 0: the window a tick sees depends on timing",
            );
        }
        Ok(f.accepted)
    }

    /// The plant's scenario against this controller's and the forecast's.
    fn check_scenarios(&mut self, state: &StateMsg, accepted: bool) {
        let sc = &mut self.scenario;
        if state.scenario_hash != sc.plant_hash {
            sc.plant_hash = state.scenario_hash;
            sc.plant_name = state.scenario;
            if let Some(mine) = self.opts.scenario_hash
                && sc.plant_hash != 0
                && mine != sc.plant_hash
            {
                self.events.plant_scenario_mismatch = true;
                tracing::warn!(
                    "the plant plays `{}` (hash {:016x}), this controller was started for \
                     another scenario (hash {mine:016x}): its ZMP reference and config may not fit",
                    state.scenario_name(),
                    sc.plant_hash
                );
            }
        }
        let fh = self.intake.window.scenario_hash();
        if accepted && fh != 0 && sc.plant_hash != 0 && fh != sc.plant_hash {
            self.events.forecast_scenario_mismatches += 1;
            if sc.warned_forecast != fh {
                sc.warned_forecast = fh;
                tracing::warn!(
                    "the forecast is of another scenario (hash {fh:016x}) than the plant plays \
                     (`{}`, {:016x}): {} such windows so far",
                    state.scenario_name(),
                    sc.plant_hash,
                    self.events.forecast_scenario_mismatches
                );
            }
        }
    }

    /// C2's schedule for this tick (see `GainHandoff::take_for_tick`).
    fn pick_up_c2(&mut self, inputs: &mut Inputs) {
        let Some(h) = self.c2.as_mut() else { return };
        let r = h.take_for_tick();
        if let Some(w) = r.waited_for {
            self.events.c2_waits += 1;
            inputs.waited += w;
        }
        if r.timed_out {
            self.events.c2_wait_timeouts += 1;
            tracing::warn!(
                "C2 did not finish a search within {} s: its schedules apply when they come \
                 until it catches up",
                self.config.controller.lockstep_c2_wait
            );
            not_reproducible(&mut self.irreproducible, "a lockstep wait for C2 timed out");
        }
    }

    /// The core's tick into `self.tau` on the robot as read (`read`: whether the state could
    /// be), with C2's schedule unless older than the horizon (or from before a restart); damping
    /// torques on a malformed state. The torques' flags.
    fn compute(&mut self, step: u64, read: Result<(), TickError>, inputs: &mut Inputs) -> u32 {
        let (horizon, time) = (self.horizon_time, self.sensed.time);
        let schedule = self
            .c2
            .as_ref()
            .map(|h| h.current())
            .filter(|sch| sch.seq > 0 && (0.0..=horizon).contains(&(time - sch.time)));
        let stale = self.c2.is_some() && schedule.is_none() && time > horizon;
        if stale && !self.schedule_was_stale {
            self.events.c2_stale_schedules += 1;
            tracing::warn!("C2 schedule missing or older than the horizon: nominal gains");
        }
        self.schedule_was_stale = stale;
        if let Some(sch) = schedule {
            self.metrics.schedule(sch);
        }
        inputs.c2_log =
            schedule.map(|sch| (sch.cost, sch.nominal_cost, sch.iterations, sch.solve_time));
        if self.config.controller.forecast_felt_at_hand {
            // FC-0b with the arm's inertia of the last tick: the next windows are taken so.
            self.intake
                .window
                .set_felt_direction(self.core.felt_direction());
        }
        let tau = &mut self.tau[..self.n_tau];
        let result = read.and_then(|()| {
            self.core
                .tick(&self.sensed, &self.intake.window, schedule, tau)
        });
        match result {
            Ok(WbcStatus::Solved) => 0,
            Ok(WbcStatus::Fallback(FallbackReason::Fallen)) => TORQUE_FLAG_FALLBACK,
            Ok(_) => {
                self.events.wbc_fallbacks += 1;
                TORQUE_FLAG_FALLBACK
            }
            Err(e) => {
                // Safe behaviour on a malformed state: joint damping toward rest, on the last
                // finite rates read.
                self.events.tick_errors += 1;
                if self.events.tick_errors.is_power_of_two() {
                    tracing::warn!(
                        "bad state at step {step}: {e} ({} so far); damping torques",
                        self.events.tick_errors
                    );
                }
                let qd = &self.last_qd[..self.n_tau];
                let limits = self.core.torque_limits();
                damping_torques(self.config.wbc.fallback_damping, qd, limits, tau);
                TORQUE_FLAG_FALLBACK
            }
        }
    }

    /// Sends `self.tau` answering `state`, and wakes the plant.
    fn publish(
        &mut self,
        state: &StateMsg,
        flags: u32,
        compute: Duration,
    ) -> Result<(), ChannelError> {
        self.seq += 1;
        self.last_flags = flags;
        let (seq, id, n, tau) = (self.seq, self.controller_id, self.n_tau, &self.tau);
        let sent = self.ports.torques.send_with(|m| {
            m.seq = seq;
            m.state_step = state.step;
            m.session = state.session;
            m.controller = id;
            m.n = n as u32;
            m.flags = flags;
            m.compute_ns = compute.as_nanos() as u64;
            m.tau[..n].copy_from_slice(&tau[..n]);
        });
        self.or_safe_torques(sent)?;
        let woken = self.ports.torque_events.notify();
        self.or_safe_torques(woken)
    }

    /// Real time without a state to control from: joint damping on the last measured rates,
    /// flagged so the receiver knows these are not control torques.
    fn damp_stale(&mut self, step: u64) -> Result<(), ChannelError> {
        let tick_start = Instant::now();
        self.seq += 1;
        let (seq, session, id) = (self.seq, self.link.session(), self.controller_id);
        let (n, damping, qd) = (self.n_tau, self.config.wbc.fallback_damping, &self.last_qd);
        let limits = self.core.torque_limits();
        let sent = self.ports.torques.send_with(|m| {
            m.seq = seq;
            m.state_step = step;
            m.session = session;
            m.controller = id;
            m.n = n as u32;
            m.flags = TORQUE_FLAG_FALLBACK;
            m.compute_ns = tick_start.elapsed().as_nanos() as u64;
            damping_torques(damping, &qd[..n], limits, &mut m.tau[..n]);
        });
        self.or_safe_torques(sent)?;
        let woken = self.ports.torque_events.notify();
        self.or_safe_torques(woken)?;
        self.events.stale_ticks += 1;
        Ok(())
    }

    /// The tick's record and, every tenth, the plan, to the logger thread (never waiting).
    fn record(&mut self, tick_time: Duration, c2_log: Option<(f64, f64, u32, f64)>) {
        let Some(l) = &self.logger else { return };
        let every = self.config.controller.log_every as u64;
        // Records at plant times that are multiples of the record period (the first tick's
        // state is at t = 0), the instants the plant's ground truth is recorded at.
        let ticks = self.metrics.ticks.saturating_sub(1);
        if ticks.is_multiple_of(every) {
            let mut record = Record::default();
            self.core.record(&mut record);
            loop_columns(&mut record, tick_time, c2_log.unwrap_or_default());
            l.tick(TickLog {
                time: self.core.last.time,
                record,
            });
        }
        if ticks.is_multiple_of(10 * every) {
            let core = &mut self.core;
            l.plan(|p| core.fill_plan(p));
        }
    }

    /// Every `controller.status_every`: a status line (a soak reads it).
    fn status_line(&mut self) {
        if self.status_every.is_zero() || Instant::now() < self.next_status {
            return;
        }
        self.next_status += self.status_every;
        let (misses, overruns) = self
            .ticker
            .as_ref()
            .map_or((0, 0), |t| (t.missed, t.overruns));
        let (p99, max) = self.metrics.take_window();
        tracing::info!(
            "status: ticks {} misses {misses} overruns {overruns} stale_periods {} reconnects {} \
             t {:.3} window_tick_p99_us {:.0} window_tick_max_us {:.0}",
            self.metrics.ticks,
            self.link.counts.stale_periods,
            self.link.counts.reconnects,
            self.metrics.sim_time,
            p99 * 1e6,
            max * 1e6
        );
    }

    /// An IPC step that fails ends the run: first, one attempt at damping torques for the last
    /// state (flagged fallback), so the plant is not left with the last control torques.
    fn or_safe_torques<T>(&mut self, step: Result<T, ChannelError>) -> Result<T, ChannelError> {
        let (ports, last_qd, n, core) = (&self.ports, &self.last_qd, self.n_tau, &self.core);
        let (seq, link) = (&mut self.seq, &self.link);
        let (controller, damping) = (self.controller_id, self.config.wbc.fallback_damping);
        or_safe_torques(step, || match link.last_step() {
            Some(step) => {
                *seq += 1;
                send_damping(
                    &ports.torques,
                    &ports.torque_events,
                    DampingMsg {
                        seq: *seq,
                        step,
                        session: link.session(),
                        controller,
                        damping,
                        qd: &last_qd[..n],
                        limits: core.torque_limits(),
                    },
                )
                .map(|()| true)
            }
            None => Ok(false),
        })
    }

    /// The summary of the run: each piece's counters as it reports them.
    fn finish(mut self, stopped_by: &str) -> ServerSummary {
        let mut s = std::mem::take(&mut self.s);
        s.stopped_by = stopped_by.into();
        s.figures = self.metrics.figures();
        s.deadlines = self.ticker.as_ref().map(Ticker::counts).unwrap_or_default();
        s.link = self.link.counts;
        s.events = self.events;
        s.core = self.core.info();
        s.wbc = self.core.wbc_counters();
        s.forecasts = self.intake.counts();
        s.c2 = self
            .c2
            .as_ref()
            .map(GainHandoff::counts)
            .unwrap_or_default();
        self.core.summarize(&mut s.parts);
        s.reproducible = self.irreproducible.is_none();
        s.reproducibility = self.irreproducible.unwrap_or_default().into();
        s.plant_scenario = format!(
            "{} ({:016x})",
            crate::channels::scenario_name(&self.scenario.plant_name),
            self.scenario.plant_hash
        );
        if let Some(l) = self.logger.take() {
            s.dropped_log_records = l.dropped.load(Ordering::Relaxed);
            l.finish();
        }
        s.dropped_log_lines = crate::logging::dropped_lines();
        s
    }
}

/// C2's gain search in its thread, for C2 (`solver`: a test's stand-in).
fn start_c2(
    config: &Config,
    robot: &ReducedModel,
    solver: Option<Box<dyn GainSolver>>,
) -> Result<Option<GainHandoff>, Box<dyn std::error::Error + Send + Sync>> {
    Ok(match (config.controller.kind, solver) {
        (ControllerKind::C2, Some(solver)) => Some(GainHandoff::spawn_with(config, solver)?),
        (ControllerKind::C2, None) => Some(GainHandoff::spawn(config, robot)?),
        _ => None,
    })
}

/// Why a run cannot reproduce from its configuration alone, if it cannot.
fn initially_irreproducible(cc: &crate::config::ControllerConfig) -> Option<&'static str> {
    if cc.mode != LoopMode::Lockstep {
        Some("real time: inputs arrive on wall-clock time")
    } else if cc.kind == ControllerKind::C2 && cc.lockstep_c2_wait == 0.0 {
        Some("controller.lockstep_c2_wait = 0: C2's schedules reach the loop on its own timing")
    } else {
        None
    }
}

/// The forecast's intake: its validation window and, in lockstep, its waits.
fn forecast_intake(
    config: &Config,
    node: &ContractNode,
    robot_mass: f64,
    horizon_time: f64,
    free_dir: Option<nalgebra::Vector3<f64>>,
) -> Result<ForecastIntake, ChannelError> {
    let cc = &config.controller;
    let lockstep = cc.mode == LoopMode::Lockstep;
    let mut window = ForecastWindow::new(
        cc.forecast_max_age,
        cc.forecast_max_lead,
        cc.forecast_decay,
        robot_mass * config.robot.gravity,
    );
    if let Some(e) = free_dir {
        window = window.with_free_direction(e.into());
    }
    Ok(ForecastIntake::new(
        window,
        node.subscriber::<ForecastMsg>()?,
        node.listener(ServiceKind::Forecast)?,
        (
            (lockstep && cc.lockstep_forecast_wait > 0.0)
                .then(|| Duration::from_secs_f64(cc.lockstep_forecast_wait)),
            Duration::from_secs_f64(cc.lockstep_first_forecast_wait),
        ),
        cc.state_timeout,
        horizon_time,
    ))
}

/// The loop's own columns of a tick record: the tick's compute time and the latest C2 result
/// (eq. (26) cost, docs/gain_search.md; nominal cost; iterations; solve time).
fn loop_columns(r: &mut Record, tick_time: Duration, c2: (f64, f64, u32, f64)) {
    let (cost, nominal, iterations, solve) = c2;
    r.put(
        col!(fixed("tick_us", 1).plot("timing/tick_us")),
        tick_time.as_secs_f64() * 1e6,
    );
    r.put(col!(sci("c2_cost", 5).plot("c2/cost")), cost);
    r.put(
        col!(sci("c2_nominal_cost", 5).plot("c2/nominal_cost")),
        nominal,
    );
    r.put(
        col!(plain("c2_iterations").plot("c2/iterations")),
        f64::from(iterations),
    );
    r.put(
        col!(fixed("c2_solve_ms", 3).plot("c2/solve_ms")),
        solve * 1e3,
    );
}

/// The columns of the controller's records (`controller.csv`'s header), from a record of `core`.
pub fn record_columns(core: &ControllerCore) -> Vec<&'static Column> {
    let mut r = Record::default();
    core.record(&mut r);
    loop_columns(&mut r, Duration::ZERO, (0.0, 0.0, 0, 0.0));
    r.columns()
}

/// The rerun log and CSV, if asked for. Lockstep keeps every tick record (the CSV is part of
/// what reruns reproduce), so its logger must get CPU time when the machine is loaded: the
/// normal class. In real time its threads (ours and the rerun SDK's) run in the idle class,
/// see `in_background`.
fn start_logger(
    config: &Config,
    opts: &ServerOptions,
    core: &ControllerCore,
) -> Result<Option<ControlLogger>, Box<dyn std::error::Error + Send + Sync>> {
    let Some(p) = &opts.rrd else { return Ok(None) };
    let columns = record_columns(core);
    let lockstep = config.controller.mode == LoopMode::Lockstep;
    let start = || {
        ControlLogger::start(
            p,
            opts.csv.as_deref(),
            &opts.recording_id,
            opts.live.as_deref(),
            config.preview.horizon,
            lockstep,
            columns.clone(),
        )
    };
    Ok(Some(if lockstep {
        start()?
    } else {
        crate::realtime::in_background(start)?
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn failure() -> ChannelError {
        ChannelError::other(crate::channels::ChannelOp::Receive, "injected")
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
        assert_eq!((e.to_string(), calls), ("receive: injected".into(), 1));
        // The step's own error comes back even when the safe torques fail too.
        let e = or_safe_torques::<u32>(Err(failure()), || {
            calls += 1;
            Err(ChannelError::other(
                crate::channels::ChannelOp::Send,
                "also down",
            ))
        })
        .unwrap_err();
        assert_eq!((e.to_string(), calls), ("receive: injected".into(), 2));
    }

    /// Over real IPC: after a failed step, a torque subscriber on the prefix sees the damping
    /// torques of the last state within the drives' limits, flagged fallback, and the failure
    /// is still returned.
    #[test]
    fn safe_torques_reach_a_subscriber_after_a_failed_step() {
        let prefix = format!("upc_test_safe_torques_{}", std::process::id());
        let node = ContractNode::open(&prefix, "controller_test").expect("contract node");
        let torques = node.publisher::<TorqueMsg>().expect("pub");
        let events = node.notifier(ServiceKind::Torques).expect("notifier");
        let plant = node.subscriber::<TorqueMsg>().expect("sub");
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
                    limits: &[10.0, 10.0, 3.0],
                },
            )
            .map(|()| true)
        })
        .unwrap_err();
        assert_eq!(e.op(), crate::channels::ChannelOp::Receive);
        let m = plant.latest().expect("receive").expect("a torque message");
        assert_eq!(m.flags, TORQUE_FLAG_FALLBACK);
        assert_eq!((m.seq, m.state_step, m.session, m.n), (9, 41, 3, 3));
        // The third joint's −4 N·m held at its 3 N·m limit.
        assert_eq!(&m.tau[..3], &[-1.0, 2.0, -3.0]);
        assert!(m.tau[3..].iter().all(|&t| t == 0.0));
    }
}
