//! The controller's parts behind one seam (as an observer pipeline): each part — the wrench
//! observer, the base estimator, the wrist tare, the forecast correction, the capture-point guard, the CoM
//! observer — declares its settings (its table, [`crate::config::PartSettings`]), its reset,
//! its update on the tick's shared quantities ([`TickFrame`]) at its [`Stage`], the values it
//! records ([`Record`]) and its counters for `summary.json`. The tick runs the parts of each
//! stage in [`PIPELINE`] order; reset, records and the summary come from the same list.
//!
//! A new part: one file implementing [`ControllerPart`] and one line in [`PIPELINE`] (its
//! settings' table in `config/default.toml`, its docs).

use std::any::Any;

use nalgebra::DVector;

use super::core::TickError;
use super::forecast_window::ForecastWindow;
use crate::config::{Config, ConfigError, ControllerKind, Layers, PartSettings, PartTables};
use crate::dynamics::Model;
use crate::preview::CartTable;
use crate::record::Record;
use crate::robot::N_CONTACTS;
use crate::robot::{Robot, RobotState};

/// Where in the tick a part runs (in this order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// On the measured state, before the model's kinematics: the floating base.
    Estimate,
    /// After the kinematics: what the controller makes of the measured forces.
    Measure,
    /// The hand force over the horizon.
    Forecast,
    /// Forces on the CoM that the preview adds to its disturbance.
    Disturbance,
}

/// What a part is built from.
pub struct PartSetup<'a> {
    /// The robot: its description, frames and model as loaded (the controller's model below
    /// has the config's gravity).
    pub robot: &'a Robot,
    pub config: &'a Config,
    pub kind: ControllerKind,
    /// The controller's model (its gravity set).
    pub model: &'a Model,
    /// The preview's cart-table (mass, gravity, CoM height).
    pub cart: &'a CartTable,
    /// Control period (s).
    pub dt: f64,
    /// The sole corners' frames (four per foot, left first).
    pub contact_frames: [usize; N_CONTACTS],
    /// The IMU's frame; `None`: on the base.
    pub imu_frame: Option<usize>,
}

/// The tick's read-only inputs.
pub struct TickInputs<'a> {
    pub sensed: &'a RobotState,
    pub forecast: &'a ForecastWindow,
}

/// The tick's shared quantities: written by the core and by the parts in stage order, read by
/// the later ones. Preallocated once; refilled every tick.
pub struct TickFrame {
    pub kind: ControllerKind,
    /// Plant time (s), control period (s), preview period (s).
    pub t: f64,
    pub dt: f64,
    pub period: f64,
    /// `Estimate`: the configuration and velocity the controller uses (the measured ones, the
    /// base estimated when `estimate_base`), and the measured centre of pressure.
    pub q: DVector<f64>,
    pub v: DVector<f64>,
    pub estimate_base: bool,
    pub cop: [f64; 2],
    /// Each foot's wrench (`RobotState::foot_wrenches`' convention): the measured ones, or a
    /// part's estimate where the robot has no foot sensors.
    pub foot_wrenches: [[f64; 6]; 2],
    /// The joint torques the controller commanded at the last tick (nv − 6; zero before).
    pub tau_commanded: DVector<f64>,
    /// From `Measure` on: the model's CoM (position, velocity), the hand's velocity, the
    /// support rectangle [[x_min, x_max], [y_min, y_max]].
    pub com: [f64; 3],
    pub com_vel: [f64; 3],
    pub hand_vel: [f64; 3],
    pub support: [[f64; 2]; 2],
    /// `Measure`: the hand force the controller uses (N) and whether it may be fed back.
    pub hand_force: [f64; 3],
    pub hand_force_trusted: bool,
    /// `Measure`: how far (s) `hand_force` lags the force on the hand (an estimate's filter;
    /// 0 for a sensor's).
    pub hand_force_lag: f64,
    /// `Measure`: whether `hand_force` is estimated (a part stands in for a wrist sensor the
    /// robot does not have), not measured.
    pub hand_force_estimated: bool,
    /// `Forecast`: the hand force over the horizon at t + (i+1)·T and the push measured now,
    /// when a part knows it. A part that fills `f_ext` fills all of it and sets `f_ext_filled`;
    /// otherwise the core fills it from the forecast as received after the `Forecast` stage,
    /// so a `Forecast` part reads it only after one that fills it (as the viability guard
    /// does, on `measured_push`).
    pub f_ext: Vec<[f64; 3]>,
    pub f_ext_filled: bool,
    pub measured_push: Option<[f64; 3]>,
    /// `Forecast`: the same horizon as the measurement alone predicts it (what C1 previews
    /// without a forecaster), where a part knows it (`measured_push` is then set).
    pub f_measured_only: Vec<[f64; 3]>,
    /// `Disturbance`: the disturbance the preview modelled at the last tick (x, y; N), and the
    /// force a part adds to it with its decay per preview step.
    pub known_disturbance: [f64; 2],
    pub com_force: [f64; 2],
    pub com_force_decay: Option<f64>,
}

impl TickFrame {
    pub fn new(kind: ControllerKind, nq: usize, nv: usize, horizon: usize) -> Self {
        Self {
            kind,
            t: 0.0,
            dt: 0.0,
            period: 0.0,
            q: DVector::zeros(nq),
            v: DVector::zeros(nv),
            estimate_base: false,
            cop: [0.0; 2],
            foot_wrenches: [[0.0; 6]; 2],
            tau_commanded: DVector::zeros(nv.saturating_sub(6)),
            com: [0.0; 3],
            com_vel: [0.0; 3],
            hand_vel: [0.0; 3],
            support: [[0.0; 2]; 2],
            hand_force: [0.0; 3],
            hand_force_trusted: true,
            hand_force_lag: 0.0,
            hand_force_estimated: false,
            f_ext: vec![[0.0; 3]; horizon],
            f_ext_filled: false,
            measured_push: None,
            f_measured_only: vec![[0.0; 3]; horizon],
            known_disturbance: [0.0; 2],
            com_force: [0.0; 2],
            com_force_decay: None,
        }
    }
}

/// One part of the controller. Allocation-free in `update`, `record` and `reset`.
pub trait ControllerPart: Send {
    fn name(&self) -> &'static str;
    /// The stages the part runs at (most at one).
    fn stages(&self) -> &'static [Stage];
    /// A new plant session: start over.
    fn reset(&mut self);
    /// This tick's work at `stage`, one of [`Self::stages`].
    fn update(
        &mut self,
        stage: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError>;
    /// This tick's values (the same columns every tick, also when inactive).
    fn record(&self, out: &mut Record);
    /// The part's entries of `summary.json` (none when it did not run).
    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>);
    /// The held object's apparent mass at the hand (world, kg), when the scene gives it.
    fn held_object(&mut self, _apparent_mass: &[[f64; 3]; 3]) {}
    /// For tests and tools that look inside a part ([`super::ControllerCore::part`]).
    fn as_any(&self) -> &dyn Any;
}

/// Builds a part (it may be inactive for this controller or these settings: it then records
/// its neutral values and runs nothing).
pub type PartBuilder =
    fn(&PartSetup) -> Result<Box<dyn ControllerPart>, Box<dyn std::error::Error + Send + Sync>>;

/// A part as the pipeline lists it: how to build it, and how to check its settings when the
/// config is loaded (before any controller is built).
pub struct PartEntry {
    pub build: PartBuilder,
    pub check: fn(&PartTables) -> Result<(), ConfigError>,
}

impl PartEntry {
    /// A part whose settings are `S`.
    pub const fn new<S: PartSettings>(build: PartBuilder) -> Self {
        Self {
            build,
            check: |t| t.get::<S>().map(|_| ()),
        }
    }
}

/// The controller's parts, in the order the tick runs them within each stage.
pub const PIPELINE: &[PartEntry] = &[
    super::wrench_estimation::PART,
    super::base_estimation::PART,
    super::wrist_tare::PART,
    super::forecast_correction::PART,
    super::viability::PART,
    super::com_observer::PART,
];

/// Every part of [`PIPELINE`] for `setup`.
pub fn build_all(
    setup: &PartSetup,
) -> Result<Vec<Box<dyn ControllerPart>>, Box<dyn std::error::Error + Send + Sync>> {
    PIPELINE.iter().map(|p| (p.build)(setup)).collect()
}

/// Every part's settings in `config` deserialize and pass their checks; the error names the
/// key and the layer it came from.
pub fn check(config: &Config, layers: &Layers) -> Result<(), ConfigError> {
    for p in PIPELINE {
        (p.check)(&config.controller.parts).map_err(|e| match e {
            ConfigError::Key { key, message, .. } => layers.range_error(&key, message),
            e => e,
        })?;
    }
    Ok(())
}

/// Run the parts of `stage`, in order.
pub fn run_stage(
    parts: &mut [Box<dyn ControllerPart>],
    stage: Stage,
    inputs: &TickInputs,
    frame: &mut TickFrame,
) -> Result<(), TickError> {
    for p in parts.iter_mut().filter(|p| p.stages().contains(&stage)) {
        p.update(stage, inputs, frame)?;
    }
    Ok(())
}
