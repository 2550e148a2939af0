//! Composite-rigid-body algorithm: the joint-space inertia `M(q)` (RBDA Table 6.2).
//!
//! Composite inertias are summed in the `(m, h, I_O)` form; each column's force `F = I^c S`
//! gives `M[j, i] = S_jᵀ F` at every ancestor j. Also leaves the world joint Jacobian in `data.j`.

use nalgebra::{DMatrix, DVector, Vector3, Vector6};

use super::data::Data;
use super::error::DynamicsError;
use super::jacobian::joint_jacobians_from_placements;
use super::kinematics::placements_unchecked;
use super::model::Model;
use super::spatial::Motion;

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
/// Works in the world frame (as Pinocchio does): composite inertias are summed in world axes (a
/// plain addition), the column force `F = I^c_i S_i` is formed once, and each ancestor entry is
/// the 6-term dot product `M[j, i] = S_jᵀ F` with world-frame subspace columns (the joint
/// Jacobian columns), instead of one force transform per ancestor as in RBDA Table 6.2.
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &[f64]) {
    placements_unchecked(model, data, q);
    joint_jacobians_from_placements(model, data);
    for (i, j) in model.joints.iter().enumerate() {
        data.ycrb[i] = data.o_m_i[i].act_inertia(&j.inertia);
    }
    let m = &mut data.m;
    let jac = &data.j;
    for i in (0..model.joints.len()).rev() {
        let ji = &model.joints[i];
        let yc = data.ycrb[i];
        for col in ji.idx_v..ji.idx_v + ji.nv() {
            let s = jac.fixed_view::<6, 1>(0, col);
            let f = yc.mul_motion(&Motion::new(
                Vector3::new(s[0], s[1], s[2]),
                Vector3::new(s[3], s[4], s[5]),
            ));
            let fv = Vector6::new(f.lin.x, f.lin.y, f.lin.z, f.ang.x, f.ang.y, f.ang.z);
            let mut cur = Some(i);
            while let Some(a) = cur {
                let ja = &model.joints[a];
                for r in ja.idx_v..ja.idx_v + ja.nv() {
                    let val = jac.fixed_view::<6, 1>(0, r).dot(&fv);
                    m[(r, col)] = val;
                    m[(col, r)] = val;
                }
                cur = ja.parent;
            }
        }
        if let Some(p) = ji.parent {
            data.ycrb[p] += yc;
        }
    }
    // Entries between joints on different branches are never written: they stay at the zero
    // `Data::new` put there (so `data.m` must not be written by callers).
}
