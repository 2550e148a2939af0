//! The true centre of pressure's margin: the plant's ZMP of the contact forces (`sim.csv`)
//! against the support rectangle the controller had at the same time (`controller.csv`). The
//! controller's own margin (`min_zmp_margin`) is its measured CoP's; on a robot that estimates
//! its CoP (docs/estimation.md) the two differ, and the truth decides whether it stood.

use std::path::Path;

use serde::Serialize;

use super::base_accuracy::{by_time, read_both};
use super::csv::Columns;

/// The smallest signed distance of the true CoP to the support's nearest edge (m; negative:
/// outside), when it happened, and the smallest along each axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrueMargin {
    pub min: f64,
    /// Simulated time of the smallest (s).
    pub at: f64,
    pub x: f64,
    pub y: f64,
    /// Samples compared (both logs at the same time).
    pub samples: usize,
}

/// The true CoP's margin, or `None` when the logs share no sample with a finite CoP and support.
pub fn true_margin(controller_csv: &Path, sim_csv: &Path) -> Option<TrueMargin> {
    let (c, s) = read_both(controller_csv, sim_csv)?;
    margin_of(&c, &s)
}

fn margin_of(ctrl: &Columns, truth: &Columns) -> Option<TrueMargin> {
    let [x0, x1, y0, y1] =
        ["sup_x_min", "sup_x_max", "sup_y_min", "sup_y_max"].map(|k| ctrl.get(k));
    let (x0, x1, y0, y1) = (x0?, x1?, y0?, y1?);
    let [ts, zx, zy] = ["t", "zmp_x", "zmp_y"].map(|k| truth.get(k));
    let (ts, zx, zy) = (ts?, zx?, zy?);
    let at = by_time(ctrl)?;
    let mut out: Option<TrueMargin> = None;
    for (j, &t) in ts.iter().enumerate() {
        let Some(&i) = at.get(&((t * 1e3).round() as i64)) else {
            continue;
        };
        let mx = (zx[j] - x0[i]).min(x1[i] - zx[j]);
        let my = (zy[j] - y0[i]).min(y1[i] - zy[j]);
        if !(mx.is_finite() && my.is_finite()) {
            continue;
        }
        let m = out.get_or_insert(TrueMargin {
            min: f64::INFINITY,
            at: t,
            x: f64::INFINITY,
            y: f64::INFINITY,
            samples: 0,
        });
        m.samples += 1;
        m.x = m.x.min(mx);
        m.y = m.y.min(my);
        if mx.min(my) < m.min {
            m.min = mx.min(my);
            m.at = t;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(cols: &[(&'static str, Vec<f64>)]) -> Columns {
        cols.iter().cloned().collect()
    }

    /// The smallest distance to the nearest edge, signed, on the samples both logs have; a
    /// sample without a CoP (NaN: nothing in contact) is skipped.
    #[test]
    fn the_nearest_edge_at_the_shared_times() {
        let ctrl = log(&[
            ("t", vec![0.0, 0.01, 0.02, 0.03]),
            ("sup_x_min", vec![-0.07; 4]),
            ("sup_x_max", vec![0.07; 4]),
            ("sup_y_min", vec![-0.1; 4]),
            ("sup_y_max", vec![0.1; 4]),
        ]);
        let truth = log(&[
            ("t", vec![0.0, 0.01, 0.015, 0.02, 0.03]),
            ("zmp_x", vec![0.0, 0.05, 0.08, 0.01, f64::NAN]),
            ("zmp_y", vec![0.0, 0.0, 0.0, -0.095, 0.0]),
        ]);
        let m = margin_of(&ctrl, &truth).expect("shared samples");
        // t = 0.015 s has no controller sample: its CoP outside the heel is not compared.
        assert_eq!(m.samples, 3);
        assert!(
            (m.min - 0.005).abs() < 1e-12 && (m.at - 0.02).abs() < 1e-12,
            "{m:?}"
        );
        assert!(
            (m.x - 0.02).abs() < 1e-12 && (m.y - 0.005).abs() < 1e-12,
            "{m:?}"
        );
        // Outside is negative.
        let outside = log(&[
            ("t", vec![0.01]),
            ("zmp_x", vec![0.09]),
            ("zmp_y", vec![0.0]),
        ]);
        let m = margin_of(&ctrl, &outside).expect("one sample");
        assert!((m.min + 0.02).abs() < 1e-12, "{m:?}");
        assert!(margin_of(&ctrl, &log(&[("t", vec![0.5])])).is_none());
    }
}
