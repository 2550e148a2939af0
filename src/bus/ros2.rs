//! What a ROS 2 machine on the robot's domain reads: the joints as `sensor_msgs/JointState` and
//! the hand's wrench as `geometry_msgs/WrenchStamped`, under ROS 2's DDS names (topic `rt/…`,
//! type `pkg::msg::dds_::Type_`), CDR little endian. `ros2 topic echo /joint_states` shows them.

use serde::{Deserialize, Serialize};

/// Topic of the joint state (`/joint_states` for ROS 2).
pub const JOINT_STATE_TOPIC: &str = "rt/joint_states";
/// Topic of the hand's wrench (`/hand_wrench` for ROS 2).
pub const HAND_WRENCH_TOPIC: &str = "rt/hand_wrench";

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From seconds (≥ 0).
    pub fn from_secs(t: f64) -> Self {
        let t = t.max(0.0);
        let sec = t.floor();
        Self {
            sec: sec as i32,
            nanosec: ((t - sec) * 1e9).round().min(999_999_999.0) as u32,
        }
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/JointState`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Wrench`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Wrench {
    pub force: Vector3,
    pub torque: Vector3,
}

/// `geometry_msgs/WrenchStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WrenchStamped {
    pub header: Header,
    pub wrench: Wrench,
}

super::dds::serde_bus_message!(JointState, "sensor_msgs::msg::dds_::JointState_");
super::dds::serde_bus_message!(WrenchStamped, "geometry_msgs::msg::dds_::WrenchStamped_");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::dds::BusMessage;

    /// The CDR bytes of a JointState as the ROS 2 type support lays them out: header (stamp,
    /// string with its NUL), then sequences with u32 lengths, doubles aligned to 8.
    #[test]
    fn a_joint_state_has_ros_2_s_layout() {
        let js = JointState {
            header: Header {
                stamp: Time { sec: 3, nanosec: 5 },
                frame_id: "".into(),
            },
            name: vec!["a".into()],
            position: vec![1.5],
            velocity: vec![],
            effort: vec![],
        };
        let mut body = Vec::new();
        js.encode_body(&mut body);
        let mut want = Vec::new();
        want.extend(3i32.to_le_bytes());
        want.extend(5u32.to_le_bytes());
        want.extend(1u32.to_le_bytes()); // frame_id: length 1 (the NUL)
        want.extend([0, 0, 0, 0]); // NUL, padding to 4
        want.extend(1u32.to_le_bytes()); // one name
        want.extend(2u32.to_le_bytes()); // "a" + NUL
        want.extend([b'a', 0, 0, 0]);
        want.extend(1u32.to_le_bytes()); // one position (at offset 28: its double is aligned)
        want.extend(1.5f64.to_le_bytes());
        want.extend(0u32.to_le_bytes());
        want.extend(0u32.to_le_bytes());
        assert_eq!(body, want);
        assert_eq!(JointState::decode_body(&body).unwrap(), js);
    }
}
