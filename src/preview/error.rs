//! Bad inputs to the preview controllers are values, never panics or silent clamps.

/// What went wrong in a preview solve; each names the offending horizon step where one exists.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PreviewError {
    #[error("{what} forecast has {got} samples, the horizon needs {need}")]
    ForecastTooShort {
        what: &'static str,
        got: usize,
        need: usize,
    },
    #[error("{what} is not finite at horizon step {step}")]
    NotFinite { what: &'static str, step: usize },
    #[error(
        "CoM disturbance lifts the robot at horizon step {step}: M g − F_z = {margin:.3} N ≤ 0 \
         (F_z = {f_z:.3} N); the forecast is invalid"
    )]
    LiftOff { step: usize, f_z: f64, margin: f64 },
    #[error("horizon {got} exceeds the workspace capacity {capacity}")]
    HorizonTooLong { got: usize, capacity: usize },
    #[error("hand effective mass M_e is not symmetric positive definite")]
    EffectiveMassNotSpd,
    #[error(
        "gain at horizon step {step} is outside its bounds or not finite: K_p = {kp}, K_d = {kd}"
    )]
    BadGain { step: usize, kp: f64, kd: f64 },
    #[error("ZMP-constrained QP failed: {0}")]
    Qp(String),
}
