//! The q̈ cost's Hessian `H = D + Vᵀ P₀ V` (D diagonal and positive, P₀ = diag(w), V the point
//! tasks' stacked r × n Jacobian: the CoM's 3 rows and the hand's 3) factored in O(n r²) and
//! applied in O(n r) instead of a dense Cholesky's O(n³) and O(n²).
//!
//! The LDLᵀ factor of a diagonal plus a rank-r term is lower semiseparable: `L_ij = v_iᵀ g_j`
//! (i > j) with v_i column i of V. Eliminating pivot j leaves the Schur complement
//! `D_rest + V_rest P_{j+1} V_restᵀ` of the same form, so one r × r matrix carries the whole
//! elimination (the product form of Gill, Golub, Murray and Saunders' rank-one modifications,
//! 1974, all r at once):
//!
//! ```text
//! P_0 = P₀;  t = P_j v_j,  d̄_j = d_j + v_jᵀ t,  g_j = t / d̄_j,  P_{j+1} = P_j − t g_jᵀ
//! ```
//!
//! With D > 0 and P_j ⪰ 0 every pivot d̄_j ≥ d_j > 0: no pivot is lost however the tasks
//! align. The solves run the same recursion on an r-vector state:
//! `L x = y`: x_i = y_i − v_iᵀ s, s += g_i x_i (forward); `Lᵀ x = y`: x_i = y_i − g_iᵀ s,
//! s += v_i x_i (backward). A right-hand side zero in its first rows stays zero there, as the
//! dense substitution's did (the soles' columns of `condensed.rs`'s W).

/// `H = L D̄ Lᵀ` of rank `R` above its diagonal, its solves scaled as a Cholesky factor's:
/// `solve_lower` is `(L D̄^½)⁻¹`. R is a constant so that the r-vectors live in registers.
pub(crate) struct LowRankCholesky<const R: usize> {
    n: usize,
    /// H's data, set before each `factor`: the diagonal D (n); v_i, dof i's column of the
    /// stacked task Jacobians; P₀'s diagonal, each row's task weight.
    pub(crate) d: Vec<f64>,
    pub(crate) v: Vec<[f64; R]>,
    pub(crate) w: [f64; R],
    /// g_i.
    g: Vec<[f64; R]>,
    /// d̄_i^(-½).
    inv_sqrt: Vec<f64>,
    /// The solves' states: an r-vector per column, `state[group][a][lane]`.
    state: [[[f64; LANES]; R]; BLOCK / LANES],
}

/// Columns solved together (the condensation's 18, and up to 6 held limits').
const BLOCK: usize = 24;
/// Columns per group: each step's arithmetic on a group is two SSE2 vectors.
const LANES: usize = 4;

impl<const R: usize> LowRankCholesky<R> {
    /// n × n.
    pub(crate) fn new(n: usize) -> Self {
        Self {
            n,
            d: vec![0.0; n],
            v: vec![[0.0; R]; n],
            w: [0.0; R],
            g: vec![[0.0; R]; n],
            inv_sqrt: vec![0.0; n],
            state: [[[0.0; LANES]; R]; BLOCK / LANES],
        }
    }

    /// Factors H from `d`, `v` and `w`. `false` when a pivot is not positive and finite (a
    /// non-positive d, or non-finite data).
    pub(crate) fn factor(&mut self) -> bool {
        let mut p = [[0.0; R]; R];
        for (a, w) in self.w.iter().enumerate() {
            p[a][a] = *w;
        }
        for j in 0..self.n {
            let vj = &self.v[j];
            let mut pivot = self.d[j];
            let mut t = [0.0; R];
            if *vj == [0.0; R] {
                // A dof no task moves: its pivot is d_j, P unchanged.
                self.g[j] = [0.0; R];
            } else {
                for a in 0..R {
                    t[a] = dot_r(&p[a], vj);
                }
                pivot += dot_r(vj, &t);
                let inv = 1.0 / pivot;
                let gj = t.map(|x| x * inv);
                // P −= t tᵀ / d̄, kept exactly symmetric.
                for a in 0..R {
                    for b in a..R {
                        let x = p[a][b] - t[a] * gj[b];
                        p[a][b] = x;
                        p[b][a] = x;
                    }
                }
                self.g[j] = gj;
            }
            if !(pivot > 0.0 && pivot.is_finite()) {
                return false;
            }
            self.inv_sqrt[j] = 1.0 / pivot.sqrt();
        }
        true
    }

    /// `B ← D̄^(-½) L⁻¹ B`, B column-major with n rows (a vector is one column).
    pub(crate) fn solve_lower(&mut self, b: &mut [f64]) {
        self.solve_lower_from(b, &[]);
    }

    /// [`Self::solve_lower`] of columns that are zero above row `start[c]` (0 where `start`
    /// is shorter): rows above a group of four's first non-zero are skipped, since a zero
    /// right-hand side gives x = 0 and leaves the state at 0 (the same bits).
    ///
    /// Rows outer, columns four at a time inner: each row's groups of four are independent
    /// chains the core overlaps, x stays in registers, and the states in L1.
    pub(crate) fn solve_lower_from(&mut self, b: &mut [f64], start: &[usize]) {
        let n = self.n;
        if b.len() == n {
            self.solve_lower_vector(b);
            return;
        }
        for (block_index, block) in b.chunks_mut(n * BLOCK).enumerate() {
            let k = block.len() / n;
            let groups = k.div_ceil(LANES);
            let state = &mut self.state[..groups];
            for s in state.iter_mut() {
                *s = [[0.0; LANES]; R];
            }
            let mut first = [0; BLOCK / LANES];
            for (q, f) in first[..groups].iter_mut().enumerate() {
                let c0 = block_index * BLOCK + q * LANES;
                *f = (c0..c0 + LANES)
                    .map(|c| start.get(c).copied().unwrap_or(0))
                    .min()
                    .unwrap_or(0);
            }
            for i in 0..n {
                let (vi, gi, scale) = (&self.v[i], &self.g[i], self.inv_sqrt[i]);
                for (q, s) in state.iter_mut().enumerate() {
                    if i < first[q] {
                        continue;
                    }
                    let cols = q * LANES..(q * LANES + LANES).min(k);
                    let mut x = [0.0; LANES];
                    for (x, c) in x.iter_mut().zip(cols.clone()) {
                        *x = block[c * n + i];
                    }
                    // x −= v_iᵀ s, in two partial sums.
                    let (mut lo, mut hi) = ([0.0; LANES], [0.0; LANES]);
                    for a in 0..R / 2 {
                        for l in 0..LANES {
                            lo[l] += vi[a] * s[a][l];
                            hi[l] += vi[R / 2 + a] * s[R / 2 + a][l];
                        }
                    }
                    if R % 2 == 1 {
                        for l in 0..LANES {
                            hi[l] += vi[R - 1] * s[R - 1][l];
                        }
                    }
                    for l in 0..LANES {
                        x[l] -= lo[l] + hi[l];
                    }
                    for (sa, ga) in s.iter_mut().zip(gi) {
                        for l in 0..LANES {
                            sa[l] += ga * x[l];
                        }
                    }
                    for (x, c) in x.iter().zip(cols) {
                        block[c * n + i] = x * scale;
                    }
                }
            }
        }
    }

    /// [`Self::solve_lower`] of one vector, its state in registers.
    fn solve_lower_vector(&self, b: &mut [f64]) {
        let mut s = [0.0; R];
        for (i, y) in b.iter_mut().enumerate() {
            let x = *y - dot_r(&self.v[i], &s);
            for (sa, ga) in s.iter_mut().zip(&self.g[i]) {
                *sa += ga * x;
            }
            *y = x * self.inv_sqrt[i];
        }
    }

    /// `b ← L⁻ᵀ D̄^(-½) b`, one vector.
    pub(crate) fn solve_upper(&self, b: &mut [f64]) {
        let mut s = [0.0; R];
        for i in (0..self.n).rev() {
            let x = b[i] * self.inv_sqrt[i] - dot_r(&self.g[i], &s);
            for (sa, va) in s.iter_mut().zip(&self.v[i]) {
                *sa += va * x;
            }
            b[i] = x;
        }
    }

    /// `b ← H⁻¹ b`, one vector.
    pub(crate) fn solve(&mut self, b: &mut [f64]) {
        self.solve_lower(b);
        self.solve_upper(b);
    }
}

/// `aᵀ b` of two r-vectors, in two halves (a shorter chain of dependent adds).
#[inline(always)]
fn dot_r<const R: usize>(a: &[f64; R], b: &[f64; R]) -> f64 {
    let h = R / 2;
    let lo: f64 = a[..h].iter().zip(&b[..h]).map(|(x, y)| x * y).sum();
    let hi: f64 = a[h..].iter().zip(&b[h..]).map(|(x, y)| x * y).sum();
    lo + hi
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// H = D + Vᵀ diag(w) V with rows of V zero on some dofs (the hand's on the legs).
    fn problem<const R: usize>(n: usize, seed: f64) -> (LowRankCholesky<R>, DMatrix<f64>) {
        let r = R;
        let mut f = LowRankCholesky::<R>::new(n);
        let v = DMatrix::from_fn(r, n, |a, i| {
            if a >= 3 && i < n / 3 {
                0.0
            } else {
                ((a * 13 + i * 7) as f64 + seed).sin()
            }
        });
        for i in 0..n {
            f.d[i] = 1e-4 + if i % 5 == 0 { 10.0 } else { 0.0 };
            for a in 0..r {
                f.v[i][a] = v[(a, i)];
            }
        }
        for a in 0..r {
            f.w[a] = if a < 3 { 1000.0 } else { 100.0 };
        }
        let h = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&f.d))
            + v.transpose()
                * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&f.w[..]))
                * &v;
        (f, h)
    }

    /// L D̄^½ written out densely from v, g and the pivots.
    fn dense_factor<const R: usize>(f: &LowRankCholesky<R>) -> DMatrix<f64> {
        let n = f.n;
        DMatrix::from_fn(n, n, |i, j| {
            let sd = 1.0 / f.inv_sqrt[j];
            match i.cmp(&j) {
                std::cmp::Ordering::Less => 0.0,
                std::cmp::Ordering::Equal => sd,
                std::cmp::Ordering::Greater => dot_r(&f.v[i], &f.g[j]) * sd,
            }
        })
    }

    /// Backward error of the factor: ‖L D̄ Lᵀ − H‖ within a few roundings of ‖H‖, as a dense
    /// Cholesky's (the pivots themselves are ill-conditioned when the tasks' rows nearly align:
    /// two backward-stable factors of one H may differ far more than their residuals).
    fn backward_error<const R: usize>(n: usize, seed: f64) {
        let (mut f, h) = problem::<R>(n, seed);
        assert!(f.factor());
        let l = dense_factor(&f);
        let ours = (&l * l.transpose() - &h).amax() / h.amax();
        let dense = h.clone().cholesky().expect("spd").l();
        let theirs = (&dense * dense.transpose() - &h).amax() / h.amax();
        assert!(
            ours < 1e-14,
            "n {n} r {R}: {ours:e} (dense Cholesky {theirs:e})"
        );
    }

    #[test]
    fn the_factor_reproduces_h_as_a_dense_cholesky_does() {
        backward_error::<6>(38, 0.3);
        backward_error::<6>(35, 1.7);
        backward_error::<3>(12, 0.0);
        backward_error::<9>(7, 2.2);
    }

    #[test]
    fn the_solves_invert_h_and_its_factors_and_keep_leading_zeros() {
        let n = 38;
        let (mut f, h) = problem::<6>(n, 0.9);
        assert!(f.factor());
        let l = dense_factor(&f);
        // 30 columns: more than one block; the odd ones zero in their first rows.
        let b = DMatrix::from_fn(n, 30, |i, c| {
            if c % 2 == 1 && i < 20 {
                0.0
            } else {
                (i as f64 * 0.37 + c as f64).cos() * 50.0
            }
        });
        let residual =
            |a: &DMatrix<f64>, x: &DMatrix<f64>| (a * x - &b).amax() / (a.amax() * x.amax());
        let mut y = b.clone();
        f.solve_lower(y.as_mut_slice());
        assert!(residual(&l, &y) < 1e-14, "{:e}", residual(&l, &y));
        for c in (1..30).step_by(2) {
            assert!(
                y.column(c).rows(0, 20).iter().all(|&x| x == 0.0),
                "column {c}"
            );
        }
        // Skipping the zero rows gives the same bits, for any grouping of the starts.
        for starts in [
            (0..30)
                .map(|c| if c % 2 == 1 { 20 } else { 0 })
                .collect::<Vec<_>>(),
            (0..30)
                .map(|c| if c < 12 { 0 } else { 20 * (c % 2) })
                .collect(),
            vec![0; 3],
        ] {
            let mut skipped = b.clone();
            f.solve_lower_from(skipped.as_mut_slice(), &starts);
            assert_eq!(skipped, y);
        }
        let mut tail = b.columns(12, 4).clone_owned();
        for c in 0..4 {
            tail.column_mut(c).rows_mut(0, 20).fill(0.0);
        }
        let mut whole = tail.clone();
        f.solve_lower(whole.as_mut_slice());
        f.solve_lower_from(tail.as_mut_slice(), &[20; 4]);
        assert_eq!(tail, whole);
        let mut z = b.column(3).clone_owned();
        f.solve_upper(z.as_mut_slice());
        let lt = l.transpose();
        let back = (&lt * &z - b.column(3)).amax() / (lt.amax() * z.amax());
        assert!(back < 1e-14, "{back:e}");
        let mut x = b.column(3).clone_owned();
        f.solve(x.as_mut_slice());
        let back = (&h * &x - b.column(3)).amax() / (h.amax() * x.amax());
        assert!(back < 1e-13, "{back:e}");
    }

    #[test]
    fn a_non_positive_or_non_finite_pivot_is_refused() {
        let (mut f, _) = problem::<6>(10, 0.5);
        f.d[4] = 0.0;
        f.v[4] = [0.0; 6];
        assert!(!f.factor());
        let (mut f, _) = problem::<6>(10, 0.5);
        f.v[2][1] = f64::NAN;
        assert!(!f.factor());
        // A zero d on a dof a task moves is a positive pivot (the CoM's base rows).
        let (mut f, _) = problem::<6>(10, 0.5);
        f.d[1] = 0.0;
        assert!(f.factor());
    }
}
