//! The seam of the controller's parts (as an observer pipeline): each part — the wrench
//! observer, the base estimator, the wrist tare, the forecast correction, the capture-point
//! guard, the CoM observer — implements [`ControllerPart`]: its stages, its reset, its update of
//! the tick's shared quantities ([`TickFrame`]), the values it records ([`Record`]) and its
//! `summary.json` entries. It is built from its own settings (a [`PartSettings`] type, its table
//! `[controller.<name>]`) and the controller's context ([`PartSetup`]), never the whole config.
//! The parts upc runs are listed in `super::parts::PIPELINE`.

use super::frame::TickFrame;
use super::tick::{Stage, TickError, TickInputs};
use crate::config::{ConfigError, ControllerKind, HandForceSource, PartSettings, PartTables};
use crate::dynamics::Model;
use crate::preview::CartTable;
use crate::record::Record;
use crate::robot::{N_CONTACTS, Robot};

/// What a part is built from besides its settings: the controller's context.
pub struct PartSetup<'a> {
    /// The robot: its description, frames and model as loaded (the controller's model below
    /// has the config's gravity).
    pub robot: &'a Robot,
    pub kind: ControllerKind,
    /// The controller's model (its gravity set).
    pub model: &'a Model,
    /// The preview's cart-table (mass, gravity, CoM height) and its period T (s).
    pub cart: &'a CartTable,
    pub period: f64,
    /// Control period (s).
    pub dt: f64,
    /// The sole corners' frames (four per foot, left first).
    pub contact_frames: [usize; N_CONTACTS],
    /// The IMU's frame; `None`: on the base.
    pub imu_frame: Option<usize>,
    /// Which hand force the whole-body QP is given (`controller.hand_force_feedback_from`): a
    /// part whose force the QP feeds back closes a loop through the hand.
    pub qp_hand_force: HandForceSource,
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
}

/// The error of a part's build.
pub type BuildError = Box<dyn std::error::Error + Send + Sync>;

/// A part type: its settings and how it is built from them (it may be inactive for this
/// controller or these settings: it then records its neutral values and runs nothing).
pub trait PartKind {
    type Settings: PartSettings;
    fn build(
        setup: &PartSetup,
        settings: Self::Settings,
    ) -> Result<Box<dyn ControllerPart>, BuildError>;
}

/// Builds a part from the config's tables.
pub type BuildPart = fn(&PartSetup, &PartTables) -> Result<Box<dyn ControllerPart>, BuildError>;

/// A part as the pipeline lists it: how to build it from the config's tables, and how to check
/// its settings when the config is loaded (before any controller is built).
pub struct PartEntry {
    pub build: BuildPart,
    pub check: fn(&PartTables) -> Result<(), ConfigError>,
}

impl PartEntry {
    /// The entry of part type `P`.
    pub const fn of<P: PartKind>() -> Self {
        Self {
            build: |setup, tables| P::build(setup, tables.get::<P::Settings>()?),
            check: |t| t.get::<P::Settings>().map(|_| ()),
        }
    }
}
