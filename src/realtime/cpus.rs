//! A CPU of its own for a launcher's control thread (`upc run`, lockstep).
//!
//! In lockstep the plant and the controller wake each other every step. Left to the scheduler,
//! the woken plant or a log thread lands on the core the controller is ticking on: measured on
//! a 2-core machine, the torques' notify took 15–20 µs p50 (the plant blocked in its wait, woken
//! by it) and the tick's p99 was about 245 µs against a 50 µs compute. A robot's computer gives
//! its control thread a core (isolated, pinned); a launcher can do the same without privileges:
//! it claims one CPU for the control thread and keeps every other process on the rest.
//!
//! The claim is an exclusive `flock` on a file per CPU in the temporary directory, so two
//! launchers on one machine (parallel tests, a sweep's cells) never pin their control threads
//! to the same CPU: a launcher that finds none free runs as before, unpinned. The lock ends with
//! the process that holds it (the file is opened close-on-exec: no child inherits it).

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd;

/// A CPU claimed for one control thread, and the process's other CPUs.
pub struct ControlCpu {
    cpu: usize,
    rest: libc::cpu_set_t,
    _lock: File,
}

impl ControlCpu {
    /// Claims the highest free CPU of the calling thread's affinity mask, never its lowest (the
    /// other processes keep at least one); `None` on a single CPU, when every candidate is
    /// claimed, or when the mask cannot be read.
    pub fn claim() -> Option<Self> {
        let mask = current_mask()?;
        let cpus: Vec<usize> = (0..max_cpus())
            // SAFETY: the index is within the set's bits.
            .filter(|&c| unsafe { libc::CPU_ISSET(c, &mask) })
            .collect();
        for &cpu in cpus.iter().skip(1).rev() {
            let path = std::env::temp_dir().join(format!("upc-control-cpu-{cpu}.lock"));
            let Ok(file) = OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
            else {
                continue;
            };
            // SAFETY: flock on a descriptor this function owns.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
                let mut rest = mask;
                // SAFETY: as above.
                unsafe { libc::CPU_CLR(cpu, &mut rest) };
                return Some(Self {
                    cpu,
                    rest,
                    _lock: file,
                });
            }
        }
        None
    }

    /// The claimed CPU.
    pub fn cpu(&self) -> usize {
        self.cpu
    }

    /// Confines the calling thread, and every process it starts from now on, to the CPUs other
    /// than the claimed one.
    pub fn leave_to_control(&self) -> std::io::Result<()> {
        // SAFETY: a valid set of the size passed, for the calling thread (pid 0).
        let r = unsafe {
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &self.rest)
        };
        if r == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }
}

/// The CPUs a `cpu_set_t` can name.
fn max_cpus() -> usize {
    8 * std::mem::size_of::<libc::cpu_set_t>()
}

/// The calling thread's affinity mask.
fn current_mask() -> Option<libc::cpu_set_t> {
    // SAFETY: cpu_set_t is plain data, filled by the syscall for the calling thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        (libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) == 0)
            .then_some(set)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two claims in one process are two launchers: never the same CPU, and never every CPU.
    #[test]
    fn claims_never_share_a_cpu_nor_take_the_last_one() {
        let mask = current_mask().expect("affinity");
        // SAFETY: as in `claim`.
        let n = (0..max_cpus())
            .filter(|&c| unsafe { libc::CPU_ISSET(c, &mask) })
            .count();
        let mut held = Vec::new();
        while let Some(c) = ControlCpu::claim() {
            assert!(
                held.iter().all(|h: &ControlCpu| h.cpu() != c.cpu()),
                "CPU {} claimed twice",
                c.cpu()
            );
            // SAFETY: as above.
            assert!(!unsafe { libc::CPU_ISSET(c.cpu(), &c.rest) });
            held.push(c);
        }
        assert!(held.len() < n.max(1), "{} claims on {n} CPUs", held.len());
        // (A launcher running beside the test would hold one: stop it first.)
        assert!(
            n < 2 || !held.is_empty(),
            "no CPU claimed of {n}: is a `upc run` holding them?"
        );
        let freed = held.pop().map(|c| c.cpu());
        drop(held);
        if let Some(cpu) = freed {
            // The lock ends with its holder: the CPU can be claimed again.
            let again: Vec<_> = std::iter::from_fn(ControlCpu::claim).take(n).collect();
            assert!(again.iter().any(|c| c.cpu() == cpu), "CPU {cpu} not freed");
        }
    }
}
