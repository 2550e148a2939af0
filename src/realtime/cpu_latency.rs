//! The CPUs' wake-up latency, bounded for the life of the process: a PM QoS request on
//! `/dev/cpu_dma_latency` (the kernel's cpu-latency QoS; it holds while the file stays open and
//! takes the least of all requests on the machine).
//!
//! Why: a loop that sleeps to its next deadline is woken on an idle CPU, and an idle CPU in a
//! deep C-state, or a virtual CPU halted and descheduled by its host, takes its exit latency to
//! run again. A request of 0 µs keeps idle CPUs polling instead of halting. Measured on this
//! project's 2-core VM (docs/results/bus.md, "The CPUs' wake-up latency"): the G1's bus
//! participant overslept 1 ms waits by 9.8–17.0 ms with the CPUs halting and the host then took
//! 35–45 % of them as steal; with the request held, the bus tests passed at 0.3–0.9 % steal.
//! The price: idle CPUs spin (power and, in a VM, the host's CPU time) while the process runs.

use std::io::Write;
use std::sync::OnceLock;

/// The request's file, open until the process exits (the kernel then drops the request).
static HELD: OnceLock<std::fs::File> = OnceLock::new();

/// Hold a wake-up latency bound of `us` µs; false (with a warning) where the OS refuses it
/// (not root: the file is root's only; no such file). A process holds one request: a later
/// call keeps the first.
pub fn hold(us: u32) -> bool {
    if HELD.get().is_some() {
        return true;
    }
    let value = i32::try_from(us).unwrap_or(i32::MAX);
    let opened = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        // The kernel reads a binary s32 of the CPU's native byte order.
        .and_then(|mut f| f.write_all(&value.to_ne_bytes()).map(|()| f));
    match opened {
        Ok(f) => {
            let _ = HELD.set(f);
            true
        }
        Err(e) => {
            tracing::warn!(
                "cannot bound the CPUs' wake-up latency to {us} µs via /dev/cpu_dma_latency \
                 ({e}); idle CPUs may halt, and a sleeping loop then wakes late"
            );
            false
        }
    }
}
