//! A real-time test's verdict is the machine's as much as the code's. On a shared 2-core VM the
//! host takes the CPUs now and then (the guest sees it as steal time in /proc/stat) and the
//! test's own processes then miss their deadlines by tens of ms, which no code change can
//! prevent. [`again_if_starved`] runs such a test again while, and only while, its failures come
//! with evidence of that; a failure without it stands at once.

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

/// Run `body` in a scratch directory named `name`. If it fails and either `starved` finds, in
/// what the run left there, that the machine starved the test's own processes, or the host
/// took more than [`STEAL_STARVED`] of the CPUs during the run, it runs again in a fresh one
/// once the machine has settled, saying so, up to [`ATTEMPTS`] runs; the last verdict stands.
pub fn again_if_starved(
    name: &str,
    starved: impl Fn(&Scratch) -> Option<String>,
    body: impl Fn(&Scratch),
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
        if attempt == ATTEMPTS {
            body(scratch);
            return;
        }
        let before = cpu_ticks();
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(scratch)));
        let Err(failure) = run else {
            return;
        };
        let steal = steal_share(before, cpu_ticks()).unwrap_or(0.0);
        let why = match starved(scratch) {
            Some(why) => why,
            None if steal > STEAL_STARVED => {
                format!("the host took {:.1} % of the CPUs", 100.0 * steal)
            }
            None => std::panic::resume_unwind(failure),
        };
        let waited = settle();
        let first = failure
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| failure.downcast_ref::<&str>().copied())
            .unwrap_or("(a panic without a message)");
        said_rerun(&format!(
            "RERUN {name}: failed on a machine that starved the test's own processes ({why}, \
             steal {:.1} % during the run); run {} of {ATTEMPTS} after {:.0} s of settling. \
             The failure: {}",
            100.0 * steal,
            attempt + 1,
            waited.as_secs_f64(),
            first.replace('\n', " | ")
        ));
    }
}

/// Where reruns are listed, one line each with the first failure (`.ci/run` prints them).
fn rerun_list() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rerun-tests.txt")
}

/// Says a rerun past the harness's capture (which hides `eprintln!` of a passing test) and
/// lists it.
fn said_rerun(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(rerun_list())
    {
        let _ = writeln!(f, "{line}");
    }
}
