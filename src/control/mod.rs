//! The control server: a fixed-rate loop that turns robot state and the hand force forecast
//! into joint torques (C0/C1 every tick, C2's gain search in its own thread, the whole-body QP).
//!
//! - [`core`]: one tick without IPC ([`ControllerCore`]).
//! - [`forecast_window`]: validated copy of the latest force forecast.
//! - [`forecast_correction`]: the forecast corrected by the measured hand force.
//! - [`viability`]: the capture-point guard on the forecast's unmeasured part.
//! - [`wrist_tare`]: the wrist sensor's offset, taken while the hand is unloaded.
//! - [`com_observer`]: the push on the CoM that nothing forecasts, from the measured CoP.
//! - [`gain_thread`]: C2 in a lower-priority thread behind wait-free triple buffers.
//! - [`logger`]: the rerun log, from its own thread, never blocking the loop.
//! - [`server`]: the loop over iceoryx2 (`upc controller`), lockstep or real time, as named
//!   steps; [`plant_link`]: which state is new, a restarted or silent plant (a state machine);
//!   [`run_metrics`]: the run's figures, tick by tick; [`summary`]: what a run reports.
//! - [`timing`]: absolute-deadline ticker (the latency histogram and the real-time setup are
//!   [`crate::realtime`]'s).

pub mod com_observer;
pub mod core;
pub mod forecast_correction;
pub mod forecast_intake;
pub mod forecast_window;
pub mod gain_thread;
pub mod logger;
pub mod plant_link;
pub mod run_metrics;
pub mod server;
pub mod summary;
pub mod timing;
pub mod viability;
pub mod wrist_tare;

pub use com_observer::{ComObserver, ComObserverSettings};
pub use core::{ControllerCore, TickError, TickRecord};
pub use forecast_correction::{
    CorrectionCounts, CorrectionEstimate, CorrectionSettings, ForecastCorrector,
};
pub use forecast_window::{ForecastRejection, ForecastWindow};
pub use gain_thread::{GainHandoff, GainSnapshot, StampedSchedule};
pub use timing::Ticker;
