//! Eq. (26) (docs/gain_search.md) as a function of the gain schedule, with the CoM jerks
//! eliminated by an exact LQ solve (for fixed gains the problem in u is LQ), and its
//! Gauss–Newton Jacobian.
//!
//! The cost is a sum of squares, ½‖r‖², with residual rows (N = horizon, i = 1…N):
//!   ZMP     √Q_e (p_a,i − p^ref_a,i)             2N   (p: eq. 11, with the F_dis of eq. 25)
//!   jerk    √R u_a,i−1                             2N
//!   hand    √Q_t,s (x̂_s,c,i − x̂^des_s,c,i)        9N   (s: pos/vel/acc, c: x/y/z)
//!   gains   √S K_p,i, √S K_d,i                     2N
//!   changes √T_w ΔK_p,i, √T_w ΔK_d,i               2N   (ΔK_1 against the gains applied now)

use faer::Mat;
use nalgebra::{DMatrix, DVector, Vector3};

use super::KnotSchedule;
use crate::preview::{
    AxisState, GainSchedule, HandPreviewer, HandState, PreviewError, PreviewPlan, ZmpPreview,
};

/// Weights of eq. (26) beyond the preview controller's Q_e and R.
#[derive(Debug, Clone, Copy)]
pub struct Eq26Weights {
    pub q_t: [f64; 3],
    pub s: f64,
    pub t_w: f64,
}

/// A snapshot of everything one gain search needs, all horizon samples at k+1…k+N.
#[derive(Debug, Clone, Copy)]
pub struct GainSearchInputs<'a> {
    pub com: [AxisState; 2],
    pub zmp_ref: &'a [[f64; 2]],
    pub hand: HandState,
    pub hand_desired: &'a [HandState],
    pub f_ext: &'a [[f64; 3]],
    /// The gains applied now, [K_p, K_d]: ΔK of the first step is taken against them.
    pub applied: [f64; 2],
}

/// Workspace to evaluate eq. (26) and its Jacobian; allocated once per horizon.
pub struct Eq26 {
    pub(crate) zmp: ZmpPreview,
    pub(crate) hand: HandPreviewer,
    pub(crate) weights: Eq26Weights,
    horizon: usize,
    pub(crate) gains: GainSchedule,
    plan: PreviewPlan,
    pub(crate) residual: Vec<f64>,
    pub(crate) jacobian: Mat<f64>,
    // Scratch for the projected Jacobian columns.
    dp: [Vec<f64>; 2],
    target: Vec<f64>,
    ff: Vec<f64>,
    du: Vec<f64>,
    dx: Vec<AxisState>,
    pub(crate) evaluations: usize,
}

impl Eq26 {
    pub fn new(
        zmp: ZmpPreview,
        hand: HandPreviewer,
        weights: Eq26Weights,
        max_params: usize,
    ) -> Self {
        let n = zmp.horizon();
        Self {
            zmp,
            hand,
            weights,
            horizon: n,
            gains: GainSchedule::constant(n, 1.0, 1.0),
            plan: PreviewPlan::with_capacity(n),
            residual: vec![0.0; 17 * n],
            jacobian: Mat::zeros(17 * n, max_params),
            dp: [vec![0.0; n], vec![0.0; n]],
            target: vec![0.0; n],
            ff: vec![0.0; n],
            du: vec![0.0; n],
            dx: vec![Vector3::zeros(); n],
            evaluations: 0,
        }
    }

    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// g_k of eq. (26) for the per-step gains in `self.gains`; fills the residual vector and
    /// leaves the hand prediction and the CoM plan of these gains in the workspace.
    pub(crate) fn evaluate_gains(&mut self, inp: &GainSearchInputs) -> Result<f64, PreviewError> {
        let n = self.horizon;
        self.evaluations += 1;
        self.hand
            .predict(&inp.hand, inp.hand_desired, &self.gains, inp.f_ext, n)?;
        self.zmp
            .solve_c1(&inp.com, inp.zmp_ref, self.hand.disturbance())?;
        self.zmp.plan(&inp.com, &mut self.plan);
        let w = &self.weights;
        let (sq_e, sq_r) = (self.zmp.q_e.sqrt(), self.zmp.r.sqrt());
        let sq_t = w.q_t.map(f64::sqrt);
        let (sq_s, sq_tw) = (w.s.sqrt(), w.t_w.sqrt());
        let r = &mut self.residual;
        for a in 0..2 {
            for i in 0..n {
                r[a * n + i] = sq_e * (self.plan.zmp[a][i] - inp.zmp_ref[i][a]);
                r[(2 + a) * n + i] = sq_r * self.plan.jerk[a][i];
            }
        }
        for (i, x) in self.hand.states().iter().enumerate() {
            let d = &inp.hand_desired[i];
            for c in 0..3 {
                r[(4 + c) * n + i] = sq_t[0] * (x.pos[c] - d.pos[c]);
                r[(7 + c) * n + i] = sq_t[1] * (x.vel[c] - d.vel[c]);
                r[(10 + c) * n + i] = sq_t[2] * (x.acc[c] - d.acc[c]);
            }
        }
        for i in 0..n {
            let (kp, kd) = (self.gains.kp[i], self.gains.kd[i]);
            let (pkp, pkd) = if i == 0 {
                (inp.applied[0], inp.applied[1])
            } else {
                (self.gains.kp[i - 1], self.gains.kd[i - 1])
            };
            r[13 * n + i] = sq_s * kp;
            r[14 * n + i] = sq_s * kd;
            r[15 * n + i] = sq_tw * (kp - pkp);
            r[16 * n + i] = sq_tw * (kd - pkd);
        }
        Ok(0.5 * r.iter().map(|v| v * v).sum::<f64>())
    }

    /// g_k of eq. (26) for a knot vector θ.
    pub fn evaluate(
        &mut self,
        knots: &KnotSchedule,
        theta: &[f64],
        inp: &GainSearchInputs,
    ) -> Result<f64, PreviewError> {
        knots.expand(theta, &mut self.gains);
        self.evaluate_gains(inp)
    }

    /// The Jacobian of the residual with respect to θ at the point of the last evaluation, with
    /// the jerks re-optimised (the LQ-projected columns: exact Gauss–Newton of the joint problem
    /// in (u, θ) with u eliminated). Column j goes to `self.jacobian[:, j]`.
    pub(crate) fn jacobian(&mut self, knots: &KnotSchedule, inp: &GainSearchInputs) {
        let n = self.horizon;
        let t = self.hand.period();
        let m_e = *self.hand.effective_mass();
        let w = self.weights;
        let (sq_e, sq_r) = (self.zmp.q_e.sqrt(), self.zmp.r.sqrt());
        let sq_t = w.q_t.map(f64::sqrt);
        let (sq_s, sq_tw) = (w.s.sqrt(), w.t_w.sqrt());
        let model = self.zmp.model;
        let (mass, zc) = (model.mass, model.com_height);
        for j in 0..knots.dim() {
            let mut col = self.jacobian.col_mut(j);
            col.fill(0.0);
            let support = knots.support(j);
            // Tangent of the hand recursion (eq. 24) and of F_dis (eq. 25) along θ_j.
            let (mut dpos, mut dvel, mut dacc) =
                (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
            let (_, _, dist) = self.zmp.last_problem();
            for a in 0..2 {
                self.dp[a][..support.start].fill(0.0);
            }
            let mut prev = (0.0, 0.0);
            for i in support.start..n {
                let x = &self.hand.states()[i];
                let d = &inp.hand_desired[i];
                let (dkp, dkd) = if i < support.end {
                    knots.derivative(j, i, self.gains.kp[i])
                } else {
                    (0.0, 0.0)
                };
                let np = dpos + dvel * t + dacc * (t * t / 2.0);
                let nv = dvel + dacc * t;
                let dcmd = (d.pos - x.pos) * dkp - np * self.gains.kp[i] + (d.vel - x.vel) * dkd
                    - nv * self.gains.kd[i];
                dpos = np;
                dvel = nv;
                dacc = dcmd;
                let df = -(m_e * dcmd);
                for c in 0..3 {
                    col[(4 + c) * n + i] = sq_t[0] * dpos[c];
                    col[(7 + c) * n + i] = sq_t[1] * dvel[c];
                    col[(10 + c) * n + i] = sq_t[2] * dacc[c];
                }
                col[13 * n + i] = sq_s * dkp;
                col[14 * n + i] = sq_s * dkd;
                col[15 * n + i] = sq_tw * (dkp - prev.0);
                col[16 * n + i] = sq_tw * (dkd - prev.1);
                prev = (dkp, dkd);
                // ZMP at fixed CoM trajectory, eq. (10): p = x + c2 ẍ + z_c α, c2 = −M z_c α0,
                // α0 = 1/(Mg − F_z), α = F_a α0.
                let f = self.hand.disturbance()[i];
                let alpha0 = dist.alpha0[i];
                let d_alpha0 = alpha0 * alpha0 * df[2];
                for a in 0..2 {
                    let acc = self.plan.com[a][i][2];
                    self.dp[a][i] =
                        -mass * zc * d_alpha0 * acc + zc * (df[a] * alpha0 + f[a] * d_alpha0);
                }
            }
            // Re-optimise the jerks against this ZMP change: LQ from x0 = 0 with target −dp.
            let (c2, riccati, _) = self.zmp.last_problem();
            let q_e = self.zmp.q_e;
            for a in 0..2 {
                for i in 0..n {
                    self.target[i] = -self.dp[a][i];
                }
                riccati.feedforward_into(&model, q_e, c2, &self.target, &mut self.ff);
                riccati.rollout_with(
                    &model,
                    &self.ff,
                    &Vector3::zeros(),
                    &mut self.du,
                    &mut self.dx,
                );
                for i in 0..n {
                    col[a * n + i] = sq_e * (self.dp[a][i] + self.dx[i][0] + c2[i] * self.dx[i][2]);
                    col[(2 + a) * n + i] = sq_r * self.du[i];
                }
            }
        }
    }

    /// Gauss–Newton normal equations JᵀJ and Jᵀr from the last [`Eq26::jacobian`].
    pub(crate) fn normal_equations(&self, dim: usize) -> (DMatrix<f64>, DVector<f64>) {
        let jac = self.jacobian.as_ref().subcols(0, dim);
        let jtj = jac.transpose() * jac;
        let h = DMatrix::from_fn(dim, dim, |a, b| jtj[(a, b)]);
        let g = DVector::from_fn(dim, |a, _| {
            jac.col(a)
                .iter()
                .zip(&self.residual)
                .map(|(x, y)| x * y)
                .sum()
        });
        (h, g)
    }

    /// The gradient of eq. (26) with respect to θ (the jerks re-optimised at every θ).
    pub fn gradient(
        &mut self,
        knots: &KnotSchedule,
        theta: &[f64],
        inp: &GainSearchInputs,
    ) -> Result<Vec<f64>, PreviewError> {
        self.evaluate(knots, theta, inp)?;
        self.jacobian(knots, inp);
        Ok(self
            .normal_equations(knots.dim())
            .1
            .iter()
            .copied()
            .collect())
    }
}
