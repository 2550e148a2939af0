//! The control server: a fixed-rate loop that turns robot state and the hand force forecast
//! into joint torques (C0/C1 every tick, C2's gain search in its own thread, the whole-body QP).
//!
//! A stack, each layer using only those below it:
//! - the tick's types: [`tick`] (stages, inputs, errors), [`frame`] (the shared quantities and
//!   how writers combine), [`part`] (the parts' seam), [`tick_record`] (what a tick produced);
//!   [`held_object`] (what the hand holds, and what follows from it);
//! - [`parts`]: the parts upc runs ([`parts::PIPELINE`], in order), each in its file and built
//!   from its own settings: `wrench_observer` (the feet's wrenches, the CoP and the hand force
//!   from the joint torques, for a robot without force sensors), `base_estimation` (the floating
//!   base from the IMU, joints and foot wrenches), `wrist_tare` (the wrist sensor's offset),
//!   `forecast_correction` (the forecast corrected by the measured hand force), `viability` (the
//!   capture-point guard on the forecast's unmeasured part), `com_observer` (the push on the CoM
//!   nothing forecasts);
//! - [`core`]: one tick without IPC ([`ControllerCore`]), running the parts by stage;
//! - the process: [`contract`] (the one reader of the state message, into a
//!   [`crate::robot::RobotState`]), [`forecast_window`] and [`forecast_intake`] (the forecast,
//!   validated), [`gain_thread`] (C2 in a lower-priority thread behind wait-free triple
//!   buffers), [`logger`] (the rerun log, from its own thread, never blocking the loop),
//!   [`plant_link`] (which state is new, a restarted or silent plant), [`run_metrics`] and
//!   [`summary`] (what a run reports), [`timing`] (absolute-deadline ticker), and [`server`]
//!   (the loop over iceoryx2, `upc controller`, lockstep or real time).
//!
//! The records the parts and the core log are [`crate::record`]'s (name, format and value
//! together); the latency histogram and the real-time setup are [`crate::realtime`]'s.

pub mod contract;
pub mod core;
pub mod forecast_intake;
pub mod forecast_window;
pub mod frame;
pub mod gain_thread;
pub mod held_object;
pub mod logger;
pub mod part;
pub mod parts;
pub mod plant_link;
pub mod run_metrics;
pub mod server;
pub mod summary;
pub mod tick;
pub mod tick_record;
pub mod timing;

pub use core::ControllerCore;
pub use forecast_window::{ForecastRejection, ForecastWindow};
pub use frame::TickFrame;
pub use gain_thread::{GainHandoff, GainSnapshot, StampedSchedule};
pub use part::{ControllerPart, PartKind, PartSetup};
pub use parts::com_observer::{ComObserver, ComObserverSettings};
pub use parts::forecast_correction::{
    CorrectionCounts, CorrectionEstimate, CorrectionSettings, ForecastCorrector,
};
pub use summary::CoreInfo;
pub use tick::{Stage, TickError, TickInputs};
pub use tick_record::TickRecord;
pub use timing::Ticker;
