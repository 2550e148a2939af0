//! The channel contract shared by every upc process: payloads ([`messages`]), service names
//! and typed iceoryx2 endpoints. Documented for other languages in `services/CHANNELS.md`.
//!
//! Services are named `<prefix>/<kind>` (prefix `upc` by default) so that several runs (tests,
//! parallel experiments) can share a machine without seeing each other. Each publish–subscribe
//! service has an event service of the same name + `/event` for wake-ups.

mod bus;
pub mod messages;

pub use bus::{Bus, ChannelError, Listener, Notifier, Publisher, Subscriber};
pub use messages::*;

/// Default service prefix.
pub const DEFAULT_PREFIX: &str = "upc";

/// The services of the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind {
    /// [`StateMsg`], simulator → controller.
    State,
    /// [`TorqueMsg`], controller → simulator.
    Torques,
    /// [`ForecastMsg`], forecaster → controller.
    Forecast,
    /// [`GroundTruthMsg`], simulator → loggers.
    GroundTruth,
}

impl ServiceKind {
    pub fn suffix(self) -> &'static str {
        match self {
            ServiceKind::State => "state",
            ServiceKind::Torques => "torques",
            ServiceKind::Forecast => "forecast",
            ServiceKind::GroundTruth => "ground_truth",
        }
    }

    /// Samples a late subscriber receives on connecting: the latest state and forecast matter,
    /// old torques do not.
    pub(crate) fn history(self) -> usize {
        match self {
            ServiceKind::State | ServiceKind::Forecast => 1,
            ServiceKind::Torques | ServiceKind::GroundTruth => 0,
        }
    }
}
