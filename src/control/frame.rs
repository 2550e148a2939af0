//! The tick's shared quantities ([`TickFrame`]): written by the core and by the parts in stage
//! order, read by the later ones. Each slot says how writers combine:
//! - an [`Estimate`] stands in for a measurement: unwritten, readers get the measurement
//!   ([`crate::robot::RobotState`]'s, never copied); one part per stage writes it, and a part of
//!   a later stage refines what an earlier one estimated (the base estimator's CoP, then the
//!   wrench observer's where the robot measures none);
//! - a [`ForceHorizon`] is produced by one part (the forecast correction) or, when none does,
//!   sampled from the forecast by the core; later parts of the stage refine what was produced
//!   (the capture-point guard);
//! - [`ComForces`] and the hand's force offset are sums: every part adds its share;
//! - the hand force's trust is a conjunction: every part that vouches must.
//!
//! What is per hand is in [`HandFrame`], one per end-effector. Preallocated once; refilled
//! every tick without allocating.

use nalgebra::DVector;

use super::tick::{Stage, TickError};
use crate::config::ControllerKind;

/// A quantity a part estimates in place of the measurement (see the module doc).
#[derive(Debug, Clone)]
pub struct Estimate<T> {
    slot: &'static str,
    value: T,
    by: Option<(&'static str, Stage)>,
}

impl<T> Estimate<T> {
    fn new(slot: &'static str, value: T) -> Self {
        Self {
            slot,
            value,
            by: None,
        }
    }

    /// The estimate to write, for `part` at `stage`: refused when another part wrote it at the
    /// same stage this tick (a later stage refines an earlier one).
    pub fn write(&mut self, part: &'static str, stage: Stage) -> Result<&mut T, TickError> {
        if let Some((first, at)) = self.by
            && at == stage
            && first != part
        {
            return Err(TickError::SlotTaken {
                slot: self.slot,
                stage,
                first,
                second: part,
            });
        }
        self.by = Some((part, stage));
        Ok(&mut self.value)
    }

    /// The estimate, when a part made one this tick.
    pub fn estimated(&self) -> Option<&T> {
        self.by.map(|_| &self.value)
    }

    /// The estimate, or the measurement when no part made one.
    pub fn or<'a>(&'a self, measured: &'a T) -> &'a T {
        self.estimated().unwrap_or(measured)
    }

    /// The part that wrote it last this tick.
    pub fn by(&self) -> Option<&'static str> {
        self.by.map(|(p, _)| p)
    }

    fn clear(&mut self) {
        self.by = None;
    }
}

/// The hand force a part makes in place of the wrist sensor's, and how far it lags the force
/// on the hand (s; an estimate's filter).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EstimatedForce {
    pub force: [f64; 3],
    pub lag: f64,
}

/// The hand force over the horizon at t + (i+1)·T (see the module doc).
#[derive(Debug, Clone)]
pub struct ForceHorizon {
    samples: Vec<[f64; 3]>,
    by: Option<&'static str>,
}

impl ForceHorizon {
    fn new(horizon: usize) -> Self {
        Self {
            samples: vec![[0.0; 3]; horizon],
            by: None,
        }
    }

    /// The horizon `part` produces in place of the forecast as received: one part produces it.
    pub fn produce(&mut self, part: &'static str) -> Result<&mut [[f64; 3]], TickError> {
        match self.by {
            Some(first) if first != part => Err(TickError::SlotTaken {
                slot: "the hand force's horizon",
                stage: Stage::Forecast,
                first,
                second: part,
            }),
            _ => {
                self.by = Some(part);
                Ok(&mut self.samples)
            }
        }
    }

    /// The horizon a part produced, to refine; `None` while it is the forecast's (not sampled
    /// yet: the core samples it after the stage).
    pub fn refine(&mut self) -> Option<&mut [[f64; 3]]> {
        self.by.map(|_| self.samples.as_mut_slice())
    }

    /// The part that produced it this tick (`None`: the forecast as received).
    pub fn produced_by(&self) -> Option<&'static str> {
        self.by
    }

    /// The samples: a part's, or after the `Forecast` stage the forecast's.
    pub fn samples(&self) -> &[[f64; 3]] {
        &self.samples
    }

    /// The core's fill when no part produced one.
    pub(super) fn sample_forecast(&mut self, at: impl Fn(usize) -> [f64; 3]) {
        if self.by.is_none() {
            for (i, f) in self.samples.iter_mut().enumerate() {
                *f = at(i);
            }
        }
    }

    fn clear(&mut self) {
        self.by = None;
    }
}

/// What the producer of the horizon knows of the push measured now: the push itself and the
/// horizon as the measurement alone predicts it (what C1 previews without a forecaster, FC-5's
/// measurement model), the horizon as the forecast alone predicts it (the corrected forecast
/// before FC-5's blend) and the forecast's weight w in that blend (1: believed whole).
#[derive(Debug, Clone)]
pub struct MeasuredPrediction {
    pub push: Option<[f64; 3]>,
    pub measured_only: Vec<[f64; 3]>,
    pub forecast_only: Vec<[f64; 3]>,
    pub weight: f64,
}

/// One end-effector's share of the frame.
#[derive(Debug, Clone)]
pub struct HandFrame {
    /// Before `Measure`, the core: the hand's velocity (world, m/s), and what the hand holds:
    /// its apparent mass at the hand Λ (world, kg; zero: nothing held).
    pub vel: [f64; 3],
    pub held_mass: [[f64; 3]; 3],
    /// `Measure`: a part's hand force in place of a wrist sensor the robot does not have.
    pub force: Estimate<EstimatedForce>,
    /// `Measure`: the offsets parts remove from the force (a wrist tare's), summed.
    pub offset: [f64; 3],
    /// `Measure`: whether the force may be fed back: every part that vouches for it must.
    pub trusted: bool,
    /// `Forecast`: the hand force over the horizon.
    pub horizon: ForceHorizon,
    /// `Forecast`: the measurement's prediction, from the part that produced the horizon.
    pub prediction: MeasuredPrediction,
}

impl HandFrame {
    fn new(horizon: usize) -> Self {
        Self {
            vel: [0.0; 3],
            held_mass: [[0.0; 3]; 3],
            force: Estimate::new("the hand force", EstimatedForce::default()),
            offset: [0.0; 3],
            trusted: true,
            horizon: ForceHorizon::new(horizon),
            prediction: MeasuredPrediction {
                push: None,
                measured_only: vec![[0.0; 3]; horizon],
                forecast_only: vec![[0.0; 3]; horizon],
                weight: 1.0,
            },
        }
    }

    /// The hand force the controller uses (N, world): a part's estimate or the measured one,
    /// less the parts' offsets.
    pub fn force_used(&self, measured: &[f64; 3]) -> [f64; 3] {
        let f = self.force.estimated().map_or(measured, |e| &e.force);
        [0, 1, 2].map(|k| f[k] - self.offset[k])
    }

    /// How far (s) [`Self::force_used`] lags the force on the hand (0 for a sensor's).
    pub fn force_lag(&self) -> f64 {
        self.force.estimated().map_or(0.0, |e| e.lag)
    }

    /// Whether the force is a part's estimate, not measured.
    pub fn force_estimated(&self) -> bool {
        self.force.estimated().is_some()
    }

    /// A part's word on whether the force may be fed back.
    pub fn vouch(&mut self, trusted: bool) {
        self.trusted &= trusted;
    }

    fn clear(&mut self) {
        self.force.clear();
        self.offset = [0.0; 3];
        self.trusted = true;
        self.horizon.clear();
        self.prediction.push = None;
    }
}

/// Most forces on the CoM that parts add in one tick.
pub const MAX_COM_FORCES: usize = 4;

/// Forces on the CoM (x, y; N) that parts add to the preview's disturbance, each decaying by
/// its factor per preview step over the horizon; the preview takes their sum.
#[derive(Debug, Clone, Copy, Default)]
pub struct ComForces {
    terms: [([f64; 2], f64); MAX_COM_FORCES],
    len: usize,
}

impl ComForces {
    /// Add a force decaying by `decay` per preview step (its first sample is `force`·`decay`).
    /// Past [`MAX_COM_FORCES`] it is refused (the pipeline's parts outgrew it).
    pub fn add(&mut self, force: [f64; 2], decay: f64) -> Result<(), TickError> {
        let slot = self
            .terms
            .get_mut(self.len)
            .ok_or(TickError::TooManyComForces(MAX_COM_FORCES))?;
        *slot = (force, decay);
        self.len += 1;
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The terms added this tick: (force, decay per preview step).
    pub fn terms(&self) -> &[([f64; 2], f64)] {
        &self.terms[..self.len]
    }

    /// Their sum now (N).
    pub fn now(&self) -> [f64; 2] {
        self.terms()
            .iter()
            .fold([0.0; 2], |s, (f, _)| [s[0] + f[0], s[1] + f[1]])
    }

    fn clear(&mut self) {
        self.len = 0;
    }
}

/// The tick's shared quantities (see the module doc).
pub struct TickFrame {
    pub kind: ControllerKind,
    /// Plant time (s), control period (s), preview period (s).
    pub t: f64,
    pub dt: f64,
    pub period: f64,
    /// `Estimate`: the configuration and velocity the controller uses, when a part estimates
    /// them (the floating base); otherwise the measured ones.
    pub q: Estimate<DVector<f64>>,
    pub v: Estimate<DVector<f64>>,
    /// The centre of pressure (world x, y; m) and each foot's wrench
    /// (`RobotState::foot_wrenches`' convention), when a part estimates them.
    pub cop: Estimate<[f64; 2]>,
    pub foot_wrenches: Estimate<[[f64; 6]; 2]>,
    /// The joint torques the controller commanded at the last tick (nv − 6; zero before).
    pub tau_commanded: DVector<f64>,
    /// From `Measure` on, the core's: the model's CoM (position, velocity) and the support
    /// rectangle [[x_min, x_max], [y_min, y_max]].
    pub com: [f64; 3],
    pub com_vel: [f64; 3],
    pub support: [[f64; 2]; 2],
    /// One per end-effector, never none (the first is the hand the scenario pushes).
    hands: Vec<HandFrame>,
    /// `Disturbance`: the disturbance the preview modelled at the last tick (x, y; N), and the
    /// forces parts add to it.
    pub known_disturbance: [f64; 2],
    pub com_forces: ComForces,
}

impl TickFrame {
    pub fn new(kind: ControllerKind, nq: usize, nv: usize, horizon: usize, hands: usize) -> Self {
        Self {
            kind,
            t: 0.0,
            dt: 0.0,
            period: 0.0,
            q: Estimate::new("the configuration", DVector::zeros(nq)),
            v: Estimate::new("the velocity", DVector::zeros(nv)),
            cop: Estimate::new("the centre of pressure", [0.0; 2]),
            foot_wrenches: Estimate::new("the foot wrenches", [[0.0; 6]; 2]),
            tau_commanded: DVector::zeros(nv.saturating_sub(6)),
            com: [0.0; 3],
            com_vel: [0.0; 3],
            support: [[0.0; 2]; 2],
            hands: (0..hands.max(1)).map(|_| HandFrame::new(horizon)).collect(),
            known_disturbance: [0.0; 2],
            com_forces: ComForces::default(),
        }
    }

    /// A new tick at plant time `t`: every estimate, sum and vouch starts over.
    pub(super) fn start(&mut self, t: f64, dt: f64, period: f64) {
        (self.t, self.dt, self.period) = (t, dt, period);
        self.q.clear();
        self.v.clear();
        self.cop.clear();
        self.foot_wrenches.clear();
        self.com_forces.clear();
        for h in &mut self.hands {
            h.clear();
        }
    }

    /// Each end-effector's share.
    pub fn hands(&self) -> &[HandFrame] {
        &self.hands
    }

    pub fn hands_mut(&mut self) -> &mut [HandFrame] {
        &mut self.hands
    }

    /// A new plant session: what the parts predicted at the last tick is forgotten (a
    /// forecast's weight back to 1).
    pub(super) fn reset_predictions(&mut self) {
        for h in &mut self.hands {
            h.prediction.push = None;
            h.prediction.weight = 1.0;
        }
    }

    /// The first end-effector's share (`hands` is never empty: built with at least one).
    pub fn hand(&self) -> &HandFrame {
        &self.hands[0]
    }

    pub fn hand_mut(&mut self) -> &mut HandFrame {
        &mut self.hands[0]
    }

    /// Whether the floating base is a part's estimate this tick.
    pub fn base_estimated(&self) -> bool {
        self.q.estimated().is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_estimate_is_the_measurement_until_written_and_one_part_per_stage_writes_it() {
        let mut e = Estimate::new("x", 0.0);
        assert_eq!(*e.or(&5.0), 5.0);
        *e.write("a", Stage::Estimate).unwrap() = 1.0;
        assert_eq!((*e.or(&5.0), e.by()), (1.0, Some("a")));
        // The same part again, and a later stage's part refining it.
        *e.write("a", Stage::Estimate).unwrap() = 2.0;
        *e.write("b", Stage::Measure).unwrap() = 3.0;
        assert_eq!((*e.or(&5.0), e.by()), (3.0, Some("b")));
        // A second part at the same stage is refused, and names both.
        let err = e.write("c", Stage::Measure).unwrap_err().to_string();
        assert!(err.contains("`c`") && err.contains("`b`"), "{err}");
        e.clear();
        assert_eq!(*e.or(&5.0), 5.0);
    }

    #[test]
    fn com_forces_add_up_and_a_horizon_has_one_producer() {
        let mut c = ComForces::default();
        c.add([1.0, 2.0], 0.5).unwrap();
        c.add([3.0, -1.0], 0.9).unwrap();
        assert_eq!(c.now(), [4.0, 1.0]);
        assert_eq!(c.terms().len(), 2);
        for _ in 2..MAX_COM_FORCES {
            c.add([0.0; 2], 1.0).unwrap();
        }
        assert!(c.add([0.0; 2], 1.0).is_err());

        let mut h = ForceHorizon::new(3);
        assert!(h.refine().is_none(), "nothing to refine before a producer");
        h.produce("p").unwrap()[0] = [1.0, 0.0, 0.0];
        assert!(h.produce("q").is_err());
        h.refine().unwrap()[1] = [2.0, 0.0, 0.0];
        h.sample_forecast(|_| [9.0; 3]);
        assert_eq!(h.samples()[..2], [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        h.clear();
        h.sample_forecast(|i| [i as f64; 3]);
        assert_eq!(h.samples()[2], [2.0; 3]);
    }

    #[test]
    fn the_hand_force_is_the_estimate_or_the_measurement_less_the_offsets() {
        let mut h = HandFrame::new(2);
        let measured = [10.0, f64::NAN, 1.0];
        h.offset = [1.0, 0.0, 0.0];
        let f = h.force_used(&measured);
        assert_eq!((f[0], f[2]), (9.0, 1.0));
        assert!(f[1].is_nan());
        h.force.write("obs", Stage::Measure).unwrap().force = [4.0, 5.0, 6.0];
        assert_eq!(h.force_used(&measured), [3.0, 5.0, 6.0]);
        assert!(h.force_estimated());
        h.vouch(true);
        h.vouch(false);
        h.vouch(true);
        assert!(!h.trusted);
        h.clear();
        assert!(h.trusted && !h.force_estimated());
    }
}
