//! The cart-table model of the CoM along one horizontal axis (docs/reduced_models.md, eq. (1)–(3),
//! (10)).

use nalgebra::{Matrix3, Vector3};

use crate::robot::ReducedModel;

/// Cart-table model: state x̂ = [x, ẋ, ẍ], input u = CoM jerk, sampling period T.
#[derive(Debug, Clone, Copy)]
pub struct CartTable {
    /// Sampling period T (s).
    pub period: f64,
    /// Constant CoM height z_c (m).
    pub com_height: f64,
    /// Total mass M (kg).
    pub mass: f64,
    /// Gravity g (m/s²).
    pub gravity: f64,
}

impl CartTable {
    /// A of eq. (3).
    pub fn a(&self) -> Matrix3<f64> {
        let t = self.period;
        Matrix3::new(1.0, t, t * t / 2.0, 0.0, 1.0, t, 0.0, 0.0, 1.0)
    }

    /// B of eq. (3).
    pub fn b(&self) -> Vector3<f64> {
        let t = self.period;
        Vector3::new(t * t * t / 6.0, t * t / 2.0, t)
    }

    /// x̂(k+1) = A x̂(k) + B u(k), eq. (1).
    pub fn step(&self, x: &Vector3<f64>, u: f64) -> Vector3<f64> {
        self.a() * x + self.b() * u
    }

    /// α0 = 1 / (M g) with no disturbance, so that the output row below is Kajita's C.
    pub fn nominal_alpha0(&self) -> f64 {
        1.0 / (self.mass * self.gravity)
    }

    /// The third entry of the output row C(k) = [1, 0, −M z_c α0(k)] (eq. 10); with α0 = 1/(Mg)
    /// it is Kajita's −z_c/g (eq. 3).
    pub fn output_acc_coeff(&self, alpha0: f64) -> f64 {
        -self.mass * self.com_height * alpha0
    }

    /// ZMP of a state under a disturbance (eq. 10): p = x − M z_c α0 ẍ + z_c α.
    pub fn zmp(&self, x: &Vector3<f64>, alpha0: f64, alpha: f64) -> f64 {
        x[0] + self.output_acc_coeff(alpha0) * x[2] + self.com_height * alpha
    }
}

// The robot owns the figures (`crate::robot::ReducedModel`); the cart-table made of them is the
// preview's, so its constructor lives here and the robot needs nothing from the preview.
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
