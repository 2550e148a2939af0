//! The finite-horizon LQ problem of docs/preview_control.md (eq. (7), (9), (15)) solved by backward
//! Riccati recursion, O(N).
//!
//! Problem (one axis; both axes share the output rows, hence the feedback gains):
//!   min ½ Σ_{j=1..N} Q_e (c_j·x_j − t_j)² + ½ Σ_{i=0..N−1} R u_i²,   x_{i+1} = A x_i + B u_i,
//! with c_j = [1, 0, c2_j] the (time-varying) output row of eq. (10) and t_j = p_ref − D the
//! disturbed reference of eq. (16). It is the problem whose condensed solution is eq. (9)/(15).
//! Horizon arrays are indexed from 0: `c2[j−1]`, `t[j−1]` belong to x_j.
//!
//! The recursions are written out for the cart-table's A (upper triangular, ones on the
//! diagonal) and a symmetric P kept as its six distinct entries: this is the per-tick hot path.
//!
//! **The tail past the horizon** (docs/preview_control.md, PC-T). The finite sum leaves the
//! cart-table's unstable mode free after step N: on a tall robot (its time constant √(z_c/g)
//! a fifth of the horizon) the optimum puts the ZMP on the reference and lets the CoM diverge
//! slowly beyond the horizon, and the robot falls. With [`Riccati::set_tail`] the last state
//! also pays the infinite-horizon cost of holding the last reference for ever,
//!
//!   ½ (x_N − x̄_N)ᵀ P_tail (x_N − x̄_N),  x̄_N = [t_N, 0, 0],  P_tail = P∞ − Q_e cᵀc   (PC-T)
//!
//! with P∞ the stabilising solution of the cart-table's discrete algebraic Riccati equation for
//! the undisturbed output row c = [1, 0, −z_c/g]: x̄_N is the rest state whose ZMP is t_N, and
//! from it every later stage costs nothing, so the finite problem is Kajita's infinite-horizon
//! preview control with the reference held after N. P_tail is the cart-table's
//! ([`CartTable::infinite_tail`]), one for this solver, the dense one and the constrained one.

use nalgebra::{Matrix3, RowVector3, Vector3};

use super::CartTable;

/// Symmetric 3×3 cost-to-go matrix, upper triangle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
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
    /// `preview_gain` belongs to the current factorisation (a fused pass leaves it stale).
    preview_valid: bool,
    len: usize,
    /// PC-T's P_tail in the backward pass's coordinates (zero: no tail), and P_tail e₀ in the
    /// state's own (the tail's linear term per unit of t_N).
    tail: Sym3,
    tail_e0: Vector3<f64>,
}

impl Riccati {
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            gain: vec![RowVector3::zeros(); capacity],
            inv_h: vec![0.0; capacity],
            preview_gain: vec![0.0; capacity],
            preview_valid: false,
            len: 0,
            tail: Sym3::default(),
            tail_e0: Vector3::zeros(),
        }
    }

    /// PC-T: the last state pays the infinite horizon's tail for `model`'s undisturbed output
    /// row (`false`: none, the paper's finite horizon), [`CartTable::infinite_tail`] carried into
    /// the backward pass's coordinates: P' = Nᵀ P N with x = N x', N = S⁻¹ T. Once, at set-up;
    /// the next factorisation uses it.
    pub fn set_tail(&mut self, model: &CartTable, q_e: f64, r: f64, on: bool) {
        self.preview_valid = false;
        self.len = 0;
        if !on {
            self.tail = Sym3::default();
            self.tail_e0 = Vector3::zeros();
            return;
        }
        let p = model.infinite_tail(q_e, r);
        let dt = model.period;
        let n = Matrix3::new(
            1.0,
            0.0,
            1.0 / 6.0,
            0.0,
            1.0 / dt,
            1.0 / (2.0 * dt),
            0.0,
            0.0,
            1.0 / (dt * dt),
        );
        let t = n.transpose() * p * n;
        self.tail = Sym3 {
            p00: t[(0, 0)],
            p01: t[(0, 1)],
            p02: t[(0, 2)],
            p11: t[(1, 1)],
            p12: t[(1, 2)],
            p22: t[(2, 2)],
        };
        self.tail_e0 = p.column(0).into_owned();
    }

    /// K_0 of the last factorisation: the receding-horizon feedback u = K_0 x (+ the preview).
    pub fn first_gain(&self) -> RowVector3<f64> {
        self.gain[0]
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
        self.backward_pass::<false>(model, q_e, r, c2, [&[], &[]]);
        self.preview_gains(model, q_e, c2);
    }

    /// Preview gains of the current factorisation: k_0 = −H_0⁻¹ Bᵀ s_1 with
    /// s_1 = −Q_e Σ_j Φ_jᵀ c_j t_j and Φ_j = (A + B K_{j−1}) ⋯ (A + B K_1); so
    /// f_j = H_0⁻¹ Q_e c_j·v_j, v_1 = B, v_{j+1} = (A + B K_j) v_j: the closed-loop response to
    /// the first input.
    fn preview_gains(&mut self, model: &CartTable, q_e: f64, c2: &[f64]) {
        let n = self.len;
        let a = model.a();
        let b = model.b();
        let mut v = b;
        let scale = self.inv_h[0] * q_e;
        for j in 1..=n {
            self.preview_gain[j - 1] = scale * (v[0] + c2[j - 1] * v[2]);
            if j == n {
                // PC-T: t_N also enters through the tail's −P_tail x̄_N.
                self.preview_gain[j - 1] += self.inv_h[0] * self.tail_e0.dot(&v);
            }
            if j < n {
                v = a * v + b * (self.gain[j] * v)[0];
            }
        }
        self.preview_valid = true;
    }

    /// Makes [`Riccati::first_input`] usable after a [`Riccati::factor_first_inputs`] (O(N),
    /// once per factorisation). `c2` must be the factorisation's.
    pub fn ensure_preview_gains(&mut self, model: &CartTable, q_e: f64, c2: &[f64]) {
        if !self.preview_valid && self.len > 0 {
            self.preview_gains(model, q_e, c2);
        }
    }

    /// [`Riccati::factor`] and the first input of each of two reference sequences (the x and y
    /// axes share the output rows) in ONE backward pass: with α0 changing every tick the gains
    /// are new each time, and the forward pass of the preview gains plus the dot products cost
    /// as much again as the recursion. The two linear cost-to-go recursions (as in
    /// [`Riccati::feedforward_into`]) ride along the Riccati recursion, whose division is the
    /// critical path, so they come almost free. Stores the same gains as [`Riccati::factor`]
    /// (for [`Riccati::feedforward_into`] / [`Riccati::rollout_with`]); the preview gains are
    /// left stale ([`Riccati::ensure_preview_gains`]).
    ///
    /// Precondition: 1 ≤ `c2.len()` ≤ capacity and every `t[a].len()` ≥ `c2.len()`.
    pub fn factor_first_inputs(
        &mut self,
        model: &CartTable,
        q_e: f64,
        r: f64,
        c2: &[f64],
        t: [&[f64]; 2],
        x0: [&Vector3<f64>; 2],
    ) -> [f64; 2] {
        let ff0 = self.backward_pass::<true>(model, q_e, r, c2, t);
        self.preview_valid = false;
        [0, 1].map(|a| (self.gain[0] * x0[a])[0] + ff0[a])
    }

    /// The backward Riccati recursion (gains K_i, 1/H_i), and with `LINEAR` the linear
    /// cost-to-go of the references `t[0]`, `t[1]` alongside; returns their first feedforward
    /// inputs k_0 (zeros without `LINEAR`).
    ///
    /// Run in coordinates where the input enters one state and every sum is an addition:
    /// x' = T⁻¹ S x, ũ = T³ u, with S = diag(1, T, T²/2) (the cart-table's powers of the
    /// period scaled out) and T = [e₀, e₁, B̃] (B̃ = [1/6, 1/2, 1/2], the scaled input). There
    /// A' = [[1, 1, 1], [0, 1, 1], [0, 0, 1]], B' = e₂, the output row c' = [1, 0, 1/6 + c2 / T²]
    /// (as sparse as the original) and R̃ = R / T⁶. B' = e₂ makes H' = R̃ + p'₂₂ a single entry
    /// of P', so the next H' is one multiply–add after this step's division
    /// (p'₂₂ ← a₂₂ − g₂² / H', everything else ready before the division): the recursion's
    /// critical path is a division and a multiply–add per step, not a division and the sums
    /// forming BᵀPB. It is the same recursion in another basis (T is well conditioned), not a
    /// rearranged one: it agrees with the dense solve as closely as the original coordinates
    /// did (8.3e-10 against 9.4e-10 worst relative difference over the α0 test's ticks).
    /// The gains are stored in the original coordinates: K = K' T⁻¹ S / T³, 1/H = (1/H') / T⁶.
    ///
    /// On a CPU with FMA a copy of the kernel compiled for it runs (one rounding per multiply–
    /// add): its gains and inputs agree with the plain kernel's within 1e-10 relative (unit test).
    ///
    /// Tried and left out (in the scaled coordinates x̃ = S x, where B̃ is dense): forming
    /// H̃_{i−1} from P̃_{i+1} and 1/H̃_i was 6 % faster but agreed with the dense solve 4× less
    /// closely (1.2e-9 against 3e-10 on an ill-conditioned tick): the subtraction of two
    /// large sums that the basis change avoids.
    fn backward_pass<const LINEAR: bool>(
        &mut self,
        model: &CartTable,
        q_e: f64,
        r: f64,
        c2: &[f64],
        t: [&[f64]; 2],
    ) -> [f64; 2] {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has FMA (checked above; the check is a cached load).
            return unsafe { self.backward_pass_fma::<LINEAR>(model, q_e, r, c2, t) };
        }
        self.backward_kernel::<LINEAR, Separate>(model, q_e, r, c2, t)
    }

    /// [`Riccati::backward_pass`] compiled with fused multiply–adds: the recursion is bound by
    /// the number of floating-point operations per step (the build targets baseline x86-64,
    /// without FMA), and a multiply feeding an add is one of them here.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "fma")]
    unsafe fn backward_pass_fma<const LINEAR: bool>(
        &mut self,
        model: &CartTable,
        q_e: f64,
        r: f64,
        c2: &[f64],
        t: [&[f64]; 2],
    ) -> [f64; 2] {
        self.backward_kernel::<LINEAR, Fused>(model, q_e, r, c2, t)
    }

    #[inline(always)]
    fn backward_kernel<const LINEAR: bool, M: MulAdd>(
        &mut self,
        model: &CartTable,
        q_e: f64,
        r: f64,
        c2: &[f64],
        t: [&[f64]; 2],
    ) -> [f64; 2] {
        let madd = M::madd;
        let n = c2.len();
        debug_assert!(n >= 1 && n <= self.capacity());
        debug_assert!(!LINEAR || t.iter().all(|t| t.len() >= n));
        let dt = model.period;
        let dt3 = dt * dt * dt;
        let (inv_dt3, inv_dt6) = (1.0 / dt3, 1.0 / (dt3 * dt3));
        let r_s = r * inv_dt6;
        // The output row's third entry in x' coordinates: γ = 1/6 + c̃/2 = 1/6 + c2 / T².
        let gamma_scale = 1.0 / (dt * dt);
        const SIXTH: f64 = 1.0 / 6.0;
        // K = K' T⁻¹ S / T³ (T⁻¹ = [[1, 0, −1/3], [0, 1, −1], [0, 0, 2]]).
        let (ks0, ks1, ks2) = (inv_dt3, dt * inv_dt3, dt * dt / 2.0 * inv_dt3);
        // P'_N = Q_e c'_Nᵀ c'_N + P'_tail (PC-T), c' = [1, 0, γ].
        let gn = madd(c2[n - 1], gamma_scale, SIXTH);
        let tail = self.tail;
        let mut p = Sym3 {
            p00: q_e + tail.p00,
            p01: tail.p01,
            p02: madd(q_e, gn, tail.p02),
            p11: tail.p11,
            p12: tail.p12,
            p22: madd(q_e * gn, gn, tail.p22),
        };
        // H' = R̃ + p'22, carried on its own: the next one is a single multiply–add after the
        // division (see `h` below).
        let mut h = p.p22 + r_s;
        // s'_N = −Q_e c'_Nᵀ t_N − P'_tail x̄'_N (PC-T; x̄'_N = t_N e₀), one lane per axis.
        let tn = [0, 1].map(|a| if LINEAR { t[a][n - 1] } else { 0.0 });
        let w = tn.map(|t| -q_e * t);
        let (mut s0, mut s1, mut s2) = (
            [0, 1].map(|a| madd(-tail.p00, tn[a], w[a])),
            tn.map(|t| -tail.p01 * t),
            [0, 1].map(|a| madd(-tail.p02, tn[a], w[a] * gn)),
        );
        let mut ff0 = [0.0; 2];
        for i in (0..n).rev() {
            let inv_h = 1.0 / h;
            // G = B'ᵀ P' A': row 2 of P' summed from the left (A' = upper-triangular ones).
            let g0 = p.p02;
            let g1 = p.p02 + p.p12;
            let g2 = g1 + p.p22;
            let (k0, k1, k2) = (-g0 * inv_h, -g1 * inv_h, -g2 * inv_h);
            let kt2 = madd(2.0, k2, madd(-1.0 / 3.0, k0, -k1));
            self.gain[i] = RowVector3::new(k0 * ks0, k1 * ks1, kt2 * ks2);
            self.inv_h[i] = inv_h * inv_dt6;
            if LINEAR {
                // s'_i = A'ᵀ s' + K'ᵀ (B'ᵀ s') − Q_e c'_iᵀ t_i, with B'ᵀ s' = s'_2.
                if i > 0 {
                    let gm = madd(c2[i - 1], gamma_scale, SIXTH);
                    let w = [0, 1].map(|a| -q_e * t[a][i - 1]);
                    let s01 = [0, 1].map(|a| s0[a] + s1[a]);
                    let n0 = [0, 1].map(|a| madd(k0, s2[a], s0[a] + w[a]));
                    let n1 = [0, 1].map(|a| madd(k1, s2[a], s01[a]));
                    let n2 = [0, 1].map(|a| madd(w[a], gm, madd(k2, s2[a], s01[a] + s2[a])));
                    (s0, s1, s2) = (n0, n1, n2);
                } else {
                    // k̃_0 = −H̃⁻¹ B'ᵀ s'_1; u = ũ / T³.
                    ff0 = s2.map(|s| -s * inv_h * inv_dt3);
                }
            }
            if i > 0 {
                // γ again (also formed in the linear branch): hoisting it above both branches
                // measured 6 % slower (3.13 against 2.95 µs at N = 300, alternating runs).
                let gm = madd(c2[i - 1], gamma_scale, SIXTH);
                let qg = q_e * gm;
                // A'ᵀ P' A': sums of P' over the upper-left blocks.
                let a01 = p.p00 + p.p01;
                let a02 = a01 + p.p02;
                let t11 = p.p01 + p.p11;
                let a11 = a01 + t11;
                let a12 = a02 + (t11 + p.p12);
                let a22 = a12 + g2;
                // P'_i = A'ᵀ P' A' + Q_e c'ᵀ c' − Gᵀ G / H'. Its (2, 2) entry plus R̃ is the
                // next H': its other terms are ready before the division, so the recursion's
                // critical path is the division and one multiply–add.
                let c22 = madd(qg, gm, a22);
                h = madd(-g2 * g2, inv_h, c22 + r_s);
                p = Sym3 {
                    p00: madd(k0, g0, p.p00 + q_e),
                    p01: madd(k0, g1, a01),
                    p02: madd(k0, g2, a02 + qg),
                    p11: madd(k1, g1, a11),
                    p12: madd(k1, g2, a12),
                    p22: madd(k2, g2, c22),
                };
            }
        }
        self.len = n;
        ff0
    }

    /// u_0 = K_0 x_0 + Σ_j f_j t_j: the first input for references `t`, O(N) without a pass
    /// over the cost-to-go. Needs the preview gains ([`Riccati::factor`], or
    /// [`Riccati::ensure_preview_gains`] after [`Riccati::factor_first_inputs`]).
    pub fn first_input(&self, x0: &Vector3<f64>, t: &[f64]) -> f64 {
        debug_assert!(self.preview_valid);
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
        // s_N = −Q_e c_N t_N − P_tail x̄_N (PC-T).
        let w = -q_e * t[n - 1];
        let tail = self.tail_e0 * t[n - 1];
        let (mut s0, mut s1, mut s2) = (w - tail[0], -tail[1], w * c2[n - 1] - tail[2]);
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

/// `a·b + c`, rounded once ([`Fused`]) or twice ([`Separate`]): the backward pass is written
/// once and compiled for CPUs with and without FMA.
trait MulAdd {
    fn madd(a: f64, b: f64, c: f64) -> f64;
}

struct Separate;
impl MulAdd for Separate {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

#[cfg(target_arch = "x86_64")]
struct Fused;
#[cfg(target_arch = "x86_64")]
impl MulAdd for Fused {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel without FMA (what a CPU without it runs; tests elsewhere run the FMA one
    /// here) gives the same gains and first inputs.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn separate_and_fused_multiply_adds_agree() {
        if !std::arch::is_x86_feature_detected!("fma") {
            return;
        }
        let model = CartTable {
            period: 0.005,
            com_height: 0.52,
            mass: 29.8,
            gravity: 9.81,
        };
        let n = 300;
        let c2: Vec<f64> = (0..n)
            .map(|i| -0.052 * (1.0 + 0.3 * (i as f64 * 0.05).sin()))
            .collect();
        let t: [Vec<f64>; 2] = [0, 1].map(|a| {
            (0..n)
                .map(|i| if i > n / 3 { 0.05 } else { 0.01 * a as f64 })
                .collect()
        });
        let run = |fused: bool| {
            let mut r = Riccati::with_capacity(n);
            let ff = if fused {
                // SAFETY: FMA checked above.
                unsafe { r.backward_pass_fma::<true>(&model, 1.0, 5e-7, &c2, [&t[0], &t[1]]) }
            } else {
                r.backward_kernel::<true, Separate>(&model, 1.0, 5e-7, &c2, [&t[0], &t[1]])
            };
            (ff, r.gain.clone(), r.inv_h.clone())
        };
        let (fa, ga, ha) = run(false);
        let (fb, gb, hb) = run(true);
        let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(b.abs()).max(1e-300);
        for a in 0..2 {
            assert!(rel(fa[a], fb[a]) < 1e-10, "{fa:?} {fb:?}");
        }
        for i in 0..n {
            assert!(rel(ha[i], hb[i]) < 1e-10, "1/H at {i}");
            for k in 0..3 {
                assert!(
                    rel(ga[i][k], gb[i][k]) < 1e-10,
                    "K at {i}: {} {}",
                    ga[i],
                    gb[i]
                );
            }
        }
    }
}
