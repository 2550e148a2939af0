//! The floating-base estimator as a controller part (docs/estimation.md): when the plant does
//! not measure the base (or `controller.base_estimation.mode = "on"`), the base of the tick's
//! configuration and velocity is estimated from the IMU, the joints and the foot wrenches, and
//! the measured centre of pressure is the foot wrenches' at the estimated soles.

use crate::col;
use crate::control::frame::TickFrame;
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::estimation::{BaseEstimate, BaseEstimator, EstimatorMode, EstimatorSettings};
use crate::record::Record;

pub struct BaseEstimation {
    estimator: BaseEstimator,
    mode: EstimatorMode,
    /// The estimator ran on the last state.
    ran: bool,
}

impl PartKind for BaseEstimation {
    type Settings = EstimatorSettings;

    fn build(
        s: &PartSetup,
        settings: EstimatorSettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        Ok(Box::new(BaseEstimation {
            estimator: BaseEstimator::new(
                s.model,
                s.contact_frames,
                s.cart.mass * s.cart.gravity,
                s.dt,
                s.imu_frame,
                settings,
            ),
            mode: settings.mode,
            ran: false,
        }))
    }
}

impl BaseEstimation {
    /// The estimator's counters (`None` when it never ran).
    pub fn counts(&self) -> Option<crate::estimation::EstimatorCounts> {
        (self.estimator.counts.ticks > 0).then_some(self.estimator.counts)
    }
}

impl ControllerPart for BaseEstimation {
    fn name(&self) -> &'static str {
        "base_estimation"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Estimate]
    }

    fn reset(&mut self) {
        self.estimator.reset();
    }

    fn update(
        &mut self,
        stage: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let s = inputs.sensed;
        let unmeasured = !s.base_measured;
        self.ran = match self.mode {
            EstimatorMode::On => true,
            EstimatorMode::Auto => unmeasured,
            EstimatorMode::Off if unmeasured => return Err(TickError::BaseUnmeasured),
            EstimatorMode::Off => false,
        };
        if !self.ran {
            return Ok(());
        }
        // The joints are the measurement's; the base is what this part makes of them.
        if !(s.q.iter().skip(7))
            .chain(s.v.iter().skip(6))
            .all(|x| x.is_finite())
        {
            return Err(TickError::NotFinite);
        }
        let feet = *frame.foot_wrenches.or(&s.foot_wrenches);
        let name = self.name();
        let q = frame.q.write(name, stage)?;
        q.copy_from(&s.q);
        let v = frame.v.write(name, stage)?;
        v.copy_from(&s.v);
        self.estimator.update(s, &feet, q, v)?;
        if let Some(cop) = self.estimator.cop {
            *frame.cop.write(name, stage)? = cop;
        }
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        // NaN when the base was measured: the truth is in the simulator's recording.
        let b = if self.ran {
            self.estimator.last
        } else {
            BaseEstimate::UNKNOWN
        };
        out.put(
            col!(fixed("est_x", 6).plot("base/position_x")),
            b.position[0],
        );
        out.put(
            col!(fixed("est_y", 6).plot("base/position_y")),
            b.position[1],
        );
        out.put(
            col!(fixed("est_z", 6).plot("base/position_z")),
            b.position[2],
        );
        out.put(
            col!(fixed("est_vx", 6).plot("base/velocity_x")),
            b.velocity[0],
        );
        out.put(
            col!(fixed("est_vy", 6).plot("base/velocity_y")),
            b.velocity[1],
        );
        out.put(
            col!(fixed("est_vz", 6).plot("base/velocity_z")),
            b.velocity[2],
        );
        out.put(col!(fixed("est_roll", 6).plot("base/roll")), b.rpy[0]);
        out.put(col!(fixed("est_pitch", 6).plot("base/pitch")), b.rpy[1]);
        out.put(col!(fixed("est_yaw", 6).plot("base/yaw")), b.rpy[2]);
        out.put(
            col!(fixed("est_innovation", 3).plot("base/innovation")),
            b.innovation,
        );
        out.flag(
            col!(plain("est_stance_left").plot("base/stance_left")),
            b.stance[0],
        );
        out.flag(
            col!(plain("est_stance_right").plot("base/stance_right")),
            b.stance[1],
        );
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        if let Some(c) = self.counts() {
            out.insert("base_estimation".into(), serde_json::json!(c));
        }
    }
}
