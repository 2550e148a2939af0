//! The forecast correction as a controller part: the horizon's hand force from the forecast
//! and the measured force, and what the correction did over a run.

use serde::{Deserialize, Serialize};

use super::{CorrectionCounts, CorrectionEstimate, CorrectionSettings, ForecastCorrector};
use crate::col;
use crate::config::{ControllerKind, HandForceSource};
use crate::control::frame::TickFrame;
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::record::Record;

/// The forecast correction as a controller part (C1, C2 with `enabled`; inactive otherwise):
/// it produces the horizon's hand force from the forecast and the measured force, and leaves
/// its measurement's prediction in the frame.
pub struct Correction {
    corrector: Option<ForecastCorrector>,
    /// The hand force the whole-body QP is given: when it is the corrected force, its
    /// door-inertia term closes a loop through the hand's acceleration, which a lag of K bins
    /// destabilises (FC-1c: K = 1).
    qp_force: HandForceSource,
}

impl PartKind for Correction {
    type Settings = CorrectionSettings;

    fn build(
        s: &PartSetup,
        settings: CorrectionSettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        let weight = s.cart.mass * s.cart.gravity;
        let corrector = (settings.enabled && s.kind != ControllerKind::C0)
            .then(|| ForecastCorrector::new(settings, s.period, s.dt, weight));
        Ok(Box::new(Correction {
            corrector,
            qp_force: s.qp_hand_force,
        }))
    }
}

impl ControllerPart for Correction {
    fn name(&self) -> &'static str {
        "forecast_correction"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Forecast]
    }

    fn reset(&mut self) {
        if let Some(c) = self.corrector.as_mut() {
            c.reset();
        }
    }

    fn update(
        &mut self,
        _: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let Some(c) = self.corrector.as_mut() else {
            return Ok(());
        };
        let (t, period, base_estimated) = (frame.t, frame.period, frame.base_estimated());
        let hand = frame.hand_mut();
        c.set_held_mass(hand.held_mass);
        c.set_measurement_lag(hand.force_lag());
        let fed_back = self
            .qp_force
            .resolve(hand.force_estimated())
            .from_correction();
        c.set_velocity_noise(match base_estimated && !fed_back {
            true => c.settings().hand_velocity_noise,
            false => 0.0,
        });
        let measured = hand.force_used(&inputs.sensed.hand_force);
        c.update(
            t,
            inputs.forecast,
            Some(measured),
            hand.vel,
            inputs.sensed.held,
        );
        let p = &mut hand.prediction;
        c.fill(
            t,
            period,
            inputs.forecast,
            hand.horizon.produce("forecast_correction")?,
            &mut p.measured_only,
            &mut p.forecast_only,
        );
        p.push = Some(c.measured_push());
        p.weight = c.estimate().weight;
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        let e = self
            .corrector
            .as_ref()
            .map(|c| *c.estimate())
            .unwrap_or_default();
        out.put(
            col!(fixed("corr_factor", 4).plot("correction/factor")),
            e.factor,
        );
        out.put(
            col!(fixed("corr_shift", 4).plot("correction/shift")),
            e.shift,
        );
        out.put(
            col!(fixed("corr_offset_x", 3).plot("correction/offset_x")),
            e.offset[0],
        );
        out.put(col!(fixed("corr_offset_y", 3)), e.offset[1]);
        out.put(col!(fixed("corr_offset_z", 3)), e.offset[2]);
        out.flag(
            col!(plain("corr_contradicted").plot("correction/contradicted")),
            e.contradicted,
        );
        out.put(
            col!(fixed("corr_trend_x", 2).plot("correction/trend_x")),
            e.trend[0],
        );
        out.put(col!(fixed("corr_trend_y", 2)), e.trend[1]);
        out.put(
            col!(fixed("corr_weight", 4).plot("correction/weight")),
            e.weight,
        );
        out.put(
            col!(fixed("corr_error_forecast", 3).plot("correction/error_forecast")),
            e.error_forecast,
        );
        out.put(
            col!(fixed("corr_error_measured", 3).plot("correction/error_measured")),
            e.error_measured,
        );
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        if let Some(c) = &self.corrector {
            let s = CorrectionSummary::of(c.counts, c.estimate());
            out.insert("forecast_correction".into(), serde_json::json!(s));
        }
    }
}

/// What the forecast correction did over a run.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct CorrectionSummary {
    /// Times the measured hand force contradicted the forecast, and the plant time it did.
    pub contradictions: u64,
    pub contradicted_time: f64,
    /// κ̂: smallest, largest and last; τ̂ last (s); d̂ last (N).
    pub factor_min: f64,
    pub factor_max: f64,
    pub factor_last: f64,
    pub shift_last: f64,
    pub offset_last: [f64; 3],
    /// Estimations of κ̂, τ̂; ticks whose measured force was not finite.
    pub estimations: u64,
    pub bad_measurements: u64,
    /// Ticks whose corrected horizon was capped at `max_lift` M g upward.
    #[serde(default)]
    pub lift_capped: u64,
    /// FC-5: the forecast's smallest weight against measurement only, times it was
    /// discounted (weight below 0.5) and the plant time it stayed so (s).
    pub weight_min: f64,
    pub discounts: u64,
    pub discounted_time: f64,
    /// Gaps in plant time across which no hand acceleration was taken.
    #[serde(default)]
    pub time_gaps: u64,
    /// Stalls of the controller (gaps in its ticks) or states its plant held after the first
    /// estimate, after which κ̂ and τ̂ were kept for a window (FC-2d).
    #[serde(default)]
    pub stalls: u64,
}

impl CorrectionSummary {
    /// From the corrector's counters and its last estimate.
    pub fn of(c: CorrectionCounts, e: &CorrectionEstimate) -> Self {
        Self {
            contradictions: c.contradictions,
            contradicted_time: c.contradicted_time,
            factor_min: c.factor_min,
            factor_max: c.factor_max,
            factor_last: e.factor,
            shift_last: e.shift,
            offset_last: e.offset,
            estimations: c.estimations,
            bad_measurements: c.bad_measurements,
            lift_capped: c.lift_capped,
            weight_min: c.weight_min,
            discounts: c.discounts,
            discounted_time: c.discounted_time,
            time_gaps: c.time_gaps,
            stalls: c.stalls,
        }
    }
}
