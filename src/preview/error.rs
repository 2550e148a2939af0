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
    #[error(
        "the {horizon}-step ({seconds:.2} s) preview without a terminal cost does not hold this \
         robot's CoM ({com_height:.2} m high): its receding-horizon loop has spectral radius \
         {radius:.5} ≥ 1, and an offset CoM drifts away until the robot falls. Set \
         preview.terminal_cost = true (the default){}",
        .stable_from.map_or(String::new(), |n| format!(", or preview.horizon ≥ {n}"))
    )]
    UnstableHorizon {
        horizon: usize,
        seconds: f64,
        com_height: f64,
        radius: f64,
        stable_from: Option<usize>,
    },
}
