//! What a run of `upc bus` counted and measured (`bus.json`): written by the participant's loop
//! and by its safety's state machine (`drive.rs`).

use crate::plant::CommandStats;

/// Counters and figures of a run (`bus.json`).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct BusSummary {
    /// What of `bus.realtime` the OS granted.
    pub realtime: crate::realtime::RealtimeReport,
    pub robot: String,
    pub domain: u16,
    pub interface: String,
    /// Valid states per second of the robot's ticks (Hz): the robot's rate less the refused.
    pub robot_rate: f64,
    pub states: u64,
    pub commands: u64,
    pub refused_bad_crc: u64,
    pub counted_bad_crc: u64,
    pub refused_stale_tick: u64,
    pub refused_non_finite: u64,
    pub undecodable: u64,
    /// States dropped unread because a newer one had arrived (the loop fell behind the robot).
    pub superseded: u64,
    /// States whose lab sample did not arrive with them (the previous one was used).
    pub lab_missing: u64,
    /// States that got no new torques within `bus.late` while a controller was live, and states
    /// answered without new torques at all (the hold, the damping, a late controller).
    pub late_answers: u64,
    pub unanswered: u64,
    /// States whose answer did not come within `bus.late` but torques answering an earlier
    /// state did (they went out).
    pub answers_behind: u64,
    /// Commands with at least one torque clamped to its effort limit.
    pub clamped_commands: u64,
    pub controller_commands: CommandStats,
    pub handovers: u64,
    /// Times the robot was taken from the controller: its silence, or the robot's.
    pub losses: u64,
    /// Of the controller's silences under control, those it ended during the brace (within
    /// `bus.hold.brace`): its torques went out again at once, without the hold.
    pub resumes: u64,
    /// Times the robot fell silent for `bus.state_timeout` (damped, then handed back when it
    /// spoke again), and the longest silence (s).
    pub robot_silences: u64,
    pub robot_silence_max: f64,
    /// Times the DDS participant's threads had ended and a new participant joined the bus.
    pub dds_rejoins: u64,
    pub hold_states: u64,
    /// States answered with the brace (the controller silent: the posture held).
    pub brace_states: u64,
    pub damping_states: u64,
    /// The longest publication of a state on the contract and to ROS 2 (s).
    pub publish_max: f64,
    /// The longest a wait for the controller's answer overran its deadline (s).
    pub wait_overshoot_max: f64,
    /// The longest write of a command on the bus (s).
    pub write_max: f64,
    /// The longest time from the controller's last torques to the brace sent for its silence
    /// (s): the bound is `bus.command_timeout` + `bus.late`.
    pub loss_to_brace_max: f64,
    /// The longest time from the controller's last torques to damping (s): after the brace,
    /// `bus.hold.brace` of robot time.
    pub loss_to_damping_max: f64,
    /// Robot time at which the controller first had the robot, and the scenario started.
    pub control_start: f64,
    pub scenario_start: f64,
    /// What the bus adds: the robot's state received → its command written, minus the wait
    /// for the controller's answer (s), and the whole state → command time.
    pub adapter_p50: f64,
    pub adapter_p99: f64,
    pub adapter_max: f64,
    pub state_to_command_p50: f64,
    pub state_to_command_p99: f64,
    pub state_to_command_max: f64,
    /// CPU time of this process per second of run (one core = 1).
    pub cpu_share: f64,
    pub wall_time: f64,
    pub error: Option<String>,
}
