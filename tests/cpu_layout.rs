//! `upc run`'s CPU layout in lockstep (`--cpus auto`, the default): the control thread alone on
//! a CPU of its own, every other thread of every participant (the plant, the forecaster, the
//! controller's logger and signal threads) off it; `--cpus shared` leaves them all to the
//! scheduler. Read from /proc while the run goes, then from its summaries. A test binary of its
//! own: the claim is machine-wide, and a parallel `upc run` would take it.

mod support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use support::upc_run::{scratch, upc_run};

/// The CPUs a task may run on: its `Cpus_allowed_list` ("0-1,3").
fn allowed(status: &Path) -> Option<Vec<usize>> {
    let text = std::fs::read_to_string(status).ok()?;
    let list = text
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))?
        .trim();
    let mut cpus = Vec::new();
    for part in list.split(',') {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        cpus.extend(a.parse::<usize>().ok()?..=b.parse::<usize>().ok()?);
    }
    Some(cpus)
}

/// The pid of the running `upc <sub>` whose command line names `prefix` (its services').
fn participant(sub: &str, prefix: &str) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let raw = std::fs::read(e.path().join("cmdline")).ok()?;
        let args: Vec<&[u8]> = raw.split(|&b| b == 0).collect();
        let named = args.get(1).is_some_and(|a| *a == sub.as_bytes());
        (named && String::from_utf8_lossy(&raw).contains(prefix)).then_some(pid)
    })
}

/// Each thread of process `pid`: its name and the CPUs it may run on.
fn threads(pid: u32) -> Vec<(u32, String, Vec<usize>)> {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter_map(|t| {
            let tid: u32 = t.file_name().to_str()?.parse().ok()?;
            let name = std::fs::read_to_string(t.path().join("comm")).ok()?;
            Some((
                tid,
                name.trim().to_owned(),
                allowed(&t.path().join("status"))?,
            ))
        })
        .collect()
}

#[test]
fn the_control_thread_runs_alone_on_a_cpu_of_its_own() {
    let mine = allowed(Path::new("/proc/self/status")).expect("this test's CPUs");
    let out = scratch("cpu_layout", "auto");
    let mut run = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["run", "--quiet", "--controller", "c1", "--duration", "4"])
        .args(["--name", "run", "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .spawn()
        .expect("upc run");
    // `upc run`'s service prefix for its C1 run (src/cli/run.rs).
    let prefix = format!("upc_{}_c1", run.id());
    // The claimed CPU is the highest of this machine's (nothing else here claims one).
    let control = (mine.len() >= 2).then(|| *mine.last().expect("a CPU"));
    if let Some(cpu) = control {
        // Seen while the controller ticks: its loop (the main thread) pinned, the rest not.
        let until = Instant::now() + Duration::from_secs(60);
        let (ctl, sim, fc) = loop {
            assert!(
                Instant::now() < until,
                "the run's participants were not seen"
            );
            assert!(
                run.try_wait().expect("wait").is_none(),
                "the run ended early"
            );
            if let (Some(c), Some(s), Some(f)) = (
                participant("controller", &prefix),
                participant("sim", &prefix),
                participant("forecast", &prefix),
            ) && allowed(Path::new(&format!("/proc/{c}/status"))) == Some(vec![cpu])
            {
                break (c, s, f);
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let mut others = 0;
        for pid in [ctl, sim, fc] {
            for (tid, name, cpus) in threads(pid) {
                if tid == ctl {
                    continue;
                }
                others += 1;
                assert!(
                    !cpus.contains(&cpu),
                    "thread {name} ({tid}) of {pid} may run on the control CPU {cpu}: {cpus:?}"
                );
            }
        }
        // The plant's loop and loggers, the controller's logger, the forecaster: all seen.
        assert!(others >= 4, "{others} other threads seen");
    }
    assert!(run.wait().expect("upc run").success(), "upc run failed");
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("run").join(f)).expect(f))
            .expect("JSON")
    };
    let summary = read("summary.json");
    assert_eq!(summary["control_cpu"].as_u64(), control.map(|c| c as u64));
    let pinned = &read("c1/controller.json")["realtime"]["pinned"];
    assert_eq!(pinned.as_bool(), Some(control.is_some()), "{pinned}");

    // Shared: nothing claimed, nothing pinned.
    let out = scratch("cpu_layout", "shared");
    let entry = upc_run(&out, "c1", &["--duration", "0.5", "--cpus", "shared"]);
    assert_eq!(entry["controller_summary"]["realtime"]["pinned"], false);
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("run/summary.json")).expect("summary"),
    )
    .expect("JSON");
    assert!(
        summary["control_cpu"].is_null(),
        "{}",
        summary["control_cpu"]
    );
}
