//! Forward kinematics: body and frame placements, body and frame velocities (RBDA §4.4).

use nalgebra::DVector;

use super::data::Data;
use super::error::DynamicsError;
use super::model::Model;
use super::spatial::{Motion, SE3};

/// Expression of a frame's velocity or Jacobian.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReferenceFrame {
    /// In the frame's own axes, at its origin.
    Local,
    /// In world-aligned axes, at the frame's origin: `[ṗ_world; ω_world]`.
    LocalWorldAligned,
}

/// Placements of every body (`data.li_m_i`, `data.o_m_i`) and frame (`data.o_m_f`).
pub fn forward_kinematics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
) -> Result<(), DynamicsError> {
    model.check_q(q)?;
    placements_unchecked(model, data, q.as_slice());
    update_frame_placements(model, data);
    Ok(())
}

/// As [`forward_kinematics`] plus body twists `data.v` (local).
pub fn forward_kinematics_velocity(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<(), DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    placements_unchecked(model, data, q.as_slice());
    let v = v.as_slice();
    for (i, j) in model.joints.iter().enumerate() {
        let vj = j.kind.motion(&v[j.idx_v..j.idx_v + j.nv()]);
        data.v[i] = match j.parent {
            Some(p) => data.li_m_i[i].act_inv_motion(&data.v[p]) + vj,
            None => vj,
        };
    }
    update_frame_placements(model, data);
    Ok(())
}

/// Hot-path kernel: `li_m_i` and `o_m_i`. Precondition: `q.len() == model.nq`.
///
/// Once per configuration: a control tick runs the CoM, M_e, CRBA, the drifts and RNEA at one
/// q, and each placed the whole tree (32 sines and cosines, 38 compositions) again. The same
/// bits of q give the same placements, so skipping is exact.
#[inline]
pub(crate) fn placements_unchecked(model: &Model, data: &mut Data, q: &[f64]) {
    debug_assert_eq!(q.len(), model.nq);
    if data.placed_at(model, q) {
        return;
    }
    for (i, j) in model.joints.iter().enumerate() {
        let li = j
            .kind
            .placed_transform(&j.placement, &q[j.idx_q..j.idx_q + j.nq()]);
        data.li_m_i[i] = li;
        data.o_m_i[i] = match j.parent {
            Some(p) => data.o_m_i[p].compose(&li),
            None => li,
        };
    }
    data.mark_placed(model, q);
}

/// For RNEA and ABA, which place the joints in their parents only (`li_m_i`): whether they
/// are placed at `q` already. If not, the record goes, as they leave `o_m_i` behind.
#[inline]
pub(crate) fn joints_placed(model: &Model, data: &mut Data, q: &[f64]) -> bool {
    let placed = data.placed_at(model, q);
    if !placed {
        data.unmark_placed();
    }
    placed
}

/// Joint `i`'s placement in its parent: the recorded one when `placed` ([`joints_placed`]),
/// else computed and stored.
#[inline(always)]
pub(crate) fn joint_placement(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    i: usize,
    placed: bool,
) -> SE3 {
    if placed {
        return data.li_m_i[i];
    }
    let j = &model.joints[i];
    let li = j
        .kind
        .placed_transform(&j.placement, &q[j.idx_q..j.idx_q + j.nq()]);
    data.li_m_i[i] = li;
    li
}

/// `data.o_m_f` from `data.o_m_i` (run after the placements; once per placement).
pub fn update_frame_placements(model: &Model, data: &mut Data) {
    if data.frames_placed {
        return;
    }
    for (k, f) in model.frames.iter().enumerate() {
        data.o_m_f[k] = frame_placement_from(data, f.parent, &f.placement);
    }
    data.frames_placed = data.placed_model.is_some();
}

#[inline]
pub(crate) fn frame_placement_from(data: &Data, parent: Option<usize>, placement: &SE3) -> SE3 {
    match parent {
        Some(p) => data.o_m_i[p].compose(placement),
        None => *placement,
    }
}

/// Velocity of frame `frame` (after [`forward_kinematics_velocity`]): `[linear; angular]` in the
/// requested expression. Frames fixed to the world have zero velocity.
pub fn frame_velocity(model: &Model, data: &Data, frame: usize, rf: ReferenceFrame) -> Motion {
    let f = &model.frames[frame];
    let Some(p) = f.parent else {
        return Motion::zero();
    };
    let local = f.placement.act_inv_motion(&data.v[p]);
    match rf {
        ReferenceFrame::Local => local,
        ReferenceFrame::LocalWorldAligned => {
            let r = &data.o_m_f[frame].rot;
            Motion::new(r * local.lin, r * local.ang)
        }
    }
}
