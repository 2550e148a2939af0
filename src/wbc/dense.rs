//! Small dense Cholesky factors and their triangular solves for the condensation
//! (`condensed.rs`): column-major, in place, no allocation.
//!
//! The pivots' reciprocals are kept with the factor: a division in each element's chain of
//! dependent operations cost more than the rest of a substitution. (Copies of these kernels
//! compiled for AVX were tried: the C1 tick within noise, 68.3 against 69.9 µs. The columns are
//! at most 38 long; the loops' overhead, not the vector width, bounds them.)

use nalgebra::DMatrix;

/// `A = L Lᵀ` of a symmetric positive definite matrix, factored in place.
pub(crate) struct Cholesky {
    /// A (lower triangle read), then L with its strict upper triangle zeroed.
    pub(crate) l: DMatrix<f64>,
    inv_diag: Vec<f64>,
}

impl Cholesky {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            l: DMatrix::zeros(n, n),
            inv_diag: vec![0.0; n],
        }
    }

    /// Factors `self.l` in place. `false` when a pivot is not positive and finite.
    pub(crate) fn factor(&mut self) -> bool {
        let n = self.l.nrows();
        cholesky_kernel(n, self.l.as_mut_slice(), &mut self.inv_diag)
    }

    /// `B ← L⁻¹ B`, B column-major with n rows (a vector is one column).
    pub(crate) fn solve_lower(&self, b: &mut [f64]) {
        let n = self.l.nrows();
        lower_kernel(n, self.l.as_slice(), &self.inv_diag, b)
    }

    /// `B ← L⁻ᵀ B`.
    pub(crate) fn solve_upper(&self, b: &mut [f64]) {
        let n = self.l.nrows();
        upper_kernel(n, self.l.as_slice(), &self.inv_diag, b)
    }

    /// `B ← A⁻¹ B`.
    pub(crate) fn solve(&self, b: &mut [f64]) {
        self.solve_lower(b);
        self.solve_upper(b);
    }
}

/// Left-looking by columns: contiguous column updates, four earlier columns per pass (one
/// load and store of the column per four, where the loops' overhead bounds these sizes).
fn cholesky_kernel(n: usize, s: &mut [f64], inv_diag: &mut [f64]) -> bool {
    for j in 0..n {
        {
            let (left, right) = s.split_at_mut(j * n);
            let target = &mut right[j..n];
            let col = |k: usize| &left[k * n + j..k * n + n];
            let mut k = 0;
            while k + 4 <= j {
                let (c0, c1, c2, c3) = (col(k), col(k + 1), col(k + 2), col(k + 3));
                let (l0, l1, l2, l3) = (c0[0], c1[0], c2[0], c3[0]);
                for (i, x) in target.iter_mut().enumerate() {
                    *x -= (l0 * c0[i] + l1 * c1[i]) + (l2 * c2[i] + l3 * c3[i]);
                }
                k += 4;
            }
            for k in k..j {
                let ck = col(k);
                let ljk = ck[0];
                if ljk != 0.0 {
                    for (x, y) in target.iter_mut().zip(ck) {
                        *x -= ljk * y;
                    }
                }
            }
        }
        let d = s[j + j * n];
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        s[j + j * n] = d;
        let inv = 1.0 / d;
        inv_diag[j] = inv;
        for x in &mut s[j * n + j + 1..j * n + n] {
            *x *= inv;
        }
        for x in &mut s[j * n..j * n + j] {
            *x = 0.0;
        }
    }
    true
}

/// Per column of B, four columns of L at a time: their 4 × 4 triangle by substitution, then
/// one pass below it (skipped while B's column is still zero, as a sole's is at first). B's
/// columns are taken in groups of [`GROUP`], each step of L over the whole group: their
/// chains of dependent operations are independent, and overlap (each column's operations are
/// those of a column alone, in the same order).
fn lower_kernel(n: usize, l: &[f64], inv_diag: &[f64], b: &mut [f64]) {
    for group in b.chunks_mut(n * GROUP) {
        let mut j = 0;
        while j + 4 <= n {
            for col in group.chunks_exact_mut(n) {
                let mut x = [0.0; 4];
                for a in 0..4 {
                    let xa = col[j + a] * inv_diag[j + a];
                    col[j + a] = xa;
                    x[a] = xa;
                    for r in a + 1..4 {
                        col[j + r] -= l[(j + a) * n + j + r] * xa;
                    }
                }
                if x != [0.0; 4] {
                    let c = |a: usize| &l[(j + a) * n + j + 4..(j + a + 1) * n];
                    let (c0, c1, c2, c3) = (c(0), c(1), c(2), c(3));
                    for (i, y) in col[j + 4..].iter_mut().enumerate() {
                        *y -= (c0[i] * x[0] + c1[i] * x[1]) + (c2[i] * x[2] + c3[i] * x[3]);
                    }
                }
            }
            j += 4;
        }
        for j in j..n {
            let lj = &l[j * n + j + 1..(j + 1) * n];
            for col in group.chunks_exact_mut(n) {
                let x = col[j] * inv_diag[j];
                col[j] = x;
                if x != 0.0 {
                    for (y, a) in col[j + 1..].iter_mut().zip(lj) {
                        *y -= a * x;
                    }
                }
            }
        }
    }
}

/// Per column of B, from the bottom: x_j = (b_j − L[j+1.., j] · x[j+1..]) / L_jj, a dot down
/// a contiguous column of L; B's columns in groups as in [`lower_kernel`].
fn upper_kernel(n: usize, l: &[f64], inv_diag: &[f64], b: &mut [f64]) {
    for group in b.chunks_mut(n * GROUP) {
        for j in (0..n).rev() {
            let lj = &l[j * n + j + 1..(j + 1) * n];
            for col in group.chunks_exact_mut(n) {
                let below = dot(lj, &col[j + 1..]);
                col[j] = (col[j] - below) * inv_diag[j];
            }
        }
    }
}

/// Columns of B a solve steps through together.
const GROUP: usize = 4;

/// `aᵀ b` with four partial sums (a single running sum is one long chain of dependent adds).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> DMatrix<f64> {
        let r = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) as f64).sin());
        &r * r.transpose() + DMatrix::identity(n, n) * 0.1
    }

    #[test]
    fn cholesky_reproduces_a_spd_matrix_and_refuses_an_indefinite_one() {
        let n = 7;
        let a = spd(n);
        let mut c = Cholesky::new(n);
        c.l.copy_from(&a);
        assert!(c.factor());
        let back = &c.l * c.l.transpose();
        assert!((back - &a).amax() < 1e-12);
        for i in 0..n {
            for j in i + 1..n {
                assert_eq!(c.l[(i, j)], 0.0);
            }
        }
        c.l.copy_from(&a);
        c.l[(3, 3)] = -10.0;
        assert!(!c.factor());
    }

    #[test]
    fn the_blocked_kernels_match_at_every_remainder() {
        for n in [1, 3, 4, 5, 8, 13, 38] {
            let a = spd(n);
            let mut c = Cholesky::new(n);
            c.l.copy_from(&a);
            assert!(c.factor(), "n = {n}");
            assert!((&c.l * c.l.transpose() - &a).amax() < 1e-10, "n = {n}");
            // A right-hand side zero at the top, as a sole's column of W.
            let b = DMatrix::from_fn(n, 2, |i, j| if i < n / 2 { 0.0 } else { (i + j) as f64 });
            let mut y = b.clone();
            c.solve_lower(y.as_mut_slice());
            assert!((&c.l * &y - &b).amax() < 1e-9, "n = {n}");
            assert!(y.rows(0, n / 2).iter().all(|&x| x == 0.0), "n = {n}");
        }
    }

    #[test]
    fn the_solves_invert_the_matrix_and_its_factors() {
        let n = 11;
        let a = spd(n);
        let mut c = Cholesky::new(n);
        c.l.copy_from(&a);
        assert!(c.factor());
        let b = DMatrix::from_fn(n, 3, |i, j| (i as f64 + 1.0) * (j as f64 - 1.3));
        let mut x = b.clone();
        c.solve(x.as_mut_slice());
        assert!((&a * &x - &b).amax() < 1e-9);
        let mut y = b.clone();
        c.solve_lower(y.as_mut_slice());
        assert!((&c.l * &y - &b).amax() < 1e-9);
        let mut z = b.clone();
        c.solve_upper(z.as_mut_slice());
        assert!((c.l.transpose() * &z - &b).amax() < 1e-9);
        let v: Vec<f64> = (0..n).map(|i| i as f64 - 4.5).collect();
        assert_eq!(dot(&v, &v), v.iter().map(|x| x * x).sum::<f64>());
    }
}
