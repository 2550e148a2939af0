//! A disturbance observer on the cart-table (docs/forecast_correction.md, "CoM observer"): the
//! horizontal force on the CoM that nothing forecasts, from the measured CoM velocity and
//! centre of pressure. Per axis, eq. (10) with F_z = 0 reads
//!
//!   M ẍ = (M g / z_c) (x − p) + F_known + F_obs,                              (OB-1)
//!
//! F_known the disturbance the preview already models (C1's F_dis now; 0 for C0). The observer
//! estimates ẋ and d = F_obs / M with a second-order Luenberger observer whose error dynamics
//! s² + 2ζω s + ω² put both poles at the bandwidth ω (OB-2); its estimate enters the preview as
//! M d̂ e^{−s/T_d} over the horizon, as the forecast correction's offset does.

pub use crate::config::ComObserverSettings;

/// The observer's state, both horizontal axes.
#[derive(Debug, Clone)]
pub struct ComObserver {
    s: ComObserverSettings,
    mass: f64,
    /// ω₀² = g / z_c.
    omega2: f64,
    dt: f64,
    l1: f64,
    l2: f64,
    vel: [f64; 2],
    d: [f64; 2],
    started: bool,
}

impl ComObserver {
    pub fn new(s: ComObserverSettings, mass: f64, gravity: f64, com_height: f64, dt: f64) -> Self {
        let w = 2.0 * std::f64::consts::PI * s.bandwidth;
        Self {
            s,
            mass,
            omega2: gravity / com_height,
            dt,
            // (OB-2) in discrete time: gains per step of the continuous 2ζω and ω².
            l1: (2.0 * s.damping * w * dt).min(1.0),
            l2: w * w * dt,
            vel: [0.0; 2],
            d: [0.0; 2],
            started: false,
        }
    }

    pub fn settings(&self) -> &ComObserverSettings {
        &self.s
    }

    pub fn reset(&mut self) {
        self.vel = [0.0; 2];
        self.d = [0.0; 2];
        self.started = false;
    }

    /// One control period: CoM position and velocity, CoP (measured) and the disturbance the
    /// preview already models (N), per axis.
    pub fn update(&mut self, com: [f64; 2], com_vel: [f64; 2], cop: [f64; 2], known: [f64; 2]) {
        if !(com.iter().chain(&com_vel).chain(&cop).chain(&known)).all(|v| v.is_finite()) {
            return;
        }
        if !self.started {
            self.vel = com_vel;
            self.started = true;
            return;
        }
        let lim = self.s.max_force / self.mass;
        for a in 0..2 {
            // Prediction by (OB-1), correction by the measured velocity.
            let acc = self.omega2 * (com[a] - cop[a]) + known[a] / self.mass + self.d[a];
            let pred = self.vel[a] + self.dt * acc;
            let e = com_vel[a] - pred;
            self.vel[a] = pred + self.l1 * e;
            self.d[a] = (self.d[a] + self.l2 * e).clamp(-lim, lim);
        }
    }

    /// F_obs = M d̂ (N), per axis.
    pub fn force(&self) -> [f64; 2] {
        self.d.map(|d| d * self.mass)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cart-table pushed by a constant force, its CoP held: the observer finds the force.
    #[test]
    fn a_constant_push_is_found_within_its_bandwidth() {
        let (m, g, z, dt) = (30.0, 9.81, 0.5, 1e-3);
        let s = ComObserverSettings {
            enabled: true,
            ..Default::default()
        };
        let mut ob = ComObserver::new(s, m, g, z, dt);
        let (mut x, mut v) = (0.0, 0.0);
        let f = 25.0;
        let p = -0.01;
        for k in 0..400 {
            let a = g / z * (x - p) + f / m;
            ob.update([x, 0.0], [v, 0.0], [p, 0.0], [0.0; 2]);
            v += a * dt;
            x += v * dt;
            if k == 150 {
                // Two poles at 5 Hz: well on its way after 0.15 s.
                assert!(ob.force()[0] > 0.6 * f, "{:?}", ob.force());
            }
        }
        assert!((ob.force()[0] - f).abs() < 0.5, "{:?}", ob.force());
        assert!(ob.force()[1].abs() < 1e-9);
        // A force the preview already models is not found again.
        let mut ob = ComObserver::new(s, m, g, z, dt);
        let (mut x, mut v) = (0.0, 0.0);
        for _ in 0..400 {
            let a = g / z * (x - p) + f / m;
            ob.update([x, 0.0], [v, 0.0], [p, 0.0], [f, 0.0]);
            v += a * dt;
            x += v * dt;
        }
        assert!(ob.force()[0].abs() < 0.5, "{:?}", ob.force());
    }
}
