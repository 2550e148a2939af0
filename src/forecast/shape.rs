//! Forecasts of the wrong shape, on purpose (`upc forecast --error-shape`, `upc run
//! --forecast-error-shape`): what a lab's forecaster gets wrong besides amplitude (`scale`) and
//! timing (`shift`). Each shape applies to every impact of the scenario's force:
//! - `truncated:F`: the push forecast over the first fraction F of its duration, nothing after
//!   (it ends too early);
//! - `decaying:T`: the push's peak force from its onset, decaying exponentially with time
//!   constant T s (it decays where the real one grows);
//! - `step`: the peak force over the whole push (a step where the real one ramps);
//! - `stretched:K`: rise, hold and fall K times as long (the push lasts K times longer);
//! - `rotated:D`: the force turned D degrees about the vertical (it points off-axis).

use std::fmt;
use std::str::FromStr;

use crate::scenario::{ForceProfile, Impact};

/// Sample spacing of a shape that is no sum of raised-cosine impacts (s): a 1 ms ramp at each
/// discontinuity, finer than the forecast's own 5 ms samples.
const DT: f64 = 1e-3;
/// A decaying forecast is cut where it has fallen below e^-10 of its peak.
const DECAY_SPAN: f64 = 10.0;

/// How the published forecast's shape departs from the scenario's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ForecastShape {
    #[default]
    Exact,
    Truncated(f64),
    Decaying(f64),
    Step,
    Stretched(f64),
    Rotated(f64),
}

impl FromStr for ForecastShape {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (name, arg) = match s.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (s, None),
        };
        let num = |what: &str, ok: fn(f64) -> bool| -> Result<f64, String> {
            let a = arg.ok_or_else(|| format!("`{name}` needs {what}: `{name}:X`"))?;
            let v: f64 = a
                .parse()
                .map_err(|_| format!("`{name}:{a}`: {a} is not a number"))?;
            if ok(v) {
                Ok(v)
            } else {
                Err(format!("`{name}:{a}`: {what} out of range"))
            }
        };
        let shape = match name {
            "exact" => ForecastShape::Exact,
            "step" => ForecastShape::Step,
            "truncated" => {
                ForecastShape::Truncated(num("a fraction in (0, 1]", |v| v > 0.0 && v <= 1.0)?)
            }
            "decaying" => ForecastShape::Decaying(num("a time constant > 0 (s)", |v| {
                v.is_finite() && v > 0.0
            })?),
            "stretched" => {
                ForecastShape::Stretched(num("a factor > 0", |v| v.is_finite() && v > 0.0)?)
            }
            "rotated" => ForecastShape::Rotated(num("an angle (degrees)", f64::is_finite)?),
            _ => {
                return Err(format!(
                    "unknown forecast shape `{s}`: exact, truncated:F, decaying:T, step, \
                     stretched:K or rotated:D"
                ));
            }
        };
        if matches!(shape, ForecastShape::Exact | ForecastShape::Step) && arg.is_some() {
            return Err(format!("`{name}` takes no value"));
        }
        Ok(shape)
    }
}

impl fmt::Display for ForecastShape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ForecastShape::Exact => write!(f, "exact"),
            ForecastShape::Step => write!(f, "step"),
            ForecastShape::Truncated(v) => write!(f, "truncated:{v}"),
            ForecastShape::Decaying(v) => write!(f, "decaying:{v}"),
            ForecastShape::Stretched(v) => write!(f, "stretched:{v}"),
            ForecastShape::Rotated(v) => write!(f, "rotated:{v}"),
        }
    }
}

/// Written as the command line spells it (`truncated:0.5`), in sweep results.
impl serde::Serialize for ForecastShape {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl ForecastShape {
    /// `profile` as forecast with this shape. Shapes other than `rotated` need the pushes, so an
    /// impact profile (a CSV profile can only be rotated).
    pub fn apply(&self, profile: &ForceProfile) -> Result<ForceProfile, String> {
        let impacts = match (self, profile) {
            (ForecastShape::Exact, p) => return Ok(p.clone()),
            (ForecastShape::Rotated(deg), ForceProfile::Samples(s)) => {
                let s = s.iter().map(|(t, f)| (*t, rotate(*f, *deg))).collect();
                return Ok(ForceProfile::Samples(s));
            }
            (_, ForceProfile::Samples(_)) => {
                return Err(format!(
                    "the forecast shape `{self}` needs a scenario of impacts (a sampled profile \
                     can only be rotated)"
                ));
            }
            (_, ForceProfile::Impacts(v)) => v,
        };
        let out = match *self {
            ForecastShape::Stretched(k) => ForceProfile::Impacts(
                impacts
                    .iter()
                    .map(|i| Impact {
                        rise: i.rise * k,
                        hold: i.hold * k,
                        fall: i.fall * k,
                        ..i.clone()
                    })
                    .collect(),
            ),
            ForecastShape::Rotated(deg) => ForceProfile::Impacts(
                impacts
                    .iter()
                    .map(|i| Impact {
                        force: rotate(i.force, deg),
                        ..i.clone()
                    })
                    .collect(),
            ),
            shape => {
                // Where each impact's shaped forecast ends.
                let span = |i: &Impact| match shape {
                    ForecastShape::Decaying(tc) => DECAY_SPAN * tc,
                    _ => i.length(),
                };
                let end = impacts
                    .iter()
                    .map(|i| i.start + span(i))
                    .fold(0.0, f64::max);
                sampled(impacts, end, shape)
            }
        };
        Ok(out)
    }
}

/// One impact's forecast at time t under `shape` (a shape drawn sample by sample).
fn contribution(shape: ForecastShape, i: &Impact, t: f64) -> [f64; 3] {
    let tau = t - i.start;
    let gain = match shape {
        ForecastShape::Truncated(frac) if tau < frac * i.length() => i.envelope(t),
        ForecastShape::Decaying(tc) if (0.0..DECAY_SPAN * tc).contains(&tau) => (-tau / tc).exp(),
        ForecastShape::Step if (0.0..i.length()).contains(&tau) => 1.0,
        _ => 0.0,
    };
    i.force.map(|f| f * gain)
}

/// The sum of each impact's forecast under `shape`, sampled every [`DT`] up to `end`.
fn sampled(impacts: &[Impact], end: f64, shape: ForecastShape) -> ForceProfile {
    let n = (end / DT).ceil() as usize + 2;
    let samples = (0..n)
        .map(|k| {
            let t = k as f64 * DT;
            let mut sum = [0.0; 3];
            for i in impacts {
                let c = contribution(shape, i, t);
                for a in 0..3 {
                    sum[a] += c[a];
                }
            }
            (t, sum)
        })
        .collect();
    ForceProfile::Samples(samples)
}

/// `f` turned `deg` degrees about the vertical.
fn rotate(f: [f64; 3], deg: f64) -> [f64; 3] {
    let (s, c) = deg.to_radians().sin_cos();
    [c * f[0] - s * f[1], s * f[0] + c * f[1], f[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push() -> (Impact, ForceProfile) {
        let i = Impact {
            start: 1.0,
            rise: 0.5,
            hold: 0.0,
            fall: 0.5,
            force: [-45.0, 0.0, 0.0],
        };
        (i.clone(), ForceProfile::Impacts(vec![i]))
    }

    #[test]
    fn each_shape_departs_from_the_push_as_named() {
        let (_, exact) = push();
        let at = |shape: &str, t: f64| {
            let s: ForecastShape = shape.parse().expect("shape");
            s.apply(&exact).expect("apply").at(t)[0]
        };
        // The push: 0 before 1 s, peak −45 N at 1.5 s, over at 2 s.
        assert!((exact.at(1.5)[0] + 45.0).abs() < 1e-12);
        // Truncated at half: the rise as forecast, nothing from its peak on.
        // (sampled every millisecond: the raised cosine within its curvature × dt² / 8)
        assert!((at("truncated:0.5", 1.25) - exact.at(1.25)[0]).abs() < 1e-3);
        assert_eq!(at("truncated:0.5", 1.6), 0.0);
        // Decaying from the onset: the peak at once, e^-1 of it a time constant later.
        assert!((at("decaying:0.3", 1.0 + 1e-3) + 45.0 * (-1e-3 / 0.3f64).exp()).abs() < 0.2);
        assert!((at("decaying:0.3", 1.3) + 45.0 * (-1.0f64).exp()).abs() < 1e-9);
        assert!(at("decaying:0.3", 0.99).abs() < 1e-12);
        // A step: the peak over the whole push, nothing outside.
        assert!((at("step", 1.05) + 45.0).abs() < 1e-9);
        assert!((at("step", 1.95) + 45.0).abs() < 1e-9);
        assert!(at("step", 2.01).abs() < 1e-12);
        // Stretched twice: the peak at 2 s, over at 3 s.
        assert!((at("stretched:2", 2.0) + 45.0).abs() < 1e-12);
        assert!(at("stretched:2", 2.5).abs() > 10.0);
        // Rotated 30° about z: the same magnitude, 30° off the x axis.
        let s: ForecastShape = "rotated:30".parse().expect("shape");
        let f = s.apply(&exact).expect("apply").at(1.5);
        assert!((f[0] + 45.0 * 30f64.to_radians().cos()).abs() < 1e-9);
        assert!((f[1] + 45.0 * 30f64.to_radians().sin()).abs() < 1e-9);
    }

    #[test]
    fn shapes_read_back_as_written_and_bad_ones_say_why() {
        for s in [
            "exact",
            "step",
            "truncated:0.5",
            "decaying:0.3",
            "stretched:2",
            "rotated:-30",
        ] {
            let shape: ForecastShape = s.parse().expect(s);
            assert_eq!(shape.to_string(), s);
        }
        for (bad, why) in [
            ("truncated", "needs"),
            ("truncated:1.5", "out of range"),
            ("decaying:0", "out of range"),
            ("step:2", "takes no value"),
            ("wobbly", "unknown forecast shape"),
        ] {
            let e = bad.parse::<ForecastShape>().expect_err(bad);
            assert!(e.contains(why), "{bad}: {e}");
        }
        let samples = ForceProfile::Samples(vec![(0.0, [1.0, 0.0, 0.0]), (1.0, [1.0, 0.0, 0.0])]);
        assert!(ForecastShape::Step.apply(&samples).is_err());
        assert!(ForecastShape::Rotated(90.0).apply(&samples).is_ok());
    }
}
