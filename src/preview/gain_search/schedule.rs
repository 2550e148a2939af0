//! The gain schedule searched by C2 (docs/gain_search.md): K_p (and K_d when free) piecewise
//! linear between knots spread evenly over the horizon. With (knots − 1) a multiple of (nm_knots − 1), the
//! Nelder–Mead baseline's schedules are a subset of the default solver's.

use crate::config::DampingMode;
use crate::preview::GainSchedule;

/// Map between a knot vector θ and per-step gains, with bounds and derivatives.
#[derive(Debug, Clone)]
pub struct KnotSchedule {
    knots: Vec<usize>,
    /// Per step i: (segment j, weight of knot j); knot j+1 gets 1 − weight.
    segment: Vec<(usize, f64)>,
    damping: DampingMode,
    zeta: f64,
    kp_bounds: [f64; 2],
    kd_bounds: [f64; 2],
}

impl KnotSchedule {
    pub fn new(
        horizon: usize,
        n_knots: usize,
        damping: DampingMode,
        zeta: f64,
        kp_bounds: [f64; 2],
        kd_bounds: [f64; 2],
    ) -> Self {
        let m = n_knots.clamp(2, horizon.max(2));
        let last = (horizon - 1) as f64;
        let mut knots: Vec<usize> = (0..m)
            .map(|j| (j as f64 * last / (m - 1) as f64).round() as usize)
            .collect();
        knots.dedup();
        let segment = (0..horizon)
            .map(|i| {
                let j = knots
                    .windows(2)
                    .position(|w| i <= w[1])
                    .unwrap_or(knots.len() - 2);
                let (a, b) = (knots[j], knots[j + 1]);
                (j, (b - i.min(b)) as f64 / (b - a) as f64)
            })
            .collect();
        Self {
            knots,
            segment,
            damping,
            zeta,
            kp_bounds,
            kd_bounds,
        }
    }

    pub fn n_knots(&self) -> usize {
        self.knots.len()
    }

    /// Dimension of θ: K_p knots, then K_d knots when damping is free.
    pub fn dim(&self) -> usize {
        match self.damping {
            DampingMode::Critical => self.knots.len(),
            DampingMode::Free => 2 * self.knots.len(),
        }
    }

    pub fn lower(&self, j: usize) -> f64 {
        if j < self.knots.len() {
            self.kp_bounds[0]
        } else {
            self.kd_bounds[0]
        }
    }

    pub fn upper(&self, j: usize) -> f64 {
        if j < self.knots.len() {
            self.kp_bounds[1]
        } else {
            self.kd_bounds[1]
        }
    }

    fn interp(&self, values: &[f64], i: usize) -> f64 {
        let (j, w) = self.segment[i];
        w * values[j] + (1.0 - w) * values[j + 1]
    }

    /// Per-step gains of θ.
    pub fn expand(&self, theta: &[f64], out: &mut GainSchedule) {
        let m = self.knots.len();
        for i in 0..self.segment.len() {
            let kp = self.interp(&theta[..m], i);
            out.kp[i] = kp;
            out.kd[i] = match self.damping {
                DampingMode::Critical => 2.0 * self.zeta * kp.max(0.0).sqrt(),
                DampingMode::Free => self.interp(&theta[m..], i),
            };
        }
    }

    /// θ sampled from a per-step schedule advanced by `shift` steps (the warm start: the
    /// previous solution shifted to the current time, its last value held), clamped to bounds.
    pub fn sample(&self, schedule: &GainSchedule, shift: usize, theta: &mut [f64]) {
        let m = self.knots.len();
        let n = schedule.len();
        for (j, &s) in self.knots.iter().enumerate() {
            let i = (s + shift).min(n - 1);
            theta[j] = schedule.kp[i].clamp(self.kp_bounds[0], self.kp_bounds[1]);
            if self.damping == DampingMode::Free {
                theta[m + j] = schedule.kd[i].clamp(self.kd_bounds[0], self.kd_bounds[1]);
            }
        }
    }

    /// Steps on which parameter j acts (the gains are zero-derivative elsewhere).
    pub fn support(&self, j: usize) -> std::ops::Range<usize> {
        let k = j % self.knots.len();
        let start = if k == 0 { 0 } else { self.knots[k - 1] };
        let end = if k + 1 == self.knots.len() {
            self.segment.len()
        } else {
            self.knots[k + 1] + 1
        };
        start..end
    }

    /// (∂K_p,i/∂θ_j, ∂K_d,i/∂θ_j) given the current per-step K_p,i.
    pub fn derivative(&self, j: usize, i: usize, kp_i: f64) -> (f64, f64) {
        let m = self.knots.len();
        let (seg, w) = self.segment[i];
        let k = j % m;
        let weight = if k == seg {
            w
        } else if k == seg + 1 {
            1.0 - w
        } else {
            0.0
        };
        match (self.damping, j < m) {
            // K_d = 2 ζ √K_p.
            (DampingMode::Critical, _) => (weight, weight * self.zeta / kp_i.max(1e-12).sqrt()),
            (DampingMode::Free, true) => (weight, 0.0),
            (DampingMode::Free, false) => (0.0, weight),
        }
    }
}
