//! Branch-induced sparse `LᵀDL` factorisation of a joint-space inertia matrix (Featherstone,
//! RBDA §6.5, Tables 6.3–6.4).
//!
//! For a kinematic tree, `M[i, j]` is non-zero only when dof `j` is an ancestor of dof `i` (or
//! the converse). Ordering the dofs so that every parent precedes its children, `M = Lᵀ D L`
//! with `L` unit lower-triangular and with the same sparsity: the factorisation costs
//! `O(n d²)` and a solve `O(n d)` (d = depth of the tree) instead of `O(n³)` / `O(n²)`.
//! Several trees (the humanoid and the door) are factorised together as one block-diagonal
//! matrix: a dof without a parent starts a new tree.

use nalgebra::{DMatrix, DVector};

/// Dof parent array (`None` for a root dof) and the factor of the last [`LtdlFactor::factor`].
#[derive(Clone, Debug)]
pub struct LtdlFactor {
    parent: Vec<Option<usize>>,
    /// Strict lower triangle: `L` (ancestor entries only); diagonal: `D`.
    ld: DMatrix<f64>,
    /// `1/√D`, filled by [`LtdlFactor::factor`].
    inv_sqrt_d: DVector<f64>,
}

/// The factorisation met a non-positive pivot (the matrix is not positive definite).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("mass matrix is not positive definite (pivot {pivot} at dof {dof})")]
pub struct NotPositiveDefinite {
    pub dof: usize,
    pub pivot: f64,
}

impl LtdlFactor {
    /// `parent[k] < k` for every dof with a parent (checked: returns `None` otherwise).
    pub fn new(parent: Vec<Option<usize>>) -> Option<Self> {
        if parent
            .iter()
            .enumerate()
            .any(|(k, p)| p.is_some_and(|p| p >= k))
        {
            return None;
        }
        let n = parent.len();
        Some(Self {
            parent,
            ld: DMatrix::zeros(n, n),
            inv_sqrt_d: DVector::zeros(n),
        })
    }

    pub fn n(&self) -> usize {
        self.parent.len()
    }

    pub fn parent(&self) -> &[Option<usize>] {
        &self.parent
    }

    /// Mutable access to the matrix to factorise: fill the lower triangle (ancestor entries and
    /// diagonal) of `M`, then call [`LtdlFactor::factor`]. Other entries are ignored.
    pub fn matrix_mut(&mut self) -> &mut DMatrix<f64> {
        &mut self.ld
    }

    /// Factorises the matrix in place (Table 6.3).
    pub fn factor(&mut self) -> Result<(), NotPositiveDefinite> {
        let n = self.n();
        let h = &mut self.ld;
        for k in (0..n).rev() {
            let hkk = h[(k, k)];
            if !(hkk > 0.0 && hkk.is_finite()) {
                return Err(NotPositiveDefinite { dof: k, pivot: hkk });
            }
            let mut i = self.parent[k];
            while let Some(ii) = i {
                let a = h[(k, ii)] / hkk;
                let mut j = Some(ii);
                while let Some(jj) = j {
                    h[(ii, jj)] -= a * h[(k, jj)];
                    j = self.parent[jj];
                }
                h[(k, ii)] = a;
                i = self.parent[ii];
            }
        }
        for k in 0..n {
            let d = h[(k, k)];
            if !(d > 0.0 && d.is_finite()) {
                return Err(NotPositiveDefinite { dof: k, pivot: d });
            }
            self.inv_sqrt_d[k] = 1.0 / d.sqrt();
        }
        Ok(())
    }

    /// `x ← L⁻ᵀ x` (solves `Lᵀ y = x`).
    #[inline]
    pub fn solve_lt(&self, x: &mut [f64]) {
        for k in (0..self.n()).rev() {
            let xk = x[k];
            if xk == 0.0 {
                continue;
            }
            let mut i = self.parent[k];
            while let Some(ii) = i {
                x[ii] -= self.ld[(k, ii)] * xk;
                i = self.parent[ii];
            }
        }
    }

    /// `x ← L⁻¹ x` (solves `L y = x`).
    #[inline]
    pub fn solve_l(&self, x: &mut [f64]) {
        for k in 0..self.n() {
            let mut i = self.parent[k];
            let mut acc = x[k];
            while let Some(ii) = i {
                acc -= self.ld[(k, ii)] * x[ii];
                i = self.parent[ii];
            }
            x[k] = acc;
        }
    }

    /// `x ← M⁻¹ x`.
    pub fn solve(&self, x: &mut [f64]) {
        self.solve_lt(x);
        for k in 0..self.n() {
            x[k] /= self.ld[(k, k)];
        }
        self.solve_l(x);
    }

    /// `x ← D^{-1/2} L⁻ᵀ x`: with `M = LᵀDL`, `(A x)ᵀ(A y) = xᵀ M⁻¹ y` for this map `A`, so a
    /// constraint row mapped by it gives the Delassus operator as a plain Gram matrix.
    pub fn half_solve(&self, x: &mut [f64]) {
        self.solve_lt(x);
        for k in 0..self.n() {
            x[k] *= self.inv_sqrt_d[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_dense_solve_on_a_tree() {
        // Tree: 0 → 1 → 2, 0 → 3, and a separate root 4 → 5.
        let parent = vec![None, Some(0), Some(1), Some(0), None, Some(4)];
        let n = parent.len();
        // Build M = Jᵀ J-like SPD with the tree sparsity: M[i,j] ≠ 0 only for ancestor pairs.
        let anc = |i: usize, j: usize| {
            let mut c = Some(i);
            while let Some(k) = c {
                if k == j {
                    return true;
                }
                c = parent[k];
            }
            false
        };
        let mut m = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                if i == j {
                    m[(i, j)] = 4.0 + i as f64;
                } else if anc(i, j) || anc(j, i) {
                    m[(i, j)] = 0.5 + 0.1 * (i + j) as f64;
                }
            }
        }
        let mut f = LtdlFactor::new(parent).unwrap();
        f.matrix_mut().copy_from(&m);
        f.factor().unwrap();
        let b = DVector::from_fn(n, |i, _| (i as f64 * 0.7).sin() + 1.0);
        let mut x = b.clone();
        f.solve(x.as_mut_slice());
        let r = &m * &x - &b;
        assert!(r.norm() < 1e-12, "residual {}", r.norm());
        // Gram property of the half solve.
        let y = DVector::from_fn(n, |i, _| (i as f64 * 1.3).cos());
        let (mut ab, mut ay) = (b.clone(), y.clone());
        f.half_solve(ab.as_mut_slice());
        f.half_solve(ay.as_mut_slice());
        let exact = y.dot(&m.clone().cholesky().unwrap().solve(&b));
        assert!((ab.dot(&ay) - exact).abs() < 1e-12);
    }
}
