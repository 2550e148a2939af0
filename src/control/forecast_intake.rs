//! The loop's side of the forecast service: each tick it offers the newest message to the
//! [`ForecastWindow`] (validation, counting), logs rejections sparingly, tracks the forecast's
//! loss on the plant's time and, in lockstep, waits (bounded) for the window whose period covers
//! the state's time, so that the window a tick sees is a function of simulated time.
//!
//! A lockstep run whose forecaster starts late (any start order) waits longer for the first
//! window of a plant session: the plant is held at its first state meanwhile, so the late
//! forecaster is taken from t = 0 and the run's bytes are those of an on-time start. Without a
//! forecaster within that wait, the run goes on without one (the forecast correction forecasts
//! from the measured hand force alone); a forecaster that joins later still is taken up from
//! its first window on, and the run is marked as depending on timing.

use std::time::{Duration, Instant};

use super::ForecastWindow;
use crate::channels::{ChannelError, ForecastMsg, Listener, Subscriber};

/// What one [`ForecastIntake::take`] saw.
#[derive(Debug, Clone, Copy, Default)]
pub struct Intake {
    /// A window was accepted this tick.
    pub accepted: bool,
    /// Time spent waiting for the window (lockstep).
    pub waited: Option<Duration>,
    /// The wait ended without the window.
    pub timed_out: bool,
    /// The wait for a forecaster's first window ended without one: going on without forecast.
    pub gave_up_first: bool,
    /// The forecast was lost this tick (nothing valid for `loss_after` of plant time and the
    /// window no longer covers the horizon): it decays to zero from here.
    pub lost: bool,
    /// Why this tick's window depends on timing, if it does (lockstep only).
    pub not_reproducible: Option<&'static str>,
}

pub struct ForecastIntake {
    pub window: ForecastWindow,
    forecasts: Subscriber<ForecastMsg>,
    events: Listener,
    /// Lockstep wait for the covering window; `None`: never wait (real time, or 0 configured).
    wait: Option<Duration>,
    /// Lockstep wait for the first window of a plant session (a forecaster starting late).
    first_wait: Option<Duration>,
    /// A window was accepted in this plant session.
    received: bool,
    /// The first-window wait of this session ended without one.
    gave_up_first: bool,
    /// Plant time of the first window accepted in this plant session.
    pub first_at: Option<f64>,
    /// Waiting is on (off after a time-out until a window arrives, or for a forecaster that
    /// promises no period).
    awaiting: bool,
    /// Plant time of the last accepted window.
    last_accepted_t: f64,
    missing: bool,
    warned_rejections: u64,
    loss_after: f64,
    horizon: f64,
}

impl ForecastIntake {
    /// The summary's counts of the forecast windows taken.
    pub fn counts(&self) -> super::summary::ForecastCounts {
        let w = &self.window;
        super::summary::ForecastCounts {
            forecasts_accepted: w.accepted,
            forecasts_rejected: w.rejected,
            forecasts_rejected_by: w.rejections,
            forecaster_restarts: w.restarts,
            forecast_never_received: w.accepted == 0,
            forecast_first_at: self.first_at,
        }
    }

    /// `wait`: the lockstep wait (`None` in real time) and, for a session's first window,
    /// `first_wait` (at least `wait`); `loss_after`: plant time without a valid window before the
    /// forecast counts as lost; `horizon`: the preview horizon (s).
    pub fn new(
        window: ForecastWindow,
        forecasts: Subscriber<ForecastMsg>,
        events: Listener,
        (wait, first_wait): (Option<Duration>, Duration),
        loss_after: f64,
        horizon: f64,
    ) -> Self {
        Self {
            window,
            forecasts,
            events,
            wait,
            first_wait: wait.map(|w| w.max(first_wait)),
            received: false,
            gave_up_first: false,
            first_at: None,
            awaiting: wait.is_some(),
            last_accepted_t: 0.0,
            missing: false,
            warned_rejections: 0,
            loss_after,
            horizon,
        }
    }

    /// A new plant run: its times start over (the window is dropped, waiting resumes).
    pub fn restart(&mut self, t: f64) {
        self.window.reset();
        self.last_accepted_t = t;
        self.awaiting = self.wait.is_some();
        self.received = false;
        self.gave_up_first = false;
        self.first_at = None;
    }

    /// Offer the newest message at plant time `t`; true if accepted.
    fn offer(&mut self, t: f64) -> Result<bool, ChannelError> {
        let window = &mut self.window;
        let Some(r) = self.forecasts.with_latest(|m| window.offer(m, t))? else {
            return Ok(false);
        };
        match r {
            Ok(()) => {
                self.last_accepted_t = t;
                if !self.received {
                    self.received = true;
                    self.first_at = Some(t);
                    tracing::info!("first forecast window taken at t = {t:.3} s");
                }
                if self.missing {
                    self.missing = false;
                    tracing::info!("forecast back at t = {t:.3} s");
                }
                Ok(true)
            }
            // Logged at the 1st, 2nd, 4th, 8th… rejection: a flood costs no log I/O.
            Err(e) => {
                let n = self.window.rejected;
                if n >= self.warned_rejections * 2 {
                    self.warned_rejections = n.max(1);
                    tracing::warn!("forecast rejected ({n} so far): {e}");
                }
                Ok(false)
            }
        }
    }

    /// The forecast for the tick at plant time `t`. `stop` ends a wait early.
    pub fn take(&mut self, t: f64, stop: impl Fn() -> bool) -> Result<Intake, ChannelError> {
        let mut out = Intake {
            accepted: self.offer(t)?,
            ..Intake::default()
        };
        if out.accepted && self.wait.is_some() {
            self.awaiting = true; // a forecaster is (back): wait for it
            if self.gave_up_first {
                self.gave_up_first = false;
                out.not_reproducible = Some(
                    "a forecaster joined after the lockstep wait for its first window: the tick it is taken at depends on timing",
                );
            }
        }
        let wait = if self.received {
            self.wait
        } else {
            self.first_wait
        };
        if let Some(wait) = wait
            && self.awaiting
            && !self.window.promised_at(t)
        {
            if self.window.accepted > 0 && !self.window.has_promise() {
                self.awaiting = false;
                out.not_reproducible = Some(
                    "the forecaster promises no period (ForecastMsg.period = 0): the window a tick sees depends on timing",
                );
            } else {
                let start = Instant::now();
                let until = start + wait;
                loop {
                    let now = Instant::now();
                    if now >= until {
                        self.awaiting = false;
                        out.timed_out = true;
                        if self.received {
                            out.not_reproducible =
                                Some("a lockstep wait for the forecast timed out");
                            tracing::warn!(
                                "no forecast window for t = {t:.3} s within {} s: going on with \
                                 the newest (not waiting again until a window arrives)",
                                wait.as_secs_f64()
                            );
                        } else {
                            // Nothing depends on timing unless a forecaster joins later.
                            self.gave_up_first = true;
                            out.gave_up_first = true;
                            tracing::warn!(
                                "no forecaster within {} s (t = {t:.3} s): going on without a \
                                 forecast; one that starts later is taken up from its first window",
                                wait.as_secs_f64()
                            );
                        }
                        break;
                    }
                    let forecasts = &self.forecasts;
                    self.events.wait_until(
                        (until - now).min(Duration::from_millis(20)),
                        Duration::ZERO,
                        || forecasts.has_samples(),
                    )?;
                    out.accepted |= self.offer(t)?;
                    if self.window.promised_at(t) || stop() {
                        break;
                    }
                }
                out.waited = Some(start.elapsed());
            }
        }
        // Lost: nothing valid for a while of plant time (rejected messages do not count) and
        // the window no longer covers the horizon.
        if !self.missing
            && self.window.accepted > 0
            && t - self.last_accepted_t > self.loss_after
            && !self.window.covers(t + self.horizon)
        {
            self.missing = true;
            out.lost = true;
            tracing::warn!(
                "no valid forecast for {:.2} s at t = {t:.3} s: the forecast decays to zero",
                t - self.last_accepted_t
            );
        }
        Ok(out)
    }
}
