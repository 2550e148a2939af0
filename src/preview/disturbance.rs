//! The CoM-disturbance horizon of SPEC §3 (eq. 10–16): α0 shared by both axes, and the ZMP shift
//! D = z_c α per axis. Built from a force forecast, validated, into preallocated storage.

use super::{CartTable, PreviewError};

/// α0(k+i) and α(k+i), i = 1 … N, for one preview solve.
///
/// Indexing convention used by every horizon quantity in this module: sample `i` (0-based) is
/// the value at step k+1+i, the instant of the i-th predicted ZMP row of eq. (5).
#[derive(Debug, Clone)]
pub struct Disturbance {
    pub(crate) alpha0: Vec<f64>,
    pub(crate) alpha: [Vec<f64>; 2],
    len: usize,
}

impl Disturbance {
    /// Storage for horizons up to `capacity` steps.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            alpha0: vec![0.0; capacity],
            alpha: [vec![0.0; capacity], vec![0.0; capacity]],
            len: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// No disturbance: α0 = 1/(M g), α = 0 — Kajita's model (C0).
    pub fn set_none(&mut self, model: &CartTable, horizon: usize) -> Result<(), PreviewError> {
        self.check_capacity(horizon)?;
        self.len = horizon;
        self.alpha0[..horizon].fill(model.nominal_alpha0());
        self.alpha[0][..horizon].fill(0.0);
        self.alpha[1][..horizon].fill(0.0);
        Ok(())
    }

    /// From a 3-D CoM-disturbance forecast F_dis (N), sample i at step k+1+i.
    ///
    /// eq. (10): α0 = 1 / (M g − F_z), α = F_xy / (M g − F_z). `M g − F_z ≤ 0` means the robot
    /// would be lifted off: an invalid forecast, reported, never divided through.
    pub fn set_forces(
        &mut self,
        model: &CartTable,
        forces: &[[f64; 3]],
        horizon: usize,
    ) -> Result<(), PreviewError> {
        self.check_capacity(horizon)?;
        if forces.len() < horizon {
            return Err(PreviewError::ForecastTooShort {
                what: "CoM disturbance",
                got: forces.len(),
                need: horizon,
            });
        }
        let weight = model.mass * model.gravity;
        for (i, f) in forces[..horizon].iter().enumerate() {
            if !f.iter().all(|v| v.is_finite()) {
                return Err(PreviewError::NotFinite {
                    what: "CoM disturbance",
                    step: i + 1,
                });
            }
            let margin = weight - f[2];
            if margin <= 0.0 {
                return Err(PreviewError::LiftOff {
                    step: i + 1,
                    f_z: f[2],
                    margin,
                });
            }
            let alpha0 = 1.0 / margin;
            self.alpha0[i] = alpha0;
            self.alpha[0][i] = f[0] * alpha0;
            self.alpha[1][i] = f[1] * alpha0;
        }
        self.len = horizon;
        Ok(())
    }

    /// D_i = z_c α(k+i) for one axis (eq. 14).
    pub fn shift(&self, model: &CartTable, axis: usize, i: usize) -> f64 {
        model.com_height * self.alpha[axis][i]
    }

    fn check_capacity(&self, horizon: usize) -> Result<(), PreviewError> {
        if horizon > self.alpha0.len() {
            return Err(PreviewError::HorizonTooLong {
                got: horizon,
                capacity: self.alpha0.len(),
            });
        }
        Ok(())
    }
}
