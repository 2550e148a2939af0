//! The channel contract shared by every upc process: payloads ([`messages`]), service names
//! and typed iceoryx2 endpoints. Documented for other languages in `services/CHANNELS.md`.
//!
//! Services are named `<prefix>/<kind>` (prefix `upc` by default) so that several runs (tests,
//! parallel experiments) can share a machine without seeing each other. Each publish–subscribe
//! service has an event service of the same name + `/event` for wake-ups.

pub mod messages;
mod node;

pub use messages::*;
pub use node::{ChannelError, ChannelOp, ContractNode, Listener, Notifier, Publisher, Subscriber};

/// A fresh non-zero identifier for a run of a process (`StateMsg::session`,
/// `TorqueMsg::controller`): wall clock and process id mixed (splitmix64), so two runs started in
/// the same nanosecond by different processes still differ.
pub fn new_run_id() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let mut z = nanos ^ (u64::from(std::process::id()) << 32);
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)).max(1)
}

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

/// A payload of the contract and the service that carries it: the contract's channels (and the
/// Zenoh framing, [`crate::bridge::wire`]) take the service from the type, so a payload cannot
/// be sent on another payload's service.
pub trait Payload: iceoryx2::prelude::ZeroCopySend + std::fmt::Debug + Copy + 'static {
    const KIND: ServiceKind;
}

impl Payload for StateMsg {
    const KIND: ServiceKind = ServiceKind::State;
}
impl Payload for TorqueMsg {
    const KIND: ServiceKind = ServiceKind::Torques;
}
impl Payload for ForecastMsg {
    const KIND: ServiceKind = ServiceKind::Forecast;
}
impl Payload for GroundTruthMsg {
    const KIND: ServiceKind = ServiceKind::GroundTruth;
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
