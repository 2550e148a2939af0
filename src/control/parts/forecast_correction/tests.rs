//! The correction against synthetic pushes, forecasts and measurements.

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
        corr.update(t, window, Some(y), [0.0; 3], false);
        corr.fill(
            t,
            0.005,
            window,
            &mut out,
            &mut [[0.0; 3]; 300],
            &mut [[0.0; 3]; 300],
        );
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
            corr.update(t, &fc.window, Some(y), [0.0; 3], false);
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
        corr.update(
            t,
            &fc.window,
            Some([measured, 0.0, 0.0]),
            [v, 0.0, 0.0],
            false,
        );
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
        let mut corr = ForecastCorrector::new(settings, 0.005, 1e-3, 300.0).with_held_mass(held);
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
                false,
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
        corr.update(
            t,
            &fc.window,
            Some([-5.1 * a, 0.0, 0.0]),
            [a * t, 0.0, 0.0],
            false,
        );
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
        corr.update(
            k as f64 * 1e-3,
            &window,
            Some([-20.0, 4.0, 0.0]),
            [0.0; 3],
            false,
        );
    }
    let mut out = vec![[0.0; 3]; 300];
    corr.fill(
        0.5,
        0.005,
        &window,
        &mut out,
        &mut [[0.0; 3]; 300],
        &mut [[0.0; 3]; 300],
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
                false,
            );
        }
        corr.fill(
            0.6,
            0.005,
            &window,
            &mut out,
            &mut [[0.0; 3]; 300],
            &mut [[0.0; 3]; 300],
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
            corr.update(t, &fc.window, Some(y), [0.0; 3], false);
            corr.fill(
                t,
                0.005,
                &fc.window,
                &mut out,
                &mut [[0.0; 3]; 300],
                &mut [[0.0; 3]; 300],
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

/// FC-5b on the correction's blend: the forecast's weight at 0.5, the push measured now 80 N
/// along −x, the forecast 120 N for 0.1 s and then none, the measurement's prediction 80 N
/// decaying. Where the forecast eases below the measurement's prediction the horizon is FC-5's
/// blend as far as the easing is not believed, and the forecast's own as far as it is; where it
/// adds push (its first 0.1 s) it is the blend whatever is believed; y, whose easing is not
/// believed, is the blend. The guard's [`keep_easing`] applies it to what [`fill`] leaves.
#[test]
fn an_easing_is_kept_from_the_hedge_as_far_as_it_is_believed() {
    use crate::control::parts::viability::keep_easing;
    let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, 1e-3, 300.0);
    let mut fc = Forecaster::new();
    fc.tick(0, 0.0, |s| [if s < 0.1 { -120.0 } else { 0.0 }, 0.0, 0.0]);
    corr.est.weight = 0.5;
    corr.offset_meas = [-80.0, 10.0, 0.0];
    corr.last_push = [-80.0, 10.0, 0.0];
    let (early, late) = (9, 39); // 50 ms and 200 ms ahead
    let push = corr.measured_push();
    for believed in [0.0, 0.5, 1.0] {
        let (mut out, mut m, mut f_fc) =
            (vec![[0.0; 3]; 60], vec![[0.0; 3]; 60], vec![[0.0; 3]; 60]);
        corr.fill(0.0, 0.005, &fc.window, &mut out, &mut m, &mut f_fc);
        let kept = keep_easing(&mut out, &f_fc, &m, push, 0.5, [believed, 0.0]);
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
        assert_eq!(kept, [believed, 0.0]);
    }
    let (mut out, mut m, mut f_fc) = ([[0.0; 3]; 60], [[0.0; 3]; 60], [[0.0; 3]; 60]);
    corr.est.weight = 1.0;
    corr.fill(0.0, 0.005, &fc.window, &mut out, &mut m, &mut f_fc);
    assert_eq!(
        keep_easing(&mut out, &f_fc, &m, push, 1.0, [1.0; 2]),
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
            false,
        );
    }
    let mut out = vec![[0.0; 3]; 300];
    corr.fill(
        0.5,
        0.005,
        &window,
        &mut out,
        &mut [[0.0; 3]; 300],
        &mut [[0.0; 3]; 300],
    );
    let cap = CorrectionSettings::default().max_lift * weight;
    assert!(out.iter().all(|f| f[2] <= cap), "{:?}", out[0]);
    assert_eq!(out[0][2], cap, "the measured lift, held, is capped");
    assert!(out[0][0] < -19.0, "{:?}", out[0]);
    assert_eq!(corr.counts.lift_capped, 1);
}

/// How a run meets the stall of [`a_stall_s_transient_is_not_read_as_the_push_come_early`].
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stall {
    /// No stall and no transient: the estimate's own course.
    None,
    /// 10 ms without ticks.
    Gap,
    /// Ticks go on, but the plant's drives had the robot (the held flag).
    Held,
}

/// An exact forecast of a 60 N push at 1 s; a stall at 0.60–0.61 s and its transient: the hand
/// pulled 12 N off as the drives were switched and the robot sagged, easing off over 0.15 s as
/// the controller takes it back (a transient of the observer's 30 ms alone does not move τ̂).
/// The largest |τ̂| after the stall, the smallest κ̂ in the push, the
/// contradictions and the stalls counted.
fn stall_run(stall: Stall) -> (f64, f64, u64, u64) {
    let (dt, start, amp) = (1e-3, 1.0, 60.0);
    let mut corr = ForecastCorrector::new(CorrectionSettings::default(), 0.005, dt, 300.0);
    let mut fc = Forecaster::new();
    let mut noise = Noise(7);
    let (mut worst_shift, mut lowest) = (0.0f64, f64::INFINITY);
    let stalled = |k: usize| (600..610).contains(&k);
    let bump = |t: f64| match t - 0.61 {
        x if x < 0.0 || stall == Stall::None => 0.0,
        x => -12.0 * (x / 0.02).min(1.0) * (-(x - 0.02).max(0.0) / 0.15).exp(),
    };
    for k in 0..1300 {
        if stalled(k) && stall == Stall::Gap {
            continue;
        }
        let t = k as f64 * dt;
        fc.tick(k, t, |s| impact(s, start, amp));
        let real = impact(t, start, amp);
        let y = [real[0] + bump(t) + 0.3 * noise.gauss(), real[1], real[2]];
        let held = stall == Stall::Held && stalled(k);
        corr.update(t, &fc.window, Some(y), [0.0; 3], held);
        if t > 0.61 {
            worst_shift = worst_shift.max(corr.estimate().shift.abs());
        }
        if t >= start + 0.1 {
            lowest = lowest.min(corr.estimate().factor);
        }
    }
    let c = corr.counts;
    (worst_shift, lowest, c.contradictions, c.stalls)
}

/// FC-2d: the controller stalls for 10 ms (no ticks; or its plant held the robot meanwhile), and
/// the measured push shows the stall's transient 0.39 s before an exact forecast's 60 N push.
/// Read as the forecast, that transient is the push come early (without FC-2d: τ̂ 0.35 s, the
/// search's edge; measured on the bus: −340 ms, κ̂ 0.16–0.31, and a fall). With it, the estimate
/// keeps the course it has without any stall, within 4 bins of τ̂ (the transient's tail left in
/// the window when the fit resumes: 13 ms here).
#[test]
fn a_stall_s_transient_is_not_read_as_the_push_come_early() {
    let (shift0, lowest0, contradictions0, stalls0) = stall_run(Stall::None);
    assert_eq!((contradictions0, stalls0), (0, 0));
    for stall in [Stall::Gap, Stall::Held] {
        let (shift, lowest, contradictions, stalls) = stall_run(stall);
        assert!(stalls >= 1, "{stall:?}");
        assert_eq!(contradictions, 0, "{stall:?}");
        assert!(
            shift <= shift0 + 0.02,
            "{stall:?}: τ̂ reached {shift} s, {shift0} s without a stall"
        );
        assert!(
            lowest >= lowest0 - 0.05,
            "{stall:?}: κ̂ fell to {lowest} in the push, {lowest0} without a stall"
        );
    }
}
