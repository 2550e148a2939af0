//! The fit (FC-2, FC-2b, FC-2c, FC-3b): κ̂ and τ̂ from the estimation window by a MAP search
//! over the candidate shifts, the priors they leave, the contradiction judged from them, and the
//! trend of what they leave unexplained. Once a bin.

use super::{
    BULK_ENERGY, DYNAMICS_TIME, EVIDENCE_SD, ForecastCorrector, SHIFT_SIGNIFICANCE, V3, axpy, dot,
};
use crate::control::forecast_window::ForecastWindow;

impl ForecastCorrector {
    /// The trend ḋ of what κ̂ f_fc(t − τ̂) leaves unexplained (FC-3b): the slope of the least-
    /// squares line through the last n_r bins' residuals, shrunk toward zero by twice its
    /// standard error (a trend the noise or the model's error could make is none). The bins'
    /// variance is the fit's own, at least the noise they carry, plus the model error in proportion to
    /// the recent forecast (as in FC-2): while a forecast explains the push, the door's and the
    /// arm's own transients are no trend to extrapolate; without one, a growing push is.
    /// O(n_r), once a bin.
    pub(super) fn fit_trend(&mut self, window: &ForecastWindow) {
        let model = self.s.model_error.powi(2) * self.recent_energy;
        let shift = self.est.shift + self.lag;
        self.est.trend = self.trend_of(window, self.est.factor, shift, model);
        // The measurement-only model's (FC-5): nothing forecast, so no model error either.
        self.trend_meas = self.trend_of(window, 0.0, 0.0, 0.0);
    }

    /// The shrunk slope of what `factor` f_fc(t − `shift`) leaves unexplained, `model` the
    /// model error's variance (N²).
    fn trend_of(&self, window: &ForecastWindow, factor: f64, shift: f64, model: f64) -> V3 {
        let n_r = self.n_r;
        if self.s.trend_horizon == 0.0 || (self.bins as usize) < n_r || n_r > self.meas.len() {
            return [0.0; 3];
        }
        // Bin j back from the newest at x_j = −j T_b: Σx, Σx² are fixed.
        let n = n_r as f64;
        let (mut sx, mut sxx) = (0.0, 0.0);
        let (mut sy, mut sxy, mut syy) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for j in 0..n_r {
            let x = -(j as f64) * self.bin;
            let centre = self.last_bin_t - (j as f64 + 0.5) * self.bin;
            let fc = if factor == 0.0 {
                [0.0; 3]
            } else {
                self.forecast_at(window, centre - shift)
            };
            let y = self.meas_bin(j);
            sx += x;
            sxx += x * x;
            for c in 0..3 {
                let r = y[c] - factor * fc[c];
                sy[c] += r;
                sxy[c] += x * r;
                syy[c] += r * r;
            }
        }
        let den = n * sxx - sx * sx;
        let floor = self.residual_var;
        let mut trend = [0.0; 3];
        for c in 0..3 {
            let b = (n * sxy[c] - sx * sy[c]) / den;
            let a = (sy[c] - b * sx) / n;
            // A bin's variance (the fit's residual, at least the noise floor, plus the model
            // error) and the slope's standard error.
            let res = (syy[c] - a * sy[c] - b * sxy[c]).max(0.0) / (n - 2.0);
            let se = (n * (res.max(floor) + model) / den).sqrt();
            let shrunk = (b.abs() - 2.0 * se).max(0.0);
            trend[c] = if b.is_finite() {
                shrunk.copysign(b)
            } else {
                0.0
            };
        }
        trend
    }

    /// κ̂ and τ̂ from the window (FC-2): for each candidate τ = m T_b, the MAP estimate of
    /// (κ, b) under y_j = κ g(t_j − τ) + b + noise, priors κ ~ N(κ₀, σ_κ²), b ~ N(d̂, σ_b²),
    /// then τ̂ the candidate of least cost with prior τ ~ N(τ₀, σ_τ²), refined by a parabola.
    pub(super) fn estimate_factor_and_shift(&mut self, window: &ForecastWindow) {
        self.fill_timeline(window);
        let fit = self.search_shift();
        let tau = self.refine_shift(fit.mi);
        let evidence = self.remember(&fit, tau);
        self.judge_contradiction(fit.kappa, tau, evidence);
        let kappa = fit.kappa;
        self.counts.estimations += 1;
        self.counts.factor_min = self.counts.factor_min.min(kappa);
        self.counts.factor_max = self.counts.factor_max.max(kappa);
    }

    /// The forecast's timeline over the window and the candidate shifts, and its prefix sums.
    fn fill_timeline(&mut self, window: &ForecastWindow) {
        let (n_w, m) = (self.n_w, self.m);
        // The timeline: g[i] is the forecast for the bin centred at
        // t_c(i) = t_newest − (n_W − 1 + M − i) T_b, i = 0 … n_W + 2M − 1; recorded bins for
        // the past (what was forecast then), the current window beyond the newest bin.
        let recorded = (self.bins as usize).min(self.fc.len());
        let newest_centre = self.last_bin_t - 0.5 * self.bin;
        for i in 0..self.g.len() {
            let back = (n_w - 1 + m) as isize - i as isize; // bins before the newest
            self.g[i] = if self.lag > 0.0 {
                // What the lagging measurement saw of the forecast at that bin's centre.
                let centre = newest_centre - back as f64 * self.bin - self.lag;
                self.forecast_at(window, centre)
            } else if back >= 0 {
                let k = back as usize;
                if k < recorded {
                    self.fc_bin(k)
                } else {
                    self.fc_bin(recorded - 1)
                }
            } else {
                window.at(newest_centre + (-back) as f64 * self.bin)
            };
        }
        for (k, g) in self.g.iter().rev().enumerate() {
            for c in 0..3 {
                self.g_rev[c][k] = g[c];
            }
        }
        self.p2[0] = 0.0;
        self.p1[0] = [0.0; 3];
        for i in 0..self.g.len() {
            self.p2[i + 1] = self.p2[i] + dot(&self.g[i], &self.g[i]);
            let mut s = self.p1[i];
            axpy(&mut s, 1.0, &self.g[i]);
            self.p1[i + 1] = s;
        }
    }

    /// Every candidate shift's MAP fit and cost (`self.costs`); the best one, unless FC-2b or
    /// FC-2c hold the prior's.
    fn search_shift(&mut self) -> ShiftFit {
        let (sy, syy) = self.correlate();
        let var = self.bin_variance();
        let best = self.fit_candidates(sy, syy, var);
        self.hold_prior_shift(best, var)
    }

    /// The window's measured bins unrolled (newest first) with their sum and sum of squares,
    /// and every candidate's Σ_j y_j · g(t_j − τ) in `self.cross` (the window's
    /// cross-correlation with the timeline).
    fn correlate(&mut self) -> (V3, f64) {
        let mut sy = [0.0; 3];
        let mut syy = 0.0;
        for k in 0..self.n_w {
            let y = self.meas_bin(k);
            self.window_meas[k] = y;
            axpy(&mut sy, 1.0, &y);
            syy += dot(&y, &y);
        }
        // Bin j outermost over the reversed rows: the inner loop over candidates reads
        // contiguous memory and vectorises, and each candidate's sum still runs over j in
        // order (the same bits). One candidate at a time this was a fifth of `update`; the loop
        // interchange alone, on `g`'s interleaved components, gained nothing.
        self.cross.fill(0.0);
        let [rx, ry, rz] = &self.g_rev;
        for (j, y) in self.window_meas.iter().enumerate() {
            // Candidate mi pairs y_j with g[n_W − 1 + 2M − mi − j] = g_rev[·][j + mi]; the
            // sum as `dot` adds it.
            let g = rx[j..].iter().zip(&ry[j..]).zip(&rz[j..]);
            for (sxy, ((gx, gy), gz)) in self.cross.iter_mut().zip(g) {
                *sxy += y[0] * gx + y[1] * gy + y[2] * gz;
            }
        }
        (sy, syy)
    }

    /// Variance of one bin: the sensor's noise of a mean over the bin (at least what the bins
    /// carry), and the model error in proportion to the recent forecast's RMS (the last
    /// estimations', decaying).
    fn bin_variance(&mut self) -> f64 {
        self.recent_energy *= (-self.bin / DYNAMICS_TIME).exp();
        (self.s.force_noise.powi(2) / self.bin_ticks as f64).max(self.residual_var)
            + self.s.model_error.powi(2) * self.recent_energy
    }

    /// The MAP fit of (κ, b) at every candidate shift (`self.costs`, `self.fits`) from the
    /// window's sums; the least cost's.
    fn fit_candidates(&mut self, sy: V3, syy: f64, var: f64) -> ShiftFit {
        let (n_w, m) = (self.n_w, self.m);
        let n = n_w as f64;
        let w_k = var / self.s.factor_sd.powi(2);
        let w_b = var / self.s.offset_sd.powi(2);
        let w_t = var / self.s.shift_sd.powi(2);
        let (k0, t0, b0) = (self.prior_factor, self.prior_shift, self.est.offset);
        let [k_lo, k_hi] = self.s.factor_bounds;
        let a = n + w_b;
        let mut rhs_b = sy;
        axpy(&mut rhs_b, w_b, &b0);
        let mut best = (f64::INFINITY, 0usize, k0);
        let mut evidence_at_best = 0.0;
        let mut energy_at_best = 0.0;
        for mi in 0..=2 * m {
            // τ = (mi − M) T_b: y_j (bin j back from the newest, j < n_W) against
            // g(t_j − τ) = g[n_W − 1 + M − j − (mi − M)] = g[n_W − 1 + 2M − mi − j].
            let hi = n_w + 2 * m - mi; // exclusive end of the window's g indices
            let lo = hi - n_w;
            let sxx = self.p2[hi] - self.p2[lo];
            let mut sx = self.p1[hi];
            axpy(&mut sx, -1.0, &self.p1[lo]);
            let sxy = self.cross[mi];
            // Eliminate b: b = (rhs_b − κ Sx) / a.
            let h = sxx + w_k - dot(&sx, &sx) / a;
            let r = sxy + w_k * k0 - dot(&sx, &rhs_b) / a;
            let kappa = if h > 0.0 { r / h } else { k0 }.clamp(k_lo, k_hi);
            let mut b = rhs_b;
            axpy(&mut b, -kappa, &sx);
            let b = b.map(|v| v / a);
            // Residual Σ|y − κ x − b|² from the sums, plus the priors (all in units of var).
            let res = syy - 2.0 * kappa * sxy - 2.0 * dot(&b, &sy)
                + kappa * kappa * sxx
                + 2.0 * kappa * dot(&b, &sx)
                + n * dot(&b, &b);
            let tau = (mi as f64 - m as f64) * self.bin;
            let mut db = b;
            axpy(&mut db, -1.0, &b0);
            let cost = res.max(0.0)
                + w_k * (kappa - k0).powi(2)
                + w_b * dot(&db, &db)
                + w_t * (tau - t0).powi(2);
            if cost < best.0 {
                best = (cost, mi, kappa);
                evidence_at_best = h;
                energy_at_best = sxx / n;
            }
            self.costs[mi] = cost;
            self.fits[mi] = [kappa, h, sxx / n];
        }
        let (cost, mi, kappa) = best;
        ShiftFit {
            mi,
            kappa,
            cost,
            var,
            evidence: evidence_at_best,
            energy: energy_at_best,
        }
    }

    /// FC-2b: a shift that lowers κ below the prior shift's κ stands only if it fits better by
    /// `SHIFT_SIGNIFICANCE` in units of the bin's variance. At a push's onset, a forecast still
    /// too small to be seen lets a shift that brings its later, larger part into the window
    /// "explain" a flat measurement with κ ≈ 0, a fit the noise picks. A shift that raises κ
    /// (the push found where the forecast put none: an early or a late forecast) is its own
    /// evidence. FC-2c: nor does a shift that would contradict the forecast (κ below κ₀ by more
    /// than the contradiction threshold) stand where the prior shift sees no forecast to judge
    /// (κ's posterior there looser than `EVIDENCE_SD`; its own κ is then the noise's): before a
    /// push's onset such a shift holds only the forecast's future, and a slow drift of the
    /// measured force (the arm and the door settling as the robot leans), which the bins'
    /// variance from successive differences does not count, passes the test above.
    fn hold_prior_shift(&self, best: ShiftFit, var: f64) -> ShiftFit {
        let (m, t0, k0) = (self.m, self.prior_shift, self.prior_factor);
        let prior_mi = ((t0 / self.bin).round() + m as f64).clamp(0.0, (2 * m) as f64) as usize;
        let [prior_kappa, prior_h, prior_energy] = self.fits[prior_mi];
        let blind = var >= EVIDENCE_SD.powi(2) * prior_h;
        let held = (best.kappa < prior_kappa
            && self.costs[prior_mi] - best.cost < SHIFT_SIGNIFICANCE * var)
            || (blind && best.kappa < k0 - self.s.contradiction);
        if !held {
            return best;
        }
        ShiftFit {
            mi: prior_mi,
            kappa: prior_kappa,
            cost: self.costs[prior_mi],
            var,
            evidence: prior_h,
            energy: prior_energy,
        }
    }

    /// τ̂ of candidate `mi`, refined between its neighbours.
    fn refine_shift(&self, mi: usize) -> f64 {
        let m = self.m;
        let mut tau = (mi as f64 - m as f64) * self.bin;
        // Sub-bin refinement: the vertex of the parabola through the three costs.
        let at = |i: Option<usize>| i.and_then(|i| self.costs.get(i)).copied();
        let (cm, c0, cp) = (
            at(mi.checked_sub(1)).unwrap_or(f64::INFINITY),
            self.costs[mi],
            at(Some(mi + 1)).unwrap_or(f64::INFINITY),
        );
        let curv = cm - 2.0 * c0 + cp;
        if cm.is_finite() && cp.is_finite() && curv > 0.0 {
            tau += 0.5 * self.bin * ((cm - cp) / curv).clamp(-1.0, 1.0);
        }
        tau
    }

    /// The estimate, and the next estimation's priors where the window gave evidence (returned).
    fn remember(&mut self, fit: &ShiftFit, tau: f64) -> bool {
        let (n_w, m) = (self.n_w, self.m);
        let (mi, kappa, var) = (fit.mi, fit.kappa, fit.var);
        let (evidence_at_best, energy_at_best) = (fit.evidence, fit.energy);
        self.est.factor = kappa;
        self.est.shift = tau;
        // The forecast levels κ̂ was fitted on (FC-4b): the window's largest at the chosen
        // shift, remembered as the priors are.
        let hi = n_w + 2 * m - mi;
        let level = (hi - n_w..hi).fold(0.0f64, |l, i| l.max(dot(&self.g[i], &self.g[i])));
        self.seen_level = level
            .sqrt()
            .max(self.seen_level * (-self.bin / self.s.forget).exp());
        // The next estimation's priors: this estimate where the window gave evidence of it
        // (else a noisy fit would random-walk the priors), relaxing toward κ = 1, τ = 0.
        // Evidence: a tight posterior (the model error scaled by the recent push keeps the tail
        // of a push, where the door's own dynamics dominate, from overwriting what its bulk
        // said) and a forecast of at least `min_force` RMS.
        let sd = (var / evidence_at_best.max(1e-300)).sqrt();
        self.recent_energy = self.recent_energy.max(energy_at_best);
        let keep = (-self.bin / self.s.forget).exp();
        let evidence = sd < EVIDENCE_SD
            && energy_at_best >= self.s.min_force.powi(2)
            && energy_at_best >= BULK_ENERGY * self.recent_energy;
        if evidence {
            self.prior_factor = kappa;
            // A refused forecast (κ̂ ≈ 0) says nothing of its timing.
            if kappa > 0.2 {
                self.prior_shift = tau;
            } else {
                self.prior_shift *= keep;
            }
        } else {
            self.prior_factor = 1.0 + (self.prior_factor - 1.0) * keep;
            self.prior_shift *= keep;
        }
        // Without evidence (a loose posterior: a forecast still too small to be seen in the
        // measurement, a shift picked among many candidates by the noise), the fit may lower
        // the forecast but not raise it: leaning into an amplified push on the noise's word
        // topples a robot, leaning less only costs the margin the measured force restores.
        if sd >= EVIDENCE_SD && kappa > self.prior_factor {
            self.est.factor = self.prior_factor;
            self.est.shift = self.prior_shift;
        }
        evidence
    }

    /// Whether the measured force contradicts the forecast (with the window's evidence).
    fn judge_contradiction(&mut self, kappa: f64, tau: f64, evidence: bool) {
        // Contradicted: κ̂ far from 1 with the window's evidence (posterior sd of κ below
        // half the threshold), not merely from a prior; it stays so until the factor the
        // estimator remembers is back within the threshold (evidence of agreement, or the
        // memory relaxing to 1 over `forget` once the forecast says nothing more).
        let c = self.s.contradiction;
        let contradicted = ((kappa - 1.0).abs() > c && evidence)
            || (self.est.contradicted && (self.prior_factor - 1.0).abs() > c);
        if contradicted && !self.est.contradicted {
            self.counts.contradictions += 1;
            tracing::warn!(
                "the measured hand force contradicts the forecast at t = {:.3} s: factor {kappa:.2}, \
                 shift {:+.0} ms ({} so far); its weight follows the factor",
                self.last_bin_t,
                tau * 1e3,
                self.counts.contradictions
            );
        } else if !contradicted && self.est.contradicted {
            tracing::info!(
                "the forecast agrees with the measured hand force again at t = {:.3} s (factor {kappa:.2})",
                self.last_bin_t
            );
        }
        self.est.contradicted = contradicted;
        if contradicted && !evidence {
            // A weak window does not lift a contradicted forecast's weight: its memory does.
            self.est.factor = self.prior_factor;
        }
    }
}

/// One shift search's outcome: the best candidate, its κ̂ and cost, the bin variance it was judged
/// with, its posterior curvature (evidence) and the window's forecast energy there.
struct ShiftFit {
    mi: usize,
    kappa: f64,
    cost: f64,
    var: f64,
    evidence: f64,
    energy: f64,
}
