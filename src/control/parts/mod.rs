//! The parts upc's controller runs ([`PIPELINE`]), in the order the tick runs them within
//! each stage; reset, records and the summary come from the same list. A new part: its file
//! here (implementing `super::part::ControllerPart` and `PartKind`), its `mod` and `PIPELINE`
//! lines here, and its table in `config/default.toml`.

pub mod base_estimation;
pub mod com_observer;
pub mod forecast_correction;
pub mod viability;
pub mod wrench_observer;
pub mod wrist_tare;

use super::frame::TickFrame;
use super::part::{BuildError, ControllerPart, PartEntry, PartSetup};
use super::tick::{Stage, TickError, TickInputs};
use crate::config::{Config, ConfigError, Layers, PartTables};

/// The controller's parts, in the order the tick runs them within each stage.
pub const PIPELINE: &[PartEntry] = &[
    PartEntry::of::<wrench_observer::WrenchObserverPart>(),
    PartEntry::of::<base_estimation::BaseEstimation>(),
    PartEntry::of::<wrist_tare::WristTare>(),
    PartEntry::of::<forecast_correction::Correction>(),
    PartEntry::of::<viability::Guard>(),
    PartEntry::of::<com_observer::Observer>(),
];

/// Every part of [`PIPELINE`] for `setup`, each from its table in `tables`.
pub fn build_all(
    setup: &PartSetup,
    tables: &PartTables,
) -> Result<Vec<Box<dyn ControllerPart>>, BuildError> {
    PIPELINE.iter().map(|p| (p.build)(setup, tables)).collect()
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
