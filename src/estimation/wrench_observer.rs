//! The external wrenches on the robot from its joint torques: a generalised-momentum residual
//! observer on the floating base (docs/estimation.md, WO-1 … WO-3), split into the feet's
//! wrenches and the hand's force.
//!
//! Why a momentum observer rather than the equations of motion solved for the wrenches: both
//! read τ_ext = M v̇ + h − Sᵀτ, but the observer never differentiates the measured velocity; it
//! filters the momentum balance to first order at its gain K (the estimate lags a step by 1/K),
//! where solving the equations of motion needs v̇ from differences of a noisy v and a filter of
//! its own on top.
//!
//! With p = M(q) v the generalised momentum and h = C v + g:
//!
//!   ṗ = Sᵀτ + Cᵀv − g + τ_ext,  Cᵀv − g = Ṁ v − h                                   (WO-1)
//!   r = K (p − p₀ − ∫ (Sᵀτ + Ṁ v − h + r) dt),  ṙ = K (τ_ext − r)                     (WO-2)
//!
//! Ṁ v from the difference of consecutive M. The residual is the external generalised force,
//! τ_ext = Σ J_cᵀ w_c over the contacts: each foot's wrench (force and moment at its sole's
//! centre) and the hand's force. They are the regularised least-squares solution of
//!
//!   min ‖r − Aᵀ w‖² + λ ‖w‖²,  A = [J_L; J_R; J_hand,lin]  (15 × nv)                  (WO-3)
//!
//! the base's six rows and the legs' pin the feet, the arm's the hand. The rows are weighed by
//! the inverse of their noise (WO-4): a velocity's error δv enters r as K M δv at once, so a
//! base velocity estimated to a few mm/s puts tens of newtons on the base's rows (K M ≈ 200/s ×
//! 35 kg), where a joint's torque estimate errs by a fraction of a newton-metre:
//!
//!   W = diag(1 / ((K M_ii σ_v,i)² + σ_τ,i²)),  σ_τ,i² = σ_τ² + (ε τ_max,i)²              (WO-4)
//!
//! A drive's torque estimate errs in proportion to its rating (its current sensing's range and
//! its gear's friction scale with the torque it is built for): ε τ_max,i. Weighed uniformly, a
//! leg's and the waist's large drives, whose friction is a few N·m, pulled the split as much as
//! an arm's small ones, and the feet's loads and the CoP took their friction.
//!
//! WO-2 passes a velocity's white noise to r at the gain K (r = K/(s+K) τ_ext + K s/(s+K) M δv).
//! A second first-order stage at K₂ on r makes the estimate critically damped when K₂ = K:
//!
//!   r₂ = K₂/(s+K₂) r,  r₂ = K K₂/((s+K)(s+K₂)) τ_ext + K K₂ s/((s+K)(s+K₂)) M δv      (WO-5)
//!
//! Its mean lag is 1/K + 1/K₂; the noise rolls off above K₂ instead of passing to Nyquist. For
//! white δv of σ per sample at the step dt and K₂ = K, the RMS noise on r₂ is K M σ √(K dt / 4)
//! against K M σ on r: at the same mean lag (K doubled) a third of it at 1 kHz. In general the
//! gain from a white velocity noise to r₂ is K K₂ √(dt / (2 (K + K₂))), which WO-4 then uses
//! for K.
//!
//! The hand's force is read through a stage of its own on r that follows a ramp without lag
//! (WO-7): the forecast correction and the QP read the hand's force when it changes, where the
//! feet's wrenches and the CoP are read while they hold. With a₁ = 2ζω, a₂ = ω² (ζ = 1/√2),
//!
//!   ẋ = ẋ_r + a₁ (r − x),  ẍ_r = a₂ (r − x),  x = (a₁ s + a₂)/(s² + a₁ s + a₂) r          (WO-7)
//!
//! Its mean lag is 0 (the numerator's a₁/a₂ cancels the denominator's), so the hand's is WO-2's
//! 1/K alone; a ramp is followed without error, a push's curvature f̈ with error f̈/a₂. Its
//! noise above ω passes at a₁ where WO-5's passes at K₂.
//!
//! WO-2's own lag is known exactly (ṙ = K (τ_ext − r)), and WO-7 already tracks ṙ as ẋ_r, so
//! the hand is read ahead by it (WO-8):
//!
//!   τ̂_ext = x + ẋ_r / K = (a₁ s + a₂ + a₂ s / K)/(s² + a₁ s + a₂) · K/(s + K) τ_ext        (WO-8)
//!
//! whose mean lag is 0 (to first order in s the lead's 1/K cancels WO-2's), and a ramp is
//! followed without error; the noise above ω passes at a₁ + a₂/K instead of a₁ (51/s against
//! 42/s at ω = 30/s, K = 100/s). Raising ω instead would leave WO-2's 1/K where it is.
//!
//! A drive's torque estimate from its current reads the motor's torque, the link's plus the
//! gear's friction. The friction identified for the drives is taken off before WO-1 (WO-6):
//!
//!   τ_link = τ_est − (c τ_max tanh(v / v_s) + b v)                                      (WO-6)

use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, SMatrix, SVector, Vector3};

use crate::dynamics::{
    Data, DynamicsError, Model, ReferenceFrame, crba, get_frame_jacobian, nonlinear_effects,
    update_frame_placements,
};

/// Unknowns of WO-3: two feet's wrenches (6 each) and the hand's force (3).
const NW: usize = 15;
/// λ of WO-3 relative to the mean of diag(A Aᵀ): keeps the split defined when a contact's
/// Jacobian loses rank (a stretched knee) without biasing a well-posed one.
const REGULARISATION: f64 = 1e-9;
/// The smallest variance of a row of WO-3 (N², N²·m²): exact inputs still give a finite weight.
const MIN_VARIANCE: f64 = 1e-6;
/// Below this total normal force (N) the feet have no centre of pressure.
const MIN_NORMAL: f64 = 1.0;

/// The wrenches an update estimated (world axes unless said).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactWrenches {
    /// Each foot's wrench of the ground, left then right: [f, τ] in its sole frame (x toward
    /// the toes, z up) about the centroid of its corners, as a six-axis foot sensor moved to
    /// the sole gives it.
    pub feet: [[f64; 6]; 2],
    /// The force on the hand (N, world).
    pub hand: [f64; 3],
    /// The centre of pressure of the feet's wrenches on the ground (world x, y; m) and their
    /// total normal force (N); `None` while they press with less than 1 N.
    pub cop: Option<[f64; 2]>,
    pub normal_force: f64,
}

/// The observer's settings (`[controller.wrench_observer]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrenchObserverGains {
    /// K of WO-2 (1/s): the estimate's bandwidth.
    pub gain: f64,
    /// σ of the velocities the observer reads: the base's linear (m/s) and angular (rad/s),
    /// the joints' (rad/s); and of the joint torques (N·m). They weigh WO-3's rows (WO-4).
    pub velocity_noise: [f64; 3],
    pub torque_noise: f64,
    /// ε of WO-4: the part of a joint torque's σ in proportion to its effort limit.
    pub torque_noise_fraction: f64,
    /// K₂ of WO-5 (1/s); 0: the residual of WO-2 as it is.
    pub filter_gain: f64,
    /// ω of WO-7 (1/s), the hand's own stage; 0: the hand's force from WO-5's r₂ as the feet's.
    pub hand_bandwidth: f64,
    /// WO-8: the hand's force read ahead by WO-2's lag through WO-7's rate (with WO-7 only).
    pub hand_lead: bool,
    /// WO-6: the drives' Coulomb friction as a fraction c of each joint's effort limit, the
    /// velocity v_s (rad/s) over which it changes sign, and the viscous b (N·m·s/rad).
    pub friction: DriveFriction,
}

/// The drives' friction as identified (WO-6); zero: the torque estimates as they are.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveFriction {
    pub coulomb: f64,
    pub velocity: f64,
    pub viscous: f64,
}

impl DriveFriction {
    /// The friction torque of a joint of effort limit `effort` at velocity `v`.
    pub fn torque(&self, effort: f64, v: f64) -> f64 {
        let coulomb = if self.coulomb > 0.0 && effort.is_finite() && self.velocity > 0.0 {
            self.coulomb * effort * (v / self.velocity).tanh()
        } else {
            0.0
        };
        coulomb + self.viscous * v
    }
}

pub struct WrenchObserver {
    model: Model,
    data: Data,
    gain: f64,
    /// Sole corners per foot (front-left, front-right, rear-left, rear-right) and the hand's
    /// frame.
    corners: [[usize; 4]; 2],
    hand: usize,
    /// p₀, ∫(…), r of WO-2; M at the last update; whether it has started.
    p0: DVector<f64>,
    integral: DVector<f64>,
    residual: DVector<f64>,
    /// r₂ of WO-5: what the split reads.
    filtered: DVector<f64>,
    filter_gain: f64,
    /// x and ẋ_r of WO-7 (the hand's stage), its ω.
    tracked: DVector<f64>,
    tracked_rate: DVector<f64>,
    hand_bandwidth: f64,
    /// WO-8's lead (s): 1/K, or 0 without it.
    hand_lead: f64,
    friction: DriveFriction,
    /// Each velocity coordinate's effort limit (WO-6; the base's six unused).
    effort: DVector<f64>,
    m_prev: DMatrix<f64>,
    started: bool,
    /// Scratch: Sᵀτ, Ṁ v, M v, one frame's Jacobian, A of WO-3.
    tau_full: DVector<f64>,
    mdot_v: DVector<f64>,
    m_v: DVector<f64>,
    jac: DMatrix<f64>,
    a: DMatrix<f64>,
    /// A W (WO-4).
    aw: DMatrix<f64>,
    velocity_noise: [f64; 3],
    /// σ_τ,i of WO-4 per velocity coordinate (zero on the base's six: no drive).
    torque_sd: DVector<f64>,
    /// Each foot's sole centre and rotation at the last update (world ← sole).
    sole_centre: [Vector3<f64>; 2],
    sole_rot: [Matrix3<f64>; 2],
    pub last: ContactWrenches,
}

impl WrenchObserver {
    /// The observer of `model` whose sole corners are `corners` (four per foot, left first,
    /// front-left, front-right, rear-left, rear-right) and whose hand is frame `hand`.
    pub fn new(
        model: &Model,
        corners: [usize; 8],
        hand: usize,
        gains: WrenchObserverGains,
    ) -> Self {
        let nv = model.nv;
        let effort = model.effort_limits();
        let torque_sd = DVector::from_fn(nv, |k, _| {
            if k < 6 {
                return 0.0;
            }
            let rated = gains.torque_noise_fraction * effort[k];
            let rated = if rated.is_finite() { rated } else { 0.0 };
            gains.torque_noise.hypot(rated)
        });
        Self {
            data: Data::new(model),
            model: model.clone(),
            gain: gains.gain,
            corners: [
                [corners[0], corners[1], corners[2], corners[3]],
                [corners[4], corners[5], corners[6], corners[7]],
            ],
            hand,
            p0: DVector::zeros(nv),
            integral: DVector::zeros(nv),
            residual: DVector::zeros(nv),
            filtered: DVector::zeros(nv),
            filter_gain: gains.filter_gain,
            tracked: DVector::zeros(nv),
            tracked_rate: DVector::zeros(nv),
            hand_bandwidth: gains.hand_bandwidth,
            hand_lead: if gains.hand_lead && gains.hand_bandwidth > 0.0 {
                1.0 / gains.gain
            } else {
                0.0
            },
            friction: gains.friction,
            effort: DVector::from_vec(effort),
            m_prev: DMatrix::zeros(nv, nv),
            started: false,
            tau_full: DVector::zeros(nv),
            mdot_v: DVector::zeros(nv),
            m_v: DVector::zeros(nv),
            jac: DMatrix::zeros(6, nv),
            a: DMatrix::zeros(NW, nv),
            aw: DMatrix::zeros(NW, nv),
            velocity_noise: gains.velocity_noise,
            torque_sd,
            sole_centre: [Vector3::zeros(); 2],
            sole_rot: [Matrix3::identity(); 2],
            last: ContactWrenches::default(),
        }
    }

    /// Start over at the next update (a new session; a state that jumped).
    pub fn reset(&mut self) {
        self.started = false;
        self.last = ContactWrenches::default();
    }

    /// The estimates' mean lag behind the wrenches (s): 1/K + 1/K₂ (WO-5).
    pub fn lag(&self) -> f64 {
        let second = if self.filter_gain > 0.0 {
            1.0 / self.filter_gain
        } else {
            0.0
        };
        1.0 / self.gain + second
    }

    /// The hand force's mean lag (s): none when WO-8 reads it ahead, WO-2's 1/K when WO-7
    /// reads it, else [`Self::lag`].
    pub fn hand_lag(&self) -> f64 {
        if self.hand_bandwidth > 0.0 {
            1.0 / self.gain - self.hand_lead
        } else {
            self.lag()
        }
    }

    /// One update on the configuration `q`, velocity `v` (Pinocchio's conventions, the base
    /// included) and the joints' torques `tau` (nv − 6), `dt` after the last one.
    pub fn update(
        &mut self,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &[f64],
        dt: f64,
    ) -> Result<&ContactWrenches, DynamicsError> {
        let nv = self.model.nv;
        // M(q) (CRBA also refreshes the joint Jacobians the contacts' rows read).
        crba(&self.model, &mut self.data, q)?;
        update_frame_placements(&self.model, &mut self.data);
        self.tau_full.fill(0.0);
        self.tau_full.rows_mut(6, nv - 6).copy_from_slice(tau);
        for k in 6..nv {
            self.tau_full[k] -= self.friction.torque(self.effort[k], v[k]); // WO-6
        }
        // A step that is not a positive time (a repeated or reordered state) starts over too.
        let starting = !self.started || dt.is_nan() || dt <= 0.0;
        if starting {
            self.data.m.mul_to(v, &mut self.p0);
            self.mdot_v.fill(0.0);
            self.m_prev.copy_from(&self.data.m);
        } else {
            // Ṁ v by the difference of consecutive M (WO-1).
            self.m_prev
                .zip_apply(&self.data.m, |prev, now| *prev = (now - *prev) / dt);
            self.m_prev.mul_to(v, &mut self.mdot_v);
            self.m_prev.copy_from(&self.data.m);
        }
        self.data.m.mul_to(v, &mut self.m_v);
        nonlinear_effects(&self.model, &mut self.data, q, v)?;
        if starting {
            // WO-2 from the quasi-static balance (v̇ = 0): r₀ = h − Sᵀτ, then r follows τ_ext
            // at rate K. From zero instead, the feet would carry nothing for the first 1/K.
            for k in 0..nv {
                self.residual[k] = self.data.tau[k] - self.tau_full[k];
                self.integral[k] = -self.residual[k] / self.gain;
            }
            self.filtered.copy_from(&self.residual);
            self.tracked.copy_from(&self.residual);
            self.tracked_rate.fill(0.0);
            self.started = true;
            self.split(0.0)?;
            return Ok(&self.last);
        }
        // WO-2, its integral by the rectangle rule on the last residual.
        for k in 0..nv {
            self.integral[k] +=
                dt * (self.tau_full[k] + self.mdot_v[k] - self.data.tau[k] + self.residual[k]);
            self.residual[k] = self.gain * (self.m_v[k] - self.p0[k] - self.integral[k]);
        }
        // WO-5, exact for a residual held over the step.
        let blend = if self.filter_gain > 0.0 {
            1.0 - (-self.filter_gain * dt).exp()
        } else {
            1.0
        };
        for k in 0..nv {
            self.filtered[k] += blend * (self.residual[k] - self.filtered[k]);
        }
        if self.hand_bandwidth > 0.0 {
            // WO-7, exact for a residual held over the step: the error e = r − x and ẋ_r
            // follow (ė, ẍ_r) = [[−a₁, −1], [a₂, 0]] (e, ẋ_r).
            let (w, zeta) = (self.hand_bandwidth, std::f64::consts::FRAC_1_SQRT_2);
            let step = (Matrix2::new(-2.0 * zeta * w, -1.0, w * w, 0.0) * dt).exp();
            for k in 0..nv {
                let e = self.residual[k] - self.tracked[k];
                let (e, rate) = (
                    step[(0, 0)] * e + step[(0, 1)] * self.tracked_rate[k],
                    step[(1, 0)] * e + step[(1, 1)] * self.tracked_rate[k],
                );
                self.tracked[k] = self.residual[k] - e;
                self.tracked_rate[k] = rate;
            }
        }
        self.split(dt)?;
        Ok(&self.last)
    }

    /// WO-3: the contacts' wrenches from the residual.
    fn split(&mut self, dt: f64) -> Result<(), DynamicsError> {
        let lwa = ReferenceFrame::LocalWorldAligned;
        for (i, ids) in self.corners.iter().enumerate() {
            let c = |k: usize| self.data.o_m_f[ids[k]].trans;
            let centre = (c(0) + c(1) + c(2) + c(3)) / 4.0;
            self.sole_centre[i] = centre;
            self.sole_rot[i] = crate::robot::sole_frame(c(0), c(1), c(2), c(3));
            // The sole's centre moves with the corner's body: J_centre = J_lin − [d]× J_ang.
            get_frame_jacobian(&self.model, &self.data, ids[0], lwa, &mut self.jac)?;
            let d = centre - c(0);
            for col in 0..self.model.nv {
                let lin = Vector3::new(self.jac[(0, col)], self.jac[(1, col)], self.jac[(2, col)]);
                let ang = Vector3::new(self.jac[(3, col)], self.jac[(4, col)], self.jac[(5, col)]);
                let lin = lin + ang.cross(&d);
                for r in 0..3 {
                    self.a[(6 * i + r, col)] = lin[r];
                    self.a[(6 * i + 3 + r, col)] = ang[r];
                }
            }
        }
        get_frame_jacobian(&self.model, &self.data, self.hand, lwa, &mut self.jac)?;
        for col in 0..self.model.nv {
            for r in 0..3 {
                self.a[(12 + r, col)] = self.jac[(r, col)];
            }
        }
        // WO-4's weights (M's diagonal is `data.m`'s: RNEA since left it as CRBA made it), with
        // WO-5's noise gain in place of K once a step is known.
        let (k1, k2) = (self.gain, self.filter_gain);
        let noise_gain = if k2 > 0.0 && dt > 0.0 {
            k1 * k2 * (dt / (2.0 * (k1 + k2))).sqrt()
        } else {
            k1
        };
        for k in 0..self.model.nv {
            let sv = match k {
                0..3 => self.velocity_noise[0],
                3..6 => self.velocity_noise[1],
                _ => self.velocity_noise[2],
            };
            let var = (noise_gain * self.data.m[(k, k)] * sv).powi(2) + self.torque_sd[k].powi(2);
            let w = 1.0 / var.max(MIN_VARIANCE);
            for i in 0..NW {
                self.aw[(i, k)] = self.a[(i, k)] * w;
            }
        }
        // (A W Aᵀ + λ I) w = A W r; the hand's from WO-7's x (WO-8: x + ẋ_r / K) when it runs.
        let mut normal = SMatrix::<f64, NW, NW>::zeros();
        let mut rhs = SVector::<f64, NW>::zeros();
        let mut rhs_hand = SVector::<f64, NW>::zeros();
        let tracking = self.hand_bandwidth > 0.0 && dt > 0.0;
        for i in 0..NW {
            // Element by element: a transposed view of the residual would be a new vector.
            rhs[i] = (0..self.model.nv)
                .map(|k| self.aw[(i, k)] * self.filtered[k])
                .sum();
            if tracking {
                rhs_hand[i] = (0..self.model.nv)
                    .map(|k| {
                        let x = self.tracked[k] + self.hand_lead * self.tracked_rate[k];
                        self.aw[(i, k)] * x
                    })
                    .sum();
            }
            for j in 0..=i {
                let x = self.aw.row(i).dot(&self.a.row(j));
                normal[(i, j)] = x;
                normal[(j, i)] = x;
            }
        }
        let lambda = REGULARISATION * normal.trace() / NW as f64;
        for i in 0..NW {
            normal[(i, i)] += lambda;
        }
        let Some(chol) = normal.cholesky() else {
            return Ok(()); // a degenerate split keeps the last estimate
        };
        let w = chol.solve(&rhs);
        let (mut total, mut sum) = (0.0, Vector3::zeros());
        for (i, r) in self.sole_rot.iter().enumerate() {
            let f = r.transpose() * Vector3::new(w[6 * i], w[6 * i + 1], w[6 * i + 2]);
            let m = r.transpose() * Vector3::new(w[6 * i + 3], w[6 * i + 4], w[6 * i + 5]);
            self.last.feet[i] = [f.x, f.y, f.z, m.x, m.y, m.z];
            if f.z > 0.0 {
                // On the sole: f_z · (x, y) = (−τ_y, τ_x), about its centre.
                let local = Vector3::new(-m.y, m.x, 0.0);
                total += f.z;
                sum += f.z * self.sole_centre[i] + r * local;
            }
        }
        let hand = if tracking { chol.solve(&rhs_hand) } else { w };
        self.last.hand = [hand[12], hand[13], hand[14]];
        self.last.normal_force = total;
        self.last.cop = (total > MIN_NORMAL).then(|| [sum.x / total, sum.y / total]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::{Force, aba_with_external_forces, integrate};
    use crate::robot::Robot;

    /// A robot floating without gravity (nothing else touches it) pushed at the hand by
    /// `force(t)` (N, world), its joints unactuated (a push of a few newtons: its light limbs
    /// swing fast under more), integrated by semi-implicit Euler at 10 kHz; the observer's
    /// estimates at 1 kHz.
    fn pushed(
        robot: &Robot,
        force: impl Fn(f64) -> Vector3<f64>,
        steps: usize,
    ) -> Vec<(f64, ContactWrenches)> {
        pushed_measured(robot, force, steps, FIRST_ORDER, 0.0, |_, _, _| 0.0)
    }

    /// K = 100/s, no second stage, no friction, exact inputs.
    const FIRST_ORDER: WrenchObserverGains = WrenchObserverGains {
        gain: 100.0,
        velocity_noise: [0.0; 3],
        torque_noise: 0.0,
        torque_noise_fraction: 0.0,
        filter_gain: 0.0,
        hand_bandwidth: 0.0,
        hand_lead: false,
        friction: DriveFriction {
            coulomb: 0.0,
            velocity: 0.05,
            viscous: 0.0,
        },
    };

    /// [`pushed`] through the observer `gains`, the joints' velocities it reads with white noise
    /// of σ `velocity_noise` (rad/s), joint `k`'s torque estimate erring by
    /// `error(k, velocity, effort)`.
    fn pushed_measured(
        robot: &Robot,
        force: impl Fn(f64) -> Vector3<f64>,
        steps: usize,
        gains: WrenchObserverGains,
        velocity_noise: f64,
        mut error: impl FnMut(usize, f64, f64) -> f64,
    ) -> Vec<(f64, ContactWrenches)> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut model = robot.model.clone();
        model.gravity = Vector3::zeros();
        let model = &model;
        let frames = robot.frames();
        let hand = model.frame_id(&frames.hand).expect("hand");
        let corners = robot
            .contacts
            .each_ref()
            .map(|c| model.frame_id(c).expect("corner"));
        let mut obs = WrenchObserver::new(model, corners, hand, gains);
        let mut read = DVector::zeros(model.nv);
        let mut data = Data::new(model);
        let (mut q, mut v) = (robot.home.clone(), DVector::zeros(model.nv));
        let mut next = q.clone();
        let tau = DVector::zeros(model.nv);
        let effort = model.effort_limits();
        let (dt, substeps) = (1e-3, 10);
        let h = dt / substeps as f64;
        let mut out = Vec::new();
        for k in 0..steps * substeps {
            let t = k as f64 * h;
            // The force at the hand frame's origin, as a wrench on its body at the body's origin.
            update_frame_placements(model, &mut data);
            crate::dynamics::forward_kinematics(model, &mut data, &q).expect("kinematics");
            update_frame_placements(model, &mut data);
            let body = model.frames[hand].parent.expect("hand on a body");
            let (o, p) = (data.o_m_i[body], data.o_m_f[hand].trans);
            let f = force(t);
            let mut fext = vec![Force::zero(); model.njoints()];
            fext[body] = Force::new(
                o.rot.transpose() * f,
                o.rot.transpose() * (p - o.trans).cross(&f),
            );
            let a = aba_with_external_forces(model, &mut data, &q, &v, &tau, &fext)
                .expect("aba")
                .clone();
            v += a * h;
            integrate(model, &q, &v, h, &mut next).expect("integrate");
            q.copy_from(&next);
            if k % substeps == substeps - 1 {
                let measured: Vec<f64> = (6..model.nv).map(|j| error(j, v[j], effort[j])).collect();
                for j in 0..model.nv {
                    let n: f64 = StandardNormal.sample(&mut rng);
                    read[j] = v[j] + if j >= 6 { velocity_noise * n } else { 0.0 };
                }
                let w = *obs.update(&q, &read, &measured, dt).expect("update");
                out.push((t + h, w));
            }
        }
        out
    }

    /// The observer of `robot` on its sole corners and hand, through `gains`.
    fn observer_of(robot: &Robot, gains: WrenchObserverGains) -> WrenchObserver {
        let corners = robot
            .contacts
            .each_ref()
            .map(|c| robot.model.frame_id(c).expect("corner"));
        let hand = robot.model.frame_id(&robot.frames().hand).expect("hand");
        WrenchObserver::new(&robot.model, corners, hand, gains)
    }

    /// A constant 5 N push at the hand of a free-floating robot (no ground): the estimate
    /// reaches it within 0.1 N in 50 ms (five time constants of K = 100/s), and the feet, which
    /// touch nothing, carry less than 0.2 N and 0.02 N·m (the free limbs swing: the rectangle rule of
    /// WO-2 at 1 kHz leaks a few per cent of the push into them).
    #[test]
    fn a_constant_hand_force_is_recovered_and_the_free_feet_carry_nothing() {
        let robot = Robot::embedded_default().expect("robot");
        let f = Vector3::new(-4.0, 2.4, 1.6);
        let est = pushed(&robot, |_| f, 100);
        for (t, w) in est.iter().filter(|(t, _)| *t >= 0.05) {
            let err = (Vector3::from(w.hand) - f).norm();
            assert!(err < 0.1, "t = {t}: hand {:?}, error {err}", w.hand);
            for foot in &w.feet {
                let (fo, mo) = (
                    Vector3::new(foot[0], foot[1], foot[2]).norm(),
                    Vector3::new(foot[3], foot[4], foot[5]).norm(),
                );
                assert!(fo < 0.2 && mo < 0.02, "t = {t}: foot {foot:?}");
            }
        }
        // The first-order lag of WO-2: after one time constant, 1 − 1/e of the force.
        let (_, at_tau) = est[9];
        let ratio = at_tau.hand[0] / f.x;
        assert!((ratio - (1.0 - (-1.0f64).exp())).abs() < 0.05, "{ratio}");
    }

    /// A ramp (50 N/s) is followed with the lag of a first-order filter: K⁻¹ = 10 ms behind.
    #[test]
    fn a_ramped_hand_force_is_followed_with_the_filters_lag() {
        let robot = Robot::embedded_default().expect("robot");
        let est = pushed(&robot, |t| Vector3::new(-50.0 * t, 0.0, 0.0), 100);
        for (t, w) in est.iter().filter(|(t, _)| *t >= 0.06) {
            let lagged = -50.0 * (t - 0.01);
            assert!(
                (w.hand[0] - lagged).abs() < 0.1,
                "t = {t}: {} vs {lagged}",
                w.hand[0]
            );
        }
    }

    /// The same push read through torque estimates with `config/sim.toml`'s MT-1 (σ 0.5 % and
    /// Coulomb friction 2 % of each joint's effort limit, viscous 0.05 N·m·s/rad): the hand's
    /// force within 1.5 N RMS from 50 ms on (the arm's few N·m of friction over its lever); with
    /// the friction compensated (WO-6) as identified, within 0.5 N, and with half of it, in
    /// between.
    #[test]
    fn a_hand_force_is_recovered_through_noisy_biased_torque_estimates() {
        let rms_with = |coulomb: f64, viscous: f64| {
            use rand::SeedableRng;
            use rand_distr::{Distribution, StandardNormal};
            let robot = Robot::embedded_default().expect("robot");
            let f = Vector3::new(-4.0, 2.4, 1.6);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let gains = WrenchObserverGains {
                friction: DriveFriction {
                    coulomb,
                    velocity: 0.05,
                    viscous,
                },
                ..FIRST_ORDER
            };
            let est = pushed_measured(
                &robot,
                |_| f,
                200,
                gains,
                0.0,
                |_, v, e| {
                    let n: f64 = StandardNormal.sample(&mut rng);
                    0.02 * e * (v / 0.05).tanh() + 0.05 * v + 0.005 * e * n
                },
            );
            let errs: Vec<f64> = est
                .iter()
                .filter(|(t, _)| *t >= 0.05)
                .map(|(_, w)| (Vector3::from(w.hand) - f).norm())
                .collect();
            (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
        };
        let (none, half, full) = (
            rms_with(0.0, 0.0),
            rms_with(0.01, 0.025),
            rms_with(0.02, 0.05),
        );
        eprintln!(
            "hand force RMS error: {none:.3} N, half compensated {half:.3}, compensated {full:.3}"
        );
        assert!(none < 1.5, "RMS {none} N");
        assert!(full < 0.5, "compensated: RMS {full} N");
        assert!(full < half && half < none, "{none} {half} {full}");
    }

    /// WO-5: two stages at K = K₂ = 100/s follow a ramp 1/K + 1/K₂ = 20 ms behind, the lag
    /// [`WrenchObserver::lag`] declares.
    #[test]
    fn the_second_stage_lags_a_ramp_by_its_time_constant() {
        let robot = Robot::embedded_default().expect("robot");
        let gains = WrenchObserverGains {
            filter_gain: 100.0,
            hand_bandwidth: 0.0,
            ..FIRST_ORDER
        };
        let est = pushed_measured(
            &robot,
            |t| Vector3::new(-50.0 * t, 0.0, 0.0),
            150,
            gains,
            0.0,
            |_, _, _| 0.0,
        );
        let lag = 0.02;
        for (t, w) in est.iter().filter(|(t, _)| *t >= 0.1) {
            let lagged = -50.0 * (t - lag);
            assert!(
                (w.hand[0] - lagged).abs() < 0.15,
                "t = {t}: {} vs {lagged}",
                w.hand[0]
            );
        }
    }

    /// WO-7: the hand's own stage (ω = 30/s) beside WO-5's (K = 100/s, K₂ = 50/s) follows a
    /// ramp (10 N/s) WO-2's 1/K = 10 ms behind, the lag [`WrenchObserver::hand_lag`] declares, where the
    /// hand read from WO-5's residual is 1/K + 1/K₂ = 30 ms behind.
    #[test]
    fn the_hands_stage_follows_a_ramp_with_the_first_stages_lag_alone() {
        let robot = Robot::embedded_default().expect("robot");
        let cascade = WrenchObserverGains {
            filter_gain: 50.0,
            ..FIRST_ORDER
        };
        let tracked = WrenchObserverGains {
            hand_bandwidth: 30.0,
            ..cascade
        };
        for (gains, lag) in [(cascade, 0.03), (tracked, 0.01)] {
            let declared = observer_of(&robot, gains).hand_lag();
            assert!((declared - lag).abs() < 1e-12, "{declared} vs {lag}");
            // 10 N/s: the floating arm swings less than under the 50 N/s above, for longer.
            let ramp = |t: f64| Vector3::new(-10.0 * t, 0.0, 0.0);
            let est = pushed_measured(&robot, ramp, 300, gains, 0.0, |_, _, _| 0.0);
            // WO-7's transient decays as e^(−ζω t): under 2 % of its start by 0.2 s; the floating
            // arm swings further from 0.3 s on, which both estimates follow late. The
            // bound is 5 ms of the ramp, a quarter of the two lags' difference.
            for (t, w) in est.iter().filter(|(t, _)| *t >= 0.2 && *t < 0.3) {
                let lagged = -10.0 * (t - lag);
                assert!(
                    (w.hand[0] - lagged).abs() < 0.05,
                    "lag {lag}: t = {t}: {} vs {lagged}",
                    w.hand[0]
                );
            }
        }
    }

    /// WO-8: WO-7 (ω = 30/s) read ahead by 1/K follows the same ramp without lag, as
    /// [`WrenchObserver::hand_lag`] declares (the bound is 5 ms of the ramp, half of WO-7's
    /// lag without WO-8: the floating arm's swing moves the error by ±4 ms); and the encoders'
    /// velocity noise reaches it by about a₁ + a₂/K against WO-7's a₁ (51/42; asserted: more,
    /// but under 1.3 times).
    #[test]
    fn the_hand_read_ahead_follows_a_ramp_without_lag() {
        let robot = Robot::embedded_default().expect("robot");
        let tracked = WrenchObserverGains {
            filter_gain: 50.0,
            hand_bandwidth: 30.0,
            ..FIRST_ORDER
        };
        let lead = WrenchObserverGains {
            hand_lead: true,
            ..tracked
        };
        let declared = observer_of(&robot, lead).hand_lag();
        assert!(declared.abs() < 1e-12, "declared {declared}");
        let ramp = |t: f64| Vector3::new(-10.0 * t, 0.0, 0.0);
        let est = pushed_measured(&robot, ramp, 300, lead, 0.0, |_, _, _| 0.0);
        for (t, w) in est.iter().filter(|(t, _)| *t >= 0.2 && *t < 0.3) {
            let truth = -10.0 * t;
            assert!(
                (w.hand[0] - truth).abs() < 0.05,
                "t = {t}: {} vs {truth}",
                w.hand[0]
            );
        }
        // The noise alone: the same push read with and without the encoders' noise.
        let f = |_| Vector3::new(-4.0, 2.4, 1.6);
        let noise = |gains: WrenchObserverGains| {
            let noisy = pushed_measured(&robot, f, 300, gains, 0.01, |_, _, _| 0.0);
            let exact = pushed_measured(&robot, f, 300, gains, 0.0, |_, _, _| 0.0);
            let errs: Vec<f64> = noisy
                .iter()
                .zip(&exact)
                .filter(|((t, _), _)| *t >= 0.1)
                .map(|((_, a), (_, b))| (Vector3::from(a.hand) - Vector3::from(b.hand)).norm())
                .collect();
            (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
        };
        let (without, with) = (noise(tracked), noise(lead));
        eprintln!("hand force noise: WO-7 {without:.3} N, read ahead (WO-8) {with:.3} N");
        assert!(
            with > without && with < 1.3 * without,
            "{with} against {without}"
        );
    }

    /// WO-5 against the velocities' noise: at the same mean lag (20 ms), K = 50/s alone against
    /// K = K₂ = 100/s, with white noise of 0.01 rad/s on every joint velocity the observer
    /// reads (the encoders' of `config/sim.toml`). Theory (WO-5): a third of the noise at
    /// 1 kHz; asserted: under half.
    #[test]
    fn the_second_stage_cuts_the_velocity_noise_at_the_same_lag() {
        let robot = Robot::embedded_default().expect("robot");
        let f = Vector3::new(-4.0, 2.4, 1.6);
        let rms = |gains: WrenchObserverGains| {
            let est = pushed_measured(&robot, |_| f, 300, gains, 0.01, |_, _, _| 0.0);
            let errs: Vec<f64> = est
                .iter()
                .filter(|(t, _)| *t >= 0.1)
                .map(|(_, w)| (Vector3::from(w.hand) - f).norm())
                .collect();
            (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
        };
        let one = rms(WrenchObserverGains {
            gain: 50.0,
            ..FIRST_ORDER
        });
        let two = rms(WrenchObserverGains {
            filter_gain: 100.0,
            hand_bandwidth: 0.0,
            ..FIRST_ORDER
        });
        eprintln!("hand force noise: K = 50 alone {one:.3} N, K = K₂ = 100 {two:.3} N");
        assert!(two < 0.5 * one, "{two} against {one}");
    }
}
