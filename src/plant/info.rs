//! What every state a plant publishes announces besides the robot: the plant run's session, the
//! scenario it plays (name, content hash, start, the force factor for this robot), the robot's
//! content hash and the plant's flags. Forecasters follow the scenario; controllers check their
//! forecast and their robot against it, and answer the session.

use crate::channels::{STATE_FLAG_HOLD, STATE_FLAG_LOCKSTEP, StateMsg};
use crate::scenario::Scenario;

/// What a state says about the plant besides the world: the run's session, the scenario it
/// plays, its flags.
#[derive(Debug, Clone)]
pub struct PlantInfo {
    pub session: u64,
    pub scenario_hash: u64,
    pub scenario: String,
    /// Plant time of the scenario's time 0 (negative: not started).
    pub scenario_start: f64,
    pub flags: u32,
    /// The scenario's force factor for the robot, and the robot's content hash.
    pub force_scale: f64,
    pub robot_hash: u64,
}

impl PlantInfo {
    /// A new plant run of `scenario`, named `name` (as the plant was given it), for the robot of
    /// content hash `robot_hash`; `lockstep`: the plant steps in lockstep with the controller.
    pub fn start(name: &str, scenario: &Scenario, robot_hash: u64, lockstep: bool) -> Self {
        PlantInfo {
            session: crate::channels::new_run_id(),
            scenario_hash: scenario.content_hash(),
            scenario: name.to_owned(),
            // Lockstep plays the scenario from 0; real time once a controller drives the robot.
            scenario_start: if lockstep { 0.0 } else { -1.0 },
            flags: if lockstep {
                STATE_FLAG_LOCKSTEP
            } else {
                STATE_FLAG_HOLD
            },
            force_scale: scenario.force_scale,
            robot_hash,
        }
    }

    /// Writes the announcement into the state `m` (allocation-free).
    pub fn announce(&self, m: &mut StateMsg) {
        m.session = self.session;
        m.scenario_hash = self.scenario_hash;
        m.scenario_start = self.scenario_start;
        m.flags = self.flags;
        m.force_scale = self.force_scale;
        m.robot_hash = self.robot_hash;
        m.set_scenario_name(&self.scenario);
    }
}
