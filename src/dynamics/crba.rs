//! Composite-rigid-body algorithm: the joint-space inertia `M(q)` (RBDA Table 6.2).
//!
//! Composite inertias are summed in the `(m, h, I_O)` form (a plain addition after a
//! parallel-axis shift); each column's force `F = I^c S` is carried up the support chain by
//! force transforms, and `M[j, i] = S_jᵀ F` is read off at each ancestor.

use nalgebra::{DMatrix, DVector};

use super::data::Data;
use super::error::DynamicsError;
use super::kinematics::placements_unchecked;
use super::model::Model;

/// `M(q)` in `data.m` (both triangles). Also refreshes `data.li_m_i`, `data.o_m_i`.
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
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &[f64]) {
    placements_unchecked(model, data, q);
    for (i, j) in model.joints.iter().enumerate() {
        data.ycrb[i] = j.inertia;
    }
    let m = &mut data.m;
    for i in (0..model.joints.len()).rev() {
        let ji = &model.joints[i];
        let yc = data.ycrb[i];
        for k in 0..ji.nv() {
            let col = ji.idx_v + k;
            let mut f = yc.mul_motion(&ji.kind.subspace_column(k));
            // Diagonal block of joint i.
            for r in 0..ji.nv() {
                m[(ji.idx_v + r, col)] = ji.kind.subspace_column(r).dot(&f);
            }
            // Off-diagonal blocks along the support (RBDA Table 6.2 inner loop).
            let mut cur = i;
            while let Some(p) = model.joints[cur].parent {
                f = data.li_m_i[cur].act_force(&f);
                let jp = &model.joints[p];
                for r in 0..jp.nv() {
                    let val = jp.kind.subspace_column(r).dot(&f);
                    m[(jp.idx_v + r, col)] = val;
                    m[(col, jp.idx_v + r)] = val;
                }
                cur = p;
            }
        }
        if let Some(p) = ji.parent {
            let yp = data.li_m_i[i].act_inertia(&yc);
            data.ycrb[p] += yp;
        }
    }
    // Entries between joints on different branches are never written: they stay at the zero
    // `Data::new` put there (so `data.m` must not be written by callers).
}
