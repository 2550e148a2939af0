//! What a control run measured, recorded tick by tick (allocation-free) and yielded as the
//! summary's figures: tick time, balance (CoP margin, time at the support edge, CoM drop), hand
//! tracking, ZMP error, C2's schedules.

use std::time::Duration;

use super::summary::RunFigures;
use super::{StampedSchedule, TickRecord};
use crate::realtime::LatencyHistogram;

/// A measured CoP closer than this to the support edge counts as at the edge (m).
pub const EDGE_BAND: f64 = 1e-3;

pub struct RunMetrics {
    dt: f64,
    hist: LatencyHistogram,
    /// The ticks since the last status line (a soak's tick p99 over time).
    window: LatencyHistogram,
    pub ticks: u64,
    pub ticks_since_reconnect: u64,
    pub sim_time: f64,
    /// The CoM height of the plant run's first tick.
    com_z0: Option<f64>,
    min_zmp_margin: f64,
    time_at_support_edge: f64,
    com_height_drop: f64,
    max_zmp_error: f64,
    hand_sq: f64,
    hand_peak_error: f64,
    c2_last_seq: u64,
    c2_seen: u64,
    c2_solve_sum: f64,
    c2_iter_sum: f64,
    c2_solve_max_ms: f64,
}

impl RunMetrics {
    pub fn new(dt: f64) -> Self {
        RunMetrics {
            dt,
            hist: LatencyHistogram::new(),
            window: LatencyHistogram::new(),
            ticks: 0,
            ticks_since_reconnect: 0,
            sim_time: 0.0,
            com_z0: None,
            min_zmp_margin: f64::INFINITY,
            time_at_support_edge: 0.0,
            com_height_drop: 0.0,
            max_zmp_error: 0.0,
            hand_sq: 0.0,
            hand_peak_error: 0.0,
            c2_last_seq: 0,
            c2_seen: 0,
            c2_solve_sum: 0.0,
            c2_iter_sum: 0.0,
            c2_solve_max_ms: 0.0,
        }
    }

    /// A new plant run: the CoM drop is measured from its first tick again.
    pub fn restart(&mut self) {
        self.com_z0 = None;
        self.ticks_since_reconnect = 0;
    }

    /// C2's schedule in use this tick: each new one counted once.
    pub fn schedule(&mut self, sch: &StampedSchedule) {
        if sch.seq == self.c2_last_seq {
            return;
        }
        self.c2_last_seq = sch.seq;
        self.c2_seen += 1;
        self.c2_solve_sum += sch.solve_time;
        self.c2_iter_sum += sch.iterations as f64;
        self.c2_solve_max_ms = self.c2_solve_max_ms.max(sch.solve_time * 1e3);
    }

    /// One control tick: its compute time and its record, with the support it was computed on.
    pub fn tick(&mut self, rec: &TickRecord, support: Option<[[f64; 2]; 2]>, tick_time: Duration) {
        self.hist.record(tick_time);
        self.window.record(tick_time);
        self.ticks += 1;
        self.ticks_since_reconnect += 1;
        self.sim_time = rec.time;
        if let Some(sup) = support {
            let margin = (0..2)
                .map(|a| (rec.cop[a] - sup[a][0]).min(sup[a][1] - rec.cop[a]))
                .fold(f64::INFINITY, f64::min);
            self.min_zmp_margin = self.min_zmp_margin.min(margin);
            if margin < EDGE_BAND {
                self.time_at_support_edge += self.dt;
            }
        }
        let z0 = *self.com_z0.get_or_insert(rec.com[2]);
        self.com_height_drop = self.com_height_drop.max(z0 - rec.com[2]);
        let zerr =
            ((rec.cop[0] - rec.zmp_ref[0]).powi(2) + (rec.cop[1] - rec.zmp_ref[1]).powi(2)).sqrt();
        self.max_zmp_error = self.max_zmp_error.max(zerr);
        self.hand_sq += rec.hand_err * rec.hand_err;
        self.hand_peak_error = self.hand_peak_error.max(rec.hand_err);
    }

    /// Tick time p99 and max since the last call (s), for a status line.
    pub fn take_window(&mut self) -> (f64, f64) {
        let out = (self.window.quantile(0.99), self.window.max());
        self.window.reset();
        out
    }

    /// The run's figures for the summary.
    pub fn figures(&self) -> RunFigures {
        let per_tick = |sum: f64| {
            if self.ticks > 0 {
                sum / self.ticks as f64
            } else {
                0.0
            }
        };
        let c2_mean = |sum: f64| {
            if self.c2_seen > 0 {
                sum / self.c2_seen as f64
            } else {
                0.0
            }
        };
        RunFigures {
            ticks: self.ticks,
            ticks_since_reconnect: self.ticks_since_reconnect,
            sim_time: self.sim_time,
            tick_p50_us: self.hist.quantile(0.5) * 1e6,
            tick_p99_us: self.hist.quantile(0.99) * 1e6,
            tick_max_us: self.hist.max() * 1e6,
            min_zmp_margin: if self.min_zmp_margin.is_finite() {
                self.min_zmp_margin
            } else {
                0.0
            },
            time_at_support_edge: self.time_at_support_edge,
            com_height_drop: self.com_height_drop,
            hand_rms_error: per_tick(self.hand_sq).sqrt(),
            hand_peak_error: self.hand_peak_error,
            max_zmp_error: self.max_zmp_error,
            c2_solve_mean_ms: c2_mean(self.c2_solve_sum) * 1e3,
            c2_solve_max_ms: self.c2_solve_max_ms,
            c2_iterations_mean: c2_mean(self.c2_iter_sum),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(t: f64, zmp_x: f64, com_z: f64, hand_err: f64) -> TickRecord {
        TickRecord {
            time: t,
            cop: [zmp_x, 0.0],
            zmp_ref: [0.0, 0.0],
            com: [0.0, 0.0, com_z],
            hand_err,
            ..TickRecord::default()
        }
    }

    /// Margins, time at the edge, CoM drop from the run's first height (again after a
    /// restart), hand RMS: against figures computed by hand.
    #[test]
    fn figures_of_a_few_ticks() {
        let mut m = RunMetrics::new(0.001);
        let sup = Some([[-0.1, 0.1], [-0.05, 0.05]]);
        let us = Duration::from_micros(100);
        m.tick(&rec(0.001, 0.02, 0.50, 3.0), sup, us);
        m.tick(&rec(0.002, 0.0995, 0.49, 4.0), sup, us); // 0.5 mm from the edge
        m.restart();
        m.tick(&rec(0.003, 0.0, 0.40, 0.0), sup, us); // a new run's first height
        let s = m.figures();
        assert_eq!((s.ticks, s.ticks_since_reconnect), (3, 1));
        assert!(
            (s.min_zmp_margin - 0.0005).abs() < 1e-12,
            "{}",
            s.min_zmp_margin
        );
        assert!((s.time_at_support_edge - 0.001).abs() < 1e-15);
        assert!(
            (s.com_height_drop - 0.01).abs() < 1e-12,
            "{}",
            s.com_height_drop
        );
        assert!((s.hand_rms_error - (25.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!((s.hand_peak_error, s.sim_time), (4.0, 0.003));
        assert!((s.max_zmp_error - 0.0995).abs() < 1e-12);
    }
}
