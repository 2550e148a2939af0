//! `[controller.forecast_correction]`: the correction's settings and their checks.

use serde::{Deserialize, Serialize};

/// `[controller.forecast_correction]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
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
    /// σ_v (m/s): the hand's velocity error while the base is estimated (its filter's velocity
    /// error, which the hand inherits); a measured base's is taken as exact. Sets FC-1c's K.
    pub hand_velocity_noise: f64,
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
    /// Length (s) of the window of the trend fit: a line through the last bins of what the
    /// forecast leaves unexplained (FC-3b).
    pub trend_window: f64,
    /// T_r (s): how far ahead the unexplained force's trend is extrapolated before it levels
    /// off (FC-4); 0 turns the trend off.
    pub trend_horizon: f64,
    /// |κ̂ − 1| beyond this, with the window's evidence, is a contradicted forecast.
    pub contradiction: f64,
    /// The corrected horizon's upward force is capped at this fraction of the robot's weight
    /// M g: the hand force of a robot tipping over (or a biased sensor) must not preview as a
    /// force lifting it (eq. (10) needs M g − F_z > 0), which the forecast intake refuses too.
    pub max_lift: f64,
    /// FC-5: the memory (s) of the forecast's and the measurement's prediction errors from which
    /// the forecast's weight is judged; 0 always believes the corrected forecast (w = 1).
    pub skill_time: f64,
}

impl Default for CorrectionSettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for CorrectionSettings {
    const TABLE: &'static str = "forecast_correction";

    fn check(&self) -> Result<(), (&'static str, String)> {
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
            ("trend_window", self.trend_window),
            ("contradiction", self.contradiction),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        for (key, v) in [
            ("max_shift", self.max_shift),
            ("trend_horizon", self.trend_horizon),
            ("skill_time", self.skill_time),
            ("hand_velocity_noise", self.hand_velocity_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((key, format!("must be finite and ≥ 0, got {v}")));
            }
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
