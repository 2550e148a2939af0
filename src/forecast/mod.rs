//! The forecaster: publishes the scenario's known hand force as a [`ForecastMsg`] window that
//! starts at the simulator's current time. Any other process can publish on the same service
//! (see `services/CHANNELS.md`); this one is the reference.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

mod shape;

pub use shape::ForecastShape;

use crate::channels::{
    ChannelError, ContractNode, ForecastMsg, MAX_FORECAST, ServiceKind, StateMsg, window_index,
};
use crate::scenario::{ForceProfile, Scenario};

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
    /// A deliberately wrong forecast, for experiments on forecast errors.
    pub error: ForecastError,
}

/// How the published forecast departs from the scenario: the force forecast for time t is
/// `scale × G(t − shift)` (a push forecast `shift` s late, `scale` times as strong), where G is
/// the scenario's force F given the wrong `shape` ([`ForecastShape`]; G = F when exact).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForecastError {
    pub scale: f64,
    pub shift: f64,
    pub shape: ForecastShape,
}

impl ForecastError {
    /// The exact forecast.
    pub const NONE: ForecastError = ForecastError {
        scale: 1.0,
        shift: 0.0,
        shape: ForecastShape::Exact,
    };
}

impl ForecastSettings {
    pub fn samples(&self) -> usize {
        ((self.window / self.dt).ceil() as usize).clamp(1, MAX_FORECAST)
    }
}

/// Fill `msg` with the window starting at plant time `t0` of `profile` played from plant time
/// `scenario_start` (infinite: not started, all zeros), with `s.error`'s scale and shift
/// applied (its shape is the caller's, applied once to `profile`: [`ForecastShape::apply`]).
pub fn fill_window(
    msg: &mut ForecastMsg,
    profile: &ForceProfile,
    seq: u64,
    t0: f64,
    scenario_start: f64,
    s: &ForecastSettings,
) {
    let len = s.samples();
    msg.seq = seq;
    msg.t0 = t0;
    msg.dt = s.dt;
    msg.len = len as u32;
    msg.period = s.period;
    if scenario_start.is_finite() {
        let out = &mut msg.forces[..len];
        profile.sample_into(t0 - scenario_start - s.error.shift, s.dt, out);
        if s.error.scale != 1.0 {
            for f in out.iter_mut() {
                *f = f.map(|x| x * s.error.scale);
            }
        }
    } else {
        msg.forces[..len].fill([0.0; 3]);
    }
}

/// What to forecast.
#[derive(Debug, Clone)]
pub enum Source {
    /// This scenario, whatever the plant plays (the controller warns when they differ).
    Fixed(Scenario),
    /// The scenario the plant announces in its states (reloaded when it changes); the default
    /// scenario when the plant announces none.
    FollowPlant,
}

/// The scenario being forecast, and its force as forecast (its shape error applied).
struct Current {
    scenario: Scenario,
    force: ForceProfile,
    hash: u64,
}

/// What the forecaster follows of the plant's states: its run, its scenario and where the
/// windows stand.
#[derive(Default)]
struct Timeline {
    /// Chosen at the first state (the plant says how hard it pushes its robot).
    current: Option<Current>,
    /// The index of the last window published.
    last_index: Option<i64>,
    /// The plant run (0: none seen yet).
    session: u64,
    /// The plant time at which the scenario started.
    scenario_start: f64,
    /// The plant hash the current scenario was chosen for (following), or checked against
    /// (fixed).
    seen_hash: Option<u64>,
}

impl Timeline {
    /// A new plant run, or its scenario started (or restarted): windows shift with it, the
    /// next one goes out at once.
    fn follow_run(&mut self, st: &StateMsg) {
        if st.session != self.session {
            if self.session != 0 {
                tracing::info!(
                    "new plant run (session {:016x}) at t = {:.3} s: forecasting for its timeline",
                    st.session,
                    st.time
                );
            }
            self.session = st.session;
            self.last_index = None;
        }
        if st.scenario_start >= 0.0 && st.scenario_start != self.scenario_start {
            self.scenario_start = st.scenario_start;
            self.last_index = None;
        }
    }

    /// The scenario to forecast, chosen again when the plant's scenario hash changes: `source`'s
    /// (fixed, or the plant's), scaled as the plant pushes its robot, given `shape`'s error.
    fn choose_scenario(&mut self, st: &StateMsg, source: &Source, shape: &ForecastShape) {
        if self.seen_hash == Some(st.scenario_hash) {
            return;
        }
        self.seen_hash = Some(st.scenario_hash);
        // The plant pushes its robot `force_scale` times the scenario's figures.
        let scale = if st.force_scale > 0.0 {
            st.force_scale
        } else {
            1.0
        };
        let chosen = match source {
            Source::Fixed(sc) => Some(sc.clone()),
            Source::FollowPlant => follow(st),
        };
        self.current = chosen.and_then(|sc| {
            let scenario = sc.with_force_scale(scale);
            match shape.apply(&scenario.force) {
                Ok(force) => Some(Current {
                    hash: scenario.content_hash(),
                    force,
                    scenario,
                }),
                Err(e) => {
                    tracing::error!("`{}`: {e}; publishing nothing", scenario.name);
                    None
                }
            }
        });
        if let Some(cur) = &self.current
            && st.scenario_hash != 0
            && cur.hash != st.scenario_hash
        {
            tracing::warn!(
                "forecasting `{}` × {scale} (hash {:016x}) while the plant plays `{}` (hash {:016x})",
                cur.scenario.name,
                cur.hash,
                st.scenario_name(),
                st.scenario_hash
            );
        }
        self.last_index = None;
    }
}

/// Publish windows until `stop` is raised, the state stream passes `until`, or IPC fails.
/// Paced by the plant's time: window k starts at k·period and is published as soon as a state
/// at or past that time is seen (see [`crate::channels::window_index`]), so its content is a function of the
/// simulated time only. A new plant run (its session changes) gets a window at once.
pub fn run(
    node: &ContractNode,
    source: &Source,
    s: &ForecastSettings,
    stop: Arc<AtomicBool>,
) -> Result<u64, ChannelError> {
    let publisher = node.publisher::<ForecastMsg>()?;
    let notifier = node.notifier(ServiceKind::Forecast)?;
    let states = node.subscriber::<StateMsg>()?;
    let wake = node.listener(ServiceKind::State)?;
    let mut timeline = Timeline::default();
    let mut seq = 0u64;
    while !stop.load(Ordering::Relaxed) {
        wake.wait(Duration::from_millis(50))?;
        // A controller that subscribed after the last window gets it now, not at the next one
        // (a lockstep plant waiting on that controller sends no new time).
        publisher.update_connections()?;
        let Some(st) = states.latest()? else {
            continue;
        };
        timeline.follow_run(&st);
        timeline.choose_scenario(&st, source, &s.error.shape);
        let Some(cur) = &timeline.current else {
            continue;
        };
        let now = st.time;
        let k = window_index(now, s.period);
        if timeline.last_index != Some(k) {
            timeline.last_index = Some(k);
            seq += 1;
            let t0 = k as f64 * s.period;
            let hash = cur.hash;
            // Before the plant starts the scenario nothing pushes: a window of zeros.
            let offset = if st.scenario_start >= 0.0 {
                timeline.scenario_start
            } else {
                f64::INFINITY
            };
            publisher.send_with(|m| {
                fill_window(m, &cur.force, seq, t0, offset, s);
                m.scenario_hash = hash;
            })?;
            notifier.notify()?;
        }
        // Done once the window covering `until` is out (a lockstep controller waits for it).
        if s.until.is_some_and(|u| now >= u - 1e-9) {
            break;
        }
    }
    Ok(seq)
}

/// Load the scenario a state announces (the default one when it announces none).
fn follow(st: &StateMsg) -> Option<Scenario> {
    let name = match st.scenario_name() {
        "" => crate::scenario::DEFAULT,
        n => n,
    };
    match Scenario::load(name) {
        Ok(scenario) => {
            tracing::info!(
                "following the plant's scenario `{name}` ({}, forces × {})",
                scenario.name,
                if st.force_scale > 0.0 {
                    st.force_scale
                } else {
                    1.0
                }
            );
            Some(scenario)
        }
        Err(e) => {
            tracing::error!(
                "cannot load the plant's scenario `{name}`: {e}; publishing nothing (give --scenario)"
            );
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_forecast_error_scales_and_delays_the_scenario_force() {
        let profile = Scenario::load("single_impact").expect("scenario").force;
        let exact = ForecastSettings {
            dt: 0.005,
            window: 2.5,
            period: 0.01,
            until: None,
            error: ForecastError::NONE,
        };
        let wrong = ForecastSettings {
            error: ForecastError {
                scale: 1.5,
                shift: 0.1,
                shape: ForecastShape::Exact,
            },
            ..exact
        };
        let (mut a, mut b): (Box<ForecastMsg>, Box<ForecastMsg>) = Default::default();
        fill_window(&mut a, &profile, 1, 0.5, 0.2, &exact);
        fill_window(&mut b, &profile, 1, 0.5, 0.2, &wrong);
        let mut peak: f64 = 0.0;
        for i in 0..exact.samples() {
            let t = 0.5 + i as f64 * 0.005;
            let want = profile.at(t - 0.2);
            let late = profile.at(t - 0.2 - 0.1);
            for c in 0..3 {
                assert!((a.forces[i][c] - want[c]).abs() < 1e-12);
                assert!((b.forces[i][c] - 1.5 * late[c]).abs() < 1e-12);
            }
            peak = peak.max(want[0].abs());
        }
        assert!(peak > 10.0, "the window covers the impact ({peak} N)");
    }
}
