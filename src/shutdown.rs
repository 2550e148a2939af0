//! Clean shutdown of upc's processes: SIGINT and SIGTERM raise a flag that the loops poll, so
//! every process finishes its last tick, closes its logs and releases its IPC resources.
//!
//! The two signals are blocked in the calling thread, and so in every thread it starts later,
//! and taken by a thread of their own with `sigwait`. No other thread is interrupted by them:
//! an interrupted wait (an iceoryx2 listener's, a sleep) would return EINTR, which iceoryx2
//! reports as an error and would end the process with a failure instead of a clean stop.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

const SIGNALS: [libc::c_int; 2] = [libc::SIGINT, libc::SIGTERM];

/// A flag raised by SIGINT or SIGTERM. Call it first thing, before starting threads.
pub fn stop_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    // A handler as well: a thread started before this call still has the signals unblocked.
    for sig in SIGNALS {
        if let Err(e) = signal_hook::flag::register(sig, Arc::clone(&flag)) {
            tracing::warn!("cannot handle signal {sig}: {e}");
        }
    }
    // SAFETY: sigset_t is plain data, initialised by sigemptyset before use; pthread_sigmask
    // only changes this thread's mask.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for sig in SIGNALS {
            libc::sigaddset(&mut set, sig);
        }
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            tracing::warn!("cannot block SIGINT/SIGTERM: waits may be interrupted");
            return flag;
        }
        set
    };
    let raised = Arc::clone(&flag);
    let waiter = std::thread::Builder::new()
        .name("upc-signals".into())
        .spawn(move || {
            loop {
                let mut sig: libc::c_int = 0;
                // SAFETY: `set` is an initialised signal set; `sig` is a valid out-pointer.
                if unsafe { libc::sigwait(&set, &mut sig) } == 0 {
                    raised.store(true, Ordering::Relaxed);
                    tracing::info!("signal {sig} received: stopping");
                }
            }
        });
    if let Err(e) = waiter {
        tracing::warn!("cannot start the signal thread: {e}");
        // SAFETY: as above; unblock so that the handler registered above takes the signals.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
    }
    flag
}
