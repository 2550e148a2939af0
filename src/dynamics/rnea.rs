//! Recursive Newton–Euler inverse dynamics (RBDA Table 5.1), in body-local frames.
//!
//! Gravity enters as a fictitious upward acceleration of the world (`a_0 = −g`), so the result
//! is `τ = M(q) a + h(q, v)` with `h` containing Coriolis, centrifugal and gravity terms.

use nalgebra::DVector;

use super::data::Data;
use super::error::DynamicsError;
use super::model::Model;
use super::spatial::Motion;

/// `τ = M(q) a + h(q, v)`, written to and returned from `data.tau`.
pub fn rnea<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
) -> Result<&'d DVector<f64>, DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    model.check_v("a", a)?;
    rnea_unchecked(
        model,
        data,
        q.as_slice(),
        Some(v.as_slice()),
        Some(a.as_slice()),
        true,
    );
    Ok(&data.tau)
}

/// Bias `h(q, v) = C(q, v) v + g(q)` (RNEA with zero acceleration), in `data.tau`.
pub fn nonlinear_effects<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<&'d DVector<f64>, DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    rnea_unchecked(model, data, q.as_slice(), Some(v.as_slice()), None, true);
    Ok(&data.tau)
}

/// Generalised gravity `g(q)` (RNEA with zero velocity and acceleration), in `data.tau`.
pub fn gravity_torques<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
) -> Result<&'d DVector<f64>, DynamicsError> {
    model.check_q(q)?;
    rnea_unchecked(model, data, q.as_slice(), None, None, true);
    Ok(&data.tau)
}

/// Hot-path kernel. Preconditions: slice lengths nq / nv / nv. `v`, `a = None` mean zero;
/// `gravity = false` drops gravity (used for J̇q̇-like drift terms).
pub(crate) fn rnea_unchecked(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: Option<&[f64]>,
    a: Option<&[f64]>,
    gravity: bool,
) {
    debug_assert_eq!(q.len(), model.nq);
    let a0 = if gravity {
        Motion::new(-model.gravity, nalgebra::Vector3::zeros())
    } else {
        Motion::zero()
    };
    // Forward pass: velocities, accelerations, net body wrenches (RBDA eq. 5.7–5.9). The
    // joints' placements as placed at this q, else placed here (and o_m_i left behind).
    let placed = super::kinematics::joints_placed(model, data, q);
    for (i, j) in model.joints.iter().enumerate() {
        let li = super::kinematics::joint_placement(model, data, q, i, placed);
        let vj = match v {
            Some(v) => j.kind.motion(&v[j.idx_v..j.idx_v + j.nv()]),
            None => Motion::zero(),
        };
        let (vp, ap) = match j.parent {
            Some(p) => (li.act_inv_motion(&data.v[p]), li.act_inv_motion(&data.a[p])),
            None => (Motion::zero(), li.act_inv_motion(&a0)),
        };
        let vi = vp + vj;
        let mut ai = ap + vi.cross_motion(&vj);
        if let Some(a) = a {
            ai += j.kind.motion(&a[j.idx_v..j.idx_v + j.nv()]);
        }
        let y = &j.inertia;
        data.f[i] = y.mul_motion(&ai) + vi.cross_force(&y.mul_motion(&vi));
        data.v[i] = vi;
        data.a[i] = ai;
    }
    // Backward pass: project onto the joint axes, accumulate into the parent (eq. 5.10–5.11).
    let tau = data.tau.as_mut_slice();
    for i in (0..model.joints.len()).rev() {
        let j = &model.joints[i];
        let fi = data.f[i];
        j.kind
            .project_force(&fi, &mut tau[j.idx_v..j.idx_v + j.nv()]);
        if let (Some(a), true) = (a, j.armature != 0.0) {
            // The rotor's reflected inertia (`Joint::armature`, on M's diagonal).
            tau[j.idx_v] += j.armature * a[j.idx_v];
        }
        if let Some(p) = j.parent {
            let fp = data.li_m_i[i].act_force(&fi);
            data.f[p] += fp;
        }
    }
}
