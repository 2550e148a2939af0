//! Who drives the robot, and what its drives receive: the participant's safety logic as a
//! state machine of its own, with no DDS and no clock of its own (the caller passes the robot's
//! time and its live time), so that every rule of docs/bus.md, "Safety", is checked on a stepped
//! clock (the tests below), not against the machine's timing.

use std::time::Instant;

use nalgebra::DVector;

use super::config::{BadCrc, BusConfig};
use super::motors::{MotorMap, Slot};
use super::summary::BusSummary;
use super::unitree_hg::{LowCmd, LowState, MOTOR_SLOTS, MotorCmd};

/// Who drives the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Drive {
    /// The drives hold the start posture (no controller yet).
    Hold,
    /// Hold blended into the controller's torques.
    Handover,
    /// The controller's torques.
    Control,
    /// The controller (or the robot) went silent: the drives hold the posture the robot had
    /// then, with the controller's last torques (which carried the robot in that posture). A
    /// standing humanoid under damping alone collapses (measured: a G1 damped for 0.16 s while
    /// the participant joined the bus again fell); a stall of a few ms must not cost the robot.
    Brace,
    /// Damping only: the silence lasted longer than `bus.hold.brace`.
    Damping,
}

/// The robot as the participant knows it: its motor map, its start and braced postures, its
/// latest state.
pub struct Robot {
    pub map: MotorMap,
    /// Each slot's position at the first state: the hold's target.
    pub start_q: [f64; MOTOR_SLOTS],
    /// Each slot's position when the controller fell silent: the brace's target.
    pub braced_q: [f64; MOTOR_SLOTS],
    /// The tick of the first state (the robot's time origin).
    pub tick0: u32,
    pub state: LowState,
    pub lab: Option<super::lab::LabState>,
}

impl Robot {
    /// The robot as its first valid state finds it: that state's positions are the hold's.
    pub fn at_first(map: MotorMap, state: LowState) -> Self {
        let start_q = positions(&state);
        Self {
            map,
            start_q,
            braced_q: start_q,
            tick0: state.tick,
            state,
            lab: None,
        }
    }
}

fn positions(state: &LowState) -> [f64; MOTOR_SLOTS] {
    let mut q = [0.0; MOTOR_SLOTS];
    for (q, m) in q.iter_mut().zip(&state.motor_state) {
        *q = f64::from(m.q);
    }
    q
}

/// The drive and what it needs to change: the controller's last torques' arrival, when the
/// drive began.
#[derive(Debug, Clone)]
pub struct Drives {
    pub drive: Drive,
    /// When the controller's last valid torques came (the participant's live time).
    pub last_command: Option<Instant>,
    /// Robot time the drive began.
    pub since: f64,
    /// When the brace began (the participant's live time: the robot's time stands still while
    /// the robot is silent).
    braced_at: Option<Instant>,
    /// The brace is a silence under control (not during the hand-over): the controller's answer
    /// during the brace gives it the robot back at once.
    resumable: bool,
}

impl Default for Drives {
    fn default() -> Self {
        Self {
            drive: Drive::Hold,
            last_command: None,
            since: 0.0,
            braced_at: None,
            resumable: false,
        }
    }
}

impl Drives {
    /// The controller's valid torques came at `now`.
    pub fn torques_arrived(&mut self, now: Instant) {
        self.last_command = Some(now);
    }

    /// Whether the controller's torques are recent enough to apply at `now`.
    pub fn current(&self, cfg: &BusConfig, now: Instant) -> bool {
        self.last_command
            .is_some_and(|c| now.saturating_duration_since(c).as_secs_f64() < cfg.command_timeout)
    }

    /// The drive's weight of the controller's torques in a hand-over at robot time `t`.
    pub fn blend(&self, cfg: &BusConfig, t: f64) -> f64 {
        match self.drive {
            Drive::Handover => ((t - self.since) / cfg.hold.handover.max(1e-9)).min(1.0),
            _ => 0.0,
        }
    }

    /// Who drives the robot at robot time `t`, live time `now`; the state's posture is braced
    /// when the controller falls silent. Counted in `s`.
    pub fn decide(
        &mut self,
        cfg: &BusConfig,
        robot: &mut Robot,
        t: f64,
        now: Instant,
        s: &mut BusSummary,
    ) {
        let next = match (self.drive, self.current(cfg, now)) {
            // The robot is where the controller left it a moment ago: its torques at once (the
            // hold would pull it toward the start posture for the hand-over's length, mid-task).
            (Drive::Brace, true) if self.resumable => Drive::Control,
            (Drive::Hold | Drive::Brace | Drive::Damping, true) => Drive::Handover,
            (Drive::Handover, true) if t - self.since >= cfg.hold.handover => Drive::Control,
            (Drive::Handover | Drive::Control, false) => Drive::Brace,
            (Drive::Brace, false) if self.brace_over(cfg, now) => Drive::Damping,
            (d, _) => d,
        };
        self.switch(next, robot, t, now, s);
        s.hold_states += u64::from(matches!(self.drive, Drive::Hold | Drive::Handover));
        s.brace_states += u64::from(self.drive == Drive::Brace);
        s.damping_states += u64::from(self.drive == Drive::Damping);
    }

    /// The robot itself is silent (its states lost on the wire, or this participant's own DDS
    /// threads ended): the brace at the posture of its last state, as for a silent controller,
    /// then damping; the hold before the controller stays.
    pub fn robot_silent(
        &mut self,
        cfg: &BusConfig,
        robot: &mut Robot,
        t: f64,
        now: Instant,
        s: &mut BusSummary,
    ) {
        let next = match self.drive {
            Drive::Control | Drive::Handover => Drive::Brace,
            Drive::Brace if self.brace_over(cfg, now) => Drive::Damping,
            d => d,
        };
        self.switch(next, robot, t, now, s);
    }

    /// Whether the brace has lasted `bus.hold.brace` at `now`.
    fn brace_over(&self, cfg: &BusConfig, now: Instant) -> bool {
        self.braced_at
            .is_some_and(|b| now.saturating_duration_since(b).as_secs_f64() >= cfg.hold.brace)
    }

    fn switch(&mut self, next: Drive, robot: &mut Robot, t: f64, now: Instant, s: &mut BusSummary) {
        if next == self.drive {
            return;
        }
        if next == Drive::Brace {
            robot.braced_q = positions(&robot.state);
            self.braced_at = Some(now);
        }
        if let Some(c) = self.last_command {
            let delay = now.saturating_duration_since(c).as_secs_f64();
            match next {
                Drive::Brace => s.loss_to_brace_max = s.loss_to_brace_max.max(delay),
                Drive::Damping => s.loss_to_damping_max = s.loss_to_damping_max.max(delay),
                _ => {}
            }
        }
        transition(self.drive, next, t - self.since, t, s);
        self.resumable = match next {
            Drive::Brace => self.drive == Drive::Control,
            Drive::Damping => false,
            _ => self.resumable,
        };
        self.since = t;
        self.drive = next;
    }
}

/// Counts and logs a change of drive at robot time `t`, `held` s after the last one.
fn transition(from: Drive, to: Drive, held: f64, t: f64, s: &mut BusSummary) {
    match to {
        // A resume (`Drives::decide`): no new control start.
        Drive::Control if from == Drive::Brace => {
            s.resumes += 1;
            tracing::info!(
                "t = {t:.3} s: the controller answers again after {held:.3} s: its torques at once"
            );
        }
        Drive::Handover => {
            s.handovers += 1;
            tracing::info!("t = {t:.3} s: the controller's torques arrived; handing over");
        }
        Drive::Control => {
            if s.control_start < 0.0 {
                s.control_start = t;
            }
            tracing::info!("t = {t:.3} s: the controller drives the robot");
        }
        Drive::Brace => {
            s.losses += 1;
            tracing::warn!(
                "t = {t:.3} s: the controller is silent: the drives hold the robot's posture"
            );
        }
        Drive::Damping => {
            s.losses += u64::from(matches!(from, Drive::Control | Drive::Handover));
            if from == Drive::Brace {
                tracing::warn!("t = {t:.3} s: the controller silent for {held:.3} s: damping");
            } else {
                tracing::warn!("t = {t:.3} s: damping the drives");
            }
        }
        Drive::Hold => {}
    }
}

/// Whether a state may be used; refusals counted.
pub fn valid(s: &LowState, bad_crc: BadCrc, summary: &mut BusSummary) -> bool {
    if !s.crc_ok() {
        match bad_crc {
            BadCrc::Refuse => {
                summary.refused_bad_crc += 1;
                return false;
            }
            BadCrc::Count => summary.counted_bad_crc += 1,
        }
    }
    let finite = s
        .motor_state
        .iter()
        .all(|m| m.q.is_finite() && m.dq.is_finite() && m.tau_est.is_finite())
        && s.imu_state.quaternion.iter().all(|x| x.is_finite())
        && s.imu_state.gyroscope.iter().all(|x| x.is_finite())
        && s.imu_state.accelerometer.iter().all(|x| x.is_finite());
    if !finite {
        summary.refused_non_finite += 1;
    }
    finite
}

/// Whether tick `a` is before `b` (wrapping u32 milliseconds).
pub fn tick_behind(a: u32, b: u32) -> bool {
    b.wrapping_sub(a) < u32::MAX / 2 && a != b
}

/// A command: the drives' hold, the controller's torques, a blend of both, the brace, or
/// damping; torques clamped to the effort limits (and whether one was); mode_machine echoed;
/// sealed.
pub fn command(
    robot: &Robot,
    cfg: &BusConfig,
    drive: Drive,
    blend: f64,
    tau: &DVector<f64>,
) -> (LowCmd, bool) {
    let mut cmd = LowCmd {
        mode_pr: robot.state.mode_pr,
        mode_machine: robot.state.mode_machine,
        ..LowCmd::default()
    };
    let hold = 1.0 - blend;
    let mut clamped = false;
    for (k, slot) in robot.map.slots.iter().enumerate() {
        let c = &mut cmd.motor_cmd[k];
        let (kp, kd) = robot.map.hold[k];
        match *slot {
            Slot::Unused => {}
            Slot::Locked { q } => {
                *c = MotorCmd {
                    mode: 1,
                    q: q as f32,
                    kp: kp as f32,
                    kd: kd as f32,
                    ..Default::default()
                };
            }
            Slot::Joint {
                actuated, effort, ..
            } => {
                let (q, kp, kd, ff) = match drive {
                    Drive::Damping => (robot.start_q[k], 0.0, cfg.damping, 0.0),
                    Drive::Hold => (robot.start_q[k], kp, kd, 0.0),
                    Drive::Handover => (
                        robot.start_q[k],
                        hold * kp,
                        hold * kd,
                        blend * tau[actuated],
                    ),
                    Drive::Control => (robot.start_q[k], 0.0, 0.0, tau[actuated]),
                    Drive::Brace => (robot.braced_q[k], kp, kd, tau[actuated]),
                };
                let limited = ff.clamp(-effort, effort);
                clamped |= limited != ff;
                *c = MotorCmd {
                    mode: 1,
                    q: q as f32,
                    dq: 0.0,
                    tau: limited as f32,
                    kp: kp as f32,
                    kd: kd as f32,
                    reserve: 0,
                };
            }
        }
    }
    cmd.seal();
    (cmd, clamped)
}

/// The safety rules on a stepped clock: each is decided by the sequence of events, never by the
/// machine's timing, so each runs once and is never rerun.
#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    const LEG: usize = 0;
    const ARM: usize = 1;

    /// A robot of two driven slots (a leg joint with a 10 N·m limit, an arm joint) and a locked
    /// one, its first state sealed with mode_machine 6.
    fn robot() -> Robot {
        let mut slots = [Slot::Unused; MOTOR_SLOTS];
        slots[LEG] = Slot::Joint {
            q: 7,
            v: 6,
            actuated: 0,
            effort: 10.0,
        };
        slots[ARM] = Slot::Joint {
            q: 8,
            v: 7,
            actuated: 1,
            effort: 100.0,
        };
        slots[2] = Slot::Locked { q: 0.25 };
        let mut hold = [(0.0, 0.0); MOTOR_SLOTS];
        hold[LEG] = (150.0, 4.0);
        hold[ARM] = (40.0, 1.0);
        hold[2] = (60.0, 2.0);
        let map = MotorMap {
            slots,
            names: vec!["knee".into(), "elbow".into(), "wrist".into()],
            hold,
        };
        Robot::at_first(map, state(100, [0.3, -0.5]))
    }

    fn state(tick: u32, q: [f32; 2]) -> LowState {
        let mut s = LowState {
            tick,
            mode_machine: 6,
            ..LowState::default()
        };
        s.motor_state[LEG].q = q[0];
        s.motor_state[ARM].q = q[1];
        s.imu_state.quaternion = [1.0, 0.0, 0.0, 0.0];
        s.seal();
        s
    }

    fn cfg() -> BusConfig {
        BusConfig::load(&[], &[]).expect("embedded bus config")
    }

    /// The participant's clock and the robot's, stepped together: `ms` of both.
    struct Clock {
        now: Instant,
        t: f64,
    }

    impl Clock {
        fn step(&mut self, ms: u64) {
            self.now += Duration::from_millis(ms);
            self.t += ms as f64 * 1e-3;
        }
    }

    fn run() -> (BusConfig, Robot, Drives, Clock, BusSummary) {
        let clock = Clock {
            now: Instant::now(),
            t: 0.0,
        };
        let s = BusSummary {
            control_start: -1.0,
            ..Default::default()
        };
        (cfg(), robot(), Drives::default(), clock, s)
    }

    fn gains(cmd: &LowCmd, k: usize) -> (f32, f32, f32, f32) {
        let m = &cmd.motor_cmd[k];
        (m.q, m.kp, m.kd, m.tau)
    }

    #[test]
    fn the_drives_hold_the_start_posture_with_the_robot_s_own_gains_until_torques_come() {
        let (cfg, mut robot, mut d, mut c, mut s) = run();
        let tau = DVector::from_vec(vec![3.0, -2.0]);
        for _ in 0..50 {
            c.step(2);
            d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
            assert_eq!(d.drive, Drive::Hold);
        }
        let (cmd, clamped) = command(&robot, &cfg, d.drive, d.blend(&cfg, c.t), &tau);
        assert!(!clamped);
        assert!(cmd.crc_ok(), "every command is sealed");
        assert_eq!(cmd.mode_machine, 6, "mode_machine echoed");
        // Per slot, as the description says: not by the joint's name.
        assert_eq!(gains(&cmd, LEG), (0.3, 150.0, 4.0, 0.0));
        assert_eq!(gains(&cmd, ARM), (-0.5, 40.0, 1.0, 0.0));
        assert_eq!(gains(&cmd, 2), (0.25, 60.0, 2.0, 0.0));
        assert_eq!(cmd.motor_cmd[3].mode, 0, "an unused slot stays disabled");
        assert_eq!(s.hold_states, 50);
    }

    #[test]
    fn torques_are_handed_over_blended_then_drive_and_are_clamped_to_the_effort_limit() {
        let (cfg, mut robot, mut d, mut c, mut s) = run();
        let tau = DVector::from_vec(vec![30.0, -2.0]);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.handovers), (Drive::Handover, 1));
        c.step(100);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        let blend = d.blend(&cfg, c.t);
        assert!((blend - 0.1 / cfg.hold.handover).abs() < 1e-9, "{blend}");
        let (cmd, clamped) = command(&robot, &cfg, d.drive, blend, &tau);
        let (q, kp, kd, ff) = gains(&cmd, ARM);
        assert_eq!(q, -0.5);
        assert!((f64::from(kp) - 40.0 * (1.0 - blend)).abs() < 1e-4, "{kp}");
        assert!((f64::from(kd) - (1.0 - blend)).abs() < 1e-5, "{kd}");
        assert!((f64::from(ff) + 2.0 * blend).abs() < 1e-5, "{ff}");
        // 30 × 0.5 = 15 N·m on a 10 N·m joint.
        assert!(clamped && gains(&cmd, LEG).3 == 10.0);
        c.step(100);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!(d.drive, Drive::Control);
        assert!((s.control_start - 0.2).abs() < 1e-9, "{}", s.control_start);
        let (cmd, clamped) = command(&robot, &cfg, d.drive, 0.0, &tau);
        assert!(clamped);
        assert_eq!(gains(&cmd, LEG).1, 0.0, "no stiffness under control");
        assert_eq!(gains(&cmd, LEG).3, 10.0);
        assert_eq!(gains(&cmd, ARM).3, -2.0);
    }

    /// Control at robot time 0.2 s, the controller's last torques at `c.now`.
    fn controlled() -> (BusConfig, Robot, Drives, Clock, BusSummary) {
        let (cfg, mut robot, mut d, mut c, mut s) = run();
        for k in 0..=100 {
            if k > 0 {
                c.step(2);
            }
            d.torques_arrived(c.now);
            d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        }
        assert_eq!(d.drive, Drive::Control);
        (cfg, robot, d, c, s)
    }

    #[test]
    fn a_silent_controller_gets_the_brace_then_damping_and_an_answer_in_the_brace_resumes() {
        let (cfg, mut robot, mut d, mut c, mut s) = controlled();
        let tau = DVector::from_vec(vec![5.0, -2.0]);
        // The robot moved under control; silence until the command timeout: still control.
        robot.state = state(700, [0.35, -0.45]);
        let timeout_ms = (cfg.command_timeout * 1e3).round() as u64;
        c.step(timeout_ms - 1);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!(d.drive, Drive::Control);
        c.step(1);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.losses), (Drive::Brace, 1));
        assert!((s.loss_to_brace_max - cfg.command_timeout).abs() < 1e-9);
        // The posture it has, the robot's gains, the last torques.
        let (cmd, _) = command(&robot, &cfg, d.drive, 0.0, &tau);
        assert_eq!(gains(&cmd, LEG), (0.35, 150.0, 4.0, 5.0));
        assert_eq!(gains(&cmd, ARM), (-0.45, 40.0, 1.0, -2.0));
        // Its answer within the brace: its torques at once, no hand-over.
        c.step(100);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!(d.drive, Drive::Brace);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.resumes, s.handovers), (Drive::Control, 1, 1));
        // Silent again, now for good: the brace for `bus.hold.brace`, then damping.
        c.step(timeout_ms);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.losses), (Drive::Brace, 2));
        let braced_at = c.t;
        while c.t - braced_at < cfg.hold.brace - 1e-9 {
            assert_eq!(d.drive, Drive::Brace, "t = {}", c.t);
            c.step(2);
            d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        }
        assert_eq!(d.drive, Drive::Damping);
        assert_eq!(
            s.losses, 2,
            "the damping of a braced silence is the same loss"
        );
        let (cmd, _) = command(&robot, &cfg, d.drive, 0.0, &tau);
        for k in [LEG, ARM] {
            let (_, kp, kd, ff) = gains(&cmd, k);
            assert_eq!((kp, f64::from(kd), ff), (0.0, cfg.damping, 0.0));
        }
        assert!(s.loss_to_damping_max >= cfg.hold.brace);
        // A late answer: the hold and a new hand-over, from the start posture.
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.handovers, s.resumes), (Drive::Handover, 2, 1));
        let (cmd, _) = command(&robot, &cfg, d.drive, 0.0, &tau);
        assert_eq!(gains(&cmd, LEG).0, 0.3);
    }

    #[test]
    fn a_silence_during_the_hand_over_is_braced_then_handed_over_again() {
        let (cfg, mut robot, mut d, mut c, mut s) = run();
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        c.step(10);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!(d.drive, Drive::Brace);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.handovers, s.resumes), (Drive::Handover, 2, 0));
    }

    #[test]
    fn the_robot_s_silence_is_braced_then_damped_and_its_return_resumes_within_the_brace() {
        let (cfg, mut robot, mut d, mut c, mut s) = controlled();
        let tau = DVector::from_vec(vec![5.0, -2.0]);
        // The robot silent (its time stands still): the brace at its last posture.
        robot.state = state(700, [0.32, -0.4]);
        c.now += Duration::from_millis(20);
        d.robot_silent(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.losses), (Drive::Brace, 1));
        let (cmd, _) = command(&robot, &cfg, d.drive, 0.0, &tau);
        assert_eq!(gains(&cmd, LEG), (0.32, 150.0, 4.0, 5.0));
        // It speaks again 0.16 s later and the controller answers: its torques at once.
        c.now += Duration::from_millis(160);
        d.robot_silent(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!(d.drive, Drive::Brace);
        c.step(2);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.resumes, s.handovers), (Drive::Control, 1, 1));
        // Silent past the brace (live time): damping; its return is a new hand-over.
        c.now += Duration::from_millis(20);
        d.robot_silent(&cfg, &mut robot, c.t, c.now, &mut s);
        c.now += Duration::from_secs_f64(cfg.hold.brace);
        d.robot_silent(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.losses), (Drive::Damping, 2));
        c.step(2);
        d.torques_arrived(c.now);
        d.decide(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.handovers), (Drive::Handover, 2));
    }

    #[test]
    fn the_robot_s_silence_before_any_controller_keeps_the_hold() {
        let (cfg, mut robot, mut d, mut c, mut s) = run();
        c.now += Duration::from_secs(2);
        d.robot_silent(&cfg, &mut robot, c.t, c.now, &mut s);
        assert_eq!((d.drive, s.losses), (Drive::Hold, 0));
    }

    #[test]
    fn bad_crc_non_finite_and_old_ticks_are_refused_and_counted() {
        let mut s = BusSummary::default();
        let good = state(5, [0.1, 0.2]);
        assert!(valid(&good, BadCrc::Refuse, &mut s));
        let mut bad = good.clone();
        bad.motor_state[LEG].q = 0.11;
        assert!(!valid(&bad, BadCrc::Refuse, &mut s));
        assert_eq!(s.refused_bad_crc, 1);
        // A simulator that leaves the CRC unset: counted, used.
        assert!(valid(&bad, BadCrc::Count, &mut s));
        assert_eq!(s.counted_bad_crc, 1);
        let mut nan = good.clone();
        nan.imu_state.gyroscope[1] = f32::NAN;
        nan.seal();
        assert!(!valid(&nan, BadCrc::Refuse, &mut s));
        assert_eq!(s.refused_non_finite, 1);
        assert!(tick_behind(4, 5) && !tick_behind(5, 5) && !tick_behind(6, 5));
        assert!(tick_behind(u32::MAX, 1), "the tick wraps");
    }
}
