//! The feet's wrenches, the centre of pressure and the hand's force estimated from the joint
//! torques (`crate::estimation::wrench_observer`, docs/estimation.md, WO), for a robot that
//! does not measure them: a Unitree G1 reports its joints, its motors' torque estimates and an
//! IMU, and no foot or wrist force sensor.
//!
//! At [`Stage::Estimate`] the last tick's feet estimate stands in for the unmeasured foot
//! wrenches (the base estimator's stance and centre of pressure read them); at
//! [`Stage::Measure`], on the base as estimated, the observer updates and its estimates replace
//! what the robot does not measure (in `auto`), before the wrist tare and every later part.

use serde::{Deserialize, Serialize};

use crate::col;
use crate::control::frame::{EstimatedForce, TickFrame};
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::estimation::wrench_observer::{
    ContactWrenches, DriveFriction, WrenchObserver, WrenchObserverGains,
};
use crate::record::Record;

/// When the observer's estimates are used (`controller.wrench_observer.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WrenchMode {
    /// For each wrench the robot does not measure (NaN in its state).
    Auto,
    /// For every wrench, over the measured ones (to compare them).
    On,
    /// Never: the observer does not run.
    Off,
}

/// `[controller.wrench_observer]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WrenchObserverSettings {
    pub mode: WrenchMode,
    /// K of WO-2 (1/s): the estimates follow a step with this bandwidth.
    pub gain: f64,
    /// σ of the base's linear velocity (m/s), its angular velocity (rad/s) and the joints'
    /// velocities (rad/s) as the controller has them, and of a joint's torque (N·m): WO-4's
    /// weights.
    pub velocity_noise: [f64; 3],
    pub torque_noise: f64,
    /// ε of WO-4: a joint torque's σ grows by this fraction of its effort limit.
    pub torque_noise_fraction: f64,
    /// K₂ of WO-5 (1/s): a second stage on the residual; 0: none.
    pub filter_gain: f64,
    /// ω of WO-7 (1/s): the hand's force through a stage of its own that follows a ramp
    /// without lag; 0: from WO-5's residual as the feet's.
    pub hand_bandwidth: f64,
    /// WO-8: the hand's force read ahead by WO-2's lag 1/K through WO-7's rate (with WO-7).
    pub hand_lead: bool,
    /// WO-6, the drives' friction as identified: Coulomb as a fraction of each joint's effort
    /// limit, the velocity over which it changes sign (rad/s), viscous (N·m·s/rad).
    pub friction_coulomb: f64,
    pub friction_velocity: f64,
    pub friction_viscous: f64,
}

impl Default for WrenchObserverSettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for WrenchObserverSettings {
    const TABLE: &'static str = "wrench_observer";

    fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.gain.is_finite() && self.gain > 0.0) {
            return Err(("gain", format!("must be finite and > 0, got {}", self.gain)));
        }
        let sizes = [
            self.velocity_noise.as_slice(),
            &[self.torque_noise, self.torque_noise_fraction],
            &[self.filter_gain, self.hand_bandwidth],
            &[self.friction_coulomb, self.friction_viscous],
        ]
        .concat();
        if !sizes.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err((
                "velocity_noise",
                "the noise sizes, filter gains and friction must be finite and ≥ 0".into(),
            ));
        }
        if self.friction_coulomb > 0.0
            && (self.friction_velocity.is_nan() || self.friction_velocity <= 0.0)
        {
            return Err((
                "friction_velocity",
                format!(
                    "must be > 0 with a Coulomb friction, got {}",
                    self.friction_velocity
                ),
            ));
        }
        Ok(())
    }
}

impl PartKind for WrenchObserverPart {
    type Settings = WrenchObserverSettings;

    fn build(
        s: &PartSetup,
        settings: WrenchObserverSettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        let hand = s.model.frame_id(&s.robot.frames().hand)?;
        let gains = WrenchObserverGains {
            gain: settings.gain,
            velocity_noise: settings.velocity_noise,
            torque_noise: settings.torque_noise,
            torque_noise_fraction: settings.torque_noise_fraction,
            filter_gain: settings.filter_gain,
            hand_bandwidth: settings.hand_bandwidth,
            hand_lead: settings.hand_lead,
            friction: DriveFriction {
                coulomb: settings.friction_coulomb,
                velocity: settings.friction_velocity,
                viscous: settings.friction_viscous,
            },
        };
        Ok(Box::new(WrenchObserverPart {
            observer: WrenchObserver::new(s.model, s.contact_frames, hand, gains),
            mode: settings.mode,
            counts: WrenchCounts::default(),
            last_time: None,
            observed: false,
        }))
    }
}

/// What the observer stands in for this tick.
#[derive(Debug, Clone, Copy)]
struct Estimated {
    feet: bool,
    cop: bool,
    hand: bool,
}

/// What the observer did over a run (`summary.json`'s `wrench_observer`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct WrenchCounts {
    pub updates: u64,
    /// Ticks whose feet wrenches, centre of pressure and hand force were the observer's.
    pub feet_ticks: u64,
    pub cop_ticks: u64,
    pub hand_ticks: u64,
    /// Updates on the commanded torques (the state measured none).
    pub commanded_torque_ticks: u64,
    /// Updates that failed (a state the model refused): the last estimate stood.
    pub failures: u64,
}

/// The observer as a controller part.
pub struct WrenchObserverPart {
    observer: WrenchObserver,
    mode: WrenchMode,
    pub counts: WrenchCounts,
    last_time: Option<f64>,
    /// Whether the observer ran this tick (its columns are empty where it did not).
    observed: bool,
}

impl WrenchObserverPart {
    /// The last estimate.
    pub fn estimate(&self) -> &ContactWrenches {
        &self.observer.last
    }

    /// Whether to stand in for a quantity the robot measures (`measured`) or not.
    fn replaces(&self, measured: bool) -> bool {
        match self.mode {
            WrenchMode::On => true,
            WrenchMode::Auto => !measured,
            WrenchMode::Off => false,
        }
    }

    /// WO on this tick's configuration and velocity (the base estimated), on the measured
    /// joint torques, or the commanded ones where the robot measures none.
    fn observe(&mut self, inputs: &TickInputs, frame: &TickFrame) {
        let s = inputs.sensed;
        let measured = &s.joint_torques;
        let torques = measured.as_slice().get(6..).unwrap_or(&[]);
        let tau = if !torques.is_empty() && torques.iter().all(|x| x.is_finite()) {
            torques
        } else {
            self.counts.commanded_torque_ticks += 1;
            frame.tau_commanded.as_slice()
        };
        let dt = self.last_time.map_or(0.0, |t0| frame.t - t0);
        self.last_time = Some(frame.t);
        match self
            .observer
            .update(frame.q.or(&s.q), frame.v.or(&s.v), tau, dt)
        {
            Ok(_) => self.counts.updates += 1,
            Err(e) => {
                self.counts.failures += 1;
                if self.counts.failures.is_power_of_two() {
                    tracing::warn!("wrench observer: {e} ({} so far)", self.counts.failures);
                }
            }
        }
    }
}

impl ControllerPart for WrenchObserverPart {
    fn name(&self) -> &'static str {
        "wrench_observer"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Estimate, Stage::Measure]
    }

    fn reset(&mut self) {
        self.observer.reset();
        self.last_time = None;
        self.observed = false;
    }

    fn update(
        &mut self,
        stage: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        if self.mode == WrenchMode::Off {
            return Ok(());
        }
        let s = inputs.sensed;
        let feet_measured = s.foot_wrenches.iter().flatten().all(|x| x.is_finite());
        match stage {
            Stage::Estimate => {
                // The last tick's feet, for the base estimator's stance and CoP.
                if self.replaces(feet_measured) {
                    *frame.foot_wrenches.write(self.name(), stage)? = self.observer.last.feet;
                }
            }
            _ => {
                let e = Estimated {
                    feet: self.replaces(feet_measured),
                    cop: self.replaces(s.cop.iter().all(|x| x.is_finite())),
                    hand: self.replaces(s.hand_force.iter().all(|x| x.is_finite())),
                };
                self.observed = e.feet || e.cop || e.hand;
                if !self.observed {
                    return Ok(()); // the robot measures them all: nothing to stand in for
                }
                self.observe(inputs, frame);
                let (w, name) = (self.observer.last, self.name());
                if e.feet {
                    *frame.foot_wrenches.write(name, stage)? = w.feet;
                    self.counts.feet_ticks += 1;
                }
                if let (true, Some(cop)) = (e.cop, w.cop) {
                    *frame.cop.write(name, stage)? = cop;
                    self.counts.cop_ticks += 1;
                }
                if e.hand {
                    *frame.hand_mut().force.write(name, stage)? = EstimatedForce {
                        force: w.hand,
                        lag: self.observer.hand_lag(),
                    };
                    self.counts.hand_ticks += 1;
                }
            }
        }
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        const UNOBSERVED: ContactWrenches = ContactWrenches {
            feet: [[f64::NAN; 6]; 2],
            hand: [f64::NAN; 3],
            cop: None,
            normal_force: f64::NAN,
        };
        let w = if self.observed {
            &self.observer.last
        } else {
            &UNOBSERVED
        };
        let cop = w.cop.unwrap_or([f64::NAN; 2]);
        out.put(col!(fixed("wo_hand_x", 3).plot("wrench/hand_x")), w.hand[0]);
        out.put(col!(fixed("wo_hand_y", 3).plot("wrench/hand_y")), w.hand[1]);
        out.put(col!(fixed("wo_hand_z", 3).plot("wrench/hand_z")), w.hand[2]);
        out.put(
            col!(fixed("wo_fz_left", 2).plot("wrench/fz_left")),
            w.feet[0][2],
        );
        out.put(
            col!(fixed("wo_fz_right", 2).plot("wrench/fz_right")),
            w.feet[1][2],
        );
        out.put(col!(fixed("wo_cop_x", 5).plot("wrench/cop_x")), cop[0]);
        out.put(col!(fixed("wo_cop_y", 5).plot("wrench/cop_y")), cop[1]);
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        if self.counts.updates + self.counts.failures > 0 {
            out.insert("wrench_observer".into(), serde_json::json!(self.counts));
        }
    }
}
