//! The plant's own behaviour when no controller drives it, as a real robot's start-up posture
//! controller (or a harness) provides: hold the robot until the torque controller's first valid
//! torques, hand over to them without a jump, hold again when they stop, and give up to bare
//! joint damping only after `lost_timeout`. Pure (no IPC, no clock): the process feeds it the
//! simulated time and whether a command is current; the tests drive it directly.
//!
//! Torques by phase (τ_c: the commanded torques, s: hand-over progress in [0, 1]):
//! - `Hold`: τ = Kp (q_ref − q) − Kd q̇ + f(t) τ_last, the posture PD of [`PosturePd`] (gains on
//!   each joint's effective inertia, legs and torso floored) at q_ref = the start posture, or
//!   the posture when the controller was lost; τ_last, the last commanded torques, fades out
//!   linearly over `feedforward_fade` (they were holding the robot up a moment ago).
//! - `Handover`: τ = (1 − s) τ_hold + s τ_c, s rising linearly over `handover`.
//! - `Control`: τ = τ_c.
//! - `Damping`: τ = −D q̇ (`sim.process.safe_damping`).

use std::time::{Duration, Instant};

use nalgebra::DVector;

use super::config::{HoldConfig, HoldKind};
use super::physics::SimError;
use super::scene::PosturePd;
use crate::dynamics::Model;

/// Who drives the robot this step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    Hold,
    Handover,
    Control,
    Damping,
}

/// Steps per phase and transitions of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct HoldStats {
    pub hold_steps: u64,
    pub handover_steps: u64,
    pub damping_steps: u64,
    /// Hand-overs started (from a hold or from damping to the controller's torques).
    pub handovers: u64,
    /// Times the controller was lost (its torques stopped while it drove the robot).
    pub losses: u64,
}

/// A phase change, for the caller to log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transition {
    pub from: Phase,
    pub to: Phase,
}

pub struct Supervisor {
    cfg: HoldConfig,
    safe_damping: f64,
    pd: Option<PosturePd>,
    phase: Phase,
    /// Simulated time the current phase started.
    since: f64,
    /// Whether the current hold follows a lost controller (start-up holds never time out).
    after_loss: bool,
    /// Last commanded torques (feed-forward of a hold after a loss).
    last_cmd: DVector<f64>,
    feedforward: DVector<f64>,
    hold_tau: DVector<f64>,
    pub stats: HoldStats,
}

impl Supervisor {
    /// A supervisor that starts by holding `q_start`.
    /// `carrying`: the frames whose supporting joints carry the body (legs, torso), which the
    /// hold stiffens to `cfg.leg_kp`, `cfg.leg_kd` at least.
    pub fn new(
        model: &Model,
        q_start: &DVector<f64>,
        carrying: &[usize],
        cfg: &HoldConfig,
        safe_damping: f64,
        dt: f64,
    ) -> Result<Self, SimError> {
        let pd = match cfg.kind {
            HoldKind::PosturePd => Some(PosturePd::hold(model, q_start, carrying, cfg, dt)?),
            HoldKind::Damping => None,
        };
        let n = model.nv - if model.has_floating_base() { 6 } else { 0 };
        Ok(Self {
            cfg: *cfg,
            safe_damping,
            pd,
            phase: if cfg.kind == HoldKind::Damping {
                Phase::Damping
            } else {
                Phase::Hold
            },
            since: 0.0,
            after_loss: false,
            last_cmd: DVector::zeros(n),
            feedforward: DVector::zeros(n),
            hold_tau: DVector::zeros(n),
            stats: HoldStats::default(),
        })
    }

    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The torques to apply at simulated time `t` into `out`. `command`: the controller's
    /// current torques, `None` while there are none (never came, or timed out). Returns the
    /// transition made this step, if any. Allocation-free.
    pub fn torques(
        &mut self,
        t: f64,
        q: &DVector<f64>,
        v: &DVector<f64>,
        command: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Option<Transition> {
        let from = self.phase;
        let to = match (from, command) {
            (Phase::Hold | Phase::Damping, Some(_)) => Phase::Handover,
            (Phase::Handover, Some(_)) if t - self.since >= self.cfg.handover => Phase::Control,
            (Phase::Handover | Phase::Control, None) => {
                self.stats.losses += u64::from(from == Phase::Control);
                self.lose(q);
                Phase::Hold
            }
            (Phase::Hold, None)
                if self.after_loss
                    && self.cfg.lost_timeout > 0.0
                    && t - self.since > self.cfg.lost_timeout =>
            {
                Phase::Damping
            }
            (p, _) => p,
        };
        // Without a PD, a hold is bare damping.
        let to = if to == Phase::Hold && self.pd.is_none() {
            Phase::Damping
        } else {
            to
        };
        if to != from {
            self.phase = to;
            self.since = t;
            self.stats.handovers += u64::from(to == Phase::Handover);
        }
        match self.phase {
            Phase::Control => {
                if let Some(c) = command {
                    out.copy_from(c);
                    self.last_cmd.copy_from(c);
                }
            }
            Phase::Handover => {
                self.stats.handover_steps += 1;
                let s = if self.cfg.handover > 0.0 {
                    ((t - self.since) / self.cfg.handover).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                self.hold(t, q, v);
                if let Some(c) = command {
                    for i in 0..out.len() {
                        out[i] = (1.0 - s) * self.hold_tau[i] + s * c[i];
                    }
                    self.last_cmd.copy_from(c);
                }
            }
            Phase::Hold => {
                self.stats.hold_steps += 1;
                self.hold(t, q, v);
                out.copy_from(&self.hold_tau);
            }
            Phase::Damping => {
                self.stats.damping_steps += 1;
                damping(self.safe_damping, v, out);
            }
        }
        (to != from).then_some(Transition { from, to })
    }

    /// Enter a hold after the controller stopped: hold the posture the robot has now, with the
    /// last commanded torques as a fading feed-forward.
    fn lose(&mut self, q: &DVector<f64>) {
        self.after_loss = true;
        if let Some(pd) = &mut self.pd {
            pd.q_ref.copy_from(q);
        }
        self.feedforward.copy_from(&self.last_cmd);
    }

    /// The hold's torques at `t` into `self.hold_tau` (damping when there is no PD).
    fn hold(&mut self, t: f64, q: &DVector<f64>, v: &DVector<f64>) {
        let Some(pd) = &self.pd else {
            damping(self.safe_damping, v, &mut self.hold_tau);
            return;
        };
        pd.torques(q, v, &mut self.hold_tau);
        // The hold of a hand-over started in this phase's `since`; the fade counts from the loss.
        let fade = if self.cfg.feedforward_fade > 0.0 && self.after_loss {
            (1.0 - (t - self.since) / self.cfg.feedforward_fade).max(0.0)
        } else {
            0.0
        };
        if fade > 0.0 {
            self.hold_tau.axpy(fade, &self.feedforward, 1.0);
        }
    }
}

/// How long the controller has been silent, in the plant's *live* wall time: a period the plant
/// itself overran (descheduled, a slow step) published no state, so the controller had nothing
/// to answer and that time does not count against it. Without this a stall of the whole machine
/// longer than `command_timeout` reads as a lost controller once the plant resumes, though the
/// controller answers within a period of the next state. A controller silent while the plant
/// runs on time is still lost after `timeout`, also when the plant runs steadily behind (its
/// passes then take less than a period each and credit nothing).
#[derive(Debug, Clone, Copy)]
pub struct CommandClock {
    period: Duration,
    timeout: Duration,
    last_pass: Option<Instant>,
    last_command: Option<Instant>,
}

impl CommandClock {
    pub fn new(period: Duration, timeout: Duration) -> Self {
        Self {
            period,
            timeout,
            last_pass: None,
            last_command: None,
        }
    }

    /// The top of a plant loop pass at `now`: what this pass took beyond one period since the
    /// last one was the plant's own stall, credited to the controller's silence.
    pub fn pass(&mut self, now: Instant) {
        if let (Some(prev), Some(cmd)) = (self.last_pass, self.last_command.as_mut()) {
            let stall = now
                .saturating_duration_since(prev)
                .saturating_sub(self.period);
            *cmd = (*cmd + stall).min(now);
        }
        self.last_pass = Some(now);
    }

    /// A fresh command arrived at `now`.
    pub fn command(&mut self, now: Instant) {
        self.last_command = Some(now);
    }

    /// Whether the last command is current at `now`.
    pub fn current(&self, now: Instant) -> bool {
        self.last_command
            .is_some_and(|t| now.saturating_duration_since(t) <= self.timeout)
    }
}

/// Joint damping `τ = −D q̇` (the actuated joints: the last `out.len()` entries of `v`).
fn damping(d: f64, v: &DVector<f64>, out: &mut DVector<f64>) {
    let off = v.len() - out.len();
    for i in 0..out.len() {
        out[i] = -d * v[off + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Robot;

    fn cfg() -> HoldConfig {
        HoldConfig {
            kind: HoldKind::PosturePd,
            frequency: 6.0,
            damping_ratio: 1.0,
            leg_kp: 800.0,
            leg_kd: 10.0,
            handover: 0.2,
            feedforward_fade: 0.5,
            lost_timeout: 1.0,
        }
    }

    #[test]
    fn holds_hands_over_continuously_holds_again_then_damps() {
        let robot = Robot::embedded_default().unwrap();
        let (model, q0) = (&robot.model, &robot.home);
        let dt = 1e-3;
        let mut sup =
            Supervisor::new(model, q0, &robot.carrying_frames(), &cfg(), 5.0, dt).unwrap();
        let n = model.nv - 6;
        let mut q = q0.clone();
        // Knee bent 0.05 rad away from the hold's posture: the PD pushes back.
        let knee = model.joint_id("l_knee").unwrap();
        let iq = model.joints[knee].idx_q;
        q[iq] += 0.05;
        let v = DVector::zeros(model.nv);
        let cmd = DVector::from_element(n, 3.0);
        let mut out = DVector::zeros(n);
        assert_eq!(sup.torques(0.0, &q, &v, None, &mut out), None);
        assert_eq!(sup.phase(), Phase::Hold);
        let hold = out.clone();
        assert!(hold[iq - 7].abs() > 1.0, "the PD acts on the bent knee");
        // The first command starts the hand-over: the torque moves from the hold's to the
        // command's by at most (1/200) of the gap per step.
        let tr = sup.torques(0.001, &q, &v, Some(&cmd), &mut out).unwrap();
        assert_eq!((tr.from, tr.to), (Phase::Hold, Phase::Handover));
        assert!(
            (out[iq - 7] - hold[iq - 7]).abs() < 1e-12,
            "no jump at the hand-over"
        );
        let mut prev = out.clone();
        let mut t = 0.001;
        while sup.phase() == Phase::Handover {
            t += dt;
            sup.torques(t, &q, &v, Some(&cmd), &mut out);
            let step = (&out - &prev).amax();
            let gap = (&cmd - &hold).amax();
            assert!(step <= gap * dt / 0.2 + 1e-9, "step {step} at t = {t}");
            prev.copy_from(&out);
        }
        assert_eq!(sup.phase(), Phase::Control);
        assert!((t - 0.201).abs() < 1.5e-3, "hand-over took until {t}");
        assert_eq!(out, cmd);
        // Commands stop: hold the posture of now, starting from the last command (no jump).
        t += dt;
        let tr = sup.torques(t, &q, &v, None, &mut out).unwrap();
        assert_eq!((tr.from, tr.to), (Phase::Control, Phase::Hold));
        let pd_now = out[iq - 7] - cmd[iq - 7];
        assert!(
            pd_now.abs() < 1e-9,
            "at the posture of the loss the PD adds nothing"
        );
        // The feed-forward fades out in feedforward_fade.
        for _ in 0..600 {
            t += dt;
            sup.torques(t, &q, &v, None, &mut out);
        }
        assert!(out.amax() < 1e-9, "{}", out.amax());
        // Past lost_timeout: bare damping.
        let mut moving = v.clone();
        moving[6 + 2] = 2.0;
        while t < 1.5 {
            t += dt;
            sup.torques(t, &q, &moving, None, &mut out);
        }
        assert_eq!(sup.phase(), Phase::Damping);
        assert!((out[2] + 10.0).abs() < 1e-12);
        // A new controller: hand-over from the damping.
        sup.torques(t + dt, &q, &v, Some(&cmd), &mut out);
        assert_eq!(sup.phase(), Phase::Handover);
        let s = sup.stats;
        assert_eq!((s.handovers, s.losses), (2, 1));
        assert!(s.hold_steps > 900 && s.handover_steps >= 200 && s.damping_steps > 0);
    }

    #[test]
    fn command_age_counts_the_plant_s_live_time_only() {
        let ms = Duration::from_millis;
        let t0 = Instant::now();
        let mut c = CommandClock::new(ms(1), ms(50));
        assert!(!c.current(t0), "no command yet");
        c.pass(t0);
        c.command(t0);
        // The plant on time, the controller silent: lost after 50 ms.
        for k in 1..=60 {
            c.pass(t0 + ms(k));
            assert_eq!(c.current(t0 + ms(k)), k <= 50, "at {k} ms");
        }
        // The plant itself stalls 45 ms after a command at 100 ms: once it resumes, the
        // controller gets a few periods to answer the new state (3 ms late here: current).
        let mut c = CommandClock::new(ms(1), ms(50));
        c.pass(t0 + ms(100));
        c.command(t0 + ms(100));
        c.pass(t0 + ms(146));
        for k in 147..=149 {
            c.pass(t0 + ms(k));
            assert!(c.current(t0 + ms(k)), "at {k} ms");
        }
        // ... but not forever: 50 ms of live time after the stall, it is lost.
        for k in 150..=200 {
            c.pass(t0 + ms(k));
        }
        assert!(!c.current(t0 + ms(200)));
        // A plant steadily behind (passes of 0.8 ms, no sleep) credits nothing.
        let mut c = CommandClock::new(ms(1), ms(50));
        let us = Duration::from_micros;
        c.pass(t0);
        c.command(t0);
        let mut now = t0;
        while now < t0 + ms(51) {
            now += us(800);
            c.pass(now);
        }
        assert!(!c.current(now));
    }

    #[test]
    fn start_up_hold_never_times_out_and_damping_kind_never_holds() {
        let robot = Robot::embedded_default().unwrap();
        let (model, q0) = (&robot.model, &robot.home);
        let carrying = robot.carrying_frames();
        let mut sup = Supervisor::new(model, q0, &carrying, &cfg(), 5.0, 1e-3).unwrap();
        let v = DVector::zeros(model.nv);
        let mut out = DVector::zeros(model.nv - 6);
        for k in 0..3000 {
            sup.torques(k as f64 * 1e-3, q0, &v, None, &mut out);
        }
        assert_eq!(sup.phase(), Phase::Hold);
        let damping = HoldConfig {
            kind: HoldKind::Damping,
            ..cfg()
        };
        let mut sup = Supervisor::new(model, q0, &carrying, &damping, 5.0, 1e-3).unwrap();
        sup.torques(0.0, q0, &v, None, &mut out);
        assert_eq!(sup.phase(), Phase::Damping);
        assert_eq!(sup.stats.hold_steps, 0);
    }
}
