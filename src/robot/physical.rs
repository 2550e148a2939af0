//! Physical checks of a robot's bodies at load, each refused with what to change:
//! - joints that move only massless links (M(q) singular whatever q);
//! - a moving body whose principal moments of inertia about its CoM break the triangle
//!   inequality A + B ≥ C, which every real body satisfies. MuJoCo refuses it too, at compile
//!   time, and its message reached the user only through the simulator's log: the same rule
//!   here makes a description upc accepts run on both plants. Bodies are upc's (a joint's child
//!   link with the links fixed to it merged), as upc writes them into MuJoCo's scene.
//!
//! - a moving body with mass and a zero principal moment (a point mass): MuJoCo refuses it
//!   ("inertia must have positive eigenvalues"); a description's `inertia_floor` gives such
//!   bodies a small moment instead of an edit to the URDF.
//!
//! Values a description left at a placeholder are warnings: nothing refuses them, but the arm's
//! capacity, the force scaling and the torque limits are computed from them.

use nalgebra::SymmetricEigen;

use super::RobotError;
use crate::dynamics::Model;

/// Slack of the triangle inequality: MuJoCo's absolute 1e-15 kg·m², or a relative 1e-9 of the
/// largest moment where that is larger, so that rounding alone never refuses a thin rod (A = 0,
/// B = C) that MuJoCo accepts.
fn slack(largest: f64) -> f64 {
    1e-15_f64.max(1e-9 * largest)
}

/// An effort limit above this many times the torque of the robot's weight at a metre is a
/// placeholder: a humanoid's strongest joints (knees, hips) give a few times that torque at most.
const PLACEHOLDER_WEIGHTS: f64 = 100.0;

/// MuJoCo's smallest positive value (`mjMINVAL`): a principal moment at or below it is none.
const MIN_MOMENT: f64 = 1e-15;

/// Raises each principal moment (about its CoM) of every body with mass to at least `floor`
/// (`inertia_floor` of a description), keeping its principal axes: the bodies that have more
/// are untouched.
pub fn apply_inertia_floor(model: &mut Model, floor: f64) {
    for j in model.joints.iter_mut() {
        if j.inertia.mass <= 0.0 {
            continue;
        }
        let eig = SymmetricEigen::new(j.inertia.inertia_com());
        if eig.eigenvalues.iter().all(|&m| m >= floor) {
            continue;
        }
        let raised = eig.eigenvalues.map(|m| m.max(floor));
        let i = eig.eigenvectors
            * nalgebra::Matrix3::from_diagonal(&raised)
            * eig.eigenvectors.transpose();
        j.inertia = crate::dynamics::Inertia::from_com(j.inertia.mass, j.inertia.com(), i);
    }
}

/// The first moving body with mass whose principal moments are not all positive (a point
/// mass) or break the triangle inequality, as an error naming its link, its moments and what to
/// change.
pub fn check_inertias(model: &Model, robot: &str) -> Result<(), RobotError> {
    for j in model.joints.iter() {
        if j.inertia.mass <= 0.0 {
            continue;
        }
        let mut m: [f64; 3] = SymmetricEigen::new(j.inertia.inertia_com())
            .eigenvalues
            .into();
        m.sort_by(f64::total_cmp);
        // MuJoCo's rule for a body with mass: every principal moment positive.
        if m[0] <= MIN_MOMENT {
            return Err(RobotError::PointMass {
                robot: robot.to_owned(),
                link: j.body.clone(),
                mass: j.inertia.mass,
                moments: format!("{:.3e}, {:.3e}, {:.3e}", m[0], m[1], m[2]),
            });
        }
        if m[0] + m[1] < m[2] - slack(m[2]) {
            return Err(RobotError::Inertia {
                robot: robot.to_owned(),
                link: j.body.clone(),
                moments: format!("{:.3e}, {:.3e}, {:.3e}", m[0], m[1], m[2]),
            });
        }
    }
    Ok(())
}

/// Joints that move only massless links ([`Model::inert_joints`]: M(q) singular), as an error
/// naming them all and both fixes.
pub fn check_inert_joints(model: &Model, robot: &str) -> Result<(), RobotError> {
    let inert = model.inert_joints();
    let Some(&first) = inert.first() else {
        return Ok(());
    };
    let names: Vec<&str> = inert
        .iter()
        .map(|&i| model.joints[i].name.as_str())
        .collect();
    Err(RobotError::InertJoints {
        robot: robot.to_owned(),
        joints: names.join(", "),
        first: model.joints[first].name.clone(),
    })
}

/// Values that look like a description's placeholders: the same effort limit on every
/// actuated joint, a body with 1 kg·m² about each axis.
pub fn placeholder_warnings(model: &Model) -> Vec<String> {
    let mut out = Vec::new();
    let efforts: Vec<f64> = model
        .joints
        .iter()
        .filter(|j| j.nv() == 1)
        .map(|j| j.limits.effort)
        .collect();
    if efforts.len() > 2 && efforts.iter().all(|&e| e.is_finite() && e == efforts[0]) {
        out.push(format!(
            "every one of the {} joints has the effort limit {} (N·m or N): a placeholder? the \
             torque limits, the arm's capacity and the force scaling come from it",
            efforts.len(),
            efforts[0]
        ));
    }
    // An effort no motor of this robot's size gives: more than `PLACEHOLDER_WEIGHTS` times the
    // torque of its whole weight at a metre (icub-models' 50000 N·m on a 33 kg robot).
    let bound = PLACEHOLDER_WEIGHTS * model.total_mass() * 9.81;
    let huge: Vec<String> = model
        .joints
        .iter()
        .filter(|j| j.nv() == 1 && j.limits.effort.is_finite() && j.limits.effort > bound)
        .map(|j| format!("{} ({})", j.name, j.limits.effort))
        .collect();
    if !huge.is_empty() {
        out.push(format!(
            "effort limits above {PLACEHOLDER_WEIGHTS} times the torque of the robot's weight \
             at a metre ({bound:.0} N·m): {} — placeholders? the torque limits, the arm's \
             capacity and the force scaling come from them",
            huge.join(", ")
        ));
    }
    for j in &model.joints {
        let i = j.inertia.inertia_com();
        let unit = (0..3).all(|a| (i[(a, a)] - 1.0).abs() < 1e-12)
            && (i[(0, 1)].abs() + i[(0, 2)].abs() + i[(1, 2)].abs()) < 1e-12;
        if unit {
            out.push(format!(
                "link '{}' has a unit inertia (1 kg·m² about each axis): a placeholder?",
                j.body
            ));
        }
    }
    out
}
