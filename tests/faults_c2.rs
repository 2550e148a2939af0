//! C2 faults: its gain search panics or is starved. C1 goes on with the nominal gains and the
//! event is counted and logged. The fault is injected by replacing the search through
//! `run_server_with` / `GainHandoff::spawn_with` (not reachable from the command line); the
//! controller runs in this process against a real `upc sim` process.

mod support;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, Once};
use std::time::{Duration, Instant};

use upc::config::{Config, ControllerKind, LoopMode};
use upc::control::GainHandoff;
use upc::control::gain_thread::{GainSnapshot, GainSolver, StampedSchedule};
use upc::control::server::{Extensions, ServerOptions, ServerSummary, run_server_with};
use upc::preview::PreviewError;

static SERIAL: Mutex<()> = Mutex::new(());
static LOGS: Mutex<Vec<u8>> = Mutex::new(Vec::new());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

struct Capture;

impl Write for Capture {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        LOGS.lock()
            .unwrap_or_else(|p| p.into_inner())
            .extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The log lines of every thread of this test binary so far.
fn logs() -> String {
    static INIT: Once = Once::new();
    INIT.call_once(|| {
        // The injected panics are expected: skip the default hook's report (and its backtrace,
        // slow enough to starve the low-priority C2 thread on a loaded machine).
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if std::thread::current().name() != Some("upc-c2") {
                default(info);
            }
        }));
        tracing_subscriber::fmt()
            .with_writer(|| Capture)
            .with_ansi(false)
            .init();
    });
    String::from_utf8_lossy(&LOGS.lock().unwrap_or_else(|p| p.into_inner())).into_owned()
}

/// A gain search that panics every time.
struct Panics;

impl GainSolver for Panics {
    fn solve(
        &mut self,
        _: &GainSnapshot,
        _: usize,
        _: &mut StampedSchedule,
    ) -> Result<(), PreviewError> {
        panic!("injected C2 fault");
    }
    fn reset(&mut self) {}
}

/// A gain search that returns the constant gains `kp`, `kd` at once, except that it panics on
/// call number `panic_at`, and that its first search from simulated time `stall_from` on lasts
/// until the simulator reaches `stall_until` (starved: no schedule meanwhile).
struct Scripted {
    kp: f64,
    kd: f64,
    calls: Arc<AtomicU32>,
    panic_at: Option<u32>,
    stall_from: f64,
    stall_until: f64,
    stalled: bool,
}

impl GainSolver for Scripted {
    fn solve(
        &mut self,
        snap: &GainSnapshot,
        _: usize,
        out: &mut StampedSchedule,
    ) -> Result<(), PreviewError> {
        let call = self.calls.fetch_add(1, Ordering::SeqCst) + 1;
        if self.panic_at == Some(call) {
            panic!("injected C2 fault");
        }
        if !self.stalled && snap.time >= self.stall_from {
            self.stalled = true;
            let give_up = Instant::now() + Duration::from_secs(60);
            while sim_time() < self.stall_until && Instant::now() < give_up {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        out.schedule.kp.fill(self.kp);
        out.schedule.kd.fill(self.kd);
        out.iterations = 1;
        Ok(())
    }
    fn reset(&mut self) {}
}

fn c2_config(mode: LoopMode) -> Config {
    let mut c = Config::embedded_default().expect("defaults");
    c.controller.kind = ControllerKind::C2;
    c.controller.mode = mode;
    // No forecaster runs here: a short wait for one (30 s by default) keeps the test short.
    c.controller.lockstep_first_forecast_wait = 1.0;
    c
}

/// Gains different from the nominal ones, inside the search's bounds.
fn other_gains(c: &Config) -> (f64, f64) {
    let [lo, hi] = c.gain_search.kp_bounds;
    let kp = if c.hand.kp * 1.5 <= hi {
        c.hand.kp * 1.5
    } else {
        0.5 * (lo + c.hand.kp)
    };
    (kp, c.nominal_kd(kp))
}

#[test]
fn gain_thread_survives_a_panicking_search_and_serves_the_next_one() {
    logs();
    let config = c2_config(LoopMode::Lockstep);
    let mut r = support::humanoid::rig(&config, ControllerKind::C2);
    r.tick(None).expect("tick");
    let (kp, kd) = other_gains(&config);
    let calls = Arc::new(AtomicU32::new(0));
    let solver = Scripted {
        kp,
        kd,
        calls: Arc::clone(&calls),
        panic_at: Some(1),
        stall_from: f64::INFINITY,
        stall_until: 0.0,
        stalled: false,
    };
    let mut h = GainHandoff::spawn_with(&config, Box::new(solver)).expect("thread");
    let wait = |h: &mut GainHandoff, f: &dyn Fn(&mut GainHandoff) -> bool| {
        let until = Instant::now() + Duration::from_secs(20);
        while !f(h) {
            assert!(Instant::now() < until, "the C2 thread did not get there");
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    h.offer(|s| r.core.snapshot(s, 1));
    wait(&mut h, &|h| h.stats.panics.load(Ordering::Relaxed) == 1);
    // The panic published nothing: the loop still sees "no schedule" (nominal gains).
    assert_eq!(h.latest().seq, 0);
    assert!(h.alive());
    h.offer(|s| r.core.snapshot(s, 2));
    wait(&mut h, &|h| h.latest().seq == 2);
    assert!(h.latest().schedule.kp.iter().all(|k| *k == kp));
    assert_eq!(h.stats.solves.load(Ordering::Relaxed), 1);
    assert!(logs().contains("C2 gain search panicked"));
}

/// No push on the door: no forecaster is needed (the controller's forecast is zero).
const QUIET: &str = "name = \"quiet\"\nduration = 1000.0\nzmp_reference = [0.0, 0.0]\n\
                     [force]\nkind = \"impacts\"\nimpacts = []\n";

/// A `upc sim` process on `prefix`, SIGKILLed when dropped.
struct Sim(Child);

impl Sim {
    fn start(prefix: &str, mode: &str, scenario: &Path) -> Sim {
        Sim(Command::new(env!("CARGO_BIN_EXE_upc"))
            .args(["sim", "--mode", mode, "--duration", "0", "--scenario"])
            .arg(scenario)
            .args(["--prefix", prefix])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("upc sim"))
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The simulator's latest time (f64 bits), for a search that stalls until a simulated time.
static SIM_TIME: AtomicU64 = AtomicU64::new(0);

fn sim_time() -> f64 {
    f64::from_bits(SIM_TIME.load(Ordering::Relaxed))
}

/// Follows the simulator's ground truth into [`SIM_TIME`] while alive.
struct SimClock(Arc<AtomicBool>, Option<std::thread::JoinHandle<()>>);

impl SimClock {
    fn start(prefix: &str) -> SimClock {
        SIM_TIME.store(0, Ordering::Relaxed);
        let stop = Arc::new(AtomicBool::new(false));
        let (stop_t, prefix) = (Arc::clone(&stop), prefix.to_string());
        let t = std::thread::spawn(move || {
            let node =
                upc::channels::ContractNode::open(&prefix, "faults-clock").expect("contract node");
            let truth = node
                .subscriber::<upc::channels::GroundTruthMsg>()
                .expect("subscriber");
            while !stop_t.load(Ordering::Relaxed) {
                if let Some(g) = truth.latest().expect("receive") {
                    SIM_TIME.store(g.time.to_bits(), Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        SimClock(stop, Some(t))
    }
}

impl Drop for SimClock {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
        if let Some(t) = self.1.take() {
            let _ = t.join();
        }
    }
}

/// Run the controller in this process for `duration` simulated seconds with `solver` as C2's
/// search; returns its summary and the (t, kp) of every logged tick.
fn run(
    name: &str,
    config: &Config,
    duration: f64,
    solver: Box<dyn GainSolver>,
) -> (ServerSummary, Vec<(f64, f64)>) {
    let prefix = format!("faults_c2_{name}_{}", std::process::id());
    let dir = std::env::temp_dir().join(format!("upc-{prefix}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let csv: PathBuf = dir.join("controller.csv");
    let mode = match config.controller.mode {
        LoopMode::Lockstep => "lockstep",
        LoopMode::Realtime => "realtime",
    };
    let scenario = dir.join("quiet.toml");
    std::fs::write(&scenario, QUIET).expect("scenario");
    let _sim = Sim::start(&prefix, mode, &scenario);
    let _clock = SimClock::start(&prefix);
    let opts = ServerOptions {
        prefix,
        duration: Some(duration),
        rrd: Some(dir.join("controller.rrd")),
        recording_id: "faults".into(),
        live: None,
        zmp_offset: [0.0, 0.0],
        startup_timeout: 40.0,
        csv: Some(csv.clone()),
        scenario_hash: None,
        robot_hash: None,
        robot_name: "icub_like".into(),
        held_mass: nalgebra::Matrix3::zeros(),
    };
    let robot = upc::robot::Robot::embedded_default().expect("robot");
    let stop = Arc::new(AtomicBool::new(false));
    let extensions = Extensions {
        c2_solver: Some(solver),
        ..Extensions::default()
    };
    let summary = run_server_with(config, &robot, &opts, stop, extensions).expect("run");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).expect("column");
    let (ti, ki) = (col("t"), col("kp"));
    let rows = lines
        .map(|l| {
            let v: Vec<f64> = l
                .split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect();
            (v[ti], v[ki])
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    (summary, rows)
}

#[test]
fn c2_panicking_in_a_run_leaves_c1_on_the_nominal_gains() {
    let _serial = serial();
    logs();
    let config = c2_config(LoopMode::Lockstep);
    let (s, rows) = run("panic", &config, 2.0, Box::new(Panics));
    assert!(s.c2.c2_panics >= 1, "{s:?}");
    assert_eq!(s.c2.c2_solves, 0, "{s:?}");
    // Past the horizon (1.5 s) with no schedule: counted once, C1 on nominal gains.
    assert_eq!(s.events.c2_stale_schedules, 1, "{s:?}");
    assert!(s.figures.ticks >= 1990, "{s:?}");
    assert_eq!(s.events.tick_errors, 0);
    assert!(s.figures.com_height_drop < 0.03, "{s:?}");
    assert!(rows.len() > 150);
    assert!(
        rows.iter().all(|(_, kp)| *kp == config.hand.kp),
        "a gain other than the nominal {} was applied",
        config.hand.kp
    );
    let l = logs();
    assert!(l.contains("C2 gain search panicked"), "{l}");
    assert!(
        l.contains("C2 schedule missing or older than the horizon"),
        "{l}"
    );
}

#[test]
fn c2_starved_past_the_horizon_falls_back_to_nominal_gains_and_recovers() {
    let _serial = serial();
    logs();
    let config = c2_config(LoopMode::Lockstep);
    let (kp, kd) = other_gains(&config);
    let solver = Scripted {
        kp,
        kd,
        calls: Arc::new(AtomicU32::new(0)),
        panic_at: None,
        // The search from t ≈ 0.3 s lasts until t = 3 s: the schedule before it is older than
        // the 1.5 s horizon from t ≈ 1.8 s until the search after it, at t ≈ 3 s.
        stall_from: 0.3,
        stall_until: 3.0,
        stalled: false,
    };
    let (s, rows) = run("starved", &config, 4.0, Box::new(solver));
    assert_eq!(s.events.c2_stale_schedules, 1, "{s:?}");
    assert_eq!(s.c2.c2_panics, 0);
    assert!(s.c2.c2_solves >= 2, "{s:?}");
    assert!(s.figures.com_height_drop < 0.03, "{s:?}");
    let applied = |from: f64, to: f64, k: f64| {
        rows.iter()
            .filter(|(t, _)| *t > from && *t < to)
            .any(|(_, x)| *x == k)
    };
    let nominal = config.hand.kp;
    assert!(
        applied(0.05, 1.4, kp),
        "C2's gains before the stall: {rows:?}"
    );
    assert!(!applied(0.05, 1.4, nominal), "{rows:?}");
    assert!(
        applied(1.85, 2.95, nominal),
        "nominal gains while starved: {rows:?}"
    );
    assert!(!applied(1.85, 2.95, kp), "{rows:?}");
    assert!(
        applied(3.2, 4.0, kp),
        "C2's gains again after the stall: {rows:?}"
    );
    assert!(logs().contains("C2 schedule missing or older than the horizon"));
}
