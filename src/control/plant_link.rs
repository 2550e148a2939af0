//! The controller's view of its plant, as a state machine of its own (no IPC): which received
//! state is new, which plant run it belongs to (a restarted simulator starts a new one), and
//! when the plant has gone quiet (a stale period) or away. The loop feeds it what it received
//! and acts on its [`Verdict`]; what it decides is in `services/FAULTS.md`.

use std::time::{Duration, Instant};

use crate::channels::StateMsg;
use crate::config::LoopMode;

/// What the loop does after a receive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Control from the received state; `restarted`: it is the first of a new plant run (the
    /// core, the forecast's time line and the metrics latch again from it).
    Control { restarted: bool },
    /// Nothing to do this pass: no state yet, a repeated one, or a silence shorter than
    /// `state_timeout` (or, in lockstep, a silent plant whose process is alive).
    Idle,
    /// Real time, no state for `state_timeout`: damping torques for the last state, `step`.
    Damp { step: u64 },
    /// No state at all within `startup_timeout` of the start.
    NeverStarted,
    /// Lockstep: no state past the reconnect timeout, and the plant's process is gone.
    Gone,
    /// Lockstep: the plant still sends the state `step` answered `state_timeout` ago. It has not
    /// seen the answer (lost, or sent before it listened): send it again, or both wait forever.
    Reanswer { step: u64 },
}

/// What the link counted over a run (`summary.json`'s keys by its fields).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LinkCounts {
    /// Passes without a new state (real time) or with a repeated one.
    pub stale_states: u64,
    /// Silences longer than `state_timeout`.
    pub stale_periods: u64,
    /// Restarted plants latched onto.
    pub reconnects: u64,
    /// Longest wall time between two fresh states (s).
    pub longest_state_gap: f64,
    /// Lockstep: answers sent again to a plant still sending the state they answer (a lost
    /// answer; 0 in a healthy run).
    #[serde(rename = "lockstep_reanswers")]
    pub reanswers: u64,
}

/// The timeouts of [`PlantLink`] (s), from `[controller]` and the command line.
#[derive(Clone, Copy, Debug)]
pub struct LinkTimeouts {
    pub state: f64,
    pub reconnect: f64,
    pub startup: f64,
}

pub struct PlantLink {
    mode: LoopMode,
    timeouts: LinkTimeouts,
    started: Instant,
    last_step: Option<u64>,
    session: u64,
    last_time: f64,
    last_state_at: Instant,
    stale: bool,
    /// Lockstep: when the plant's liveness was last checked, and whether a wait for a live but
    /// silent plant was logged in this stale period.
    liveness_checked: Option<Instant>,
    waiting_for_live_plant: bool,
    pub counts: LinkCounts,
}

impl PlantLink {
    pub fn new(mode: LoopMode, timeouts: LinkTimeouts) -> Self {
        Self::new_at(Instant::now(), mode, timeouts)
    }

    /// [`PlantLink::new`] started at `now` (the clock is the caller's: tests step it).
    pub fn new_at(now: Instant, mode: LoopMode, timeouts: LinkTimeouts) -> Self {
        PlantLink {
            mode,
            timeouts,
            started: now,
            last_step: None,
            session: 0,
            last_time: 0.0,
            last_state_at: now,
            stale: false,
            liveness_checked: None,
            waiting_for_live_plant: false,
            counts: LinkCounts::default(),
        }
    }

    /// The step of the last state controlled from (`None` before the first).
    pub fn last_step(&self) -> Option<u64> {
        self.last_step
    }

    /// How long the plant has been silent at `now` (s since its last fresh state, or the last
    /// answer in lockstep); 0 before its first state.
    pub fn quiet_at(&self, now: Instant) -> f64 {
        match self.last_step {
            Some(_) => now
                .saturating_duration_since(self.last_state_at)
                .as_secs_f64(),
            None => 0.0,
        }
    }

    /// The plant run (session) of the last state.
    pub fn session(&self) -> u64 {
        self.session
    }

    /// Classifies the newest received state, if any. `plant_alive` is asked (at most every
    /// 100 ms) in lockstep when the plant has been silent past the reconnect timeout.
    pub fn classify(
        &mut self,
        received: Option<&StateMsg>,
        plant_alive: impl FnOnce() -> bool,
    ) -> Verdict {
        self.classify_at(Instant::now(), received, plant_alive)
    }

    /// [`PlantLink::classify`] at `now`.
    pub fn classify_at(
        &mut self,
        now: Instant,
        received: Option<&StateMsg>,
        plant_alive: impl FnOnce() -> bool,
    ) -> Verdict {
        // A new session, or a step that goes back, is a new plant run (a restarted simulator);
        // the same step again is the lockstep simulator re-sending a state it waits on.
        let restarted = matches!((received, self.last_step),
            (Some(st), Some(l)) if st.step < l || (st.session != self.session && st.session != 0));
        match received {
            Some(st) if restarted || self.last_step.is_none_or(|l| st.step > l) => {
                self.accept(now, st, restarted);
                Verdict::Control { restarted }
            }
            repeated => self.without_state(now, repeated.is_some(), plant_alive),
        }
    }

    /// The state was answered: lockstep waits for the forecast or C2 before the answer are not
    /// the plant's silence.
    pub fn answered(&mut self) {
        self.answered_at(Instant::now());
    }

    /// [`PlantLink::answered`] at `now`.
    pub fn answered_at(&mut self, now: Instant) {
        self.last_state_at = now;
    }

    fn accept(&mut self, now: Instant, state: &StateMsg, restarted: bool) {
        if let Some(last) = self.last_step {
            let gap = now.duration_since(self.last_state_at).as_secs_f64();
            self.counts.longest_state_gap = self.counts.longest_state_gap.max(gap);
            if restarted {
                self.counts.reconnects += 1;
                tracing::warn!(
                    "simulator restarted: step {} (t = {:.3} s) after step {last} (t = {:.3} \
                     s), {gap:.3} s without state; references re-latched, control resumes \
                     (reconnect {})",
                    state.step,
                    state.time,
                    self.last_time,
                    self.counts.reconnects
                );
            } else if self.stale {
                tracing::info!(
                    "state back at step {} after {gap:.3} s: control resumes",
                    state.step
                );
            }
        }
        self.stale = false;
        self.waiting_for_live_plant = false;
        self.last_step = Some(state.step);
        self.session = state.session;
        self.last_time = state.time;
    }

    fn without_state(
        &mut self,
        now: Instant,
        repeated: bool,
        plant_alive: impl FnOnce() -> bool,
    ) -> Verdict {
        let Some(last) = self.last_step else {
            return if now.duration_since(self.started).as_secs_f64() > self.timeouts.startup {
                Verdict::NeverStarted
            } else {
                Verdict::Idle
            };
        };
        let realtime = self.mode == LoopMode::Realtime;
        self.counts.stale_states += u64::from(realtime || repeated);
        let quiet = now.duration_since(self.last_state_at).as_secs_f64();
        if quiet <= self.timeouts.state {
            return Verdict::Idle;
        }
        if repeated && !realtime {
            // A lockstep plant resends the state it waits on: it is alive, and waits for us.
            self.counts.reanswers += 1;
            self.last_state_at = now;
            if self.counts.reanswers.is_power_of_two() {
                tracing::warn!(
                    "the simulator still waits on step {last} {quiet:.3} s after its answer: \
                     answering it again ({} so far)",
                    self.counts.reanswers
                );
            }
            return Verdict::Reanswer { step: last };
        }
        if !self.stale {
            self.stale = true;
            self.counts.stale_periods += 1;
            let t = self.last_time;
            if realtime {
                tracing::warn!(
                    "no state for {quiet:.3} s after step {last} (t = {t:.3} s): damping \
                     torques until a simulator publishes again"
                );
            } else {
                tracing::warn!(
                    "no state for {quiet:.3} s after step {last} (t = {t:.3} s): waiting {} s \
                     for a simulator",
                    self.timeouts.reconnect
                );
            }
        }
        if realtime {
            return Verdict::Damp { step: last };
        }
        // A lockstep run is a function of its inputs, not of wall time: a plant that is slow
        // (starved, stopped in a debugger) is waited for; one whose process is gone ends it.
        let due = self
            .liveness_checked
            .is_none_or(|t| now.duration_since(t) >= Duration::from_millis(100));
        if quiet > self.timeouts.state + self.timeouts.reconnect && due {
            self.liveness_checked = Some(now);
            if !plant_alive() {
                return Verdict::Gone;
            }
            if !self.waiting_for_live_plant {
                self.waiting_for_live_plant = true;
                tracing::warn!(
                    "no state for {quiet:.3} s, but the simulator's process is alive: waiting \
                     for it"
                );
            }
        }
        Verdict::Idle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(step: u64, session: u64) -> StateMsg {
        StateMsg {
            step,
            session,
            time: step as f64 * 1e-3,
            ..StateMsg::default()
        }
    }

    /// A clock the test steps: no sleeps, no timing in the assertions.
    struct Clock(Instant);

    impl Clock {
        fn new() -> Self {
            Clock(Instant::now())
        }
        fn advance(&mut self, ms: u64) -> Instant {
            self.0 += Duration::from_millis(ms);
            self.0
        }
    }

    fn link(clock: &Clock, mode: LoopMode, state: f64) -> PlantLink {
        PlantLink::new_at(
            clock.0,
            mode,
            LinkTimeouts {
                state,
                reconnect: 0.0,
                startup: 0.05,
            },
        )
    }

    #[test]
    fn new_steps_control_repeats_idle_and_a_step_back_or_new_session_restarts() {
        let c = Clock::new();
        let mut l = link(&c, LoopMode::Lockstep, 10.0);
        let now = c.0;
        let alive = || true;
        assert_eq!(l.classify_at(now, None, alive), Verdict::Idle);
        assert_eq!(
            l.classify_at(now, Some(&state(0, 7)), alive),
            Verdict::Control { restarted: false }
        );
        assert_eq!(l.classify_at(now, Some(&state(0, 7)), alive), Verdict::Idle);
        assert_eq!(l.counts.stale_states, 1, "a repeated state in lockstep");
        assert_eq!(
            l.classify_at(now, Some(&state(1, 7)), alive),
            Verdict::Control { restarted: false }
        );
        assert_eq!(
            l.classify_at(now, Some(&state(0, 7)), alive),
            Verdict::Control { restarted: true }
        );
        assert_eq!(
            l.classify_at(now, Some(&state(5, 9)), alive),
            Verdict::Control { restarted: true }
        );
        assert_eq!(
            (l.counts.reconnects, l.session(), l.last_step()),
            (2, 9, Some(5))
        );
    }

    #[test]
    fn silence_damps_in_real_time_and_ends_lockstep_only_when_the_plant_is_gone() {
        let mut c = Clock::new();
        let mut rt = link(&c, LoopMode::Realtime, 0.001);
        rt.classify_at(c.0, Some(&state(3, 1)), || true);
        // Within the state timeout: not yet silence.
        assert_eq!(rt.classify_at(c.advance(1), None, || true), Verdict::Idle);
        assert_eq!(rt.counts.stale_periods, 0);
        assert_eq!(
            rt.classify_at(c.advance(1), None, || true),
            Verdict::Damp { step: 3 }
        );
        assert_eq!(
            rt.classify_at(c.advance(1), None, || true),
            Verdict::Damp { step: 3 }
        );
        assert_eq!(
            rt.counts.stale_periods, 1,
            "one period, however many passes"
        );
        let mut ls = link(&c, LoopMode::Lockstep, 0.001);
        ls.classify_at(c.0, Some(&state(3, 1)), || true);
        // Past the state timeout but the plant is alive: waited for, liveness asked.
        let mut asked = false;
        assert_eq!(
            ls.classify_at(c.advance(2), None, || {
                asked = true;
                true
            }),
            Verdict::Idle,
            "alive: waited for"
        );
        assert!(asked, "the plant's liveness is asked once silent");
        // Asked at most every 100 ms: a dead plant 50 ms later is not yet noticed ...
        let mut asked = false;
        assert_eq!(
            ls.classify_at(c.advance(50), None, || {
                asked = true;
                false
            }),
            Verdict::Idle
        );
        assert!(!asked, "liveness asked again within 100 ms");
        // ... and is, once 100 ms have passed since the last question.
        assert_eq!(ls.classify_at(c.advance(60), None, || false), Verdict::Gone);
        // Back: the period ends and the gap (112 ms) is measured.
        assert_eq!(
            ls.classify_at(c.0, Some(&state(4, 1)), || true),
            Verdict::Control { restarted: false }
        );
        assert!(
            (ls.counts.longest_state_gap - 0.112).abs() < 1e-9,
            "{}",
            ls.counts.longest_state_gap
        );
    }

    /// A lost answer must not deadlock lockstep: the plant resends the state it waits on, and
    /// past `state_timeout` the link says to answer it again (once per timeout).
    #[test]
    fn a_state_still_resent_after_its_answer_is_answered_again() {
        let mut c = Clock::new();
        let mut l = link(&c, LoopMode::Lockstep, 0.05);
        let alive = || true;
        assert_eq!(
            l.classify_at(c.0, Some(&state(3, 1)), alive),
            Verdict::Control { restarted: false }
        );
        l.answered_at(c.advance(5));
        assert_eq!(
            l.classify_at(c.advance(49), Some(&state(3, 1)), alive),
            Verdict::Idle,
            "within the timeout of the answer"
        );
        assert_eq!(
            l.classify_at(c.advance(2), Some(&state(3, 1)), alive),
            Verdict::Reanswer { step: 3 }
        );
        assert_eq!(l.classify_at(c.0, Some(&state(3, 1)), alive), Verdict::Idle);
        assert_eq!(l.counts.reanswers, 1);
        // Silence (no state at all) is not a resend: waited for, never answered again.
        assert_eq!(l.classify_at(c.advance(60), None, alive), Verdict::Idle);
        assert_eq!(l.counts.reanswers, 1);
    }

    #[test]
    fn no_state_at_all_is_reported_after_the_startup_timeout() {
        let mut c = Clock::new();
        let mut l = link(&c, LoopMode::Lockstep, 1.0);
        assert_eq!(l.classify_at(c.advance(50), None, || true), Verdict::Idle);
        assert_eq!(
            l.classify_at(c.advance(1), None, || true),
            Verdict::NeverStarted
        );
    }
}
