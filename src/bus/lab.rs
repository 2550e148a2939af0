//! What a lab adds to a G1's own measurements, on a topic of upc's own (`upc/lab_state`, never
//! on the robot's topics): the floating base (motion capture), the sole forces (force plates),
//! the hand's force and the door (an instrumented door), and the simulator's own figures when
//! the robot is simulated. Published by upc's plants on the bus; the bus participant fills the
//! contract's unmeasured values from it when it is there (docs/bus.md, "The lab topic").

use serde::{Deserialize, Serialize};

use crate::channels::N_CONTACTS;

/// upc's own topic beside the robot's.
pub const LAB_STATE_TOPIC: &str = "upc/lab_state";

/// One sample, paired with the `rt/lowstate` of the same `tick`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LabState {
    /// The `rt/lowstate` tick this sample belongs to.
    pub tick: u32,
    /// Plant time (s).
    pub time: f64,
    /// Base position and orientation x y z, qx qy qz qw (world).
    pub base_pose: [f64; 7],
    /// Base linear and angular velocity (base frame), as the contract's `v[..6]`.
    pub base_velocity: [f64; 6],
    /// Sole corner forces (N, world, ground on robot) and where they apply (m), in the
    /// contract's contact order.
    pub contact_forces: [[f64; 3]; N_CONTACTS],
    pub contact_points: [[f64; 3]; N_CONTACTS],
    /// Force of the door on the hand (N, world).
    pub hand_force: [f64; 3],
    /// Centre of pressure (m), valid when `loaded`.
    pub zmp: [f64; 2],
    pub loaded: bool,
    /// Robot centre of mass (m, world).
    pub com: [f64; 3],
    pub door_angle: f64,
    pub door_velocity: f64,
    pub door_torque: f64,
    pub max_penetration: f64,
    pub max_slip_speed: f64,
    pub loop_error: f64,
    /// Plant time at which the scenario's push started (negative: not yet).
    pub scenario_start: f64,
}

impl LabState {
    /// A lab without motion capture or force plates: the base and the forces unmeasured (NaN),
    /// the scenario's clock, the door and the simulator's own figures kept.
    pub fn unmeasured(&mut self) {
        self.base_pose = [f64::NAN; 7];
        self.base_velocity = [f64::NAN; 6];
        self.contact_forces = [[f64::NAN; 3]; N_CONTACTS];
        self.hand_force = [f64::NAN; 3];
        self.zmp = [f64::NAN; 2];
        self.loaded = false;
    }

    /// Whether the lab measures the floating base.
    pub fn has_base(&self) -> bool {
        self.base_pose
            .iter()
            .chain(&self.base_velocity)
            .all(|x| x.is_finite())
    }
}

super::dds::serde_bus_message!(LabState, "upc::msg::dds_::LabState_");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::dds::BusMessage;

    #[test]
    fn a_lab_state_survives_its_encoding() {
        let mut s = LabState {
            tick: 7,
            time: 0.014,
            loaded: true,
            scenario_start: -1.0,
            ..Default::default()
        };
        s.base_pose[6] = 1.0;
        s.contact_forces[5] = [1.0, -2.0, 300.0];
        let mut body = Vec::new();
        s.encode_body(&mut body);
        assert_eq!(LabState::decode_body(&body).unwrap(), s);
        assert!(LabState::decode_body(&body[..body.len() - 3]).is_err());
    }
}
