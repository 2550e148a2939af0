//! Real-time process setup, shared by every process with a loop (controller, plant, bridge, bus):
//! SCHED_FIFO priority, locked memory, CPU affinity, the CPUs' wake-up latency, background and
//! lower-priority threads, the log threads' drain loop, and loop latency statistics
//! ([`latency`]). Each step that the OS
//! refuses (no CAP_SYS_NICE, container limits) degrades with a warning, never an error.
//!
//! A bottom module: it depends on [`crate::config`] only, so the plant and the transports time
//! their loops without depending on the controller.

pub mod cpu_latency;
pub mod cpus;
pub mod latency;

pub use cpus::ControlCpu;
pub use latency::LatencyHistogram;

use crate::config::RealtimeSettings;

/// What was actually applied.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct RealtimeReport {
    pub fifo: bool,
    pub memory_locked: bool,
    pub pinned: bool,
    /// The CPUs' wake-up latency bound held ([`cpu_latency`]); absent in older summaries.
    #[serde(default)]
    pub cpu_latency_held: bool,
}

/// Apply to the calling thread (and, for mlockall, the process).
pub fn apply(s: &RealtimeSettings) -> RealtimeReport {
    let mut r = RealtimeReport::default();
    if s.lock_memory {
        // SAFETY: plain syscall with constant flags.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
            r.memory_locked = true;
        } else {
            tracing::warn!(
                "mlockall refused ({}); running with pageable memory",
                std::io::Error::last_os_error()
            );
        }
    }
    if s.fifo_priority > 0 {
        let param = libc::sched_param {
            sched_priority: s.fifo_priority.clamp(1, 99),
        };
        // SAFETY: valid sched_param for the calling thread (pid 0).
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0 {
            r.fifo = true;
        } else {
            tracing::warn!(
                "SCHED_FIFO priority {} refused ({}); running with the default scheduler",
                s.fifo_priority,
                std::io::Error::last_os_error()
            );
        }
    }
    if let Some(us) = s.cpu_latency_us {
        r.cpu_latency_held = cpu_latency::hold(us);
    }
    if let Some(cpu) = s.cpu {
        // SAFETY: cpu_set_t is plain data; CPU_SET bounds are checked against its size.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu < 8 * std::mem::size_of::<libc::cpu_set_t>() {
                libc::CPU_SET(cpu, &mut set);
                if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
                    r.pinned = true;
                }
            }
        }
        if !r.pinned {
            tracing::warn!("cannot pin the control thread to CPU {cpu}; running unpinned");
        }
    }
    r
}

/// Run `f` with the calling thread in the SCHED_IDLE class, then restore its class. Threads that
/// `f` starts (the rerun SDK's batcher and file writer, our logger threads) inherit the class,
/// so they run only on a core nothing else wants: in lockstep the simulator and the controller
/// wake each other every step, and a logging thread holding the core they wake on is the tail
/// of the IPC latency. Where the class cannot be changed, `f` just runs.
pub fn in_background<T>(f: impl FnOnce() -> T) -> T {
    // SAFETY: sched_getscheduler/getparam/setscheduler on the calling thread (pid 0) with a
    // valid sched_param.
    let (policy, param) = unsafe {
        let mut p = libc::sched_param { sched_priority: 0 };
        (libc::sched_getscheduler(0), {
            libc::sched_getparam(0, &mut p);
            p
        })
    };
    let idle = libc::sched_param { sched_priority: 0 };
    let lowered =
        policy >= 0 && unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &idle) } == 0;
    let out = f();
    if lowered {
        // SAFETY: as above; restores what was read.
        if unsafe { libc::sched_setscheduler(0, policy, &param) } != 0 {
            tracing::warn!(
                "could not restore the scheduling class after starting the log threads: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    out
}

/// The run is over: every thread of this process in the idle class (the log threads that
/// [`in_background`] started, the rerun SDK's among them) back in the normal class, and those
/// [`lower_priority`] lowered back to nice 0 (where allowed), so that they flush and end on a
/// loaded machine, where the idle class hardly runs (two busy loops held a controller's end,
/// and its summary, until they stopped). Returns how many moved.
pub fn leave_background() -> usize {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    let normal = libc::sched_param { sched_priority: 0 };
    let mut moved = 0;
    for tid in tasks
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse().ok())
    {
        // SAFETY: sched_getscheduler/setscheduler on a thread of this process with a valid
        // sched_param; a thread that ended meanwhile gives an error, ignored.
        unsafe {
            if libc::sched_getscheduler(tid) == libc::SCHED_IDLE
                && libc::sched_setscheduler(tid, libc::SCHED_OTHER, &normal) == 0
            {
                moved += 1;
            }
            if libc::getpriority(libc::PRIO_PROCESS, tid as libc::id_t) > 0 {
                libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, 0);
            }
        }
    }
    moved
}

/// A log thread's receive loop: every `period`, handle what has been queued, until every
/// sender is gone (then the rest). Why not `recv`: a blocked receiver makes each `try_send` of
/// the real-time loop a futex wake-up of this thread, which then lands on the core the other
/// lockstep process is about to wake on. Polling keeps the loop's send a plain queue write.
pub fn drain_periodically<T>(
    rx: &std::sync::mpsc::Receiver<T>,
    period: std::time::Duration,
    mut handle: impl FnMut(T),
) {
    use std::sync::mpsc::TryRecvError;
    loop {
        loop {
            match rx.try_recv() {
                Ok(item) => handle(item),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return,
            }
        }
        std::thread::sleep(period);
    }
}

/// Lower the calling thread's priority (the C2 worker and loggers must never preempt the loop).
pub fn lower_priority(nice: i32) {
    // SAFETY: setpriority on the calling thread (who = 0 with PRIO_PROCESS applies to the thread
    // on Linux, where threads are tasks).
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, nice);
    }
}

#[cfg(test)]
mod tests {
    /// A thread started in the background (the idle class) is back in the normal class once
    /// the run is over, so that it can flush on a loaded machine.
    #[test]
    fn threads_started_in_the_background_leave_it_at_the_end() {
        let (tid_tx, tid_rx) = std::sync::mpsc::channel();
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let t = super::in_background(|| {
            std::thread::spawn(move || {
                // SAFETY: gettid has no arguments.
                let tid = unsafe { libc::syscall(libc::SYS_gettid) } as libc::pid_t;
                tid_tx.send(tid).expect("send");
                let _ = done_rx.recv();
            })
        });
        let tid = tid_rx.recv().expect("tid");
        // SAFETY: sched_getscheduler on a thread of this process.
        let policy = || unsafe { libc::sched_getscheduler(tid) };
        // Any thread may enter the idle class (no privilege needed).
        assert_eq!(policy(), libc::SCHED_IDLE);
        assert!(super::leave_background() >= 1);
        assert_eq!(policy(), libc::SCHED_OTHER);
        done_tx.send(()).expect("send");
        t.join().expect("join");
    }
}
