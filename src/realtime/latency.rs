//! Latency statistics of a loop in a fixed histogram (no allocation per sample), kept by every
//! process that times its loop: the controller, the plant, the bridge and the bus participant.

use std::time::Duration;

/// Latency statistics with 1 µs bins up to 20 ms (beyond: the last bin), allocated once.
pub struct LatencyHistogram {
    bins: Vec<u32>,
    count: u64,
    max: Duration,
    sum: f64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    const BINS: usize = 20_000;

    pub fn new() -> Self {
        Self {
            bins: vec![0; Self::BINS],
            count: 0,
            max: Duration::ZERO,
            sum: 0.0,
        }
    }

    pub fn record(&mut self, d: Duration) {
        let us = (d.as_micros() as usize).min(Self::BINS - 1);
        self.bins[us] = self.bins[us].saturating_add(1);
        self.count += 1;
        self.max = self.max.max(d);
        self.sum += d.as_secs_f64();
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// Empty again, keeping its storage (a window of the loop's figures, without allocating).
    pub fn reset(&mut self) {
        self.bins.fill(0);
        self.count = 0;
        self.max = Duration::ZERO;
        self.sum = 0.0;
    }

    /// The q-quantile (0…1) in seconds, at 1 µs resolution (upper bin edge).
    pub fn quantile(&self, q: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let target = ((self.count as f64) * q).ceil().max(1.0) as u64;
        let mut acc = 0u64;
        for (us, &n) in self.bins.iter().enumerate() {
            acc += n as u64;
            if acc >= target {
                return (us + 1) as f64 * 1e-6;
            }
        }
        self.max.as_secs_f64()
    }

    pub fn max(&self) -> f64 {
        self.max.as_secs_f64()
    }

    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles() {
        let mut h = LatencyHistogram::new();
        for us in 1..=100u64 {
            h.record(Duration::from_micros(us));
        }
        assert!(
            (h.quantile(0.5) - 51e-6).abs() < 1.5e-6,
            "{}",
            h.quantile(0.5)
        );
        assert!((h.quantile(0.99) - 100e-6).abs() < 1.5e-6);
        assert_eq!(h.max(), 100e-6);
        // A new window: only what is recorded after the reset counts.
        h.reset();
        assert_eq!((h.count(), h.quantile(0.99), h.max()), (0, 0.0, 0.0));
        h.record(Duration::from_micros(7));
        assert!(
            (h.quantile(0.99) - 8e-6).abs() < 1e-9,
            "{}",
            h.quantile(0.99)
        );
    }
}
