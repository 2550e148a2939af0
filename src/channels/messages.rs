//! The `#[repr(C)]` payloads exchanged between upc's processes. Their layout is the wire format:
//! any process (Rust, Python with ctypes, C) that mirrors it field by field, with the same
//! iceoryx2 type name, can publish or subscribe. Documented in `services/CHANNELS.md`.
//!
//! Units are SI; vectors are in the world frame (z up) unless a field says otherwise.

use iceoryx2::prelude::*;

/// Capacity of the q, v and τ arrays: the contract's largest robot, nq ≤ 128 (a floating base
/// and 121 joints; the iCub-like humanoid uses nq = 39, nv = 38, 32 torques, Romeo with its
/// fingers nq = 62). A robot beyond it locks joints in its description (`locked`). Changing it
/// changes the payloads' layout: raise [`CONTRACT_VERSION`].
pub const MAX_DOF: usize = 128;
/// Version of the payloads' layout (services/CHANNELS.md, "Contract version"): raised whenever
/// a payload of this file changes. iceoryx2 refuses a peer of another layout when it opens a
/// service; the Zenoh framing carries the version in its header.
/// 1: `MAX_DOF` = 48; 2: `MAX_DOF` = 128; 3: the sensor block of [`StateMsg`] (IMU, foot
/// wrenches, sample times); 4: the measured joint torques of [`StateMsg`].
pub const CONTRACT_VERSION: u16 = 4;
/// Contact points: four sole corners per foot, order l_fl, l_fr, l_rl, l_rr, r_fl, r_fr, r_rl, r_rr.
pub const N_CONTACTS: usize = 8;
/// Capacity of a force forecast (samples).
pub const MAX_FORECAST: usize = 2048;

/// Robot state, simulator → controller, once per simulation step.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("upc::StateMsg")]
pub struct StateMsg {
    /// Simulation step counter (starts at 0, +1 per step).
    pub step: u64,
    /// Simulated time (s).
    pub time: f64,
    pub nq: u32,
    pub nv: u32,
    /// Configuration: [base position (3), base quaternion xyzw (4), joints…] (Pinocchio order).
    pub q: [f64; MAX_DOF],
    /// Velocity: [base linear (3), base angular (3) in the base frame, joint rates…].
    pub v: [f64; MAX_DOF],
    /// Force of the ground on each sole corner (N, world).
    pub contact_forces: [[f64; 3]; N_CONTACTS],
    /// Centre of pressure of the contact forces on the ground (m, world x, y).
    pub zmp: [f64; 2],
    /// Door hinge angle (rad) and rate (rad/s).
    pub door_angle: f64,
    pub door_velocity: f64,
    /// Force of the door on the right hand (N, world): the true hand–door force.
    pub hand_force: [f64; 3],
    /// Identifies this run of the plant (random, non-zero, fixed from its first state to its
    /// last): a restarted plant has a new one. Torques echo it (`TorqueMsg::session`).
    pub session: u64,
    /// Content hash of the scenario the plant plays ([`crate::scenario::Scenario::content_hash`]);
    /// 0: none announced (a real robot).
    pub scenario_hash: u64,
    /// Plant time (s) at which the scenario's time 0 fell: the door pushes with the scenario's
    /// force at `time − scenario_start`. A real-time simulator starts the scenario when a
    /// controller has taken the robot over; lockstep at 0. Negative: not started yet.
    pub scenario_start: f64,
    /// `STATE_FLAG_*` bits.
    pub flags: u32,
    pub _pad: u32,
    /// Factor the plant applies to the scenario's forces for its robot (the scenario's file
    /// forces × this are what pushes: a forecaster following the plant scales by it too);
    /// 0: none announced (read as 1).
    pub force_scale: f64,
    /// Content hash of the plant's robot description and URDF
    /// ([`crate::robot::Robot::hash`]); a controller refuses states of another robot. 0: none
    /// announced (a real robot: the controller checks dimensions only).
    pub robot_hash: u64,
    /// Name (embedded) or path of the scenario the plant plays, UTF-8, NUL-padded.
    pub scenario: [u8; SCENARIO_NAME_LEN],
    // The sensor block: what a robot's SDK gives beside the joints (services/CHANNELS.md,
    // "Sensors"). A plant that measures its floating base (a simulator on truth, a motion-capture
    // lab) also fills `q[..7]` and `v[..6]`; one that does not sets `STATE_FLAG_BASE_UNMEASURED`
    // and the controller estimates them from this block.
    /// IMU orientation: its frame (mounted on the base, aligned with it) in the world, quaternion
    /// xyzw; the yaw is the IMU's own (it drifts on a real one).
    pub imu_orientation: [f64; 4],
    /// IMU angular velocity (rad/s, IMU frame).
    pub imu_angular_velocity: [f64; 3],
    /// IMU specific force (m/s², IMU frame): what an accelerometer reads, the acceleration minus
    /// gravity (at rest, +g along the world's up).
    pub imu_linear_acceleration: [f64; 3],
    /// Wrench of the ground on each foot, left then right: [fx, fy, fz, τx, τy, τz] (N, N·m) in
    /// the sole frame (x toward the toes, z up from the sole), about the centroid of the foot's
    /// four corners; as a six-axis foot F/T sensor gives it, moved to the sole.
    pub foot_wrenches: [[f64; 6]; 2],
    /// Plant time (s) at which each sensor group was sampled, `SENSOR_*` order (joints, IMU,
    /// feet, hand): `time` minus the group's latency; unchanged over a lost sample.
    pub stamps: [f64; 4],
    /// Measured joint torques (N·m), indexed like `v` (the floating base's six entries NaN): a
    /// robot's drive torque estimates (the G1's `tau_est`), the torques upc's plants applied
    /// over the step; NaN where the plant does not measure them.
    pub joint_torques: [f64; MAX_DOF],
}

/// Indices of [`StateMsg::stamps`].
pub const SENSOR_JOINTS: usize = 0;
pub const SENSOR_IMU: usize = 1;
pub const SENSOR_FEET: usize = 2;
pub const SENSOR_HAND: usize = 3;

/// Capacity of `StateMsg::scenario` (bytes).
pub const SCENARIO_NAME_LEN: usize = 128;

/// The text of a NUL-padded scenario name (empty when not valid UTF-8).
pub fn scenario_name(bytes: &[u8; SCENARIO_NAME_LEN]) -> &str {
    let end = bytes
        .iter()
        .position(|&b| b == 0)
        .unwrap_or(SCENARIO_NAME_LEN);
    std::str::from_utf8(&bytes[..end]).unwrap_or("")
}

/// The plant holds the robot itself (start-up posture hold, or the hold after the controller was
/// lost): torques are not applied yet, or only in part during the hand-over.
pub const STATE_FLAG_HOLD: u32 = 1;
/// The plant runs in lockstep (waits for the torques answering each state).
pub const STATE_FLAG_LOCKSTEP: u32 = 2;
/// The hold gave way to bare joint damping (`sim.hold.lost_timeout` passed without a controller).
pub const STATE_FLAG_DAMPING: u32 = 4;
/// The plant does not measure its floating base: `q[..7]` and `v[..6]` are NaN, and a
/// controller estimates them from the sensor block (IMU, joints, foot wrenches).
pub const STATE_FLAG_BASE_UNMEASURED: u32 = 8;

impl StateMsg {
    /// The scenario name announced by the plant (empty when none or not valid UTF-8).
    pub fn scenario_name(&self) -> &str {
        scenario_name(&self.scenario)
    }

    /// Announce `name` (truncated to the capacity at a character boundary).
    pub fn set_scenario_name(&mut self, name: &str) {
        let mut end = name.len().min(SCENARIO_NAME_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        self.scenario = [0; SCENARIO_NAME_LEN];
        self.scenario[..end].copy_from_slice(&name.as_bytes()[..end]);
    }
}

/// Joint torques, controller → simulator, answering one state.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("upc::TorqueMsg")]
pub struct TorqueMsg {
    /// Sequence number of this command, strictly increasing per controller run.
    pub seq: u64,
    /// The `StateMsg::step` these torques answer (lockstep pairs them).
    pub state_step: u64,
    /// Number of torques (actuated joints, nv − 6 for a floating base).
    pub n: u32,
    /// Controller status flags (see `TORQUE_FLAG_*`).
    pub flags: u32,
    /// Controller compute time for this answer (ns): lets the simulator separate IPC latency
    /// from compute in its round-trip measurement.
    pub compute_ns: u64,
    /// The `StateMsg::session` of the plant run these torques answer: a plant applies only
    /// torques computed from its own states.
    pub session: u64,
    /// Identifies this run of the controller (random, non-zero): a plant accepts a `seq` that
    /// starts over when this changes (a restarted controller).
    pub controller: u64,
    /// Joint torques (N·m), model joint order.
    pub tau: [f64; MAX_DOF],
}

/// The controller's torques came from its fallback (solver failure, stale state…).
pub const TORQUE_FLAG_FALLBACK: u32 = 1;

/// Hand force forecast, forecaster → controller: the force the environment will apply on the
/// hand at `t0 + i·dt`, i = 0 … len−1 (simulated time).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("upc::ForecastMsg")]
pub struct ForecastMsg {
    /// Sequence number, strictly increasing per forecaster run.
    pub seq: u64,
    /// Time of the first sample (s, simulated time).
    pub t0: f64,
    /// Sample spacing (s), > 0.
    pub dt: f64,
    /// Number of valid samples, ≤ MAX_FORECAST.
    pub len: u32,
    pub _pad: u32,
    /// The window is the forecaster's word for simulated times in [t0, t0 + period): the next
    /// window starts at t0 + period. In lockstep the controller waits for the window whose
    /// period covers the state's time, which makes the run reproducible. 0: no promise (the
    /// controller uses the newest window, as in real time).
    pub period: f64,
    /// Content hash of the scenario forecast (as in `StateMsg::scenario_hash`); 0: unknown.
    pub scenario_hash: u64,
    /// Forces (N, world).
    pub forces: [[f64; 3]; MAX_FORECAST],
}

/// Ground-truth diagnostics of the simulator, for loggers and tests (not for the controller).
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("upc::GroundTruthMsg")]
pub struct GroundTruthMsg {
    pub step: u64,
    pub time: f64,
    /// Centre of mass (m, world).
    pub com: [f64; 3],
    /// Hand–handle loop-closure error (m).
    pub loop_error: f64,
    /// Deepest contact penetration (m, ≥ 0).
    pub max_penetration: f64,
    /// Fastest tangential speed of a contact point in contact (m/s).
    pub max_slip_speed: f64,
    /// Door hinge torque applied this step (N·m).
    pub door_torque: f64,
    /// Wall time of the physics step (s).
    pub step_time: f64,
    pub solver_iterations: u32,
    /// Torque messages rejected so far (wrong length, non-finite, out of order).
    pub rejected_commands: u32,
    /// Steps run with stale (or no) torques so far.
    pub stale_commands: u64,
    /// `STATE_FLAG_*` of the state published with it.
    pub flags: u32,
    pub _pad: u32,
    /// Steps the plant held the robot itself so far (start-up and after a lost controller).
    pub hold_steps: u64,
}

macro_rules! zeroed_default {
    ($($t:ty),*) => {$(
        impl Default for $t {
            fn default() -> Self {
                // SAFETY: plain-old-data of integers and floats; all-zero bits are valid.
                unsafe { core::mem::zeroed() }
            }
        }
    )*};
}
zeroed_default!(StateMsg, TorqueMsg, ForecastMsg, GroundTruthMsg);

// The forecast windows' rule of the contract: which window is the forecaster's word at a time
// (its `period`), read alike by the forecaster and the controller.

/// Index of the forecast window that covers simulated time `t` when windows start every
/// `period` at 0, period, 2·period, …: the forecaster publishes window k at t0 = k·period once
/// the plant's time reaches it, and a lockstep controller at time `t` waits for window
/// `window_index(t)`. The 1e-6 absorbs the rounding of a time accumulated in steps.
pub fn window_index(t: f64, period: f64) -> i64 {
    (t / period + 1e-6).floor() as i64
}

/// Whether a window starting at `t0` and promising `period` is the forecaster's word at `t`
/// (`t` in [t0, t0 + period), with the tolerance of [`window_index`]).
pub fn window_covers(t0: f64, period: f64, t: f64) -> bool {
    window_index(t - t0, period) < 1
}
