//! A test's missing prerequisite (a Python environment, a robot package, MuJoCo) never passes
//! in silence. Under CI (`CI` set, as CI sets it) it fails the test with the command that
//! installs it: `scripts/setup.sh` installs every one, so its absence there is a broken setup.
//! Elsewhere the test is skipped visibly: a `SKIPPED` line written past the test harness's
//! output capture (it shows in a plain `cargo test`), and a line in `skipped-tests.txt` of
//! cargo's test scratch directory, which `.ci/run` prints at the end.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Whether this run is CI's: `CI` set to anything but empty, `0` or `false`.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "0" && v != "false")
}

/// Says `line` past the harness's output capture (`eprintln!` is captured for a passing test; a
/// write to the handle is not) and appends it to `list`, which `.ci/run` prints.
pub fn said_and_listed(line: &str, list: &Path) {
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(list)
    {
        let _ = writeln!(f, "{line}");
    }
}

/// Where skipped tests are listed, one line each (the test, what was missing).
pub fn skip_list() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("skipped-tests.txt")
}

/// The calling test lacks `what`; `install` is the command that provides it. Panics under CI;
/// otherwise says so on the terminal, lists it, and returns (the caller then skips).
pub fn missing(what: &str, install: &str) {
    let test = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    assert!(
        !in_ci(),
        "{test}: {what}. Under CI every prerequisite of the tests must be installed: run \
         `{install}`"
    );
    said_and_listed(
        &format!("SKIPPED {test}: {what} (install: {install})"),
        &skip_list(),
    );
}

/// The install command of everything the tests need.
pub const SETUP: &str = "scripts/setup.sh";
