//! Drift terms `J̇(q, v) v` of several frames and of the centre of mass from ONE forward pass.
//!
//! The dynamics library gives `frame_jdot_v` for one frame (one forward pass each). The QP needs
//! the drift of the hand, of both soles and of the CoM every tick, so this runs the pass once
//! (through `frame_jdot_v`, which leaves the body twists and the `q̈ = 0`, gravity-free body
//! accelerations in `data.v`, `data.a`) and reads every other drift off those bodies:
//!
//! - frame (`LocalWorldAligned`): `[p̈_world; ω̇_world]`, the classical acceleration of the frame
//!   origin at `q̈ = 0`, as `frame_jdot_v` defines it;
//! - CoM: `c̈ = Σ m_i c̈_i / M` with, per body (local twist `(v, ω)`, local acceleration `(v̇, ω̇)`,
//!   first moment `h = m c`): `m c̈_i = R_i (m v̇ + ω̇ × h + ω × (m v + ω × h))`.
//!
//! So `J_com q̈ + com_drift` is the world CoM acceleration. Tested against central finite
//! differences of `J v` along `q ⊕ ±v·dt` (constant `v` means `q̈ = 0` in this convention).

use nalgebra::{DVector, Vector3};

use crate::dynamics::spatial::Motion;
use crate::dynamics::{Data, DynamicsError, Model, ReferenceFrame, frame_jdot_v};

/// Runs the `q̈ = 0` forward pass and returns the drift of `first_frame` (world-aligned
/// `[p̈; ω̇]`). Afterwards [`frame_drift_from_pass`] and [`com_drift_from_pass`] read the drift of
/// any other frame / of the CoM from `data` (until `data` is overwritten by another algorithm).
pub fn drift_pass(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    first_frame: usize,
) -> Result<Motion, DynamicsError> {
    frame_jdot_v(
        model,
        data,
        q,
        v,
        first_frame,
        ReferenceFrame::LocalWorldAligned,
    )
}

/// World-aligned drift `[p̈_world; ω̇_world]` of frame `frame` after [`drift_pass`].
/// Precondition: `frame < model.frames.len()`.
pub fn frame_drift_from_pass(model: &Model, data: &Data, frame: usize) -> Motion {
    let f = &model.frames[frame];
    let Some(p) = f.parent else {
        return Motion::zero();
    };
    let vf = f.placement.act_inv_motion(&data.v[p]);
    let af = f.placement.act_inv_motion(&data.a[p]);
    let r = data.o_m_i[p].rot * f.placement.rot;
    let classical = af.lin + vf.ang.cross(&vf.lin);
    Motion::new(r * classical, r * af.ang)
}

/// World CoM drift `J̇_com v` after [`drift_pass`] (m/s²). Zero for a massless model.
pub fn com_drift_from_pass(model: &Model, data: &Data) -> Vector3<f64> {
    let mass = model.total_mass();
    if mass <= 0.0 {
        return Vector3::zeros();
    }
    let mut sum = Vector3::zeros();
    for (i, j) in model.joints.iter().enumerate() {
        let y = &j.inertia;
        let (v, a) = (&data.v[i], &data.a[i]);
        let local =
            y.mass * a.lin + a.ang.cross(&y.h) + v.ang.cross(&(y.mass * v.lin + v.ang.cross(&y.h)));
        sum += data.o_m_i[i].rot * local;
    }
    sum / mass
}

/// Convenience (allocation-free): the CoM drift `J̇_com(q, v) v` alone (one forward pass).
pub fn com_drift(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<Vector3<f64>, DynamicsError> {
    if model.frames.is_empty() {
        return Err(DynamicsError::UnknownFrame("(model has no frames)".into()));
    }
    drift_pass(model, data, q, v, 0)?;
    Ok(com_drift_from_pass(model, data))
}
