//! `upc bus`: the participant that is the plant on upc's contract and the controller on the
//! robot's bus. The controller, forecasters, bridge and loggers see a plant like any other; the
//! robot sees one low-level controller on `rt/lowcmd`.
//!
//! The robot's rate governs: every valid `rt/lowstate` becomes one [`StateMsg`], and one
//! `rt/lowcmd` answers it, with the controller's torques for that state when they arrive within
//! `bus.late`, else with the last ones while they are current. Safety (docs/bus.md, "Safety"):
//! - no command before a valid state, and none at all while another participant writes
//!   `rt/lowcmd` (Unitree's motion service must be released first);
//! - until the controller's first valid torques the drives hold the start posture (kp, kd,
//!   tau = 0), then the torques are blended in over `bus.hold.handover`;
//! - the controller silent for `bus.command_timeout` (of this loop's live time) → the brace: the
//!   drives hold the posture the robot has, with the controller's last torques, its answer
//!   meanwhile driving at once; silent for `bus.hold.brace` → damping (kp = 0, kd =
//!   `bus.damping`, tau = 0) until it answers again, then a new hand-over (`drive.rs`);
//! - every torque clamped to its joint's effort limit; mode_machine echoed from the state;
//! - a state with a bad CRC (`bus.bad_crc`), a tick that does not advance or a non-finite value
//!   is refused and counted; no valid state for `bus.state_timeout` → the brace at the last
//!   state's posture, repeated every 2 ms, damping after `bus.hold.brace`, until the robot speaks
//!   again; none for `bus.robot_lost` ends the run (the robot is gone: nothing to command).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::DVector;

use super::config::BusConfig;
use super::dds::{DdsError, Inbox, Liveness, Outbox, participant};
use super::drive::{Drive, Drives, Robot, command, tick_behind, valid};
use super::lab::{LAB_STATE_TOPIC, LabState};
use super::motors::MotorMap;
use super::ros2::{
    HAND_WRENCH_TOPIC, Header, JOINT_STATE_TOPIC, JointState, Time, Vector3, Wrench, WrenchStamped,
};
pub use super::summary::BusSummary;
use super::unitree_hg::{LOW_CMD_TOPIC, LOW_STATE_TOPIC, LowCmd, LowState};
use crate::channels::{
    ChannelError, ContractNode, N_CONTACTS, STATE_FLAG_BASE_UNMEASURED, STATE_FLAG_DAMPING,
    STATE_FLAG_HOLD, ServiceKind, StateMsg, TORQUE_FLAG_FALLBACK, TorqueMsg,
};
use crate::plant::feet::fill_foot_wrenches;
use crate::plant::{CommandGate, CommandOrigin, PlantInfo};
use crate::realtime::LatencyHistogram;

/// Errors that end a run.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    #[error(transparent)]
    Dds(#[from] DdsError),
    #[error(transparent)]
    Channel(#[from] ChannelError),
    #[error("{0}")]
    Setup(String),
    #[error(
        "another participant writes rt/lowcmd ({0} writer(s)): two controllers would fight over \
         the drives. Release Unitree's own motion service first (its SDK's motion switcher, \
         `ReleaseMode`), and stop any other low-level controller"
    )]
    OtherController(usize),
    #[error("no valid rt/lowstate within {0} s: is the robot (or its simulator) on this domain?")]
    NoRobot(f64),
    #[error("the robot is gone: no valid rt/lowstate for {0} s")]
    RobotLost(f64),
}

/// What the participant was asked to run.
#[derive(Debug, Clone)]
pub struct BusOptions {
    pub bus: BusConfig,
    pub robot: Arc<crate::robot::Robot>,
    /// The scenario the robot is pushed with (`sim.scenario`): its name, content hash and
    /// force factor go out with every state.
    pub scenario: String,
    /// `sim.mode = "lockstep"`: the scenario is announced as playing from the first state;
    /// in real time it starts when the lab's sample says it did.
    pub lockstep: bool,
    /// iceoryx2 prefix and node name of upc's contract.
    pub prefix: String,
    pub node_name: String,
    /// Run this long (s of robot time; 0: until interrupted).
    pub duration: f64,
}

/// The poll period of the wait for the controller's answer: what it adds to an answer at most.
const ANSWER_POLL: Duration = Duration::from_micros(50);

/// How often the brace (then damping) is written while the robot is silent: a G1's state
/// period, so that a robot whose states are lost on the way but which still listens keeps
/// receiving it.
const SILENT_REPEAT: Duration = Duration::from_millis(2);

/// How often, while the robot is silent, the participant checks that its own DDS threads run.
const LIVENESS_CHECK: Duration = Duration::from_millis(10);

/// How many times the damping is written, every [`SILENT_REPEAT`], when the bus stops.
const FINAL_DAMPING: usize = 5;

/// How long a state waits for the lab's sample of its tick (s).
const LAB_WAIT: f64 = 3e-4;

/// The participant's side of the robot's bus: a DDS participant and its readers and writers,
/// replaced whole when the participant's threads end ([`Session::rejoin_if_ended`]).
struct RobotBus {
    states: Inbox<LowState>,
    labs: Inbox<LabState>,
    commands: Outbox<LowCmd>,
    joint_states: Outbox<JointState>,
    wrenches: Outbox<WrenchStamped>,
    live: Liveness,
    /// Last: dropped after the readers and writers that belong to it.
    #[expect(dead_code, reason = "held for its readers and writers, never read")]
    dp: rustdds::DomainParticipant,
}

impl RobotBus {
    /// A new participant on `net` with the bus's readers and writers; `before_writing` runs
    /// once the readers are there and before any writer is (nothing is written here).
    fn open(
        net: super::dds::BusNetwork,
        before_writing: impl FnOnce(&rustdds::DomainParticipant) -> Result<(), BusError>,
    ) -> Result<Self, BusError> {
        let dp = participant(net)?;
        let states = Inbox::new(&dp, LOW_STATE_TOPIC)?;
        let labs = Inbox::new(&dp, LAB_STATE_TOPIC)?;
        before_writing(&dp)?;
        Ok(Self {
            states,
            labs,
            commands: Outbox::new(&dp, LOW_CMD_TOPIC)?,
            joint_states: Outbox::new(&dp, JOINT_STATE_TOPIC)?,
            wrenches: Outbox::new(&dp, HAND_WRENCH_TOPIC)?,
            live: Liveness::of_new_participant(),
            dp,
        })
    }
}

/// The participant's endpoints: the robot's bus and upc's contract.
struct Endpoints {
    bus: RobotBus,
    state_out: crate::channels::Publisher<StateMsg>,
    torques: crate::channels::Subscriber<TorqueMsg>,
    state_event: crate::channels::Notifier,
    torque_event: crate::channels::Listener,
}

impl Endpoints {
    /// The robot's `bus` with upc's contract under `prefix`, as node `node_name`.
    fn open(bus: RobotBus, prefix: &str, node_name: &str) -> Result<Self, BusError> {
        let contract = ContractNode::open(prefix, node_name)?;
        Ok(Self {
            bus,
            state_out: contract.publisher()?,
            torques: contract.subscriber()?,
            state_event: contract.notifier(ServiceKind::State)?,
            torque_event: contract.listener(ServiceKind::Torques)?,
        })
    }
}

/// What the loop keeps between states.
struct Session<'a> {
    cfg: &'a BusConfig,
    desc: &'a crate::robot::Robot,
    robot: Robot,
    info: PlantInfo,
    gate: CommandGate,
    /// The controller's last valid torques.
    tau: DVector<f64>,
    drives: Drives,
    msg: Box<StateMsg>,
    points: [[f64; 3]; N_CONTACTS],
    tick0: u32,
    step: u64,
    /// When `robot.state` arrived.
    received: Instant,
    adapter: LatencyHistogram,
    round_trip: LatencyHistogram,
    summary: BusSummary,
}

/// Runs the participant until the duration elapses, `stop` is raised or the robot is lost.
pub fn run(opts: &BusOptions, stop: &AtomicBool) -> Result<BusSummary, BusError> {
    let cfg = &opts.bus;
    let map = MotorMap::new(&opts.robot).map_err(BusError::Setup)?;
    // Before the participant: the DDS library's threads inherit the scheduling.
    let realtime = crate::realtime::apply(&cfg.realtime);
    let mut summary = BusSummary {
        realtime,
        robot: opts.robot.name().into(),
        domain: cfg.domain,
        interface: cfg.interface.to_string(),
        scenario_start: -1.0,
        control_start: -1.0,
        ..Default::default()
    };
    let mut bus = RobotBus::open(cfg.network(), |dp| refuse_other_controllers(dp, cfg, stop))?;
    // Nothing is commanded before the first valid state.
    let Some(state) = first_state(&mut bus, cfg, stop, &mut summary)? else {
        return Ok(summary);
    };
    let info = announcement(opts)?;
    let mut ep = Endpoints::open(bus, &opts.prefix, &opts.node_name)?;
    tracing::info!(
        "on the bus: robot `{}` on domain {} via {}; contract prefix `{}`",
        opts.robot.name(),
        cfg.domain,
        cfg.interface,
        opts.prefix
    );
    let mut session = Session::new(cfg, &opts.robot, Robot::at_first(map, state), info, summary);
    let (cpu0, wall0) = (cpu_time(), Instant::now());
    let result = session.run(&mut ep, opts.duration, stop);
    session.leave_damped(&ep);
    let mut s = session.finish(&ep);
    s.wall_time = wall0.elapsed().as_secs_f64();
    s.cpu_share = (cpu_time() - cpu0) / s.wall_time.max(1e-9);
    s.error = result.as_ref().err().map(|e| e.to_string());
    match result {
        Err(e @ BusError::RobotLost(_)) => {
            tracing::error!("{e}");
            Ok(s)
        }
        Err(e) => Err(e),
        Ok(()) => Ok(s),
    }
}

/// The robot's first valid state (`None`: stopped before it came), refusals counted; none
/// within `bus.first_state_timeout` is an error.
fn first_state(
    bus: &mut RobotBus,
    cfg: &BusConfig,
    stop: &AtomicBool,
    summary: &mut BusSummary,
) -> Result<Option<LowState>, BusError> {
    let first = Instant::now() + Duration::from_secs_f64(cfg.first_state_timeout);
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        match bus.states.wait(first)? {
            None => return Err(BusError::NoRobot(cfg.first_state_timeout)),
            Some(s) if valid(&s, cfg.bad_crc, summary) => return Ok(Some(s)),
            Some(_) => {}
        }
    }
}

/// The plant run's announcement: the forces this robot is pushed with, as every plant
/// announces them (the forecaster scales its forecast and the controller checks the hash by
/// them).
fn announcement(opts: &BusOptions) -> Result<PlantInfo, BusError> {
    let scenario = opts
        .robot
        .scenario(&opts.scenario)
        .map_err(|e| BusError::Setup(e.to_string()))?;
    Ok(PlantInfo::start(
        &opts.scenario,
        &scenario,
        opts.robot.hash,
        opts.lockstep,
    ))
}

/// Watch `rt/lowcmd` for `bus.discovery` before writing to it: a writer there is another
/// controller (Unitree's motion service, another upc).
fn refuse_other_controllers(
    dp: &rustdds::DomainParticipant,
    cfg: &BusConfig,
    stop: &AtomicBool,
) -> Result<(), BusError> {
    let mut watch = Inbox::<LowCmd>::new(dp, LOW_CMD_TOPIC)?;
    let until = Instant::now() + Duration::from_secs_f64(cfg.discovery);
    while Instant::now() < until && !stop.load(Ordering::Relaxed) {
        let _ = watch.wait(until)?;
    }
    match watch.foreign_writers() {
        0 => Ok(()),
        foreign => Err(BusError::OtherController(foreign)),
    }
}

impl<'a> Session<'a> {
    /// The loop's state at the robot's first state: the drives hold, no controller yet.
    fn new(
        cfg: &'a BusConfig,
        desc: &'a crate::robot::Robot,
        robot: Robot,
        info: PlantInfo,
        summary: BusSummary,
    ) -> Self {
        Self {
            cfg,
            desc,
            tick0: robot.tick0,
            robot,
            gate: CommandGate::for_session(info.session),
            info,
            tau: DVector::zeros(desc.model.nv - 6),
            drives: Drives::default(),
            msg: Box::default(),
            points: [[0.0; 3]; N_CONTACTS],
            step: 0,
            received: Instant::now(),
            adapter: LatencyHistogram::new(),
            round_trip: LatencyHistogram::new(),
            summary,
        }
    }

    /// Leaves the robot damped, not under the last torques: written for a few of a G1's state
    /// periods, since one sample written just before the participant goes can be lost with it
    /// (a CI run's robot kept the hold as its last command) and the drives keep the last.
    fn leave_damped(&mut self, ep: &Endpoints) {
        for _ in 0..FINAL_DAMPING {
            let _ = ep.bus.commands.write(self.command(Drive::Damping, 0.0));
            std::thread::sleep(SILENT_REPEAT);
        }
    }

    /// One pass per robot state until the duration, a stop or the robot's silence.
    fn run(
        &mut self,
        ep: &mut Endpoints,
        duration: f64,
        stop: &AtomicBool,
    ) -> Result<(), BusError> {
        loop {
            let t = self.time();
            if duration > 0.0 && t > duration || stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            self.pair_lab(ep)?;
            let start = Instant::now();
            self.publish(ep, t)?;
            let published = Instant::now();
            self.summary.publish_max = self
                .summary
                .publish_max
                .max((published - start).as_secs_f64());
            let waited = self.await_answer(ep, published)?;
            self.decide(t);
            self.write_drive(ep, t)?;
            let total = self.received.elapsed();
            self.round_trip.record(total);
            self.adapter.record(total.saturating_sub(waited));
            self.next_state(ep)?;
        }
    }

    /// Robot time of the current state (s since the first).
    fn time(&self) -> f64 {
        f64::from(self.robot.state.tick.wrapping_sub(self.tick0)) * 1e-3
    }

    /// The lab's sample of this state's tick, if the lab publishes: it may trail the robot's.
    fn pair_lab(&mut self, ep: &mut Endpoints) -> Result<(), BusError> {
        let robot = &mut self.robot;
        while let Some(l) = ep.bus.labs.try_take()? {
            robot.lab = Some(l);
        }
        if robot
            .lab
            .as_ref()
            .is_some_and(|l| l.tick != robot.state.tick)
        {
            let until = self.received + Duration::from_secs_f64(LAB_WAIT);
            while let Some(l) = ep.bus.labs.wait(until)? {
                let this = l.tick == robot.state.tick;
                robot.lab = Some(l);
                if this {
                    break;
                }
            }
            self.summary.lab_missing += u64::from(
                robot
                    .lab
                    .as_ref()
                    .is_some_and(|l| l.tick != robot.state.tick),
            );
        }
        if let Some(l) = &robot.lab
            && l.scenario_start >= 0.0
            && self.info.scenario_start < 0.0
        {
            self.info.scenario_start = l.scenario_start - f64::from(self.tick0) * 1e-3;
            self.summary.scenario_start = self.info.scenario_start;
        }
        Ok(())
    }

    /// The contract's state and the ROS 2 messages of this robot state.
    fn publish(&mut self, ep: &mut Endpoints, t: f64) -> Result<(), BusError> {
        self.info.flags = match self.drives.drive {
            Drive::Hold | Drive::Handover | Drive::Brace => STATE_FLAG_HOLD,
            Drive::Damping => STATE_FLAG_DAMPING,
            Drive::Control => 0,
        };
        fill(
            &mut self.msg,
            &self.robot,
            self.desc,
            &self.info,
            (self.step, t),
            &mut self.points,
        );
        let msg = &self.msg;
        ep.state_out.send_with(|m| *m = **msg)?;
        ep.state_event.notify()?;
        publish_ros(&ep.bus.joint_states, &ep.bus.wrenches, &self.robot, t)?;
        Ok(())
    }

    /// Takes the controller's valid torques; the state the newest of them answers, if any came.
    fn take_torques(&mut self, ep: &mut Endpoints) -> Result<Option<u64>, BusError> {
        let mut fresh = None;
        while let Some(m) = ep.torques.receive()? {
            let holding = matches!(
                self.drives.drive,
                Drive::Hold | Drive::Brace | Drive::Damping
            );
            if holding && m.flags & TORQUE_FLAG_FALLBACK != 0 {
                continue;
            }
            let origin = CommandOrigin {
                session: m.session,
                controller: m.controller,
            };
            let n = self.tau.len();
            if self.gate.check(origin, m.seq, m.n, &m.tau, n).is_ok() {
                self.tau.as_mut_slice().copy_from_slice(&m.tau[..n]);
                self.drives.torques_arrived(Instant::now());
                fresh = Some(m.state_step);
            }
        }
        Ok(fresh)
    }

    /// Whether the controller's torques are recent enough to apply.
    fn current(&self) -> bool {
        self.drives.current(self.cfg, Instant::now())
    }

    /// The controller's answer to this state, until `bus.late` (no wait while there is no live
    /// controller: the hold or the damping go out at once); how long it waited since the state
    /// was published. The controller ticks on its own clock, in step with the robot's: when its
    /// answer to this state does not come in time, its newest torques go out (an answer to an
    /// earlier state: counted, `answers_behind`) while they are current.
    fn await_answer(
        &mut self,
        ep: &mut Endpoints,
        published: Instant,
    ) -> Result<Duration, BusError> {
        let live = self.current();
        let late = if live { self.cfg.late } else { 0.0 };
        let deadline = self.received + Duration::from_secs_f64(late);
        let mut newest = None;
        loop {
            if let Some(answered) = self.take_torques(ep)? {
                if answered >= self.step {
                    return Ok(published.elapsed());
                }
                newest = Some(answered);
            }
            let now = Instant::now();
            if now >= deadline {
                self.summary.late_answers += u64::from(live);
                match newest {
                    Some(_) => self.summary.answers_behind += 1,
                    None => self.summary.unanswered += 1,
                }
                // The wait was the controller's, answered or not: not the bus's own time.
                return Ok(published.elapsed());
            }
            // Polled, not a blocking wait on the torques' event: that wait overran its deadline by
            // 10 ms when the controller had been killed (measured), past the damping bound.
            ep.torque_event.drain()?;
            std::thread::sleep((deadline - now).min(ANSWER_POLL));
            let overslept = now.elapsed().saturating_sub(deadline - now).as_secs_f64();
            self.summary.wait_overshoot_max = self.summary.wait_overshoot_max.max(overslept);
        }
    }

    /// Who drives the robot now.
    fn decide(&mut self, t: f64) {
        let (drives, robot) = (&mut self.drives, &mut self.robot);
        drives.decide(self.cfg, robot, t, Instant::now(), &mut self.summary);
    }

    /// Waits for the next valid state. A controller falling silent meanwhile is braced at once,
    /// without waiting for the robot: the bound is `bus.command_timeout`, not a robot period.
    /// A robot silent for `bus.state_timeout` is braced too, every [`SILENT_REPEAT`] (damped
    /// after `bus.hold.brace`); silent for `bus.robot_lost`, it is gone.
    fn next_state(&mut self, ep: &mut Endpoints) -> Result<(), BusError> {
        let waiting = Instant::now();
        let silent = waiting + Duration::from_secs_f64(self.cfg.state_timeout);
        let mut lost = waiting + Duration::from_secs_f64(self.cfg.robot_lost);
        let mut counted = false;
        let mut liveness_checked: Option<Instant> = None;
        loop {
            let now = Instant::now();
            let driven = matches!(self.drives.drive, Drive::Handover | Drive::Control);
            let controller = self
                .drives
                .last_command
                .filter(|_| driven)
                .map(|c| c + Duration::from_secs_f64(self.cfg.command_timeout));
            let robot = if now < silent {
                silent
            } else {
                (now + SILENT_REPEAT).min(lost)
            };
            let until = controller.map_or(robot, |c| c.min(robot));
            match ep.bus.states.wait_newest(until)? {
                None if Instant::now() >= lost => {
                    return Err(BusError::RobotLost(self.cfg.robot_lost));
                }
                None if Instant::now() >= silent => {
                    if !counted {
                        counted = true;
                        self.summary.robot_silences += 1;
                        tracing::warn!(
                            "the robot is silent (no valid rt/lowstate for {} s): the brace, \
                             damping after {} s",
                            self.cfg.state_timeout,
                            self.cfg.hold.brace
                        );
                    }
                    let t = self.time();
                    let (drives, robot) = (&mut self.drives, &mut self.robot);
                    drives.robot_silent(self.cfg, robot, t, Instant::now(), &mut self.summary);
                    // Our own participant may be what went silent: checked as the silence
                    // begins, then every LIVENESS_CHECK.
                    let now = Instant::now();
                    if liveness_checked.is_none_or(|c| now - c >= LIVENESS_CHECK) {
                        liveness_checked = Some(now);
                        if self.rejoin_if_ended(ep)? {
                            // The new participant gets the whole time to hear the robot.
                            lost = Instant::now() + Duration::from_secs_f64(self.cfg.robot_lost);
                        }
                    }
                    self.write_drive(ep, t)?;
                }
                None => {
                    // The controller's deadline: torques that came meanwhile keep it.
                    let _ = self.take_torques(ep)?;
                    if !self.current() {
                        let t = self.time();
                        self.decide(t);
                        self.write_drive(ep, t)?;
                    }
                }
                Some(s)
                    if s.tick == self.robot.state.tick
                        || tick_behind(s.tick, self.robot.state.tick) =>
                {
                    self.summary.refused_stale_tick += 1;
                }
                Some(s) if valid(&s, self.cfg.bad_crc, &mut self.summary) => {
                    if counted {
                        let gap = waiting.elapsed().as_secs_f64();
                        self.summary.robot_silence_max = self.summary.robot_silence_max.max(gap);
                        tracing::info!("the robot speaks again after {gap:.3} s");
                    }
                    self.robot.state = s;
                    self.received = Instant::now();
                    self.step += 1;
                    return Ok(());
                }
                Some(_) => {}
            }
        }
    }

    /// A new participant in place of one whose threads ended (see [`Liveness`]); whether it was
    /// replaced. The robot, which kept publishing, is heard again once discovery matches the new
    /// one; the drives meanwhile keep the last command they got (the robot's own watchdog
    /// stands behind that).
    fn rejoin_if_ended(&mut self, ep: &mut Endpoints) -> Result<bool, BusError> {
        if !ep.bus.live.ended() {
            return Ok(false);
        }
        tracing::warn!(
            "t = {:.3} s: the DDS participant's threads ended (rustdds stops on an interrupted \
             poll: this process was stopped and continued?): joining the bus again",
            self.time()
        );
        let fresh = RobotBus::open(self.cfg.network(), |_| Ok(()))?;
        let old = std::mem::replace(&mut ep.bus, fresh);
        self.summary.undecodable += old.states.undecodable + old.labs.undecodable;
        self.summary.superseded += old.states.superseded;
        // Its surviving thread, if any, ends with it: counted only the new participant's after.
        drop(old);
        ep.bus.live = Liveness::of_new_participant();
        self.summary.dds_rejoins += 1;
        Ok(true)
    }

    /// The drive's command at robot time `t`: the answer to a state, or between states when the
    /// controller or the robot is silent (the brace at once, not at the robot's next state, then
    /// damping); counted and its write timed.
    fn write_drive(&mut self, ep: &mut Endpoints, t: f64) -> Result<(), BusError> {
        let blend = self.drives.blend(self.cfg, t);
        let cmd = self.command(self.drives.drive, blend);
        let w = Instant::now();
        ep.bus.commands.write(cmd)?;
        self.summary.write_max = self.summary.write_max.max(w.elapsed().as_secs_f64());
        self.summary.commands += 1;
        Ok(())
    }

    /// The command for this state: the drives' hold, the controller's torques, a blend of both,
    /// or damping; torques clamped to the effort limits; mode_machine echoed; sealed.
    fn command(&mut self, drive: Drive, blend: f64) -> LowCmd {
        let (cmd, clamped) = command(&self.robot, self.cfg, drive, blend, &self.tau);
        self.summary.clamped_commands += u64::from(clamped);
        cmd
    }

    /// The run's figures.
    fn finish(self, ep: &Endpoints) -> BusSummary {
        let mut s = self.summary;
        s.states = self.step + 1;
        // The robot's rate from its own clock: states per second of ticks.
        let span = f64::from(self.robot.state.tick.wrapping_sub(self.tick0)) * 1e-3;
        s.robot_rate = if span > 0.0 {
            self.step as f64 / span
        } else {
            0.0
        };
        // Added to the counts of participants replaced before this one.
        s.undecodable += ep.bus.states.undecodable + ep.bus.labs.undecodable;
        s.superseded += ep.bus.states.superseded;
        s.controller_commands = self.gate.stats;
        s.adapter_p50 = self.adapter.quantile(0.5);
        s.adapter_p99 = self.adapter.quantile(0.99);
        s.adapter_max = self.adapter.max();
        s.state_to_command_p50 = self.round_trip.quantile(0.5);
        s.state_to_command_p99 = self.round_trip.quantile(0.99);
        s.state_to_command_max = self.round_trip.max();
        s
    }
}

/// The contract's state from the robot's: joints and IMU from `rt/lowstate`; the base, sole and
/// hand forces and the door from the lab topic when there is one, else unmeasured.
fn fill(
    m: &mut StateMsg,
    robot: &Robot,
    desc: &crate::robot::Robot,
    info: &PlantInfo,
    (step, t): (u64, f64),
    points: &mut [[f64; 3]; N_CONTACTS],
) {
    let model = &desc.model;
    m.step = step;
    m.time = t;
    m.nq = model.nq as u32;
    m.nv = model.nv as u32;
    m.joint_torques.fill(f64::NAN);
    for (k, q, v, _, _) in robot.map.joints() {
        let s = &robot.state.motor_state[k];
        m.q[q] = f64::from(s.q);
        m.v[v] = f64::from(s.dq);
        m.joint_torques[v] = f64::from(s.tau_est);
    }
    info.announce(m);
    match &robot.lab {
        Some(l) => {
            m.q[..7].copy_from_slice(&l.base_pose);
            m.v[..6].copy_from_slice(&l.base_velocity);
            m.contact_forces = l.contact_forces;
            *points = l.contact_points;
            m.zmp = l.zmp;
            m.hand_force = l.hand_force;
            m.door_angle = l.door_angle;
            m.door_velocity = l.door_velocity;
            // A lab without motion capture: the estimator's base.
            if !l.has_base() {
                m.flags |= STATE_FLAG_BASE_UNMEASURED;
            }
        }
        None => {
            m.q[..7].fill(f64::NAN);
            m.v[..6].fill(f64::NAN);
            m.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
            m.hand_force = [f64::NAN; 3];
            m.flags |= STATE_FLAG_BASE_UNMEASURED;
        }
    }
    // The sensor block: the foot wrenches from the sole forces, the robot's own IMU.
    fill_foot_wrenches(m, points);
    let imu = &robot.state.imu_state;
    let [w, x, y, z] = imu.quaternion.map(f64::from);
    m.imu_orientation = [x, y, z, w];
    m.imu_angular_velocity = imu.gyroscope.map(f64::from);
    m.imu_linear_acceleration = imu.accelerometer.map(f64::from);
    m.stamps = [t; 4];
}

/// The joints and the hand's wrench for ROS 2.
fn publish_ros(
    joints: &Outbox<JointState>,
    wrenches: &Outbox<WrenchStamped>,
    robot: &Robot,
    t: f64,
) -> Result<(), DdsError> {
    let header = Header {
        stamp: Time::from_secs(t),
        frame_id: String::new(),
    };
    let mut js = JointState {
        header: header.clone(),
        ..Default::default()
    };
    for (k, name) in robot.map.names.iter().enumerate() {
        let s = &robot.state.motor_state[k];
        js.name.push(name.clone());
        js.position.push(f64::from(s.q));
        js.velocity.push(f64::from(s.dq));
        js.effort.push(f64::from(s.tau_est));
    }
    joints.write(js)?;
    if let Some(l) = robot
        .lab
        .as_ref()
        .filter(|l| l.hand_force.iter().all(|x| x.is_finite()))
    {
        let [x, y, z] = l.hand_force;
        wrenches.write(WrenchStamped {
            header: Header {
                frame_id: "world".into(),
                ..header
            },
            wrench: Wrench {
                force: Vector3 { x, y, z },
                torque: Vector3::default(),
            },
        })?;
    }
    Ok(())
}

/// CPU time of this process (s).
fn cpu_time() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
