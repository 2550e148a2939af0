//! Joint and frame Jacobians (6×nv, rows `[linear; angular]`) and the drift `J̇q̇`.
//!
//! `data.j` holds the world Jacobian of all joints: column `k` is `oMi · S_k`, the spatial
//! velocity (world axes, at the world origin) produced by a unit rate of dof `k`. A frame
//! Jacobian is read off it by shifting the linear rows to the frame origin (and rotating for
//! [`ReferenceFrame::Local`]). Only the frame's supporting columns are non-zero.

use nalgebra::{DMatrix, DVector, Vector3};

use super::data::Data;
use super::error::DynamicsError;
use super::kinematics::{ReferenceFrame, placements_unchecked, update_frame_placements};
use super::model::Model;
use super::spatial::{Motion, SE3};

/// Placements of all bodies and frames, and `data.j` for every joint.
pub fn compute_joint_jacobians<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
) -> Result<&'d DMatrix<f64>, DynamicsError> {
    model.check_q(q)?;
    placements_unchecked(model, data, q.as_slice());
    update_frame_placements(model, data);
    joint_jacobians_from_placements(model, data);
    Ok(&data.j)
}

/// `data.j` from the current `data.o_m_i`.
pub(crate) fn joint_jacobians_from_placements(model: &Model, data: &mut Data) {
    for (i, j) in model.joints.iter().enumerate() {
        let o = data.o_m_i[i];
        for k in 0..j.nv() {
            let col = o.act_motion(&j.kind.subspace_column(k));
            write_column(&mut data.j, j.idx_v + k, &col);
        }
    }
}

#[inline]
fn write_column(m: &mut DMatrix<f64>, c: usize, x: &Motion) {
    let mut col = m.column_mut(c);
    col[0] = x.lin.x;
    col[1] = x.lin.y;
    col[2] = x.lin.z;
    col[3] = x.ang.x;
    col[4] = x.ang.y;
    col[5] = x.ang.z;
}

/// Maps a world-origin column to the frame `o_m_f` in expression `rf`.
#[inline]
fn to_frame(col: &Motion, o_m_f: &SE3, rf: ReferenceFrame) -> Motion {
    // Velocity of the point at the frame origin: v_O + ω × p.
    let lin = col.lin + col.ang.cross(&o_m_f.trans);
    match rf {
        ReferenceFrame::LocalWorldAligned => Motion::new(lin, col.ang),
        ReferenceFrame::Local => {
            let rt = o_m_f.rot.transpose();
            Motion::new(rt * lin, rt * col.ang)
        }
    }
}

/// Jacobian of frame `frame` into `out` (6×nv), reading `data.j` and `data.o_m_f` (run
/// [`compute_joint_jacobians`] first). Non-supporting columns are zeroed.
pub fn get_frame_jacobian(
    model: &Model,
    data: &Data,
    frame: usize,
    rf: ReferenceFrame,
    out: &mut DMatrix<f64>,
) -> Result<(), DynamicsError> {
    check_frame_out(model, frame, out)?;
    out.fill(0.0);
    let o_m_f = data.o_m_f[frame];
    let mut cur = model.frames[frame].parent;
    while let Some(i) = cur {
        let j = &model.joints[i];
        for c in j.idx_v..j.idx_v + j.nv() {
            let col = data.j.column(c);
            let m = Motion::new(
                Vector3::new(col[0], col[1], col[2]),
                Vector3::new(col[3], col[4], col[5]),
            );
            write_column(out, c, &to_frame(&m, &o_m_f, rf));
        }
        cur = j.parent;
    }
    Ok(())
}

fn check_frame_out(model: &Model, frame: usize, out: &DMatrix<f64>) -> Result<(), DynamicsError> {
    if frame >= model.frames.len() {
        return Err(DynamicsError::UnknownFrame(format!("#{frame}")));
    }
    if out.nrows() != 6 || out.ncols() != model.nv {
        return Err(DynamicsError::DimensionMismatch {
            what: "Jacobian output columns (rows must be 6)",
            expected: model.nv,
            got: out.ncols(),
        });
    }
    Ok(())
}

/// Placements plus the Jacobian of one frame, in `data.frame_j`. Computes only the frame's
/// supporting columns (cheaper than [`compute_joint_jacobians`] for a single frame).
pub fn frame_jacobian<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<&'d DMatrix<f64>, DynamicsError> {
    model.check_q(q)?;
    check_frame_out(model, frame, &data.frame_j)?;
    placements_unchecked(model, data, q.as_slice());
    let f = &model.frames[frame];
    let o_m_f = super::kinematics::frame_placement_from(data, f.parent, &f.placement);
    data.o_m_f[frame] = o_m_f;
    data.frame_j.fill(0.0);
    let mut cur = f.parent;
    while let Some(i) = cur {
        let j = &model.joints[i];
        let o = data.o_m_i[i];
        for k in 0..j.nv() {
            let col = o.act_motion(&j.kind.subspace_column(k));
            write_column(&mut data.frame_j, j.idx_v + k, &to_frame(&col, &o_m_f, rf));
        }
        cur = j.parent;
    }
    Ok(&data.frame_j)
}

/// `J̇(q, v) v` of frame `frame`: the frame's acceleration when `q̈ = 0`, without gravity.
/// `Local`: the spatial acceleration in the frame (the derivative of `J_local v`).
/// `LocalWorldAligned`: `[p̈_world; ω̇_world]` (classical linear acceleration of the origin).
/// Refreshes placements and body twists.
pub fn frame_jdot_v(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion, DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    if frame >= model.frames.len() {
        return Err(DynamicsError::UnknownFrame(format!("#{frame}")));
    }
    placements_unchecked(model, data, q.as_slice());
    let vs = v.as_slice();
    // Forward pass of RNEA with q̈ = 0 and no gravity: a_i = X a_λ + v_i × v_J.
    for (i, j) in model.joints.iter().enumerate() {
        let vj = j.kind.motion(&vs[j.idx_v..j.idx_v + j.nv()]);
        let li = data.li_m_i[i];
        let (vi, ai) = match j.parent {
            Some(p) => (
                li.act_inv_motion(&data.v[p]) + vj,
                li.act_inv_motion(&data.a[p]),
            ),
            None => (vj, Motion::zero()),
        };
        data.a[i] = ai + vi.cross_motion(&vj);
        data.v[i] = vi;
    }
    let f = &model.frames[frame];
    let Some(p) = f.parent else {
        return Ok(Motion::zero());
    };
    let vf = f.placement.act_inv_motion(&data.v[p]);
    let af = f.placement.act_inv_motion(&data.a[p]);
    Ok(match rf {
        ReferenceFrame::Local => af,
        ReferenceFrame::LocalWorldAligned => {
            let r = data.o_m_i[p].rot * f.placement.rot;
            let classical = af.lin + vf.ang.cross(&vf.lin);
            Motion::new(r * classical, r * af.ang)
        }
    })
}
