//! C1 with the predicted ZMP kept inside the support bounds as hard constraints (Wieber 2006,
//! beyond the paper; docs/preview_control.md). A sparse QP over the inputs and states of both axes, solved with clarabel:
//!   min ½ Σ Q_e (c_i·x_i − t_i)² + ½ R u²   s.t.  x_{i+1} = A x_i + B u_i,
//!   p_min − D_i ≤ c_i·x_i ≤ p_max − D_i     (the true ZMP c_i·x_i + D_i inside, eq. 11).
//! The sparsity is fixed, so after the first tick only the values are updated. This mode
//! allocates (assembly and the interior-point solve); the Riccati C1 is the allocation-free path.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use nalgebra::Matrix3;

use super::{AxisState, CartTable, Disturbance, PreviewError};

pub struct ConstrainedPreview {
    model: CartTable,
    q_e: f64,
    r: f64,
    horizon: usize,
    bounds: [[f64; 2]; 2],
    disturbance: Disturbance,
    solver: Option<DefaultSolver<f64>>,
    /// PC-T's P_tail on the last state, if on.
    tail: Option<Matrix3<f64>>,
}

struct Qp {
    p: CscMatrix<f64>,
    q: Vec<f64>,
    a: CscMatrix<f64>,
    b: Vec<f64>,
}

impl ConstrainedPreview {
    /// `bounds` = [[x_min, x_max], [y_min, y_max]] of the support.
    pub fn new(model: CartTable, q_e: f64, r: f64, horizon: usize, bounds: [[f64; 2]; 2]) -> Self {
        Self {
            model,
            q_e,
            r,
            horizon,
            bounds,
            disturbance: Disturbance::with_capacity(horizon),
            solver: None,
            tail: None,
        }
    }

    /// With `on`, the last state pays the infinite horizon's tail (PC-T), as
    /// [`super::ZmpPreview::with_terminal_cost`].
    pub fn with_terminal_cost(mut self, on: bool) -> Self {
        self.tail = on.then(|| self.model.infinite_tail(self.q_e, self.r));
        self.solver = None;
        self
    }

    /// Like [`super::ZmpPreview::solve_c1`], with the ZMP bounds enforced. An infeasible bound
    /// (a disturbance no CoM motion can absorb) is an error; the caller falls back to C1.
    pub fn solve(
        &mut self,
        state: &[AxisState; 2],
        zmp_ref: &[[f64; 2]],
        f_dis: &[[f64; 3]],
    ) -> Result<[f64; 2], PreviewError> {
        let n = self.horizon;
        self.disturbance.set_forces(&self.model, f_dis, n)?;
        if zmp_ref.len() < n {
            return Err(PreviewError::ForecastTooShort {
                what: "ZMP reference",
                got: zmp_ref.len(),
                need: n,
            });
        }
        if state.iter().any(|s| s.iter().any(|v| !v.is_finite())) {
            return Err(PreviewError::NotFinite {
                what: "CoM state",
                step: 0,
            });
        }
        let qp = self.assemble(state, zmp_ref);
        let solver = match self.solver.as_mut() {
            Some(s) => {
                s.update_data(&qp.p, &qp.q, &qp.a, &qp.b)
                    .map_err(|e| PreviewError::Qp(e.to_string()))?;
                s
            }
            None => {
                let settings = DefaultSettings {
                    verbose: false,
                    presolve_enable: false,
                    ..DefaultSettings::default()
                };
                let cones = [
                    SupportedConeT::ZeroConeT(6 * n),
                    SupportedConeT::NonnegativeConeT(4 * n),
                ];
                let s = DefaultSolver::new(&qp.p, &qp.q, &qp.a, &qp.b, &cones, settings)
                    .map_err(|e| PreviewError::Qp(e.to_string()))?;
                self.solver.insert(s)
            }
        };
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {
                Ok([solver.solution.x[0], solver.solution.x[4 * n]])
            }
            status => Err(PreviewError::Qp(format!(
                "ZMP bounds cannot be met: {status:?}"
            ))),
        }
    }

    fn assemble(&self, state: &[AxisState; 2], zmp_ref: &[[f64; 2]]) -> Qp {
        let n = self.horizon;
        let m = &self.model;
        let (a, b) = (m.a(), m.b());
        let nv = 8 * n;
        let (mut pi, mut pj, mut pv) = (Vec::new(), Vec::new(), Vec::new());
        let (mut ai, mut aj, mut av) = (Vec::new(), Vec::new(), Vec::new());
        let mut q = vec![0.0; nv];
        let mut rhs = vec![0.0; 10 * n];
        for axis in 0..2 {
            let off = axis * 4 * n;
            let u = |i: usize| off + i;
            let x = |i: usize, s: usize| off + n + 3 * (i - 1) + s; // state x_i, i ≥ 1
            let ax0 = a * state[axis];
            for i in 0..n {
                let c2 = m.output_acc_coeff(self.disturbance.alpha0[i]);
                let d = self.disturbance.shift(m, axis, i);
                let t = zmp_ref[i][axis] - d;
                // Cost: R u_i² and Q_e (c·x_{i+1} − t)², upper triangle.
                pi.push(u(i));
                pj.push(u(i));
                pv.push(self.r);
                // PC-T on the last state: ½ (x_N − x̄)ᵀ P_tail (x_N − x̄), x̄ = [t_N, 0, 0].
                let tail = self
                    .tail
                    .filter(|_| i + 1 == n)
                    .unwrap_or_else(Matrix3::zeros);
                let stage = [[1.0, 0.0, c2], [0.0, 0.0, 0.0], [c2, 0.0, c2 * c2]];
                for s1 in 0..3 {
                    for s2 in s1..3 {
                        let v = self.q_e * stage[s1][s2] + tail[(s1, s2)];
                        if v != 0.0 || (s1 != 1 && s2 != 1) {
                            pi.push(x(i + 1, s1));
                            pj.push(x(i + 1, s2));
                            pv.push(v);
                        }
                    }
                }
                for (s, c) in [(0, 1.0), (1, 0.0), (2, c2)] {
                    q[x(i + 1, s)] = -self.q_e * t * c - tail[(s, 0)] * t;
                }
                // Dynamics x_{i+1} − A x_i − B u_i = 0 (x_0 known: moves to the right side).
                for s in 0..3 {
                    let row = axis * 3 * n + 3 * i + s;
                    ai.push(row);
                    aj.push(x(i + 1, s));
                    av.push(1.0);
                    ai.push(row);
                    aj.push(u(i));
                    av.push(-b[s]);
                    if i > 0 {
                        for s2 in s..3 {
                            ai.push(row);
                            aj.push(x(i, s2));
                            av.push(-a[(s, s2)]);
                        }
                    } else {
                        rhs[row] = ax0[s];
                    }
                }
                // Bounds on the true ZMP.
                let row = 6 * n + axis * 2 * n + 2 * i;
                for (sign, r) in [(1.0, row), (-1.0, row + 1)] {
                    ai.push(r);
                    aj.push(x(i + 1, 0));
                    av.push(sign);
                    ai.push(r);
                    aj.push(x(i + 1, 2));
                    av.push(sign * c2);
                }
                rhs[row] = self.bounds[axis][1] - d;
                rhs[row + 1] = d - self.bounds[axis][0];
            }
        }
        Qp {
            p: CscMatrix::new_from_triplets(nv, nv, pi, pj, pv),
            q,
            a: CscMatrix::new_from_triplets(10 * n, nv, ai, aj, av),
            b: rhs,
        }
    }
}
