//! The `upc sim` process: the [`World`] stepped in lockstep with the controller or at wall-clock
//! rate, its state published over iceoryx2 ([`crate::channels`]) every step.
//!
//! - **Lockstep**: publish state `k`, wait for the [`TorqueMsg`] with `state_step = k`, step.
//!   Answers to older states are counted as stale and skipped; no answer within
//!   `sim.process.lockstep_timeout` (`first_command_timeout` for the first one) is an error. The
//!   run is a pure function of the commands: two runs are bit-identical.
//! - **Real-time**: step every `dt` of wall time (absolute deadlines, overruns counted) with the
//!   newest valid torques; steps without a fresh command are counted as stale. With no command
//!   for longer than `sim.process.command_timeout`, the safe behaviour applies joint damping
//!   torques `−D q̇` (`safe_damping`) until commands return; both transitions are logged.
//!
//! Every torque message goes through [`CommandGate`]: a wrong `n`, a non-finite torque or a
//! non-increasing `seq` is rejected, counted and never applied (logged, rate-limited).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::DVector;

use crate::control::timing::LatencyHistogram;

use crate::channels::{
    Bus, ChannelError, GroundTruthMsg, MAX_DOF, N_CONTACTS, ServiceKind, StateMsg, TorqueMsg,
};

use super::command::{CommandGate, CommandStats};
use super::config::{Mode, SimConfig};
use super::record::{Recorder, RecorderStats};
use super::scene::{DoorDrive, default_scene};
use super::world::{SimError, StepReport, World};

/// Errors that end a run.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Channel(#[from] ChannelError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("lockstep: no torques answering state {step} within {timeout:.3} s")]
    Timeout { step: u64, timeout: f64 },
    #[error("the scene does not fit the channel contract: {0}")]
    Contract(String),
    #[error("{0}")]
    Setup(String),
}

/// What to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub config: SimConfig,
    /// Write the ground truth to this `.rrd`.
    pub rrd: Option<PathBuf>,
    pub recording_id: Option<String>,
    /// iceoryx2 node name.
    pub node_name: String,
}

/// Step-time histogram (1 µs bins up to 20 ms) and counters of a run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunSummary {
    pub steps: u64,
    pub sim_time: f64,
    pub wall_time: f64,
    pub step_time_p50: f64,
    pub step_time_p99: f64,
    pub step_time_max: f64,
    pub overruns: u64,
    pub commands: CommandStats,
    pub safe_mode_steps: u64,
    pub max_penetration: f64,
    pub max_slip_speed: f64,
    pub max_loop_error: f64,
    pub recorder: RecorderStats,
    /// Lockstep: state published → answering torques received, minus the controller's own
    /// compute time (s): the IPC and wake-up overhead of one round trip.
    pub ipc_overhead_p50: f64,
    pub ipc_overhead_p99: f64,
    pub ipc_overhead_max: f64,
}

/// Fills a [`StateMsg`] from the world (allocation-free).
pub fn fill_state(m: &mut StateMsg, w: &World, zmp: [f64; 2], hand_force: [f64; 3]) {
    m.step = w.steps();
    m.time = w.time();
    let (q, v) = (w.q(), w.v());
    m.nq = q.len() as u32;
    m.nv = v.len() as u32;
    m.q[..q.len()].copy_from_slice(q.as_slice());
    m.v[..v.len()].copy_from_slice(v.as_slice());
    for (k, f) in w.contact_forces().iter().take(N_CONTACTS).enumerate() {
        m.contact_forces[k] = [f.x, f.y, f.z];
    }
    m.zmp = zmp;
    m.door_angle = w.door_angle();
    m.door_velocity = w.door_velocity();
    m.hand_force = hand_force;
}

struct Endpoints {
    state: crate::channels::Publisher<StateMsg>,
    truth: crate::channels::Publisher<GroundTruthMsg>,
    torques: crate::channels::Subscriber<TorqueMsg>,
    state_event: crate::channels::Notifier,
    truth_event: crate::channels::Notifier,
    torque_event: crate::channels::Listener,
}

/// Runs `upc sim` until the configured duration elapses or `stop` is raised.
pub fn run(opts: &RunOptions, stop: &AtomicBool) -> Result<RunSummary, ProcessError> {
    let cfg = &opts.config;
    let (scene, scenario) = default_scene(cfg).map_err(|e| ProcessError::Setup(e.to_string()))?;
    let (mut world, drive) = (scene.world, scene.drive);
    if world.q().len() > MAX_DOF || world.contact_forces().len() != N_CONTACTS {
        return Err(ProcessError::Contract(format!(
            "nq = {} (max {MAX_DOF}), {} contacts (need {N_CONTACTS})",
            world.q().len(),
            world.contact_forces().len()
        )));
    }
    tracing::info!(
        "sim: {:?} mode, dt = {} s, duration = {} s, scenario `{}`, prefix `{}`, door {}",
        cfg.mode,
        cfg.dt,
        cfg.duration,
        scenario.name,
        cfg.process.prefix,
        if cfg.door { "on" } else { "off" }
    );
    let bus = Bus::open(&cfg.process.prefix, &opts.node_name)?;
    let ep = Endpoints {
        state: bus.publisher(ServiceKind::State)?,
        truth: bus.publisher(ServiceKind::GroundTruth)?,
        torques: bus.subscriber(ServiceKind::Torques)?,
        state_event: bus.notifier(ServiceKind::State)?,
        truth_event: bus.notifier(ServiceKind::GroundTruth)?,
        torque_event: bus.listener(ServiceKind::Torques)?,
    };
    let mut recorder = match &opts.rrd {
        Some(path) => Some(
            // Its threads in the idle class: they must not delay the lockstep wake-ups.
            crate::control::realtime::in_background(|| {
                Recorder::spawn(path, opts.recording_id.as_deref(), &world)
            })
            .map_err(|e| ProcessError::Setup(format!("rerun recording {}: {e}", path.display())))?,
        ),
        None => None,
    };
    let mut looper = Looper {
        tau: DVector::zeros(world.n_actuated()),
        gate: CommandGate::default(),
        timing: LatencyHistogram::new(),
        ipc: LatencyHistogram::new(),
        published_at: Instant::now(),
        zmp: [0.0; 2],
        hand_force: [0.0; 3],
        max_pen: 0.0,
        max_slip: 0.0,
        max_loop: 0.0,
        safe_steps: 0,
        overruns: 0,
        last_reject_log: None,
        record_every: (cfg.record_period / cfg.dt).round().max(1.0) as u64,
    };
    // State 0 before any step.
    looper.publish(&ep, &world, &StepReport::default(), 0.0)?;
    if let Some(r) = &mut recorder {
        r.offer(&mut world, &looper.hand_force);
    }
    let total_steps = if cfg.duration > 0.0 {
        (cfg.duration / cfg.dt).round() as u64
    } else {
        u64::MAX
    };
    let start = Instant::now();
    let result = match cfg.mode {
        Mode::Lockstep => looper.lockstep(
            cfg,
            &ep,
            &mut world,
            &drive,
            &mut recorder,
            total_steps,
            stop,
        ),
        Mode::Realtime => looper.realtime(
            cfg,
            &ep,
            &mut world,
            &drive,
            &mut recorder,
            total_steps,
            stop,
        ),
    };
    let wall = start.elapsed().as_secs_f64();
    let rec_stats = recorder.map(|r| r.finish()).unwrap_or_default();
    result?;
    let summary = RunSummary {
        steps: world.steps(),
        sim_time: world.time(),
        wall_time: wall,
        step_time_p50: looper.timing.quantile(0.5),
        step_time_p99: looper.timing.quantile(0.99),
        step_time_max: looper.timing.max(),
        overruns: looper.overruns,
        commands: looper.gate.stats,
        safe_mode_steps: looper.safe_steps,
        max_penetration: looper.max_pen,
        max_slip_speed: looper.max_slip,
        max_loop_error: looper.max_loop,
        recorder: rec_stats,
        ipc_overhead_p50: looper.ipc.quantile(0.5),
        ipc_overhead_p99: looper.ipc.quantile(0.99),
        ipc_overhead_max: looper.ipc.max(),
    };
    tracing::info!("sim finished: {summary:?}");
    Ok(summary)
}

struct Looper {
    tau: DVector<f64>,
    gate: CommandGate,
    timing: LatencyHistogram,
    ipc: LatencyHistogram,
    published_at: Instant,
    zmp: [f64; 2],
    hand_force: [f64; 3],
    max_pen: f64,
    max_slip: f64,
    max_loop: f64,
    safe_steps: u64,
    overruns: u64,
    last_reject_log: Option<Instant>,
    record_every: u64,
}

impl Looper {
    /// Validates a command; on acceptance copies its torques into `self.tau`.
    fn accept(&mut self, msg: &TorqueMsg, n: usize) -> bool {
        match self.gate.check(msg.seq, msg.n, &msg.tau, n) {
            Ok(()) => {
                self.tau.as_mut_slice().copy_from_slice(&msg.tau[..n]);
                true
            }
            Err(e) => {
                let now = Instant::now();
                if self
                    .last_reject_log
                    .is_none_or(|t| now.duration_since(t) > Duration::from_secs(1))
                {
                    tracing::warn!(
                        "rejected torque command: {e} ({} rejected so far)",
                        self.gate.stats.rejected()
                    );
                    self.last_reject_log = Some(now);
                }
                false
            }
        }
    }

    fn step(
        &mut self,
        ep: &Endpoints,
        world: &mut World,
        drive: &DoorDrive,
        recorder: &mut Option<Recorder>,
    ) -> Result<(), ProcessError> {
        let t0 = Instant::now();
        let door_torque = drive.torque(world.time());
        let rep = world.step(&self.tau, door_torque)?;
        let dt_step = t0.elapsed().as_secs_f64();
        self.timing.record(Duration::from_secs_f64(dt_step));
        if let Some(z) = rep.zmp {
            self.zmp = z;
        }
        self.hand_force = rep.hand_force;
        self.max_pen = self.max_pen.max(rep.max_penetration);
        self.max_slip = self.max_slip.max(rep.max_slip_speed);
        self.max_loop = self.max_loop.max(rep.loop_error);
        self.publish(ep, world, &rep, dt_step)?;
        if let Some(r) = recorder
            && world.steps().is_multiple_of(self.record_every)
        {
            r.offer(world, &self.hand_force);
        }
        Ok(())
    }

    fn publish(
        &mut self,
        ep: &Endpoints,
        world: &World,
        rep: &StepReport,
        step_time: f64,
    ) -> Result<(), ProcessError> {
        let (zmp, hand) = (self.zmp, self.hand_force);
        ep.state.send_with(|m| fill_state(m, world, zmp, hand))?;
        let stats = self.gate.stats;
        ep.truth.send_with(|g| {
            g.step = world.steps();
            g.time = world.time();
            g.com = rep.com;
            g.loop_error = rep.loop_error;
            g.max_penetration = rep.max_penetration;
            g.max_slip_speed = rep.max_slip_speed;
            g.door_torque = rep.door_torque;
            g.step_time = step_time;
            g.solver_iterations = rep.solver_iterations;
            g.rejected_commands = stats.rejected().min(u32::MAX as u64) as u32;
            g.stale_commands = stats.stale;
        })?;
        ep.state_event.notify()?;
        self.published_at = Instant::now();
        ep.truth_event.notify()?;
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn lockstep(
        &mut self,
        cfg: &SimConfig,
        ep: &Endpoints,
        world: &mut World,
        drive: &DoorDrive,
        recorder: &mut Option<Recorder>,
        total: u64,
        stop: &AtomicBool,
    ) -> Result<(), ProcessError> {
        let n = world.n_actuated();
        while world.steps() < total && !stop.load(Ordering::Relaxed) {
            let want = world.steps();
            let timeout = if want == 0 {
                cfg.process.first_command_timeout
            } else {
                cfg.process.lockstep_timeout
            };
            let deadline = Instant::now() + Duration::from_secs_f64(timeout);
            'wait: loop {
                while let Some(msg) = ep.torques.receive()? {
                    if !self.accept(&msg, n) {
                        continue;
                    }
                    if msg.state_step == want {
                        let round_trip = self.published_at.elapsed();
                        // State 0 waits for the controller to start: not an IPC figure.
                        if want > 0 {
                            self.ipc.record(
                                round_trip.saturating_sub(Duration::from_nanos(msg.compute_ns)),
                            );
                        }
                        break 'wait;
                    }
                    // A valid answer to another state: not applied.
                    self.gate.stats.stale += 1;
                }
                let now = Instant::now();
                if now >= deadline {
                    return Err(ProcessError::Timeout {
                        step: want,
                        timeout,
                    });
                }
                if stop.load(Ordering::Relaxed) {
                    return Ok(());
                }
                let woken = ep.torque_event.wait_until(
                    (deadline - now).min(Duration::from_millis(20)),
                    Duration::from_secs_f64(cfg.process.ipc_spin_us * 1e-6),
                    || ep.torques.has_samples(),
                )?;
                if !woken {
                    // A controller that connected after this state was sent has neither the
                    // sample nor its wake-up: send the same state again (it skips duplicates).
                    let (zmp, hand) = (self.zmp, self.hand_force);
                    ep.state.send_with(|m| fill_state(m, world, zmp, hand))?;
                    ep.state_event.notify()?;
                }
            }
            self.step(ep, world, drive, recorder)?;
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn realtime(
        &mut self,
        cfg: &SimConfig,
        ep: &Endpoints,
        world: &mut World,
        drive: &DoorDrive,
        recorder: &mut Option<Recorder>,
        total: u64,
        stop: &AtomicBool,
    ) -> Result<(), ProcessError> {
        let n = world.n_actuated();
        let period = Duration::from_secs_f64(cfg.dt);
        let cmd_timeout = Duration::from_secs_f64(cfg.process.command_timeout);
        let start = Instant::now();
        let mut next = start + period;
        let mut last_cmd = start;
        let mut commanded = DVector::zeros(n);
        let mut safe = false;
        while world.steps() < total && !stop.load(Ordering::Relaxed) {
            let mut fresh = false;
            while let Some(msg) = ep.torques.receive()? {
                if self.accept(&msg, n) {
                    fresh = true;
                }
            }
            let now = Instant::now();
            if fresh {
                last_cmd = now;
                commanded.copy_from(&self.tau);
            } else {
                self.gate.stats.stale += 1;
            }
            let timed_out = now.duration_since(last_cmd) > cmd_timeout;
            if timed_out != safe {
                safe = timed_out;
                if safe {
                    tracing::warn!(
                        "no torques for {:.3} s at t = {:.3} s: safe behaviour (joint damping {} N·m·s/rad)",
                        now.duration_since(last_cmd).as_secs_f64(),
                        world.time(),
                        cfg.process.safe_damping
                    );
                } else {
                    tracing::info!(
                        "torques are back at t = {:.3} s: leaving the safe behaviour",
                        world.time()
                    );
                }
            }
            if safe {
                self.safe_steps += 1;
                let off = world.v().len() - n;
                for i in 0..n {
                    self.tau[i] = -cfg.process.safe_damping * world.v()[off + i];
                }
            } else {
                self.tau.copy_from(&commanded);
            }
            self.step(ep, world, drive, recorder)?;
            let now = Instant::now();
            if now > next {
                self.overruns += 1;
                if now - next > 10 * period {
                    next = now; // far behind: resynchronise instead of bursting
                }
            } else {
                std::thread::sleep(next - now);
            }
            next += period;
        }
        Ok(())
    }
}
