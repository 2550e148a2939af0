//! C0 and C1: ZMP preview control of the CoM along x and y (docs/preview_control.md,
//! docs/disturbance.md, eq. (1)–(16)).

use nalgebra::{Matrix3, Vector3};

use super::dense::CondensedHorizon;
use super::{CartTable, Disturbance, PreviewError, Riccati};
use crate::config::LqSolverKind;

/// The cart-table state [x, ẋ, ẍ] of one axis.
pub type AxisState = Vector3<f64>;

/// ZMP preview controller with its preallocated workspace. One instance per control loop; the
/// Riccati path (the default) allocates nothing per solve.
#[derive(Debug, Clone)]
pub struct ZmpPreview {
    pub model: CartTable,
    pub q_e: f64,
    pub r: f64,
    horizon: usize,
    solver: LqSolverKind,
    disturbance: Disturbance,
    c2: Vec<f64>,
    targets: [Vec<f64>; 2],
    riccati: Riccati,
    /// Output rows of the current factorisation: with an unchanged α0 horizon (no vertical
    /// disturbance, or C0) the gains are reused and a solve is two O(N) dot products.
    factored_c2: Vec<f64>,
    factored: bool,
    ff: [Vec<f64>; 2],
    /// PC-T's P_tail for the dense reference (the Riccati solver keeps its own).
    tail: Option<Matrix3<f64>>,
}

/// The predicted horizon of the last solve: jerks u_0…u_{N−1}, CoM states and ZMP at k+1…k+N.
#[derive(Debug, Clone)]
pub struct PreviewPlan {
    pub jerk: [Vec<f64>; 2],
    pub com: [Vec<AxisState>; 2],
    pub zmp: [Vec<f64>; 2],
}

impl PreviewPlan {
    pub fn with_capacity(n: usize) -> Self {
        Self {
            jerk: [vec![0.0; n], vec![0.0; n]],
            com: [vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]],
            zmp: [vec![0.0; n], vec![0.0; n]],
        }
    }
}

impl ZmpPreview {
    pub fn new(model: CartTable, q_e: f64, r: f64, horizon: usize, solver: LqSolverKind) -> Self {
        Self {
            model,
            q_e,
            r,
            horizon,
            solver,
            disturbance: Disturbance::with_capacity(horizon),
            c2: vec![0.0; horizon],
            targets: [vec![0.0; horizon], vec![0.0; horizon]],
            riccati: Riccati::with_capacity(horizon),
            factored_c2: vec![0.0; horizon],
            factored: false,
            ff: [vec![0.0; horizon], vec![0.0; horizon]],
            tail: None,
        }
    }

    /// With `on`, the last predicted state pays the infinite horizon's tail (PC-T,
    /// `preview.terminal_cost`; docs/preview_control.md); without, the paper's finite horizon.
    pub fn with_terminal_cost(mut self, on: bool) -> Self {
        self.riccati.set_tail(&self.model, self.q_e, self.r, on);
        self.tail = on.then(|| self.model.infinite_tail(self.q_e, self.r));
        self.factored = false;
        self
    }

    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The spectral radius of C0's receding-horizon loop x ← (A + B K_0) x on the undisturbed
    /// cart-table: below 1, an offset CoM returns to a held reference. Factorises (set-up only).
    pub fn closed_loop_radius(&mut self) -> f64 {
        let n = self.horizon;
        let c2 = self.model.output_acc_coeff(self.model.nominal_alpha0());
        self.c2[..n].fill(c2);
        self.factored = false;
        self.riccati
            .factor(&self.model, self.q_e, self.r, &self.c2[..n]);
        let k = self.riccati.first_gain();
        (self.model.a() + self.model.b() * k)
            .complex_eigenvalues()
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max)
    }

    /// A start-up check (PC-T): with the tail the loop is the infinite horizon's, stable for
    /// any robot; without it, a horizon too short for the robot's pendulum (a tall robot at the
    /// paper's 1.5 s) is refused, naming the horizon that would do.
    pub fn check_holds_the_com(&mut self) -> Result<(), PreviewError> {
        if self.tail.is_some() {
            return Ok(());
        }
        let radius = self.closed_loop_radius();
        if radius < 1.0 {
            return Ok(());
        }
        let mut longer = self.horizon;
        let stable_from = loop {
            longer += longer.div_ceil(8);
            if longer > 20_000 {
                break None;
            }
            let mut p = ZmpPreview::new(self.model, self.q_e, self.r, longer, self.solver);
            if p.closed_loop_radius() < 1.0 {
                break Some(longer);
            }
        };
        Err(PreviewError::UnstableHorizon {
            horizon: self.horizon,
            seconds: self.horizon as f64 * self.model.period,
            com_height: self.model.com_height,
            radius,
            stable_from,
        })
    }

    /// C0 (Kajita–Wieber): track `zmp_ref` (samples at k+1…k+N, [x, y]) ignoring any disturbance.
    /// Returns the CoM jerk to apply now, [u_x, u_y].
    pub fn solve_c0(
        &mut self,
        state: &[AxisState; 2],
        zmp_ref: &[[f64; 2]],
    ) -> Result<[f64; 2], PreviewError> {
        self.disturbance.set_none(&self.model, self.horizon)?;
        self.solve(state, zmp_ref)
    }

    /// C1: the same on the disturbed model, with the CoM-disturbance forecast `f_dis`
    /// (3-D, samples at k+1…k+N).
    pub fn solve_c1(
        &mut self,
        state: &[AxisState; 2],
        zmp_ref: &[[f64; 2]],
        f_dis: &[[f64; 3]],
    ) -> Result<[f64; 2], PreviewError> {
        self.disturbance
            .set_forces(&self.model, f_dis, self.horizon)?;
        self.solve(state, zmp_ref)
    }

    fn solve(
        &mut self,
        state: &[AxisState; 2],
        zmp_ref: &[[f64; 2]],
    ) -> Result<[f64; 2], PreviewError> {
        let n = self.horizon;
        if zmp_ref.len() < n {
            return Err(PreviewError::ForecastTooShort {
                what: "ZMP reference",
                got: zmp_ref.len(),
                need: n,
            });
        }
        for axis in 0..2 {
            if !state[axis].iter().all(|v| v.is_finite()) {
                return Err(PreviewError::NotFinite {
                    what: "CoM state",
                    step: 0,
                });
            }
        }
        // Loops over slices without an early exit or an index check (they vectorise); a
        // non-finite reference sample makes its target non-finite (α is finite), found after.
        let zmp_ref = &zmp_ref[..n];
        let (m, d) = (&self.model, &self.disturbance);
        for (c2, a0) in self.c2[..n].iter_mut().zip(&d.alpha0[..n]) {
            *c2 = m.output_acc_coeff(*a0);
        }
        let mut finite = true;
        for (axis, target) in self.targets.iter_mut().enumerate() {
            for ((t, z), shift) in target[..n].iter_mut().zip(zmp_ref).zip(d.shifts(m, axis)) {
                // eq. (16): p_rd = p_ref − D.
                *t = z[axis] - shift;
                finite &= t.is_finite();
            }
        }
        if !finite
            && let Some(i) = zmp_ref
                .iter()
                .position(|z| !z.iter().all(|v| v.is_finite()))
        {
            return Err(PreviewError::NotFinite {
                what: "ZMP reference",
                step: i + 1,
            });
        }
        let refactor = !self.factored || self.factored_c2[..n] != self.c2[..n];
        if refactor {
            self.factored_c2[..n].copy_from_slice(&self.c2[..n]);
            self.factored = true;
        }
        match self.solver {
            // New output rows (α0 moved): one fused backward pass gives the gains and both
            // first inputs. Same rows as last time: the stored preview gains, two dot products.
            LqSolverKind::Riccati if refactor => Ok(self.riccati.factor_first_inputs(
                &self.model,
                self.q_e,
                self.r,
                &self.c2[..n],
                [&self.targets[0][..n], &self.targets[1][..n]],
                [&state[0], &state[1]],
            )),
            LqSolverKind::Riccati => {
                self.riccati
                    .ensure_preview_gains(&self.model, self.q_e, &self.c2[..n]);
                Ok([0, 1].map(|a| self.riccati.first_input(&state[a], &self.targets[a][..n])))
            }
            LqSolverKind::Dense => {
                if refactor {
                    self.riccati
                        .factor(&self.model, self.q_e, self.r, &self.c2[..n]);
                }
                let horizon =
                    CondensedHorizon::build(&self.model, &self.c2[..n], self.tail.as_ref());
                let u = horizon
                    .solve(
                        self.q_e,
                        self.r,
                        [&state[0], &state[1]],
                        [&self.targets[0][..n], &self.targets[1][..n]],
                    )
                    .ok_or_else(|| {
                        PreviewError::Qp("dense normal matrix is not positive definite".into())
                    })?;
                Ok([u[0][0], u[1][0]])
            }
        }
    }

    /// The predicted horizon of the last solve from `state` (CoM states, jerks and the ZMP that the
    /// disturbed model predicts, eq. (11)); `false`, `out` untouched, before any solve (a
    /// controller whose first states were bad has no gains yet).
    pub fn plan(&mut self, state: &[AxisState; 2], out: &mut PreviewPlan) -> bool {
        if self.riccati.is_empty() {
            return false;
        }
        let n = self.horizon;
        for axis in 0..2 {
            let ff = &mut self.ff[axis][..n];
            self.riccati.feedforward_into(
                &self.model,
                self.q_e,
                &self.c2[..n],
                &self.targets[axis][..n],
                ff,
            );
            self.riccati.rollout_with(
                &self.model,
                ff,
                &state[axis],
                &mut out.jerk[axis][..n],
                &mut out.com[axis][..n],
            );
            for i in 0..n {
                out.zmp[axis][i] = self.model.zmp(
                    &out.com[axis][i],
                    self.disturbance.alpha0[i],
                    self.disturbance.alpha[axis][i],
                );
            }
        }
        true
    }

    /// The ZMP the model predicts one preview step ahead after applying `u` from `state`
    /// (eq. 11, first row), O(1): the first sample of [`ZmpPreview::plan`]'s ZMP.
    pub fn next_zmp(&self, state: &[AxisState; 2], u: [f64; 2]) -> [f64; 2] {
        [0, 1].map(|a| {
            let x1 = self.model.step(&state[a], u[a]);
            self.model.zmp(
                &x1,
                self.disturbance.alpha0[0],
                self.disturbance.alpha[a][0],
            )
        })
    }

    /// Output-row coefficients c2 and references of the last solve (for C2's Jacobians).
    pub(crate) fn last_problem(&self) -> (&[f64], &Riccati, &Disturbance) {
        (&self.c2[..self.horizon], &self.riccati, &self.disturbance)
    }
}
