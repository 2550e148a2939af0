//! The one place the controller reads the channel contract's state message: [`read_state`]
//! checks it against the robot and copies it into a [`RobotState`]; the tick and its parts
//! read only that.

use super::tick::TickError;
use crate::channels::{
    MAX_DOF, SENSOR_FEET, SENSOR_HAND, SENSOR_IMU, SENSOR_JOINTS, STATE_FLAG_BASE_UNMEASURED,
    STATE_FLAG_HOLD, StateMsg,
};
use crate::robot::{RobotState, SensorStamps};

// The contract carries each of the robot's contact points (its sole corners).
const _: () = assert!(crate::channels::N_CONTACTS == crate::robot::N_CONTACTS);

/// Fill `out` (sized for the robot) from `msg`. Its time, hold and task clock are read from
/// any message; the measurement is refused from a message of other dimensions than the robot's,
/// or announcing another robot than `robot_hash` (0 on either side: not checked), and `out`
/// keeps the last one read. Finiteness is the tick's to judge (an unmeasured base is NaN until
/// estimated).
pub fn read_state(msg: &StateMsg, robot_hash: u64, out: &mut RobotState) -> Result<(), TickError> {
    out.time = msg.time;
    out.held = msg.flags & STATE_FLAG_HOLD != 0;
    out.task_time = task_time(msg.time, msg.scenario_hash, msg.scenario_start);
    let (nq, nv) = (out.q.len(), out.v.len());
    // The message's arrays hold MAX_DOF values: a size beyond them is refused before any
    // slice by it (a model larger than the message would otherwise match it).
    let fits = |n: u32| n as usize <= MAX_DOF;
    if !fits(msg.nq) || !fits(msg.nv) || msg.nq as usize != nq || msg.nv as usize != nv {
        return Err(TickError::Dimensions {
            nq: msg.nq,
            nv: msg.nv,
            model_nq: nq,
            model_nv: nv,
        });
    }
    if msg.robot_hash != 0 && robot_hash != 0 && msg.robot_hash != robot_hash {
        return Err(TickError::Robot {
            plant: msg.robot_hash,
            mine: robot_hash,
        });
    }
    out.q.as_mut_slice().copy_from_slice(&msg.q[..nq]);
    out.v.as_mut_slice().copy_from_slice(&msg.v[..nv]);
    out.base_measured = msg.flags & STATE_FLAG_BASE_UNMEASURED == 0;
    out.joint_torques
        .as_mut_slice()
        .copy_from_slice(&msg.joint_torques[..nv]);
    out.imu_orientation = msg.imu_orientation;
    out.imu_angular_velocity = msg.imu_angular_velocity;
    out.imu_linear_acceleration = msg.imu_linear_acceleration;
    out.foot_wrenches = msg.foot_wrenches;
    out.cop = msg.zmp;
    out.hand_force = msg.hand_force;
    out.stamps = SensorStamps {
        joints: msg.stamps[SENSOR_JOINTS],
        imu: msg.stamps[SENSOR_IMU],
        feet: msg.stamps[SENSOR_FEET],
        hand: msg.stamps[SENSOR_HAND],
    };
    Ok(())
}

/// The task's clock (s), from a state's time, scenario hash and scenario start: the scenario's
/// time when the plant announces one, `None` while it announces one not started yet (a
/// real-time plant holds the robot and starts its scenario when a controller has taken the
/// robot over); the plant's time when it announces none (a real robot: its session is the task).
pub fn task_time(time: f64, scenario_hash: u64, scenario_start: f64) -> Option<f64> {
    match scenario_hash {
        0 => Some(time),
        _ if scenario_start >= 0.0 => Some(time - scenario_start),
        _ => None,
    }
}
