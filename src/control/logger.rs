//! The controller's rerun log, written by its own thread. The loop hands records over a bounded
//! channel with `try_send` (a full channel drops the record and counts it): logging never blocks
//! the real-time loop. In lockstep (`lossless`) tick records wait for room instead, so that the
//! CSV of a rerun holds the same rows. Horizon-sized plan records come from a small pool of preallocated buffers that the
//! logger returns after use, so the loop does not allocate either.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, sync_channel};
use std::thread::JoinHandle;

use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, TimeSeriesView, Vertical,
};

use super::TickRecord;

/// Per-tick figures beyond the controller core's record.
#[derive(Debug, Clone, Copy, Default)]
pub struct TickLog {
    pub core: TickRecord,
    /// Tick compute time (s).
    pub tick_time: f64,
    /// Latest C2 result: eq. (26) cost (docs/gain_search.md), nominal cost, iterations, solve
    /// time (s).
    pub c2_cost: f64,
    pub c2_nominal_cost: f64,
    pub c2_iterations: u32,
    pub c2_solve_time: f64,
}

/// The predicted horizon at one tick (decimated).
#[derive(Debug, Clone)]
pub struct PlanLog {
    pub time: f64,
    pub com_height: f64,
    pub zmp: Vec<[f32; 2]>,
    pub com: Vec<[f32; 2]>,
    pub f_dis: Vec<f32>,
    pub kp: Vec<f32>,
}

// A tick record is copied by value (no allocation); plans travel boxed from the pool.
#[allow(clippy::large_enum_variant)]
enum Item {
    Tick(TickLog),
    Plan(Box<PlanLog>),
}

/// How often the logger thread takes the queued records (the queue holds 1024 ticks' worth).
const DRAIN_PERIOD: std::time::Duration = std::time::Duration::from_millis(20);

pub struct ControlLogger {
    tx: Option<SyncSender<Item>>,
    free: Receiver<Box<PlanLog>>,
    handle: Option<JoinHandle<()>>,
    pub dropped: Arc<AtomicU64>,
    lossless: bool,
}

impl ControlLogger {
    /// Start the logger writing `path` with the given recording id (shared with the simulator's
    /// log so both open on one timeline).
    pub fn start(
        path: &std::path::Path,
        csv: Option<&std::path::Path>,
        recording_id: &str,
        live: Option<&str>,
        horizon: usize,
        lossless: bool,
    ) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        let rec = crate::recording::open(path, Some(recording_id), live)?;
        send_blueprint(&rec);
        let mut csv = match csv {
            Some(p) => {
                let mut w = std::io::BufWriter::new(std::fs::File::create(p)?);
                writeln!(w, "{CSV_HEADER}")?;
                Some(w)
            }
            None => None,
        };
        let (tx, rx) = sync_channel::<Item>(1024);
        let (free_tx, free) = sync_channel::<Box<PlanLog>>(4);
        for _ in 0..3 {
            let plan = PlanLog {
                time: 0.0,
                com_height: 0.0,
                zmp: vec![[0.0; 2]; horizon],
                com: vec![[0.0; 2]; horizon],
                f_dis: vec![0.0; horizon],
                kp: vec![0.0; horizon],
            };
            let _ = free_tx.try_send(Box::new(plan));
        }
        let handle = std::thread::Builder::new()
            .name("upc-ctl-log".into())
            .spawn(move || {
                if !lossless {
                    crate::realtime::lower_priority(15);
                }
                crate::realtime::drain_periodically(&rx, DRAIN_PERIOD, |item| match item {
                    Item::Tick(t) => {
                        log_tick(&rec, &t);
                        if let Some(w) = csv.as_mut() {
                            let _ = write_csv(w, &t);
                        }
                    }
                    Item::Plan(p) => {
                        log_plan(&rec, &p);
                        let _ = free_tx.try_send(p);
                    }
                });
                if let Some(w) = csv.as_mut() {
                    let _ = w.flush();
                }
                let _ = rec.flush_blocking();
            })?;
        Ok(Self {
            tx: Some(tx),
            free,
            handle: Some(handle),
            dropped: Arc::new(AtomicU64::new(0)),
            lossless,
        })
    }

    pub fn tick(&self, t: TickLog) {
        let Some(tx) = &self.tx else { return };
        let sent = if self.lossless {
            tx.send(Item::Tick(t)).is_ok()
        } else {
            tx.try_send(Item::Tick(t)).is_ok()
        };
        if !sent {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Borrow a free plan buffer, let `fill` write it, queue it. Skipped if none is free.
    pub fn plan(&self, fill: impl FnOnce(&mut PlanLog)) {
        match self.free.try_recv() {
            Ok(mut p) => {
                fill(&mut p);
                if let Some(tx) = &self.tx
                    && tx.try_send(Item::Plan(p)).is_err()
                {
                    self.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Flush and close the file (the last tick is in it once this returns).
    pub fn finish(mut self) {
        self.tx.take();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

impl Drop for ControlLogger {
    fn drop(&mut self) {
        self.tx.take();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Columns of `controller.csv`; readers go by name (`upc compare`), so columns may be added.
pub const CSV_HEADER: &str = "t,com_x,com_y,com_z,zmp_ref_x,zmp_ref_y,zmp_pred_x,zmp_pred_y,zmp_meas_x,zmp_meas_y,hand_err,kp,kd,f_ext_x,f_ext_y,f_ext_z,f_dis_x,f_dis_y,f_dis_z,hand_x,hand_y,hand_z,sup_x_min,sup_x_max,sup_y_min,sup_y_max,tick_us,wbc_us,wbc_solved,c2_cost,c2_iterations,f_meas_x,f_meas_y,f_meas_z,f_raw_x,f_raw_y,f_raw_z,corr_factor,corr_shift,corr_offset_x,corr_offset_y,corr_offset_z,corr_contradicted,f_obs_x,f_obs_y,est_x,est_y,est_z,est_vx,est_vy,est_vz,est_roll,est_pitch,est_yaw,est_innovation,corr_trend_x,corr_trend_y,guard_x,guard_y,capture_x,capture_y,corr_weight,corr_error_forecast,corr_error_measured";

fn write_csv(w: &mut impl Write, t: &TickLog) -> std::io::Result<()> {
    let c = &t.core;
    // The base estimate's columns are NaN when the base was measured.
    let b = c.base.unwrap_or(crate::estimation::BaseEstimate::UNKNOWN);
    writeln!(
        w,
        "{:.4},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.2},{:.2},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.1},{:.1},{},{:.5e},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.3},{:.3},{:.3},{},{:.3},{:.3},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.3},{:.2},{:.2},{:.3},{:.3},{:.5},{:.5},{:.4},{:.3},{:.3}",
        c.time,
        c.com[0],
        c.com[1],
        c.com[2],
        c.zmp_ref[0],
        c.zmp_ref[1],
        c.zmp_pred[0],
        c.zmp_pred[1],
        c.zmp_meas[0],
        c.zmp_meas[1],
        c.hand_err,
        c.kp,
        c.kd,
        c.f_ext[0],
        c.f_ext[1],
        c.f_ext[2],
        c.f_dis[0],
        c.f_dis[1],
        c.f_dis[2],
        c.hand_pos[0],
        c.hand_pos[1],
        c.hand_pos[2],
        c.support[0][0],
        c.support[0][1],
        c.support[1][0],
        c.support[1][1],
        t.tick_time * 1e6,
        c.wbc_time * 1e6,
        u8::from(c.wbc_solved),
        t.c2_cost,
        t.c2_iterations,
        c.f_meas[0],
        c.f_meas[1],
        c.f_meas[2],
        c.f_raw[0],
        c.f_raw[1],
        c.f_raw[2],
        c.correction.factor,
        c.correction.shift,
        c.correction.offset[0],
        c.correction.offset[1],
        c.correction.offset[2],
        u8::from(c.correction.contradicted),
        c.f_obs[0],
        c.f_obs[1],
        b.position[0],
        b.position[1],
        b.position[2],
        b.velocity[0],
        b.velocity[1],
        b.velocity[2],
        b.rpy[0],
        b.rpy[1],
        b.rpy[2],
        b.innovation,
        c.correction.trend[0],
        c.correction.trend[1],
        c.viability_scale[0],
        c.viability_scale[1],
        c.capture_point[0],
        c.capture_point[1],
        c.correction.weight,
        c.correction.error_forecast,
        c.correction.error_measured,
    )
}

fn send_blueprint(rec: &rerun::RecordingStream) {
    let blueprint = Blueprint::new(Horizontal::new([
        Spatial3DView::new("3D").with_origin("/").into(),
        Vertical::new([
            TimeSeriesView::new("ZMP x")
                .with_contents(["/controller/zmp/**"])
                .into(),
            TimeSeriesView::new("hand error")
                .with_contents(["/controller/hand/**"])
                .into(),
            TimeSeriesView::new("hand force: forecast and measured")
                .with_contents(["/controller/forecast/**"])
                .into(),
            TimeSeriesView::new("gains")
                .with_contents(["/controller/gains/**"])
                .into(),
            TimeSeriesView::new("timing")
                .with_contents(["/controller/timing/**", "/controller/c2/**"])
                .into(),
        ])
        .into(),
    ]));
    if let Err(e) = blueprint.send(
        rec,
        BlueprintActivation {
            make_active: true,
            make_default: true,
        },
    ) {
        tracing::warn!("cannot write the rerun blueprint: {e}");
    }
}

fn scalar(rec: &rerun::RecordingStream, path: &str, v: f64) {
    let _ = rec.log(path, &rerun::Scalars::single(v));
}

fn log_tick(rec: &rerun::RecordingStream, t: &TickLog) {
    let c = &t.core;
    rec.set_duration_secs("sim_time", c.time);
    scalar(rec, "controller/zmp/reference_x", c.zmp_ref[0]);
    scalar(rec, "controller/zmp/predicted_x", c.zmp_pred[0]);
    scalar(rec, "controller/zmp/measured_x", c.zmp_meas[0]);
    scalar(rec, "controller/zmp/reference_y", c.zmp_ref[1]);
    scalar(rec, "controller/zmp/predicted_y", c.zmp_pred[1]);
    scalar(rec, "controller/zmp/measured_y", c.zmp_meas[1]);
    scalar(rec, "controller/com/x", c.com[0]);
    scalar(rec, "controller/com/y", c.com[1]);
    scalar(rec, "controller/hand/error", c.hand_err);
    scalar(rec, "controller/hand/f_ext_x", c.f_ext[0]);
    scalar(rec, "controller/hand/f_dis_x", c.f_dis[0]);
    // The forecast as received, as corrected, against the measured force; the correction's
    // estimate (docs/forecast_correction.md).
    scalar(rec, "controller/forecast/received_x", c.f_raw[0]);
    scalar(rec, "controller/forecast/corrected_x", c.f_ext[0]);
    scalar(rec, "controller/forecast/measured_x", c.f_meas[0]);
    scalar(rec, "controller/forecast/received_y", c.f_raw[1]);
    scalar(rec, "controller/forecast/corrected_y", c.f_ext[1]);
    scalar(rec, "controller/forecast/measured_y", c.f_meas[1]);
    scalar(rec, "controller/correction/factor", c.correction.factor);
    scalar(rec, "controller/correction/trend_x", c.correction.trend[0]);
    scalar(rec, "controller/correction/weight", c.correction.weight);
    scalar(
        rec,
        "controller/correction/error_forecast",
        c.correction.error_forecast,
    );
    scalar(
        rec,
        "controller/correction/error_measured",
        c.correction.error_measured,
    );
    scalar(rec, "controller/viability/scale_x", c.viability_scale[0]);
    scalar(rec, "controller/viability/scale_y", c.viability_scale[1]);
    scalar(rec, "controller/viability/capture_x", c.capture_point[0]);
    scalar(
        rec,
        "controller/correction/shift_ms",
        c.correction.shift * 1e3,
    );
    scalar(
        rec,
        "controller/correction/offset_x",
        c.correction.offset[0],
    );
    scalar(
        rec,
        "controller/correction/contradicted",
        f64::from(u8::from(c.correction.contradicted)),
    );
    if let Some(b) = &c.base {
        // The base estimate (docs/estimation.md); the truth is in the simulator's recording.
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            scalar(
                rec,
                &format!("controller/base/position_{axis}"),
                b.position[k],
            );
            scalar(
                rec,
                &format!("controller/base/velocity_{axis}"),
                b.velocity[k],
            );
        }
        scalar(rec, "controller/base/roll_deg", b.rpy[0].to_degrees());
        scalar(rec, "controller/base/pitch_deg", b.rpy[1].to_degrees());
        scalar(rec, "controller/base/yaw_deg", b.rpy[2].to_degrees());
        scalar(rec, "controller/base/innovation", b.innovation);
        scalar(
            rec,
            "controller/base/stance_left",
            f64::from(u8::from(b.stance[0])),
        );
        scalar(
            rec,
            "controller/base/stance_right",
            f64::from(u8::from(b.stance[1])),
        );
    }
    scalar(rec, "controller/observer/f_x", c.f_obs[0]);
    scalar(rec, "controller/observer/f_y", c.f_obs[1]);
    scalar(rec, "controller/gains/kp", c.kp);
    scalar(rec, "controller/gains/kd", c.kd);
    scalar(rec, "controller/timing/tick_us", t.tick_time * 1e6);
    scalar(rec, "controller/timing/wbc_us", c.wbc_time * 1e6);
    scalar(rec, "controller/c2/cost", t.c2_cost);
    scalar(rec, "controller/c2/nominal_cost", t.c2_nominal_cost);
    scalar(rec, "controller/c2/iterations", t.c2_iterations as f64);
    scalar(rec, "controller/c2/solve_ms", t.c2_solve_time * 1e3);
}

fn log_plan(rec: &rerun::RecordingStream, p: &PlanLog) {
    rec.set_duration_secs("sim_time", p.time);
    let zmp: Vec<[f32; 3]> = p.zmp.iter().map(|z| [z[0], z[1], 0.0]).collect();
    let com: Vec<[f32; 3]> = p
        .com
        .iter()
        .map(|c| [c[0], c[1], p.com_height as f32])
        .collect();
    let _ = rec.log("controller/plan/zmp", &rerun::LineStrips3D::new([zmp]));
    let _ = rec.log("controller/plan/com", &rerun::LineStrips3D::new([com]));
    let _ = rec.log(
        "controller/plan/f_dis_x",
        &rerun::BarChart::new(p.f_dis.clone()),
    );
    let _ = rec.log("controller/plan/kp", &rerun::BarChart::new(p.kp.clone()));
}
