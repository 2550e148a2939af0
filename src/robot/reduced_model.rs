//! What the reduced models take from the robot (docs/reduced_models.md): the cart-table's mass
//! and CoM height, the hand's M_e and set-point, the support rectangle. The robot computes them
//! from its model at home ([`super::Robot::reduced`]) and every user receives this value: they
//! are facts of the robot, not settings, so no config key holds them. The reduced models built
//! from it (the cart-table: `ReducedModel::cart_table`) are the preview's and live there.

use nalgebra::{Matrix3, Vector3};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReducedModel {
    /// Total mass M (kg).
    pub mass: f64,
    /// Constant CoM height z_c above the soles (m).
    pub com_height: f64,
    /// The ZMP's support interval about the feet centre, [[x_min, x_max], [y_min, y_max]] (m).
    pub support: [[f64; 2]; 2],
    /// Operational-space inertia M_e of the arm chain at home (kg, 3×3 SPD, eq. (21)–(23)).
    pub effective_mass: Matrix3<f64>,
    /// The hand's set-point in the feet frame (m).
    pub hand_position: Vector3<f64>,
}
