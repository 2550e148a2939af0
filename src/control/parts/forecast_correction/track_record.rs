//! The forecast's record (FC-5): every bin, the push each model predicted [`LEADS`] ago
//! against the push measured now, and from their errors the forecast's weight w in the blend.

use super::blend::unexplained;
use super::{DISCOUNTED, ForecastCorrector, LEADS, TRUSTED, dot};
use crate::control::forecast_window::ForecastWindow;

impl ForecastCorrector {
    /// FC-5, once a bin: each model's prediction of this bin made [`LEADS`] ago against the
    /// measured push, the weight w that minimises the combination's mean square error over the
    /// last `skill_time`, and the models' predictions of the push `LEADS` ahead.
    ///
    /// With e_f, e_m the errors of the forecast's and the measurement's predictions, the
    /// combination w f_f + (1 − w) f_m errs by e_m − w (e_m − e_f), whose mean square is least
    /// at w* = E[e_m·(e_m − e_f)] / E|e_m − e_f|² (Bates & Granger's combination of forecasts,
    /// their errors' correlation included). Where the two predictions agree the data say
    /// nothing of w: a prior w = 1 weighing as a disagreement of `min_force` RMS keeps the
    /// forecast's anticipation before a push, and clamping to [0, 1] keeps w a blend.
    pub(super) fn judge_forecast(&mut self, window: &ForecastWindow) {
        if self.s.skill_time == 0.0 {
            return;
        }
        let b = self.bins as usize - 1;
        let y = self.meas_bin(0);
        let centre = self.last_bin_t - 0.5 * self.bin;
        let mut m = [0.0; 4];
        let mut judged = 0;
        for (k, &lead) in LEADS.iter().enumerate() {
            let slot = self.lead_at[k] + b % lead;
            if b >= lead {
                let (p_f, p_m) = (self.pred_forecast[slot], self.pred_measured[slot]);
                let e_f = [0, 1, 2].map(|c| y[c] - p_f[c]);
                let e_m = [0, 1, 2].map(|c| y[c] - p_m[c]);
                let d = [0, 1, 2].map(|c| e_m[c] - e_f[c]);
                m[0] += dot(&e_m, &d);
                m[1] += dot(&d, &d);
                m[2] += dot(&e_f, &e_f);
                m[3] += dot(&e_m, &e_m);
                judged += 1;
            }
            let s = lead as f64 * self.bin;
            let p = self.forecast_at(window, centre + s - self.est.shift - self.lag);
            let (ahead, w) = self.ahead(s);
            let u = unexplained(&self.est.offset, &self.est.trend, ahead, w);
            let p = self.scaled(&p);
            self.pred_forecast[slot] = [0, 1, 2].map(|c| p[c] + u[c]);
            self.pred_measured[slot] = unexplained(&self.offset_meas, &self.trend_meas, ahead, w);
        }
        if judged == 0 {
            return;
        }
        let a = 1.0 - (-self.bin / self.s.skill_time).exp();
        for (s, v) in self.skill.iter_mut().zip(m) {
            *s += a * (v / judged as f64 - *s);
        }
        let prior = self.s.min_force.powi(2);
        let w = ((self.skill[0] + prior) / (self.skill[1] + prior)).clamp(0.0, 1.0);
        let w = if w.is_finite() { w } else { 1.0 };
        self.est.weight = w;
        self.est.error_forecast = self.skill[2].sqrt();
        self.est.error_measured = self.skill[3].sqrt();
        self.counts.weight_min = self.counts.weight_min.min(w);
        if !self.discounted && w < DISCOUNTED {
            self.discounted = true;
            self.counts.discounts += 1;
            if self.counts.discounts.is_power_of_two() {
                tracing::warn!(
                    "the forecast predicts the measured hand force worse than the measurement alone at \
                     t = {:.3} s (RMS error {:.1} N against {:.1} N): its weight is {w:.2} ({} \
                     times so far)",
                    self.last_bin_t,
                    self.est.error_forecast,
                    self.est.error_measured,
                    self.counts.discounts
                );
            }
        } else if self.discounted && w > TRUSTED {
            self.discounted = false;
            tracing::info!(
                "the forecast predicts the measured hand force again at t = {:.3} s (weight {w:.2})",
                self.last_bin_t
            );
        }
    }
}
