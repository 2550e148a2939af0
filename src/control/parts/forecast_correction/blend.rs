//! The horizon the previewer sees (FC-4, FC-4b) and FC-5's blend of the forecast's prediction
//! with the measurement's.

use super::{ForecastCorrector, V3, dot};
use crate::control::forecast_window::ForecastWindow;

/// FC-4's unexplained part ahead: (d̂ + ḋ `ahead`) `w`, with [`ForecastCorrector::ahead`]'s
/// factors.
pub(super) fn unexplained(offset: &V3, trend: &V3, ahead: f64, w: f64) -> V3 {
    [0, 1, 2].map(|c| (offset[c] + trend[c] * ahead) * w)
}

impl ForecastCorrector {
    /// κ̂ f_fc for the horizon (FC-4b): an amplification (κ̂ > 1) is believed up to the forecast
    /// levels it was fitted on, and beyond them the forecast gains only what it gained there,
    /// (κ̂ − 1) times that level. A forecast 2× too slow and one 4× too weak rise alike at their
    /// onset; applying the onset's κ̂ = 4 to the slow forecast's peak previews a push 4× the
    /// real one (and the robot leans into it).
    pub(super) fn scaled(&self, p: &V3) -> V3 {
        let k = self.est.factor;
        if k <= 1.0 {
            return p.map(|v| k * v);
        }
        let n = dot(p, p).sqrt();
        let gain = if n > self.seen_level {
            1.0 + (k - 1.0) * self.seen_level / n
        } else {
            k
        };
        p.map(|v| gain * v)
    }

    /// FC-4's factors at s ahead: how far the trend is extrapolated, T_o + T_r (1 − e^{−s/T_r})
    /// (the observer lags a ramp by T_o; the trend levels off after T_r), and the blend-out
    /// e^{−s/T_d}.
    pub(super) fn ahead(&self, s: f64) -> (f64, f64) {
        let t_r = self.s.trend_horizon;
        let ramp = if t_r > 0.0 {
            t_r * (1.0 - (-s / t_r).exp())
        } else {
            0.0
        };
        (
            self.s.offset_time_constant + ramp,
            (-s / self.s.offset_decay).exp(),
        )
    }

    /// The corrected hand force over the horizon (FC-4): `out[i]` for t + (i + 1) `period`,
    /// blended toward the measurement's prediction as far as the forecast's record has fallen
    /// (FC-5); and, as long as `out`, that prediction in `measured_only` (FC-5's measurement
    /// model, FC-4 with f_fc ≡ 0: what C1 previews without a forecaster) and the forecast's
    /// own in `forecast_only` (FC-4 before the blend: what FC-5b keeps an easing from).
    pub fn fill(
        &mut self,
        t: f64,
        period: f64,
        window: &ForecastWindow,
        out: &mut [V3],
        measured_only: &mut [V3],
        forecast_only: &mut [V3],
    ) {
        let e = self.est;
        // FC-4's factors by recursion over the samples (an exp per sample costs a fifth of
        // this function).
        let decay = (-period / self.s.offset_decay).exp();
        let (t_o, t_r) = (self.s.offset_time_constant, self.s.trend_horizon);
        let ramp = if t_r > 0.0 {
            (-period / t_r).exp()
        } else {
            0.0
        };
        // The forecast as received, at the fitted shift, first: its lookups branch, and the
        // pass after them then runs without a branch on the sample.
        for (i, f) in out.iter_mut().enumerate() {
            let s = (i + 1) as f64 * period;
            *f = self.forecast_at(window, t + s - e.shift);
        }
        let mut w = 1.0;
        let mut r = 1.0;
        let mut capped = false;
        let samples = out.iter_mut().zip(measured_only.iter_mut());
        for ((f, m_i), f_i) in samples.zip(forecast_only.iter_mut()) {
            w *= decay;
            r *= ramp;
            let ahead = t_o + t_r * (1.0 - r);
            let u = unexplained(&e.offset, &e.trend, ahead, w);
            let p = self.scaled(f);
            *f = [0, 1, 2].map(|c| p[c] + u[c]);
            *f_i = *f;
            let m = unexplained(&self.offset_meas, &self.trend_meas, ahead, w);
            *m_i = m;
            if e.weight < 1.0 {
                // FC-5: toward measurement only as the forecast's record falls.
                *f = [0, 1, 2].map(|c| f[c] + (1.0 - e.weight) * (m[c] - f[c]));
            }
            // Never a force that lifts the robot (a tipping robot's hand, a biased sensor).
            let over = f[2] > self.lift_cap;
            capped |= over;
            if over {
                f[2] = self.lift_cap;
            }
        }
        if capped {
            self.counts.lift_capped += 1;
            if self.counts.lift_capped.is_power_of_two() {
                tracing::warn!(
                    "the corrected hand force would lift the robot (offset d̂_z = {:.0} N): \
                     capped at {:.0} N ({} ticks so far)",
                    e.offset[2],
                    self.lift_cap,
                    self.counts.lift_capped
                );
            }
        }
    }
}
