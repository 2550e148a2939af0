//! Settings of the control loop's parts (`[controller.realtime]`, `[controller.forecast_correction]`,
//! `[controller.com_observer]`): plain data that the config reads and validates, and that
//! `crate::control` uses.

use serde::Deserialize;

/// `[controller.realtime]` settings.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealtimeSettings {
    /// SCHED_FIFO priority (1–99) of the control thread; 0 keeps the default scheduler.
    pub fifo_priority: i32,
    /// mlockall(MCL_CURRENT | MCL_FUTURE): no page faults on the control path.
    pub lock_memory: bool,
    /// CPU to pin the control thread to; none if absent.
    pub cpu: Option<usize>,
}

/// `[controller.forecast_correction]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectionSettings {
    /// Correct the forecast (C1, C2); off: the forecast as received.
    pub enabled: bool,
    /// Length W of the estimation window (s).
    pub window: f64,
    /// Largest |τ| searched (s).
    pub max_shift: f64,
    /// σ: standard deviation of one measured force sample (N), the estimation's noise model.
    pub force_noise: f64,
    /// ε: the part of the force no amplitude and shift explain (the door's and the arm's own
    /// dynamics), relative to the forecast's RMS over the window; adds (ε·RMS)² to a bin's
    /// variance.
    pub model_error: f64,
    /// A window whose forecast RMS (at τ̂) is below this (N) never becomes the estimator's
    /// memory: the tail of a push says little about its amplitude.
    pub min_force: f64,
    /// σ_κ: how far κ may plausibly be from its prior mean (1, or the last estimate).
    pub factor_sd: f64,
    /// σ_τ: how far τ may plausibly be from its prior mean (0, or the last estimate), s.
    pub shift_sd: f64,
    /// σ_b: how far the window's offset may be from the offset observer's estimate (N).
    pub offset_sd: f64,
    /// Bounds of κ̂.
    pub factor_bounds: [f64; 2],
    /// Time constant (s) with which the priors return to κ = 1, τ = 0 without evidence.
    pub forget: f64,
    /// Time constant T_o of the offset observer (s).
    pub offset_time_constant: f64,
    /// Time constant T_d of the offset's decay over the horizon (s).
    pub offset_decay: f64,
    /// |κ̂ − 1| beyond this, with the window's evidence, is a contradicted forecast.
    pub contradiction: f64,
    /// The corrected horizon's upward force is capped at this fraction of the robot's weight
    /// M g: the hand force of a robot tipping over (or a biased sensor) must not preview as a
    /// force lifting it (eq. (10) needs M g − F_z > 0), which the forecast intake refuses too.
    pub max_lift: f64,
}

impl Default for CorrectionSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            window: 0.3,
            max_shift: 0.35,
            force_noise: 2.0,
            model_error: 0.15,
            min_force: 5.0,
            factor_sd: 2.0,
            shift_sd: 0.05,
            offset_sd: 3.0,
            factor_bounds: [0.0, 3.0],
            forget: 3.0,
            offset_time_constant: 0.05,
            offset_decay: 0.3,
            contradiction: 0.5,
            max_lift: 0.5,
        }
    }
}

impl CorrectionSettings {
    /// Why the settings are unusable, if they are: (key, reason).
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, v) in [
            ("window", self.window),
            ("force_noise", self.force_noise),
            ("model_error", self.model_error),
            ("min_force", self.min_force),
            ("factor_sd", self.factor_sd),
            ("shift_sd", self.shift_sd),
            ("offset_sd", self.offset_sd),
            ("forget", self.forget),
            ("offset_time_constant", self.offset_time_constant),
            ("offset_decay", self.offset_decay),
            ("contradiction", self.contradiction),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        if !(self.max_shift.is_finite() && self.max_shift >= 0.0) {
            return Err(("max_shift", format!("must be ≥ 0, got {}", self.max_shift)));
        }
        if !(self.max_lift > 0.0 && self.max_lift < 1.0) {
            return Err((
                "max_lift",
                format!("must be in (0, 1), got {}", self.max_lift),
            ));
        }
        let [lo, hi] = self.factor_bounds;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) {
            return Err(("factor_bounds", format!("need 0 ≤ lo < hi, got {lo}, {hi}")));
        }
        Ok(())
    }
}

/// `[controller.com_observer]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComObserverSettings {
    /// Estimate and preview pushes on the CoM that nothing forecasts (C0, C1, C2).
    pub enabled: bool,
    /// Bandwidth of the observer (Hz).
    pub bandwidth: f64,
    /// Damping ratio of its error dynamics.
    pub damping: f64,
    /// Time constant of the estimate's decay over the horizon (s).
    pub decay: f64,
    /// Largest force the estimate may take, per axis (N): a tipping foot breaks eq. (OB-1).
    pub max_force: f64,
}

impl Default for ComObserverSettings {
    fn default() -> Self {
        Self {
            enabled: false,
            bandwidth: 5.0,
            damping: 1.0,
            decay: 0.3,
            max_force: 300.0,
        }
    }
}

impl ComObserverSettings {
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, v) in [
            ("bandwidth", self.bandwidth),
            ("damping", self.damping),
            ("decay", self.decay),
            ("max_force", self.max_force),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        Ok(())
    }
}
