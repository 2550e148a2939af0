//! The capture-point guard on unconfirmed forecasts (docs/forecast_correction.md, VG-1, VG-2).
//!
//! C1 and C2 lean the robot into a forecast push before it arrives; nothing measured can say
//! before its onset that it will not come (a phantom). A lean is safe only as far as the robot
//! could stop if the forecast force never came: the capture point of the cart-table under the
//! force measured now,
//!
//!   ξ_m = x + ẋ/ω + F_now/(M ω²),  ω² = g/z_c,                                   (VG-1)
//!
//! must stay inside the support, where the ZMP can hold it (Pratt et al., capturability). The
//! part of the horizon's force not measured yet is faded as ξ_m comes within `margin` (a
//! fraction of the support's half-length) of an edge, over `band`:
//!
//!   f̂_i ← b_i + s (f̂_i − b_i),  s = clamp((d − margin)/band, 0, 1),                (VG-2)
//!
//! per horizontal axis and horizon sample where the forecast adds force along its own
//! direction (a push to come, not one forecast to ease): b_i the measured push if it acts along
//! f̂_i's direction, else zero; d the distance of ξ_m (a fraction of the half-length) to the
//! edge that push leans the robot toward (a push to come along −x is met by leaning toward +x,
//! which is what a phantom leaves the robot with). A push that arrives is measured, moves ξ_m
//! with it and lifts the fade at once; a phantom's lean stops where the robot can still stand
//! without it.
//!
//! A forecast that the measured push will ease is the same bet the other way (VG-3): the robot
//! eases off before the push does, and if it does not (a forecast that ends too early), the push
//! drives it toward the edge it leans against. An easing faster than the measurement alone
//! predicts (FC-5's measurement model: what C1 previews without a forecaster) is faded toward
//! that prediction as ξ_m comes within `ease_margin` of that edge, and believed again as ξ_m
//! passes beyond it (over `band`): there the measured push cannot be held whatever the lean, and
//! only its easing can save the robot (a short impact's peak, which an exact forecast's easing
//! lets the robot ride out). For the same reason FC-5's hedge of an easing toward the
//! measurement is lifted there (FC-5b: [`easing_believed`], applied to the correction's blend by
//! [`keep_easing`]). The capture point itself is VG-1's one home, [`CapturePoint`].
//! Allocation-free.

use serde::{Deserialize, Serialize};

use crate::col;
use crate::config::ControllerKind;
use crate::control::frame::{MeasuredPrediction, TickFrame};
use crate::control::part::{BuildError, ControllerPart, PartKind, PartSetup};
use crate::control::tick::{Stage, TickError, TickInputs};
use crate::preview::CapturePoint;
use crate::record::Record;

type V3 = [f64; 3];

/// What the guard did over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ViabilityCounts {
    /// Ticks with the forecast faded (s < 1 on an axis), and episodes of them.
    pub faded_ticks: u64,
    pub episodes: u64,
    /// Smallest s seen.
    pub min_scale: f64,
    /// FC-5b: plant time (s) an easing of the measured push was kept from FC-5's hedge.
    pub easing_believed_time: f64,
}

/// The push measured now (N), and over the horizon as the measurement alone predicts it (FC-5's
/// measurement model), when known: the hedge VG-3 fades an easing toward.
#[derive(Clone, Copy)]
pub struct MeasuredPush<'a> {
    pub now: V3,
    pub ahead: Option<&'a [V3]>,
}

impl MeasuredPush<'_> {
    /// Measured now only (the horizon's hedge is the push now).
    pub fn now(now: V3) -> Self {
        Self { now, ahead: None }
    }
}

/// How far beyond an edge the capture point is: `d` its distance to the edge (m, negative
/// beyond it), `half` the support's half-length (m); 0 inside, rising to 1 at `band` half-lengths
/// beyond. There the measured push cannot be held whatever the lean (VG-3's second line).
pub fn beyond_edge(d: f64, half: f64, band: f64) -> f64 {
    if d < 0.0 {
        (-d / half / band).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// FC-5b: per horizontal axis, how far a forecast's easing of the push measured now (`push`, N)
/// is believed over FC-5's hedge toward the measurement: [`beyond_edge`] of the capture point
/// under that push (`com`, `vcom`: m, m/s) to the edge of `support` ([[x_min, x_max],
/// [y_min, y_max]]) the push drives the robot toward. If the push stays, the robot cannot stop
/// there with the hedge or without it; if it eases, believing the easing is what lets it ride
/// the push out. 0 on an axis with nothing measured or non-finite inputs.
pub fn easing_believed(
    capture: &CapturePoint,
    com: [f64; 2],
    vcom: [f64; 2],
    support: [[f64; 2]; 2],
    push: V3,
    band: f64,
) -> [f64; 2] {
    [0, 1].map(|a| {
        let xi = capture.at(com[a], vcom[a], push[a]);
        let [lo, hi] = support[a];
        let half = 0.5 * (hi - lo);
        let d = if push[a] < 0.0 {
            xi - lo
        } else if push[a] > 0.0 {
            hi - xi
        } else {
            return 0.0;
        };
        if d.is_finite() && half > 0.0 {
            beyond_edge(d, half, band)
        } else {
            0.0
        }
    })
}

/// FC-5b on the horizon `f` that FC-5 blended as f_fc + (1 − w)(m − f_fc) (`w` the forecast's
/// weight, `forecast_only` f_fc, `measured_only` m): on each horizontal axis, a sample where the
/// forecast eases the push measured now (`push`) below the measurement's prediction, (f_fc − m)
/// against the push, is blended with w + (1 − w) b instead, b of that axis in `believed`
/// ([`easing_believed`]). Returns b on the axes where a sample was kept (0 elsewhere).
pub fn keep_easing(
    f: &mut [V3],
    forecast_only: &[V3],
    measured_only: &[V3],
    push: V3,
    w: f64,
    believed: [f64; 2],
) -> [f64; 2] {
    let mut kept = [0.0; 2];
    if w.is_nan() || w >= 1.0 || believed == [0.0; 2] {
        return kept;
    }
    for ((f, f_fc), m) in f.iter_mut().zip(forecast_only).zip(measured_only) {
        for c in 0..2 {
            if believed[c] > 0.0 && (f_fc[c] - m[c]) * push[c] < 0.0 {
                let weight = w + (1.0 - w) * believed[c];
                f[c] = f_fc[c] + (1.0 - weight) * (m[c] - f_fc[c]);
                kept[c] = believed[c];
            }
        }
    }
    kept
}

pub struct ViabilityGuard {
    s: ViabilitySettings,
    capture: CapturePoint,
    fading: bool,
    /// The last tick's scales (x, y) and capture points (m).
    pub last_scale: [f64; 2],
    pub last_capture: [f64; 2],
    /// FC-5b's b on the axes where the last tick kept an easing (0 elsewhere).
    pub last_easing: [f64; 2],
    pub counts: ViabilityCounts,
}

impl ViabilityGuard {
    /// For a cart-table of `mass` (kg) at `com_height` (m) under `gravity` (m/s²).
    pub fn new(settings: ViabilitySettings, mass: f64, gravity: f64, com_height: f64) -> Self {
        Self {
            s: settings,
            capture: CapturePoint::new(mass, gravity, com_height),
            fading: false,
            last_scale: [1.0; 2],
            last_capture: [0.0; 2],
            last_easing: [0.0; 2],
            counts: ViabilityCounts {
                min_scale: 1.0,
                ..Default::default()
            },
        }
    }

    /// A new plant session: the episode state starts over (counters are kept).
    pub fn reset(&mut self) {
        self.fading = false;
        self.last_scale = [1.0; 2];
        self.last_easing = [0.0; 2];
    }

    /// FC-5b ([`keep_easing`]) on `horizon`, then VG-2 and VG-3 ([`Self::apply`]), from the
    /// prediction of the part that produced the horizon, at plant time `t` after a control
    /// period `dt`.
    #[allow(clippy::too_many_arguments)]
    pub fn guard(
        &mut self,
        t: f64,
        dt: f64,
        com: [f64; 2],
        vcom: [f64; 2],
        support: [[f64; 2]; 2],
        prediction: &MeasuredPrediction,
        push: V3,
        horizon: &mut [V3],
    ) {
        let p = prediction;
        let b = easing_believed(&self.capture, com, vcom, support, push, self.s.band);
        let (f_fc, m) = (&p.forecast_only, &p.measured_only);
        self.last_easing = keep_easing(horizon, f_fc, m, push, p.weight, b);
        if self.last_easing != [0.0; 2] {
            self.counts.easing_believed_time += dt;
        }
        let measured = MeasuredPush {
            now: push,
            ahead: Some(m),
        };
        self.apply(t, com, vcom, support, measured, horizon);
    }

    /// Fades the unmeasured part of `horizon` (the hand force over the preview, N) by VG-2,
    /// from the CoM position and velocity (m, m/s, horizontal), the support rectangle
    /// ([[x_min, x_max], [y_min, y_max]]) and the push measured now (N). Non-finite inputs
    /// leave the horizon as it is.
    pub fn apply(
        &mut self,
        t: f64,
        com: [f64; 2],
        vcom: [f64; 2],
        support: [[f64; 2]; 2],
        push: MeasuredPush,
        horizon: &mut [V3],
    ) {
        let scales = self.scales(com, vcom, support, push.now);
        let faded = scales.iter().flatten().flatten().any(|s| *s < 1.0);
        let used = if faded {
            self.fade(&scales, push, horizon)
        } else {
            [1.0; 2]
        };
        self.last_scale = used;
        self.count(t, used, support);
    }

    /// Per axis, the scales of an unmeasured force toward −a (the robot leans toward +a, the +
    /// edge is at risk) and toward +a (the − edge): VG-2's for a push to come, VG-3's for an
    /// easing, as `[push, easing]`. The capture points are kept for the record.
    fn scales(
        &mut self,
        com: [f64; 2],
        vcom: [f64; 2],
        support: [[f64; 2]; 2],
        push_now: V3,
    ) -> [[[f64; 2]; 2]; 2] {
        let mut scale = [[1.0; 2]; 2];
        let mut ease = [[1.0; 2]; 2];
        for a in 0..2 {
            let xi = self.capture.at(com[a], vcom[a], push_now[a]);
            let [lo, hi] = support[a];
            let half = 0.5 * (hi - lo);
            if !(xi.is_finite() && half > 0.0 && push_now[a].is_finite()) {
                continue;
            }
            let fade = |d: f64, m: f64| ((d / half - m) / self.s.band).clamp(0.0, 1.0);
            let (m, e) = (self.s.margin, self.s.ease_margin);
            // Indexed by the departure's sign: a force toward −a (more push along −a, or a
            // push along +a easing) is met by leaning toward +a, and the + edge is at risk.
            scale[a] = [fade(hi - xi, m), fade(xi - lo, m)];
            // Beyond the edge, the measured push cannot be held whatever the lean: only its
            // easing can save the robot, so the forecast's easing is believed again.
            let ease_fade = |d: f64| {
                if d < 0.0 {
                    beyond_edge(d, half, self.s.band)
                } else {
                    fade(d, e)
                }
            };
            ease[a] = if e < 0.0 {
                [1.0; 2]
            } else {
                [ease_fade(hi - xi), ease_fade(xi - lo)]
            };
            self.last_capture[a] = xi;
        }
        [scale, ease]
    }

    /// VG-2 and VG-3 on each horizon sample with the axes' `[scale, ease]`; the smallest scale
    /// used per axis.
    fn fade(
        &self,
        [scale, ease]: &[[[f64; 2]; 2]; 2],
        push: MeasuredPush,
        horizon: &mut [V3],
    ) -> [f64; 2] {
        let (push_now, measured_only) = (push.now, push.ahead);
        let mut used = [1.0f64; 2];
        for (i, f) in horizon.iter_mut().enumerate() {
            let reference = measured_only.and_then(|m| m.get(i));
            for a in 0..2 {
                // The forecast's departure from the push measured now: a push to come (the
                // forecast beyond it along its own direction, all of it where nothing or the
                // opposite is measured; VG-2) or the measured push easing (VG-3) — guarded only
                // below what the measurement alone predicts (what C1 would preview without a
                // forecaster), and faded toward that.
                let now = push_now[a].abs();
                let u = if now > 0.0 { push_now[a] / now } else { 0.0 };
                let along = f[a] * u;
                let (easing, base) = if along > 0.0 && along < now {
                    let floor = reference.map_or(now, |m| (m[a] * u).min(now));
                    if along >= floor {
                        continue;
                    }
                    (true, floor * u)
                } else if along > 0.0 {
                    (false, push_now[a])
                } else {
                    (false, 0.0)
                };
                let extra = f[a] - base;
                if extra == 0.0 || (easing && self.s.ease_margin < 0.0) {
                    continue;
                }
                let s = match (easing, extra < 0.0) {
                    (false, true) => scale[a][0],
                    (false, false) => scale[a][1],
                    (true, true) => ease[a][0],
                    (true, false) => ease[a][1],
                };
                used[a] = used[a].min(s);
                f[a] = base + s * extra;
            }
        }
        used
    }

    /// The counters of a tick that used `used`, and a line when an episode starts.
    fn count(&mut self, t: f64, used: [f64; 2], support: [[f64; 2]; 2]) {
        let faded = used.iter().any(|s| *s < 1.0);
        if faded {
            self.counts.faded_ticks += 1;
            self.counts.min_scale = self.counts.min_scale.min(used[0].min(used[1]));
            if !self.fading {
                self.counts.episodes += 1;
                if self.counts.episodes.is_power_of_two() {
                    tracing::info!(
                        "t = {t:.3} s: the capture point under the measured force is {:.0} / {:.0} mm \
                         from the support's centre: the unmeasured forecast is faded (scale {:.2} / \
                         {:.2}) until a push arrives or the robot is back ({} times so far)",
                        (self.last_capture[0] - 0.5 * (support[0][0] + support[0][1])) * 1e3,
                        (self.last_capture[1] - 0.5 * (support[1][0] + support[1][1])) * 1e3,
                        used[0],
                        used[1],
                        self.counts.episodes
                    );
                }
            }
        }
        self.fading = faded;
    }
}

/// The capture-point guard as a controller part (C1, C2): it guards the horizon a part
/// produced with a measured push (the forecast correction's); inactive otherwise.
pub struct Guard {
    guard: Option<ViabilityGuard>,
    /// Whether it ever guarded a horizon (its columns are neutral and its summary absent until).
    ran: bool,
}

impl PartKind for Guard {
    type Settings = ViabilitySettings;

    fn build(
        s: &PartSetup,
        settings: ViabilitySettings,
    ) -> Result<Box<dyn ControllerPart>, BuildError> {
        let on = settings.enabled && s.kind != ControllerKind::C0;
        let c = s.cart;
        Ok(Box::new(Guard {
            guard: on.then(|| ViabilityGuard::new(settings, c.mass, c.gravity, c.com_height)),
            ran: false,
        }))
    }
}

impl ControllerPart for Guard {
    fn name(&self) -> &'static str {
        "viability"
    }

    fn stages(&self) -> &'static [Stage] {
        &[Stage::Forecast]
    }

    fn reset(&mut self) {
        if let Some(g) = self.guard.as_mut() {
            g.reset();
        }
    }

    fn update(
        &mut self,
        _: Stage,
        _inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let Some(g) = self.guard.as_mut() else {
            return Ok(());
        };
        let (t, dt, support) = (frame.t, frame.dt, frame.support);
        let (com, vcom) = (frame.com, frame.com_vel);
        let hand = frame.hand_mut();
        let (Some(push), Some(horizon)) = (hand.prediction.push, hand.horizon.refine()) else {
            return Ok(());
        };
        self.ran = true;
        let (com, vcom) = ([com[0], com[1]], [vcom[0], vcom[1]]);
        g.guard(t, dt, com, vcom, support, &hand.prediction, push, horizon);
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        let g = self.guard.as_ref().filter(|_| self.ran);
        let (scale, capture, easing) = g.map_or(([1.0; 2], [f64::NAN; 2], [0.0; 2]), |g| {
            (g.last_scale, g.last_capture, g.last_easing)
        });
        out.put(
            col!(fixed("guard_x", 3).plot("viability/scale_x")),
            scale[0],
        );
        out.put(
            col!(fixed("guard_y", 3).plot("viability/scale_y")),
            scale[1],
        );
        out.put(
            col!(fixed("capture_x", 5).plot("viability/capture_x")),
            capture[0],
        );
        out.put(col!(fixed("capture_y", 5)), capture[1]);
        out.put(
            col!(fixed("guard_easing_x", 3).plot("viability/easing_believed_x")),
            easing[0],
        );
        out.put(col!(fixed("guard_easing_y", 3)), easing[1]);
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        if let Some(g) = self.guard.as_ref().filter(|_| self.ran) {
            out.insert("viability".into(), serde_json::json!(g.counts));
        }
    }
}

/// `[controller.viability]`: the capture-point guard on unconfirmed forecasts
/// (`control::parts::viability`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ViabilitySettings {
    /// Fade the forecast's unmeasured part as the capture point nears an edge (C1, C2).
    pub enabled: bool,
    /// Distance to the nearer support edge (fraction of the half-length) at which the
    /// unmeasured forecast is gone.
    pub margin: f64,
    /// Width of the fade (fraction of the half-length) beyond the margin.
    pub band: f64,
    /// The margin for a forecast easing the measured push (VG-3): the robot eases off the push
    /// before it does, and the edge at risk is the one the push drives it toward if it does not
    /// ease. Beyond that edge the easing is believed again (nothing else can save the robot).
    /// Negative: easing is never faded.
    pub ease_margin: f64,
}

impl Default for ViabilitySettings {
    /// The embedded `config/default.toml`'s table (their one home).
    fn default() -> Self {
        crate::config::embedded_part()
    }
}

impl crate::config::PartSettings for ViabilitySettings {
    const TABLE: &'static str = "viability";

    fn check(&self) -> Result<(), (&'static str, String)> {
        if !(0.0..1.0).contains(&self.margin) {
            return Err(("margin", format!("must be in [0, 1), got {}", self.margin)));
        }
        if !(self.ease_margin.is_finite() && self.ease_margin < 1.0) {
            return Err((
                "ease_margin",
                format!("must be finite and < 1, got {}", self.ease_margin),
            ));
        }
        if !(self.band.is_finite() && self.band > 0.0) {
            return Err(("band", format!("must be finite and > 0, got {}", self.band)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn guard() -> ViabilityGuard {
        // M ω² = 30 kg × 9.81 / 0.5 m ≈ 589 N/m.
        ViabilityGuard::new(ViabilitySettings::default(), 30.0, 9.81, 0.5)
    }

    const SUPPORT: [[f64; 2]; 2] = [[-0.07, 0.07], [-0.1, 0.1]];

    /// `apply` with the CoM at rest at `com_x` (y 0) on [`SUPPORT`], the push measured now only.
    fn at_rest(g: &mut ViabilityGuard, t: f64, com_x: f64, push: V3, h: &mut [V3]) {
        g.apply(
            t,
            [com_x, 0.0],
            [0.0; 2],
            SUPPORT,
            MeasuredPush::now(push),
            h,
        );
    }

    #[test]
    fn a_robot_at_rest_keeps_the_whole_forecast() {
        let mut g = guard();
        let mut h = vec![[-80.0, 5.0, 0.0]; 10];
        g.apply(
            0.0,
            [0.0; 2],
            [0.0; 2],
            SUPPORT,
            MeasuredPush::now([0.0; 3]),
            &mut h,
        );
        assert!(h.iter().all(|f| *f == [-80.0, 5.0, 0.0]));
        assert_eq!(g.counts.faded_ticks, 0);
    }

    /// Leaning 60 mm forward with nothing measured: the capture point is past the margin, the
    /// forecast beyond the measured push is dropped; once the push is measured, the same lean
    /// is a balance against it and the forecast is kept.
    #[test]
    fn an_unmeasured_lean_fades_and_a_measured_push_lifts_the_fade() {
        let mut g = guard();
        let mut h = vec![[-80.0, 0.0, 0.0]; 10];
        g.apply(
            0.0,
            [0.04, 0.0],
            [0.1, 0.0],
            SUPPORT,
            MeasuredPush::now([0.0; 3]),
            &mut h,
        );
        assert_eq!(g.last_scale[0], 0.0, "{:?}", g.last_capture);
        assert!(h.iter().all(|f| f[0] == 0.0), "{:?}", h[0]);
        assert_eq!((g.counts.faded_ticks, g.counts.episodes), (1, 1));
        // The push of −30 N measured: ξ_m = 0.04 + 0.1 × 0.2258 − 30 / 588.6 ≈ 0.0116 m.
        let mut h = vec![[-80.0, 0.0, 0.0]; 10];
        g.apply(
            0.001,
            [0.04, 0.0],
            [0.1, 0.0],
            SUPPORT,
            MeasuredPush::now([-30.0, 0.0, 0.0]),
            &mut h,
        );
        assert_eq!(g.last_scale, [1.0, 1.0]);
        assert!(h.iter().all(|f| f[0] == -80.0));
        assert_eq!(g.counts.episodes, 1);
    }

    /// The edge at risk is the one a push to come leans the robot toward: with the capture
    /// point near the rear edge, more push along −x (met by leaning forward) is kept and a push
    /// to come along +x (met by leaning back) is faded. Near the front edge, more push along −x
    /// is faded. The push's easing (VG-3) is kept unless the capture point is within
    /// `ease_margin` (0.1 here) + `band` of the rear edge, the one the push drives the robot
    /// toward if it does not ease.
    #[test]
    fn only_a_departure_toward_the_near_edge_fades() {
        let mut g = ViabilityGuard::new(
            ViabilitySettings {
                ease_margin: 0.1,
                ..Default::default()
            },
            30.0,
            9.81,
            0.5,
        );
        let mut h = vec![[-60.0, 0.0, 0.0], [-20.0, 0.0, 0.0], [30.0, 0.0, 0.0]];
        let push = [-40.0, 0.0, 0.0];
        // ξ_m = −0.06 m: com − 40 / (M ω²) = −0.06.
        let com = -0.06 + 40.0 / g.capture.stiffness();
        at_rest(&mut g, 0.0, com, push, &mut h);
        assert!((g.last_capture[0] + 0.06).abs() < 1e-12);
        assert_eq!(
            h[0][0], -60.0,
            "more push, leaning away from the rear edge: kept"
        );
        // d = 0.01 / 0.07 of the half-length: the easing scaled by (d − 0.1) / 0.1.
        let s = (0.01 / 0.07 - 0.1) / 0.1;
        assert!(
            (h[1][0] - (-40.0 + s * 20.0)).abs() < 1e-9,
            "the push easing toward the rear edge: scaled by {s}, {}",
            h[1][0]
        );
        assert_eq!(h[2][0], 0.0, "a push to come along +x: faded to none");
        let mut h = vec![[-60.0, 0.0, 0.0], [-20.0, 0.0, 0.0]];
        let com = 0.06 + 40.0 / g.capture.stiffness();
        at_rest(&mut g, 0.001, com, push, &mut h);
        assert_eq!(h[0][0], -40.0, "more push toward the front edge: faded");
        assert_eq!(h[1][0], -20.0, "its easing, away from the rear edge: kept");
        // Beyond the rear edge the measured push cannot be held whatever the lean: the easing
        // is believed again, fully once ξ_m is `band` beyond it.
        for (beyond, s) in [(0.05, 0.5), (0.1, 1.0), (0.3, 1.0)] {
            let mut h = vec![[-20.0, 0.0, 0.0]];
            let com = -0.07 - beyond * 0.07 + 40.0 / g.capture.stiffness();
            at_rest(&mut g, 0.002, com, push, &mut h);
            assert!(
                (h[0][0] - (-40.0 + s * 20.0)).abs() < 1e-9,
                "ξ_m {beyond} of the half-length beyond the rear edge: easing scaled by {s}, {}",
                h[0][0]
            );
        }
        // With `ease_margin` < 0 the easing is never faded.
        let mut g = ViabilityGuard::new(
            ViabilitySettings {
                ease_margin: -1.0,
                ..Default::default()
            },
            30.0,
            9.81,
            0.5,
        );
        let mut h = vec![[-20.0, 0.0, 0.0]];
        let com = -0.069 + 40.0 / g.capture.stiffness();
        at_rest(&mut g, 0.0, com, push, &mut h);
        assert_eq!(h[0][0], -20.0);
        assert_eq!(g.counts.faded_ticks, 0);
    }

    /// With the measurement-only horizon given, an easing is guarded only below it, and faded
    /// toward it: the forecast that eases no faster than the measurement alone predicts is what
    /// C1 would preview without a forecaster, and is left as it is.
    #[test]
    fn an_easing_is_guarded_below_what_the_measurement_alone_predicts() {
        let mut g = guard();
        let push = [-40.0, 0.0, 0.0];
        // ξ_m 1 mm inside the rear edge: the easing fully faded (s = 0).
        let com = -0.069 + 40.0 / g.capture.stiffness();
        let measured_only = [[-30.0, 0.0, 0.0], [-30.0, 0.0, 0.0], [-50.0, 0.0, 0.0]];
        let mut h = vec![[-35.0, 0.0, 0.0], [-20.0, 0.0, 0.0], [-20.0, 0.0, 0.0]];
        g.apply(
            0.0,
            [com, 0.0],
            [0.0; 2],
            SUPPORT,
            MeasuredPush {
                now: push,
                ahead: Some(&measured_only),
            },
            &mut h,
        );
        assert_eq!(
            h[0][0], -35.0,
            "easing slower than the measurement predicts: kept"
        );
        assert_eq!(
            h[1][0], -30.0,
            "easing faster: held at the measurement's prediction"
        );
        assert_eq!(
            h[2][0], -40.0,
            "the measurement predicts more: held at the push now"
        );
    }

    /// FC-5b's belief in an easing: 0 while the capture point under the measured push is inside
    /// the support, rising over `band` beyond the edge that push drives the robot toward (the
    /// heel for a push along −x, the toe along +x), 0 with nothing measured on the axis.
    #[test]
    fn an_easing_is_believed_beyond_the_edge_the_push_drives_toward() {
        let s = ViabilitySettings::default();
        let capture = CapturePoint::new(30.0, 9.81, 0.5);
        let k = 30.0 * 9.81 / 0.5;
        let believed = |com: f64, push: f64| {
            easing_believed(
                &capture,
                [com, 0.0],
                [0.0; 2],
                SUPPORT,
                [push, 0.0, 0.0],
                s.band,
            )
        };
        // 60 N along −x: F/(M ω²) ≈ 102 mm behind the CoM.
        let behind = 60.0 / k;
        assert_eq!(believed(behind, -60.0), [0.0; 2], "inside");
        let half_band = 0.5 * s.band * 0.07;
        let b = believed(-0.07 - half_band + behind, -60.0)[0];
        assert!((b - 0.5).abs() < 1e-9, "{b}");
        assert_eq!(
            believed(-0.07 - 0.02 + behind, -60.0),
            [1.0, 0.0],
            "beyond the heel"
        );
        // The same capture point with the push along +x: the toe edge is far, nothing believed.
        assert_eq!(believed(-0.07 - 0.02 - behind, 60.0), [0.0; 2]);
        assert_eq!(
            believed(0.07 + 0.02 - behind, 60.0),
            [1.0, 0.0],
            "beyond the toe"
        );
        assert_eq!(believed(0.5, 0.0), [0.0; 2], "nothing measured");
    }

    /// Between margin and margin + band the unmeasured part is scaled linearly, toward the
    /// measured push (not toward zero).
    #[test]
    fn inside_the_band_the_unmeasured_part_is_scaled() {
        let mut g = guard();
        let s = ViabilitySettings::default();
        // ξ_m at the middle of the band: d = margin + band / 2.
        let d = s.margin + 0.5 * s.band;
        let xi = 0.07 - d * 0.07;
        let mut h = vec![[-50.0, 0.0, 0.0]; 3];
        let com = xi + 10.0 / g.capture.stiffness();
        at_rest(&mut g, 0.0, com, [-10.0, 0.0, 0.0], &mut h);
        assert!((g.last_scale[0] - 0.5).abs() < 1e-9, "{:?}", g.last_scale);
        assert!((h[0][0] + 30.0).abs() < 1e-9, "{:?}", h[0]);
    }
}
