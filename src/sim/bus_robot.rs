//! `upc sim --bus unitree`: upc's plant (its own engine or MuJoCo) speaking as a G1 does, for
//! tests and demos without a robot. It publishes `rt/lowstate` at the robot's rate (joints,
//! motor torque estimates, the IMU at its mounting; nothing else) and applies `rt/lowcmd` as the
//! drives do, τ = tau + kp (q − q_meas) + kd (dq − dq_meas) clamped to the effort limits, at
//! every physics step with the latest command. What a G1 does not measure (base, sole and hand
//! forces) goes out on upc's own lab topic only ([`crate::bus::lab`]).
//!
//! On `--sensing realistic` the robot measures what its description's `[sensors]` says, through
//! the sensor models (encoders, IMU, the drives' torque estimates of MT-1 in `tau_est`), and the
//! lab has no motion capture or force plates: its sample carries the scenario's clock and the
//! door only, so the controller runs on what the G1 measures (docs/bus.md, "Sensing").
//!
//! Until the first valid command that carries torques (a controller's, through `upc bus`'s
//! hand-over; or the first command at all, `bus.sim.harness = "command"`, for a controller
//! that drives the drives' PD only) the robot hangs in its harness (the plant's hold at the
//! start posture, as `[sim.hold]`), as a lab keeps a robot on its gantry until its controller
//! has it: the drives' hold alone (`upc bus` before any controller: kp, kd, tau = 0) does not
//! keep a standing G1 up, and a loaded machine can start the controller seconds after the bus.
//! The scenario's push starts `bus.sim.scenario_delay` after the release. A
//! command with a bad CRC is ignored (as the robot does) and counted; no valid command for
//! `bus.sim.command_loss` lets the drives go limp (the robot's own watchdog).
//! `bus.sim.silence` withholds the states for a while, as a wire that loses them. Stopped and
//! continued (a debugger, Ctrl-Z), rustdds's threads end on the interrupted poll: the robot then
//! hears no command, checks its participant and joins the bus again, as `upc bus` does.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::DVector;

use super::config::{Mode, SimConfig};
use super::hold::Supervisor;
use super::physics::{Engine, Physics, StepReport};
use super::process::{
    Plant, PlantUser, ProcessError, apply_scenario, build_plant, fill_state, push_frame,
    put_applied_torques, sensors_of,
};
use super::record::Recorder;
use super::scene::DoorDrive;
use super::sensors::{ImuMount, RobotSensors, Sensors};
use crate::bus::BusConfig;
use crate::bus::config::HarnessRelease;
use crate::bus::dds::{BusNetwork, DdsError, Inbox, Liveness, Outbox, participant};
use crate::bus::lab::{LAB_STATE_TOPIC, LabState};
use crate::bus::motors::{MotorMap, Slot};
use crate::bus::unitree_hg::{LOW_CMD_TOPIC, LOW_STATE_TOPIC, LowCmd, LowState};
use crate::channels::{N_CONTACTS, StateMsg};
use crate::plant::PlantInfo;

/// What the simulated robot runs.
#[derive(Debug, Clone)]
pub struct SimRobotOptions {
    pub sim: SimConfig,
    /// Write the ground truth to this `.rrd`, with this recording id.
    pub rrd: Option<std::path::PathBuf>,
    pub recording_id: Option<String>,
    pub bus: BusConfig,
    pub robot: Arc<crate::robot::Robot>,
    pub engine: Engine,
}

/// Counters of a run (`sim.json` of a bus run).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SimRobotSummary {
    pub plant: String,
    pub robot: String,
    pub rate: f64,
    pub steps: u64,
    pub sim_time: f64,
    pub states: u64,
    /// States withheld by `bus.sim.silence`.
    pub silenced_states: u64,
    pub commands: u64,
    pub bad_crc_commands: u64,
    /// Commands whose mode_machine differs from the robot's.
    pub wrong_mode_machine: u64,
    /// Commands with a torque (tau + PD) above a joint's effort limit before the drive's clamp.
    pub over_limit_commands: u64,
    pub largest_effort_ratio: f64,
    /// Commands whose feed-forward `tau` alone is above a joint's effort limit (a controller
    /// that clamps sends none).
    pub feedforward_over_limit: u64,
    /// Plant time of the first valid command, of the robot's release from its harness (the
    /// first command with torques, or the first, as `bus.sim.harness` says), of the scenario's
    /// start, and of each time the drives went limp for want of commands.
    pub first_command: f64,
    pub released: f64,
    pub scenario_start: f64,
    pub limp_steps: u64,
    pub harness_steps: u64,
    /// Steps under damping only (every enabled slot kp = 0, kd > 0, tau = 0), and the first
    /// plant time of each such stretch.
    pub damping_steps: u64,
    pub damping_starts: Vec<f64>,
    pub overruns: u64,
    /// Times the DDS participant's threads had ended and a new participant joined the bus.
    pub dds_rejoins: u64,
    pub max_penetration: f64,
    pub error: Option<String>,
}

/// Runs the simulated robot until the duration elapses or `stop` is raised.
pub fn run(opts: &SimRobotOptions, stop: &AtomicBool) -> Result<SimRobotSummary, ProcessError> {
    struct OnBus<'a>(&'a SimRobotOptions, &'a AtomicBool);
    impl PlantUser for OnBus<'_> {
        type Output = SimRobotSummary;
        fn with<P: Physics>(self, plant: Plant<P>) -> Result<SimRobotSummary, ProcessError> {
            run_on_bus(self.0, plant, self.1)
        }
    }
    build_plant(&opts.sim, &opts.robot, opts.engine, OnBus(opts, stop))
}

fn dds(e: DdsError) -> ProcessError {
    ProcessError::Setup(e.to_string())
}

fn run_on_bus<P: Physics>(
    opts: &SimRobotOptions,
    plant: Plant<P>,
    stop: &AtomicBool,
) -> Result<SimRobotSummary, ProcessError> {
    let (cfg, bus) = (&opts.sim, &opts.bus);
    let map = MotorMap::new(&opts.robot).map_err(ProcessError::Setup)?;
    // A robot's loop has its own computer: `bus.realtime` gives the simulated one its priority
    // (before the participant, whose threads inherit it).
    crate::realtime::apply(&bus.realtime);
    let mut robot = BusRobot::new(opts, plant, map, RobotEnd::open(bus.network())?)?;
    tracing::info!(
        "simulated {} on the bus: domain {} via {}, rt/lowstate at {:.0} Hz, physics at {:.0} Hz",
        opts.robot.name(),
        bus.domain,
        bus.interface,
        robot.summary.rate,
        1.0 / cfg.dt
    );
    let total = if cfg.duration > 0.0 {
        (cfg.duration / cfg.dt).round() as u64
    } else {
        u64::MAX
    };
    let period = Duration::from_secs_f64(cfg.dt);
    let record_every = (cfg.record_period / cfg.dt).round().max(1.0) as u64;
    let mut next = Instant::now() + period;
    while robot.world.steps() < total && !stop.load(Ordering::Relaxed) {
        // The state of this step goes out first: a command answers a state.
        if robot.world.steps().is_multiple_of(robot.every) {
            robot.publish()?;
        }
        robot.take_commands()?;
        robot.rejoin_if_ended()?;
        if let Err(e) = robot.step() {
            robot.summary.error = Some(e.to_string());
            break;
        }
        if robot.world.steps().is_multiple_of(record_every)
            && let Some(r) = &mut robot.recorder
        {
            r.offer(&mut robot.world, &robot.rep.hand_force);
        }
        let now = Instant::now();
        if now > next {
            robot.summary.overruns += 1;
            if now - next > 10 * period {
                next = now;
            }
        } else {
            std::thread::sleep(next - now);
        }
        next += period;
    }
    robot.summary.steps = robot.world.steps();
    robot.summary.sim_time = robot.world.time();
    if let Some(r) = robot.recorder.take() {
        r.finish();
    }
    Ok(robot.summary)
}

/// The robot's side of the bus: its participant, readers and writers, replaced whole when the
/// participant's threads end.
struct RobotEnd {
    states: Outbox<LowState>,
    labs: Outbox<LabState>,
    commands: Inbox<LowCmd>,
    live: Liveness,
    network: BusNetwork,
    /// When a valid command last came, and the participant was last checked (wall time).
    heard: Instant,
    checked: Instant,
    /// Last: dropped after the readers and writers that belong to it.
    #[expect(dead_code, reason = "held for its readers and writers, never read")]
    dp: rustdds::DomainParticipant,
}

/// Without a command for this long (wall time), the robot checks its participant's threads,
/// then every this long: /proc is read, which a silent bus can afford.
const LIVENESS_CHECK: Duration = Duration::from_millis(20);

impl RobotEnd {
    fn open(network: BusNetwork) -> Result<Self, ProcessError> {
        let dp = participant(network).map_err(dds)?;
        let now = Instant::now();
        Ok(Self {
            states: Outbox::new(&dp, LOW_STATE_TOPIC).map_err(dds)?,
            labs: Outbox::new(&dp, LAB_STATE_TOPIC).map_err(dds)?,
            commands: Inbox::new(&dp, LOW_CMD_TOPIC).map_err(dds)?,
            live: Liveness::of_new_participant(),
            network,
            heard: now,
            checked: now,
            dp,
        })
    }
}

/// The simulated robot: the plant, its drives and harness, its bus endpoints.
struct BusRobot<'a, P> {
    opts: &'a SimRobotOptions,
    world: P,
    drive: DoorDrive,
    map: MotorMap,
    bus: RobotEnd,
    /// The plant's hold until the first command (the robot's harness).
    harness: Supervisor,
    sensors: Sensors,
    /// What the robot measures and its drives' torque estimates (on `realistic`).
    info: PlantInfo,
    push_frame: Option<usize>,
    /// Publish a state every this many physics steps.
    every: u64,
    tau: DVector<f64>,
    /// The torques of the last step, the drives' estimates in the next state.
    applied: Vec<f64>,
    /// The latest valid command and the plant time it came.
    latest: Option<(LowCmd, f64)>,
    msg: Box<StateMsg>,
    points: [[f64; 3]; N_CONTACTS],
    rep: StepReport,
    damping: bool,
    recorder: Option<Recorder>,
    summary: SimRobotSummary,
}

impl<'a, P: Physics> BusRobot<'a, P> {
    fn new(
        opts: &'a SimRobotOptions,
        plant: Plant<P>,
        map: MotorMap,
        end: RobotEnd,
    ) -> Result<Self, ProcessError> {
        let (cfg, bus) = (&opts.sim, &opts.bus);
        let Plant {
            physics: world,
            drive,
            scenario,
            carrying,
            ..
        } = plant;
        let every = (1.0 / (bus.sim.rate * cfg.dt)).round().max(1.0) as u64;
        let harness = Supervisor::new(
            world.robot(),
            world.q(),
            &carrying,
            &cfg.hold,
            cfg.process.safe_damping,
            cfg.dt,
        )?;
        let sensors = Sensors::with_robot(
            &sensors_of(cfg, &opts.robot),
            -world.robot().gravity.z,
            opts.robot
                .imu_frame
                .map(|f| ImuMount::new(&opts.robot.model, f)),
            RobotSensors {
                spec: opts.robot.description.sensors,
                effort: world.robot().effort_limits(),
            },
        );
        let push_frame = push_frame(cfg, &opts.robot)?;
        let recorder = match &opts.rrd {
            Some(path) => Some(
                Recorder::spawn(
                    path,
                    opts.recording_id.as_deref(),
                    None,
                    &world,
                    &opts.robot,
                    true,
                )
                .map_err(|e| {
                    ProcessError::Setup(format!("rerun recording {}: {e}", path.display()))
                })?,
            ),
            None => None,
        };
        let n = world.n_actuated();
        Ok(Self {
            summary: SimRobotSummary {
                plant: world.engine().into(),
                robot: opts.robot.name().into(),
                rate: 1.0 / (every as f64 * cfg.dt),
                first_command: -1.0,
                released: -1.0,
                scenario_start: -1.0,
                ..Default::default()
            },
            rep: *world.last_report(),
            info: PlantInfo::start(
                &cfg.scenario,
                &scenario,
                opts.robot.hash,
                cfg.mode == Mode::Lockstep,
            ),
            bus: end,
            opts,
            world,
            drive,
            map,
            harness,
            sensors,
            push_frame,
            every,
            tau: DVector::zeros(n),
            applied: vec![0.0; n],
            latest: None,
            msg: Box::default(),
            points: [[0.0; 3]; N_CONTACTS],
            damping: false,
            recorder,
        })
    }

    /// The state as the G1 reports it, and the lab's sample (first: the participant pairs it
    /// with the state of its tick).
    fn publish(&mut self) -> Result<(), ProcessError> {
        let (bus, t) = (&self.opts.bus, self.world.time());
        let [from, length] = bus.sim.silence;
        if (from..from + length).contains(&t) {
            self.summary.silenced_states += 1;
            return Ok(());
        }
        let rep = &self.rep;
        fill_state(
            &mut self.msg,
            &self.world,
            &self.info,
            rep.zmp.unwrap_or_default(),
            rep.hand_force,
        );
        for (p, c) in self.points.iter_mut().zip(self.world.contact_points()) {
            *p = [c.x, c.y, c.z];
        }
        // The lab's sample from the truth, before the robot's sensors.
        if bus.sim.lab {
            let mut lab = lab_state(&self.msg, rep, &self.world, &self.summary);
            // On `realistic` the lab has no motion capture or force plates.
            if self.sensors.realistic() {
                lab.unmeasured();
            }
            self.bus.labs.write(lab).map_err(dds)?;
        }
        // The models' step is the plant's (their latencies and the accelerometer's difference
        // count plant steps); they are sampled every `every` of them.
        let dt = self.opts.sim.dt;
        // The torques applied over the last step: what the drives' estimates read (MT-1 on
        // `realistic`).
        put_applied_torques(&mut self.msg, &self.applied);
        self.sensors.apply(&mut self.msg, dt, &self.points);
        let state = low_state(&self.msg, &self.map, bus.sim.mode_machine, t);
        self.bus.states.write(state).map_err(dds)?;
        self.summary.states += 1;
        Ok(())
    }

    /// The commands that arrived: the valid ones counted and the newest kept; the harness left
    /// as `bus.sim.harness` says, and the scenario's push started `bus.sim.scenario_delay`
    /// after it.
    fn take_commands(&mut self) -> Result<(), ProcessError> {
        let (bus, t) = (&self.opts.bus, self.world.time());
        while let Some(c) = self.bus.commands.try_take().map_err(dds)? {
            if !c.crc_ok() {
                self.summary.bad_crc_commands += 1;
                continue;
            }
            self.summary.commands += 1;
            self.summary.wrong_mode_machine += u64::from(c.mode_machine != bus.sim.mode_machine);
            if self.summary.first_command < 0.0 {
                self.summary.first_command = t;
                tracing::info!("t = {t:.3} s: first command");
            }
            let release = match bus.sim.harness {
                HarnessRelease::Torques => carries_torques(&c, &self.map),
                HarnessRelease::Command => true,
            };
            if self.summary.released < 0.0 && release {
                self.summary.released = t;
                tracing::info!("t = {t:.3} s: out of the harness ({:?})", bus.sim.harness);
            }
            self.latest = Some((c, t));
            self.bus.heard = Instant::now();
        }
        if self.summary.scenario_start < 0.0
            && self.summary.released >= 0.0
            && t >= self.summary.released + bus.sim.scenario_delay
        {
            self.summary.scenario_start = t;
            tracing::info!("t = {t:.3} s: scenario `{}` starts", self.opts.sim.scenario);
        }
        Ok(())
    }

    /// A new participant in place of one whose threads ended, checked while no command comes
    /// (before the first too: a robot stopped and continued before its controller came).
    fn rejoin_if_ended(&mut self) -> Result<(), ProcessError> {
        let now = Instant::now();
        if now - self.bus.heard < LIVENESS_CHECK || now - self.bus.checked < LIVENESS_CHECK {
            return Ok(());
        }
        self.bus.checked = now;
        if !self.bus.live.ended() {
            return Ok(());
        }
        tracing::warn!(
            "t = {:.3} s: the DDS participant's threads ended (rustdds stops on an interrupted \
             poll: this process was stopped and continued?): joining the bus again",
            self.world.time()
        );
        // The liveness is taken again once the old participant is gone: its surviving threads
        // must not count as the new one's.
        let network = self.bus.network;
        drop(std::mem::replace(&mut self.bus, RobotEnd::open(network)?));
        self.bus.live = Liveness::of_new_participant();
        self.summary.dds_rejoins += 1;
        Ok(())
    }

    /// One physics step under the drives (or the harness, or limp drives) and the scenario.
    fn step(&mut self) -> Result<(), ProcessError> {
        let t = self.world.time();
        let loss = self.opts.bus.sim.command_loss;
        let live = self.latest.as_ref().filter(|(_, at)| t - at < loss);
        match live {
            _ if self.summary.released < 0.0 => {
                let (q, v) = (self.world.q(), self.world.v());
                self.harness.torques(t, q, v, None, &mut self.tau);
                self.summary.harness_steps += 1;
            }
            None => {
                self.tau.fill(0.0);
                self.summary.limp_steps += 1;
            }
            Some((c, _)) => {
                let (q, v) = (self.world.q(), self.world.v());
                let d = drives(c, &self.map, q, v, &mut self.tau, &mut self.summary);
                if d && !self.damping {
                    self.summary.damping_starts.push(t);
                }
                self.damping = d;
                self.summary.damping_steps += u64::from(d);
            }
        }
        self.applied.copy_from_slice(self.tau.as_slice());
        let start = self.summary.scenario_start;
        let door_torque = apply_scenario(&mut self.world, &self.drive, self.push_frame, start)?;
        self.rep = self.world.step(&self.tau, door_torque)?;
        self.summary.max_penetration = self.summary.max_penetration.max(self.rep.max_penetration);
        Ok(())
    }
}

/// Whether a command carries feed-forward torques on an enabled joint (a controller drives),
/// not only the drives' hold or damping.
fn carries_torques(c: &LowCmd, map: &MotorMap) -> bool {
    map.joints()
        .any(|(k, ..)| c.motor_cmd[k].mode == 1 && c.motor_cmd[k].tau != 0.0)
}

/// The drives under a command: τ = tau + kp (q − q_meas) + kd (dq − dq_meas) on enabled slots,
/// clamped to the effort limit; whether it is damping only.
fn drives(
    c: &LowCmd,
    map: &MotorMap,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &mut DVector<f64>,
    summary: &mut SimRobotSummary,
) -> bool {
    let mut over = false;
    let mut ff_over = false;
    let mut damping = true;
    for (k, iq, iv, a, effort) in map.joints() {
        let m = &c.motor_cmd[k];
        if m.mode != 1 {
            tau[a] = 0.0;
            continue;
        }
        let t = f64::from(m.tau)
            + f64::from(m.kp) * (f64::from(m.q) - q[iq])
            + f64::from(m.kd) * (f64::from(m.dq) - v[iv]);
        damping &= m.kp == 0.0 && m.tau == 0.0 && m.kd > 0.0;
        ff_over |= f64::from(m.tau).abs() > effort * (1.0 + 1e-6);
        if t.abs() > effort {
            over = true;
            summary.largest_effort_ratio = summary.largest_effort_ratio.max(t.abs() / effort);
        }
        tau[a] = t.clamp(-effort, effort);
    }
    summary.over_limit_commands += u64::from(over);
    summary.feedforward_over_limit += u64::from(ff_over);
    damping
}

/// The G1's state from the plant's as measured: joints of the motor slots, the drives' torque
/// estimates, the IMU; sealed.
fn low_state(m: &StateMsg, map: &MotorMap, mode_machine: u8, t: f64) -> LowState {
    let mut s = LowState {
        mode_machine,
        tick: (t * 1e3).round() as u32,
        ..LowState::default()
    };
    for (k, slot) in map.slots.iter().enumerate() {
        let ms = &mut s.motor_state[k];
        match *slot {
            Slot::Joint { q, v, .. } => {
                ms.mode = 1;
                ms.q = m.q[q] as f32;
                ms.dq = m.v[v] as f32;
                ms.tau_est = m.joint_torques[v] as f32;
            }
            Slot::Locked { q } => {
                ms.mode = 1;
                ms.q = q as f32;
            }
            Slot::Unused => {}
        }
    }
    let [x, y, z, w] = m.imu_orientation;
    s.imu_state.quaternion = [w, x, y, z].map(|v| v as f32);
    s.imu_state.gyroscope = m.imu_angular_velocity.map(|v| v as f32);
    s.imu_state.accelerometer = m.imu_linear_acceleration.map(|v| v as f32);
    let r = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let (roll, pitch, yaw) = r.euler_angles();
    s.imu_state.rpy = [roll as f32, pitch as f32, yaw as f32];
    s.seal();
    s
}

/// What the lab measures at this state.
fn lab_state(
    m: &StateMsg,
    rep: &StepReport,
    world: &impl Physics,
    summary: &SimRobotSummary,
) -> LabState {
    let mut base_pose = [0.0; 7];
    base_pose.copy_from_slice(&m.q[..7]);
    let mut base_velocity = [0.0; 6];
    base_velocity.copy_from_slice(&m.v[..6]);
    let mut contact_points = [[0.0; 3]; N_CONTACTS];
    for (p, c) in contact_points.iter_mut().zip(world.contact_points()) {
        *p = [c.x, c.y, c.z];
    }
    LabState {
        tick: (m.time * 1e3).round() as u32,
        time: m.time,
        base_pose,
        base_velocity,
        contact_forces: m.contact_forces,
        contact_points,
        hand_force: m.hand_force,
        zmp: m.zmp,
        loaded: rep.zmp.is_some(),
        com: rep.com,
        door_angle: m.door_angle,
        door_velocity: m.door_velocity,
        door_torque: rep.door_torque,
        max_penetration: rep.max_penetration,
        max_slip_speed: rep.max_slip_speed,
        loop_error: rep.loop_error,
        scenario_start: summary.scenario_start,
    }
}
