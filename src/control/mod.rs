//! The control server: a fixed-rate loop that turns robot state and the hand force forecast
//! into joint torques (C0/C1 every tick, C2's gain search in its own thread, the whole-body QP).
//!
//! - [`core`]: one tick without IPC ([`ControllerCore`]); [`contract`]: the one place the
//!   state message is read (into a [`crate::robot::RobotState`]); [`tick_record`]: what a
//!   tick produced.
//! - [`parts`]: the controller's parts behind one trait, run by stage in the order of
//!   [`parts::PIPELINE`]; the records they log are
//!   [`crate::record`]'s (name, format and value together). The parts:
//!   - [`wrench_estimation`]: the feet's wrenches, the CoP and the hand force from the joint
//!     torques, for a robot without force sensors;
//!   - [`base_estimation`]: the floating base from the IMU, joints and foot wrenches;
//!   - [`wrist_tare`]: the wrist sensor's offset, taken while the hand is unloaded;
//!   - [`forecast_correction`]: the forecast corrected by the measured hand force;
//!   - [`viability`]: the capture-point guard on the forecast's unmeasured part;
//!   - [`com_observer`]: the push on the CoM that nothing forecasts, from the measured CoP.
//! - [`forecast_window`]: validated copy of the latest force forecast.
//! - [`gain_thread`]: C2 in a lower-priority thread behind wait-free triple buffers.
//! - [`logger`]: the rerun log, from its own thread, never blocking the loop.
//! - [`server`]: the loop over iceoryx2 (`upc controller`), lockstep or real time, as named
//!   steps; [`plant_link`]: which state is new, a restarted or silent plant (a state machine);
//!   [`run_metrics`]: the run's figures, tick by tick; [`summary`]: what a run reports.
//! - [`timing`]: absolute-deadline ticker (the latency histogram and the real-time setup are
//!   [`crate::realtime`]'s).

pub mod base_estimation;
pub mod com_observer;
pub mod contract;
pub mod core;
pub mod forecast_correction;
pub mod forecast_intake;
pub mod forecast_window;
pub mod gain_thread;
pub mod logger;
pub mod parts;
pub mod plant_link;
pub mod run_metrics;
pub mod server;
pub mod summary;
pub mod tick_record;
pub mod timing;
pub mod viability;
pub mod wrench_estimation;
pub mod wrist_tare;

pub use com_observer::{ComObserver, ComObserverSettings};
pub use core::{ControllerCore, TickError};
pub use forecast_correction::{
    CorrectionCounts, CorrectionEstimate, CorrectionSettings, ForecastCorrector,
};
pub use forecast_window::{ForecastRejection, ForecastWindow};
pub use gain_thread::{GainHandoff, GainSnapshot, StampedSchedule};
pub use parts::{ControllerPart, Stage};
pub use tick_record::TickRecord;
pub use timing::Ticker;
