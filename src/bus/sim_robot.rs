//! `upc sim --bus unitree`: upc's plant (its own engine or MuJoCo) speaking as a G1 does, for
//! tests and demos without a robot. It publishes `rt/lowstate` at the robot's rate (joints,
//! motor torque estimates, the IMU at its mounting; nothing else) and applies `rt/lowcmd` as the
//! drives do, τ = tau + kp (q − q_meas) + kd (dq − dq_meas) clamped to the effort limits, at
//! every physics step with the latest command. What a G1 does not measure (base, sole and hand
//! forces) goes out on upc's own lab topic only ([`super::lab`]).
//!
//! Until the first valid command the robot hangs in its harness (the plant's hold at the start
//! posture, as `[sim.hold]`); the scenario's push starts `bus.sim.scenario_delay` after it. A
//! command with a bad CRC is ignored (as the robot does) and counted; no valid command for
//! `bus.sim.command_loss` lets the drives go limp (the robot's own watchdog).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::DVector;

use super::config::BusConfig;
use super::dds::{DdsError, Inbox, Outbox, participant};
use super::lab::{LAB_STATE_TOPIC, LabState};
use super::motors::{MotorMap, Slot};
use super::unitree_hg::{LOW_CMD_TOPIC, LOW_STATE_TOPIC, LowCmd, LowState};
use crate::channels::{N_CONTACTS, StateMsg};
use crate::sim::config::Push;
use crate::sim::hold::Supervisor;
use crate::sim::physics::{Engine, Physics};
use crate::sim::process::{Plant, PlantInfo, PlantUser, ProcessError, build_plant, fill_state};
use crate::sim::sensors::{ImuMount, Sensing, Sensors, SensorsConfig};

/// What the simulated robot runs.
#[derive(Debug, Clone)]
pub struct SimRobotOptions {
    pub sim: crate::sim::SimConfig,
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
    /// Plant time of the first valid command, of the scenario's start, and of each time the
    /// drives went limp for want of commands.
    pub first_command: f64,
    pub scenario_start: f64,
    pub limp_steps: u64,
    pub harness_steps: u64,
    /// Steps under damping only (every enabled slot kp = 0, kd > 0, tau = 0), and the first
    /// plant time of each such stretch.
    pub damping_steps: u64,
    pub damping_starts: Vec<f64>,
    pub overruns: u64,
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
    let Plant {
        physics: mut world,
        drive,
        scenario,
        carrying,
        ..
    } = plant;
    let map = MotorMap::new(&opts.robot).map_err(ProcessError::Setup)?;
    // A robot's loop has its own computer: `bus.realtime` gives the simulated one its priority
    // (before the participant, whose threads inherit it).
    crate::control::realtime::apply(&bus.realtime);
    let dp = participant(bus.network()).map_err(dds)?;
    let states = Outbox::<LowState>::new(&dp, LOW_STATE_TOPIC).map_err(dds)?;
    let labs = Outbox::<LabState>::new(&dp, LAB_STATE_TOPIC).map_err(dds)?;
    let mut commands = Inbox::<LowCmd>::new(&dp, LOW_CMD_TOPIC).map_err(dds)?;
    let dt = cfg.dt;
    let every = (1.0 / (bus.sim.rate * dt)).round().max(1.0) as u64;
    let mut summary = SimRobotSummary {
        plant: world.engine().into(),
        robot: opts.robot.name().into(),
        rate: 1.0 / (every as f64 * dt),
        first_command: -1.0,
        scenario_start: -1.0,
        ..Default::default()
    };
    tracing::info!(
        "simulated {} on the bus: domain {} via {}, rt/lowstate at {:.0} Hz, physics at {:.0} Hz",
        opts.robot.name(),
        bus.domain,
        bus.interface,
        summary.rate,
        1.0 / dt
    );
    let mut harness = Supervisor::new(
        world.robot(),
        world.q(),
        &carrying,
        &cfg.hold,
        cfg.process.safe_damping,
        dt,
    )?;
    let truth = SensorsConfig {
        sensing: Sensing::Truth,
        ..cfg.sensors
    };
    let mut sensors = Sensors::new(
        &truth,
        -world.robot().gravity.z,
        opts.robot
            .imu_frame
            .map(|f| ImuMount::new(&opts.robot.model, f)),
    );
    let info = PlantInfo::start(cfg, &scenario, opts.robot.hash);
    let push_frame = match cfg.push {
        Push::Hand => Some(
            opts.robot
                .model
                .frame_id(&opts.robot.description.hand.frame)
                .map_err(crate::sim::SimError::from)?,
        ),
        Push::Door | Push::None => None,
    };
    let n = world.n_actuated();
    let mut tau = DVector::zeros(n);
    let mut applied = vec![0.0; n];
    let mut latest: Option<(LowCmd, f64)> = None;
    let mut msg = Box::<StateMsg>::default();
    let mut points = [[0.0; 3]; N_CONTACTS];
    let mut rep = *world.last_report();
    let mut damping = false;
    let total = if cfg.duration > 0.0 {
        (cfg.duration / dt).round() as u64
    } else {
        u64::MAX
    };
    let period = Duration::from_secs_f64(dt);
    let mut next = Instant::now() + period;
    while world.steps() < total && !stop.load(Ordering::Relaxed) {
        let t = world.time();
        // The publish of the state of this step comes first: a command answers a state.
        if world.steps().is_multiple_of(every) {
            fill_state(
                &mut msg,
                &world,
                &info,
                rep.zmp.unwrap_or_default(),
                rep.hand_force,
            );
            for (p, c) in points.iter_mut().zip(world.contact_points()) {
                *p = [c.x, c.y, c.z];
            }
            sensors.apply(&mut msg, dt * every as f64, &points);
            // The lab's sample first: the participant pairs it with the state of its tick.
            if bus.sim.lab {
                labs.write(lab_state(&msg, &rep, &world, &summary))
                    .map_err(dds)?;
            }
            let state = low_state(&msg, &map, &applied, bus.sim.mode_machine, t);
            states.write(state).map_err(dds)?;
            summary.states += 1;
        }
        while let Some(c) = commands.try_take().map_err(dds)? {
            if !c.crc_ok() {
                summary.bad_crc_commands += 1;
                continue;
            }
            summary.commands += 1;
            summary.wrong_mode_machine += u64::from(c.mode_machine != bus.sim.mode_machine);
            if summary.first_command < 0.0 {
                summary.first_command = t;
                tracing::info!("t = {t:.3} s: first command; out of the harness");
            }
            latest = Some((c, t));
        }
        if summary.scenario_start < 0.0
            && summary.first_command >= 0.0
            && t >= summary.first_command + bus.sim.scenario_delay
        {
            summary.scenario_start = t;
            tracing::info!("t = {t:.3} s: scenario `{}` starts", cfg.scenario);
        }
        let live = latest
            .as_ref()
            .filter(|(_, at)| t - at < bus.sim.command_loss);
        match live {
            None if summary.first_command < 0.0 => {
                harness.torques(t, world.q(), world.v(), None, &mut tau);
                summary.harness_steps += 1;
            }
            None => {
                tau.fill(0.0);
                summary.limp_steps += 1;
            }
            Some((c, _)) => {
                let d = drives(c, &map, world.q(), world.v(), &mut tau, &mut summary);
                if d && !damping {
                    summary.damping_starts.push(t);
                }
                damping = d;
                summary.damping_steps += u64::from(d);
            }
        }
        applied.copy_from_slice(tau.as_slice());
        let door_torque = if summary.scenario_start >= 0.0 {
            drive.torque(world.sample_time(t - summary.scenario_start))
        } else {
            0.0
        };
        if let Some(frame) = push_frame {
            let f = if summary.scenario_start >= 0.0 {
                drive.hand_force(t - summary.scenario_start)
            } else {
                [0.0; 3]
            };
            world.set_push(frame, nalgebra::Vector3::from(f))?;
        }
        rep = match world.step(&tau, door_torque) {
            Ok(r) => r,
            Err(e) => {
                summary.error = Some(e.to_string());
                break;
            }
        };
        summary.max_penetration = summary.max_penetration.max(rep.max_penetration);
        let now = Instant::now();
        if now > next {
            summary.overruns += 1;
            if now - next > 10 * period {
                next = now;
            }
        } else {
            std::thread::sleep(next - now);
        }
        next += period;
    }
    summary.steps = world.steps();
    summary.sim_time = world.time();
    Ok(summary)
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

/// The G1's state from the plant's: joints of the motor slots, the applied torques as the
/// drives' estimates, the IMU; sealed.
fn low_state(m: &StateMsg, map: &MotorMap, applied: &[f64], mode_machine: u8, t: f64) -> LowState {
    let mut s = LowState {
        mode_machine,
        tick: (t * 1e3).round() as u32,
        ..LowState::default()
    };
    for (k, slot) in map.slots.iter().enumerate() {
        let ms = &mut s.motor_state[k];
        match *slot {
            Slot::Joint { q, v, actuated, .. } => {
                ms.mode = 1;
                ms.q = m.q[q] as f32;
                ms.dq = m.v[v] as f32;
                ms.tau_est = applied[actuated] as f32;
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
    rep: &crate::sim::StepReport,
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
