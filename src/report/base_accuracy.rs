//! The base estimate's error against the plant's truth, from a lockstep run's logs: the
//! controller's `controller.csv` (`est_*` columns) and the plant's `sim.csv` (`base_*`), joined
//! on their common sample times.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::UnitQuaternion;

use super::csv::{Columns, Reading};

/// RMS and largest error over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BaseAccuracy {
    /// Samples compared.
    pub samples: usize,
    /// Base position (m): 3-D error, RMS and max; height error, max and at the last sample.
    pub position_rms: f64,
    pub position_max: f64,
    pub height_max: f64,
    pub height_last: f64,
    /// Base linear velocity (m/s, world): RMS and max of the 3-D error.
    pub velocity_rms: f64,
    pub velocity_max: f64,
    /// Orientation (deg): the angle of the rotation between estimate and truth, RMS and max;
    /// the tilt (roll and pitch) alone, RMS.
    pub orientation_rms_deg: f64,
    pub orientation_max_deg: f64,
    pub tilt_rms_deg: f64,
}

/// Samples of a log by time in ms (both logs print t to 0.1 ms).
pub(super) fn by_time(log: &Columns) -> Option<HashMap<i64, usize>> {
    Some(
        log.get("t")?
            .iter()
            .enumerate()
            .map(|(i, &t)| ((t * 1e3).round() as i64, i))
            .collect(),
    )
}

/// The estimate's error, or `None` when the logs hold no estimate (a measured base) or no truth.
pub fn base_accuracy(controller_csv: &Path, sim_csv: &Path) -> Option<BaseAccuracy> {
    let (c, s) = read_both(controller_csv, sim_csv)?;
    accuracy_of(&c, &s)
}

/// Both logs, read leniently; `None` if either cannot be read.
pub(super) fn read_both(controller_csv: &Path, sim_csv: &Path) -> Option<(Columns, Columns)> {
    Some((
        Columns::read(controller_csv, Reading::Lenient).ok()?,
        Columns::read(sim_csv, Reading::Lenient).ok()?,
    ))
}

fn accuracy_of(est: &Columns, truth: &Columns) -> Option<BaseAccuracy> {
    let get = |m: &Columns, names: [&str; 9]| -> Option<Vec<[f64; 9]>> {
        let cols: Vec<&Vec<f64>> = names.iter().map(|n| m.get(n)).collect::<Option<_>>()?;
        let n = cols.iter().map(|c| c.len()).min()?;
        Some(
            (0..n)
                .map(|i| std::array::from_fn(|k| cols[k][i]))
                .collect(),
        )
    };
    let e = get(
        est,
        [
            "est_x",
            "est_y",
            "est_z",
            "est_vx",
            "est_vy",
            "est_vz",
            "est_roll",
            "est_pitch",
            "est_yaw",
        ],
    )?;
    let t = get(
        truth,
        [
            "base_x",
            "base_y",
            "base_z",
            "base_vx",
            "base_vy",
            "base_vz",
            "base_roll",
            "base_pitch",
            "base_yaw",
        ],
    )?;
    // Samples by time in ms (both logs print t to 0.1 ms).
    let key = |x: f64| (x * 1e3).round() as i64;
    let truth_at: HashMap<i64, usize> = truth
        .get("t")?
        .iter()
        .enumerate()
        .map(|(i, &x)| (key(x), i))
        .collect();
    let mut a = BaseAccuracy::default();
    let (mut p2, mut v2, mut o2, mut tilt2) = (0.0, 0.0, 0.0, 0.0);
    for (i, &time) in est.get("t")?.iter().enumerate() {
        let (Some(ei), Some(&j)) = (e.get(i), truth_at.get(&key(time))) else {
            continue;
        };
        let ti = t[j];
        if !ei.iter().chain(ti.iter()).all(|x| x.is_finite()) {
            continue;
        }
        let norm = |o: usize| ((0..3).map(|k| (ei[o + k] - ti[o + k]).powi(2)).sum::<f64>()).sqrt();
        let (dp, dv) = (norm(0), norm(3));
        let r = |x: &[f64; 9]| UnitQuaternion::from_euler_angles(x[6], x[7], x[8]);
        let rel = r(ei).inverse() * r(&ti);
        let angle = rel.angle().to_degrees();
        // The tilt: the angle between the two frames' z axes.
        let tilt = (r(ei) * nalgebra::Vector3::z())
            .angle(&(r(&ti) * nalgebra::Vector3::z()))
            .to_degrees();
        let dz = ei[2] - ti[2];
        a.samples += 1;
        p2 += dp * dp;
        v2 += dv * dv;
        o2 += angle * angle;
        tilt2 += tilt * tilt;
        a.position_max = a.position_max.max(dp);
        a.velocity_max = a.velocity_max.max(dv);
        a.orientation_max_deg = a.orientation_max_deg.max(angle);
        a.height_max = a.height_max.max(dz.abs());
        a.height_last = dz;
    }
    if a.samples == 0 {
        return None;
    }
    let n = a.samples as f64;
    a.position_rms = (p2 / n).sqrt();
    a.velocity_rms = (v2 / n).sqrt();
    a.orientation_rms_deg = (o2 / n).sqrt();
    a.tilt_rms_deg = (tilt2 / n).sqrt();
    Some(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::csv::tests::lenient;

    /// A known offset in position, velocity and yaw is what the comparison reports; rows
    /// without an estimate (NaN) or without a truth sample are skipped.
    #[test]
    fn the_error_of_known_offsets() {
        let est = "t,est_x,est_y,est_z,est_vx,est_vy,est_vz,est_roll,est_pitch,est_yaw\n\
                   0.0100,0.003,0,0.5,0.02,0,0,0,0,0.01\n\
                   0.0200,0.003,0,0.5,0.02,0,0,0,0,0.01\n\
                   0.0300,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN\n\
                   0.0400,9,9,9,9,9,9,0,0,0\n";
        let truth = "t,base_x,base_y,base_z,base_vx,base_vy,base_vz,base_roll,base_pitch,base_yaw\n\
                     0.0100,0,0,0.5,0,0,0,0,0,0\n\
                     0.0200,0,0,0.5,0,0,0,0,0,0\n\
                     0.0300,0,0,0.5,0,0,0,0,0,0\n";
        let a = accuracy_of(&lenient(est), &lenient(truth)).unwrap();
        assert_eq!(a.samples, 2);
        assert!((a.position_rms - 0.003).abs() < 1e-12 && (a.velocity_max - 0.02).abs() < 1e-12);
        assert!((a.orientation_rms_deg - 0.01f64.to_degrees()).abs() < 1e-9);
        assert!(a.tilt_rms_deg < 1e-6 && a.height_max == 0.0);
    }
}
