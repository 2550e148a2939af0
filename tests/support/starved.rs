//! A real-time test's verdict is the machine's as much as the code's. On a shared 2-core VM the
//! host takes the CPUs now and then (the guest sees it as steal time in /proc/stat) and the
//! test's own processes then miss their deadlines by tens of ms, which no code change can
//! prevent. [`checked_then_timed`] runs such a test's timed checks again while, and only while,
//! their failures come with evidence of that from outside the processes under test; a failure
//! without it stands at once, and the checks that no clock decides are never rerun.

use super::prereq::said_and_listed;
use super::procs::Scratch;
use std::time::{Duration, Instant};

/// Runs of a real-time test in all: a failure with evidence of starvation is followed by
/// another run, up to this many; the last run's verdict stands. (On 2-core CI machines two
/// runs in a row of `tests/bus.rs`' `upc run` were starved, the controller's robot handed back
/// 21 times in 12 s; on an idle machine the same run is handed back 0–3 times.)
pub const ATTEMPTS: usize = 3;

/// The share of the CPUs' time the host took (steal) above which a run counts as starved.
pub const STEAL_STARVED: f64 = 0.05;

/// Before another run: wait (at most this long) for a second with less than half the starved
/// share of steal.
const SETTLE_MAX: Duration = Duration::from_secs(30);

/// CPU time counters summed over all CPUs (ticks): (steal, total), from /proc/stat's first line.
fn cpu_ticks() -> Option<(u64, u64)> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let fields: Vec<u64> = stat
        .lines()
        .next()?
        .split_whitespace()
        .skip(1)
        .take(8)
        .map(|v| v.parse().ok())
        .collect::<Option<_>>()?;
    (fields.len() == 8).then(|| (fields[7], fields.iter().sum()))
}

/// The steal share between two readings of [`cpu_ticks`].
fn steal_share(from: Option<(u64, u64)>, to: Option<(u64, u64)>) -> Option<f64> {
    let ((s0, t0), (s1, t1)) = (from?, to?);
    (t1 > t0).then(|| (s1.saturating_sub(s0)) as f64 / (t1 - t0) as f64)
}

/// Wait for a second of the machine with little steal, at most [`SETTLE_MAX`]; returns how
/// long it waited.
fn settle() -> Duration {
    let start = Instant::now();
    while start.elapsed() < SETTLE_MAX {
        let before = cpu_ticks();
        std::thread::sleep(Duration::from_secs(1));
        if steal_share(before, cpu_ticks()).is_none_or(|s| s < STEAL_STARVED / 2.0) {
            break;
        }
    }
    start.elapsed()
}

/// A real-time test in three parts: `run` starts the processes and collects what they left
/// (a failure there reruns on evidence, like a timed check); `correct` checks what no clock
/// decides (CRC, mode echo, clamps, refusals, counts of events the test caused), once, never
/// rerun: its failure stands at once; `timed` checks what the machine's timing decides, and
/// runs again only on evidence from outside the processes under test: the host's steal, a
/// stall of the test harness itself (a thread of this process oversleeping [`HARNESS_STALL`]),
/// or what `starved` finds in what the test's own peers left (never a process under test
/// excusing itself). Each rerun is said and listed with its first failure.
pub fn checked_then_timed<T>(
    name: &str,
    starved: impl Fn(&Scratch) -> Option<String>,
    run: impl Fn(&Scratch) -> T,
    correct: impl Fn(&T),
    timed: impl Fn(&T),
) {
    // The failed runs' directories stay until the verdict (for a look if it is a failure).
    let mut runs: Vec<Scratch> = Vec::with_capacity(ATTEMPTS);
    for attempt in 1..=ATTEMPTS {
        runs.push(Scratch::new(&if attempt == 1 {
            name.to_string()
        } else {
            format!("{name}_again{attempt}")
        }));
        let scratch = &runs[attempt - 1];
        let before = cpu_ticks();
        let watch = HarnessWatch::start();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let out = run(scratch);
            (correct)(&out);
            out
        }));
        let out = match outcome {
            Ok(out) => out,
            Err(f) if attempt < ATTEMPTS => {
                let stall = watch.stop();
                let Some(why) = outside_evidence(before, stall, || starved(scratch)) else {
                    std::panic::resume_unwind(f);
                };
                said_rerun(name, attempt, &why, &*f);
                continue;
            }
            Err(f) => std::panic::resume_unwind(f),
        };
        if attempt == ATTEMPTS {
            timed(&out);
            return;
        }
        let checked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| timed(&out)));
        let stall = watch.stop();
        let Err(failure) = checked else {
            return;
        };
        let Some(why) = outside_evidence(before, stall, || starved(scratch)) else {
            std::panic::resume_unwind(failure);
        };
        said_rerun(name, attempt, &why, &*failure);
    }
}

/// A stall of the test harness's own watch thread above which the machine starved the test.
pub const HARNESS_STALL: Duration = Duration::from_millis(20);

/// A thread of the test process that sleeps 1 ms at a time and keeps its worst oversleep:
/// when the harness itself stalls, the machine (not the code under test) took the CPUs.
struct HarnessWatch {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<Duration>,
}

impl HarnessWatch {
    fn start() -> Self {
        use std::sync::atomic::Ordering;
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = std::sync::Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let mut worst = Duration::ZERO;
            while !flag.load(Ordering::Relaxed) {
                let t = Instant::now();
                std::thread::sleep(Duration::from_millis(1));
                worst = worst.max(t.elapsed().saturating_sub(Duration::from_millis(1)));
            }
            worst
        });
        Self { stop, thread }
    }

    fn stop(self) -> Duration {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap_or(Duration::ZERO)
    }
}

/// Why a failed run may be the machine's: the host's steal, the harness's own stall, or what
/// the test's own peers left (`peers`); `None`: the failure stands.
fn outside_evidence(
    before: Option<(u64, u64)>,
    stall: Duration,
    peers: impl FnOnce() -> Option<String>,
) -> Option<String> {
    let steal = steal_share(before, cpu_ticks()).unwrap_or(0.0);
    if steal > STEAL_STARVED {
        return Some(format!("the host took {:.1} % of the CPUs", 100.0 * steal));
    }
    if stall > HARNESS_STALL {
        return Some(format!(
            "the test harness itself stalled {:.1} ms",
            stall.as_secs_f64() * 1e3
        ));
    }
    peers()
}

/// Says and lists a rerun after `attempt` failed with `failure` for `why`, once the machine
/// has settled.
fn said_rerun(name: &str, attempt: usize, why: &str, failure: &(dyn std::any::Any + Send)) {
    let waited = settle();
    let first = failure
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| failure.downcast_ref::<&str>().copied())
        .unwrap_or("(a panic without a message)");
    said_and_listed(
        &format!(
            "RERUN {name}: failed on a starved machine ({why}); run {} of {ATTEMPTS} after {:.0} s \
         of settling. The failure: {}",
            attempt + 1,
            waited.as_secs_f64(),
            first.replace('\n', " | ")
        ),
        &rerun_list(),
    );
}

/// Where reruns are listed, one line each with the first failure (`.ci/run` prints them).
fn rerun_list() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rerun-tests.txt")
}
