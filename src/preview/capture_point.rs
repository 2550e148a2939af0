//! The capture point of the cart-table under a constant force (VG-1, docs/forecast_correction.md),
//! per horizontal axis: where the ZMP must be for the robot to stop (Pratt et al.,
//! capturability). The one home of VG-1, read by the capture-point guard and by FC-5b.

/// VG-1 for one cart-table.
#[derive(Debug, Clone, Copy)]
pub struct CapturePoint {
    /// M ω² = M g / z_c (N/m) and 1/ω (s).
    stiffness: f64,
    inv_omega: f64,
}

impl CapturePoint {
    /// For a cart-table of `mass` (kg) at `com_height` (m) under `gravity` (m/s²).
    pub fn new(mass: f64, gravity: f64, com_height: f64) -> Self {
        let omega2 = gravity / com_height;
        Self {
            stiffness: mass * omega2,
            inv_omega: 1.0 / omega2.sqrt(),
        }
    }

    /// M ω² (N/m): the push that moves the capture point by a metre.
    pub fn stiffness(&self) -> f64 {
        self.stiffness
    }

    /// ξ_m = x + ẋ/ω + F/(M ω²) on one axis (VG-1): where the ZMP must be for the robot to stop
    /// under `push` (N) held as it is.
    pub fn at(&self, com: f64, vcom: f64, push: f64) -> f64 {
        com + vcom * self.inv_omega + push / self.stiffness
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Under a constant push F the cart-table's equilibrium ZMP is x + F/(M ω²) (its ZMP
    /// equation ẍ = ω² (x − p) + F/M at rest), and from rest with velocity ẋ the divergent
    /// component x + ẋ/ω is where it stops.
    #[test]
    fn the_capture_point_is_the_divergent_component_shifted_by_the_push() {
        let (m, g, z) = (30.0, 9.81, 0.5);
        let c = CapturePoint::new(m, g, z);
        let omega = (g / z).sqrt();
        assert!((c.at(0.1, 0.0, 0.0) - 0.1).abs() < 1e-15);
        assert!((c.at(0.0, 0.4, 0.0) - 0.4 / omega).abs() < 1e-12);
        let f = -60.0;
        assert!((c.at(0.0, 0.0, f) - f / (m * omega * omega)).abs() < 1e-12);
    }
}
