//! Settings of the control loop's parts (`[controller.realtime]`, `[controller.forecast_correction]`,
//! `[controller.com_observer]`): plain data that the config reads and validates, and that
//! `crate::control` uses.

use serde::Deserialize;

/// `[controller.realtime]` settings.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
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
    fn default() -> Self {
        Self {
            enabled: true,
            window: 0.3,
            max_shift: 0.35,
            force_noise: 2.0,
            model_error: 0.15,
            min_force: 5.0,
            factor_sd: 2.0,
            shift_sd: 0.3,
            offset_sd: 3.0,
            factor_bounds: [0.0, 3.0],
            forget: 3.0,
            offset_time_constant: 0.05,
            offset_decay: 0.6,
            trend_window: 0.05,
            trend_horizon: 0.25,
            contradiction: 0.5,
            max_lift: 0.5,
            skill_time: 0.3,
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

/// `[controller.viability]`: the capture-point guard on unconfirmed forecasts
/// (`control::viability`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViabilitySettings {
    /// Fade the forecast's unmeasured part as the capture point nears an edge (C1, C2).
    pub enabled: bool,
    /// Distance to the nearer support edge (fraction of the half-length) at which the
    /// unmeasured forecast is gone.
    pub margin: f64,
    /// Width of the fade (fraction of the half-length) beyond the margin.
    pub band: f64,
    /// The margin for a forecast easing the measured push (VG-3): the robot eases off the push
    /// before it does, and the edge at risk is the one the push drives it toward if it does not
    /// ease. Negative (the default: it costs the 0.3 s impact's κ × τ map up to a quarter,
    /// docs/forecast_correction.md): easing is never faded.
    pub ease_margin: f64,
}

impl Default for ViabilitySettings {
    fn default() -> Self {
        Self {
            enabled: true,
            margin: 0.35,
            band: 0.1,
            ease_margin: -1.0,
        }
    }
}

impl ViabilitySettings {
    /// Why the settings are unusable, if they are: (key, reason).
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(0.0..1.0).contains(&self.margin) {
            return Err(("margin", format!("must be in [0, 1), got {}", self.margin)));
        }
        if !(self.ease_margin.is_finite() && self.ease_margin < 1.0) {
            return Err((
                "ease_margin",
                format!("must be finite and < 1, got {}", self.ease_margin),
            ));
        }
        if !(self.band.is_finite() && self.band > 0.0) {
            return Err(("band", format!("must be finite and > 0, got {}", self.band)));
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

/// `[controller.wrist_tare]`: the wrist sensor's offset, taken while the hand is unloaded
/// (`control::wrist_tare`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WristTareSettings {
    /// Quiet time averaged (s) at the start of each plant session; 0: no tare.
    pub duration: f64,
    /// Largest offset taken (N): a larger average is a load, and is refused.
    pub max_offset: f64,
}

impl Default for WristTareSettings {
    fn default() -> Self {
        Self {
            duration: 0.3,
            max_offset: 10.0,
        }
    }
}

impl WristTareSettings {
    pub fn check(&self) -> Result<(), (&'static str, String)> {
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

/// When the base estimator runs (`controller.estimator.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorMode {
    /// When the plant's states say it does not measure its base (`STATE_FLAG_BASE_UNMEASURED`).
    Auto,
    /// Always, also over a measured base (to check the estimate against it).
    On,
    /// Never: a plant that does not measure its base is refused, tick by tick.
    Off,
}

/// `[controller.estimator]`: the floating-base estimator (docs/estimation.md).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSettings {
    pub mode: EstimatorMode,
    /// A foot carrying more than this fraction of the robot's weight is a stance foot.
    pub contact_load: f64,
    /// σ of the accelerometer's error in the prediction (m/s²): noise, bias, vibration.
    pub accel_noise: f64,
    /// How fast a stance foot may creep (m/√s); a swing foot is free.
    pub foot_drift: f64,
    /// σ of a foot's position relative to the base from the leg's kinematics (m).
    pub kinematics_noise: f64,
    /// σ of the base velocity from a stance leg's kinematics (m/s).
    pub velocity_noise: f64,
    /// Cut-off of the joint velocities' first-order low-pass (Hz; 0: unfiltered).
    pub joint_velocity_cutoff: f64,
    /// Bound of a tick's normalised innovation (χ² of the stance feet's measurements) beyond
    /// which the tick disagrees with the filter (a slipping foot, a bad sensor).
    pub innovation_limit: f64,
    /// Consecutive disagreeing ticks that declare the estimate diverged (it is restarted).
    pub divergence_ticks: u32,
    /// An IMU sample older than this (s) is lost: the tick is refused (damping torques).
    pub imu_timeout: f64,
    /// Time constant (s) of the IMU's tilt correction from the soles of two flat stance feet
    /// (docs/estimation.md, EST-5); 0: the IMU's attitude as given.
    pub tilt_time: f64,
    /// Time constant (s) of the gyro's bias estimate against the attitude filter's rate
    /// (EST-6); 0: the gyro as given.
    pub gyro_bias_time: f64,
}

impl Default for EstimatorSettings {
    fn default() -> Self {
        Self {
            mode: EstimatorMode::Auto,
            contact_load: 0.1,
            accel_noise: 0.5,
            foot_drift: 1e-3,
            kinematics_noise: 2e-3,
            velocity_noise: 0.03,
            joint_velocity_cutoff: 0.0,
            innovation_limit: 200.0,
            divergence_ticks: 50,
            imu_timeout: 0.1,
            tilt_time: 1.0,
            gyro_bias_time: 0.0,
        }
    }
}

impl EstimatorSettings {
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, v) in [
            ("accel_noise", self.accel_noise),
            ("foot_drift", self.foot_drift),
            ("kinematics_noise", self.kinematics_noise),
            ("velocity_noise", self.velocity_noise),
            ("innovation_limit", self.innovation_limit),
            ("imu_timeout", self.imu_timeout),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        if !(self.contact_load > 0.0 && self.contact_load < 1.0) {
            return Err((
                "contact_load",
                format!("must be in (0, 1), got {}", self.contact_load),
            ));
        }
        if !(self.joint_velocity_cutoff.is_finite() && self.joint_velocity_cutoff >= 0.0) {
            return Err((
                "joint_velocity_cutoff",
                format!("must be ≥ 0, got {}", self.joint_velocity_cutoff),
            ));
        }
        for (key, v) in [
            ("tilt_time", self.tilt_time),
            ("gyro_bias_time", self.gyro_bias_time),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((key, format!("must be ≥ 0, got {v}")));
            }
        }
        if self.divergence_ticks == 0 {
            return Err(("divergence_ticks", "must be ≥ 1".into()));
        }
        Ok(())
    }
}
