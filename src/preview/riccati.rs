//! The finite-horizon LQ problem of SPEC §2–3 solved by backward Riccati recursion, O(N).
//!
//! Problem (one axis; both axes share the output rows, hence the feedback gains):
//!   min ½ Σ_{j=1..N} Q_e (c_j·x_j − t_j)² + ½ Σ_{i=0..N−1} R u_i²,   x_{i+1} = A x_i + B u_i,
//! with c_j = [1, 0, c2_j] the (time-varying) output row of eq. (10) and t_j = p_ref − D the
//! disturbed reference of eq. (16). It is the problem whose condensed solution is eq. (9)/(15).
//! Horizon arrays are indexed from 0: `c2[j−1]`, `t[j−1]` belong to x_j.

use nalgebra::{Matrix3, RowVector3, Vector3};

use super::CartTable;

/// Riccati workspace: feedback gains K_i, 1/H_i and feedforward terms, preallocated.
#[derive(Debug, Clone)]
pub struct Riccati {
    gain: Vec<RowVector3<f64>>,
    inv_h: Vec<f64>,
    ff: [Vec<f64>; 2],
    len: usize,
}

impl Riccati {
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            gain: vec![RowVector3::zeros(); capacity],
            inv_h: vec![0.0; capacity],
            ff: [vec![0.0; capacity], vec![0.0; capacity]],
            len: 0,
        }
    }

    pub fn capacity(&self) -> usize {
        self.inv_h.len()
    }

    /// Horizon of the last backward pass.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Backward pass of the cost-to-go matrix P: the feedback gains u_i = K_i x_i + k_i, which
    /// depend only on the output rows (α0), not on the references.
    ///
    /// Precondition (checked by the callers that take user input): `c2.len() ≤ capacity`, ≥ 1.
    pub fn factor(&mut self, model: &CartTable, q_e: f64, r: f64, c2: &[f64]) {
        let n = c2.len();
        debug_assert!(n >= 1 && n <= self.capacity());
        let a = model.a();
        let b = model.b();
        let row = |j: usize| RowVector3::new(1.0, 0.0, c2[j]);
        // P_N = Q_e c_Nᵀ c_N.
        let mut p: Matrix3<f64> = row(n - 1).transpose() * row(n - 1) * q_e;
        for i in (0..n).rev() {
            let pb = p * b;
            let h = r + b.dot(&pb);
            let g = pb.transpose() * a; // Bᵀ P A
            let inv_h = 1.0 / h;
            self.gain[i] = -g * inv_h;
            self.inv_h[i] = inv_h;
            if i > 0 {
                let c = row(i - 1);
                // P_i = Q_i + Aᵀ P A − Gᵀ H⁻¹ G (Riccati difference equation).
                p = a.transpose() * p * a - g.transpose() * g * inv_h + c.transpose() * c * q_e;
                p = (p + p.transpose()) * 0.5;
            }
        }
        self.len = n;
    }

    /// Backward pass of the linear cost-to-go term s for one reference sequence `t`, writing the
    /// feedforward inputs k_i into `ff`. Reuses the gains of [`Riccati::factor`].
    pub fn feedforward_into(
        &self,
        model: &CartTable,
        q_e: f64,
        c2: &[f64],
        t: &[f64],
        ff: &mut [f64],
    ) {
        let n = self.len;
        debug_assert!(c2.len() >= n && t.len() >= n && ff.len() >= n);
        let a = model.a();
        let b = model.b();
        let row = |j: usize| Vector3::new(1.0, 0.0, c2[j]);
        // s_N = −Q_e c_N t_N.
        let mut s: Vector3<f64> = row(n - 1) * (-q_e * t[n - 1]);
        for i in (0..n).rev() {
            let h = b.dot(&s);
            ff[i] = -h * self.inv_h[i];
            if i > 0 {
                // s_i = q_i + Aᵀ s + K_iᵀ (Bᵀ s), with q_i = −Q_e c_i t_i.
                s = a.tr_mul(&s) + self.gain[i].transpose() * h + row(i - 1) * (-q_e * t[i - 1]);
            }
        }
    }

    /// Feedforward for both axes (stored in the workspace).
    pub fn feedforward(&mut self, model: &CartTable, q_e: f64, c2: &[f64], targets: [&[f64]; 2]) {
        let mut ff = std::mem::take(&mut self.ff);
        for (axis, t) in targets.iter().enumerate() {
            self.feedforward_into(model, q_e, c2, t, &mut ff[axis]);
        }
        self.ff = ff;
    }

    /// u_0 = K_0 x_0 + k_0 for an axis, after [`Riccati::feedforward`].
    pub fn first_input(&self, axis: usize, x0: &Vector3<f64>) -> f64 {
        (self.gain[0] * x0)[0] + self.ff[axis][0]
    }

    /// Roll the optimal policy forward from x0 with feedforward `ff`, writing inputs u_0…u_{N−1}
    /// and states x_1…x_N.
    pub fn rollout_with(
        &self,
        model: &CartTable,
        ff: &[f64],
        x0: &Vector3<f64>,
        inputs: &mut [f64],
        states: &mut [Vector3<f64>],
    ) {
        let a = model.a();
        let b = model.b();
        let mut x = *x0;
        for i in 0..self.len {
            let u = (self.gain[i] * x)[0] + ff[i];
            x = a * x + b * u;
            inputs[i] = u;
            states[i] = x;
        }
    }

    /// [`Riccati::rollout_with`] using the stored feedforward of `axis`.
    pub fn rollout(
        &self,
        model: &CartTable,
        axis: usize,
        x0: &Vector3<f64>,
        inputs: &mut [f64],
        states: &mut [Vector3<f64>],
    ) {
        self.rollout_with(model, &self.ff[axis], x0, inputs, states)
    }
}
