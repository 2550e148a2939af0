//! Hand impedance previewer (docs/hand_previewer.md, eq. (17), (23)–(25)): the hand under the
//! operational-space impedance law and a known external force, over the horizon, and the equivalent
//! CoM disturbance the body feels.
//!
//! Choices, written down:
//! - The J̇_e J_e† velocity term of eq. (23)–(25) is neglected (docs/hand_previewer.md): over
//!   a 1.5 s horizon the chest→hand configuration barely changes while the hand holds the door.
//! - eq. (24) is read as a semi-implicit step: position and velocity advance with the cart-table
//!   A, then the acceleration at k+1 is the impedance law evaluated at the new position and
//!   velocity, with the gains, desired state and force of step k+1.
//! - A held door keeps the hand on its path (HP-1, docs/hand_previewer.md): the hand moves along
//!   the path's direction e only, carrying the leaf's mass m, and the hinge takes what the
//!   impedance pushes across e. F_dis (eq. (25)) is then the force the door really passes,
//!   across e as well.

use nalgebra::{Matrix3, Vector3};

use super::PreviewError;

/// Position, velocity and acceleration of the hand (m, world-aligned axes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HandState {
    pub pos: Vector3<f64>,
    pub vel: Vector3<f64>,
    pub acc: Vector3<f64>,
}

/// Impedance gains over the horizon; sample i applies at step k+1+i. K_p, K_d are shared by
/// the three axes (K_e = K_p M_e, C_e = K_d M_e).
#[derive(Debug, Clone, PartialEq)]
pub struct GainSchedule {
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
}

impl GainSchedule {
    pub fn constant(n: usize, kp: f64, kd: f64) -> Self {
        Self {
            kp: vec![kp; n],
            kd: vec![kd; n],
        }
    }

    pub fn len(&self) -> usize {
        self.kp.len().min(self.kd.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The previewer with its preallocated horizon buffers.
#[derive(Debug, Clone)]
pub struct HandPreviewer {
    period: f64,
    m_e: Matrix3<f64>,
    m_e_inv: Matrix3<f64>,
    states: Vec<HandState>,
    f_dis: Vec<[f64; 3]>,
    len: usize,
    /// The held object's path (HP-1): e and the object's mass m along it; `None`: free in space.
    held: Option<(Vector3<f64>, f64)>,
    /// HP-1's s̈ = a·F_ext + b·ẍ_cmd: a = e / d, b = M_e e / d, d = eᵀ M_e e + m.
    path_force: Vector3<f64>,
    path_cmd: Vector3<f64>,
}

impl HandPreviewer {
    pub fn new(period: f64, m_e: Matrix3<f64>, capacity: usize) -> Result<Self, PreviewError> {
        let mut p = Self {
            period,
            m_e: Matrix3::identity(),
            m_e_inv: Matrix3::identity(),
            states: vec![HandState::default(); capacity],
            f_dis: vec![[0.0; 3]; capacity],
            len: 0,
            held: None,
            path_force: Vector3::zeros(),
            path_cmd: Vector3::zeros(),
        };
        p.set_effective_mass(m_e)?;
        Ok(p)
    }

    /// Update M_e (the controller recomputes it from the configuration every tick).
    pub fn set_effective_mass(&mut self, m_e: Matrix3<f64>) -> Result<(), PreviewError> {
        let symmetric = (m_e - m_e.transpose()).abs().max() <= 1e-9 * (1.0 + m_e.abs().max());
        let chol = m_e
            .cholesky()
            .filter(|_| symmetric && m_e.iter().all(|v| v.is_finite()));
        let chol = chol.ok_or(PreviewError::EffectiveMassNotSpd)?;
        self.m_e = m_e;
        self.m_e_inv = chol.inverse();
        self.update_path();
        Ok(())
    }

    /// Keep the hand on a held object's path (HP-1): `Some((e, m))`, e the path's unit
    /// direction (world) and m the object's mass along it (0: its inertia left out); `None`:
    /// free in space, eq. (24).
    pub fn set_held_path(&mut self, path: Option<(Vector3<f64>, f64)>) {
        self.held =
            path.filter(|(e, m)| (e.norm() - 1.0).abs() < 1e-9 && m.is_finite() && *m >= 0.0);
        self.update_path();
    }

    /// HP-1's coefficients for the current M_e and path.
    fn update_path(&mut self) {
        if let Some((e, m)) = self.held {
            let me = self.m_e * e;
            let d = e.dot(&me) + m;
            self.path_force = e / d;
            self.path_cmd = me / d;
        }
    }

    pub fn effective_mass(&self) -> &Matrix3<f64> {
        &self.m_e
    }

    pub fn period(&self) -> f64 {
        self.period
    }

    /// One step of eq. (24) from `x` with the gains, desired state and external force of the
    /// next step; returns the next state and the CoM disturbance F_dis of eq. (25) at that step.
    /// Always inlined: left out of line (as the codegen units' partition may decide) it doubled
    /// the previewer's cost in the C1 tick (perf, `control/c1_tick_phantom`).
    #[inline(always)]
    pub fn step(
        &self,
        x: &HandState,
        desired: &HandState,
        kp: f64,
        kd: f64,
        f_ext: &Vector3<f64>,
    ) -> (HandState, Vector3<f64>) {
        self.step_on(
            self.held.as_ref().map(|(e, _)| e),
            x,
            desired,
            kp,
            kd,
            f_ext,
        )
    }

    /// [`Self::step`] with the path given (`predict` reads it once, outside its loop).
    #[inline(always)]
    fn step_on(
        &self,
        path: Option<&Vector3<f64>>,
        x: &HandState,
        desired: &HandState,
        kp: f64,
        kd: f64,
        f_ext: &Vector3<f64>,
    ) -> (HandState, Vector3<f64>) {
        let t = self.period;
        let pos = x.pos + x.vel * t + x.acc * (t * t / 2.0);
        let vel = x.vel + x.acc * t;
        // eq. (17): the commanded operational-space acceleration of the impedance law.
        let cmd = (desired.pos - pos) * kp + (desired.vel - vel) * kd + desired.acc;
        let acc = match path {
            // eq. (23) without the J̇J† term: M_e ẍ = F_ext + M_e ẍ_cmd.
            None => cmd + self.m_e_inv * f_ext,
            // HP-1: ẍ = s̈ e, (eᵀ M_e e + m) s̈ = eᵀ F_ext + eᵀ M_e ẍ_cmd.
            Some(e) => e * (self.path_force.dot(f_ext) + self.path_cmd.dot(&cmd)),
        };
        // eq. (25): F_dis = −[K_e (x_des − x) + C_e (ẋ_des − ẋ) + M_e ẍ_des] = −M_e ẍ_cmd.
        let f_dis = -(self.m_e * cmd);
        (HandState { pos, vel, acc }, f_dis)
    }

    /// Predict the hand over `horizon` steps from `x0` and fill the F_dis forecast (samples at
    /// k+1…k+N). `desired`, `gains` and `f_ext` need at least `horizon` samples.
    pub fn predict(
        &mut self,
        x0: &HandState,
        desired: &[HandState],
        gains: &GainSchedule,
        f_ext: &[[f64; 3]],
        horizon: usize,
    ) -> Result<(), PreviewError> {
        if horizon > self.states.len() {
            return Err(PreviewError::HorizonTooLong {
                got: horizon,
                capacity: self.states.len(),
            });
        }
        for (what, got) in [
            ("desired hand", desired.len()),
            ("gain schedule", gains.len()),
            ("hand force", f_ext.len()),
        ] {
            if got < horizon {
                return Err(PreviewError::ForecastTooShort {
                    what,
                    got,
                    need: horizon,
                });
            }
        }
        let finite = |v: &Vector3<f64>| v.iter().all(|c| c.is_finite());
        if !(finite(&x0.pos) && finite(&x0.vel) && finite(&x0.acc)) {
            return Err(PreviewError::NotFinite {
                what: "hand state",
                step: 0,
            });
        }
        // Inputs checked in one pass, step by step (the first bad one reported), so that the
        // recursion below is a tight loop.
        for i in 0..horizon {
            let (kp, kd) = (gains.kp[i], gains.kd[i]);
            if !(kp.is_finite() && kd.is_finite() && kp > 0.0 && kd >= 0.0) {
                return Err(PreviewError::BadGain {
                    step: i + 1,
                    kp,
                    kd,
                });
            }
            if !f_ext[i].iter().all(|c| c.is_finite()) {
                return Err(PreviewError::NotFinite {
                    what: "hand force",
                    step: i + 1,
                });
            }
            let d = &desired[i];
            if !(finite(&d.pos) && finite(&d.vel) && finite(&d.acc)) {
                return Err(PreviewError::NotFinite {
                    what: "desired hand",
                    step: i + 1,
                });
            }
        }
        // Two loops, so that eq. (24)'s carries no test of the path per step.
        match self.held.map(|(e, _)| e) {
            None => self.roll(*x0, None, desired, gains, f_ext, horizon),
            Some(e) => {
                // On the held path the hand moves along e only (a door's hinge takes the rest).
                let x = HandState {
                    vel: e * e.dot(&x0.vel),
                    acc: e * e.dot(&x0.acc),
                    ..*x0
                };
                self.roll(x, Some(&e), desired, gains, f_ext, horizon);
            }
        }
        self.len = horizon;
        Ok(())
    }

    /// eq. (24) over `horizon` steps from `x` (inputs checked by `predict`).
    #[inline(always)]
    fn roll(
        &mut self,
        mut x: HandState,
        path: Option<&Vector3<f64>>,
        desired: &[HandState],
        gains: &GainSchedule,
        f_ext: &[[f64; 3]],
        horizon: usize,
    ) {
        for i in 0..horizon {
            let (next, f_dis) = self.step_on(
                path,
                &x,
                &desired[i],
                gains.kp[i],
                gains.kd[i],
                &Vector3::from(f_ext[i]),
            );
            self.states[i] = next;
            self.f_dis[i] = f_dis.into();
            x = next;
        }
    }

    /// Predicted hand states at k+1…k+N of the last [`HandPreviewer::predict`].
    pub fn states(&self) -> &[HandState] {
        &self.states[..self.len]
    }

    /// The F_dis forecast at k+1…k+N of the last [`HandPreviewer::predict`].
    pub fn disturbance(&self) -> &[[f64; 3]] {
        &self.f_dis[..self.len]
    }
}
