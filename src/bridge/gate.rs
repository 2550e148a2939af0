//! What the bridge takes from the network before any check of the bytes: one forecast source at
//! a time, at a bounded rate.
//!
//! Two forecasters interleaving their windows would make the controller's forecast jump between
//! two models each tick; a source that floods the bridge would take its time. The first source
//! is taken; another is refused (and counted) until the taken one has been silent for
//! `takeover`, so a forecaster that restarts, or a standby that replaces a dead one, is taken
//! after that pause. The rate is a token bucket: `burst` windows at once, `rate_hz` sustained.

use std::time::{Duration, Instant};

/// Why the gate refused a forecast.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Another source is being taken.
    SecondSource,
    /// Over the rate.
    RateLimited,
}

#[derive(Debug)]
pub struct ForecastGate {
    rate_hz: f64,
    burst: f64,
    takeover: Duration,
    tokens: f64,
    refilled: Option<Instant>,
    source: Option<(String, Instant)>,
    /// How many times a source was taken (the first included).
    pub sources_taken: u64,
}

impl ForecastGate {
    pub fn new(rate_hz: f64, burst: u32, takeover: Duration) -> Self {
        ForecastGate {
            rate_hz,
            burst: f64::from(burst),
            takeover,
            tokens: f64::from(burst),
            refilled: None,
            source: None,
            sources_taken: 0,
        }
    }

    /// Whether a forecast from `source`, arrived at `now`, passes.
    pub fn admit(&mut self, source: &str, now: Instant) -> Result<(), Refusal> {
        match &mut self.source {
            Some((taken, last)) if taken == source => *last = now,
            Some((_, last)) if now.saturating_duration_since(*last) < self.takeover => {
                return Err(Refusal::SecondSource);
            }
            _ => {
                self.source = Some((source.to_owned(), now));
                self.sources_taken += 1;
                tracing::info!(
                    "bridge: forecasts taken from source `{source}` (source {} so far)",
                    self.sources_taken
                );
            }
        }
        let dt = self
            .refilled
            .map_or(0.0, |t| now.saturating_duration_since(t).as_secs_f64());
        self.refilled = Some(now);
        self.tokens = (self.tokens + dt * self.rate_hz).min(self.burst);
        if self.tokens < 1.0 {
            return Err(Refusal::RateLimited);
        }
        self.tokens -= 1.0;
        Ok(())
    }

    /// The source being taken, if any.
    pub fn source(&self) -> Option<&str> {
        self.source.as_ref().map(|(s, _)| s.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_source_at_a_time_and_a_takeover_after_silence() {
        let t0 = Instant::now();
        let ms = |m: u64| t0 + Duration::from_millis(m);
        let mut g = ForecastGate::new(1000.0, 10, Duration::from_millis(500));
        assert_eq!(g.admit("fc1", ms(0)), Ok(()));
        assert_eq!(g.admit("fc2", ms(10)), Err(Refusal::SecondSource));
        assert_eq!(g.admit("fc1", ms(20)), Ok(()));
        // fc2 keeps trying while fc1 is alive: still refused.
        assert_eq!(g.admit("fc2", ms(400)), Err(Refusal::SecondSource));
        // fc1 silent for 500 ms: fc2 takes over, and fc1 is now the second source.
        assert_eq!(g.admit("fc2", ms(520)), Ok(()));
        assert_eq!(g.admit("fc1", ms(530)), Err(Refusal::SecondSource));
        assert_eq!(g.source(), Some("fc2"));
        assert_eq!(g.sources_taken, 2);
    }

    #[test]
    fn a_burst_passes_then_the_sustained_rate() {
        let t0 = Instant::now();
        let mut g = ForecastGate::new(100.0, 5, Duration::from_secs(1));
        let passed = (0..50).filter(|_| g.admit("", t0).is_ok()).count();
        assert_eq!(passed, 5);
        assert_eq!(g.admit("", t0), Err(Refusal::RateLimited));
        // 100 ms later: 10 tokens refilled, capped at the burst of 5.
        let t1 = t0 + Duration::from_millis(100);
        let passed = (0..50).filter(|_| g.admit("", t1).is_ok()).count();
        assert_eq!(passed, 5);
        // At the sustained rate (one per 10 ms) every window passes.
        let steady = (1..=100)
            .filter(|i| g.admit("", t1 + Duration::from_millis(10 * i)).is_ok())
            .count();
        assert_eq!(steady, 100);
    }
}
