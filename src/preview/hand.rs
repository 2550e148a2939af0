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

fn finite(v: &Vector3<f64>) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// The gains' bounds: K_p > 0, K_d ≥ 0, both finite (without early exit, so that a pass over
/// the schedule vectorises).
fn gains_in_bounds(kp: f64, kd: f64) -> bool {
    kp.is_finite() & (kp > 0.0) & kd.is_finite() & (kd >= 0.0)
}

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
    pub fn step(
        &self,
        x: &HandState,
        desired: &HandState,
        kp: f64,
        kd: f64,
        f_ext: &Vector3<f64>,
    ) -> (HandState, Vector3<f64>) {
        let path = self.held.as_ref().map(|(e, _)| e);
        self.step_on(path, x, desired, kp, kd, f_ext)
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
    /// k+1…k+N). `desired`, `gains` and `f_ext` need at least `horizon` samples. On an error
    /// the prediction is empty.
    pub fn predict(
        &mut self,
        x0: &HandState,
        desired: &[HandState],
        gains: &GainSchedule,
        f_ext: &[[f64; 3]],
        horizon: usize,
    ) -> Result<(), PreviewError> {
        self.len = 0;
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
        if !(finite(&x0.pos) && finite(&x0.vel) && finite(&x0.acc)) {
            return Err(PreviewError::NotFinite {
                what: "hand state",
                step: 0,
            });
        }
        // The gains' bounds in one pass without early exit (it vectorises); the step is looked
        // for only when one is out.
        let gains_ok = gains.kp[..horizon]
            .iter()
            .zip(&gains.kd[..horizon])
            .fold(true, |ok, (&kp, &kd)| ok & gains_in_bounds(kp, kd));
        if !gains_ok {
            return Err(self.first_bad_input(desired, gains, f_ext, horizon));
        }
        // Two loops, so that eq. (24)'s carries no test of the path per step.
        let finite_out = match self.held.map(|(e, _)| e) {
            None => self.roll(*x0, None, desired, gains, f_ext, horizon),
            Some(e) => {
                // On the held path the hand moves along e only (a door's hinge takes the rest).
                let x = HandState {
                    vel: e * e.dot(&x0.vel),
                    acc: e * e.dot(&x0.acc),
                    ..*x0
                };
                self.roll(x, Some(&e), desired, gains, f_ext, horizon)
            }
        };
        // The desired states and forces are not checked one by one before the recursion:
        // with K_p > 0 every one of them enters the next acceleration, and a non-finite value
        // never becomes finite again through the recursion's sums and products (∞·0 and ∞ − ∞
        // are NaN), so the last state and the F_dis sum carry any of them. Only then is the
        // first bad input looked for, to name it.
        if !finite_out {
            return Err(self.first_bad_input(desired, gains, f_ext, horizon));
        }
        self.len = horizon;
        Ok(())
    }

    /// The first input, in step order, that the recursion cannot take; an overflow of the
    /// prediction itself (finite inputs too large) when there is none.
    #[cold]
    fn first_bad_input(
        &self,
        desired: &[HandState],
        gains: &GainSchedule,
        f_ext: &[[f64; 3]],
        horizon: usize,
    ) -> PreviewError {
        for i in 0..horizon {
            let (kp, kd) = (gains.kp[i], gains.kd[i]);
            if !gains_in_bounds(kp, kd) {
                return PreviewError::BadGain {
                    step: i + 1,
                    kp,
                    kd,
                };
            }
            if !f_ext[i].iter().all(|c| c.is_finite()) {
                return PreviewError::NotFinite {
                    what: "hand force",
                    step: i + 1,
                };
            }
            let d = &desired[i];
            if !(finite(&d.pos) && finite(&d.vel) && finite(&d.acc)) {
                return PreviewError::NotFinite {
                    what: "desired hand",
                    step: i + 1,
                };
            }
        }
        let step = self.states[..horizon]
            .iter()
            .zip(&self.f_dis[..horizon])
            .position(|(s, f)| {
                !(finite(&s.pos)
                    && finite(&s.vel)
                    && finite(&s.acc)
                    && f.iter().all(|c| c.is_finite()))
            })
            .map_or(horizon, |i| i + 1);
        PreviewError::NotFinite {
            what: "hand prediction (inputs too large)",
            step,
        }
    }

    /// eq. (24) over `horizon` steps from `x` (gains checked by `predict`); whether the last
    /// state and every F_dis are finite.
    #[inline(always)]
    fn roll(
        &mut self,
        mut x: HandState,
        path: Option<&Vector3<f64>>,
        desired: &[HandState],
        gains: &GainSchedule,
        f_ext: &[[f64; 3]],
        horizon: usize,
    ) -> bool {
        // Σ F_dis: non-finite if any sample is (or the sum overflows: then the check names it).
        let mut f_sum = 0.0;
        for i in 0..horizon {
            let (next, f_dis) = self.step_on(
                path,
                &x,
                &desired[i],
                gains.kp[i],
                gains.kd[i],
                &Vector3::from(f_ext[i]),
            );
            f_sum += f_dis.x + f_dis.y + f_dis.z;
            self.states[i] = next;
            self.f_dis[i] = f_dis.into();
            x = next;
        }
        f_sum.is_finite() && finite(&x.pos) && finite(&x.vel) && finite(&x.acc)
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

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = 300;
    const T: f64 = 0.005;

    fn m_e() -> Matrix3<f64> {
        Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 1.2)
    }

    /// Varying gains, set-points and forces, so that no term of the step drops out.
    fn inputs() -> (Vec<HandState>, GainSchedule, Vec<[f64; 3]>) {
        let desired = (0..N)
            .map(|i| {
                let s = i as f64 * 0.01;
                HandState {
                    pos: Vector3::new(0.3 + 0.01 * s.sin(), -0.2, 0.9 + 0.02 * s.cos()),
                    vel: Vector3::new(0.01 * s.cos(), 0.0, -0.02 * s.sin()),
                    acc: Vector3::new(-0.01 * s.sin(), 0.001, -0.02 * s.cos()),
                }
            })
            .collect();
        let gains = GainSchedule {
            kp: (0..N)
                .map(|i| 80.0 + 40.0 * (i as f64 * 0.02).sin())
                .collect(),
            kd: (0..N)
                .map(|i| 15.0 + 5.0 * (i as f64 * 0.03).cos())
                .collect(),
        };
        let f = (0..N)
            .map(|i| {
                let s = i as f64 * T;
                [40.0 * (3.0 * s).sin(), -12.0 * s, 5.0 * (7.0 * s).cos()]
            })
            .collect();
        (desired, gains, f)
    }

    fn start() -> HandState {
        HandState {
            pos: Vector3::new(0.31, -0.21, 0.88),
            vel: Vector3::new(0.05, -0.02, 0.01),
            acc: Vector3::new(0.3, 0.1, -0.2),
        }
    }

    /// docs/hand_previewer.md's four lines (eq. (17), (23), (25)) and HP-1, written out here,
    /// against the previewer's whole horizon, free and on a held path.
    #[test]
    fn the_prediction_is_the_documented_step() {
        let (desired, gains, f) = inputs();
        let e = Vector3::new(0.6, 0.8, 0.0);
        let m = 5.1;
        for path in [None, Some((e, m))] {
            let mut hp = HandPreviewer::new(T, m_e(), N).unwrap();
            hp.set_held_path(path);
            hp.predict(&start(), &desired, &gains, &f, N).unwrap();
            let minv = m_e().try_inverse().unwrap();
            let mut x = start();
            if path.is_some() {
                x.vel = e * e.dot(&x.vel);
                x.acc = e * e.dot(&x.acc);
            }
            let (mut worst_x, mut worst_f) = (0.0_f64, 0.0_f64);
            for i in 0..N {
                let (d, kp, kd) = (&desired[i], gains.kp[i], gains.kd[i]);
                let fe = Vector3::from(f[i]);
                let pos = x.pos + x.vel * T + x.acc * (T * T / 2.0);
                let vel = x.vel + x.acc * T;
                let cmd = (d.pos - pos) * kp + (d.vel - vel) * kd + d.acc;
                let acc = match path {
                    None => cmd + minv * fe,
                    Some((e, m)) => {
                        let me = m_e() * e;
                        e * ((e.dot(&fe) + me.dot(&cmd)) / (e.dot(&me) + m))
                    }
                };
                x = HandState { pos, vel, acc };
                let f_dis = -(m_e() * cmd);
                let got = hp.states()[i];
                worst_x = worst_x
                    .max((got.pos - pos).amax() / 1e-3)
                    .max((got.vel - vel).amax() / 1e-2)
                    .max((got.acc - acc).amax() / 1.0);
                worst_f = worst_f.max((Vector3::from(hp.disturbance()[i]) - f_dis).amax());
            }
            // Relative to each quantity's scale (mm, cm/s, m/s²; N): rounding only.
            assert!(worst_x < 1e-9, "{path:?}: state off by {worst_x:e}");
            assert!(worst_f < 1e-9, "{path:?}: F_dis off by {worst_f:e} N");
        }
    }

    /// Inputs are checked after the recursion; the first bad one, in step order, is named,
    /// and a failed prediction leaves nothing to read.
    #[test]
    fn every_bad_input_is_named_at_its_step() {
        let (desired, gains, f) = inputs();
        let mut hp = HandPreviewer::new(T, m_e(), N).unwrap();
        let x0 = start();
        let expect = |hp: &mut HandPreviewer,
                      d: &[HandState],
                      g: &GainSchedule,
                      f: &[[f64; 3]],
                      want: PreviewError| {
            hp.predict(&x0, &desired, &gains, &inputs().2, N).unwrap();
            assert_eq!(hp.disturbance().len(), N);
            assert_eq!(hp.predict(&x0, d, g, f, N), Err(want));
            assert!(hp.disturbance().is_empty() && hp.states().is_empty());
        };
        let mut d = desired.clone();
        d[6].pos.y = f64::NAN;
        let desired_at = |step| PreviewError::NotFinite {
            what: "desired hand",
            step,
        };
        expect(&mut hp, &d, &gains, &f, desired_at(7));
        // With K_d = 0 a non-finite desired velocity is multiplied by zero: still caught.
        let mut d = desired.clone();
        let mut g = gains.clone();
        d[20].vel.x = f64::INFINITY;
        g.kd[20] = 0.0;
        expect(&mut hp, &d, &g, &f, desired_at(21));
        let mut d = desired.clone();
        d[N - 1].acc.z = f64::NEG_INFINITY;
        expect(&mut hp, &d, &gains, &f, desired_at(N));
        // The last force enters the last state's acceleration only.
        let mut ff = f.clone();
        ff[N - 1][1] = f64::INFINITY;
        expect(
            &mut hp,
            &desired,
            &gains,
            &ff,
            PreviewError::NotFinite {
                what: "hand force",
                step: N,
            },
        );
        // Of a bad gain and a bad force, the earlier step is named.
        let mut g = gains.clone();
        g.kp[40] = 0.0;
        let mut ff = f.clone();
        ff[10][0] = f64::NAN;
        let force_at_11 = PreviewError::NotFinite {
            what: "hand force",
            step: 11,
        };
        expect(&mut hp, &desired, &g, &ff, force_at_11);
        let mut ff = f.clone();
        ff[60][0] = f64::NAN;
        let gain_at_41 = PreviewError::BadGain {
            step: 41,
            kp: 0.0,
            kd: g.kd[40],
        };
        expect(&mut hp, &desired, &g, &ff, gain_at_41);
        // Finite inputs whose prediction overflows.
        let mut d = desired.clone();
        d[100].pos.x = 1e306;
        let err = hp.predict(&x0, &d, &gains, &f, N).unwrap_err();
        assert!(
            matches!(
                err,
                PreviewError::NotFinite {
                    what: "hand prediction (inputs too large)",
                    ..
                }
            ),
            "{err}"
        );
    }
}
