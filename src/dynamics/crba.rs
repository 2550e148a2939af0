//! Composite-rigid-body algorithm: the joint-space inertia `M(q)` (RBDA Table 6.2).
//!
//! Composite inertias are summed in the `(m, h, I_O)` form; each column's force `F = I^c S`
//! gives `M[j, i] = S_jᵀ F` at every ancestor j. Also leaves the world joint Jacobian in `data.j`.

use nalgebra::{DMatrix, DVector, Vector6};

use super::data::Data;
use super::error::DynamicsError;
use super::joint::JointKind;
use super::model::Model;
use super::spatial::{Force, Motion};

/// `M(q)` in `data.m` (both triangles). Also refreshes `data.li_m_i`, `data.o_m_i`, `data.j`.
pub fn crba<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
) -> Result<&'d DMatrix<f64>, DynamicsError> {
    model.check_q(q)?;
    crba_unchecked(model, data, q.as_slice());
    Ok(&data.m)
}

/// Hot-path kernel. Precondition: `q.len() == model.nq`.
///
/// Works in the world frame (as Pinocchio's `Convention::WORLD`): composite inertias are summed
/// in world axes (a plain addition), and the column force `F_k = I^c S_k` of every dof is formed
/// once with the world-frame subspace column `S_k` (the joint Jacobian column). Joints being in
/// depth-first order, the dofs of joint i's sub-tree are the contiguous range
/// `idx_v .. idx_v + nv_subtree`, so row k of joint i is `M[k, c] = S_kᵀ F_c` over that range:
/// a 6-term dot product per entry, read and written sequentially.
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &[f64]) {
    debug_assert_eq!(q.len(), model.nq);
    forward_pass(model, data, q);
    backward_pass(model, data);
}

/// Placements, world Jacobian columns and body inertias in world axes.
fn forward_pass(model: &Model, data: &mut Data, q: &[f64]) {
    super::kinematics::placements_unchecked(model, data, q);
    for (i, j) in model.joints.iter().enumerate() {
        let o = data.o_m_i[i];
        match j.kind {
            // S = (0, axis) carried to the world origin: ω = R axis, v = p × ω.
            JointKind::Revolute { axis } => {
                let w = o.rot * axis;
                let v = o.trans.cross(&w);
                data.j
                    .fixed_view_mut::<6, 1>(0, j.idx_v)
                    .copy_from(&Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z));
            }
            _ => {
                for k in 0..j.nv() {
                    let s = o.act_motion(&j.kind.subspace_column(k));
                    data.j
                        .fixed_view_mut::<6, 1>(0, j.idx_v + k)
                        .copy_from(&s.to_vector());
                }
            }
        }
        data.oycrb[i] = o.act_inertia(&j.inertia);
    }
}

/// Composite inertias, column forces and the rows of M over each sub-tree.
fn backward_pass(model: &Model, data: &mut Data) {
    let nv = model.nv;
    let m = data.m.as_mut_slice();
    for i in (0..model.joints.len()).rev() {
        let ji = &model.joints[i];
        let y = data.oycrb[i];
        let (s, e) = (ji.idx_v, ji.idx_v + data.nv_subtree[i]);
        for d in s..s + ji.nv() {
            let sd = Motion::from_vector(&data.j.fixed_view::<6, 1>(0, d).into_owned());
            data.fcrb[d] = y.mul_motion(&sd).to_vector();
        }
        if let JointKind::FreeFlyer = ji.kind {
            // The free-flyer's six world columns are X_o (its world placement as a motion
            // transform), so its rows are X_oᵀ F_c: each F_c expressed in the body, one inverse
            // force transform for six entries.
            let o = data.o_m_i[i];
            for c in s..e {
                let f = o
                    .act_inv_force(&Force::from_vector(&data.fcrb[c]))
                    .to_vector();
                m[c * nv + s..c * nv + s + 6].copy_from_slice(f.as_slice());
                for (k, x) in f.iter().enumerate() {
                    m[(s + k) * nv + c] = *x;
                }
            }
        } else {
            row_of_1dof(m, nv, &data.j, &data.fcrb, s, e);
        }
        if let Some(p) = ji.parent {
            data.oycrb[p] += y;
        }
    }
    // Entries between joints on different branches are never written: they stay at the zero
    // `Data::new` put there (so `data.m` must not be written by callers).
    // The rotors' reflected inertia on the diagonal (`Joint::armature`).
    for j in model.joints.iter().filter(|j| j.armature != 0.0) {
        m[j.idx_v * nv + j.idx_v] += j.armature;
    }
}

/// Row `d` of M (a 1-dof joint) over its sub-tree's columns `d .. e`, and the same entries of
/// column `d`: `M[d, c] = M[c, d] = S_dᵀ F_c`.
#[inline(always)]
fn row_of_1dof(
    m: &mut [f64],
    nv: usize,
    jac: &DMatrix<f64>,
    fcrb: &[Vector6<f64>],
    d: usize,
    e: usize,
) {
    let sd: Vector6<f64> = jac.fixed_view::<6, 1>(0, d).into_owned();
    // Column-major: columns 0..=d on the left, d+1.. on the right.
    let (left, right) = m.split_at_mut((d + 1) * nv);
    let col_d = &mut left[d * nv + d..d * nv + e];
    col_d[0] = dot6(&sd, &fcrb[d]);
    for ((m_cd, col_c), fc) in col_d[1..]
        .iter_mut()
        .zip(right.chunks_exact_mut(nv))
        .zip(&fcrb[d + 1..e])
    {
        let val = dot6(&sd, fc);
        *m_cd = val;
        col_c[d] = val;
    }
}

/// 6-term dot product summed as a tree (three independent products at a time, not one chain).
#[inline(always)]
fn dot6(a: &Vector6<f64>, b: &Vector6<f64>) -> f64 {
    (a[0] * b[0] + a[3] * b[3]) + (a[1] * b[1] + a[4] * b[4]) + (a[2] * b[2] + a[5] * b[5])
}
