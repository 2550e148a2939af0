//! What the draft locks or adds to the model: the fingers and the joints that move no mass
//! locked, an armature on the joints whose body has no mass, an inertia floor for point
//! masses.

use std::collections::HashMap;

use super::arms::Arms;
use super::tree::Tree;
use super::{ARMATURE, INERTIA_FLOOR, POINT_MASS, lock_value};
use crate::dynamics::{BaseJoint, Model};
use crate::robot::RobotError;

/// The joints below the hands (fingers), locked at [`lock_value`] (a note says how many).
pub(super) fn finger_joints(
    urdf: &urdf_rs::Robot,
    tree: &Tree,
    model: &Model,
    arms: &Arms,
    notes: &mut Vec<String>,
) -> Vec<(String, f64)> {
    let mut locked: Vec<(String, f64)> = Vec::new();
    let palms = std::iter::once(&arms.right_palm).chain(&arms.left_palm);
    for p in palms {
        for l in tree.subtree(p).iter().skip(1) {
            if let Some((_, true)) = tree.parent.get(l)
                && let Some(j) = urdf.joints.iter().find(|j| &j.child.link == l)
            {
                locked.push((j.name.clone(), lock_value(model, &j.name)));
            }
        }
    }
    if !locked.is_empty() {
        notes.push(format!(
            "{} joints below the hands (fingers) are locked: the door is held by the hand",
            locked.len()
        ));
    }
    locked
}

/// The joints that still move no mass with `locked` locked (M singular): locked too. Returns
/// the model with all of them locked.
pub(super) fn lock_inert_joints(
    urdf: &urdf_rs::Robot,
    model: &Model,
    locked: &mut Vec<(String, f64)>,
    notes: &mut Vec<String>,
) -> Result<Model, RobotError> {
    let names: HashMap<String, f64> = locked.iter().cloned().collect();
    let reduced = Model::from_urdf_robot_locked(urdf, BaseJoint::Floating, &names)?;
    let inert: Vec<String> = reduced
        .inert_joints()
        .into_iter()
        .map(|i| reduced.joints[i].name.clone())
        .collect();
    if !inert.is_empty() {
        notes.push(format!(
            "{} joints move no mass (massless links in the URDF) and are locked: {}",
            inert.len(),
            inert.join(", ")
        ));
        for n in inert {
            let v = lock_value(model, &n);
            locked.push((n, v));
        }
    }
    Ok(reduced)
}

/// Joints whose body has no mass (a ball joint split into one-axis joints through massless
/// links), given [`ARMATURE`]: a rotor's inertia keeps M invertible where two of their axes
/// align (gimbal lock, which a falling robot reaches).
pub(super) fn massless_joints(
    reduced: &Model,
    locked: &[(String, f64)],
    notes: &mut Vec<String>,
) -> Vec<String> {
    let armature: Vec<String> = reduced
        .joints
        .iter()
        .filter(|j| j.nv() == 1 && j.inertia.mass <= 0.0)
        .filter(|j| !locked.iter().any(|(n, _)| *n == j.name))
        .map(|j| j.name.clone())
        .collect();
    if !armature.is_empty() {
        notes.push(format!(
            "{} joints carry a link without mass (ball joints split into one-axis joints): \
             [armature] gives each {ARMATURE} kg·m², so that M stays invertible where their \
             axes align",
            armature.len()
        ));
    }
    armature
}

/// Point masses (MuJoCo refuses them): `inertia_floor` on their moments, when there are any.
pub(super) fn point_masses(reduced: &Model, notes: &mut Vec<String>) -> Option<f64> {
    let points: Vec<String> = reduced
        .joints
        .iter()
        .filter(|j| {
            j.inertia.mass > 0.0
                && nalgebra::SymmetricEigen::new(j.inertia.inertia_com())
                    .eigenvalues
                    .min()
                    <= POINT_MASS
        })
        .map(|j| j.body.clone())
        .collect();
    (!points.is_empty()).then(|| {
        notes.push(format!(
            "{} links are point masses (no rotational inertia: {}): inertia_floor gives them \
             {INERTIA_FLOOR:e} kg·m² about each axis",
            points.len(),
            points.join(", ")
        ));
        INERTIA_FLOOR
    })
}
