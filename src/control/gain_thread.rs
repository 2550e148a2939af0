//! C2's gain search in its own lower-priority thread. The control loop offers snapshots and
//! takes time-stamped schedules through wait-free triple buffers. In real time it never waits
//! for C2 and takes the newest schedule each tick. In lockstep (with a non-zero
//! `controller.lockstep_c2_wait`) the schedule answering a snapshot applies exactly `c2_every`
//! ticks after it, the loop waiting for it (bounded): the tick a schedule reaches the loop is then a function of the
//! tick count, not of the machine's timing. A schedule older than the horizon, or a dead
//! worker, means the nominal gains (C1).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::{Matrix3, Vector3};
use triple_buffer::{Input, Output, triple_buffer};

use crate::config::Config;
use crate::preview::gain_search::{GainSearch, GainSearchInputs};
use crate::preview::{AxisState, GainSchedule, HandState};

/// What the gain search needs from one control tick (horizon samples at k+1…k+N).
#[derive(Debug, Clone)]
pub struct GainSnapshot {
    /// Simulated time of the tick (s); 0 and `seq` 0 mean "no snapshot yet".
    pub time: f64,
    pub seq: u64,
    pub com: [AxisState; 2],
    pub hand: HandState,
    pub m_e: Matrix3<f64>,
    /// The held object's path the previewer keeps the hand on (HP-1): its direction and mass.
    pub held_path: Option<(Vector3<f64>, f64)>,
    pub zmp_ref: Vec<[f64; 2]>,
    pub hand_desired: Vec<HandState>,
    pub f_ext: Vec<[f64; 3]>,
    pub applied: [f64; 2],
}

impl GainSnapshot {
    pub fn empty(n: usize) -> Self {
        Self {
            time: 0.0,
            seq: 0,
            com: [Vector3::zeros(); 2],
            hand: HandState::default(),
            m_e: Matrix3::identity(),
            held_path: None,
            zmp_ref: vec![[0.0; 2]; n],
            hand_desired: vec![HandState::default(); n],
            f_ext: vec![[0.0; 3]; n],
            applied: [0.0; 2],
        }
    }
}

/// A gain schedule with the time of the snapshot it was computed from.
#[derive(Debug, Clone)]
pub struct StampedSchedule {
    /// Snapshot time (s): `schedule` sample i applies at `time + (i+1)·T`.
    pub time: f64,
    /// Snapshot sequence number; 0 = none yet.
    pub seq: u64,
    pub schedule: GainSchedule,
    pub cost: f64,
    pub nominal_cost: f64,
    pub iterations: u32,
    pub solve_time: f64,
}

/// Counters shared with the worker.
#[derive(Debug, Default)]
pub struct GainWorkerStats {
    /// Sequence number of the last snapshot the worker finished with (solved or failed).
    pub processed: AtomicU64,
    pub solves: AtomicU64,
    pub failures: AtomicU64,
    pub panics: AtomicU64,
}

/// One gain search from a snapshot, as run by the C2 thread. [`GainSearch`] is the one used in
/// production; tests put a failing, panicking or slow one in its place with
/// [`GainHandoff::spawn_with`] to exercise the loop's fallback to the nominal gains.
pub trait GainSolver: Send {
    /// Search from `snap`, warm-started from the last result shifted by `shift` preview steps;
    /// on success fill `out` (schedule, costs, iterations, solve time) without allocating.
    fn solve(
        &mut self,
        snap: &GainSnapshot,
        shift: usize,
        out: &mut StampedSchedule,
    ) -> Result<(), crate::preview::PreviewError>;
    /// Forget the warm start (after a failure or a panic).
    fn reset(&mut self);
}

impl GainSolver for GainSearch {
    fn solve(
        &mut self,
        snap: &GainSnapshot,
        shift: usize,
        out: &mut StampedSchedule,
    ) -> Result<(), crate::preview::PreviewError> {
        self.set_effective_mass(snap.m_e)?;
        self.set_held_path(snap.held_path);
        let inputs = GainSearchInputs {
            com: snap.com,
            zmp_ref: &snap.zmp_ref,
            hand: snap.hand,
            hand_desired: &snap.hand_desired,
            f_ext: &snap.f_ext,
            applied: snap.applied,
        };
        let report = self.search(&inputs, shift)?;
        out.schedule.kp.copy_from_slice(&self.schedule().kp);
        out.schedule.kd.copy_from_slice(&self.schedule().kd);
        out.cost = report.cost;
        out.nominal_cost = report.nominal_cost;
        out.iterations = report.iterations as u32;
        out.solve_time = report.elapsed.as_secs_f64();
        Ok(())
    }

    fn reset(&mut self) {
        GainSearch::reset(self);
    }
}

/// When the loop takes a new schedule.
#[derive(Debug, Clone, Copy)]
enum Pickup {
    /// The newest, every tick (real time).
    Newest,
    /// The one answering the snapshot of `every` ticks earlier, waited for up to `wait`; after a
    /// time-out, the newest until the worker has caught up (`behind`).
    Lagged {
        every: u64,
        wait: Duration,
        /// Snapshot seq and the tick (1-based) from which its schedule applies.
        due: Option<(u64, u64)>,
        behind: bool,
    },
}

/// What [`GainHandoff::take_for_tick`] did.
#[derive(Debug, Clone, Copy, Default)]
pub struct PickupReport {
    /// It waited for the worker (lockstep, a schedule due this tick).
    pub waited_for: Option<Duration>,
    /// The wait ended without the schedule (time-out or a dead worker).
    pub timed_out: bool,
}

/// The loop's side of the hand-off.
pub struct GainHandoff {
    snapshots: Input<GainSnapshot>,
    schedules: Output<StampedSchedule>,
    worker: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    pickup: Pickup,
    /// Ticks begun ([`take_for_tick`](Self::take_for_tick) calls) and the last offered seq.
    ticks: u64,
    last_offered: u64,
    pub stats: Arc<GainWorkerStats>,
}

impl GainHandoff {
    /// The summary's counts of C2's searches.
    pub fn counts(&self) -> super::summary::C2Counts {
        super::summary::C2Counts {
            c2_solves: self.stats.solves.load(Ordering::Relaxed),
            c2_failures: self.stats.failures.load(Ordering::Relaxed),
            c2_panics: self.stats.panics.load(Ordering::Relaxed),
        }
    }

    /// Start the worker thread with a gain search on `robot`'s reduced models configured from
    /// `config`.
    pub fn spawn(
        config: &Config,
        robot: &crate::robot::ReducedModel,
    ) -> Result<Self, crate::preview::PreviewError> {
        Self::spawn_with(config, Box::new(GainSearch::from_config(config, robot)?))
    }

    /// Start the worker thread with `solver` (horizon and nominal gains from `config`).
    pub fn spawn_with(
        config: &Config,
        mut solver: Box<dyn GainSolver>,
    ) -> Result<Self, crate::preview::PreviewError> {
        let n = config.preview.horizon;
        let period = config.preview.period;
        let nominal = GainSchedule::constant(n, config.hand.kp, config.nominal_kd(config.hand.kp));
        let (snapshots, mut snap_out) = triple_buffer(&GainSnapshot::empty(n));
        let empty = StampedSchedule {
            time: 0.0,
            seq: 0,
            schedule: nominal,
            cost: 0.0,
            nominal_cost: 0.0,
            iterations: 0,
            solve_time: 0.0,
        };
        let (mut sched_in, schedules) = triple_buffer(&empty);
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(GainWorkerStats::default());
        let (stop_w, stats_w) = (Arc::clone(&stop), Arc::clone(&stats));
        let worker = std::thread::Builder::new()
            .name("upc-c2".into())
            .spawn(move || {
                crate::realtime::lower_priority(10);
                let mut last_time: Option<f64> = None;
                while !stop_w.load(Ordering::Relaxed) {
                    if !snap_out.update() {
                        std::thread::park_timeout(Duration::from_millis(2));
                        continue;
                    }
                    let snap = snap_out.output_buffer();
                    if snap.seq == 0 {
                        continue;
                    }
                    // A snapshot earlier than the last (a restarted simulator) shifts nothing.
                    let shift = last_time.map_or(0, |t| ((snap.time - t) / period).round().max(0.0) as usize);
                    let out = sched_in.input_buffer_mut();
                    let seq = snap.seq;
                    let outcome = catch_unwind(AssertUnwindSafe(|| solver.solve(snap, shift, out)));
                    match outcome {
                        Ok(Ok(())) => {
                            out.time = snap.time;
                            out.seq = snap.seq;
                            sched_in.publish();
                            stats_w.solves.fetch_add(1, Ordering::Relaxed);
                            last_time = Some(snap.time);
                        }
                        Ok(Err(e)) => {
                            stats_w.failures.fetch_add(1, Ordering::Relaxed);
                            tracing::warn!("C2 gain search failed: {e}; C1 keeps the last or nominal gains");
                            solver.reset();
                        }
                        Err(_) => {
                            stats_w.panics.fetch_add(1, Ordering::Relaxed);
                            tracing::error!("C2 gain search panicked; restarting it cold, C1 keeps the nominal gains");
                            solver.reset();
                            last_time = None;
                        }
                    }
                    // After the publish: a loop that sees `processed` reach its snapshot finds
                    // the schedule (or knows the search failed).
                    stats_w.processed.store(seq, Ordering::Release);
                }
            })
            .map_err(|e| crate::preview::PreviewError::Qp(format!("cannot start the C2 thread: {e}")))?;
        Ok(Self {
            snapshots,
            schedules,
            worker: Some(worker),
            stop,
            pickup: if config.controller.mode == crate::config::LoopMode::Lockstep
                && config.controller.lockstep_c2_wait > 0.0
            {
                Pickup::Lagged {
                    every: config.controller.c2_every as u64,
                    wait: Duration::from_secs_f64(config.controller.lockstep_c2_wait),
                    due: None,
                    behind: false,
                }
            } else {
                Pickup::Newest
            },
            ticks: 0,
            last_offered: 0,
            stats,
        })
    }

    /// Offer a snapshot (filled in place, no allocation) and wake the worker. Wait-free.
    pub fn offer(&mut self, fill: impl FnOnce(&mut GainSnapshot)) {
        let snap = self.snapshots.input_buffer_mut();
        fill(snap);
        self.last_offered = snap.seq;
        if let Pickup::Lagged { every, due, .. } = &mut self.pickup {
            *due = Some((snap.seq, self.ticks + *every));
        }
        self.snapshots.publish();
        if let Some(w) = &self.worker {
            w.thread().unpark();
        }
    }

    /// Begin a tick: take the schedule it applies, [`current`](Self::current) until the next
    /// call. Real time: the newest (wait-free). Lockstep: a new one only at the tick it is due,
    /// waiting for the worker if needed.
    pub fn take_for_tick(&mut self) -> PickupReport {
        self.ticks += 1;
        let mut report = PickupReport::default();
        let processed = self.stats.processed.load(Ordering::Acquire);
        let take = match &mut self.pickup {
            Pickup::Newest => true,
            Pickup::Lagged { behind: true, .. } if processed < self.last_offered => true,
            Pickup::Lagged {
                wait, due, behind, ..
            } => {
                *behind = false;
                match *due {
                    Some((seq, at)) if self.ticks >= at => {
                        *due = None;
                        let start = std::time::Instant::now();
                        let done = wait_until_processed(&self.stats, seq, *wait, &self.worker);
                        report.waited_for = Some(start.elapsed());
                        report.timed_out = !done;
                        *behind = !done;
                        true
                    }
                    _ => false,
                }
            }
        };
        if take {
            self.schedules.update();
        }
        report
    }

    /// The newest schedule (seq 0: none yet), taking it now whatever the pick-up policy: for
    /// tests and tools outside the loop. Wait-free.
    pub fn latest(&mut self) -> &StampedSchedule {
        self.schedules.read()
    }

    /// The schedule of the current tick (seq 0: none yet).
    pub fn current(&self) -> &StampedSchedule {
        self.schedules.output_buffer()
    }

    /// Whether the worker thread is still running.
    pub fn alive(&self) -> bool {
        self.worker.as_ref().is_some_and(|w| !w.is_finished())
    }
}

/// Wait until the worker is done with snapshot `seq` (solved or failed), at most `timeout`.
/// False on time-out or a dead worker.
fn wait_until_processed(
    stats: &GainWorkerStats,
    seq: u64,
    timeout: Duration,
    worker: &Option<JoinHandle<()>>,
) -> bool {
    let until = std::time::Instant::now() + timeout;
    loop {
        if stats.processed.load(Ordering::Acquire) >= seq {
            return true;
        }
        if worker.as_ref().is_none_or(|w| w.is_finished()) || std::time::Instant::now() >= until {
            return false;
        }
        std::thread::sleep(Duration::from_micros(20));
    }
}

impl Drop for GainHandoff {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(w) = self.worker.take() {
            w.thread().unpark();
            let _ = w.join();
        }
    }
}
