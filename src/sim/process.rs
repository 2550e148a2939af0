//! The `upc sim` process, the plant runtime: a physics engine ([`Physics`]: upc's own
//! [`super::World`] or MuJoCo) stepped in lockstep with the controller or at wall-clock rate, its
//! state published over iceoryx2 ([`crate::channels`]) every step. Everything below is the
//! runtime's, the same for every engine.
//!
//! - **Lockstep**: publish state `k`, wait for the [`TorqueMsg`] with `state_step = k`, step.
//!   Answers to older states are counted as stale and skipped; no answer within
//!   `sim.process.lockstep_timeout` (`first_command_timeout` for the first one) is an error,
//!   unless the controller has answered before and its process is still alive (starved, in a
//!   debugger): that one is waited for. The run is a pure function of the commands: two runs
//!   are bit-identical.
//! - **Real-time**: step every `dt` of wall time (absolute deadlines, overruns counted). Who
//!   drives the robot is the [`Supervisor`]'s call: until the controller's first valid torques
//!   the robot is held at its start posture (`[sim.hold]`), then handed over to the torques
//!   without a jump; with no command for `sim.process.command_timeout` (of the plant's own live
//!   time: its own stalls are not the controller's silence, [`CommandClock`]) it is held again, and
//!   after `sim.hold.lost_timeout` only damped. Transitions are logged; the state's flags say
//!   when the plant holds.
//!
//! Every state carries the run's `session` and the scenario played (name and content hash):
//! forecasters follow it, controllers check their forecast against it. Every torque message
//! goes through [`CommandGate`]: a wrong `n`, a non-finite torque, a non-increasing `seq` (per
//! controller run) or another plant session is rejected, counted and never applied (logged,
//! rate-limited).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::DVector;

use crate::realtime::LatencyHistogram;

use crate::channels::{
    ChannelError, ContractNode, GroundTruthMsg, MAX_DOF, N_CONTACTS, STATE_FLAG_DAMPING,
    STATE_FLAG_HOLD, STATE_FLAG_LOCKSTEP, ServiceKind, StateMsg, TORQUE_FLAG_FALLBACK, TorqueMsg,
};

use super::config::{Mode, Push, SimConfig};
use super::hold::{CommandClock, HoldStats, Phase, Supervisor};
use super::physics::{Engine, Physics, SimError, StepReport};
use super::record::{Recorder, RecorderStats};
use super::scene::{DoorDrive, default_scene};
use super::sensors::{FootSensing, ImuMount, RobotSensors, SensorCounts, Sensors, SensorsConfig};
use super::truth_csv::{truth_record, write_truth};
use crate::plant::{CommandGate, CommandOrigin, CommandStats, PlantInfo};
use crate::robot::{FootSensors, Robot};

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
    /// The robot in the scene (`--robot`; the embedded default when built by tests).
    pub robot: std::sync::Arc<crate::robot::Robot>,
    /// Write the ground truth to this `.rrd`.
    pub rrd: Option<PathBuf>,
    pub recording_id: Option<String>,
    /// Stream the recording to this live rerun viewer too (gRPC proxy URL).
    pub live: Option<String>,
    /// iceoryx2 node name.
    pub node_name: String,
    /// Lockstep: write the ground truth every `record_period` as CSV here (reproducible bytes).
    pub truth_csv: Option<PathBuf>,
    /// The physics engine (`--plant`).
    pub engine: Engine,
}

/// Step-time histogram (1 µs bins up to 20 ms) and counters of a run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunSummary {
    /// The physics engine (`upc`, `mujoco`) and its version.
    pub plant: String,
    pub plant_version: String,
    pub steps: u64,
    pub sim_time: f64,
    pub wall_time: f64,
    pub step_time_p50: f64,
    pub step_time_p99: f64,
    pub step_time_max: f64,
    pub overruns: u64,
    pub commands: CommandStats,
    /// Steps under bare joint damping (no hold, or the hold gave up).
    pub safe_mode_steps: u64,
    /// The plant's own hold: steps per phase, hand-overs, controller losses (real time).
    pub hold: HoldStats,
    pub mode: String,
    pub robot: String,
    pub force_scale: f64,
    pub scenario: String,
    pub scenario_hash: String,
    pub session: String,
    /// Plant time at which the scenario started (negative: never).
    pub scenario_start: f64,
    pub max_penetration: f64,
    pub max_slip_speed: f64,
    pub max_loop_error: f64,
    /// `truth` or `realistic` (`sim.sensors.sensing`), and the sensor models' counters.
    pub sensing: String,
    pub sensor_counts: Option<SensorCounts>,
    pub recorder: RecorderStats,
    /// Lockstep: state published → answering torques received, minus the controller's own
    /// compute time (s): the IPC and wake-up overhead of one round trip.
    pub ipc_overhead_p50: f64,
    pub ipc_overhead_p99: f64,
    pub ipc_overhead_max: f64,
    /// What ended the run early (a lockstep timeout, the physics giving up, the channels), if
    /// anything: the summary is written all the same.
    pub error: Option<String>,
}

/// Fills a [`StateMsg`] from the physics (allocation-free).
pub fn fill_state(
    m: &mut StateMsg,
    w: &impl Physics,
    info: &PlantInfo,
    zmp: [f64; 2],
    hand_force: [f64; 3],
) {
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
    info.announce(m);
}

struct Endpoints {
    state: crate::channels::Publisher<StateMsg>,
    truth: crate::channels::Publisher<GroundTruthMsg>,
    torques: crate::channels::Subscriber<TorqueMsg>,
    state_event: crate::channels::Notifier,
    truth_event: crate::channels::Notifier,
    torque_event: crate::channels::Listener,
}

/// Runs `upc sim` until the configured duration elapses or `stop` is raised: the scene built
/// for the chosen engine, then the plant runtime on it.
pub fn run(opts: &RunOptions, stop: &AtomicBool) -> Result<RunSummary, ProcessError> {
    struct Runtime<'a>(&'a RunOptions, &'a AtomicBool);
    impl PlantUser for Runtime<'_> {
        type Output = RunSummary;
        fn with<P: Physics>(self, plant: Plant<P>) -> Result<RunSummary, ProcessError> {
            run_plant(self.0, plant, self.1)
        }
    }
    build_plant(&opts.config, &opts.robot, opts.engine, Runtime(opts, stop))
}

/// What runs on a plant whatever its engine (the plant runtime, or the robot on a bus).
pub trait PlantUser {
    type Output;
    fn with<P: Physics>(self, plant: Plant<P>) -> Result<Self::Output, ProcessError>;
}

/// The scene built for `engine`, handed to `user`.
pub fn build_plant<U: PlantUser>(
    cfg: &SimConfig,
    robot: &crate::robot::Robot,
    engine: Engine,
    user: U,
) -> Result<U::Output, ProcessError> {
    match engine {
        Engine::Upc => {
            let (scene, scenario) =
                default_scene(cfg, robot).map_err(|e| ProcessError::Setup(e.to_string()))?;
            user.with(Plant {
                physics: scene.world,
                drive: scene.drive,
                scenario,
                carrying: scene.carrying,
                version: env!("CARGO_PKG_VERSION").into(),
            })
        }
        #[cfg(upc_mujoco)]
        Engine::Mujoco => user.with(mujoco_plant(cfg, robot)?),
        #[cfg(not(upc_mujoco))]
        Engine::Mujoco => Err(ProcessError::Setup(super::mujoco::UNAVAILABLE.into())),
    }
}

/// MuJoCo with the scene generated for it, the robot settled onto its contacts.
#[cfg(upc_mujoco)]
fn mujoco_plant(
    cfg: &SimConfig,
    robot: &crate::robot::Robot,
) -> Result<Plant<super::mujoco::MujocoPlant>, ProcessError> {
    let setup = |e: &dyn std::fmt::Display| ProcessError::Setup(e.to_string());
    let scenario = robot.scenario(&cfg.scenario).map_err(|e| setup(&e))?;
    let scene = super::mujoco::build(robot, cfg, &scenario)?;
    let physics = super::mujoco::MujocoPlant::new(robot, &scene)?;
    let version = super::mujoco::version().unwrap_or_default();
    tracing::info!(
        "MuJoCo {version}: the robot settled {:.2} mm onto its contacts in {} s",
        physics.settle_sink() * 1e3,
        super::mujoco::SETTLE_TIME
    );
    Ok(Plant {
        physics,
        drive: scene.drive,
        scenario,
        carrying: robot.carrying_frames(),
        version,
    })
}

/// A physics engine with the scene it plays.
pub struct Plant<P> {
    pub physics: P,
    pub drive: DoorDrive,
    pub scenario: crate::scenario::Scenario,
    /// Frames whose supporting joints carry the body (the hold stiffens them).
    pub carrying: Vec<usize>,
    /// The engine's version, for the summary.
    pub version: String,
}

/// The plant runtime: state and ground truth published every step, torques gated, the
/// supervisor's hold in real time, the recording, the summary; any [`Physics`] underneath.
fn run_plant<P: Physics>(
    opts: &RunOptions,
    plant: Plant<P>,
    stop: &AtomicBool,
) -> Result<RunSummary, ProcessError> {
    let cfg = &opts.config;
    let Plant {
        physics: mut world,
        drive,
        scenario,
        carrying,
        version,
    } = plant;
    check_setup(opts, &world)?;
    let lockstep = cfg.mode == Mode::Lockstep;
    let info = PlantInfo::start(&cfg.scenario, &scenario, opts.robot.hash, lockstep);
    log_start(opts, &world, &version, &scenario, &info);
    let node = ContractNode::open(&cfg.process.prefix, &opts.node_name)?;
    let ep = Endpoints {
        state: node.publisher()?,
        truth: node.publisher()?,
        torques: node.subscriber()?,
        state_event: node.notifier(ServiceKind::State)?,
        truth_event: node.notifier(ServiceKind::GroundTruth)?,
        torque_event: node.listener(ServiceKind::Torques)?,
    };
    let mut recorder = start_recorder(opts, &world)?;
    let mut looper = Looper::new(opts, &world, info, &carrying, open_truth_csv(opts, &world)?)?;
    // State 0 before any step (an engine that settles the robot first reports its forces).
    let first = *world.last_report();
    if let Some(z) = first.zmp {
        looper.zmp = z;
    }
    looper.hand_force = first.hand_force;
    looper.publish(&ep, &world, &first, 0.0)?;
    if let Some(r) = &mut recorder {
        r.offer(&mut world, &looper.hand_force);
    }
    let total_steps = if cfg.duration > 0.0 {
        (cfg.duration / cfg.dt).round() as u64
    } else {
        u64::MAX
    };
    let start = Instant::now();
    let mut run = Run {
        cfg,
        ep: &ep,
        drive: &drive,
        recorder: &mut recorder,
        total: total_steps,
        stop,
    };
    let result = match cfg.mode {
        Mode::Lockstep => looper.lockstep(&mut run, &mut world),
        Mode::Realtime => looper.realtime(&mut run, &mut world),
    };
    let wall = start.elapsed().as_secs_f64();
    // The CSV first: the recording's flush may take long on a loaded machine.
    if let Some(w) = &mut looper.truth_csv {
        use std::io::Write;
        w.flush()
            .map_err(|e| ProcessError::Setup(format!("ground-truth CSV: {e}")))?;
    }
    let recorder = recorder.map(|r| r.finish()).unwrap_or_default();
    let summary = looper.summary(opts, &world, version, wall, recorder, result.err());
    tracing::info!("sim finished: {summary:?}");
    Ok(summary)
}

/// What a run is set up with that the contract or the mode cannot carry.
fn check_setup(opts: &RunOptions, world: &impl Physics) -> Result<(), ProcessError> {
    let cfg = &opts.config;
    if world.q().len() > MAX_DOF || world.contact_forces().len() != N_CONTACTS {
        return Err(ProcessError::Contract(format!(
            "nq = {} (max {MAX_DOF}), {} contacts (need {N_CONTACTS}): lock the joints the \
             controller need not move (`locked` in the robot description, e.g. fingers)",
            world.q().len(),
            world.contact_forces().len()
        )));
    }
    if cfg.scenario.len() > crate::channels::SCENARIO_NAME_LEN {
        return Err(ProcessError::Setup(format!(
            "scenario `{}` is longer than the {} bytes a state announces: use a shorter path",
            cfg.scenario,
            crate::channels::SCENARIO_NAME_LEN
        )));
    }
    if opts.truth_csv.is_some() && cfg.mode != Mode::Lockstep {
        return Err(ProcessError::Setup(
            "--truth-csv is written from the stepping loop: lockstep only".into(),
        ));
    }
    Ok(())
}

fn log_start(
    opts: &RunOptions,
    world: &impl Physics,
    version: &str,
    scenario: &crate::scenario::Scenario,
    info: &PlantInfo,
) {
    let (cfg, robot) = (&opts.config, &opts.robot);
    tracing::info!(
        "sim: {} {version}, robot `{}` ({:.1} kg, forces × {:.3}), {:?} mode, dt = {} s, \
         duration = {} s, scenario `{}` ({}, hash {:016x}), prefix `{}`, door {}, session \
         {:016x}, hold {:?}",
        world.engine(),
        robot.name(),
        robot.derived.mass,
        scenario.force_scale,
        cfg.mode,
        cfg.dt,
        cfg.duration,
        cfg.scenario,
        scenario.name,
        info.scenario_hash,
        cfg.process.prefix,
        if cfg.door { "on" } else { "off" },
        info.session,
        cfg.hold.kind
    );
}

/// The ground truth's rerun recording, if asked for.
fn start_recorder(
    opts: &RunOptions,
    world: &impl Physics,
) -> Result<Option<Recorder>, ProcessError> {
    let Some(path) = &opts.rrd else {
        return Ok(None);
    };
    // Real time: its threads in the idle class, they must not delay the steps. Lockstep must
    // end on a loaded machine too, where idle-class threads hardly run.
    Recorder::spawn(
        path,
        opts.recording_id.as_deref(),
        opts.live.as_deref(),
        world,
        &opts.robot,
        opts.config.mode == Mode::Realtime,
    )
    .map(Some)
    .map_err(|e| ProcessError::Setup(format!("rerun recording {}: {e}", path.display())))
}

/// The lockstep ground-truth CSV, its header written (the columns of `world`'s truth record),
/// if asked for.
fn open_truth_csv(
    opts: &RunOptions,
    world: &impl Physics,
) -> Result<Option<std::io::BufWriter<std::fs::File>>, ProcessError> {
    let Some(p) = &opts.truth_csv else {
        return Ok(None);
    };
    let file = std::fs::File::create(p)
        .map_err(|e| ProcessError::Setup(format!("ground-truth CSV {}: {e}", p.display())))?;
    let mut w = std::io::BufWriter::new(file);
    let columns = truth_record(world, world.last_report(), [0.0; 2], [0.0; 3]);
    columns
        .write_csv_header(&mut w)
        .map_err(|e| ProcessError::Setup(format!("ground-truth CSV: {e}")))?;
    Ok(Some(w))
}

/// `sim.push = "hand"`: the robot frame the scenario's force is applied at.
pub fn push_frame(
    cfg: &SimConfig,
    robot: &crate::robot::Robot,
) -> Result<Option<usize>, ProcessError> {
    Ok(match cfg.push {
        Push::Hand => Some(
            robot
                .model
                .frame_id(&robot.description.hand.frame)
                .map_err(SimError::from)?,
        ),
        Push::Door | Push::None => None,
    })
}

/// The scenario's push before a step from plant time `start` (negative: not started): the
/// force at the hand frame `push_frame` if the push is applied there; the door's hinge torque,
/// returned.
pub fn apply_scenario<P: Physics>(
    world: &mut P,
    drive: &DoorDrive,
    push_frame: Option<usize>,
    start: f64,
) -> Result<f64, ProcessError> {
    let t = world.time() - start;
    if let Some(frame) = push_frame {
        let f = if start >= 0.0 {
            drive.hand_force(t)
        } else {
            [0.0; 3]
        };
        world.set_push(frame, nalgebra::Vector3::from(f))?;
    }
    Ok(if start >= 0.0 {
        drive.torque(world.sample_time(t))
    } else {
        0.0
    })
}

/// What both loops share for a run.
struct Run<'a> {
    cfg: &'a SimConfig,
    ep: &'a Endpoints,
    drive: &'a DoorDrive,
    recorder: &'a mut Option<Recorder>,
    total: u64,
    stop: &'a AtomicBool,
}

struct Looper {
    tau: DVector<f64>,
    gate: CommandGate,
    info: PlantInfo,
    supervisor: Supervisor,
    truth_csv: Option<std::io::BufWriter<std::fs::File>>,
    timing: LatencyHistogram,
    ipc: LatencyHistogram,
    published_at: Instant,
    zmp: [f64; 2],
    hand_force: [f64; 3],
    max_pen: f64,
    max_slip: f64,
    max_loop: f64,
    overruns: u64,
    last_reject_log: Option<Instant>,
    record_every: u64,
    /// `sim.push = "hand"`: the robot frame the scenario's force is applied at.
    push_frame: Option<usize>,
    /// The sensor block of the published state and the models it passes through (on
    /// `realistic`: the robot's sensors, what it lacks, its torque estimates), and the sole
    /// corners' positions for them (scratch).
    sensors: Sensors,
    points: [[f64; 3]; N_CONTACTS],
    /// The plant's step (s).
    dt: f64,
    /// The state last published, as measured.
    last_state: Box<StateMsg>,
}

/// The torques `tau` applied over the step (actuated joints) into the state's `joint_torques`,
/// the base's NaN: what the drives' torque sensing reads ([`Sensors::apply`]).
pub(crate) fn put_applied_torques(m: &mut StateMsg, tau: &[f64]) {
    m.joint_torques.fill(f64::NAN);
    let base = m.nv as usize - tau.len();
    m.joint_torques[base..base + tau.len()].copy_from_slice(tau);
}

/// The sensor models' settings, the feet as the robot's description says when it says.
pub(crate) fn sensors_of(cfg: &SimConfig, robot: &Robot) -> SensorsConfig {
    let mut s = cfg.sensors;
    match robot.description.sensors.feet {
        Some(FootSensors::Corners) => s.feet = FootSensing::Corners,
        Some(FootSensors::SixAxis) => s.feet = FootSensing::SixAxis,
        // No foot sensor: the corners' models run and NaN is published for them.
        Some(FootSensors::None) | None => {}
    }
    s
}

fn log_transition(from: Phase, to: Phase, t: f64, cfg: &SimConfig) {
    match (from, to) {
        (_, Phase::Handover) => tracing::info!(
            "t = {t:.3} s: the controller's torques arrived; handing over from {from:?} in {} s",
            cfg.hold.handover
        ),
        (_, Phase::Control) => tracing::info!("t = {t:.3} s: the controller drives the robot"),
        (_, Phase::Hold) => tracing::warn!(
            "t = {t:.3} s: no torques for {} s: holding the robot ({:?}; bare damping after {} s)",
            cfg.process.command_timeout,
            cfg.hold.kind,
            cfg.hold.lost_timeout
        ),
        (_, Phase::Damping) => tracing::warn!(
            "t = {t:.3} s: safe behaviour, joint damping {} N·m·s/rad (no hold)",
            cfg.process.safe_damping
        ),
    }
}

impl Looper {
    fn new(
        opts: &RunOptions,
        world: &impl Physics,
        info: PlantInfo,
        carrying: &[usize],
        truth_csv: Option<std::io::BufWriter<std::fs::File>>,
    ) -> Result<Self, ProcessError> {
        let (cfg, robot) = (&opts.config, &opts.robot);
        let supervisor = Supervisor::new(
            world.robot(),
            world.q(),
            carrying,
            &cfg.hold,
            cfg.process.safe_damping,
            cfg.dt,
        )?;
        Ok(Looper {
            tau: DVector::zeros(world.n_actuated()),
            gate: CommandGate::for_session(info.session),
            info,
            supervisor,
            truth_csv,
            timing: LatencyHistogram::new(),
            ipc: LatencyHistogram::new(),
            published_at: Instant::now(),
            zmp: [0.0; 2],
            hand_force: [0.0; 3],
            max_pen: 0.0,
            max_slip: 0.0,
            max_loop: 0.0,
            overruns: 0,
            last_reject_log: None,
            record_every: (cfg.record_period / cfg.dt).round().max(1.0) as u64,
            push_frame: push_frame(cfg, robot)?,
            sensors: Sensors::with_robot(
                &sensors_of(cfg, robot),
                -world.robot().gravity.z,
                robot.imu_frame.map(|f| ImuMount::new(&robot.model, f)),
                RobotSensors {
                    spec: robot.description.sensors,
                    effort: world.robot().effort_limits(),
                },
            ),
            points: [[0.0; 3]; N_CONTACTS],
            dt: cfg.dt,
            last_state: Box::default(),
        })
    }

    /// The run's summary; `error`: what ended it early, if anything.
    fn summary(
        &self,
        opts: &RunOptions,
        world: &impl Physics,
        version: String,
        wall: f64,
        recorder: RecorderStats,
        error: Option<ProcessError>,
    ) -> RunSummary {
        let cfg = &opts.config;
        RunSummary {
            plant: world.engine().into(),
            plant_version: version,
            steps: world.steps(),
            sim_time: world.time(),
            wall_time: wall,
            step_time_p50: self.timing.quantile(0.5),
            step_time_p99: self.timing.quantile(0.99),
            step_time_max: self.timing.max(),
            overruns: self.overruns,
            commands: self.gate.stats,
            safe_mode_steps: self.supervisor.stats.damping_steps,
            hold: self.supervisor.stats,
            mode: format!("{:?}", cfg.mode).to_lowercase(),
            scenario: cfg.scenario.clone(),
            robot: opts.robot.name().to_string(),
            force_scale: self.info.force_scale,
            scenario_hash: format!("{:016x}", self.info.scenario_hash),
            session: format!("{:016x}", self.info.session),
            scenario_start: self.info.scenario_start,
            max_penetration: self.max_pen,
            max_slip_speed: self.max_slip,
            max_loop_error: self.max_loop,
            sensing: cfg.sensors.sensing.name().into(),
            sensor_counts: self.sensors.realistic().then(|| self.sensors.counts()),
            recorder,
            ipc_overhead_p50: self.ipc.quantile(0.5),
            ipc_overhead_p99: self.ipc.quantile(0.99),
            ipc_overhead_max: self.ipc.max(),
            error: error.map(|e| e.to_string()),
        }
    }

    /// Validates a command; on acceptance copies its torques into `self.tau`.
    /// Gates `msg`; a valid one that `applies` becomes the torques to apply.
    fn accept(&mut self, msg: &TorqueMsg, n: usize, applies: bool) -> bool {
        let origin = CommandOrigin {
            session: msg.session,
            controller: msg.controller,
        };
        match self
            .gate
            .check_answer(origin, msg.seq, msg.n, &msg.tau, n, applies)
        {
            Ok(()) => {
                if applies {
                    self.tau.as_mut_slice().copy_from_slice(&msg.tau[..n]);
                }
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

    fn step<P: Physics>(
        &mut self,
        ep: &Endpoints,
        world: &mut P,
        drive: &DoorDrive,
        recorder: &mut Option<Recorder>,
    ) -> Result<(), ProcessError> {
        let t0 = Instant::now();
        let door_torque = apply_scenario(world, drive, self.push_frame, self.info.scenario_start)?;
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
        if world.steps().is_multiple_of(self.record_every) {
            if let Some(r) = recorder {
                r.offer(world, &self.hand_force);
            }
            if let Some(w) = &mut self.truth_csv {
                write_truth(w, world, &rep, self.zmp, self.hand_force)
                    .map_err(|e| ProcessError::Setup(format!("ground-truth CSV: {e}")))?;
            }
        }
        Ok(())
    }

    fn publish(
        &mut self,
        ep: &Endpoints,
        world: &impl Physics,
        rep: &StepReport,
        step_time: f64,
    ) -> Result<(), ProcessError> {
        let (zmp, hand) = (self.zmp, self.hand_force);
        // Lockstep never holds: it does not step without torques.
        if self.info.flags & STATE_FLAG_LOCKSTEP == 0 {
            self.info.flags = match self.supervisor.phase() {
                Phase::Hold | Phase::Handover => STATE_FLAG_HOLD,
                Phase::Damping => STATE_FLAG_DAMPING,
                Phase::Control => 0,
            };
        }
        let info = &self.info;
        for (p, c) in self.points.iter_mut().zip(world.contact_points()) {
            *p = [c.x, c.y, c.z];
        }
        let (sensors, points, dt) = (&mut self.sensors, &self.points, self.dt);
        let (last, tau) = (&mut self.last_state, &self.tau);
        ep.state.send_with(|m| {
            fill_state(m, world, info, zmp, hand);
            // The torques applied over the step: what the drives' estimates read (MT-1).
            put_applied_torques(m, tau.as_slice());
            sensors.apply(m, dt, points);
            **last = *m;
        })?;
        let stats = self.gate.stats;
        let (flags, hold_steps) = (self.info.flags, self.supervisor.stats.hold_steps);
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
            g.flags = flags;
            g.hold_steps = hold_steps;
        })?;
        ep.state_event.notify()?;
        self.published_at = Instant::now();
        ep.truth_event.notify()?;
        Ok(())
    }

    fn lockstep<P: Physics>(&mut self, run: &mut Run, world: &mut P) -> Result<(), ProcessError> {
        let (cfg, ep, total, stop) = (run.cfg, run.ep, run.total, run.stop);
        let n = world.n_actuated();
        while world.steps() < total && !stop.load(Ordering::Relaxed) {
            let want = world.steps();
            let timeout = if want == 0 {
                cfg.process.first_command_timeout
            } else {
                cfg.process.lockstep_timeout
            };
            let mut deadline = Instant::now() + Duration::from_secs_f64(timeout);
            let mut waiting_for_live_controller = false;
            'wait: loop {
                while let Some(msg) = ep.torques.receive()? {
                    // A valid answer to another state is counted stale and not applied.
                    let answers = msg.state_step == want;
                    if self.accept(&msg, n, answers) && answers {
                        let round_trip = self.published_at.elapsed();
                        // State 0 waits for the controller to start: not an IPC figure.
                        if want > 0 {
                            self.ipc.record(
                                round_trip.saturating_sub(Duration::from_nanos(msg.compute_ns)),
                            );
                        }
                        break 'wait;
                    }
                }
                let now = Instant::now();
                if now >= deadline {
                    // A controller whose process is alive is slow (starved, in a debugger, or
                    // at the first state waiting for its forecaster), not gone: a lockstep run
                    // waits for it.
                    if ep.torques.has_live_publisher() {
                        if !waiting_for_live_controller {
                            waiting_for_live_controller = true;
                            tracing::warn!(
                                "no torques for state {want} within {timeout} s, but the \
                                 controller's process is alive: waiting for it"
                            );
                        }
                        deadline = now + Duration::from_millis(100);
                        continue;
                    }
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
                    // The same bytes: the sensors are not sampled again (a resend depends on
                    // wall-clock timing, the noise must not).
                    let last = &self.last_state;
                    ep.state.send_with(|m| *m = **last)?;
                    ep.state_event.notify()?;
                }
            }
            self.step(ep, world, run.drive, run.recorder)?;
        }
        Ok(())
    }

    fn realtime<P: Physics>(&mut self, run: &mut Run, world: &mut P) -> Result<(), ProcessError> {
        let (cfg, ep, total, stop) = (run.cfg, run.ep, run.total, run.stop);
        let n = world.n_actuated();
        let period = Duration::from_secs_f64(cfg.dt);
        let mut clock =
            CommandClock::new(period, Duration::from_secs_f64(cfg.process.command_timeout));
        let start = Instant::now();
        let mut next = start + period;
        let mut commanded = DVector::zeros(n);
        let mut applied = DVector::zeros(n);
        while world.steps() < total && !stop.load(Ordering::Relaxed) {
            clock.pass(Instant::now());
            let mut fresh = false;
            while let Some(msg) = ep.torques.receive()? {
                // A controller's own fallback (it has no state to control from) does not take
                // the robot from the hold; once it drives the robot, its fallbacks apply.
                let holding = matches!(self.supervisor.phase(), Phase::Hold | Phase::Damping);
                if holding && msg.flags & TORQUE_FLAG_FALLBACK != 0 {
                    continue;
                }
                if self.accept(&msg, n, true) {
                    fresh = true;
                    commanded.copy_from(&self.tau);
                }
            }
            let now = Instant::now();
            if fresh {
                clock.command(now);
            } else {
                self.gate.stats.stale += 1;
            }
            let current = clock.current(now);
            let t = world.time();
            let transition = self.supervisor.torques(
                t,
                world.q(),
                world.v(),
                current.then_some(&commanded),
                &mut applied,
            );
            if let Some(tr) = transition {
                log_transition(tr.from, tr.to, t, cfg);
                if tr.to == Phase::Control && self.info.scenario_start < 0.0 {
                    self.info.scenario_start = t;
                    tracing::info!("t = {t:.3} s: scenario `{}` starts", cfg.scenario);
                }
            }
            self.tau.copy_from(&applied);
            self.step(ep, world, run.drive, run.recorder)?;
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
