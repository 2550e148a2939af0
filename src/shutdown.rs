//! Clean shutdown of upc's processes: SIGINT and SIGTERM raise a flag that the loops poll, so
//! every process finishes its last tick, closes its logs and releases its IPC resources.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// A flag raised by SIGINT or SIGTERM.
pub fn stop_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        if let Err(e) = signal_hook::flag::register(sig, Arc::clone(&flag)) {
            tracing::warn!("cannot handle signal {sig}: {e}");
        }
    }
    flag
}
