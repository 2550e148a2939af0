//! Configuration-space integration and difference (the Lie-group `⊕` / `⊖`).
//!
//! 1-DoF joints add `v·dt`. The free-flyer moves by the SE(3) exponential of its body twist:
//! `M' = M · exp(v dt)`, the quaternion updated multiplicatively and renormalised, so it stays
//! unit to rounding whatever the step.

use nalgebra::{DVector, Quaternion, UnitQuaternion, Vector3};

use super::error::DynamicsError;
use super::joint::JointKind;
use super::model::Model;
use super::spatial::{Motion, exp6, log3};

/// `out = q ⊕ v·dt`. `out` must have length nq (it may not alias `q`).
pub fn integrate(
    model: &Model,
    q: &DVector<f64>,
    v: &DVector<f64>,
    dt: f64,
    out: &mut DVector<f64>,
) -> Result<(), DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    if out.len() != model.nq {
        return Err(DynamicsError::DimensionMismatch {
            what: "integrate output",
            expected: model.nq,
            got: out.len(),
        });
    }
    for j in &model.joints {
        let (iq, iv) = (j.idx_q, j.idx_v);
        match j.kind {
            JointKind::FreeFlyer => {
                let quat = unit_quat(q, iq + 3);
                let twist = Motion::new(
                    Vector3::new(v[iv], v[iv + 1], v[iv + 2]) * dt,
                    Vector3::new(v[iv + 3], v[iv + 4], v[iv + 5]) * dt,
                );
                let step = exp6(&twist);
                let p = Vector3::new(q[iq], q[iq + 1], q[iq + 2]) + quat * step.trans;
                let dq = UnitQuaternion::from_scaled_axis(twist.ang);
                let nq = quat * dq;
                let c = nq.quaternion().coords; // (x, y, z, w)
                out[iq] = p.x;
                out[iq + 1] = p.y;
                out[iq + 2] = p.z;
                for k in 0..4 {
                    out[iq + 3 + k] = c[k];
                }
            }
            _ => out[iq] = q[iq] + v[iv] * dt,
        }
    }
    Ok(())
}

/// `out = q1 ⊖ q0`: the velocity that integrates `q0` to `q1` in unit time.
pub fn difference(
    model: &Model,
    q0: &DVector<f64>,
    q1: &DVector<f64>,
    out: &mut DVector<f64>,
) -> Result<(), DynamicsError> {
    model.check_q(q0)?;
    model.check_q(q1)?;
    model.check_v("difference output", out)?;
    for j in &model.joints {
        let (iq, iv) = (j.idx_q, j.idx_v);
        match j.kind {
            JointKind::FreeFlyer => {
                let r0 = unit_quat(q0, iq + 3);
                let r1 = unit_quat(q1, iq + 3);
                let rel = r0.inverse() * r1;
                let w = log3(rel.to_rotation_matrix().matrix());
                let dp = r0.inverse()
                    * (Vector3::new(q1[iq], q1[iq + 1], q1[iq + 2])
                        - Vector3::new(q0[iq], q0[iq + 1], q0[iq + 2]));
                // Invert the V matrix of exp6: v = V(ω)⁻¹ dp.
                let v_lin = v_inverse(&w) * dp;
                for k in 0..3 {
                    out[iv + k] = v_lin[k];
                    out[iv + 3 + k] = w[k];
                }
            }
            _ => out[iv] = q1[iq] - q0[iq],
        }
    }
    Ok(())
}

fn unit_quat(q: &DVector<f64>, at: usize) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[at + 3], q[at], q[at + 1], q[at + 2]))
}

/// Inverse of the left Jacobian `V(ω)` of SE(3) (closed form).
fn v_inverse(w: &Vector3<f64>) -> nalgebra::Matrix3<f64> {
    let t = w.norm();
    let wx = super::spatial::skew(w);
    let coef = if t < 1e-4 {
        1.0 / 12.0 + t * t / 720.0
    } else {
        let half = 0.5 * t;
        (1.0 - half * half.cos() / half.sin()) / (t * t)
    };
    nalgebra::Matrix3::identity() - 0.5 * wx + coef * wx * wx
}
