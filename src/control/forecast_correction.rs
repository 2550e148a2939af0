//! Forecast correction from the measured hand force (docs/forecast_correction.md): between the
//! forecast intake and the hand previewer, the forecast is read as the push to come up to an
//! amplitude factor κ, a time shift τ and an offset d. The wrist sensor measures the push less
//! what the held object (the door) takes to move with the hand, of apparent mass Λ at the hand:
//!
//!   f_meas(t) + Λ ẍ_h(t) ≈ κ f_fc(t − τ) + d,                               (FC-1)
//!
//! A hand force estimated rather than measured (a robot without a wrist sensor, from its joint
//! torques) lags the push by its filter's mean delay δ; the forecast is compared with it δ
//! later, so that δ is not read as a late push (FC-1b):
//!
//!   f_meas(t) + Λ ẍ_h(t) ≈ κ f_fc(t − τ − δ) + d.                           (FC-1b)
//!
//! ẍ_h the hand's acceleration: the change of its bin-mean velocity over K bins (FC-1c,
//! [`acceleration_bins`]): one with exact velocities, with a wrist sensor's force or with the
//! corrected force fed back; with an estimated base, the fewest that keep Λ ẍ_h's noise within a
//! force sample's, as far as the force's own lag allows. κ and τ estimated
//! from a short window of the measured push against the forecast's past, d by an observer on
//! what κ and τ leave unexplained. The horizon the previewer sees is
//!
//!   f̂(t + s) = κ̂ f_fc(t + s − τ̂) + (d̂ + ḋ (T_o + T_r (1 − e^{−s/T_r}))) e^{−s/T_d}.  (FC-4)
//!
//! ḋ the trend of what the forecast leaves unexplained, a line fitted through its last bins
//! (FC-3b): a push the forecast misses, or one nothing forecasts, is extrapolated while it grows.
//!
//! A forecast the measurement contradicts (a phantom push: κ̂ → 0; an amplitude far off) is
//! scaled down until it agrees again. With no forecast at all, f̂ is the offset alone: the
//! measurement held and decaying (a robot with only a wrist force sensor).
//!
//! A forecast of the wrong shape (no κ and τ explain it) is judged by its record: every bin,
//! FC-4 with the forecast and FC-4 without it (measurement only) each predict the push a few
//! leads ahead; when those times come, their errors give the weight w of the forecast's
//! prediction in the least-squares combination of the two (FC-5), and the horizon is
//!
//!   f̂ = w f̂_forecast + (1 − w) f̂_measured.                                  (FC-5)
//!
//! That blend hedges a forecast's easing on the push staying; where the capture point under the
//! measured push is beyond the edge it drives the robot toward, the push cannot be held if it
//! stays, and the easing is kept from the hedge (FC-5b, [`ForecastCorrector::fill`]).
//!
//! Real-time: every buffer is allocated in [`ForecastCorrector::new`]; a tick is O(1) but one
//! tick in `bin_ticks`, which re-estimates κ and τ in O(window × shifts).

use super::forecast_window::ForecastWindow;

use std::any::Any;

use serde::{Deserialize, Serialize};

use super::core::TickError;
use super::parts::{ControllerPart, PartEntry, PartSetup, Stage, TickFrame, TickInputs};
use super::viability::{CapturePoint, ViabilitySettings, easing_believed};
use crate::col;
use crate::config::{ControllerKind, HandForceSource};
use crate::record::Record;

/// The correction's current estimate, for logs and the summary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CorrectionEstimate {
    /// κ̂.
    pub factor: f64,
    /// τ̂ (s): the force comes τ̂ after the forecast says (negative: before).
    pub shift: f64,
    /// d̂ (N).
    pub offset: [f64; 3],
    /// The window's evidence contradicts the forecast (|κ̂ − 1| > `contradiction`).
    pub contradicted: bool,
    /// ḋ (N/s): the trend of the unexplained force (zero when `trend_horizon` is 0).
    pub trend: [f64; 3],
    /// w (FC-5): the weight of the corrected forecast against measurement only, in [0, 1].
    pub weight: f64,
    /// RMS error (N) of the push predicted a lead ahead with the forecast and without it, over
    /// the last `skill_time` (FC-5): how well each explained the measurement so far.
    pub error_forecast: f64,
    pub error_measured: f64,
    /// FC-5b (x, y): how far the horizon's easing of the measured push was kept from FC-5's
    /// hedge at the last fill (0 where no easing sample was hedged).
    pub easing_believed: [f64; 2],
}

impl Default for CorrectionEstimate {
    fn default() -> Self {
        Self {
            factor: 1.0,
            shift: 0.0,
            offset: [0.0; 3],
            contradicted: false,
            trend: [0.0; 3],
            weight: 1.0,
            error_forecast: 0.0,
            error_measured: 0.0,
            easing_believed: [0.0; 2],
        }
    }
}

/// Counters of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CorrectionCounts {
    /// Times the forecast became contradicted.
    pub contradictions: u64,
    /// Plant time spent contradicted (s).
    pub contradicted_time: f64,
    /// Estimations run, and ticks whose measured force was not finite (skipped).
    pub estimations: u64,
    pub bad_measurements: u64,
    /// Smallest and largest κ̂ seen.
    pub factor_min: f64,
    pub factor_max: f64,
    /// Ticks whose corrected horizon asked for more upward force than `max_lift` M g (capped).
    pub lift_capped: u64,
    /// FC-5: smallest weight w, times w fell below 0.5 (until back above 0.9) and the plant
    /// time it stayed there (s).
    pub weight_min: f64,
    pub discounts: u64,
    pub discounted_time: f64,
    /// FC-5b: plant time (s) an easing of the measured push was kept from FC-5's hedge.
    pub easing_believed_time: f64,
    /// Gaps in plant time longer than two bins between ticks (a stalled controller), across
    /// which no hand acceleration was taken (FC-1c).
    pub time_gaps: u64,
}

type V3 = [f64; 3];

/// Posterior standard deviation of κ below which an estimate becomes the next prior.
const EVIDENCE_SD: f64 = 0.1;
/// Time constant (s) of the model error's scale after a push: the door and the arm ring on.
const DYNAMICS_TIME: f64 = 0.5;
/// Memory of the bins' residual variance (s).
const NOISE_TIME: f64 = 1.0;
/// A window is remembered when its forecast energy is at least this fraction of the recent
/// largest: the bulk of a push, not its tail.
const BULK_ENERGY: f64 = 0.25;
/// FC-5's leads (bins): 10 ms to 320 ms at 5 ms bins, doubling, around the cart-table's time
/// constant 1/ω ≈ 0.23 s, the lead over which a push decides a fall.
const LEADS: [usize; 6] = [2, 4, 8, 16, 32, 64];
/// FC-2b: how much better (−2 log posterior) a shift that lowers κ must fit than the prior's:
/// between χ²₁'s 0.95 and 0.99 points (3.84, 6.63).
const SHIFT_SIGNIFICANCE: f64 = 5.0;
/// Below this weight the forecast is discounted (counted, logged); back above [`TRUSTED`].
const DISCOUNTED: f64 = 0.5;
const TRUSTED: f64 = 0.9;

/// FC-1c's largest K (40 ms at 5 ms bins): a longer difference lags a push's rise.
const MAX_ACCELERATION_BINS: usize = 8;

/// FC-1c: the bins K over which the hand's bin-mean velocity is differenced. The fewest that
/// keep the door-inertia term Λ ẍ_h's noise within one force sample's: a velocity error of σ_v
/// in each of two bins K T_b apart gives Λ ẍ_h an error of m √2 σ_v / (K T_b), m = tr Λ (Λ's
/// largest eigenvalue for a door's m e eᵀ, a bound otherwise), so K ≥ m √2 σ_v / (T_b σ_f).
/// The error is taken as the same in every bin: an estimated base's velocity error is
/// low-passed by its filter and does not average out over a bin. But no more than keep ẍ_h as
/// fresh as the force it is added to: the difference is centred K T_b / 2 behind the bin's
/// centre, the force's own door inertia δ (`lag`, FC-1b) behind it, so K ≤ 2 δ / T_b. A wrist
/// sensor's force (δ = 0) takes K = 1 whatever the noise: a lagging ẍ_h left the door's
/// inertia in its push. Exact velocities (σ_v = 0) take K = 1. Within [1,
/// [`MAX_ACCELERATION_BINS`]].
pub fn acceleration_bins(
    mass: f64,
    velocity_noise: f64,
    bin: f64,
    force_noise: f64,
    lag: f64,
) -> usize {
    let noisy = mass * std::f64::consts::SQRT_2 * velocity_noise / (bin * force_noise);
    // The tolerance keeps a lag of a whole number of half-bins (1/K of WO-2: 10 ms) from
    // rounding down.
    let fresh = (2.0 * lag / bin + 1e-9).floor();
    let k = if noisy.is_nan() {
        1.0
    } else {
        noisy.ceil().min(fresh)
    };
    if k.is_nan() || k <= 1.0 {
        1
    } else {
        k.min(MAX_ACCELERATION_BINS as f64) as usize
    }
}

fn dot(a: &V3, b: &V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn axpy(y: &mut V3, a: f64, x: &V3) {
    for c in 0..3 {
        y[c] += a * x[c];
    }
}

/// FC-4's unexplained part ahead: (d̂ + ḋ `ahead`) `w`, with [`ForecastCorrector::ahead`]'s
/// factors.
fn unexplained(offset: &V3, trend: &V3, ahead: f64, w: f64) -> V3 {
    [0, 1, 2].map(|c| (offset[c] + trend[c] * ahead) * w)
}

/// The estimator with its preallocated history.
pub struct ForecastCorrector {
    s: CorrectionSettings,
    /// Bin length T_b (s) = the preview period, and control ticks per bin.
    bin: f64,
    bin_ticks: usize,
    /// Control period (s).
    dt: f64,
    /// Largest upward force of the corrected horizon (N): `max_lift` M g.
    lift_cap: f64,
    /// Window bins n_W and shift bins M (candidates τ = m T_b, m = −M…M).
    n_w: usize,
    m: usize,
    /// Bins of the trend fit (≤ n_W).
    n_r: usize,
    /// Rings of bin means: measured force, and the forecast for the bin's times as it was then.
    meas: Vec<V3>,
    fc: Vec<V3>,
    /// Bins recorded so far (the rings' write index is `bins % len`).
    bins: u64,
    /// Plant time of the newest recorded bin's end.
    last_bin_t: f64,
    /// The bin being accumulated.
    acc_meas: V3,
    acc_fc: V3,
    acc_n: usize,
    /// Λ: the held object's apparent mass at the hand (world, kg; zero: nothing held).
    held_mass: [V3; 3],
    /// The sum of the hand's velocity over the bin being accumulated, the last bins' mean
    /// velocities (newest first; `vel_known` of them), and the newest acceleration: the change
    /// of the bins' mean velocities over K bins (FC-1c; a measured velocity's white noise enters
    /// divided by √(ticks per bin), not by one).
    acc_vel: V3,
    acc_vel_n: usize,
    /// Plant time of the last tick with a measurement: a gap longer than two bins (a stalled
    /// controller) restarts the velocity history, whose differences assume contiguous bins.
    last_t: f64,
    vel_hist: [V3; MAX_ACCELERATION_BINS + 1],
    vel_known: usize,
    last_acc: V3,
    /// σ (m/s) of the hand's velocity as the controller has it (0: taken as exact).
    velocity_noise: f64,
    /// Scratch: the forecast timeline g over [t_b − (n_W − 1 + M) T_b, t_b + M T_b] and its
    /// prefix sums (Σ|g|², Σg).
    g: Vec<V3>,
    /// The timeline reversed, one component per row (`g_rev[c][k] = g[len − 1 − k][c]`): the
    /// cross-correlation reads it forward and contiguous, two candidates per SIMD register.
    g_rev: [Vec<f64>; 3],
    p2: Vec<f64>,
    p1: Vec<V3>,
    /// Scratch: the window's measured bins, newest first (the ring unrolled once per bin: the
    /// shift search reads each n_W × (2M + 1) times, and a ring index costs an integer division).
    window_meas: Vec<V3>,
    /// Scratch: each candidate shift's cost.
    costs: Vec<f64>,
    /// Scratch: each candidate shift's cross-correlation Σ_j y_j · g(t_j − τ).
    cross: Vec<f64>,
    /// Each candidate's κ, evidence h and forecast energy (FC-2b).
    fits: Vec<[f64; 3]>,
    est: CorrectionEstimate,
    /// Prior means (relaxing to 1 and 0 at `forget`).
    prior_factor: f64,
    prior_shift: f64,
    /// The measurement's lag (FC-1b, s).
    lag: f64,
    /// The windows' recent largest mean square forecast (N²), decaying at [`DYNAMICS_TIME`]:
    /// the scale of the model error, which outlasts the push that excited it.
    recent_energy: f64,
    /// The noise a bin really carries (the sensor's, and its hand acceleration's from noisy
    /// velocities), per axis, over the last `NOISE_TIME`, when it exceeds the configured sensor
    /// noise: half the mean square of the change of a bin's residual about the estimate from
    /// one bin to the next. Differencing leaves the noise and removes a smooth mismatch (a
    /// wrong forecast must not read as noise, or it would never be refused).
    residual_var: f64,
    last_residual: Option<V3>,
    /// The push measured at the last tick with a measurement.
    last_push: V3,
    /// FC-4b: the largest forecast (N) κ̂ was fitted on, relaxing at `forget`.
    seen_level: f64,
    /// FC-5: the measurement-only model (FC-3, FC-3b with f_fc = 0): its offset and trend.
    offset_meas: V3,
    trend_meas: V3,
    /// FC-5: per lead of [`LEADS`], a ring of that many bins of the push each model predicted
    /// (concatenated: lead k's ring starts at `lead_at[k]`).
    lead_at: [usize; LEADS.len()],
    pred_forecast: Vec<V3>,
    pred_measured: Vec<V3>,
    /// FC-5's exponentially weighted means over `skill_time`: e_m·(e_m − e_f), |e_m − e_f|²,
    /// |e_f|², |e_m|² (N²), e_f and e_m the two models' prediction errors.
    skill: [f64; 4],
    /// The forecast is discounted (w fell below [`DISCOUNTED`] and has not risen above
    /// [`TRUSTED`] since).
    discounted: bool,
    pub counts: CorrectionCounts,
}

impl ForecastCorrector {
    /// `bin`: the preview period (s); `dt`: the control period (s); `weight`: the robot's M g
    /// (N).
    pub fn new(settings: CorrectionSettings, bin: f64, dt: f64, weight: f64) -> Self {
        let bin_ticks = ((bin / dt).round() as usize).max(1);
        let bin = bin_ticks as f64 * dt;
        let n_w = ((settings.window / bin).round() as usize).max(2);
        let m = (settings.max_shift / bin).round() as usize;
        let hist = n_w + m;
        let timeline = n_w + 2 * m;
        let n_r = ((settings.trend_window / bin).round() as usize).clamp(3, n_w.max(3));
        let mut lead_at = [0; LEADS.len()];
        for k in 1..LEADS.len() {
            lead_at[k] = lead_at[k - 1] + LEADS[k - 1];
        }
        let leads: usize = LEADS.iter().sum();
        Self {
            s: settings,
            bin,
            bin_ticks,
            dt,
            lift_cap: settings.max_lift * weight,
            n_w,
            m,
            n_r,
            meas: vec![[0.0; 3]; n_w],
            fc: vec![[0.0; 3]; hist],
            bins: 0,
            last_bin_t: f64::NEG_INFINITY,
            acc_meas: [0.0; 3],
            acc_fc: [0.0; 3],
            acc_n: 0,
            held_mass: [[0.0; 3]; 3],
            acc_vel: [0.0; 3],
            acc_vel_n: 0,
            last_t: f64::NEG_INFINITY,
            vel_hist: [[0.0; 3]; MAX_ACCELERATION_BINS + 1],
            vel_known: 0,
            last_acc: [0.0; 3],
            velocity_noise: 0.0,
            g: vec![[0.0; 3]; timeline],
            g_rev: std::array::from_fn(|_| vec![0.0; timeline]),
            p2: vec![0.0; timeline + 1],
            p1: vec![[0.0; 3]; timeline + 1],
            window_meas: vec![[0.0; 3]; n_w],
            costs: vec![f64::INFINITY; 2 * m + 1],
            cross: vec![0.0; 2 * m + 1],
            fits: vec![[1.0, 0.0, 0.0]; 2 * m + 1],
            est: CorrectionEstimate::default(),
            prior_factor: 1.0,
            prior_shift: 0.0,
            lag: 0.0,
            recent_energy: 0.0,
            residual_var: 0.0,
            last_residual: None,
            last_push: [0.0; 3],
            seen_level: 0.0,
            offset_meas: [0.0; 3],
            trend_meas: [0.0; 3],
            lead_at,
            pred_forecast: vec![[0.0; 3]; leads],
            pred_measured: vec![[0.0; 3]; leads],
            skill: [0.0; 4],
            discounted: false,
            counts: CorrectionCounts {
                factor_min: 1.0,
                factor_max: 1.0,
                weight_min: 1.0,
                ..Default::default()
            },
        }
    }

    /// Λ, the held object's apparent mass at the hand (world, kg, symmetric): its inertia force
    /// −Λ ẍ_h is taken out of the measured force (FC-1).
    pub fn with_held_mass(mut self, held_mass: [V3; 3]) -> Self {
        self.held_mass = held_mass;
        self
    }

    /// σ (m/s) of the hand's velocity as the controller has it this tick: the base's velocity
    /// error when the base is estimated, 0 when it is measured (FC-1c). Not finite or negative:
    /// 0.
    pub fn set_velocity_noise(&mut self, sigma: f64) {
        self.velocity_noise = if sigma.is_finite() {
            sigma.max(0.0)
        } else {
            0.0
        };
    }

    /// K (FC-1c): the bins the hand's acceleration is differenced over, for the held mass, the
    /// velocity's and the force's noise and the measurement's lag as they are now.
    pub fn acceleration_window_bins(&self) -> usize {
        let mass = (0..3).map(|r| self.held_mass[r][r]).sum::<f64>();
        let (v, f) = (self.velocity_noise, self.s.force_noise);
        acceleration_bins(mass, v, self.bin, f, self.lag)
    }

    /// The push the measured force `y` says, with the hand accelerating at `acc`: y + Λ acc.
    fn push(&self, y: &V3, acc: &V3) -> V3 {
        [0, 1, 2].map(|r| y[r] + dot(&self.held_mass[r], acc))
    }

    /// The push measured at the last tick (FC-1's left side: the measured force plus Λ times
    /// the hand's newest bin acceleration); zero before the first measurement.
    pub fn measured_push(&self) -> V3 {
        self.last_push
    }

    pub fn settings(&self) -> &CorrectionSettings {
        &self.s
    }

    pub fn estimate(&self) -> &CorrectionEstimate {
        &self.est
    }

    /// A new plant run: its times start over. Counters are kept. Allocation-free.
    pub fn reset(&mut self) {
        self.bins = 0;
        self.last_bin_t = f64::NEG_INFINITY;
        self.acc_meas = [0.0; 3];
        self.acc_fc = [0.0; 3];
        self.acc_n = 0;
        self.acc_vel = [0.0; 3];
        self.acc_vel_n = 0;
        self.last_t = f64::NEG_INFINITY;
        self.vel_known = 0;
        self.last_acc = [0.0; 3];
        self.est = CorrectionEstimate::default();
        self.prior_factor = 1.0;
        self.prior_shift = 0.0;
        self.recent_energy = 0.0;
        self.residual_var = 0.0;
        self.last_residual = None;
        self.last_push = [0.0; 3];
        self.seen_level = 0.0;
        self.offset_meas = [0.0; 3];
        self.trend_meas = [0.0; 3];
        self.skill = [0.0; 4];
        self.discounted = false;
    }

    /// The forecast as received, for plant time `t`: the window where it covers `t` or `t` is
    /// past the newest recorded bin; the recorded history for earlier times (a window starts
    /// at its forecaster's present, so the forecast's past lives here only).
    // Always inlined: called per horizon sample, out of line its call was a third of its cost
    // (perf, `control/c1_tick`).
    #[inline(always)]
    pub fn forecast_at(&self, window: &ForecastWindow, t: f64) -> V3 {
        if window.covers(t) || self.bins == 0 || t >= self.last_bin_t {
            return window.at(t);
        }
        // Bin k (k = 0 the newest) is centred at last_bin_t − (k + ½) T_b.
        let len = self.fc.len();
        let recorded = (self.bins as usize).min(len);
        let x = (self.last_bin_t - t) / self.bin - 0.5;
        if x <= 0.0 {
            return self.fc_bin(0);
        }
        // x > 0 here, so truncation is floor (and no libm call: the build targets baseline
        // x86-64, which has no rounding instruction).
        let k = x as usize;
        if k + 1 >= recorded {
            return self.fc_bin(recorded - 1);
        }
        let w = x - k as f64;
        let (a, b) = (self.fc_bin(k), self.fc_bin(k + 1));
        [0, 1, 2].map(|c| a[c] + w * (b[c] - a[c]))
    }

    /// How far (s) the measured hand force lags the force on the hand (the estimate's filter,
    /// FC-1b): the forecast is compared with it that much later, and previewed as fitted.
    pub fn set_measurement_lag(&mut self, lag: f64) {
        self.lag = if lag.is_finite() { lag.max(0.0) } else { 0.0 };
    }

    /// The k-th newest recorded forecast bin (k < recorded).
    fn fc_bin(&self, k: usize) -> V3 {
        let len = self.fc.len();
        self.fc[(self.bins as usize - 1 - k) % len]
    }

    fn meas_bin(&self, k: usize) -> V3 {
        let len = self.meas.len();
        self.meas[(self.bins as usize - 1 - k) % len]
    }

    /// One control tick at plant time `t` with the force measured at the hand (`None`: no
    /// measurement this tick) and the hand's measured velocity (world). Updates the offset
    /// observer every tick and κ̂, τ̂ once a bin.
    pub fn update(&mut self, t: f64, window: &ForecastWindow, measured: Option<V3>, hand_vel: V3) {
        let finite = |y: &V3| y.iter().all(|v| v.is_finite());
        let Some(y) = measured.filter(|y| finite(y) && finite(&hand_vel)) else {
            if measured.is_some() {
                self.counts.bad_measurements += 1;
            }
            return;
        };
        let now = window.at(t);
        // Offset observer (FC-3): a disturbance state driven by what κ̂, τ̂ leave unexplained,
        // d̂ ← d̂ + L (y + Λ ẍ_h − κ̂ f_fc(t − τ̂) − d̂), L = 1 − e^{−dt/T_o}, with the newest
        // bin's acceleration (one tick's velocity difference is mostly noise).
        let explained = self.forecast_at(window, t - self.est.shift - self.lag);
        let l = 1.0 - (-self.dt / self.s.offset_time_constant).exp();
        let push = self.push(&y, &self.last_acc);
        self.last_push = push;
        for c in 0..3 {
            let r = push[c] - self.est.factor * explained[c];
            self.est.offset[c] += l * (r - self.est.offset[c]);
            // The measurement-only model's offset (FC-5): the same observer with f_fc = 0.
            self.offset_meas[c] += l * (push[c] - self.offset_meas[c]);
        }
        if self.est.contradicted {
            self.counts.contradicted_time += self.dt;
        }
        if self.discounted {
            self.counts.discounted_time += self.dt;
        }
        // The bin: means of the measured force and of the forecast for the same ticks.
        axpy(&mut self.acc_meas, 1.0, &y);
        axpy(&mut self.acc_fc, 1.0, &now);
        let since = t - self.last_t;
        if since.is_nan() || since < 0.0 || since > 2.0 * self.bin {
            // A gap (or time going back): no acceleration from velocities across it.
            if self.last_t.is_finite() {
                self.counts.time_gaps += 1;
            }
            self.acc_vel = [0.0; 3];
            self.acc_vel_n = 0;
            self.vel_known = 0;
        }
        self.last_t = t;
        axpy(&mut self.acc_vel, 1.0, &hand_vel);
        self.acc_vel_n += 1;
        self.acc_n += 1;
        if self.acc_n < self.bin_ticks {
            return;
        }
        let inv = 1.0 / self.acc_n as f64;
        let i_m = self.bins as usize % self.meas.len();
        let i_f = self.bins as usize % self.fc.len();
        // The bin's push (FC-1): its mean measured force plus Λ times the hand's acceleration,
        // the change of the mean velocity from K bins back to this one (FC-1c; over fewer while
        // a session has fewer, none for its first bin; it lags the bin by K/2 bins).
        self.vel_hist.copy_within(..MAX_ACCELERATION_BINS, 1);
        let inv_vel = 1.0 / self.acc_vel_n as f64;
        self.vel_hist[0] = self.acc_vel.map(|v| v * inv_vel);
        self.vel_known = (self.vel_known + 1).min(MAX_ACCELERATION_BINS + 1);
        let k = self.acceleration_window_bins().min(self.vel_known - 1);
        self.last_acc = match k {
            0 => [0.0; 3],
            _ => {
                let (v, v0, span) = (self.vel_hist[0], self.vel_hist[k], k as f64 * self.bin);
                [0, 1, 2].map(|c| (v[c] - v0[c]) / span)
            }
        };
        self.acc_vel = [0.0; 3];
        self.acc_vel_n = 0;
        self.meas[i_m] = self.push(&self.acc_meas.map(|v| v * inv), &self.last_acc);
        self.fc[i_f] = self.acc_fc.map(|v| v * inv);
        self.acc_meas = [0.0; 3];
        self.acc_fc = [0.0; 3];
        self.acc_n = 0;
        self.bins += 1;
        self.last_bin_t = t + 0.5 * self.dt;
        // The bin's residual about the current estimate (κ̂ f_fc(t − τ̂) + d̂ at its centre).
        let centre = self.last_bin_t - 0.5 * self.bin;
        let explained = self.forecast_at(window, centre - self.est.shift - self.lag);
        let e: V3 = [0, 1, 2].map(|c| self.meas[i_m][c] - self.est.factor * explained[c]);
        if let Some(e0) = self.last_residual {
            let d2 = (0..3).map(|c| (e[c] - e0[c]).powi(2)).sum::<f64>() / 6.0;
            self.residual_var += (1.0 - (-self.bin / NOISE_TIME).exp()) * (d2 - self.residual_var);
        }
        self.last_residual = Some(e);
        if self.bins as usize >= self.n_w {
            self.estimate_factor_and_shift(window);
        }
        self.fit_trend(window);
        self.judge_forecast(window);
    }

    /// The trend ḋ of what κ̂ f_fc(t − τ̂) leaves unexplained (FC-3b): the slope of the least-
    /// squares line through the last n_r bins' residuals, shrunk toward zero by twice its
    /// standard error (a trend the noise or the model's error could make is none). The bins'
    /// variance is the fit's own, at least the noise they carry, plus the model error in proportion to
    /// the recent forecast (as in FC-2): while a forecast explains the push, the door's and the
    /// arm's own transients are no trend to extrapolate; without one, a growing push is.
    /// O(n_r), once a bin.
    fn fit_trend(&mut self, window: &ForecastWindow) {
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

    /// κ̂ f_fc for the horizon (FC-4b): an amplification (κ̂ > 1) is believed up to the forecast
    /// levels it was fitted on, and beyond them the forecast gains only what it gained there,
    /// (κ̂ − 1) times that level. A forecast 2× too slow and one 4× too weak rise alike at their
    /// onset; applying the onset's κ̂ = 4 to the slow forecast's peak previews a push 4× the
    /// real one (and the robot leans into it).
    fn scaled(&self, p: &V3) -> V3 {
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
    fn ahead(&self, s: f64) -> (f64, f64) {
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
    fn judge_forecast(&mut self, window: &ForecastWindow) {
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

    /// κ̂ and τ̂ from the window (FC-2): for each candidate τ = m T_b, the MAP estimate of
    /// (κ, b) under y_j = κ g(t_j − τ) + b + noise, priors κ ~ N(κ₀, σ_κ²), b ~ N(d̂, σ_b²),
    /// then τ̂ the candidate of least cost with prior τ ~ N(τ₀, σ_τ²), refined by a parabola.
    fn estimate_factor_and_shift(&mut self, window: &ForecastWindow) {
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

    /// Every candidate shift's MAP fit and cost (`self.costs`); the best one.
    fn search_shift(&mut self) -> ShiftFit {
        let (n_w, m) = (self.n_w, self.m);
        // Sums over the window of the measurement alone.
        let mut sy = [0.0; 3];
        let mut syy = 0.0;
        for k in 0..n_w {
            let y = self.meas_bin(k);
            self.window_meas[k] = y;
            axpy(&mut sy, 1.0, &y);
            syy += dot(&y, &y);
        }
        // Every candidate's Σ_j y_j · g(t_j − τ) (the window's cross-correlation with the
        // timeline), bin j outermost over the reversed rows: the inner loop over candidates
        // reads contiguous memory and vectorises, and each candidate's sum still runs over j in
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
        let n = n_w as f64;
        // Variance of one bin: the sensor's noise of a mean over the bin, and the model error
        // in proportion to the recent forecast's RMS (the last estimations', decaying).
        self.recent_energy *= (-self.bin / DYNAMICS_TIME).exp();
        let var = (self.s.force_noise.powi(2) / self.bin_ticks as f64).max(self.residual_var)
            + self.s.model_error.powi(2) * self.recent_energy;
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
        // FC-2b: a shift that lowers κ below the prior shift's κ stands only if it fits better
        // by `SHIFT_SIGNIFICANCE` in units of the bin's variance. At a push's onset, a forecast
        // still too small to be seen lets a shift that brings its later, larger part into the
        // window "explain" a flat measurement with κ ≈ 0, a fit the noise picks. A shift that
        // raises κ (the push found where the forecast put none: an early or a late forecast) is
        // its own evidence. FC-2c: nor does a shift that would contradict the forecast (κ below
        // κ₀ by more than the contradiction threshold) stand where the prior shift sees no
        // forecast to judge (κ's posterior there looser than `EVIDENCE_SD`; its own κ is then
        // the noise's): before a push's onset such a shift holds only the forecast's future,
        // and a slow drift of the measured force (the arm and the door settling as the robot
        // leans), which the bins' variance from successive differences does not count, passes
        // the test above.
        let prior_mi = ((t0 / self.bin).round() + m as f64).clamp(0.0, (2 * m) as f64) as usize;
        let [prior_kappa, prior_h, prior_energy] = self.fits[prior_mi];
        let blind = var >= EVIDENCE_SD.powi(2) * prior_h;
        let held = (best.2 < prior_kappa
            && self.costs[prior_mi] - best.0 < SHIFT_SIGNIFICANCE * var)
            || (blind && best.2 < k0 - self.s.contradiction);
        if held {
            best = (self.costs[prior_mi], prior_mi, prior_kappa);
            evidence_at_best = prior_h;
            energy_at_best = prior_energy;
        }
        let (_, mi, kappa) = best;
        ShiftFit {
            mi,
            kappa,
            var,
            evidence: evidence_at_best,
            energy: energy_at_best,
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

    /// The corrected hand force over the horizon (FC-4): `out[i]` for t + (i + 1) `period`;
    /// and in `measured_only[i]` (as long as `out`) the same horizon as the measurement alone
    /// predicts it (FC-5's measurement model, FC-4 with f_fc ≡ 0: what C1 previews without a
    /// forecaster). `easing_believed` (x, y; in [0, 1]): how far a sample where the forecast
    /// eases the push measured now below the measurement's prediction is kept from FC-5's hedge
    /// (FC-5b, `viability::easing_believed`; zero: FC-5 alone).
    pub fn fill(
        &mut self,
        t: f64,
        period: f64,
        window: &ForecastWindow,
        out: &mut [V3],
        measured_only: &mut [V3],
        easing_believed: [f64; 2],
    ) {
        let e = self.est;
        let push = self.last_push;
        let mut believed = [0.0; 2];
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
        for (f, m_i) in out.iter_mut().zip(measured_only.iter_mut()) {
            w *= decay;
            r *= ramp;
            let ahead = t_o + t_r * (1.0 - r);
            let u = unexplained(&e.offset, &e.trend, ahead, w);
            let p = self.scaled(f);
            *f = [0, 1, 2].map(|c| p[c] + u[c]);
            let m = unexplained(&self.offset_meas, &self.trend_meas, ahead, w);
            *m_i = m;
            if e.weight < 1.0 {
                // FC-5: toward measurement only as the forecast's record falls; FC-5b: but not
                // an easing of the measured push (f below m along it) where only its easing
                // can save the robot.
                let mut weight = [e.weight; 3];
                for c in 0..2 {
                    if easing_believed[c] > 0.0 && (f[c] - m[c]) * push[c] < 0.0 {
                        weight[c] += (1.0 - e.weight) * easing_believed[c];
                        believed[c] = easing_believed[c];
                    }
                }
                *f = [0, 1, 2].map(|c| f[c] + (1.0 - weight[c]) * (m[c] - f[c]));
            }
            // Never a force that lifts the robot (a tipping robot's hand, a biased sensor).
            let over = f[2] > self.lift_cap;
            capped |= over;
            if over {
                f[2] = self.lift_cap;
            }
        }
        self.est.easing_believed = believed;
        if believed != [0.0; 2] {
            self.counts.easing_believed_time += self.dt;
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

/// `[controller.forecast_correction]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectionSettings {
    /// Correct the forecast (C1, C2); off: the forecast as received.
    pub enabled: bool,
    /// Length W of the estimation window (s).
    pub window: f64,
    /// Largest |τ| searched (s).
    pub max_shift: f64,
    /// σ: standard deviation of one measured force sample (N), the estimation's noise model.
    pub force_noise: f64,
    /// σ_v (m/s): the hand's velocity error while the base is estimated (its filter's velocity
    /// error, which the hand inherits); a measured base's is taken as exact. Sets FC-1c's K.
    pub hand_velocity_noise: f64,
    /// ε: the part of the force no amplitude and shift explain (the door's and the arm's own
    /// dynamics), relative to the forecast's RMS over the window; adds (ε·RMS)² to a bin's
    /// variance.
    pub model_error: f64,
    /// A window whose forecast RMS (at τ̂) is below this (N) never becomes the estimator's
    /// memory: the tail of a push says little about its amplitude.
    pub min_force: f64,
    /// σ_κ: how far κ may plausibly be from its prior mean (1, or the last estimate).
    pub factor_sd: f64,
    /// σ_τ: how far τ may plausibly be from its prior mean (0, or the last estimate), s.
    pub shift_sd: f64,
    /// σ_b: how far the window's offset may be from the offset observer's estimate (N).
    pub offset_sd: f64,
    /// Bounds of κ̂.
    pub factor_bounds: [f64; 2],
    /// Time constant (s) with which the priors return to κ = 1, τ = 0 without evidence.
    pub forget: f64,
    /// Time constant T_o of the offset observer (s).
    pub offset_time_constant: f64,
    /// Time constant T_d of the offset's decay over the horizon (s).
    pub offset_decay: f64,
    /// Length (s) of the window of the trend fit: a line through the last bins of what the
    /// forecast leaves unexplained (FC-3b).
    pub trend_window: f64,
    /// T_r (s): how far ahead the unexplained force's trend is extrapolated before it levels
    /// off (FC-4); 0 turns the trend off.
    pub trend_horizon: f64,
    /// |κ̂ − 1| beyond this, with the window's evidence, is a contradicted forecast.
    pub contradiction: f64,
    /// The corrected horizon's upward force is capped at this fraction of the robot's weight
    /// M g: the hand force of a robot tipping over (or a biased sensor) must not preview as a
    /// force lifting it (eq. (10) needs M g − F_z > 0), which the forecast intake refuses too.
    pub max_lift: f64,
    /// FC-5: the memory (s) of the forecast's and the measurement's prediction errors from which
    /// the forecast's weight is judged; 0 always believes the corrected forecast (w = 1).
    pub skill_time: f64,
}

impl Default for CorrectionSettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for CorrectionSettings {
    const TABLE: &'static str = "forecast_correction";

    fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, v) in [
            ("window", self.window),
            ("force_noise", self.force_noise),
            ("model_error", self.model_error),
            ("min_force", self.min_force),
            ("factor_sd", self.factor_sd),
            ("shift_sd", self.shift_sd),
            ("offset_sd", self.offset_sd),
            ("forget", self.forget),
            ("offset_time_constant", self.offset_time_constant),
            ("offset_decay", self.offset_decay),
            ("trend_window", self.trend_window),
            ("contradiction", self.contradiction),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((key, format!("must be finite and > 0, got {v}")));
            }
        }
        for (key, v) in [
            ("max_shift", self.max_shift),
            ("trend_horizon", self.trend_horizon),
            ("skill_time", self.skill_time),
            ("hand_velocity_noise", self.hand_velocity_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((key, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if !(self.max_lift > 0.0 && self.max_lift < 1.0) {
            return Err((
                "max_lift",
                format!("must be in (0, 1), got {}", self.max_lift),
            ));
        }
        let [lo, hi] = self.factor_bounds;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) {
            return Err(("factor_bounds", format!("need 0 ≤ lo < hi, got {lo}, {hi}")));
        }
        Ok(())
    }
}

/// One shift search's outcome: the best candidate, its κ̂, the bin variance it was judged
/// with, its posterior curvature (evidence) and the window's forecast energy there.
struct ShiftFit {
    mi: usize,
    kappa: f64,
    var: f64,
    evidence: f64,
    energy: f64,
}

/// The forecast correction as a controller part (C1, C2 with `enabled`; inactive otherwise):
/// it fills the horizon's hand force from the forecast and the measured force.
pub struct Correction {
    corrector: Option<ForecastCorrector>,
    /// FC-5b, with the capture-point guard on: the cart-table's capture point (VG-1) and the
    /// guard's `band`.
    easing: Option<(CapturePoint, f64)>,
    /// The hand force the whole-body QP is given: when it is the corrected force, its
    /// door-inertia term closes a loop through the hand's acceleration, which a lag of K bins
    /// destabilises (FC-1c: K = 1).
    qp_force: HandForceSource,
}

/// This part in `super::parts::PIPELINE`.
pub const PART: PartEntry = PartEntry::new::<CorrectionSettings>(build);

fn build(
    s: &PartSetup,
) -> Result<Box<dyn ControllerPart>, Box<dyn std::error::Error + Send + Sync>> {
    let settings: CorrectionSettings = s.config.controller.parts.get()?;
    let p = &s.config.preview;
    let corrector = (settings.enabled && s.kind != ControllerKind::C0)
        .then(|| ForecastCorrector::new(settings, p.period, s.dt, s.cart.mass * s.cart.gravity));
    let qp_force = s.config.controller.hand_force_feedback_from;
    let guard: ViabilitySettings = s.config.controller.parts.get()?;
    let c = s.cart;
    let easing = guard.enabled.then(|| {
        (
            CapturePoint::new(c.mass, c.gravity, c.com_height),
            guard.band,
        )
    });
    Ok(Box::new(Correction {
        corrector,
        easing,
        qp_force,
    }))
}

impl Correction {
    pub fn corrector(&self) -> Option<&ForecastCorrector> {
        self.corrector.as_ref()
    }
}

impl ControllerPart for Correction {
    fn name(&self) -> &'static str {
        "forecast_correction"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Forecast]
    }

    fn reset(&mut self) {
        if let Some(c) = self.corrector.as_mut() {
            c.reset();
        }
    }

    fn update(
        &mut self,
        _: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let Some(c) = self.corrector.as_mut() else {
            return Ok(());
        };
        c.set_measurement_lag(frame.hand_force_lag);
        let fed_back = self
            .qp_force
            .resolve(frame.hand_force_estimated)
            .from_correction();
        c.set_velocity_noise(match frame.estimate_base && !fed_back {
            true => c.settings().hand_velocity_noise,
            false => 0.0,
        });
        c.update(
            frame.t,
            inputs.forecast,
            Some(frame.hand_force),
            frame.hand_vel,
        );
        let push = c.measured_push();
        let believed = self.easing.map_or([0.0; 2], |(capture, band)| {
            let (com, vcom) = (frame.com, frame.com_vel);
            easing_believed(
                &capture,
                [com[0], com[1]],
                [vcom[0], vcom[1]],
                frame.support,
                push,
                band,
            )
        });
        c.fill(
            frame.t,
            frame.period,
            inputs.forecast,
            &mut frame.f_ext,
            &mut frame.f_measured_only,
            believed,
        );
        frame.f_ext_filled = true;
        frame.measured_push = Some(push);
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        let e = self
            .corrector
            .as_ref()
            .map(|c| *c.estimate())
            .unwrap_or_default();
        out.put(
            col!(fixed("corr_factor", 4).plot("correction/factor")),
            e.factor,
        );
        out.put(
            col!(fixed("corr_shift", 4).plot("correction/shift")),
            e.shift,
        );
        out.put(
            col!(fixed("corr_offset_x", 3).plot("correction/offset_x")),
            e.offset[0],
        );
        out.put(col!(fixed("corr_offset_y", 3)), e.offset[1]);
        out.put(col!(fixed("corr_offset_z", 3)), e.offset[2]);
        out.flag(
            col!(plain("corr_contradicted").plot("correction/contradicted")),
            e.contradicted,
        );
        out.put(
            col!(fixed("corr_trend_x", 2).plot("correction/trend_x")),
            e.trend[0],
        );
        out.put(col!(fixed("corr_trend_y", 2)), e.trend[1]);
        out.put(
            col!(fixed("corr_weight", 4).plot("correction/weight")),
            e.weight,
        );
        out.put(
            col!(fixed("corr_error_forecast", 3).plot("correction/error_forecast")),
            e.error_forecast,
        );
        out.put(
            col!(fixed("corr_error_measured", 3).plot("correction/error_measured")),
            e.error_measured,
        );
        out.put(
            col!(fixed("corr_easing_believed_x", 3).plot("correction/easing_believed_x")),
            e.easing_believed[0],
        );
        out.put(
            col!(fixed("corr_easing_believed_y", 3)),
            e.easing_believed[1],
        );
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        if let Some(c) = &self.corrector {
            let s = CorrectionSummary::of(c.counts, c.estimate());
            out.insert("forecast_correction".into(), serde_json::json!(s));
        }
    }

    fn held_object(&mut self, apparent_mass: &[[f64; 3]; 3]) {
        self.corrector = self
            .corrector
            .take()
            .map(|c| c.with_held_mass(*apparent_mass));
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// What the forecast correction did over a run.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct CorrectionSummary {
    /// Times the measured hand force contradicted the forecast, and the plant time it did.
    pub contradictions: u64,
    pub contradicted_time: f64,
    /// κ̂: smallest, largest and last; τ̂ last (s); d̂ last (N).
    pub factor_min: f64,
    pub factor_max: f64,
    pub factor_last: f64,
    pub shift_last: f64,
    pub offset_last: [f64; 3],
    /// Estimations of κ̂, τ̂; ticks whose measured force was not finite.
    pub estimations: u64,
    pub bad_measurements: u64,
    /// Ticks whose corrected horizon was capped at `max_lift` M g upward.
    #[serde(default)]
    pub lift_capped: u64,
    /// FC-5: the forecast's smallest weight against measurement only, times it was
    /// discounted (weight below 0.5) and the plant time it stayed so (s).
    pub weight_min: f64,
    pub discounts: u64,
    pub discounted_time: f64,
    /// FC-5b: plant time (s) an easing of the measured push was kept from FC-5's hedge.
    pub easing_believed_time: f64,
    /// Gaps in plant time across which no hand acceleration was taken.
    #[serde(default)]
    pub time_gaps: u64,
}

impl CorrectionSummary {
    /// From the corrector's counters and its last estimate.
    pub fn of(c: CorrectionCounts, e: &CorrectionEstimate) -> Self {
        Self {
            contradictions: c.contradictions,
            contradicted_time: c.contradicted_time,
            factor_min: c.factor_min,
            factor_max: c.factor_max,
            factor_last: e.factor,
            shift_last: e.shift,
            offset_last: e.offset,
            estimations: c.estimations,
            bad_measurements: c.bad_measurements,
            lift_capped: c.lift_capped,
            weight_min: c.weight_min,
            discounts: c.discounts,
            discounted_time: c.discounted_time,
            easing_believed_time: c.easing_believed_time,
            time_gaps: c.time_gaps,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::ForecastMsg;

    /// A 1 s raised-cosine impact of `a` N along −x starting at `start`.
    fn impact(t: f64, start: f64, a: f64) -> V3 {
        let x = t - start;
        if !(0.0..1.0).contains(&x) {
            return [0.0; 3];
        }
        [
            -a * 0.5 * (1.0 - (2.0 * std::f64::consts::PI * x).cos()),
            0.0,
            0.0,
        ]
    }

    /// Deterministic Gaussian noise (Box–Muller over a xorshift).
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn gauss(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// A forecaster as `upc forecast` publishes: every 100 ticks, 400 samples of 5 ms of `f`
    /// from now.
    struct Forecaster {
        window: ForecastWindow,
        msg: Box<ForecastMsg>,
    }

    impl Forecaster {
        fn new() -> Self {
            Self {
                window: ForecastWindow::new(1.0, 1.0, 0.2, 1e4),
                msg: Box::default(),
            }
        }

        fn tick(&mut self, k: usize, t: f64, f: impl Fn(f64) -> V3) {
            if !k.is_multiple_of(100) {
                return;
            }
            let msg = &mut self.msg;
            msg.seq += 1;
            (msg.t0, msg.dt, msg.len, msg.period) = (t, 0.005, 400, 0.1);
            for i in 0..400 {
                msg.forces[i] = f(t + i as f64 * 0.005);
            }
            self.window.offer(msg, t).unwrap();
        }
    }

    struct Run {
        kappa_at_200ms: f64,
        tau_at_200ms: f64,
        /// First time after onset from which κ̂ stays within 10 % of the truth until 0.5 s.
        settled_after: Option<f64>,
        contradictions: u64,
        forecast_at_peak: f64,
    }

    /// The forecaster publishes `scale × F(t − shift)` every 0.1 s (windows of 2 s at 5 ms, as
    /// upc's); the hand measures F + bias + noise at 1 kHz.
    fn run(scale: f64, shift: f64, bias: f64, sigma: f64, seed: u64, phantom: bool) -> Run {
        run_lagged(scale, shift, bias, sigma, seed, phantom, 0.0, 0.0)
    }

    /// [`run`] with the measurement lagging the push through two first-order stages of
    /// `lag / 2` each (mean delay `lag`, as WO-5's estimate), `declared` of it told the
    /// correction (FC-1b).
    #[allow(clippy::too_many_arguments)]
    fn run_lagged(
        scale: f64,
        shift: f64,
        bias: f64,
        sigma: f64,
        seed: u64,
        phantom: bool,
        lag: f64,
        declared: f64,
    ) -> Run {
        let dt = 1e-3;
        let start = 1.0;
        let amp = 60.0;
        let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, dt, 300.0);
        let mut fc = Forecaster::new();
        let mut noise = Noise(seed);
        let mut out = vec![[0.0; 3]; 300];
        let (mut k200, mut t200) = (f64::NAN, f64::NAN);
        let mut settled_after = None;
        let truth = 1.0 / scale;
        let mut forecast_at_peak = f64::NAN;
        let mut stages = [[0.0; 3]; 2];
        for k in 0..2000 {
            let t = k as f64 * dt;
            fc.tick(k, t, |s| impact(s - shift, start, amp).map(|v| v * scale));
            let window = &fc.window;
            let real = if phantom {
                [0.0; 3]
            } else {
                impact(t, start, amp)
            };
            let a = if lag > 0.0 {
                1.0 - (-dt / (0.5 * lag)).exp()
            } else {
                1.0
            };
            for c in 0..3 {
                stages[0][c] += a * (real[c] - stages[0][c]);
                stages[1][c] += a * (stages[0][c] - stages[1][c]);
            }
            let y = [0, 1, 2].map(|c| stages[1][c] + bias + sigma * noise.gauss());
            corr.set_measurement_lag(declared);
            corr.update(t, window, Some(y), [0.0; 3]);
            corr.fill(t, 0.005, window, &mut out, &mut [[0.0; 3]; 300], [0.0; 2]);
            let e = *corr.estimate();
            let onset = start;
            if (t - (onset + 0.2)).abs() < 0.5 * dt {
                k200 = e.factor;
                t200 = e.shift;
            }
            if t > onset && t < start + 0.5 {
                let ok = (e.factor - truth).abs() <= 0.1 * truth.max(0.1);
                match (ok, settled_after) {
                    (true, None) => settled_after = Some(t - onset),
                    (false, Some(_)) => settled_after = None,
                    _ => {}
                }
            }
            // What the horizon says 0.1 s before the real peak at start + 0.5 s.
            if (t - (start + 0.4)).abs() < 0.5 * dt {
                forecast_at_peak = out[19][0];
            }
        }
        Run {
            kappa_at_200ms: k200,
            tau_at_200ms: t200,
            settled_after,
            contradictions: corr.counts.contradictions,
            forecast_at_peak,
        }
    }

    #[test]
    fn an_exact_forecast_is_left_as_it_is() {
        let r = run(1.0, 0.0, 0.0, 0.0, 1, false);
        assert!(
            (r.kappa_at_200ms - 1.0).abs() < 1e-3,
            "{}",
            r.kappa_at_200ms
        );
        assert!(r.tau_at_200ms.abs() < 1e-3, "{}", r.tau_at_200ms);
        assert_eq!(r.contradictions, 0);
        assert!(
            (r.forecast_at_peak + 60.0).abs() < 0.5,
            "{}",
            r.forecast_at_peak
        );
    }

    /// An estimated hand force lagging the push by 20 ms (WO-5 at K = K₂ = 100/s) against an
    /// exact forecast: told the lag, the correction finds the forecast on time (|τ̂| < 5 ms at
    /// 200 ms) and κ̂ settles within 10 % of 1 by 300 ms; not told, it reads the lag as a push
    /// 10 ms late or more, and would preview every push that much late.
    #[test]
    fn a_lagging_estimate_is_not_read_as_a_late_push() {
        for seed in [3, 17] {
            let told = run_lagged(1.0, 0.0, 0.0, 2.0, seed, false, 0.02, 0.02);
            assert!(told.tau_at_200ms.abs() < 0.005, "τ̂ {}", told.tau_at_200ms);
            let settled = told.settled_after.unwrap_or(f64::INFINITY);
            assert!(settled <= 0.3, "κ̂ settled after {settled} s");
            let untold = run_lagged(1.0, 0.0, 0.0, 2.0, seed, false, 0.02, 0.0);
            assert!(untold.tau_at_200ms > 0.01, "τ̂ {}", untold.tau_at_200ms);
        }
    }

    /// FC-2c, the blind prior shift: before an exact forecast's push, the measured force drifts
    /// by −2 N over 0.4 s (the arm and the door settling as the robot leans into the coming
    /// push) with little noise. A shift that brings the forecast's future into the window fits
    /// the drift with κ ≈ 0; the prior shift sees no forecast yet, so that shift must not stand:
    /// no contradiction, and κ̂ back at 1 once the push shows.
    #[test]
    fn a_drift_before_the_push_does_not_contradict_the_forecast() {
        let (dt, start, amp) = (1e-3, 1.0, 60.0);
        for seed in [3, 17, 99] {
            let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, dt, 300.0);
            let mut fc = Forecaster::new();
            let mut noise = Noise(seed);
            let mut lowest = f64::INFINITY;
            for k in 0..1300 {
                let t = k as f64 * dt;
                fc.tick(k, t, |s| impact(s, start, amp));
                let drift = -2.0 * ((t - 0.6) / 0.4).clamp(0.0, 1.0);
                let real = impact(t, start, amp);
                let y = [real[0] + drift + 0.3 * noise.gauss(), real[1], real[2]];
                corr.update(t, &fc.window, Some(y), [0.0; 3]);
                if t >= start + 0.1 {
                    lowest = lowest.min(corr.estimate().factor);
                }
            }
            assert_eq!(corr.counts.contradictions, 0, "seed {seed}");
            assert!(
                lowest > 0.8,
                "seed {seed}: κ̂ fell to {lowest} during the push"
            );
        }
    }

    /// The goal: κ within 10 % of the truth within 200 ms of contact onset, with
    /// σ = 2 N noise and a 5 N bias on the measured force; τ within a bin and a half.
    #[test]
    fn factor_and_shift_are_recovered_under_noise_and_bias() {
        for (scale, shift) in [
            (1.5, 0.0),
            (0.5, 0.0),
            (0.75, 0.15),
            (1.25, -0.15),
            (1.0, 0.3),
            (1.0, -0.3),
            (2.0, 0.0),
        ] {
            for seed in [3, 17, 99] {
                let r = run(scale, shift, 5.0, 2.0, seed, false);
                let truth = 1.0 / scale;
                let at = r.settled_after.unwrap_or(f64::INFINITY);
                eprintln!(
                    "scale {scale} shift {shift:+}: κ̂ {:.3} (truth {truth:.3}), τ̂ {:+.3} (truth {:+}), within 10 % after {:.0} ms",
                    r.kappa_at_200ms,
                    r.tau_at_200ms,
                    -shift,
                    at * 1e3
                );
                // Within 200 ms for |shift| ≤ 150 ms (the goal's range); a forecast 300 ms early
                // looks like a phantom for its first 300 ms and takes longer.
                let bound = if shift < -0.2 { 0.3 } else { 0.2 };
                assert!(at <= bound, "scale {scale} shift {shift} seed {seed}: {at}");
                assert!(
                    shift < -0.2 || (r.tau_at_200ms + shift).abs() <= 0.0075,
                    "scale {scale} shift {shift} seed {seed}: τ̂ {}",
                    r.tau_at_200ms
                );
            }
        }
    }

    /// The hand held by an impedance (M_h ẍ = f − K x − C ẋ) on a door of apparent mass Λ
    /// pushed by F: the sensor measures f = F − Λ ẍ. Returns the largest |κ̂ − κ| and |τ̂| from
    /// 0.2 s after the push's onset to its end, with the correction told Λ (`known`) or not.
    fn run_on_door(scale: f64, known: bool) -> (f64, f64) {
        let (dt, start, amp) = (1e-3, 1.0, 60.0);
        let (m_h, lambda) = (1.5, 5.1);
        let (k, c) = (600.0 * m_h, 2.0 * 600f64.sqrt() * m_h);
        let mut held = [[0.0; 3]; 3];
        held[0][0] = lambda;
        let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, dt, 300.0);
        if known {
            corr = corr.with_held_mass(held);
        }
        let mut fc = Forecaster::new();
        let (mut x, mut v) = (0.0, 0.0);
        let (mut worst_k, mut worst_t) = (0.0f64, 0.0f64);
        for step in 0..2200 {
            let t = step as f64 * dt;
            fc.tick(step, t, |s| impact(s, start, amp).map(|f| f * scale));
            // Semi-implicit Euler of (M_h + Λ) ẍ = F − K x − C ẋ; the sensor between hand and door.
            let push = impact(t, start, amp)[0];
            let acc = (push - k * x - c * v) / (m_h + lambda);
            let measured = push - lambda * acc;
            v += acc * dt;
            x += v * dt;
            corr.update(t, &fc.window, Some([measured, 0.0, 0.0]), [v, 0.0, 0.0]);
            if t >= start + 0.2 && t < start + 1.0 {
                let e = corr.estimate();
                worst_k = worst_k.max((e.factor - 1.0 / scale).abs());
                worst_t = worst_t.max(e.shift.abs());
            }
        }
        (worst_k, worst_t)
    }

    /// The door's inertia is no forecast error once the correction knows it (FC-1): an exact
    /// forecast stays exact through the push, and a ×1.5 one is read as such. Without Λ the
    /// same push reads as a late and too strong forecast (what C2 lost its margin to).
    #[test]
    fn the_held_doors_inertia_is_not_read_as_a_forecast_error() {
        for (scale, known) in [(1.0, true), (1.0, false), (1.5, true), (1.5, false)] {
            let (dk, dt) = run_on_door(scale, known);
            eprintln!(
                "×{scale}, Λ known {known}: max |κ̂ − κ| {dk:.3}, max |τ̂| {:.1} ms",
                dt * 1e3
            );
        }
        let (dk, dt) = run_on_door(1.0, true);
        assert!(
            dk < 0.03 && dt < 0.004,
            "known Λ: |κ̂ − 1| {dk:.3}, |τ̂| {dt:.4} s"
        );
        let (dk, dt) = run_on_door(1.0, false);
        assert!(
            dk > 0.1 && dt > 0.02,
            "unknown Λ: |κ̂ − 1| {dk:.3}, |τ̂| {dt:.4} s"
        );
        let (dk, _) = run_on_door(1.5, true);
        assert!(dk < 0.05, "×1.5 with known Λ: |κ̂ − 2/3| {dk:.3}");
    }

    /// FC-1c's K: the fewest bins for the noise, no more than the force's lag allows.
    #[test]
    fn the_acceleration_is_differenced_over_the_bins_the_noise_needs_and_the_lag_allows() {
        // m √2 σ_v / (T_b σ_f) = 5.1 √2 0.005 / (0.005 · 2) = 3.6; 2 δ / T_b = 4.
        let k = |v, lag| acceleration_bins(5.1, v, 0.005, 2.0, lag);
        assert_eq!(k(0.005, 0.010), 4);
        assert_eq!(k(0.0, 0.010), 1, "exact velocities");
        assert_eq!(k(0.005, 0.0), 1, "a wrist sensor's force does not lag");
        assert_eq!(k(0.005, 0.0075), 3, "the lag bounds it");
        assert_eq!(k(0.002, 0.010), 2, "the noise bounds it");
        assert_eq!(k(0.1, 1.0), MAX_ACCELERATION_BINS);
        assert_eq!(k(f64::NAN, 0.010), 1);
        assert_eq!(acceleration_bins(5.1, 0.005, 0.005, 0.0, 0.010), 4);
        assert_eq!(
            acceleration_bins(0.0, 0.005, 0.005, 2.0, 0.010),
            1,
            "nothing held"
        );
    }

    /// FC-1c on a door at rest read through an estimated base's velocity (an error of σ_v =
    /// 5 mm/s, constant over each bin and independent between bins, the model's): through Λ the
    /// one-bin difference puts m √2 σ_v / T_b = 7.2 N of noise on the push; with the K = 4 that
    /// a force lagging 10 ms allows, 1.8 N, within the force sensor's σ_f = 2 N.
    #[test]
    fn an_estimated_velocitys_noise_stays_out_of_the_push() {
        let rms = |lag: f64| {
            let mut held = [[0.0; 3]; 3];
            held[0][0] = 5.1;
            let settings = CorrectionSettings::default();
            let mut corr =
                ForecastCorrector::new(settings, 0.005, 1e-3, 300.0).with_held_mass(held);
            corr.set_measurement_lag(lag);
            corr.set_velocity_noise(0.005);
            let (fc, mut noise, mut err) = (Forecaster::new(), Noise(7), Vec::new());
            let mut v = 0.0;
            for step in 0..3000 {
                if step % 5 == 0 {
                    v = 0.005 * noise.gauss();
                }
                corr.update(
                    step as f64 * 1e-3,
                    &fc.window,
                    Some([0.0; 3]),
                    [v, 0.0, 0.0],
                );
                if step >= 100 && step % 5 == 4 {
                    err.push(corr.measured_push()[0]);
                }
            }
            let k = corr.acceleration_window_bins();
            (
                k,
                (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt(),
            )
        };
        let (k1, one) = rms(0.0);
        let (k4, four) = rms(0.010);
        eprintln!("K = {k1}: {one:.2} N, K = {k4}: {four:.2} N");
        assert_eq!((k1, k4), (1, 4));
        assert!(
            (one - 7.2).abs() < 0.7,
            "K = 1: {one:.2} N (7.2 N expected)"
        );
        assert!(
            (four - 1.8).abs() < 0.3 && four < 2.0,
            "K = 4: {four:.2} N (1.8 N expected)"
        );
    }

    /// FC-1c across a stalled controller: the hand accelerating steadily at 2 m/s² and the
    /// ticks resuming 50 ms later. A difference across the gap would take its 70 ms for K = 4
    /// bins' 20 ms and read 3.5 a (the push 25 N off, where Λ a is 10.2 N); the history restarts
    /// instead, so the push errs by at most Λ a while it refills, and the gap is counted.
    #[test]
    fn no_acceleration_is_taken_across_a_gap_in_time() {
        let (a, dt) = (2.0, 1e-3);
        let mut held = [[0.0; 3]; 3];
        held[0][0] = 5.1;
        let settings = CorrectionSettings::default();
        let mut corr = ForecastCorrector::new(settings, 0.005, dt, 300.0).with_held_mass(held);
        corr.set_measurement_lag(0.010);
        corr.set_velocity_noise(0.005);
        let fc = Forecaster::new();
        let mut worst = 0.0f64;
        for step in (0..400).chain(450..800) {
            let t = step as f64 * dt;
            // The door takes Λ a from the hand: the sensor reads −Λ a, the push is zero.
            corr.update(t, &fc.window, Some([-5.1 * a, 0.0, 0.0]), [a * t, 0.0, 0.0]);
            if step >= 100 {
                worst = worst.max(corr.measured_push()[0].abs());
            }
        }
        assert_eq!(corr.counts.time_gaps, 1);
        assert!(worst <= 5.1 * a + 1e-6, "push {worst:.2} N across the gap");
    }

    #[test]
    fn a_phantom_push_is_refused() {
        let r = run(1.0, 0.0, 5.0, 2.0, 5, true);
        assert!(r.kappa_at_200ms < 0.1, "{}", r.kappa_at_200ms);
        assert_eq!(r.contradictions, 1);
        // 0.1 s before the phantom's peak the horizon no longer forecasts its force.
        assert!(r.forecast_at_peak.abs() < 10.0, "{}", r.forecast_at_peak);
    }

    #[test]
    fn without_a_forecast_the_measurement_is_held_and_decays() {
        let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, 1e-3, 300.0);
        let window = ForecastWindow::new(1.0, 1.0, 0.2, 1e4);
        for k in 0..500 {
            corr.update(k as f64 * 1e-3, &window, Some([-20.0, 4.0, 0.0]), [0.0; 3]);
        }
        let mut out = vec![[0.0; 3]; 300];
        corr.fill(
            0.5,
            0.005,
            &window,
            &mut out,
            &mut [[0.0; 3]; 300],
            [0.0; 2],
        );
        let t_d = CorrectionSettings::default().offset_decay;
        assert!(
            (out[0][0] + 20.0 * (-0.005f64 / t_d).exp()).abs() < 1e-3,
            "{:?}",
            out[0]
        );
        let s = 0.3;
        assert!(
            (out[59][1] - 4.0 * (-s / t_d).exp()).abs() < 1e-3,
            "{:?}",
            out[59]
        );
        assert_eq!(corr.counts.lift_capped, 0);
    }

    /// Without a forecast, a growing measured push is extrapolated along its trend (FC-3b, FC-4).
    /// A ramp of 100 N/s under σ = 0.5 N reads as 100 ± 20 N/s, and the horizon 0.15 s ahead
    /// says more than the force now held and blended out; under σ = 2 N the 50 ms fit's slope is shrunk by twice its
    /// standard error (≈ 2 × 20 N/s) but keeps its sign; a steady force under σ = 2 N has
    /// (almost) no trend.
    #[test]
    fn without_a_forecast_a_growing_push_is_extrapolated() {
        let s = CorrectionSettings::default();
        let window = ForecastWindow::new(1.0, 1.0, 0.2, 1e4);
        let mut out = vec![[0.0; 3]; 300];
        for (rate, sigma, seed) in [(100.0, 0.5, 7), (100.0, 2.0, 7), (0.0, 2.0, 11)] {
            let mut corr = ForecastCorrector::new(s, 0.005, 1e-3, 300.0);
            let mut noise = Noise(seed);
            let mut f = 0.0;
            for k in 0..600 {
                let t = k as f64 * 1e-3;
                f = -10.0 - rate * (t - 0.3).max(0.0);
                corr.update(
                    t,
                    &window,
                    Some([f + sigma * noise.gauss(), 0.0, 0.0]),
                    [0.0; 3],
                );
            }
            corr.fill(
                0.6,
                0.005,
                &window,
                &mut out,
                &mut [[0.0; 3]; 300],
                [0.0; 2],
            );
            let trend = corr.estimate().trend[0];
            eprintln!(
                "rate {rate}, σ {sigma}: trend {trend:.1} N/s, now {f:.1} N, in 0.15 s {:.1} N",
                out[29][0]
            );
            match (rate > 0.0, sigma < 1.0) {
                (true, true) => {
                    assert!((trend + rate).abs() <= 20.0, "{trend}");
                    // Held and blended out it would be f e^{−0.15/T_d}.
                    let held = f * (-0.15 / s.offset_decay).exp();
                    assert!(out[29][0] < 1.1 * held, "{} against {held}", out[29][0]);
                }
                (true, false) => assert!((-rate..=-20.0).contains(&trend), "{trend}"),
                _ => assert!(trend.abs() <= 5.0, "{trend}"),
            }
        }
    }

    /// FC-5 on a 1 s, 60 N push measured with σ = 2 N noise and a 5 N bias: the weight of a
    /// forecast as long as the push stays at least 0.5 through it; one that forecasts the push
    /// twice as long (its end a second late) falls below 0.25 within 0.3 s of the real push's
    /// end, and both are back above 0.9 after 3 s of quiet. FC-4b: at the slow forecast's onset
    /// (κ̂ at its bound: the push rises 4× faster than forecast), the horizon previews at most
    /// the forecast's own peak plus (κ̂ − 1) times the level κ̂ was fitted on, not κ̂ × its peak.
    #[test]
    fn a_forecast_of_the_wrong_shape_loses_its_weight_and_regains_it() {
        let dt = 1e-3;
        let (start, amp) = (1.0, 60.0);
        // A raised cosine of `len` s.
        let push = |t: f64, len: f64| -> f64 {
            let x = (t - start) / len;
            if (0.0..1.0).contains(&x) {
                -amp * 0.5 * (1.0 - (2.0 * std::f64::consts::PI * x).cos())
            } else {
                0.0
            }
        };
        for len in [1.0, 2.0] {
            let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, dt, 300.0);
            let mut fc = Forecaster::new();
            let mut noise = Noise(5);
            let mut out = vec![[0.0; 3]; 300];
            let (mut w_push, mut w_after, mut peak_ahead) = (1.0f64, 1.0f64, 0.0f64);
            for k in 0..6000 {
                let t = k as f64 * dt;
                fc.tick(k, t, |s| [push(s, len), 0.0, 0.0]);
                let y = [push(t, 1.0) + 5.0 + 2.0 * noise.gauss(), 0.0, 0.0];
                corr.update(t, &fc.window, Some(y), [0.0; 3]);
                corr.fill(
                    t,
                    0.005,
                    &fc.window,
                    &mut out,
                    &mut [[0.0; 3]; 300],
                    [0.0; 2],
                );
                let w = corr.estimate().weight;
                if (start..start + 1.0).contains(&t) {
                    w_push = w_push.min(w);
                }
                if (start + 1.0..start + 1.3).contains(&t) {
                    w_after = w_after.min(w);
                }
                if (t - (start + 0.25)).abs() < 0.5 * dt {
                    peak_ahead = out.iter().map(|f| -f[0]).fold(0.0, f64::max);
                    eprintln!(
                        "len {len}: at +0.25 s κ̂ {:.2}, fitted on {:.1} N, previewed peak {peak_ahead:.1} N",
                        corr.estimate().factor,
                        corr.seen_level
                    );
                }
            }
            let e = *corr.estimate();
            eprintln!(
                "len {len}: weight ≥ {w_push:.2} in the push, ≥ {w_after:.2} after it, {:.2} at the end; {} discounts",
                e.weight, corr.counts.discounts
            );
            assert!(e.weight > 0.9, "{}", e.weight);
            if len == 1.0 {
                assert!(w_push >= 0.5, "{w_push}");
                assert_eq!(corr.counts.discounts, 0);
            } else {
                assert!(w_after < 0.25, "{w_after}");
                assert!(corr.counts.discounts >= 1);
                // The slow forecast's peak is 60 N; κ̂ × 60 N would be up to 180 N.
                assert!(peak_ahead < 110.0, "{peak_ahead}");
            }
        }
    }

    /// FC-5b: the forecast's weight at 0.5, the push measured now 80 N along −x, the forecast
    /// 120 N for 0.1 s and then none, the measurement's prediction 80 N decaying. Where the
    /// forecast eases below the measurement's prediction the horizon is FC-5's blend as far as
    /// the easing is not believed, and the forecast's own as far as it is; where it adds push
    /// (its first 0.1 s) it is the blend whatever is believed; y, whose easing is not believed,
    /// is the blend.
    #[test]
    fn an_easing_is_kept_from_the_hedge_as_far_as_it_is_believed() {
        let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, 1e-3, 300.0);
        let mut fc = Forecaster::new();
        fc.tick(0, 0.0, |s| [if s < 0.1 { -120.0 } else { 0.0 }, 0.0, 0.0]);
        corr.est.weight = 0.5;
        corr.offset_meas = [-80.0, 10.0, 0.0];
        corr.last_push = [-80.0, 10.0, 0.0];
        let (early, late) = (9, 39); // 50 ms and 200 ms ahead
        for believed in [0.0, 0.5, 1.0] {
            let (mut out, mut m) = (vec![[0.0; 3]; 60], vec![[0.0; 3]; 60]);
            corr.fill(0.0, 0.005, &fc.window, &mut out, &mut m, [believed, 0.0]);
            let w = 0.5 + 0.5 * believed;
            assert!(m[late][0] < -50.0, "{:?}", m[late]);
            assert!(
                (out[late][0] - (1.0 - w) * m[late][0]).abs() < 1e-9,
                "{believed}: {:?}",
                out[late]
            );
            assert!(
                (out[early][0] - 0.5 * (-120.0 + m[early][0])).abs() < 1e-9,
                "{:?}",
                out[early]
            );
            assert!(
                (out[late][1] - 0.5 * m[late][1]).abs() < 1e-9,
                "{:?}",
                out[late]
            );
            assert_eq!(corr.estimate().easing_believed, [believed, 0.0]);
        }
        corr.est.weight = 1.0;
        corr.fill(
            0.0,
            0.005,
            &fc.window,
            &mut [[0.0; 3]; 60],
            &mut [[0.0; 3]; 60],
            [1.0; 2],
        );
        assert_eq!(
            corr.estimate().easing_believed,
            [0.0; 2],
            "nothing hedged at w = 1"
        );
    }

    /// A robot tipping over pulls on its hand: a measured upward force beyond its weight must
    /// not preview as a force lifting it (eq. (10) needs M g − F_z > 0). The horizon is capped
    /// at `max_lift` M g, counted; the other axes are left alone.
    #[test]
    fn the_corrected_horizon_never_lifts_the_robot() {
        let weight = 300.0;
        let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, 1e-3, weight);
        let window = ForecastWindow::new(1.0, 1.0, 0.2, 1e4);
        for k in 0..500 {
            corr.update(
                k as f64 * 1e-3,
                &window,
                Some([-20.0, 0.0, 1.5 * weight]),
                [0.0; 3],
            );
        }
        let mut out = vec![[0.0; 3]; 300];
        corr.fill(
            0.5,
            0.005,
            &window,
            &mut out,
            &mut [[0.0; 3]; 300],
            [0.0; 2],
        );
        let cap = CorrectionSettings::default().max_lift * weight;
        assert!(out.iter().all(|f| f[2] <= cap), "{:?}", out[0]);
        assert_eq!(out[0][2], cap, "the measured lift, held, is capped");
        assert!(out[0][0] < -19.0, "{:?}", out[0]);
        assert_eq!(corr.counts.lift_capped, 1);
    }
}
