//! A fixed CSC sparsity pattern over a dense column-major scratch matrix.
//!
//! Each tick the QP is assembled into dense nalgebra matrices (62 columns: filling them is a
//! few µs and keeps the algebra readable), then the pattern's entries are gathered into the
//! `nzval` array clarabel's `update_P` / `update_A` take. The pattern is decided once from the
//! model's structure and includes structural zeros (entries that happen to vanish at some
//! configuration), so it never changes and the solver's symbolic factorisation is reused.

use clarabel::algebra::CscMatrix;
use nalgebra::DMatrix;

pub(crate) struct Pattern {
    dense_nrows: usize,
    nrows: usize,
    ncols: usize,
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    /// Column-major index into the dense scratch of each stored entry.
    dense_index: Vec<usize>,
}

impl Pattern {
    /// Entries `(r, c)` with `keep(r, c)`, in CSC order.
    pub(crate) fn from_mask(
        nrows: usize,
        ncols: usize,
        keep: impl FnMut(usize, usize) -> bool,
    ) -> Self {
        let rows: Vec<usize> = (0..nrows).collect();
        Self::from_mask_rows(nrows, &rows, ncols, keep)
    }

    /// The sub-matrix made of the dense scratch's rows `rows` (renumbered 0..), entries
    /// `(rows[i], c)` with `keep(rows[i], c)`.
    pub(crate) fn from_mask_rows(
        dense_nrows: usize,
        rows: &[usize],
        ncols: usize,
        mut keep: impl FnMut(usize, usize) -> bool,
    ) -> Self {
        let mut colptr = Vec::with_capacity(ncols + 1);
        let mut rowval = Vec::new();
        let mut dense_index = Vec::new();
        colptr.push(0);
        for c in 0..ncols {
            for (i, &r) in rows.iter().enumerate() {
                if keep(r, c) {
                    rowval.push(i);
                    dense_index.push(r + c * dense_nrows);
                }
            }
            colptr.push(rowval.len());
        }
        Self {
            dense_nrows,
            nrows: rows.len(),
            ncols,
            colptr,
            rowval,
            dense_index,
        }
    }

    /// Whether dense entry `(r, c)` is stored.
    pub(crate) fn contains(&self, r: usize, c: usize) -> bool {
        let target = r + c * self.dense_nrows;
        self.dense_index[self.colptr[c]..self.colptr[c + 1]]
            .binary_search(&target)
            .is_ok()
    }

    pub(crate) fn nnz(&self) -> usize {
        self.rowval.len()
    }

    /// `out[k] = dense[entry k]` (no allocation; `out.len() == nnz`).
    pub(crate) fn gather(&self, dense: &DMatrix<f64>, out: &mut [f64]) {
        debug_assert_eq!(dense.nrows(), self.dense_nrows);
        debug_assert_eq!(dense.ncols(), self.ncols);
        let d = dense.as_slice();
        for (o, &i) in out.iter_mut().zip(&self.dense_index) {
            *o = d[i];
        }
    }

    /// A CSC matrix with this pattern and the given values (allocates: solver construction).
    pub(crate) fn to_csc(&self, values: &[f64]) -> CscMatrix<f64> {
        CscMatrix::new(
            self.nrows,
            self.ncols,
            self.colptr.clone(),
            self.rowval.clone(),
            values.to_vec(),
        )
    }
}
