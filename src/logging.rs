//! The processes' diagnostics: `tracing` events written to stderr by a background thread through
//! a bounded, lossy queue, so that no thread that logs — the control loop above all — ever waits
//! on stderr. A pipe nobody drains (a stopped `upc run`, a full journal) used to stall the tick
//! inside its `write`; now the queue fills and further lines are dropped and counted
//! ([`dropped_lines`]; the controller's summary carries the count as `dropped_log_lines`, and
//! the process reports it on stderr at exit when not zero).

use std::io::Write;
use std::sync::OnceLock;

use tracing_appender::non_blocking::{ErrorCounter, NonBlocking, NonBlockingBuilder, WorkerGuard};
use tracing_subscriber::EnvFilter;

/// Lines the queue holds before it drops: several seconds of the loop's worst warning rate, a
/// few MB at most.
pub const QUEUE_LINES: usize = 8192;

static DROPPED: OnceLock<ErrorCounter> = OnceLock::new();

/// A lossy non-blocking writer over `sink` holding up to `lines` lines: a write queues the line
/// (dropping and counting it when the queue is full) and returns; a thread writes them out.
pub fn non_blocking<W: Write + Send + 'static>(
    sink: W,
    lines: usize,
) -> (NonBlocking, WorkerGuard) {
    NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(lines)
        .thread_name("upc-log")
        .finish(sink)
}

/// Keeps the writer thread for the process; dropping it writes out the queue (waiting at most
/// about a second) and reports dropped lines on stderr.
#[must_use = "dropping the guard stops the log writer"]
pub struct LogGuard {
    guard: Option<WorkerGuard>,
}

impl Drop for LogGuard {
    fn drop(&mut self) {
        drop(self.guard.take());
        let n = dropped_lines();
        if n > 0 {
            eprintln!("log: {n} line(s) dropped (stderr was not read fast enough)");
        }
    }
}

/// The log filter without `RUST_LOG`. rustdds logs, at error level, the multicast groups it
/// cannot leave on a loopback without multicast and its shutdown: noise on the bus.
pub const DEFAULT_FILTER: &str = "info,rustdds=error,rustdds::network::udp_listener=off";

/// Installs the global subscriber: `RUST_LOG` (default `info`, with the DDS library's own
/// chatter at `error`: it reports locators and multicast sockets it does not use as errors
/// ([`DEFAULT_FILTER`])), colours on a terminal only, lines to stderr through [`non_blocking`].
/// Keep the guard for the whole process.
pub fn init_stderr() -> LogGuard {
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let (writer, guard) = non_blocking(std::io::stderr(), QUEUE_LINES);
    let counter = writer.error_counter();
    let installed = tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_FILTER)),
        )
        .with_writer(writer)
        // Colours on a terminal only: `upc run` and systemd send the processes' logs to files.
        .with_ansi(ansi)
        .try_init()
        .is_ok();
    if installed {
        let _ = DROPPED.set(counter);
    }
    LogGuard { guard: Some(guard) }
}

/// Log lines dropped so far because the queue to stderr was full (0 before [`init_stderr`]).
pub fn dropped_lines() -> u64 {
    DROPPED.get().map_or(0, |c| c.dropped_lines() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::sync::{Arc, Condvar, Mutex};
    use std::time::Duration;

    /// A sink whose writes block until it is opened (a pipe nobody reads).
    #[derive(Clone)]
    struct Gate(Arc<(Mutex<bool>, Condvar)>);

    impl Gate {
        fn new() -> Self {
            Self(Arc::new((Mutex::new(false), Condvar::new())))
        }
        fn open(&self) {
            *self.0.0.lock().unwrap() = true;
            self.0.1.notify_all();
        }
    }

    impl Write for Gate {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let (m, c) = &*self.0;
            let _open = c.wait_while(m.lock().unwrap(), |open| !*open).unwrap();
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// Logs `n` lines through `writer` on a thread; returns a receiver told when it is done.
    fn log_lines<W>(writer: W, n: usize) -> mpsc::Receiver<()>
    where
        W: for<'w> tracing_subscriber::fmt::MakeWriter<'w> + Send + Sync + 'static,
    {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let sub = tracing_subscriber::fmt().with_writer(writer).finish();
            tracing::subscriber::with_default(sub, || {
                for i in 0..n {
                    tracing::warn!("line {i}");
                }
            });
            let _ = tx.send(());
        });
        rx
    }

    #[test]
    fn a_blocked_sink_does_not_block_the_logging_thread() {
        // Written to directly, the blocked sink holds the logging thread (the hazard).
        let direct = Gate::new();
        let sink = direct.clone();
        let done = log_lines(move || sink.clone(), 3);
        assert!(
            done.recv_timeout(Duration::from_millis(300)).is_err(),
            "the direct sink should block"
        );
        direct.open();
        done.recv_timeout(Duration::from_secs(10))
            .expect("unblocked");

        // Through the non-blocking writer, the same sink blocked: every call returns, the
        // lines beyond the queue are dropped and counted.
        let gate = Gate::new();
        let (writer, guard) = non_blocking(gate.clone(), 4);
        let counter = writer.error_counter();
        let n = 100;
        let done = log_lines(writer, n);
        done.recv_timeout(Duration::from_secs(10))
            .expect("logging blocked on a blocked sink");
        // At most the queue (4) and the line the writer thread holds got through.
        let dropped = counter.dropped_lines();
        assert!((n - 5..=n).contains(&dropped), "{dropped} dropped");
        gate.open();
        drop(guard);
    }
}
