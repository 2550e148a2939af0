//! Child processes that never outlive the process that started them.

use std::os::unix::process::CommandExt;
use std::process::Command;

/// `cmd`'s process is killed (SIGKILL) when the thread that spawns it ends, the whole process
/// with it: a sweep's task killed with its worker, or an `upc run` killed by a signal, leaves no
/// participant running. Spawn from a thread that waits for the child (the kernel ties the
/// signal to the spawning thread, not the process).
pub fn dies_with_parent(cmd: &mut Command) {
    signalled_at_parent_death(cmd, libc::SIGKILL);
}

/// As [`dies_with_parent`], but the child gets SIGTERM, to stop what it started itself (the
/// Ray driver shuts its local cluster down).
pub fn stopped_with_parent(cmd: &mut Command) {
    signalled_at_parent_death(cmd, libc::SIGTERM);
}

fn signalled_at_parent_death(cmd: &mut Command, signal: libc::c_int) {
    // SAFETY: the hook runs in the child between fork and exec, and calls only getpid-family
    // functions and prctl, which are async-signal-safe.
    let parent = unsafe { libc::getpid() };
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, signal) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The parent may have died between the fork and the prctl: then nothing would
            // signal this child.
            if libc::getppid() != parent {
                return Err(std::io::Error::other(
                    "the parent exited before the child started",
                ));
            }
            Ok(())
        });
    }
}
