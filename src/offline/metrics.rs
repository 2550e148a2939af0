//! Run metrics of the reduced-model closed loop.

use serde::Serialize;

/// One step of a run, as written to the CSV.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Row {
    pub t: f64,
    pub com: [f64; 2],
    pub zmp: [f64; 2],
    pub zmp_ref: [f64; 2],
    pub hand_error: f64,
    pub kp: f64,
    pub kd: f64,
    pub f_ext: [f64; 3],
    pub f_dis: [f64; 3],
    /// Controller compute time of the step (s).
    pub solve_time: f64,
}

/// Distance beyond the support edge below which the ZMP counts as inside (m).
pub const SUPPORT_TOLERANCE: f64 = 1e-6;

/// Summary figures of a run.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Metrics {
    /// max ‖p − p_ref‖ (m).
    pub max_zmp_error: f64,
    /// Time the ZMP spends outside the support rectangle (s).
    pub time_outside_support: f64,
    /// Largest distance of the ZMP beyond the support edge (m, 0 if always inside).
    pub max_support_excursion: f64,
    pub hand_rms_error: f64,
    pub hand_peak_error: f64,
    pub solve_p50: f64,
    pub solve_p99: f64,
    pub solve_max: f64,
}

impl Metrics {
    pub fn from_rows(rows: &[Row], period: f64, support: [[f64; 2]; 2]) -> Metrics {
        let mut m = Metrics::default();
        if rows.is_empty() {
            return m;
        }
        let mut sq = 0.0;
        for r in rows {
            let e = ((r.zmp[0] - r.zmp_ref[0]).powi(2) + (r.zmp[1] - r.zmp_ref[1]).powi(2)).sqrt();
            m.max_zmp_error = m.max_zmp_error.max(e);
            let mut out = 0.0f64;
            for a in 0..2 {
                out = out
                    .max(support[a][0] - r.zmp[a])
                    .max(r.zmp[a] - support[a][1]);
            }
            // Interior-point solutions of the constrained mode sit on the bound to ~1e-9 m.
            if out > SUPPORT_TOLERANCE {
                m.time_outside_support += period;
                m.max_support_excursion = m.max_support_excursion.max(out);
            }
            sq += r.hand_error * r.hand_error;
            m.hand_peak_error = m.hand_peak_error.max(r.hand_error);
        }
        m.hand_rms_error = (sq / rows.len() as f64).sqrt();
        let mut times: Vec<f64> = rows.iter().map(|r| r.solve_time).collect();
        times.sort_by(f64::total_cmp);
        let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
        m.solve_p50 = q(0.5);
        m.solve_p99 = q(0.99);
        m.solve_max = q(1.0);
        m
    }
}
