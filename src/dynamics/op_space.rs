//! Operational-space inertia of a sub-chain (docs/hand_previewer.md, eq. (21)–(23)):
//! `M_e = (J H̃⁻¹ Jᵀ)⁻¹` and the dynamically consistent pseudo-inverse `J̄ = H̃⁻¹ Jᵀ M_e`
//! (Khatib 1987).
//!
//! The sub-chain is the set of joints strictly between a root body (e.g. `chest`) and a frame
//! (e.g. `r_hand`). `H̃` is the block of `M(q)` for those joints and `J` the 3×n world-aligned
//! linear Jacobian of the frame restricted to them. `H̃` only depends on the sub-tree hanging
//! below the chain's first joint, so a CRBA over that sub-tree suffices.

use nalgebra::{DMatrix, DVector, Matrix3};

use super::data::Data;
use super::error::DynamicsError;
use super::kinematics::{frame_placement_from, placements_unchecked};
use super::model::Model;

/// Preallocated workspace and results for one (root, frame) pair; [`OpSpaceWorkspace::compute`]
/// does not allocate.
#[derive(Clone, Debug)]
pub struct OpSpaceWorkspace {
    frame: usize,
    /// Chain joints, root side first.
    chain: Vec<usize>,
    /// Offset of each chain joint in `dofs`.
    chain_offset: Vec<usize>,
    /// Every joint of the sub-tree below the chain's first joint, in model order.
    subtree: Vec<usize>,
    /// Velocity indices of the chain (column `k` of `h_tilde`, `j_e`, … is dof `dofs[k]`).
    pub dofs: Vec<usize>,
    /// `H̃` (n×n).
    pub h_tilde: DMatrix<f64>,
    /// Cholesky factor of `H̃` (lower triangle).
    chol: DMatrix<f64>,
    /// `J_e` (3×n), world-aligned linear rows at the frame origin.
    pub j_e: DMatrix<f64>,
    /// `H̃⁻¹ J_eᵀ` (n×3).
    y: DMatrix<f64>,
    /// `Λ⁻¹ = J_e H̃⁻¹ J_eᵀ`.
    pub lambda_inv: Matrix3<f64>,
    /// `M_e = Λ`.
    pub m_e: Matrix3<f64>,
    /// `J̄ = H̃⁻¹ J_eᵀ M_e` (n×3).
    pub j_bar: DMatrix<f64>,
}

impl OpSpaceWorkspace {
    /// Workspace for the chain from body/frame `root` (exclusive) to frame `frame`.
    pub fn new(model: &Model, root: &str, frame: &str) -> Result<Self, DynamicsError> {
        let root_joint = model.frames[model.frame_id(root)?].parent;
        let frame_id = model.frame_id(frame)?;
        let not_ancestor = || DynamicsError::NotAnAncestor {
            root: root.to_owned(),
            frame: frame.to_owned(),
        };
        let mut chain = Vec::new();
        let mut cur = model.frames[frame_id].parent;
        loop {
            if cur == root_joint {
                break;
            }
            let Some(i) = cur else {
                return Err(not_ancestor());
            };
            chain.push(i);
            cur = model.joints[i].parent;
        }
        if chain.is_empty() {
            return Err(not_ancestor());
        }
        chain.reverse();
        let first = chain[0];
        let subtree: Vec<usize> = (first..model.njoints())
            .filter(|&i| model.is_ancestor(first, i))
            .collect();
        let dofs: Vec<usize> = chain
            .iter()
            .flat_map(|&i| {
                let j = &model.joints[i];
                j.idx_v..j.idx_v + j.nv()
            })
            .collect();
        let n = dofs.len();
        let chain_offset = chain
            .iter()
            .scan(0, |off, &i| {
                let here = *off;
                *off += model.joints[i].nv();
                Some(here)
            })
            .collect();
        Ok(Self {
            frame: frame_id,
            chain,
            chain_offset,
            subtree,
            dofs,
            h_tilde: DMatrix::zeros(n, n),
            chol: DMatrix::zeros(n, n),
            j_e: DMatrix::zeros(3, n),
            y: DMatrix::zeros(n, 3),
            lambda_inv: Matrix3::zeros(),
            m_e: Matrix3::zeros(),
            j_bar: DMatrix::zeros(n, 3),
        })
    }

    /// Number of chain dofs.
    pub fn n(&self) -> usize {
        self.dofs.len()
    }

    /// `M_e` at `q` (also fills `h_tilde`, `j_e`, `lambda_inv`, `j_bar`). Uses `data` as
    /// scratch (placements, composite inertias).
    pub fn compute(
        &mut self,
        model: &Model,
        data: &mut Data,
        q: &DVector<f64>,
    ) -> Result<&Matrix3<f64>, DynamicsError> {
        model.check_q(q)?;
        placements_unchecked(model, data, q.as_slice());
        self.fill_h_tilde(model, data);
        self.fill_jacobian(model, data);
        cholesky_in_place(&self.h_tilde, &mut self.chol)?;
        // Y = H̃⁻¹ Jᵀ by two triangular solves per column.
        for c in 0..3 {
            for r in 0..self.n() {
                self.y[(r, c)] = self.j_e[(c, r)];
            }
            solve_cholesky_column(&self.chol, &mut self.y, c);
        }
        let mut li = Matrix3::zeros();
        for r in 0..3 {
            for c in 0..3 {
                let mut s = 0.0;
                for k in 0..self.n() {
                    s += self.j_e[(r, k)] * self.y[(k, c)];
                }
                li[(r, c)] = s;
            }
        }
        self.lambda_inv = li;
        let chol3 = li.cholesky().ok_or(DynamicsError::Singular(
            "J H̃⁻¹ Jᵀ (the hand Jacobian is rank deficient)",
        ))?;
        self.m_e = chol3.inverse();
        for r in 0..self.n() {
            for c in 0..3 {
                let mut s = 0.0;
                for k in 0..3 {
                    s += self.y[(r, k)] * self.m_e[(k, c)];
                }
                self.j_bar[(r, c)] = s;
            }
        }
        Ok(&self.m_e)
    }

    /// CRBA restricted to the sub-tree, reading only the chain's rows and columns.
    fn fill_h_tilde(&mut self, model: &Model, data: &mut Data) {
        for &i in &self.subtree {
            data.ycrb[i] = model.joints[i].inertia;
        }
        let first = self.chain[0];
        for &i in self.subtree.iter().rev() {
            if i != first
                && let Some(p) = model.joints[i].parent
            {
                let y = data.li_m_i[i].act_inertia(&data.ycrb[i]);
                data.ycrb[p] += y;
            }
        }
        // Columns of the chain joints, propagated up the chain only (RBDA Table 6.2).
        for (ci, &i) in self.chain.iter().enumerate() {
            let ji = &model.joints[i];
            let col0 = self.chain_offset[ci];
            for k in 0..ji.nv() {
                let col = col0 + k;
                let mut f = data.ycrb[i].mul_motion(&ji.kind.subspace_column(k));
                for r in 0..ji.nv() {
                    self.h_tilde[(col0 + r, col)] = ji.kind.subspace_column(r).dot(&f);
                }
                self.h_tilde[(col, col)] += ji.armature;
                let mut cur = i;
                for cj in (0..ci).rev() {
                    f = data.li_m_i[cur].act_force(&f);
                    let p = self.chain[cj];
                    let jp = &model.joints[p];
                    let row0 = self.chain_offset[cj];
                    for r in 0..jp.nv() {
                        let val = jp.kind.subspace_column(r).dot(&f);
                        self.h_tilde[(row0 + r, col)] = val;
                        self.h_tilde[(col, row0 + r)] = val;
                    }
                    cur = p;
                }
            }
        }
    }

    fn fill_jacobian(&mut self, model: &Model, data: &Data) {
        let f = &model.frames[self.frame];
        let o_m_f = frame_placement_from(data, f.parent, &f.placement);
        let mut c = 0;
        for &i in &self.chain {
            let j = &model.joints[i];
            for k in 0..j.nv() {
                let col = data.o_m_i[i].act_motion(&j.kind.subspace_column(k));
                let lin = col.lin + col.ang.cross(&o_m_f.trans);
                self.j_e[(0, c)] = lin.x;
                self.j_e[(1, c)] = lin.y;
                self.j_e[(2, c)] = lin.z;
                c += 1;
            }
        }
    }
}

/// Lower Cholesky factor of a symmetric positive-definite matrix, into `l` (no allocation).
fn cholesky_in_place(a: &DMatrix<f64>, l: &mut DMatrix<f64>) -> Result<(), DynamicsError> {
    let n = a.nrows();
    l.fill(0.0);
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d <= 0.0 || !d.is_finite() {
            return Err(DynamicsError::Singular("H̃ (chain joint-space inertia)"));
        }
        let d = d.sqrt();
        l[(j, j)] = d;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / d;
        }
    }
    Ok(())
}

/// Solves `L Lᵀ x = b` in place for column `c` of `b`.
fn solve_cholesky_column(l: &DMatrix<f64>, b: &mut DMatrix<f64>, c: usize) {
    let n = l.nrows();
    for i in 0..n {
        let mut s = b[(i, c)];
        for k in 0..i {
            s -= l[(i, k)] * b[(k, c)];
        }
        b[(i, c)] = s / l[(i, i)];
    }
    for i in (0..n).rev() {
        let mut s = b[(i, c)];
        for k in i + 1..n {
            s -= l[(k, i)] * b[(k, c)];
        }
        b[(i, c)] = s / l[(i, i)];
    }
}
