//! Centre of mass: position, velocity and Jacobian (world frame).
//!
//! The Jacobian uses subtree masses and first moments: a unit rate of dof k moves the whole
//! subtree of its joint rigidly, so its CoM column is `(m_sub v_O + ω × h_sub) / M` with the
//! world-origin Jacobian column `(v_O, ω)`.

use nalgebra::{DMatrix, DVector, Vector3};

use super::data::Data;
use super::error::DynamicsError;
use super::jacobian::joint_jacobians_from_placements;
use super::kinematics::placements_unchecked;
use super::model::Model;

fn total_mass_checked(model: &Model) -> Result<f64, DynamicsError> {
    let m = model.total_mass();
    if m > 0.0 {
        Ok(m)
    } else {
        Err(DynamicsError::Singular("total mass (zero)"))
    }
}

/// World CoM at `q`, in `data.com`.
pub fn center_of_mass(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
) -> Result<Vector3<f64>, DynamicsError> {
    model.check_q(q)?;
    let mass = total_mass_checked(model)?;
    placements_unchecked(model, data, q.as_slice());
    let mut h = Vector3::zeros();
    for (i, j) in model.joints.iter().enumerate() {
        let o = &data.o_m_i[i];
        h += o.rot * j.inertia.h + j.inertia.mass * o.trans;
    }
    data.com = h / mass;
    Ok(data.com)
}

/// World CoM and its velocity, in `data.com`, `data.vcom`; returns `(com, vcom)`.
pub fn center_of_mass_velocity(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<(Vector3<f64>, Vector3<f64>), DynamicsError> {
    model.check_v("v", v)?;
    super::kinematics::forward_kinematics_velocity(model, data, q, v)?;
    let mass = total_mass_checked(model)?;
    let mut h = Vector3::zeros();
    let mut p = Vector3::zeros();
    for (i, j) in model.joints.iter().enumerate() {
        let o = &data.o_m_i[i];
        let y = &j.inertia;
        h += o.rot * y.h + y.mass * o.trans;
        // Linear momentum m (v + ω × c) = m v + ω × h (body frame), rotated to the world.
        let vi = &data.v[i];
        p += o.rot * (y.mass * vi.lin + vi.ang.cross(&y.h));
    }
    data.com = h / mass;
    data.vcom = p / mass;
    Ok((data.com, data.vcom))
}

/// CoM Jacobian (3×nv, world axes) in `data.jcom`; also sets `data.com`, `data.j`,
/// `data.subtree_mass`.
pub fn jacobian_center_of_mass<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
) -> Result<&'d DMatrix<f64>, DynamicsError> {
    model.check_q(q)?;
    let mass = total_mass_checked(model)?;
    placements_unchecked(model, data, q.as_slice());
    joint_jacobians_from_placements(model, data);
    for (i, j) in model.joints.iter().enumerate() {
        let o = &data.o_m_i[i];
        data.subtree_mass[i] = j.inertia.mass;
        data.subtree_h[i] = o.rot * j.inertia.h + j.inertia.mass * o.trans;
    }
    let mut h_total = Vector3::zeros();
    for i in (0..model.joints.len()).rev() {
        match model.joints[i].parent {
            Some(p) => {
                let (m, h) = (data.subtree_mass[i], data.subtree_h[i]);
                data.subtree_mass[p] += m;
                data.subtree_h[p] += h;
            }
            None => h_total += data.subtree_h[i],
        }
    }
    data.com = h_total / mass;
    let inv = 1.0 / mass;
    for c in 0..model.nv {
        let i = model.dof_joint[c];
        let col = data.j.column(c);
        let v_o = Vector3::new(col[0], col[1], col[2]);
        let w = Vector3::new(col[3], col[4], col[5]);
        let x = (data.subtree_mass[i] * v_o + w.cross(&data.subtree_h[i])) * inv;
        data.jcom[(0, c)] = x.x;
        data.jcom[(1, c)] = x.y;
        data.jcom[(2, c)] = x.z;
    }
    Ok(&data.jcom)
}
