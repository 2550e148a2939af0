//! Real `upc` processes for the multi-process tests: a scratch directory and prefix per test,
//! child processes killed on every path, and an observer of the simulator's ground truth.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use serde_json::Value;
use upc::channels::{ContractNode, GroundTruthMsg, StateMsg, TORQUE_FLAG_FALLBACK, TorqueMsg};

/// The real-time tests share two cores with everything else: one at a time.
pub static SERIAL: Mutex<()> = Mutex::new(());

pub fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

/// No push on the door: the robot only has to stand, so that what a test sees is the fault's
/// doing (an unforecast impact tips the robot by design, see config/scenarios).
pub const QUIET: &str = "name = \"quiet\"\nduration = 1000.0\nzmp_reference = [0.0, 0.0]\n\
                     [force]\nkind = \"impacts\"\nimpacts = []\n";

/// A scratch directory and a service prefix unique to one test.
pub struct Scratch {
    pub dir: PathBuf,
    pub prefix: String,
}

impl Scratch {
    pub fn new(name: &str) -> Self {
        let prefix = format!("{name}_{}", std::process::id());
        let dir = std::env::temp_dir().join(format!("upc-{prefix}"));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch dir");
        std::fs::write(dir.join("quiet.toml"), QUIET).expect("scenario");
        Scratch { dir, prefix }
    }

    pub fn scenario(&self) -> String {
        self.path("quiet.toml").display().to_string()
    }

    pub fn path(&self, f: &str) -> PathBuf {
        self.dir.join(f)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // A failed test's files stay for a look, and anyone's with UPC_KEEP_SCRATCH set.
        if !std::thread::panicking() && std::env::var_os("UPC_KEEP_SCRATCH").is_none() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Stop `pids` (SIGSTOP) for `secs` of wall time, then continue them in the same order.
pub fn freeze(pids: &[i32], secs: f64) {
    for &pid in pids {
        // SAFETY: signalling a process this test started (directly or through `upc run`).
        unsafe { libc::kill(pid, libc::SIGSTOP) };
    }
    std::thread::sleep(Duration::from_secs_f64(secs));
    for &pid in pids {
        // SAFETY: as above.
        unsafe { libc::kill(pid, libc::SIGCONT) };
    }
}

/// Child processes, SIGKILLed and reaped when dropped (a failing assertion leaves none behind).
#[derive(Default)]
pub struct Procs(pub Vec<(String, Child)>);

impl Procs {
    /// Start `upc args…` with its stderr in `<dir>/<name>.log`.
    pub fn start(&mut self, s: &Scratch, name: &str, args: &[&str]) {
        let log = std::fs::File::create(s.path(&format!("{name}.log"))).expect("log file");
        let child = Command::new(env!("CARGO_BIN_EXE_upc"))
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("upc starts");
        self.0.push((name.to_string(), child));
    }

    pub fn pid(&self, name: &str) -> i32 {
        self.0
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, c)| c.id() as i32)
            .unwrap_or_else(|| panic!("no process {name}"))
    }

    /// Freeze `names` (SIGSTOP) for `secs` of wall time, then resume them in the same order: a
    /// stall of those processes as a busy or misbehaving machine causes it.
    pub fn freeze(&self, names: &[&str], secs: f64) {
        let pids: Vec<i32> = names.iter().map(|n| self.pid(n)).collect();
        freeze(&pids, secs);
    }

    pub fn signal(&self, name: &str, sig: i32) {
        // SAFETY: signalling our own child, which we have not reaped yet.
        unsafe { libc::kill(self.pid(name), sig) };
    }

    /// Wait for `name` to exit (at most `limit`) and forget it.
    pub fn wait(&mut self, name: &str, limit: Duration) -> ExitStatus {
        let i = self
            .0
            .iter()
            .position(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no process {name}"));
        let (_, mut child) = self.0.remove(i);
        let until = Instant::now() + limit;
        loop {
            if let Some(st) = child.try_wait().expect("try_wait") {
                return st;
            }
            if Instant::now() > until {
                // Say what it was doing before it is gone: its threads and its log.
                let seen = where_it_hangs(child.id() as i32);
                let _ = child.kill();
                let _ = child.wait();
                panic!("{name} did not exit within {limit:?}: {seen}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Signal `name` and expect a clean exit (status 0).
    pub fn stop(&mut self, s: &Scratch, name: &str, sig: i32) {
        self.signal(name, sig);
        let st = self.wait(name, Duration::from_secs(15));
        assert!(
            st.success(),
            "{name} exited with {st} after signal {sig}:\n{}",
            log(s, name)
        );
    }

    pub fn kill_all(&mut self) {
        for (_, c) in &mut self.0 {
            let _ = c.kill();
        }
        for (_, c) in &mut self.0 {
            let _ = c.wait();
        }
        self.0.clear();
    }
}

impl Drop for Procs {
    fn drop(&mut self) {
        self.kill_all();
    }
}

/// `upc controller` in real time on the scratch's quiet scenario and prefix, its summary in
/// `<dir>/controller.json`, then `extra`.
pub fn controller_args(s: &Scratch, extra: &[&str]) -> Vec<String> {
    let scenario = s.scenario();
    let mut v: Vec<String> = [
        "controller",
        "--realtime",
        "--scenario",
        &scenario,
        "--duration",
        "1000",
        "--prefix",
        &s.prefix,
    ]
    .iter()
    .map(|x| x.to_string())
    .collect();
    v.push("--summary".into());
    v.push(s.path("controller.json").display().to_string());
    v.extend(extra.iter().map(|x| x.to_string()));
    v
}

/// Start [`controller_args`] as process `controller`.
pub fn start_controller(p: &mut Procs, s: &Scratch, extra: &[&str]) {
    let args = controller_args(s, extra);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    p.start(s, "controller", &args);
}

/// [`start_controller`] in lockstep.
pub fn start_lockstep_controller(p: &mut Procs, s: &Scratch, extra: &[&str]) {
    let mut args = controller_args(s, extra);
    args.retain(|a| a != "--realtime");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    p.start(s, "controller", &args);
}

/// Start `upc sim` on the test's scenario and prefix as process `name`, its summary in
/// `<name>.json`: in real time until stopped, unless `extra` sets `--mode` or `--duration`.
pub fn start_plant(p: &mut Procs, s: &Scratch, name: &str, extra: &[&str]) {
    let summary = s.path(&format!("{name}.json")).display().to_string();
    let scenario = s.scenario();
    let mut args = vec!["sim"];
    for (flag, value) in [("--mode", "realtime"), ("--duration", "0")] {
        if !extra.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    args.extend([
        "--scenario",
        &scenario,
        "--prefix",
        &s.prefix,
        "--summary",
        &summary,
    ]);
    args.extend_from_slice(extra);
    p.start(s, name, &args);
}

/// A TCP port free on loopback now (the OS picks it; a process binds it a moment later).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// Runs `upc args…` to completion (logs at warn) and asserts that it succeeded, with its
/// stderr in the message.
pub fn upc_ok<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) {
    let out = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc starts");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

pub fn log(s: &Scratch, name: &str) -> String {
    std::fs::read_to_string(s.path(&format!("{name}.log"))).unwrap_or_default()
}

pub fn json(p: &Path) -> Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

pub fn u(v: &Value, k: &str) -> u64 {
    v[k].as_u64()
        .unwrap_or_else(|| panic!("{k} missing in {v}"))
}

pub fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64()
        .unwrap_or_else(|| panic!("{k} missing in {v}"))
}

/// What the test sees of the simulator's ground truth: the current run's time and CoM height.
#[derive(Debug, Default, Clone, Copy)]
pub struct Seen {
    pub time: f64,
    /// Simulator runs seen (the time going back starts a new one).
    pub runs: u32,
    pub com_z0: f64,
    pub com_z_min: f64,
    /// Of the current run: the plant's flags, its hold steps, the fastest slip seen.
    pub flags: u32,
    pub hold_steps: u64,
    pub max_slip: f64,
    /// When the fastest slip was seen (s, plant time).
    pub max_slip_time: f64,
    /// Plant time at which the current run's scenario started, as the plant announces it in
    /// its state (negative: not yet).
    pub scenario_start: f64,
}

impl Seen {
    /// How far the CoM fell below its height in the run's first state (m). Fails when that
    /// state carried no CoM (a humanoid's is well above 0.1 m): measured from zero, the drop
    /// could never fail a test.
    pub fn com_drop(&self) -> f64 {
        assert!(
            self.com_z0 > 0.1,
            "no CoM height in the plant's first state: {self:?}"
        );
        self.com_z0 - self.com_z_min
    }
}

/// Watches `<prefix>/ground_truth` from a thread of the test process.
pub struct Observer {
    seen: Arc<Mutex<Seen>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Observer {
    pub fn start(prefix: &str) -> Self {
        let seen = Arc::new(Mutex::new(Seen::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (seen_t, stop_t, prefix) = (Arc::clone(&seen), Arc::clone(&stop), prefix.to_string());
        let thread = std::thread::spawn(move || {
            let node = ContractNode::open(&prefix, "faults-observer").expect("observer node");
            let truth = node.subscriber::<GroundTruthMsg>().expect("ground truth");
            let state = node.subscriber::<StateMsg>().expect("state");
            while !stop_t.load(Ordering::Relaxed) {
                while let Some(g) = truth.receive().expect("receive") {
                    let mut s = seen_t.lock().unwrap();
                    if s.runs == 0 || g.time < s.time - 1e-9 {
                        s.runs += 1;
                        s.com_z0 = g.com[2];
                        s.com_z_min = g.com[2];
                        s.max_slip = 0.0;
                        s.scenario_start = -1.0;
                    }
                    s.flags = g.flags;
                    s.hold_steps = g.hold_steps;
                    if g.max_slip_speed > s.max_slip {
                        s.max_slip = g.max_slip_speed;
                        s.max_slip_time = g.time;
                    }
                    s.time = g.time;
                    s.com_z_min = s.com_z_min.min(g.com[2]);
                }
                while let Some(m) = state.receive().expect("receive") {
                    // A state of the run the ground truth is on (a restarted plant's time
                    // starts again below it).
                    let mut s = seen_t.lock().unwrap();
                    if s.runs > 0 && m.time <= s.time + 0.5 && m.time >= s.time - 0.5 {
                        s.scenario_start = m.scenario_start;
                    }
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        });
        Observer {
            seen,
            stop,
            thread: Some(thread),
        }
    }

    pub fn get(&self) -> Seen {
        *self.seen.lock().unwrap()
    }

    /// Wait until the simulator's run number `run` reaches simulated time `t`.
    pub fn wait_for(&self, run: u32, t: f64, procs: &mut Procs, s: &Scratch) {
        self.wait_until(run, procs, s, &format!("t = {t} s"), |seen| seen.time >= t);
    }

    /// Wait until the simulator's run number `run` has played `t` s of its scenario (from the
    /// start the plant announces: a real-time plant starts it once a controller has the robot,
    /// however long that took).
    pub fn wait_for_scenario(&self, run: u32, t: f64, procs: &mut Procs, s: &Scratch) {
        let what = format!("scenario time {t} s");
        self.wait_until(run, procs, s, &what, |seen| {
            seen.scenario_start >= 0.0 && seen.time >= seen.scenario_start + t
        });
    }

    fn wait_until(
        &self,
        run: u32,
        procs: &mut Procs,
        s: &Scratch,
        what: &str,
        reached: impl Fn(&Seen) -> bool,
    ) {
        let until = Instant::now() + Duration::from_secs(40);
        loop {
            let seen = self.get();
            if seen.runs > run || (seen.runs == run && reached(&seen)) {
                return;
            }
            // A process that died early fails here with its log rather than by a timeout.
            for (name, child) in &mut procs.0 {
                if let Ok(Some(st)) = child.try_wait() {
                    panic!("{name} exited early ({st}):\n{}", log(s, name));
                }
            }
            assert!(
                Instant::now() < until,
                "simulator run {run} did not reach {what}: {seen:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// The controller's torques as a thread of the test process receives them: when each came and
/// whether it was a fallback (damping) command.
pub struct TorqueWatch {
    seen: Arc<Mutex<Vec<(Instant, bool)>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl TorqueWatch {
    pub fn start(prefix: &str) -> Self {
        let seen = Arc::new(Mutex::new(Vec::with_capacity(1 << 16)));
        let stop = Arc::new(AtomicBool::new(false));
        let (seen_t, stop_t, prefix) = (Arc::clone(&seen), Arc::clone(&stop), prefix.to_string());
        let thread = std::thread::spawn(move || {
            let node = ContractNode::open(&prefix, "torque-watch").expect("watch node");
            let torques = node.subscriber::<TorqueMsg>().expect("torques");
            while !stop_t.load(Ordering::Relaxed) {
                while let Some(m) = torques.receive().expect("receive") {
                    let fallback = m.flags & TORQUE_FLAG_FALLBACK != 0;
                    seen_t.lock().unwrap().push((Instant::now(), fallback));
                }
                std::thread::sleep(Duration::from_micros(200));
            }
        });
        TorqueWatch {
            seen,
            stop,
            thread: Some(thread),
        }
    }

    /// The torques received after `from`: (s after `from`, fallback).
    pub fn after(&self, from: Instant) -> Vec<(f64, bool)> {
        let seen = self.seen.lock().unwrap();
        seen.iter()
            .filter(|(t, _)| *t >= from)
            .map(|(t, f)| ((*t - from).as_secs_f64(), *f))
            .collect()
    }
}

impl Drop for TorqueWatch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Observer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The Python of `.venv` if it imports `modules` (comma-separated), else `None`: a failure
/// under CI, a visible skip elsewhere (`support::prereq`).
pub fn venv_python(modules: &str) -> Option<PathBuf> {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    let ok = Command::new(&py)
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        super::prereq::missing(
            &format!("{} cannot import {modules}", py.display()),
            super::prereq::SETUP,
        );
    }
    ok.then_some(py)
}

/// A CSV without the named columns, line by line (header first).
pub fn csv_without(path: &Path, skip: &[&str]) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let keep: Vec<bool> = header.iter().map(|h| !skip.contains(h)).collect();
    std::iter::once(header.join(","))
        .chain(lines.map(|l| {
            l.split(',')
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(v, _)| v)
                .collect::<Vec<_>>()
                .join(",")
        }))
        .collect()
}

/// The unit's `ExecStart=` command line, continuation lines joined, as arguments after the
/// binary; `--prefix` set to the test's and `/var/log/upc/` moved into its scratch directory.
pub fn unit_args(unit: &str, s: &Scratch) -> Vec<String> {
    let path = format!("{}/services/{unit}.service", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("unit file");
    let joined = text.replace("\\\n", " ");
    let line = joined
        .lines()
        .find_map(|l| l.strip_prefix("ExecStart="))
        .unwrap_or_else(|| panic!("{path} has no ExecStart"));
    let mut words = line.split_whitespace();
    assert_eq!(words.next(), Some("/usr/local/bin/upc"), "{path}");
    let logs = format!("{}/", s.dir.display());
    let mut args: Vec<String> = words.map(|w| w.replace("/var/log/upc/", &logs)).collect();
    let p = args
        .iter()
        .position(|a| a == "--prefix")
        .unwrap_or_else(|| panic!("{path}: no --prefix"));
    args[p + 1] = s.prefix.clone();
    args
}

/// A process that does not exit, as /proc shows it: each thread's name, state and kernel wait
/// channel, and the end of what it wrote to its stderr (its log).
pub fn where_it_hangs(pid: i32) -> String {
    let read = |p: String| std::fs::read_to_string(p).unwrap_or_default();
    let mut out = String::from("threads:");
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task"))
        .into_iter()
        .flatten();
    for task in tasks.flatten() {
        let t = task.path();
        let stat = read(format!("{}/stat", t.display()));
        // The state follows the parenthesised name.
        let state = stat.rsplit(") ").next().and_then(|r| r.split(' ').next());
        out.push_str(&format!(
            " [{} {} {}]",
            read(format!("{}/comm", t.display())).trim(),
            state.unwrap_or("?"),
            read(format!("{}/wchan", t.display())).trim()
        ));
    }
    let log = std::fs::read_link(format!("/proc/{pid}/fd/2"))
        .ok()
        .and_then(|f| std::fs::read_to_string(f).ok())
        .unwrap_or_default();
    let tail: Vec<&str> = log.lines().rev().take(20).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    format!("{out}\nits log's end:\n{}", tail.join("\n"))
}
