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

    /// PC-T's P_tail = P∞ − Q_e cᵀc (docs/preview_control.md): P∞ the stabilising solution of
    /// the discrete algebraic Riccati equation for the undisturbed output row c, by its plain
    /// fixed-point iteration (once, at set-up; it converges at the square of the closed loop's
    /// slowest pole).
    pub fn infinite_tail(&self, q_e: f64, r: f64) -> Matrix3<f64> {
        let (a, b) = (self.a(), self.b());
        let c = Vector3::new(1.0, 0.0, self.output_acc_coeff(self.nominal_alpha0()));
        let q = c * c.transpose() * q_e;
        let mut p = q;
        for _ in 0..1_000_000 {
            let pb = p * b;
            let g = a.transpose() * pb;
            let next = q + a.transpose() * p * a - g * g.transpose() / (r + b.dot(&pb));
            let next = (next + next.transpose()) / 2.0;
            let moved = (next - p).abs().max();
            p = next;
            if moved <= 1e-14 * p.abs().max() {
                break;
            }
        }
        p - q
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
