//! The forecaster: publishes the scenario's known hand force as a [`ForecastMsg`] window that
//! starts at the simulator's current time. Any other process can publish on the same service
//! (see `services/CHANNELS.md`); this one is the reference.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::channels::{Bus, ChannelError, ForecastMsg, MAX_FORECAST, ServiceKind, StateMsg};
use crate::scenario::ForceProfile;

/// How the forecaster samples and paces its windows.
#[derive(Debug, Clone, Copy)]
pub struct ForecastSettings {
    /// Sample spacing (s).
    pub dt: f64,
    /// Length of each window (s); longer than the preview horizon so a controller that reads a
    /// slightly old window still covers its horizon.
    pub window: f64,
    /// Simulated time between two windows (s).
    pub period: f64,
    /// Stop after this simulated time (s); `None` runs until asked to stop.
    pub until: Option<f64>,
}

impl ForecastSettings {
    pub fn samples(&self) -> usize {
        ((self.window / self.dt).ceil() as usize).clamp(1, MAX_FORECAST)
    }
}

/// Fill `msg` with the window of `profile` starting at `t0`.
pub fn fill_window(
    msg: &mut ForecastMsg,
    profile: &ForceProfile,
    seq: u64,
    t0: f64,
    s: &ForecastSettings,
) {
    let len = s.samples();
    msg.seq = seq;
    msg.t0 = t0;
    msg.dt = s.dt;
    msg.len = len as u32;
    profile.sample_into(t0, s.dt, &mut msg.forces[..len]);
}

/// Publish windows until `stop` is raised, the state stream passes `until`, or IPC fails.
/// Paced by the simulator's time: a window per `period` of simulated time, aligned to it.
pub fn run(
    bus: &Bus,
    profile: &ForceProfile,
    s: &ForecastSettings,
    stop: Arc<AtomicBool>,
) -> Result<u64, ChannelError> {
    let publisher = bus.publisher::<ForecastMsg>(ServiceKind::Forecast)?;
    let notifier = bus.notifier(ServiceKind::Forecast)?;
    let states = bus.subscriber::<StateMsg>(ServiceKind::State)?;
    let wake = bus.listener(ServiceKind::State)?;
    let mut seq = 0u64;
    let mut next = f64::NEG_INFINITY;
    // Publish a first window at t = 0 so a controller starting before the simulator has one.
    let mut now = 0.0;
    while !stop.load(Ordering::Relaxed) {
        if now >= next {
            seq += 1;
            publisher.send_with(|m| fill_window(m, profile, seq, now, s))?;
            notifier.notify()?;
            next = (now / s.period).floor() * s.period + s.period;
        }
        if s.until.is_some_and(|u| now >= u - 0.5 * s.period) {
            break;
        }
        wake.wait(Duration::from_millis(50))?;
        if let Some(t) = states.latest()?.map(|m| m.time) {
            // Time going back is a restarted simulator: publish for its timeline at once.
            if t + s.period < now {
                next = f64::NEG_INFINITY;
            }
            now = t;
        }
    }
    Ok(seq)
}
