//! The contact and hand wrenches the controller had against the plant's truth, from a lockstep
//! run's logs (docs/estimation.md, "Measured"): the hand force (the wrench observer's `wo_hand_*`
//! when it ran, else the measured `f_meas_*`), each foot's load (`wo_fz_*`, the observer only)
//! and the centre of pressure the controller closed on (`zmp_meas_*`), against `sim.csv`'s
//! `hand_f*`, `lfoot_fz`/`rfoot_fz` and `zmp_*`, joined on their common sample times.
//!
//! "During pushes" are the samples whose true horizontal hand force is at least
//! [`PUSH_FORCE`]; "standing" the others. The hand's lag is the shift of the estimate that
//! best aligns it with the truth during pushes (a parabola through the best sample shift and
//! its neighbours: finer than the logs' 10 ms).

use std::collections::HashMap;
use std::path::Path;

use super::base_accuracy::{by_time, read_both};
use super::csv::Columns;

/// A true horizontal hand force at least this large (N) is a push.
pub const PUSH_FORCE: f64 = 5.0;

/// Largest estimate lag searched (s).
const MAX_LAG: f64 = 0.1;

/// RMS, median and 99th percentile of an error (the error's magnitude for p50 / p99).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorStats {
    pub samples: usize,
    pub rms: f64,
    pub p50: f64,
    pub p99: f64,
}

impl ErrorStats {
    fn of(mut e: Vec<f64>) -> Self {
        if e.is_empty() {
            return Self::default();
        }
        let n = e.len();
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
        e.iter_mut().for_each(|x| *x = x.abs());
        e.sort_by(f64::total_cmp);
        let at = |p: f64| e[((p * (n - 1) as f64).round() as usize).min(n - 1)];
        Self {
            samples: n,
            rms,
            p50: at(0.5),
            p99: at(0.99),
        }
    }
}

/// Which hand force the controller had.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HandSource {
    /// The wrench observer's (`wo_hand_*`).
    #[default]
    Observer,
    /// A wrist sensor's (`f_meas_*`).
    Measured,
}

impl std::fmt::Display for HandSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Observer => "observer",
            Self::Measured => "measured",
        })
    }
}

/// The wrenches' error over a run (N, m, s).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WrenchAccuracy {
    /// Which hand force was compared.
    pub hand_source: HandSource,
    /// The hand force's x and y errors, during pushes and standing.
    pub hand_x_push: ErrorStats,
    pub hand_y_push: ErrorStats,
    pub hand_x_standing: ErrorStats,
    /// The shift (s) of the hand estimate that best matches the truth during pushes.
    pub hand_lag: f64,
    /// The centre of pressure's x and y errors, standing and during pushes.
    pub cop_x_standing: ErrorStats,
    pub cop_y_standing: ErrorStats,
    pub cop_x_push: ErrorStats,
    pub cop_y_push: ErrorStats,
    /// Each foot's load (both feet's samples together); none without the observer.
    pub foot_load: Option<ErrorStats>,
}

/// The error, or `None` when the logs hold neither a hand force nor a CoP to compare.
pub fn wrench_accuracy(controller_csv: &Path, sim_csv: &Path) -> Option<WrenchAccuracy> {
    let (c, s) = read_both(controller_csv, sim_csv)?;
    accuracy_of(&c, &s)
}

/// A column that holds at least one finite value.
fn col<'a>(m: &'a Columns, n: &str) -> Option<&'a Vec<f64>> {
    m.get(n).filter(|c| c.iter().any(|x| x.is_finite()))
}

fn accuracy_of(est: &Columns, truth: &Columns) -> Option<WrenchAccuracy> {
    let (hand_source, hx, hy) = match (col(est, "wo_hand_x"), col(est, "wo_hand_y")) {
        (Some(x), Some(y)) => (HandSource::Observer, x, y),
        _ => (
            HandSource::Measured,
            col(est, "f_meas_x")?,
            col(est, "f_meas_y")?,
        ),
    };
    let (tx, ty) = (truth.get("hand_fx")?, truth.get("hand_fy")?);
    let (cx, cy) = (est.get("zmp_meas_x")?, est.get("zmp_meas_y")?);
    let (zx, zy) = (truth.get("zmp_x")?, truth.get("zmp_y")?);
    let est_at = by_time(est)?;
    let truth_t = truth.get("t")?;
    let at = |c: &Vec<f64>, i: usize| c.get(i).copied().unwrap_or(f64::NAN);
    // The truth samples with a controller sample at the same time, and whether a push.
    let pairs: Vec<(usize, usize, bool)> = truth_t
        .iter()
        .enumerate()
        .filter_map(|(j, &t)| {
            let i = *est_at.get(&((t * 1e3).round() as i64))?;
            Some((i, j, at(tx, j).hypot(at(ty, j)) >= PUSH_FORCE))
        })
        .collect();
    if pairs.is_empty() {
        return None;
    }
    let errors = |e: &Vec<f64>, t: &Vec<f64>, push: bool| -> ErrorStats {
        ErrorStats::of(
            pairs
                .iter()
                .filter(|p| p.2 == push)
                .map(|&(i, j, _)| at(e, i) - at(t, j))
                .filter(|x| x.is_finite())
                .collect(),
        )
    };
    let foot_load = match (col(est, "wo_fz_left"), col(est, "wo_fz_right")) {
        (Some(l), Some(r)) => {
            let (tl, tr) = (truth.get("lfoot_fz")?, truth.get("rfoot_fz")?);
            let e = pairs
                .iter()
                .flat_map(|&(i, j, _)| [at(l, i) - at(tl, j), at(r, i) - at(tr, j)])
                .filter(|x| x.is_finite())
                .collect();
            Some(ErrorStats::of(e))
        }
        _ => None,
    };
    Some(WrenchAccuracy {
        hand_source,
        hand_x_push: errors(hx, tx, true),
        hand_y_push: errors(hy, ty, true),
        hand_x_standing: errors(hx, tx, false),
        hand_lag: lag(&pairs, &est_at, truth_t, hx, tx),
        cop_x_standing: errors(cx, zx, false),
        cop_y_standing: errors(cy, zy, false),
        cop_x_push: errors(cx, zx, true),
        cop_y_push: errors(cy, zy, true),
        foot_load,
    })
}

/// The shift of the estimate (s, ≥ 0: it trails) that minimises its RMS error during pushes.
fn lag(
    pairs: &[(usize, usize, bool)],
    est_at: &HashMap<i64, usize>,
    truth_t: &[f64],
    e: &[f64],
    t: &[f64],
) -> f64 {
    // The logs' sample spacing (ms), from the first two truth samples.
    let step = match truth_t {
        [a, b, ..] => ((b - a) * 1e3).round().max(1.0) as i64,
        _ => return f64::NAN,
    };
    let shifts = (MAX_LAG * 1e3) as i64 / step;
    let mse = |k: i64| -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for &(_, j, push) in pairs {
            let key = (truth_t[j] * 1e3).round() as i64 + k * step;
            if let (true, Some(&i)) = (push, est_at.get(&key)) {
                let d = e[i] - t[j];
                if d.is_finite() {
                    sum += d * d;
                    n += 1;
                }
            }
        }
        if n == 0 {
            f64::INFINITY
        } else {
            sum / n as f64
        }
    };
    let m: Vec<f64> = (0..=shifts).map(mse).collect();
    let Some((best, _)) = m
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1))
    else {
        return f64::NAN;
    };
    // A parabola through the best shift and its neighbours places the minimum between samples.
    let frac = match (best.checked_sub(1).map(|k| m[k]), m.get(best + 1)) {
        (Some(a), Some(&c)) if a.is_finite() && c.is_finite() => {
            let den = a - 2.0 * m[best] + c;
            if den > 0.0 { 0.5 * (a - c) / den } else { 0.0 }
        }
        _ => 0.0,
    };
    (best as f64 + frac) * step as f64 * 1e-3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::csv::tests::lenient;

    /// An estimate that is the truth 20 ms late plus a constant 1 N, and a CoP 3 mm off, is
    /// what the comparison reports; the feet's loads are compared when the observer ran.
    #[test]
    fn a_known_lag_offset_and_cop_error() {
        let force = |t: f64| {
            if (0.2..0.8).contains(&t) {
                40.0 * (std::f64::consts::PI * (t - 0.2) / 0.6).sin()
            } else {
                0.0
            }
        };
        let mut est =
            String::from("t,wo_hand_x,wo_hand_y,zmp_meas_x,zmp_meas_y,wo_fz_left,wo_fz_right\n");
        let mut truth = String::from("t,hand_fx,hand_fy,zmp_x,zmp_y,lfoot_fz,rfoot_fz\n");
        for k in 0..100 {
            let t = k as f64 * 0.01;
            est += &format!(
                "{t:.4},{},0,0.003,-0.003,{},150\n",
                force(t - 0.02) + 1.0,
                150.0 + 2.0
            );
            truth += &format!("{t:.4},{},0,0,0,150,150\n", force(t));
        }
        let a = accuracy_of(&lenient(&est), &lenient(&truth)).unwrap();
        assert_eq!(a.hand_source, HandSource::Observer);
        assert!((a.hand_lag - 0.02).abs() < 0.004, "lag {}", a.hand_lag);
        // Standing: the offset (the push's lagging tails below 5 N add to the RMS only).
        assert!(
            (a.hand_x_standing.p50 - 1.0).abs() < 1e-9 && a.hand_x_standing.rms >= 1.0,
            "{:?}",
            a.hand_x_standing
        );
        assert!(
            a.hand_x_push.rms > 1.0,
            "the lag adds to the offset: {:?}",
            a.hand_x_push
        );
        assert!(
            (a.cop_x_standing.rms - 0.003).abs() < 1e-9 && (a.cop_y_push.p99 - 0.003).abs() < 1e-9
        );
        let feet = a.foot_load.unwrap();
        assert_eq!(feet.samples, 200);
        assert!((feet.rms - 2f64.sqrt()).abs() < 1e-9, "{feet:?}");
        assert_eq!((feet.p50, feet.p99), (2.0, 2.0), "{feet:?}");
    }

    /// Without the observer the measured hand force is compared, and no foot loads.
    #[test]
    fn a_measured_hand_force_without_the_observer() {
        let est = "t,f_meas_x,f_meas_y,zmp_meas_x,zmp_meas_y\n0.0100,6,0,0,0\n0.0200,6,0,0,0\n";
        let truth = "t,hand_fx,hand_fy,zmp_x,zmp_y\n0.0100,5,0,0,0\n0.0200,5,0,0,0\n";
        let a = accuracy_of(&lenient(est), &lenient(truth)).unwrap();
        assert_eq!(
            (a.hand_source, a.hand_x_push.samples),
            (HandSource::Measured, 2)
        );
        assert!((a.hand_x_push.rms - 1.0).abs() < 1e-12 && a.foot_load.is_none());
    }
}
