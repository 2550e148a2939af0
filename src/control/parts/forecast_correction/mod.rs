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
//! stays, and the capture-point guard keeps the easing from the hedge (FC-5b,
//! `super::viability::keep_easing`, from the two predictions and w this part leaves in the frame).
//!
//! The pieces: the estimator's state and its tick (here), the fit of κ, τ and the trend
//! ([`fit`]), the forecast's record against measurement only ([`track_record`], FC-5), the
//! horizon and its blend ([`blend`], FC-4, FC-5), the controller part ([`part`]) and its
//! settings ([`settings`]).
//!
//! Real-time: every buffer is allocated in [`ForecastCorrector::new`]; a tick is O(1) but one
//! tick in `bin_ticks`, which re-estimates κ and τ in O(window × shifts).

mod blend;
mod fit;
mod part;
mod settings;
#[cfg(test)]
mod tests;
mod track_record;

pub use part::{Correction, CorrectionSummary};
pub use settings::CorrectionSettings;

use crate::control::forecast_window::ForecastWindow;

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
    /// Gaps in plant time longer than two bins between ticks (a stalled controller), across
    /// which no hand acceleration was taken (FC-1c).
    pub time_gaps: u64,
    /// Ticks that followed a gap in the controller's own ticks (more than 2.5 periods: it
    /// stalled) or whose state the plant's drives held (its brace of a silent controller): the
    /// measurement around them is the stall's, not the push's, so κ̂ and τ̂ were kept as they
    /// were for a settling time and a window after (FC-2d).
    pub stalls: u64,
}

type V3 = [f64; 3];

/// Posterior standard deviation of κ below which an estimate becomes the next prior.
const EVIDENCE_SD: f64 = 0.1;
/// Time constant (s) of the model error's scale after a push: the door and the arm ring on.
const DYNAMICS_TIME: f64 = 0.5;
/// FC-2d: how long the measured push takes to settle after a stall (s): not only the wrench
/// observer's and the acceleration window's tens of ms but the robot's sag under the drives'
/// switch and its recovery, a tenth of a second and more.
const STALL_SETTLE: f64 = 0.2;
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
    /// FC-2d: no estimation of κ̂, τ̂ before this bin (a stall's window is not fitted).
    fit_from_bin: u64,
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
            fit_from_bin: 0,
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
        self.set_held_mass(held_mass);
        self
    }

    /// Λ for the ticks from now on (what the hand holds now).
    pub fn set_held_mass(&mut self, held_mass: [V3; 3]) {
        self.held_mass = held_mass;
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
        self.fit_from_bin = 0;
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

    /// FC-2d: a stall of the controller (a gap of more than 2.5 periods in its ticks: two
    /// states or more missed; one superseded state is a loaded machine's routine) or a
    /// state its plant held (the bus's brace of a silent controller) leaves a transient in the
    /// measured push — the drives' switch, the hand's lurch, an observer's step over the gap —
    /// that the fit can explain only by sliding the forecast's next push under it (measured: a
    /// 2–14 ms stall read as a push 340 ms early, κ̂ 0.16–0.31, and a fall). κ̂ and τ̂ stay as
    /// they were until the window holds no bin of the stall and its settling
    /// ([`STALL_SETTLE`]); the offset observer (FC-3) still takes the transient. A hold before
    /// the first estimate (the plant's start) has no estimate to protect.
    fn watch_for_stalls(&mut self, t: f64, held: bool) {
        let gap = self.last_t.is_finite() && t - self.last_t > 2.5 * self.dt;
        if gap || (held && self.counts.estimations > 0) {
            self.counts.stalls += 1;
            let settle = (STALL_SETTLE / self.bin).ceil() as u64;
            self.fit_from_bin = self.bins + settle + self.n_w as u64;
        }
    }

    /// One control tick at plant time `t` with the force measured at the hand (`None`: no
    /// measurement this tick) and the hand's measured velocity (world); `held`: the plant's
    /// drives, not this controller's torques, moved the robot up to this state. Updates the
    /// offset observer every tick and κ̂, τ̂ once a bin.
    pub fn update(
        &mut self,
        t: f64,
        window: &ForecastWindow,
        measured: Option<V3>,
        hand_vel: V3,
        held: bool,
    ) {
        self.watch_for_stalls(t, held);
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
        if let Some(e0) = self
            .last_residual
            .filter(|_| self.bins >= self.fit_from_bin)
        {
            let d2 = (0..3).map(|c| (e[c] - e0[c]).powi(2)).sum::<f64>() / 6.0;
            self.residual_var += (1.0 - (-self.bin / NOISE_TIME).exp()) * (d2 - self.residual_var);
        }
        self.last_residual = Some(e);
        if self.bins as usize >= self.n_w && self.bins >= self.fit_from_bin {
            self.estimate_factor_and_shift(window);
        }
        self.fit_trend(window);
        self.judge_forecast(window);
    }
}
