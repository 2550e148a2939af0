//! The CoM-disturbance horizon (docs/disturbance.md, eq. (10)–(16)): α0 shared by both axes, and
//! the ZMP shift D = z_c α per axis. Built from a force forecast, validated, into preallocated
//! storage.

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
        let forces = &forces[..horizon];
        // Loops over slices, none with an early exit or an index check, so that they vectorise
        // (the divisions are most of this per-tick O(N) work): the margins, their reciprocals
        // α0, then α; the results checked last (a bad sample leaves α0 ≤ 0 or a non-finite
        // value), and the first bad sample looked for only when there is one.
        let alpha0 = &mut self.alpha0[..horizon];
        for (a, f) in alpha0.iter_mut().zip(forces) {
            *a = weight - f[2];
        }
        for a in alpha0.iter_mut() {
            *a = 1.0 / *a;
        }
        let [ax, ay] = &mut self.alpha;
        let (ax, ay) = (&mut ax[..horizon], &mut ay[..horizon]);
        for (((x, y), f), a) in ax
            .iter_mut()
            .zip(ay.iter_mut())
            .zip(forces)
            .zip(alpha0.iter())
        {
            *x = f[0] * a;
            *y = f[1] * a;
        }
        let good = |a: f64, x: f64, y: f64| {
            (a > 0.0) & (a < f64::INFINITY) & (x.abs() < f64::INFINITY) & (y.abs() < f64::INFINITY)
        };
        let samples = || alpha0.iter().zip(ax.iter()).zip(ay.iter());
        if !samples().fold(true, |ok, ((&a, &x), &y)| ok & good(a, x, y))
            && let Some(i) = samples().position(|((&a, &x), &y)| !good(a, x, y))
        {
            let f = forces[i];
            let margin = weight - f[2];
            let a = alpha0[i];
            return Err(
                if f.iter().all(|v| v.is_finite()) && !(a > 0.0 && a < f64::INFINITY) {
                    // M g − F_z ≤ 0 (or so small that α0 overflows).
                    PreviewError::LiftOff {
                        step: i + 1,
                        f_z: f[2],
                        margin,
                    }
                } else {
                    PreviewError::NotFinite {
                        what: "CoM disturbance",
                        step: i + 1,
                    }
                },
            );
        }
        self.len = horizon;
        Ok(())
    }

    /// D_i = z_c α(k+i) for one axis (eq. 14).
    pub fn shift(&self, model: &CartTable, axis: usize, i: usize) -> f64 {
        shift_of(model, self.alpha[axis][i])
    }

    /// D_i for one axis, i = 0 … `len` − 1, as [`Disturbance::shift`] gives them.
    pub fn shifts<'a>(
        &'a self,
        model: &'a CartTable,
        axis: usize,
    ) -> impl Iterator<Item = f64> + 'a {
        self.alpha[axis][..self.len]
            .iter()
            .map(|&a| shift_of(model, a))
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

/// eq. (14): D = z_c α.
#[inline(always)]
fn shift_of(model: &CartTable, alpha: f64) -> f64 {
    model.com_height * alpha
}
