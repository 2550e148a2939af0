//! The controller's rerun log, written by its own thread. The loop hands records over a bounded
//! channel with `try_send` (a full channel drops the record and counts it): logging never blocks
//! the real-time loop. In lockstep (`lossless`) tick and plan records wait for room instead, so
//! that a rerun logs the same records. Horizon-sized plan records come from a small pool of
//! preallocated buffers that the logger returns after use, so the loop does not allocate either.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, TimeSeriesView, Vertical,
};

use crate::record::{Column, Record};

/// One tick's record (the core's, the parts' and the loop's columns) at plant time `time`.
#[derive(Debug, Clone, Copy)]
pub struct TickLog {
    pub time: f64,
    pub record: Record,
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
        columns: Vec<&'static Column>,
    ) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        let rec = crate::recording::open(path, Some(recording_id), live)?;
        send_blueprint(&rec);
        let mut csv = match csv {
            Some(p) => {
                let mut w = std::io::BufWriter::new(std::fs::File::create(p)?);
                let names: Vec<&str> = columns.iter().map(|c| c.name).collect();
                writeln!(w, "{}", names.join(","))?;
                Some(w)
            }
            None => None,
        };
        let dropped = Arc::new(AtomicU64::new(0));
        let misfits = dropped.clone();
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
                            // A record whose columns are not the header's is not written
                            // under it (counted as dropped): a column and its value never part.
                            let fits = t
                                .record
                                .iter()
                                .map(|(c, _)| c.name)
                                .eq(columns.iter().map(|c| c.name));
                            if fits {
                                let _ = t.record.write_csv_row(w);
                            } else {
                                misfits.fetch_add(1, Ordering::Relaxed);
                            }
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
            dropped,
            lossless,
        })
    }

    pub fn tick(&self, t: TickLog) {
        self.queue(Item::Tick(t));
    }

    /// Hands `item` to the logger thread: in lockstep it waits for room, in real time a full
    /// channel drops it (counted).
    fn queue(&self, item: Item) {
        let Some(tx) = &self.tx else { return };
        let sent = if self.lossless {
            tx.send(item).is_ok()
        } else {
            tx.try_send(item).is_ok()
        };
        if !sent {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Borrow a free plan buffer, let `fill` write it, queue it. Skipped if none is free; in
    /// lockstep it waits for the logger to return one, as tick records wait for room, so that a
    /// rerun logs the same plans.
    pub fn plan(&self, fill: impl FnOnce(&mut PlanLog)) {
        let buffer = if self.lossless {
            self.free.recv().ok()
        } else {
            self.free.try_recv().ok()
        };
        let Some(mut p) = buffer else {
            self.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        fill(&mut p);
        self.queue(Item::Plan(p));
    }

    /// Flush and close the file (the last tick is in it once this returns).
    pub fn finish(mut self) {
        crate::realtime::leave_background();
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

/// One CSV row: each value in its column's format.
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
            TimeSeriesView::new("forecast correction and guard")
                .with_contents(["/controller/correction/**", "/controller/viability/**"])
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

/// The plotted columns, each a scalar at `controller/<plot>`.
fn log_tick(rec: &rerun::RecordingStream, t: &TickLog) {
    rec.set_duration_secs("sim_time", t.time);
    for (c, v) in t.record.iter() {
        if let Some(path) = c.plot {
            scalar(rec, &format!("controller/{path}"), v);
        }
    }
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
