//! Live viewing: `upc run --connect URL` streams both recordings to a running rerun viewer (here
//! `rerun --save`, the viewer's gRPC server writing what it receives) besides the `.rrd` files:
//! the viewer gets every record the files get, and the lockstep run's bytes do not change.
//! Needs `.venv`'s rerun (scripts/setup.sh installs it): fails without it under CI, skips visibly
//! elsewhere (`support::prereq`).

mod support;

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use support::procs::{csv_without, free_port};
use support::rrd::rrd_times;

fn run(out: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let st = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["run", "--quiet", "--controller", "c1", "--duration", "1.5"])
        .args(["--name", name, "--out"])
        .arg(out)
        .args(extra)
        .stdout(Stdio::null())
        .status()
        .expect("upc run");
    let dir = out.join(name).join("c1");
    assert!(
        st.success(),
        "{}",
        std::fs::read_to_string(dir.join("controller.log")).unwrap_or_default()
    );
    dir
}

#[test]
fn a_live_viewer_gets_every_record_of_the_files_and_the_run_is_unchanged() {
    let rerun = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/rerun");
    if !rerun.exists() {
        support::prereq::missing(
            &format!("no rerun viewer at {}", rerun.display()),
            support::prereq::SETUP,
        );
        return;
    }
    let out = std::env::temp_dir().join(format!("upc-live-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("dir");
    let port = free_port();
    let live = out.join("live.rrd");
    // A process group: `rerun` is a Python launcher of the viewer's binary, both are stopped.
    let mut viewer = Command::new(&rerun)
        .args(["--port", &port.to_string(), "--save"])
        .arg(&live)
        .process_group(0)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("rerun starts");
    let until = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < until, "rerun never listened on {port}");
        std::thread::sleep(Duration::from_millis(50));
    }
    let url = format!("rerun+http://127.0.0.1:{port}/proxy");
    let streamed = run(&out, "live", &["--connect", &url]);
    let plain = run(&out, "plain", &[]);
    // The server writes each message as it comes: stop the group (its binary ignores SIGINT
    // while a stream is open; SIGTERM ends it).
    let group = -(viewer.id() as libc::pid_t);
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGKILL] {
        // SAFETY: signalling the process group of our own child.
        unsafe { libc::kill(group, sig) };
        let until = Instant::now() + Duration::from_secs(3);
        while Instant::now() < until && unsafe { libc::kill(group, 0) } == 0 {
            let _ = viewer.try_wait();
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    let _ = viewer.wait();

    for (file, prefix) in [
        ("controller.rrd", "/controller/timing"),
        ("sim.rrd", "/world/robot"),
    ] {
        let (in_file, last) = rrd_times(&streamed.join(file), prefix);
        let (in_viewer, last_live) = rrd_times(&live, prefix);
        assert!(in_file > 50, "{file}: {in_file} records");
        eprintln!("{prefix}: {in_file} records in the file, {in_viewer} in the viewer");
        assert_eq!(
            in_viewer, in_file,
            "{prefix}: the viewer got {in_viewer} of {in_file}"
        );
        assert_eq!(last_live, last, "{prefix}");
    }
    // Streaming to a viewer changes nothing the controller computes.
    let csv = |d: &Path| {
        csv_without(
            &d.join("controller.csv"),
            &["tick_us", "wbc_us", "c2_solve_ms"],
        )
    };
    assert_eq!(csv(&streamed), csv(&plain));
    assert_eq!(
        std::fs::read(streamed.join("sim.csv")).expect("sim.csv"),
        std::fs::read(plain.join("sim.csv")).expect("sim.csv")
    );
    let _ = std::fs::remove_dir_all(&out);
}
