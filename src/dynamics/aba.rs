//! Articulated-body algorithm: forward dynamics `q̈ = M⁻¹(τ − h)` in O(n) (RBDA Table 7.1).
//!
//! Articulated inertias are 6×6 matrices (`[lin; ang]` ordering); they are carried to the parent
//! by a block-wise congruence on their symmetric blocks, and the 1-DoF joints use rank-one
//! updates with `U = I^A S` read off the columns their axis selects.

use nalgebra::{Cholesky, DVector, Vector6};

use super::data::Data;
use super::error::DynamicsError;
use super::joint::JointKind;
use super::model::Model;
use super::spatial::{Force, Motion};

/// Forward dynamics: `q̈` in `data.ddq` for torques `tau` (free-flyer entries of `tau` are the
/// wrench applied on the root, normally zero).
pub fn aba<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<&'d DVector<f64>, DynamicsError> {
    check(model, q, v, tau)?;
    aba_unchecked(
        model,
        data,
        q.as_slice(),
        v.as_slice(),
        tau.as_slice(),
        None,
    )?;
    Ok(&data.ddq)
}

/// As [`aba`] with external wrenches `fext[i]` acting on body `i`, expressed in the body frame
/// at its origin (one per joint).
pub fn aba_with_external_forces<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: &[Force],
) -> Result<&'d DVector<f64>, DynamicsError> {
    check(model, q, v, tau)?;
    if fext.len() != model.njoints() {
        return Err(DynamicsError::DimensionMismatch {
            what: "fext",
            expected: model.njoints(),
            got: fext.len(),
        });
    }
    aba_unchecked(
        model,
        data,
        q.as_slice(),
        v.as_slice(),
        tau.as_slice(),
        Some(fext),
    )?;
    Ok(&data.ddq)
}

fn check(
    model: &Model,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<(), DynamicsError> {
    model.check_q(q)?;
    model.check_v("v", v)?;
    model.check_v("tau", tau)
}

/// Kernel. Preconditions: slice lengths nq / nv / nv (/ njoints). Fails only when an
/// articulated inertia is singular (a massless terminal body on a moving joint).
pub(crate) fn aba_unchecked(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    fext: Option<&[Force]>,
) -> Result<(), DynamicsError> {
    velocities_and_bias(model, data, q, v, fext);
    articulated_inertias(model, data, tau)?;
    accelerations(model, data);
    Ok(())
}

/// Pass 1, root to leaves: kinematics, bias accelerations c, rigid inertias, bias forces p
/// (eq. 7.36-7.38).
#[inline]
fn velocities_and_bias(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    fext: Option<&[Force]>,
) {
    let placed = super::kinematics::joints_placed(model, data, q);
    for (i, j) in model.joints.iter().enumerate() {
        let li = super::kinematics::joint_placement(model, data, q, i, placed);
        let vj = j.kind.motion(&v[j.idx_v..j.idx_v + j.nv()]);
        let vi = match j.parent {
            Some(p) => li.act_inv_motion(&data.v[p]) + vj,
            None => vj,
        };
        data.v[i] = vi;
        data.c[i] = vi.cross_motion(&vj);
        let y = &j.inertia;
        data.ia[i] = y.to_matrix();
        let mut pa = vi.cross_force(&y.mul_motion(&vi));
        if let Some(fext) = fext {
            pa -= fext[i];
        }
        data.f[i] = pa;
    }
}

/// Pass 2, leaves to root: articulated inertias and bias forces, each carried to its parent
/// (eq. 7.39-7.45).
#[inline]
fn articulated_inertias(model: &Model, data: &mut Data, tau: &[f64]) -> Result<(), DynamicsError> {
    for i in (0..model.joints.len()).rev() {
        let j = &model.joints[i];
        // Parents precede children: the parent's inertia is in `head`.
        let (head, tail) = data.ia.split_at_mut(i);
        let ia = &mut tail[0];
        let pa = data.f[i];
        let li = data.li_m_i[i];
        let singular = || DynamicsError::SingularJoint {
            joint: j.name.clone(),
        };
        let (u_col, d, s_pa) = match j.kind {
            JointKind::FreeFlyer => {
                // S = 1: U = D = I^A, u = τ − p; D is kept factored for pass 3.
                let chol = ia.cholesky().ok_or_else(singular)?;
                data.d_chol[i] = chol.unpack_dirty();
                let mut u = Vector6::zeros();
                for k in 0..6 {
                    u[k] = tau[j.idx_v + k] - pa.to_vector()[k];
                    data.u_vec[j.idx_v + k] = u[k];
                }
                if let Some(p) = j.parent {
                    // I^a = I^A − I^A (I^A)⁻¹ I^A = 0; p^a = p + u = τ-side wrench.
                    let pa_new = pa.to_vector() + u;
                    data.f[p] += li.act_force(&Force::from_vector(&pa_new));
                }
                continue;
            }
            // S = (0, axis): U = I^A S reads the angular columns; D = Sᵀ U, Sᵀ p.
            JointKind::Revolute { axis } => {
                let u_col: Vector6<f64> = ia.fixed_columns::<3>(3) * axis;
                // D = Sᵀ I^A S + armature (the rotor's inertia about the joint axis).
                let d = axis.dot(&u_col.fixed_rows::<3>(3)) + j.armature;
                (u_col, d, axis.dot(&pa.ang))
            }
            JointKind::Prismatic { axis } => {
                let u_col: Vector6<f64> = ia.fixed_columns::<3>(0) * axis;
                let d = axis.dot(&u_col.fixed_rows::<3>(0)) + j.armature;
                (u_col, d, axis.dot(&pa.lin))
            }
        };
        // I^A is positive semi-definite: its largest entry is on its diagonal.
        let scale = ia.diagonal().max();
        if d.abs() <= 1e-14 * (1.0 + scale) || !d.is_finite() {
            return Err(singular());
        }
        let d_inv = 1.0 / d;
        data.d_inv[i] = d_inv;
        data.u_col[i] = u_col;
        let u = tau[j.idx_v] - s_pa;
        data.u_vec[j.idx_v] = u;
        if let Some(p) = j.parent {
            // I^a = I^A − U D⁻¹ Uᵀ (in place: I^A is not needed afterwards).
            *ia -= (u_col * d_inv) * u_col.transpose();
            let pa_a: Vector6<f64> =
                pa.to_vector() + *ia * data.c[i].to_vector() + u_col * (d_inv * u);
            li.add_act_matrix6(ia, &mut head[p]);
            data.f[p] += li.act_force(&Force::from_vector(&pa_a));
        }
    }
    Ok(())
}

/// Pass 3, root to leaves: the joints' accelerations q̈ and the bodies' (eq. 7.46-7.48).
#[inline]
fn accelerations(model: &Model, data: &mut Data) {
    let a0 = Motion::new(-model.gravity, nalgebra::Vector3::zeros());
    for (i, j) in model.joints.iter().enumerate() {
        let li = &data.li_m_i[i];
        let ap = match j.parent {
            Some(p) => li.act_inv_motion(&data.a[p]),
            None => li.act_inv_motion(&a0),
        };
        let a_pre = ap + data.c[i];
        match j.kind {
            JointKind::FreeFlyer => {
                let a_vec = a_pre.to_vector();
                let mut u = Vector6::zeros();
                for k in 0..6 {
                    u[k] = data.u_vec[j.idx_v + k];
                }
                // q̈ = D⁻¹(u − Uᵀ a) with U = D = I^A.
                let ddq = Cholesky::pack_dirty(data.d_chol[i]).solve(&u) - a_vec;
                for k in 0..6 {
                    data.ddq[j.idx_v + k] = ddq[k];
                }
                data.a[i] = Motion::from_vector(&(a_vec + ddq));
            }
            _ => {
                let ddq =
                    data.d_inv[i] * (data.u_vec[j.idx_v] - a_pre.to_vector().dot(&data.u_col[i]));
                data.ddq[j.idx_v] = ddq;
                data.a[i] = a_pre + j.kind.motion(&[ddq]);
            }
        }
    }
}
