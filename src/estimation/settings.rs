//! `[controller.base_estimation]`: when the base estimator runs and its noise model
//! (docs/estimation.md).

use serde::{Deserialize, Serialize};

/// When the base estimator runs (`controller.base_estimation.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorMode {
    /// When the plant's states say it does not measure its base (`STATE_FLAG_BASE_UNMEASURED`).
    Auto,
    /// Always, also over a measured base (to check the estimate against it).
    On,
    /// Never: a plant that does not measure its base is refused, tick by tick.
    Off,
}

/// `[controller.base_estimation]`: the floating-base estimator (docs/estimation.md).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
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
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for EstimatorSettings {
    const TABLE: &'static str = "base_estimation";

    fn check(&self) -> Result<(), (&'static str, String)> {
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
