//! Sweeps on Ray (`--engine ray`, docs/sweeps.md) against the local pool: the same map, a
//! worker node killed mid-sweep, a cell that cannot run, a stopped sweep resumed, a worker with
//! another build. Every Ray process here is on loopback (node address 127.0.0.2, usage stats
//! off) and stopped by the process group the test started, never by Ray's own machine-wide
//! stop command.

mod support;

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use support::procs::{Scratch, free_port, json, serial, venv_python};

/// The loopback address of the head node, which the sweep's driver joins (Ray turns 127.0.0.1
/// into the host's outward address).
const NODE_IP: &str = "127.0.0.2";
/// The worker node's: a driver joins the node at its own address, so the worker, whose death
/// the driver must survive, has another.
const WORKER_IP: &str = "127.0.0.3";

/// A small map: C0 and C1 at two forecast factors, one 1 s impact, two cases per cell (80 N,
/// then 40 N: the tolerance is 40 N).
const MAP: [&str; 14] = [
    "robustness",
    "--controllers",
    "c0,c1",
    "--durations",
    "1.0",
    "--scales",
    "0.5,1",
    "--shifts",
    "0",
    "--no-phantom",
    "--max",
    "1.0=80",
    "--tol",
    "40",
];

fn ray_bin() -> Option<PathBuf> {
    venv_python("ray")?;
    Some(Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/ray"))
}

fn upc(args: &[&str], out: &Path, env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(args)
        .arg("--quiet")
        .arg("--out")
        .arg(out)
        .envs(env.iter().copied())
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc starts")
}

fn ok(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    err
}

/// The local pool's map of [`MAP`], computed once for the tests that compare with it (under
/// the build's test directory: it outlives the tests that share it).
fn local_map() -> &'static Path {
    static LOCAL: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    LOCAL.get_or_init(|| {
        let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("sweep_ray_local_map");
        let _ = std::fs::remove_dir_all(&dir);
        ok(&upc(&[&MAP[..], &["--jobs", "2"]].concat(), &dir, &[]));
        dir
    })
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The map's data and figures, which must match byte for byte (the reports' wall times differ).
fn assert_same_map(a: &Path, b: &Path) {
    assert_eq!(
        String::from_utf8_lossy(&read(&a.join("robustness.csv"))),
        String::from_utf8_lossy(&read(&b.join("robustness.csv")))
    );
    let figs = |d: &Path| {
        let mut v: Vec<PathBuf> = std::fs::read_dir(d.join("figures"))
            .expect("figures")
            .map(|e| e.expect("entry").path())
            .collect();
        v.sort();
        v
    };
    let (fa, fb) = (figs(a), figs(b));
    assert_eq!(fa.len(), fb.len());
    assert!(!fa.is_empty());
    for (x, y) in fa.iter().zip(&fb) {
        assert!(read(x) == read(y), "{} differs", y.display());
    }
}

/// A process as /proc shows it.
#[derive(Debug, Clone)]
struct Proc {
    pid: i32,
    ppid: i32,
    pgrp: i32,
    comm: String,
}

fn procs() -> Vec<Proc> {
    let mut v = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<i32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let rest: Vec<&str> = stat[close + 2..].split(' ').collect();
        // A zombie has exited: only its parent's wait is missing.
        if rest.first() == Some(&"Z") {
            continue;
        }
        let num = |i: usize| rest.get(i).and_then(|s| s.parse().ok()).unwrap_or(0);
        v.push(Proc {
            pid,
            ppid: num(1),
            pgrp: num(2),
            comm: stat[open + 1..close].to_string(),
        });
    }
    v
}

/// `root`'s descendants, `root` excluded.
fn descendants(root: i32) -> Vec<Proc> {
    let all = procs();
    let mut out: Vec<Proc> = Vec::new();
    let mut frontier = vec![root];
    while let Some(p) = frontier.pop() {
        for c in all.iter().filter(|c| c.ppid == p) {
            frontier.push(c.pid);
            out.push(c.clone());
        }
    }
    out
}

fn alive(pid: i32) -> bool {
    procs().iter().any(|p| p.pid == pid)
}

/// Waits up to `limit` for every pid of `pids` to be gone; the ones still running.
fn survivors(pids: &[i32], limit: Duration) -> Vec<i32> {
    let until = Instant::now() + limit;
    loop {
        let left: Vec<i32> = pids.iter().copied().filter(|&p| alive(p)).collect();
        if left.is_empty() || Instant::now() > until {
            return left;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A Ray cluster of `ray start --block` processes, each node in a process group of its own;
/// dropped, every group is killed.
struct Cluster {
    nodes: Vec<Child>,
    address: String,
}

impl Cluster {
    /// A head and `workers` worker nodes, one CPU each.
    fn start(ray: &Path, s: &Scratch, workers: usize) -> Cluster {
        // Unix socket paths under the temp dir must stay short.
        let temp = PathBuf::from(format!("/tmp/upc-ray-{}", std::process::id()));
        let port = free_port();
        let address = format!("{NODE_IP}:{port}");
        let node = |extra: &[String], log: &str| -> Child {
            let log = std::fs::File::create(s.path(log)).expect("log");
            Command::new(ray)
                .args(["start", "--block", "--num-cpus=1", "--disable-usage-stats"])
                .args(extra)
                .env("RAY_USAGE_STATS_ENABLED", "0")
                .stdout(log.try_clone().expect("log"))
                .stderr(log)
                .process_group(0)
                .spawn()
                .expect("ray start")
        };
        let mut c = Cluster {
            nodes: vec![node(
                &[
                    "--head".into(),
                    format!("--node-ip-address={NODE_IP}"),
                    format!("--port={port}"),
                    "--include-dashboard=false".into(),
                    format!("--temp-dir={}", temp.display()),
                ],
                "head.log",
            )],
            address,
        };
        c.wait_for(1, s);
        for i in 0..workers {
            let n = node(
                &[
                    format!("--address={}", c.address),
                    format!("--node-ip-address={WORKER_IP}"),
                ],
                &format!("worker{i}.log"),
            );
            c.nodes.push(n);
            c.wait_for(2 + i, s);
        }
        c
    }

    /// Waits until `n` nodes are alive.
    fn wait_for(&self, n: usize, s: &Scratch) {
        let py = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
        let script = format!(
            "import time, ray\n\
             ray.init(address='{}', _node_ip_address='{NODE_IP}', logging_level='ERROR')\n\
             t = time.time()\n\
             while sum(x['Alive'] for x in ray.nodes()) < {n} and time.time() - t < 60:\n\
             \x20   time.sleep(0.5)\n\
             assert sum(x['Alive'] for x in ray.nodes()) >= {n}\n",
            self.address
        );
        let mut tries = 0;
        // The head's GCS takes a few seconds to listen.
        while !Command::new(&py)
            .args(["-c", &script])
            .env("RAY_USAGE_STATS_ENABLED", "0")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|st| st.success())
        {
            tries += 1;
            assert!(
                tries < 30,
                "the Ray cluster did not come up: {}",
                std::fs::read_to_string(s.path("head.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_secs(1));
        }
    }

    /// The process group of node `i` (0: the head).
    fn group(&self, i: usize) -> i32 {
        self.nodes[i].id() as i32
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for n in &mut self.nodes {
            // SAFETY: signalling the process group this test started.
            unsafe { libc::kill(-(n.id() as i32), libc::SIGKILL) };
            let _ = n.wait();
        }
    }
}

/// The map on a two-node Ray cluster is the local pool's, byte for byte; with a worker node
/// killed mid-sweep it still is (its cell runs again on the head), and the `upc` processes that
/// node was running die with it.
#[test]
fn a_two_node_ray_cluster_gives_the_local_map_even_when_a_node_dies() {
    let _one = serial();
    let Some(ray) = ray_bin() else { return };
    let s = Scratch::new("sweep_ray");
    let local = local_map();

    let cluster = Cluster::start(&ray, &s, 1);
    let on_ray = |out: &Path| {
        Command::new(env!("CARGO_BIN_EXE_upc"))
            .args(MAP)
            .args([
                "--engine",
                "ray",
                "--ray-address",
                &cluster.address,
                "--quiet",
            ])
            .arg("--out")
            .arg(out)
            .env("UPC_RAY_NODE_IP", NODE_IP)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("upc starts")
    };
    let whole = s.path("ray");
    ok(&on_ray(&whole).wait_with_output().expect("upc"));
    assert_same_map(local, &whole);
    let runs = std::fs::read_to_string(whole.join("ray/runs.jsonl")).expect("runs.jsonl");
    assert!(runs.contains("\"nodes\": 2"), "{runs}");

    // Again, and the worker node killed while it searches a cell.
    let killed = s.path("ray_killed");
    let sweep = on_ray(&killed);
    let worker = cluster.group(1);
    let until = Instant::now() + Duration::from_secs(60);
    let upcs = loop {
        let in_node: Vec<Proc> = procs().into_iter().filter(|p| p.pgrp == worker).collect();
        let upcs: Vec<Proc> = in_node
            .iter()
            .filter(|p| p.comm == "upc")
            .cloned()
            .collect();
        // A cell's case under way: `upc sweep-cell`, its `upc run`, and the participants.
        if upcs.len() >= 3 {
            // The node dies: every process of it but upc's own, which must follow by themselves.
            for p in in_node.iter().filter(|p| p.comm != "upc") {
                // SAFETY: signalling a process of the node this test started.
                unsafe { libc::kill(p.pid, libc::SIGKILL) };
            }
            break upcs;
        }
        assert!(
            Instant::now() < until,
            "no cell ever ran on the worker node"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let pids: Vec<i32> = upcs.iter().map(|p| p.pid).collect();
    let left = survivors(&pids, Duration::from_secs(10));
    assert!(left.is_empty(), "outlived their node: {left:?} of {upcs:?}");
    let err = ok(&sweep.wait_with_output().expect("upc"));
    assert_same_map(local, &killed);
    eprintln!("{err}");
}

/// A cell that cannot run (the plant refuses it) is reported once, with the plant's reason,
/// and the other cells still run; never counted as survived.
#[test]
fn a_cell_that_cannot_run_is_reported_once_with_its_reason() {
    let _one = serial();
    if ray_bin().is_none() {
        return;
    }
    let s = Scratch::new("sweep_ray_failed");
    let out = s.path("sweep");
    // MuJoCo's scene pushes through the door only: it refuses `sim.push = "none"`.
    let o = upc(
        &[
            "robustness",
            "--plant",
            "mujoco",
            "--controllers",
            "c1",
            "--durations",
            "1.0",
            "--scales",
            "0.5,1",
            "--shifts",
            "0",
            "--tol",
            "50",
            "--sim-set",
            "sim.push=\"none\"",
            "--engine",
            "ray",
            "--jobs",
            "2",
        ],
        &out,
        &[],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("2 cells failed"), "{err}");
    // Once each: the driver reports a failed cell when its task returns, and Ray does not run
    // a task again that returned.
    assert_eq!(err.matches("ray_sweep: cell failed").count(), 2, "{err}");
    assert_eq!(err.matches("sim.push must be").count(), 4, "{err}");
    let j = json(&out.join("robustness.json"));
    assert_eq!(j["failed_cells"].as_array().map(Vec::len), Some(2), "{j}");
    assert_eq!(j["rows"].as_array().map(Vec::len), Some(0), "{j}");
    let md = std::fs::read_to_string(out.join("robustness.md")).expect("md");
    assert!(md.contains("## Cells that failed"), "{md}");
}

/// A sweep whose driver is killed leaves nothing running, and started again it runs only the
/// cells not done; a third start runs nothing. The map is the local pool's.
#[test]
fn a_stopped_ray_sweep_resumes_from_the_cells_done() {
    let _one = serial();
    if ray_bin().is_none() {
        return;
    }
    let s = Scratch::new("sweep_ray_resume");
    let local = local_map();
    let out = s.path("sweep");
    let args = [
        &MAP[..],
        &["--engine", "ray", "--jobs", "1", "--quiet", "--out"],
    ]
    .concat();
    let mut first = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(&args)
        .arg(&out)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("upc starts");
    let cells = out.join("cells");
    let until = Instant::now() + Duration::from_secs(120);
    let done = |d: &Path| {
        std::fs::read_dir(d).map_or(0, |r| {
            r.flatten()
                .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
                .count()
        })
    };
    while done(&cells) == 0 {
        assert!(Instant::now() < until, "no cell finished");
        assert!(
            first.try_wait().expect("wait").is_none(),
            "the sweep ended early"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let tree: Vec<i32> = descendants(first.id() as i32)
        .iter()
        .map(|p| p.pid)
        .collect();
    let _ = first.kill();
    let _ = first.wait();
    let left = survivors(&tree, Duration::from_secs(15));
    assert!(left.is_empty(), "outlived the stopped sweep: {left:?}");
    let before = done(&cells);
    assert!(
        before < 3,
        "the sweep was not stopped mid-way: {before} of 3 cells done"
    );

    let err = ok(&upc(
        &[&MAP[..], &["--engine", "ray", "--jobs", "1"]].concat(),
        &out,
        &[],
    ));
    assert!(
        err.contains(&format!("{before} of 3 cells already done")),
        "{err}"
    );
    assert_same_map(local, &out);
    let err = ok(&upc(
        &[&MAP[..], &["--engine", "ray", "--jobs", "1"]].concat(),
        &out,
        &[],
    ));
    assert!(err.contains("3 of 3 cells already done"), "{err}");
    assert!(!err.contains("ray_sweep"), "the driver ran again: {err}");
    assert_same_map(local, &out);
}

/// A node whose `upc` is another build refuses the sweep's tasks, naming itself.
#[test]
fn a_worker_with_another_upc_build_refuses_its_tasks() {
    let _one = serial();
    if ray_bin().is_none() {
        return;
    }
    let s = Scratch::new("sweep_ray_build");
    // The same program with one byte more: it runs, but it is not the sweep's build.
    let other = s.path("upc-other");
    let mut bytes = read(Path::new(env!("CARGO_BIN_EXE_upc")));
    bytes.push(0);
    std::fs::write(&other, bytes).expect("copy");
    std::fs::set_permissions(&other, std::os::unix::fs::PermissionsExt::from_mode(0o755))
        .expect("chmod");
    let o = upc(
        &[&MAP[..], &["--engine", "ray", "--jobs", "1"]].concat(),
        &s.path("sweep"),
        &[("UPC_EXE", other.to_str().expect("utf-8"))],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("runs another upc build"), "{err}");
}

/// A cell whose `upc sweep-cell` crashes (killed here) fails once with the signal as its reason:
/// not run again (it returned), not on the map; the other cells are searched.
#[test]
fn a_crashed_cell_is_reported_once_and_not_run_again() {
    let _one = serial();
    if ray_bin().is_none() {
        return;
    }
    let s = Scratch::new("sweep_ray_crash");
    let out = s.path("sweep");
    let sweep = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([&MAP[..], &["--engine", "ray", "--jobs", "1"]].concat())
        .arg("--out")
        .arg(&out)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("upc starts");
    let until = Instant::now() + Duration::from_secs(60);
    let cell = loop {
        let found = descendants(sweep.id() as i32).into_iter().find(|p| {
            p.comm == "upc"
                && std::fs::read(format!("/proc/{}/cmdline", p.pid))
                    .is_ok_and(|c| c.windows(10).any(|w| w == b"sweep-cell"))
        });
        if let Some(p) = found {
            break p;
        }
        assert!(Instant::now() < until, "no cell started");
        std::thread::sleep(Duration::from_millis(20));
    };
    // SAFETY: signalling a process of the sweep this test started.
    unsafe { libc::kill(cell.pid, libc::SIGKILL) };
    let o = sweep.wait_with_output().expect("upc");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("1 cell failed"), "{err}");
    assert_eq!(err.matches("ray_sweep: cell failed").count(), 1, "{err}");
    assert!(err.contains("killed by signal 9"), "{err}");
    let j = json(&out.join("robustness.json"));
    assert_eq!(j["failed_cells"].as_array().map(Vec::len), Some(1), "{j}");
    // The other two cells were searched.
    assert_eq!(j["rows"].as_array().map(Vec::len), Some(2), "{j}");
}
