//! What the reduced models take from the robot (docs/reduced_models.md): the cart-table's mass
//! and CoM height, the hand's M_e and set-point, the support rectangle. `crate::robot` computes
//! them from the model at home (`crate::robot::Robot::reduced`) and every user receives this
//! value: they are facts of the robot, not settings, so no config key holds them.

use nalgebra::{Matrix3, Vector3};

use super::CartTable;

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

impl ReducedModel {
    /// The cart-table of eq. (1)–(3) sampled at `period` under gravity `gravity` (a setting of
    /// the world, `robot.gravity` of the config).
    pub fn cart_table(&self, period: f64, gravity: f64) -> CartTable {
        CartTable {
            period,
            com_height: self.com_height,
            mass: self.mass,
            gravity,
        }
    }
}
