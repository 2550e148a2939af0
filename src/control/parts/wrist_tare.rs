//! The wrist force sensor's offset, taken while the hand is known to be unloaded (a tare), and
//! removed from every measured hand force the controller uses.
//!
//! Why: the whole-body QP feeds the measured hand force back (eq. 23 holds on the arm), so
//! the hand renders any sensor offset b as a real push: against the door, which resists no
//! static force along its swing, the hand drifts by ≈ b / K_p before the first push, and the
//! arm meets the push extended and at its torque limits. With the other sensors exact, a 2 N
//! offset alone toppled C2 on `multiple_impacts` (docs/sensing.md, "The wrist's offset"). A
//! robot's stack zeroes its F/T sensors before a contact task for the same reason.
//!
//! The tare averages the measured force over `duration` seconds of ticks in which the
//! forecast announces (almost) no force and the hand is (almost) at rest, from the start of
//! each plant session. An average larger than `max_offset` is not a sensor offset but a load
//! (a held weight, a push the forecast missed): it is refused, counted, and nothing is removed.
//! What the tare cannot remove is the sensor's drift after it (and its noise).

use serde::{Deserialize, Serialize};

use crate::control::frame::TickFrame;
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::record::Record;

/// Ticks count toward the tare only while the forecast's force is below this (N)...
const QUIET_FORCE: f64 = 1.0;
/// ... and the hand moves slower than this (m/s).
const QUIET_SPEED: f64 = 0.05;
/// The tare is taken only in the task's first second (its clock: [`RobotState::task_time`](crate::robot::RobotState)): a controller
/// that joins a running task (restarted mid-task) meets a hand already at work, and skips it.
const TARE_BEFORE: f64 = 1.0;

/// The tare's state: accumulating, taken, or refused.
#[derive(Debug, Clone)]
pub struct WristTare {
    settings: WristTareSettings,
    sum: [f64; 3],
    /// Quiet time accumulated (s).
    quiet: f64,
    offset: [f64; 3],
    state: TareState,
    refusals: u64,
}

/// Where the tare of the current session stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TareState {
    /// Averaging quiet ticks (or disabled: `duration` = 0 never leaves it and removes nothing).
    Pending,
    /// The offset is removed from every measured force.
    Taken,
    /// The average was beyond `max_offset`: nothing is removed this session.
    Refused,
    /// The task's first second passed without enough quiet ticks (a controller that joined a
    /// running task): nothing is removed.
    Skipped,
}

impl WristTare {
    pub fn new(settings: WristTareSettings) -> Self {
        Self {
            settings,
            sum: [0.0; 3],
            quiet: 0.0,
            offset: [0.0; 3],
            state: TareState::Pending,
            refusals: 0,
        }
    }

    /// A new plant session: the tare is taken again.
    pub fn reset(&mut self) {
        self.sum = [0.0; 3];
        self.quiet = 0.0;
        self.offset = [0.0; 3];
        self.state = TareState::Pending;
    }

    /// The measured force less the offset; accumulates the tare while it is pending. `t`: the
    /// task's time (`RobotState::task_time`; s); `dt`: the tick's period (s); `expected`: the forecast's force now;
    /// `hand_speed` (m/s); `held`: the plant holds the robot (its hold loads the hand as it
    /// pleases: not quiet). A non-finite measurement is returned as it is (the callers refuse
    /// it) and not accumulated.
    pub fn apply(
        &mut self,
        t: Option<f64>,
        measured: [f64; 3],
        expected: [f64; 3],
        hand_speed: f64,
        held: bool,
        dt: f64,
    ) -> [f64; 3] {
        let finite = measured.iter().all(|x| x.is_finite());
        if self.state == TareState::Pending && self.enabled() && t.is_some_and(|t| t >= TARE_BEFORE)
        {
            self.state = TareState::Skipped;
        }
        if self.state == TareState::Pending && self.settings.duration > 0.0 && finite {
            let quiet = !held && norm(expected) < QUIET_FORCE && hand_speed < QUIET_SPEED;
            if quiet {
                for k in 0..3 {
                    self.sum[k] += measured[k] * dt;
                }
                self.quiet += dt;
                // Half a tick early: `duration` / dt ticks, whatever the rounding of the sum.
                if self.quiet >= self.settings.duration - 0.5 * dt {
                    self.finish();
                }
            }
        }
        [0, 1, 2].map(|k| measured[k] - self.offset[k])
    }

    fn finish(&mut self) {
        let mean = self.sum.map(|s| s / self.quiet);
        if norm(mean) <= self.settings.max_offset {
            self.offset = mean;
            self.state = TareState::Taken;
        } else {
            self.state = TareState::Refused;
            self.refusals += 1;
        }
    }

    /// The offset removed (N; zero unless taken).
    pub fn offset(&self) -> [f64; 3] {
        self.offset
    }

    /// Whether the measured force, less [`WristTare::offset`], is a force and not partly a
    /// sensor offset: not while the tare is pending (the hand would yield to the offset being
    /// measured and load the door, which the tare would then take for the offset), nor after a
    /// refused one (a constant the controller cannot tell from a push: an 8 N-per-axis offset
    /// fed back toppled C1; docs/sensing.md). What may be fed back to the whole-body QP.
    pub fn trusted(&self) -> bool {
        !(self.enabled() && matches!(self.state, TareState::Pending | TareState::Refused))
    }

    /// Whether a tare is taken at all (`duration` > 0).
    pub fn enabled(&self) -> bool {
        self.settings.duration > 0.0
    }

    pub fn state(&self) -> TareState {
        self.state
    }

    /// Tares refused over the controller's life (a load larger than `max_offset`).
    pub fn refusals(&self) -> u64 {
        self.refusals
    }
}

impl PartKind for WristTare {
    type Settings = WristTareSettings;

    fn build(
        _: &PartSetup,
        settings: WristTareSettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        Ok(Box::new(WristTare::new(settings)))
    }
}

impl ControllerPart for WristTare {
    fn name(&self) -> &'static str {
        "wrist_tare"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Measure]
    }

    fn reset(&mut self) {
        WristTare::reset(self);
    }

    /// The offset removed from the hand force, and whether the force may be fed back.
    fn update(
        &mut self,
        _: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let before = self.state;
        let sensed = inputs.sensed;
        let (t, dt) = (frame.t, frame.dt);
        let hand = frame.hand_mut();
        self.apply(
            sensed.task_time,
            hand.force_used(&sensed.hand_force),
            inputs.forecast.at(t),
            nalgebra::Vector3::from(hand.vel).norm(),
            sensed.held,
            dt,
        );
        for k in 0..3 {
            hand.offset[k] += self.offset[k];
        }
        hand.vouch(self.trusted());
        if self.state != before {
            self.log_transition(t);
        }
        Ok(())
    }

    fn record(&self, _out: &mut Record) {}

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        out.insert("wrist_tare_offset".into(), serde_json::json!(self.offset));
        out.insert(
            "wrist_tare_refusals".into(),
            serde_json::json!(self.refusals),
        );
    }
}

impl WristTare {
    /// Says what the tare did, once per change (the loop's diagnostics never block it).
    fn log_transition(&self, t: f64) {
        let b = self.offset;
        match self.state {
            TareState::Taken => tracing::info!(
                "wrist tared at t = {t:.3} s: offset ({:.2}, {:.2}, {:.2}) N removed from the measured hand force",
                b[0],
                b[1],
                b[2]
            ),
            TareState::Refused => tracing::warn!(
                "wrist tare refused at t = {t:.3} s: the quiet hand measures more than \
                 controller.wrist_tare.max_offset (a load, or an offset too large to be one); \
                 the hand force is not fed back to the whole-body QP this session"
            ),
            TareState::Skipped => tracing::info!(
                "wrist tare skipped: no quiet second at the task's start (a controller that \
                 joined a running task); the measured hand force is used as it is"
            ),
            TareState::Pending => {}
        }
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `[controller.wrist_tare]`: the wrist sensor's offset, taken while the hand is unloaded
/// (`control::parts::wrist_tare`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WristTareSettings {
    /// Quiet time averaged (s) at the start of each plant session; 0: no tare.
    pub duration: f64,
    /// Largest offset taken (N): a larger average is a load, and is refused.
    pub max_offset: f64,
}

impl Default for WristTareSettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for WristTareSettings {
    const TABLE: &'static str = "wrist_tare";

    fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.duration.is_finite() && self.duration >= 0.0) {
            return Err((
                "duration",
                format!("must be finite and ≥ 0, got {}", self.duration),
            ));
        }
        if !(self.max_offset.is_finite() && self.max_offset > 0.0) {
            return Err((
                "max_offset",
                format!("must be finite and > 0, got {}", self.max_offset),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::contract::task_time;

    fn tare(duration: f64) -> WristTare {
        WristTare::new(WristTareSettings {
            duration,
            max_offset: 10.0,
        })
    }

    #[test]
    fn the_offset_of_quiet_ticks_is_removed_after_the_duration() {
        let mut t = tare(0.1);
        let bias = [2.0, -1.5, 0.5];
        // Noise that averages out over the window: ± 0.5 N alternating.
        for k in 0..99 {
            let s = if k % 2 == 0 { 0.5 } else { -0.5 };
            let out = t.apply(Some(0.0), bias.map(|b| b + s), [0.0; 3], 0.0, false, 1e-3);
            assert_eq!(out, bias.map(|b| b + s), "nothing removed while pending");
        }
        assert_eq!(t.state(), TareState::Pending);
        t.apply(Some(0.0), bias.map(|b| b + 0.5), [0.0; 3], 0.0, false, 1e-3);
        assert_eq!(t.state(), TareState::Taken);
        for k in 0..3 {
            assert!((t.offset()[k] - bias[k]).abs() < 0.02, "{:?}", t.offset());
        }
        let out = t.apply(
            Some(0.0),
            [12.0, -1.5, 0.5],
            [10.0, 0.0, 0.0],
            0.0,
            false,
            1e-3,
        );
        assert!(
            (out[0] - 10.0).abs() < 0.02 && out[1].abs() < 0.02,
            "{out:?}"
        );
    }

    #[test]
    fn forecast_pushes_and_a_moving_hand_do_not_count_and_a_load_is_refused() {
        let mut t = tare(0.01);
        // A forecast push and a moving hand: their ticks are not the sensor's offset.
        for _ in 0..100 {
            t.apply(
                Some(0.0),
                [30.0, 0.0, 0.0],
                [30.0, 0.0, 0.0],
                0.0,
                false,
                1e-3,
            );
            t.apply(Some(0.0), [30.0, 0.0, 0.0], [0.0; 3], 0.2, false, 1e-3);
        }
        assert_eq!(t.state(), TareState::Pending);
        // The plant's hold: its ticks are not quiet either.
        for _ in 0..100 {
            t.apply(Some(0.0), [0.0, 0.0, -5.0], [0.0; 3], 0.0, true, 1e-3);
        }
        assert_eq!(t.state(), TareState::Pending);
        // A quiet hand holding 20 N: a load, not an offset.
        for _ in 0..10 {
            t.apply(Some(0.0), [0.0, 0.0, -20.0], [0.0; 3], 0.0, false, 1e-3);
        }
        assert_eq!(t.state(), TareState::Refused);
        assert!(!t.trusted(), "a refused tare's force is not fed back");
        assert_eq!(t.refusals(), 1);
        assert_eq!(
            t.apply(Some(0.0), [0.0, 0.0, -20.0], [0.0; 3], 0.0, false, 1e-3),
            [0.0, 0.0, -20.0]
        );
        t.reset();
        assert_eq!(t.state(), TareState::Pending);
    }

    #[test]
    fn a_controller_joining_a_running_session_skips_the_tare() {
        let mut t = tare(0.1);
        assert_eq!(
            t.apply(Some(3.0), [2.0; 3], [0.0; 3], 0.0, false, 1e-3),
            [2.0; 3]
        );
        assert_eq!(t.state(), TareState::Skipped);
    }

    #[test]
    fn the_task_clock_is_the_scenarios_and_waits_for_its_start() {
        // A real robot announces no scenario: its session is the task.
        assert_eq!(task_time(3.0, 0, -1.0), Some(3.0));
        // A real-time plant started its scenario at 1.2 s, when a controller took over.
        assert_eq!(task_time(1.5, 7, 1.2).map(|x| (x * 1e9).round()), Some(3e8));
        // Still holding the robot: the task has not started.
        assert_eq!(task_time(1.5, 7, -1.0), None);
    }

    #[test]
    fn a_controller_joining_during_the_start_up_hold_tares_after_it() {
        let mut t = tare(0.1);
        // The plant holds the robot a second into its session; the task has not started.
        for _ in 0..1000 {
            t.apply(None, [2.0; 3], [0.0; 3], 0.0, true, 1e-3);
        }
        assert_eq!(t.state(), TareState::Pending);
        // Handed over, the scenario starts: its first quiet ticks tare the wrist.
        for k in 0..100 {
            t.apply(Some(k as f64 * 1e-3), [2.0; 3], [0.0; 3], 0.0, false, 1e-3);
        }
        assert_eq!(t.state(), TareState::Taken);
        assert_eq!(
            t.apply(Some(0.2), [2.0; 3], [0.0; 3], 0.0, false, 1e-3),
            [0.0; 3]
        );
    }

    #[test]
    fn a_zero_duration_never_tares() {
        let mut t = tare(0.0);
        for _ in 0..1000 {
            assert_eq!(
                t.apply(Some(0.0), [2.0; 3], [0.0; 3], 0.0, false, 1e-3),
                [2.0; 3]
            );
        }
        assert_eq!(t.state(), TareState::Pending);
    }
}
