//! Faults between and inside upc's processes, and bad input (documented in services/FAULTS.md):
//! the server keeps the robot safe and loses no data. Each test starts real `upc` processes on a
//! prefix of its own, kills all of them on every path (a drop guard), and asserts counts and
//! states, never durations: this runs on loaded machines.

mod support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use support::procs::*;
use support::rrd::rrd_times;
use upc::channels::{ContractNode, ForecastMsg, MAX_FORECAST, ServiceKind, StateMsg};

fn start_forecaster(p: &mut Procs, s: &Scratch, name: &str) {
    let scenario = s.scenario();
    p.start(
        s,
        name,
        &[
            "forecast",
            "--scenario",
            &scenario,
            "--until",
            "1000",
            "--prefix",
            &s.prefix,
        ],
    );
}

/// The robot is standing: the CoM is within 3 cm of its initial height.
fn assert_standing(seen: &Seen) {
    let drop = seen.com_drop();
    assert!(drop < 0.03, "the CoM dropped {drop} m: {seen:?}");
}

#[test]
fn simulator_killed_and_restarted_controller_holds_reconnects_and_resumes() {
    let _serial = serial();
    let s = Scratch::new("restart");
    let mut p = Procs::default();
    let obs = Observer::start(&s.prefix);
    let csv = s.path("controller.csv").display().to_string();
    let rrd = s.path("controller.rrd").display().to_string();
    start_controller(&mut p, &s, &["--rrd", &rrd, "--csv", &csv]);
    start_forecaster(&mut p, &s, "forecaster");
    start_plant(&mut p, &s, "sim1", &[]);
    obs.wait_for(1, 1.0, &mut p, &s);
    p.signal("sim1", libc::SIGKILL);
    let _ = p.wait("sim1", Duration::from_secs(5));
    let killed_at = obs.get().time;
    // Longer than controller.state_timeout (0.5 s): a stale period with damping torques.
    std::thread::sleep(Duration::from_millis(900));
    start_plant(&mut p, &s, "sim2", &[]);
    obs.wait_for(2, 2.0, &mut p, &s);
    let seen = obs.get();
    p.stop(&s, "controller", libc::SIGTERM);
    p.stop(&s, "sim2", libc::SIGTERM);
    p.stop(&s, "forecaster", libc::SIGTERM);

    let c = json(&s.path("controller.json"));
    let clog = log(&s, "controller");
    assert_eq!(u(&c, "reconnects"), 1, "{c}");
    assert!(clog.contains("simulator restarted"), "{clog}");
    // It noticed the silence, held the damping torques while stale, then resumed.
    assert_eq!(u(&c, "stale_periods"), 1, "{c}");
    assert!(u(&c, "stale_ticks") > 50, "{c}");
    assert!(f(&c, "longest_state_gap") > 0.9, "{c}");
    let sim2 = json(&s.path("sim2.json"));
    assert!(u(&c, "ticks_since_reconnect") > 0, "{c}");
    // Ticked up to the kill and through the restarted run: the controller's CSV (every 10th
    // tick, stamped with the plant's time) reaches the time of the kill, goes back to the new
    // run's start and reaches the last time the test saw. How many ticks a second of wall time
    // holds is not asserted: a loaded machine misses deadlines without any fault.
    let text = std::fs::read_to_string(&csv).expect("controller.csv");
    let times: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap_or("").parse().expect("t"))
        .collect();
    let back = (1..times.len())
        .find(|&i| times[i] < times[i - 1])
        .unwrap_or_else(|| panic!("the CSV's time never goes back: {times:?}"));
    let (run1, run2) = times.split_at(back);
    assert!(
        run1[run1.len() - 1] >= killed_at - 0.05,
        "first run logged to {} s, killed at {killed_at} s",
        run1[run1.len() - 1]
    );
    assert!(run2[0] < 0.5, "the restarted run logged from {} s", run2[0]);
    assert!(
        run2[run2.len() - 1] >= seen.time - 0.05,
        "restarted run logged to {} s, seen to {} s",
        run2[run2.len() - 1],
        seen.time
    );
    assert!(u(&sim2["commands"], "accepted") > 0, "{sim2}");
    assert_eq!(u(&sim2["hold"], "handovers"), 1, "{sim2}");
    assert_eq!(u(&c, "tick_errors"), 0, "{c}");
    // The restarted simulator's robot stayed up, as measured by both sides.
    assert_eq!(seen.runs, 2);
    assert_standing(&seen);
    assert!(f(&c, "com_height_drop") < 0.03, "{c}");
}

/// In lockstep, a peer that is gone ends the run on its own: a SIGKILLed simulator stops the
/// controller after `state_timeout` ("simulator stopped", exit 0), a SIGKILLed controller
/// fails the simulator after `lockstep_timeout` (a peer only stopped or starved is waited for:
/// `tests/determinism.rs`).
#[test]
fn lockstep_peer_killed_ends_the_run() {
    let _serial = serial();
    let s = Scratch::new("lockstep_gone");
    let mut p = Procs::default();
    let obs = Observer::start(&s.prefix);
    start_lockstep_controller(&mut p, &s, &[]);
    start_forecaster(&mut p, &s, "forecaster");
    start_plant(
        &mut p,
        &s,
        "sim1",
        &["--mode", "lockstep", "--duration", "1000"],
    );
    obs.wait_for(1, 0.3, &mut p, &s);
    p.signal("sim1", libc::SIGKILL);
    let _ = p.wait("sim1", Duration::from_secs(5));
    let st = p.wait("controller", Duration::from_secs(10));
    assert!(st.success(), "controller: {st}\n{}", log(&s, "controller"));
    let c = json(&s.path("controller.json"));
    assert_eq!(c["stopped_by"], "simulator stopped", "{c}");
    // The other way round.
    start_lockstep_controller(&mut p, &s, &[]);
    start_plant(
        &mut p,
        &s,
        "sim2",
        &["--mode", "lockstep", "--duration", "1000"],
    );
    obs.wait_for(2, 0.3, &mut p, &s);
    p.signal("controller", libc::SIGKILL);
    let _ = p.wait("controller", Duration::from_secs(5));
    let st = p.wait("sim2", Duration::from_secs(10));
    assert!(!st.success(), "sim2 should fail: {st}");
    let sim_log = log(&s, "sim2");
    assert!(
        sim_log.contains("no torques answering state"),
        "sim2's log: {sim_log}"
    );
    p.stop(&s, "forecaster", libc::SIGTERM);
}

#[test]
fn lockstep_controller_waits_for_a_restarted_simulator_when_configured() {
    let _serial = serial();
    let s = Scratch::new("restart_lockstep");
    let mut p = Procs::default();
    let obs = Observer::start(&s.prefix);
    start_lockstep_controller(&mut p, &s, &["--set", "controller.reconnect_timeout=30"]);
    start_forecaster(&mut p, &s, "forecaster");
    start_plant(&mut p, &s, "sim1", &["--mode", "lockstep"]);
    obs.wait_for(1, 0.5, &mut p, &s);
    p.signal("sim1", libc::SIGKILL);
    let _ = p.wait("sim1", Duration::from_secs(5));
    std::thread::sleep(Duration::from_millis(900));
    // The new simulator runs 1 s and stops by itself: in lockstep it exits 0 only if every one
    // of its states was answered.
    start_plant(
        &mut p,
        &s,
        "sim2",
        &["--mode", "lockstep", "--duration", "1"],
    );
    let st = p.wait("sim2", Duration::from_secs(40));
    assert!(st.success(), "sim2: {st}\n{}", log(&s, "sim2"));
    p.stop(&s, "controller", libc::SIGTERM);
    p.stop(&s, "forecaster", libc::SIGTERM);
    let c = json(&s.path("controller.json"));
    assert_eq!(u(&c, "reconnects"), 1, "{c}");
    // The kill's silence, as the controller measured it (the 0.9 s sleep and sim2's start).
    assert!(f(&c, "longest_state_gap") >= 0.9, "{c}");
    // Counted as a stale period when the controller polled during it (the end of sim2 may be
    // another, before the controller got its signal). Not always: once on a loaded 2-core CI
    // machine none was counted with a 1.04 s gap measured, the loop kept from polling through
    // it (no timeout, no re-answer counted), so the gap above is the assertion.
    assert!(u(&c, "stale_periods") <= 2, "{c}");
    assert_eq!(
        u(&c, "stale_ticks"),
        0,
        "lockstep has nobody to send them to: {c}"
    );
    // States 0 to 1000 (the last one may go with its simulator).
    assert!(
        (1000..=1001).contains(&u(&c, "ticks_since_reconnect")),
        "{c}"
    );
    let sim2 = json(&s.path("sim2.json"));
    assert_eq!(u(&sim2, "steps"), 1000, "{sim2}");
    assert_standing(&obs.get());
}

#[test]
fn forecaster_killed_controller_runs_on_a_decaying_forecast_and_takes_a_new_one() {
    let _serial = serial();
    let s = Scratch::new("forecaster");
    let mut p = Procs::default();
    let obs = Observer::start(&s.prefix);
    start_controller(&mut p, &s, &[]);
    start_forecaster(&mut p, &s, "forecaster1");
    start_plant(&mut p, &s, "sim", &[]);
    obs.wait_for(1, 0.8, &mut p, &s);
    p.signal("forecaster1", libc::SIGKILL);
    let _ = p.wait("forecaster1", Duration::from_secs(5));
    // The last 2.5 s window stops covering the 1.5 s horizon 1 s after the kill.
    let t_kill = obs.get().time;
    obs.wait_for(1, t_kill + 1.8, &mut p, &s);
    start_forecaster(&mut p, &s, "forecaster2");
    obs.wait_for(1, t_kill + 3.0, &mut p, &s);
    let seen = obs.get();
    p.stop(&s, "controller", libc::SIGINT);
    p.stop(&s, "sim", libc::SIGTERM);
    p.stop(&s, "forecaster2", libc::SIGTERM);

    let c = json(&s.path("controller.json"));
    let clog = log(&s, "controller");
    assert!(c["forecast_lost"].as_bool().unwrap_or(false), "{c}");
    assert_eq!(u(&c, "forecast_losses"), 1, "{c}");
    assert!(clog.contains("no valid forecast"), "{clog}");
    // The new forecaster counts from 1 again: its windows are taken, not refused as old.
    assert!(clog.contains("forecast back"), "{clog}");
    assert!(u(&c, "forecaster_restarts") >= 1, "{c}");
    assert_eq!(u(&c["forecasts_rejected_by"], "out_of_order"), 0, "{c}");
    assert!(u(&c, "forecasts_accepted") > 100, "{c}");
    assert_eq!(u(&c, "tick_errors"), 0, "{c}");
    assert_eq!(u(&c, "reconnects"), 0, "{c}");
    assert_standing(&seen);
}

/// One kind of forecast message the test publisher sends.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Valid,
    NanForce,
    InfForce,
    ZeroStep,
    NegativeStep,
    NanStep,
    EmptyLength,
    BeyondCapacity,
    FarPast,
    FarFuture,
    NanTime,
    LiftOff,
    Replayed,
}

const BAD: [Kind; 12] = [
    Kind::NanForce,
    Kind::InfForce,
    Kind::ZeroStep,
    Kind::NegativeStep,
    Kind::NanStep,
    Kind::EmptyLength,
    Kind::BeyondCapacity,
    Kind::FarPast,
    Kind::FarFuture,
    Kind::NanTime,
    Kind::LiftOff,
    Kind::Replayed,
];

/// Publishes forecasts on `<prefix>/forecast` every 5 ms of wall time from the simulator's
/// time until it reaches `until`: valid ones, or valid and bad ones alternately.
fn publish_forecasts(prefix: &str, until: f64, with_bad: bool) -> Vec<(Kind, u64)> {
    let node = ContractNode::open(prefix, "faults-forecaster").expect("contract node");
    let out = node.publisher::<ForecastMsg>().expect("publisher");
    let wake = node.notifier(ServiceKind::Forecast).expect("notifier");
    let states = node.subscriber::<StateMsg>().expect("states");
    let mut sent: Vec<(Kind, u64)> = Vec::new();
    let mut count = |k: Kind| match sent.iter_mut().find(|(x, _)| *x == k) {
        Some((_, n)) => *n += 1,
        None => sent.push((k, 1)),
    };
    let lift = 1.0e5; // N, far above the humanoid's weight M g
    let (mut seq, mut now, mut i) = (0u64, None::<f64>, 0usize);
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(60) {
        if let Some(st) = states.latest().expect("state") {
            now = Some(st.time);
        }
        let Some(t) = now else {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        if t >= until {
            break;
        }
        let kind = if with_bad && i % 2 == 1 {
            BAD[(i / 2) % BAD.len()]
        } else {
            Kind::Valid
        };
        i += 1;
        seq += 1;
        out.send_with(|m| {
            m.seq = seq;
            m.t0 = t;
            m.dt = 0.005;
            m.len = 500; // 2.5 s of the quiet scenario's zero force (the sample is zeroed)
            match kind {
                Kind::Valid => {}
                Kind::NanForce => m.forces[7][0] = f64::NAN,
                Kind::InfForce => m.forces[300][2] = f64::INFINITY,
                Kind::ZeroStep => m.dt = 0.0,
                Kind::NegativeStep => m.dt = -0.005,
                Kind::NanStep => m.dt = f64::NAN,
                Kind::EmptyLength => m.len = 0,
                Kind::BeyondCapacity => m.len = MAX_FORECAST as u32 + 1,
                Kind::FarPast => m.t0 = t - 100.0,
                Kind::FarFuture => m.t0 = t + 100.0,
                Kind::NanTime => m.t0 = f64::NAN,
                Kind::LiftOff => m.forces[42][2] = lift,
                // An old window replayed: its seq and start are behind the current one.
                Kind::Replayed => {
                    m.seq = 1;
                    m.t0 = (t - 0.5).max(0.0);
                }
            }
        })
        .expect("send");
        wake.notify().expect("notify");
        count(kind);
        std::thread::sleep(Duration::from_millis(5));
    }
    sent
}

fn forecast_run(s: &Scratch, with_bad: bool) -> (Value, Vec<(Kind, u64)>, String) {
    let mut p = Procs::default();
    // 500 Hz: room in each period on a loaded machine, so that a difference in deadline misses
    // would be the forecasts' doing; still more than one tick per forecast (every 5 ms).
    start_controller(&mut p, s, &["--set", "controller.rate_hz=500"]);
    start_plant(&mut p, s, "sim", &[]);
    let sent = publish_forecasts(&s.prefix, 3.0, with_bad);
    p.stop(s, "controller", libc::SIGTERM);
    p.stop(s, "sim", libc::SIGTERM);
    (json(&s.path("controller.json")), sent, log(s, "controller"))
}

#[test]
fn bad_forecasts_are_rejected_counted_logged_and_leave_the_loop_alone() {
    let _serial = serial();
    let clean_dir = Scratch::new("forecast_clean");
    let (clean, sent_clean, _) = forecast_run(&clean_dir, false);
    let bad_dir = Scratch::new("forecast_bad");
    let (bad, sent_bad, bad_log) = forecast_run(&bad_dir, true);

    let n = |sent: &[(Kind, u64)], k: Kind| sent.iter().find(|(x, _)| *x == k).map_or(0, |x| x.1);
    assert_eq!(u(&clean, "forecasts_rejected"), 0, "{clean}");
    assert!(
        u(&clean, "forecasts_accepted") as f64 > 0.8 * n(&sent_clean, Kind::Valid) as f64,
        "{clean}"
    );
    // Every bad message the loop read was refused, by the right rule; the valid ones between
    // them were all taken. (The loop reads the newest message per tick: a stall may merge two.)
    let bad_sent: u64 = BAD.iter().map(|k| n(&sent_bad, *k)).sum();
    let valid_sent = n(&sent_bad, Kind::Valid);
    let rejected = u(&bad, "forecasts_rejected");
    let accepted = u(&bad, "forecasts_accepted");
    assert!(
        rejected as f64 > 0.8 * bad_sent as f64 && rejected <= bad_sent,
        "{rejected} rejected of {bad_sent} bad: {bad}"
    );
    assert!(
        accepted as f64 > 0.8 * valid_sent as f64 && accepted <= valid_sent,
        "{accepted} accepted of {valid_sent} valid: {bad}"
    );
    let by = &bad["forecasts_rejected_by"];
    for (key, kinds) in [
        ("not_finite", &[Kind::NanForce, Kind::InfForce][..]),
        (
            "bad_step",
            &[Kind::ZeroStep, Kind::NegativeStep, Kind::NanStep],
        ),
        ("bad_length", &[Kind::EmptyLength, Kind::BeyondCapacity]),
        (
            "out_of_time",
            &[Kind::FarPast, Kind::FarFuture, Kind::NanTime],
        ),
        ("lift_off", &[Kind::LiftOff]),
        ("out_of_order", &[Kind::Replayed]),
    ] {
        let sent: u64 = kinds.iter().map(|k| n(&sent_bad, *k)).sum();
        let got = u(by, key);
        assert!(
            got as f64 >= 0.6 * sent as f64 && got <= sent,
            "{key}: {got} rejected of {sent} sent: {by}"
        );
    }
    assert!(bad_log.contains("forecast rejected"), "{bad_log}");
    // Rate-limited: a log line at the 1st, 2nd, 4th… rejection, not one per message.
    let lines = bad_log.matches("forecast rejected").count() as u64;
    assert!(lines <= 2 + rejected.ilog2() as u64, "{lines} log lines");
    // The loop is unaffected: no tick error, no stale period. What a rejection costs in time is measured by a criterion bench (`cargo bench --bench control`:
    // `forecast_offer_*`), not asserted here: a timed assertion in a real-time test fails on a
    // loaded machine without any fault.
    for v in [&clean, &bad] {
        assert_eq!(u(v, "tick_errors"), 0, "{v}");
        assert_eq!(u(v, "stale_periods"), 0, "{v}");
    }
}

/// Stop a controller, a simulator and a forecaster with the given signals; every one exits 0
/// and its logs are complete up to its last tick.
fn stop_cleanly(name: &str, realtime: bool, signals: [i32; 3]) {
    let s = Scratch::new(name);
    let mut p = Procs::default();
    let obs = Observer::start(&s.prefix);
    let (crrd, srrd) = (s.path("controller.rrd"), s.path("sim.rrd"));
    let (crrd, srrd) = (crrd.display().to_string(), srrd.display().to_string());
    let mut cargs = controller_args(&s, &["--rrd", &crrd]);
    let mut sim_mode = "realtime";
    if !realtime {
        cargs.retain(|a| a != "--realtime");
        sim_mode = "lockstep";
    }
    let cargs: Vec<&str> = cargs.iter().map(String::as_str).collect();
    p.start(&s, "controller", &cargs);
    start_forecaster(&mut p, &s, "forecaster");
    let summary = s.path("sim.json").display().to_string();
    p.start(
        &s,
        "sim",
        &[
            "sim",
            "--mode",
            sim_mode,
            "--duration",
            "0",
            "--scenario",
            &s.scenario(),
            "--prefix",
            &s.prefix,
            "--summary",
            &summary,
            "--rrd",
            &srrd,
        ],
    );
    obs.wait_for(1, 1.5, &mut p, &s);
    for (proc_name, sig) in ["controller", "sim", "forecaster"].iter().zip(signals) {
        p.signal(proc_name, sig);
    }
    for proc_name in ["controller", "sim", "forecaster"] {
        let st = p.wait(proc_name, Duration::from_secs(15));
        assert!(st.success(), "{proc_name}: {st}\n{}", log(&s, proc_name));
    }
    let c = json(&s.path("controller.json"));
    let ticks = u(&c, "ticks");
    assert!(ticks > 1000, "{c}");
    // The controller's log holds every tick record the loop handed over, the last included.
    let (records, last) = rrd_times(Path::new(&crrd), "/controller/timing");
    let dropped = u(&c, "dropped_log_records");
    // Records at ticks 1, 11, 21, … (plant times on the 10 ms grid the plant records at).
    assert_eq!(records as u64 + dropped, ticks.div_ceil(10), "{c}");
    let t_end = f(&c, "sim_time");
    assert!(
        last <= t_end + 1e-6 && last > t_end - 0.0105,
        "last logged tick at {last} s, last tick at {t_end} s"
    );
    // The simulator's log holds every frame it wrote, up to its last step.
    let sim = json(&s.path("sim.json"));
    let (frames, last) = rrd_times(Path::new(&srrd), "/world/robot");
    let written = u(&sim["recorder"], "written");
    assert_eq!(u(&sim["recorder"], "dropped"), 0, "{sim}");
    assert!(
        (frames as i64 - written as i64).abs() <= 1,
        "{frames} frames in sim.rrd, {written} written"
    );
    let t_end = f(&sim, "sim_time");
    assert!(
        last <= t_end + 1e-6 && last > t_end - 0.0105,
        "last frame at {last} s, simulator stopped at {t_end} s"
    );
}

#[test]
fn sigint_and_sigterm_stop_every_process_with_complete_logs() {
    let _serial = serial();
    stop_cleanly(
        "signals_rt",
        true,
        [libc::SIGINT, libc::SIGTERM, libc::SIGINT],
    );
    stop_cleanly(
        "signals_ls",
        false,
        [libc::SIGTERM, libc::SIGINT, libc::SIGTERM],
    );
}

#[test]
fn sigkilled_processes_leave_nothing_that_stops_the_next_start() {
    let _serial = serial();
    let s = Scratch::new("sigkill");
    let obs = Observer::start(&s.prefix);
    // More rounds than the services have publisher slots (4): without the clean-up of dead
    // nodes, a start would fail on the dead ones' ports.
    for round in 1..=5u32 {
        let mut p = Procs::default();
        start_controller(&mut p, &s, &[]);
        start_forecaster(&mut p, &s, "forecaster");
        start_plant(&mut p, &s, "sim", &[]);
        obs.wait_for(round, 0.3, &mut p, &s);
        for name in ["controller", "forecaster", "sim"] {
            p.signal(name, libc::SIGKILL);
        }
        p.kill_all();
        for name in ["controller", "forecaster", "sim"] {
            let _ = std::fs::rename(
                s.path(&format!("{name}.log")),
                s.path(&format!("{name}-{round}.log")),
            );
        }
    }
    let mut p = Procs::default();
    start_controller(&mut p, &s, &[]);
    start_forecaster(&mut p, &s, "forecaster");
    start_plant(&mut p, &s, "sim", &[]);
    obs.wait_for(6, 1.5, &mut p, &s);
    p.stop(&s, "controller", libc::SIGTERM);
    p.stop(&s, "sim", libc::SIGTERM);
    p.stop(&s, "forecaster", libc::SIGTERM);
    let c = json(&s.path("controller.json"));
    assert!(u(&c, "ticks") > 1000, "{c}");
    assert!(u(&c, "forecasts_accepted") > 50, "{c}");
    let logs: String = std::fs::read_dir(&s.dir)
        .expect("dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "log"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
        .collect();
    assert!(!logs.contains("already exists"), "{logs}");
    assert!(logs.contains("removed stale iceoryx2 resources"), "{logs}");
}

/// `upc args…` fails, and its error message contains every one of `wanted`.
fn fails_with(args: &[&str], wanted: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(args)
        .env("RUST_LOG", "error")
        .output()
        .expect("upc runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "upc {args:?} succeeded");
    for w in wanted {
        assert!(err.contains(w), "upc {args:?}: `{w}` missing from: {err}");
    }
}

#[test]
fn bad_config_urdf_and_scenario_name_the_culprit_on_the_command_line() {
    let s = Scratch::new("bad_input");
    let write = |name: &str, text: &str| {
        let p = s.path(name);
        std::fs::write(&p, text).expect("write");
        p.display().to_string()
    };
    // Config: unknown key, wrong type, out of range, in a file, a scenario, or --set.
    let unknown = write("unknown.toml", "[controller]\nratehz = 500.0\n");
    let wrong = write("wrong.toml", "[controller]\nrate_hz = \"fast\"\n");
    let range = write("range.toml", "[controller]\nstate_timeout = -1.0\n");
    let nested = write(
        "nested.toml",
        "[controller.realtime]\nfifo_priority = 200\n",
    );
    for sub in ["controller", "preview"] {
        fails_with(
            &[sub, "--config", &unknown],
            &["controller.ratehz", &unknown],
        );
        fails_with(
            &[sub, "--config", &wrong],
            &["controller.rate_hz", &wrong, "string"],
        );
        fails_with(
            &[sub, "--config", &range],
            &["controller.state_timeout", &range, "> 0"],
        );
        fails_with(
            &[sub, "--config", &nested],
            &["controller.realtime.fifo_priority", &nested],
        );
    }
    fails_with(
        &["controller", "--set", "controller.reconnect_timeout=-2"],
        &["controller.reconnect_timeout", "--set"],
    );
    let sim_unknown = write("sim_unknown.toml", "[sim]\nfrictio = 0.5\n");
    let sim_wrong = write("sim_wrong.toml", "[sim.process]\nsafe_damping = [1]\n");
    let sim_range = write("sim_range.toml", "[sim]\ndt = 0.0\n");
    fails_with(
        &["sim", "--config", &sim_unknown],
        &["sim.frictio", &sim_unknown],
    );
    fails_with(
        &["sim", "--config", &sim_wrong],
        &["sim.process.safe_damping", &sim_wrong],
    );
    fails_with(&["sim", "--config", &sim_range], &["sim.dt", &sim_range]);
    let syntax = write("syntax.toml", "[controller\nrate_hz = 1\n");
    fails_with(&["controller", "--config", &syntax], &[&syntax, "syntax"]);
    let missing = s.path("nowhere.toml").display().to_string();
    fails_with(&["controller", "--config", &missing], &[&missing]);
    let scenario_cfg = write(
        "scenario_cfg.toml",
        "name = \"x\"\nduration = 1.0\nzmp_reference = [0.0, 0.0]\n[force]\nkind = \"impacts\"\nimpacts = []\n\
         [config.preview]\nhorizon = \"long\"\n",
    );
    fails_with(
        &["controller", "--scenario", &scenario_cfg],
        &["preview.horizon", &scenario_cfg],
    );

    // Scenario: a missing file names its path, for every process that takes one.
    let gone = s.path("no/such/scenario.toml").display().to_string();
    for sub in ["controller", "sim", "forecast", "preview", "run"] {
        fails_with(&[sub, "--scenario", &gone], &[&gone]);
    }

    // URDF: the error names the element at fault. The controller reads it through a robot
    // description (`--robot file.toml`), whose own errors name the key and the file.
    let description = |urdf: &str| {
        format!(
            "name = \"bad\"\n[urdf]\npath = \"{urdf}\"\n[feet.left]\nframe = \"l\"\ncontacts = \"frames\"\n\
             [feet.right]\nframe = \"r\"\ncontacts = \"frames\"\n[hand]\nframe = \"h\"\nchain_root = \"c\"\n"
        )
    };
    let missing_urdf = s.path("robot.urdf").display().to_string();
    let d = write("missing.toml", &description(&missing_urdf));
    fails_with(&["controller", "--robot", &d], &[&missing_urdf]);
    let typo = write(
        "typo.toml",
        &description(&missing_urdf).replace("[hand]", "[hand]\nframes = 1"),
    );
    fails_with(&["controller", "--robot", &typo], &["hand.frames", &typo]);
    fails_with(&["sim", "--robot", "nao"], &["no robot named `nao`"]);
    let inertial = r#"<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let robot = |body: &str| {
        format!(
            r#"<robot name="r"><link name="base">{inertial}</link><link name="arm">{inertial}</link>{body}</robot>"#
        )
    };
    let cases = [
        (
            "child.urdf",
            robot(r#"<joint name="elbow" type="revolute"><parent link="base"/><child link="forearm"/><axis xyz="0 0 1"/></joint>"#),
            vec!["elbow", "forearm"],
        ),
        (
            "type.urdf",
            robot(r#"<joint name="wrist" type="ball"><parent link="base"/><child link="arm"/></joint>"#),
            vec!["wrist", "ball"],
        ),
        (
            "mass.urdf",
            r#"<robot name="r"><link name="base"><inertial><mass value="heavy"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link></robot>"#.to_string(),
            vec!["mass", "heavy", "base"],
        ),
        (
            "axis.urdf",
            robot(r#"<joint name="knee" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1"/></joint>"#),
            vec!["axis", "knee"],
        ),
        (
            "limit.urdf",
            robot(r#"<joint name="hip" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/><limit lower="-1" upper="x" effort="1" velocity="1"/></joint>"#),
            vec!["limit", "upper", "hip"],
        ),
        (
            "unclosed.urdf",
            r#"<robot name="r"><link name="base">"#.to_string(),
            vec!["link", "base", "not closed"],
        ),
        (
            "inertia.urdf",
            r#"<robot name="r"><link name="base"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="-1" iyz="0" izz="1"/></inertial></link></robot>"#.to_string(),
            vec!["base", "inertia"],
        ),
    ];
    for (file, text, wanted) in &cases {
        let p = write(file, text);
        fails_with(&["model", &p], wanted);
        let d = write(&format!("{file}.toml"), &description(&p));
        fails_with(&["controller", "--robot", &d], wanted);
    }
}
