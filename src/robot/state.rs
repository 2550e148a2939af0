//! What the controller knows of its robot at one tick: the measured joints and base, the IMU,
//! the wrenches, each sensor group with the time it was sampled. Filled from the channel
//! contract at one place (`crate::control::contract`); past it nothing reads the wire, and
//! every size is the robot's (its model's nq and nv), not the message's.

use nalgebra::DVector;

/// The time (plant clock, s) each sensor group was sampled: the state's time less the group's
/// latency; unchanged over a lost sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SensorStamps {
    pub joints: f64,
    pub imu: f64,
    pub feet: f64,
    pub hand: f64,
}

/// The robot as measured at one tick (preallocated for its model; refilled every tick).
#[derive(Debug, Clone)]
pub struct RobotState {
    /// Plant time (s).
    pub time: f64,
    /// Configuration and velocity (Pinocchio order, the model's nq and nv). When
    /// `base_measured` is false the floating base's entries are NaN until estimated.
    pub q: DVector<f64>,
    pub v: DVector<f64>,
    pub base_measured: bool,
    /// Measured joint torques (N·m), indexed like `v` (the base's entries NaN); NaN where the
    /// robot does not measure them.
    pub joint_torques: DVector<f64>,
    /// IMU: orientation (quaternion xyzw, world), angular velocity (rad/s) and specific force
    /// (m/s²) in its frame.
    pub imu_orientation: [f64; 4],
    pub imu_angular_velocity: [f64; 3],
    pub imu_linear_acceleration: [f64; 3],
    /// Ground wrench on each foot, left then right, [f, τ] in the sole frame about the
    /// centroid of its corners (N, N·m).
    pub foot_wrenches: [[f64; 6]; 2],
    /// Centre of pressure on the ground (world x, y; m), as the robot reports it.
    pub cop: [f64; 2],
    /// Force of the held object on the hand (N, world).
    pub hand_force: [f64; 3],
    pub stamps: SensorStamps,
    /// The robot is held by its plant (start-up hold or hand-over): not under control yet.
    pub held: bool,
    /// The task's clock (s): the scenario's time when the plant plays one, the plant's time
    /// when it announces none; `None` while an announced scenario has not started.
    pub task_time: Option<f64>,
}

impl RobotState {
    /// A state for a robot of `nq` coordinates and `nv` velocities, everything unmeasured.
    pub fn new(nq: usize, nv: usize) -> Self {
        Self {
            time: 0.0,
            q: DVector::from_element(nq, f64::NAN),
            v: DVector::from_element(nv, f64::NAN),
            base_measured: false,
            joint_torques: DVector::from_element(nv, f64::NAN),
            imu_orientation: [0.0, 0.0, 0.0, 1.0],
            imu_angular_velocity: [0.0; 3],
            imu_linear_acceleration: [0.0; 3],
            foot_wrenches: [[0.0; 6]; 2],
            cop: [0.0; 2],
            hand_force: [0.0; 3],
            stamps: SensorStamps::default(),
            held: false,
            task_time: None,
        }
    }
}
