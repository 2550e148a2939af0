//! The finite-horizon LQ problem of SPEC §2–3 solved by backward Riccati recursion, O(N).
//!
//! Problem (one axis; both axes share the output rows, hence the feedback gains):
//!   min ½ Σ_{j=1..N} Q_e (c_j·x_j − t_j)² + ½ Σ_{i=0..N−1} R u_i²,   x_{i+1} = A x_i + B u_i,
//! with c_j = [1, 0, c2_j] the (time-varying) output row of eq. (10) and t_j = p_ref − D the
//! disturbed reference of eq. (16). It is the problem whose condensed solution is eq. (9)/(15).
//! Horizon arrays are indexed from 0: `c2[j−1]`, `t[j−1]` belong to x_j.
//!
//! The recursions are written out for the cart-table's A (upper triangular, ones on the
//! diagonal) and a symmetric P kept as its six distinct entries: this is the per-tick hot path.

use nalgebra::{RowVector3, Vector3};

use super::CartTable;

/// Symmetric 3×3 cost-to-go matrix, upper triangle.
#[derive(Debug, Clone, Copy)]
struct Sym3 {
    p00: f64,
    p01: f64,
    p02: f64,
    p11: f64,
    p12: f64,
    p22: f64,
}

/// Riccati workspace: feedback gains K_i, 1/H_i and the preview gains of the first input.
#[derive(Debug, Clone)]
pub struct Riccati {
    gain: Vec<RowVector3<f64>>,
    inv_h: Vec<f64>,
    preview_gain: Vec<f64>,
    len: usize,
}

impl Riccati {
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            gain: vec![RowVector3::zeros(); capacity],
            inv_h: vec![0.0; capacity],
            preview_gain: vec![0.0; capacity],
            len: 0,
        }
    }

    pub fn capacity(&self) -> usize {
        self.inv_h.len()
    }

    /// Horizon of the last factorisation.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Backward pass of the cost-to-go matrix P: the feedback gains u_i = K_i x_i + k_i, which
    /// depend only on the output rows (α0), not on the references. Also computes the preview
    /// gains f_j of the first input, u_0 = K_0 x_0 + Σ_j f_j t_j (Kajita's preview gains).
    ///
    /// Precondition (checked by the callers that take user input): 1 ≤ `c2.len()` ≤ capacity.
    pub fn factor(&mut self, model: &CartTable, q_e: f64, r: f64, c2: &[f64]) {
        let n = c2.len();
        debug_assert!(n >= 1 && n <= self.capacity());
        let t = model.period;
        let t2 = t * t / 2.0;
        let [b0, b1, b2] = [t * t * t / 6.0, t2, t];
        // P_N = Q_e c_Nᵀ c_N, c = [1, 0, c2].
        let cn = c2[n - 1];
        let mut p = Sym3 {
            p00: q_e,
            p01: 0.0,
            p02: q_e * cn,
            p11: 0.0,
            p12: 0.0,
            p22: q_e * cn * cn,
        };
        // H = R + Bᵀ P B summed as a balanced tree straight from P: the division by H is the
        // recursion's latency bottleneck, so nothing else waits in front of it.
        let (w00, w11, w22) = (b0 * b0, b1 * b1, b2 * b2);
        let (w01, w02, w12) = (2.0 * b0 * b1, 2.0 * b0 * b2, 2.0 * b1 * b2);
        for i in (0..n).rev() {
            let h = ((r + w00 * p.p00) + (w11 * p.p11 + w22 * p.p22))
                + ((w01 * p.p01 + w02 * p.p02) + w12 * p.p12);
            let inv_h = 1.0 / h;
            let pb0 = p.p00 * b0 + p.p01 * b1 + p.p02 * b2;
            let pb1 = p.p01 * b0 + p.p11 * b1 + p.p12 * b2;
            let pb2 = p.p02 * b0 + p.p12 * b1 + p.p22 * b2;
            // G = Bᵀ P A.
            let g0 = pb0;
            let g1 = t * pb0 + pb1;
            let g2 = t2 * pb0 + t * pb1 + pb2;
            self.gain[i] = RowVector3::new(-g0 * inv_h, -g1 * inv_h, -g2 * inv_h);
            self.inv_h[i] = inv_h;
            if i > 0 {
                // P_i = Aᵀ P A + Q_e c_iᵀ c_i − Gᵀ H⁻¹ G (Riccati difference equation).
                let m01 = t * p.p00 + p.p01;
                let m11 = t * p.p01 + p.p11;
                let m02 = t2 * p.p00 + t * p.p01 + p.p02;
                let m12 = t2 * p.p01 + t * p.p11 + p.p12;
                let m22 = t2 * p.p02 + t * p.p12 + p.p22;
                let c = c2[i - 1];
                p = Sym3 {
                    p00: (p.p00 + q_e) - (g0 * g0) * inv_h,
                    p01: m01 - (g0 * g1) * inv_h,
                    p02: (m02 + q_e * c) - (g0 * g2) * inv_h,
                    p11: (t * m01 + m11) - (g1 * g1) * inv_h,
                    p12: (t * m02 + m12) - (g1 * g2) * inv_h,
                    p22: (t2 * m02 + t * m12 + m22 + q_e * c * c) - (g2 * g2) * inv_h,
                };
            }
        }
        // Preview gains: k_0 = −H_0⁻¹ Bᵀ s_1 with s_1 = −Q_e Σ_j Φ_jᵀ c_j t_j and
        // Φ_j = (A + B K_{j−1}) ⋯ (A + B K_1); so f_j = H_0⁻¹ Q_e c_j·v_j, v_1 = B,
        // v_{j+1} = (A + B K_j) v_j: the closed-loop response to the first input.
        let a = model.a();
        let b = model.b();
        let mut v = b;
        let scale = self.inv_h[0] * q_e;
        for j in 1..=n {
            self.preview_gain[j - 1] = scale * (v[0] + c2[j - 1] * v[2]);
            if j < n {
                v = a * v + b * (self.gain[j] * v)[0];
            }
        }
        self.len = n;
    }

    /// u_0 = K_0 x_0 + Σ_j f_j t_j: the first input for references `t`, O(N) without a pass
    /// over the cost-to-go.
    pub fn first_input(&self, x0: &Vector3<f64>, t: &[f64]) -> f64 {
        let n = self.len;
        let ff: f64 = self.preview_gain[..n]
            .iter()
            .zip(&t[..n])
            .map(|(f, t)| f * t)
            .sum();
        (self.gain[0] * x0)[0] + ff
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
        let dt = model.period;
        let dt2 = dt * dt / 2.0;
        let [b0, b1, b2] = [dt * dt * dt / 6.0, dt2, dt];
        // s_N = −Q_e c_N t_N.
        let w = -q_e * t[n - 1];
        let (mut s0, mut s1, mut s2) = (w, 0.0, w * c2[n - 1]);
        for i in (0..n).rev() {
            let h = b0 * s0 + b1 * s1 + b2 * s2;
            ff[i] = -h * self.inv_h[i];
            if i > 0 {
                // s_i = Aᵀ s + K_iᵀ (Bᵀ s) − Q_e c_i t_i.
                let k = &self.gain[i];
                let w = -q_e * t[i - 1];
                let n0 = s0 + k[0] * h + w;
                let n1 = dt * s0 + s1 + k[1] * h;
                let n2 = dt2 * s0 + dt * s1 + s2 + k[2] * h + w * c2[i - 1];
                (s0, s1, s2) = (n0, n1, n2);
            }
        }
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
}
