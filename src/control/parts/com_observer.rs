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

use serde::{Deserialize, Serialize};

use crate::col;
use crate::config::ControllerKind;
use crate::control::frame::TickFrame;
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::record::Record;

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

/// The CoM observer as a controller part (`enabled`; for C0 too): its force, decaying over the
/// horizon, is added to the preview's disturbance.
pub struct Observer {
    observer: Option<ComObserver>,
}

impl PartKind for Observer {
    type Settings = ComObserverSettings;

    fn build(
        s: &PartSetup,
        settings: ComObserverSettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        let c = s.cart;
        Ok(Box::new(Observer {
            observer: settings
                .enabled
                .then(|| ComObserver::new(settings, c.mass, c.gravity, c.com_height, s.dt)),
        }))
    }
}

impl ControllerPart for Observer {
    fn name(&self) -> &'static str {
        "com_observer"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Disturbance]
    }

    fn reset(&mut self) {
        if let Some(o) = self.observer.as_mut() {
            o.reset();
        }
    }

    /// Against the disturbance the preview modelled at the last tick (none for C0).
    fn update(
        &mut self,
        _: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let Some(o) = self.observer.as_mut() else {
            return Ok(());
        };
        let known = if frame.kind == ControllerKind::C0 {
            [0.0; 2]
        } else {
            frame.known_disturbance
        };
        let (com, vcom) = (frame.com, frame.com_vel);
        let cop = *frame.cop.or(&inputs.sensed.cop);
        o.update([com[0], com[1]], [vcom[0], vcom[1]], cop, known);
        let decay = (-frame.period / o.settings().decay).exp();
        frame.com_forces.add(o.force(), decay)
    }

    fn record(&self, out: &mut Record) {
        let f = self.observer.as_ref().map_or([0.0; 2], |o| o.force());
        out.put(col!(fixed("f_obs_x", 3).plot("observer/f_x")), f[0]);
        out.put(col!(fixed("f_obs_y", 3).plot("observer/f_y")), f[1]);
    }

    fn summarize(&self, _out: &mut serde_json::Map<String, serde_json::Value>) {}
}

/// `[controller.com_observer]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ComObserverSettings {
    /// Estimate and preview pushes on the CoM that nothing forecasts (C0, C1, C2).
    pub enabled: bool,
    /// Bandwidth of the observer (Hz).
    pub bandwidth: f64,
    /// Damping ratio of its error dynamics.
    pub damping: f64,
    /// Time constant of the estimate's decay over the horizon (s).
    pub decay: f64,
    /// Largest force the estimate may take, per axis (N): a tipping foot breaks eq. (OB-1).
    pub max_force: f64,
}

impl Default for ComObserverSettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for ComObserverSettings {
    const TABLE: &'static str = "com_observer";

    fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, v) in [
            ("bandwidth", self.bandwidth),
            ("damping", self.damping),
            ("decay", self.decay),
            ("max_force", self.max_force),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        Ok(())
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
