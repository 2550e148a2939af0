//! upc on a robot's own bus (docs/bus.md): the G1's low-level DDS topics, end to end.
//!
//! - upc's plant speaking as a G1 (`upc sim --bus unitree`), `upc bus` (its systemd unit's
//!   command line) and a real-time
//!   controller: the robot held, handed over, standing, silent for a while (damped, handed
//!   back), then its controller killed and the
//!   drives damped within the stated bound; no feed-forward torque above an effort limit.
//!   `upc bus` itself stopped and continued: a new DDS participant, the robot handed back.
//! - `upc run --bus unitree`: the same verdict as on upc's contract.
//! - An independent robot on the other side of the wire: CycloneDDS 0.10.2 (Debian's library,
//!   its Python binding built against it by scripts/setup.sh) with Unitree's IDL types and its
//!   own CRC (`scripts/g1_bus_peer.py`): every command sealed, mode_machine echoed, states with
//!   a bad CRC refused, the rate held, the joints seen by a ROS 2-typed reader; a second
//!   controller on `rt/lowcmd` makes `upc bus` refuse to start.
//!
//! DDS stays on the loopback (config/bus.toml's defaults; the Cyclone side uses
//! scripts/cyclone-loopback.xml). Each test has its own DDS domain.

mod support;

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use support::procs::*;
use support::robots::installed;
use support::starved::again_if_starved;

fn domain(d: u16) -> String {
    format!("bus.domain={d}")
}

/// A summary the failed run may not have written (no evidence then).
fn summary(path: &std::path::Path) -> Option<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Starvation in a bus participant's summary: a wait overslept by more than 5 ms.
fn participant_starved(bus_json: &std::path::Path) -> Option<String> {
    let bus = summary(bus_json)?;
    let over = bus["wait_overshoot_max"].as_f64()?;
    (over > 0.005).then(|| format!("the participant overslept a wait by {:.1} ms", over * 1e3))
}

#[test]
fn a_g1_on_the_bus_stands_and_is_damped_within_10_ms_of_its_controller_s_death() {
    let _one = serial();
    if installed("g1").is_none() {
        return;
    }
    let starved = |s: &Scratch| participant_starved(&s.path("bus.json"));
    again_if_starved("bus_damping", starved, |s| {
        let mut p = g1_bus_and_controller(
            s,
            21,
            // The robot's states lost on the wire for 80 ms, 4 s in: damped, then handed back.
            // (The participant itself stopped is the next test's.)
            &["--bus-set", "bus.sim.silence=[4.0, 0.08]"],
        );
        std::thread::sleep(Duration::from_secs(6));
        // A 15 ms stall of the controller (stopped and continued): damped, then its torques again at
        // once (`bus.hold.resume`), without the hold.
        p.signal("controller", libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(15));
        p.signal("controller", libc::SIGCONT);
        std::thread::sleep(Duration::from_secs(2));
        p.signal("controller", libc::SIGKILL);
        std::thread::sleep(Duration::from_secs(1));
        p.stop(s, "bus", libc::SIGTERM);
        p.stop(s, "sim", libc::SIGTERM);
        let bus = json(&s.path("bus.json"));
        let sim = json(&s.path("sim.json"));
        // The controller had the robot, lost it to the robot's silence, had it back, then lost it
        // to its death. Without real-time scheduling (this test
        // runs without it) the controller may stall past `command_timeout` (6 ms) before its death
        // too: the bus then damps and hands the robot back, as designed. Each loss but the last was
        // followed by a handover, and every one was damped within the bound below.
        assert!(bus["error"].is_null(), "{bus}");
        // config/bus.toml's wake-up latency bound, held where the OS lets it (root: as the
        // systemd unit runs, and as CI does).
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        let held = bus["realtime"]["cpu_latency_held"].as_bool();
        assert_eq!(
            held,
            Some(root),
            "wake-up latency bound held as root only: {bus}"
        );
        assert!(u(&bus, "robot_silences") >= 1, "{bus}");
        let silence = f(&bus, "robot_silence_max");
        assert!((0.06..1.0).contains(&silence), "{bus}");
        assert!(u(&sim, "silenced_states") >= 30, "{sim}");
        let resumes = u(&bus, "resumes");
        eprintln!(
            "the robot silent for {silence:.3} s: damped, then handed back; {} hand-overs, {} losses, \
         {resumes} resumed at once",
            u(&bus, "handovers"),
            u(&bus, "losses")
        );
        assert!(u(&bus, "handovers") >= 2, "{bus}");
        assert!(
            resumes >= 1,
            "the stalled controller was not resumed: {bus}"
        );
        assert!(f(&bus, "control_start") >= 0.0, "{bus}");
        let losses = u(&bus, "losses");
        assert!(losses >= 1, "{bus}");
        assert_eq!(u(&bus, "handovers") + resumes, losses, "{bus}");
        let transient = losses.saturating_sub(2 + u(&bus, "robot_silences"));
        if transient > 0 {
            eprintln!(
                "note: {transient} transient loss(es) of the controller before its death (no real-time scheduling)"
            );
        }
        assert!(u(&bus, "damping_states") > 100, "{bus}");
        // The bound: the controller's last torques → the damping command, within 10 ms of the
        // participant's live time. Without real-time scheduling the participant itself can be
        // descheduled for ms (a loaded 2-core machine: it overslept a 1 ms poll by 7 ms, and the
        // damping came 11.2 ms after the last torques); its own worst stalls are added, the wait's
        // and the publication's, since one loss can meet both (a CI run: 15.1 ms with a 4.6 ms
        // overslept wait and a 4.5 ms publication).
        let delay = f(&bus, "loss_to_damping_max");
        let own_stall = f(&bus, "wait_overshoot_max") + f(&bus, "publish_max");
        assert!(delay > 0.0 && delay <= 0.010 + own_stall, "{bus}");
        // The robot received damping from a loss on (once per loss at most), valid and echoed.
        let starts = sim["damping_starts"].as_array().expect("damping_starts");
        assert!(!starts.is_empty() && starts.len() as u64 <= losses, "{sim}");
        assert!(u(&sim, "damping_steps") > 200, "{sim}");
        assert_eq!(u(&sim, "bad_crc_commands"), 0, "{sim}");
        assert_eq!(u(&sim, "wrong_mode_machine"), 0, "{sim}");
        assert_eq!(u(&sim, "feedforward_over_limit"), 0, "{sim}");
        // The robot's rate as the participant read it: 500 Hz, less the robot's 80 ms silence
        // and, on a loaded machine without real-time scheduling, the states a newer one superseded
        // before they were read (91 of 3800 and a 469 Hz reading once on a 2-core CI machine). A
        // participant that read every other state, or each twice, is far outside.
        assert!((f(&bus, "robot_rate") - 500.0).abs() < 50.0, "{bus}");
        assert_eq!(u(&bus, "refused_bad_crc"), 0, "{bus}");
        assert_eq!(u(&bus, "clamped_commands"), 0, "{bus}");
    });
}

/// `upc bus` itself stopped for 15 ms and continued (a debugger, Ctrl-Z): rustdds's threads end
/// on the interrupted poll that brings (docs/bus.md, "Safety"), the robot falls silent to the
/// participant, and it joins the bus again with a new DDS participant: the robot heard again
/// well within `bus.robot_lost`, then handed back to the controller through the hold.
#[test]
fn a_g1_participant_stopped_and_continued_joins_the_bus_again_and_hands_the_robot_back() {
    let _one = serial();
    if installed("g1").is_none() {
        return;
    }
    let starved = |s: &Scratch| participant_starved(&s.path("bus.json"));
    again_if_starved("bus_rejoin", starved, |s| {
        let mut p = g1_bus_and_controller(s, 26, &[]);
        std::thread::sleep(Duration::from_secs(5));
        p.freeze(&["bus"], 0.015);
        std::thread::sleep(Duration::from_secs(3));
        p.stop(s, "bus", libc::SIGTERM);
        p.stop(s, "sim", libc::SIGTERM);
        let bus = json(&s.path("bus.json"));
        let sim = json(&s.path("sim.json"));
        assert!(bus["error"].is_null(), "{bus}");
        assert_eq!(u(&bus, "dds_rejoins"), 1, "{bus}");
        let silence = f(&bus, "robot_silence_max");
        assert!((0.0..0.5).contains(&silence) && silence > 0.0, "{bus}");
        eprintln!(
            "the participant stopped 15 ms: a new DDS participant, the robot heard again after \
             {silence:.3} s"
        );
        // The hand-over at the start and the one after the robot's silence.
        assert!(u(&bus, "handovers") >= 2, "{bus}");
        // The robot kept receiving the participant's commands after it joined again: nine in
        // ten of its states from the first command on (a participant that never came back
        // would have answered only the 4 s of 7 before the stop).
        let commanded = f(&sim, "sim_time") - f(&sim, "first_command");
        assert!(
            u(&sim, "commands") as f64 > 0.9 * 500.0 * commanded,
            "{sim}"
        );
        assert_eq!(u(&sim, "bad_crc_commands"), 0, "{sim}");
    });
}

/// upc's plant as a G1 on DDS domain `d` (`upc sim --bus unitree`, forever, with `sim_extra`),
/// `upc bus` as its systemd unit starts it, and a real-time controller of the G1.
fn g1_bus_and_controller(s: &Scratch, d: u16, sim_extra: &[&str]) -> Procs {
    let mut p = Procs::default();
    let d = domain(d);
    let sim_summary = s.path("sim.json").display().to_string();
    let scenario = s.scenario();
    p.start(
        s,
        "sim",
        &[
            "sim",
            "--bus",
            "unitree",
            "--robot",
            "g1",
            "--scenario",
            &scenario,
            "--duration",
            "0",
            "--summary",
            &sim_summary,
            "--bus-set",
            &d,
        ]
        .iter()
        .chain(sim_extra)
        .copied()
        .collect::<Vec<_>>(),
    );
    // `upc bus` as its systemd unit starts it (services/upc-bus.service: the G1's domain and
    // network, SCHED_FIFO, its summary in the log directory, here the scratch one), moved to
    // the test's domain, the loopback and the default scheduler by later `--bus-set`s.
    let mut bus = unit_args("upc-bus", s);
    assert!(bus.iter().any(|a| a.ends_with("bus.json")), "{bus:?}");
    bus.extend(
        [
            "--scenario",
            &scenario,
            "--bus-set",
            &d,
            "--bus-set",
            "bus.interface=127.0.0.1",
            "--bus-set",
            "bus.realtime.fifo_priority=0",
            "--bus-set",
            "bus.realtime.lock_memory=false",
        ]
        .map(String::from),
    );
    let bus: Vec<&str> = bus.iter().map(String::as_str).collect();
    p.start(s, "bus", &bus);
    start_controller(
        &mut p,
        s,
        &["--robot", "g1", "--set", "controller.rate_hz=500.0"],
    );
    p
}

#[test]
fn upc_run_through_the_bus_keeps_c1_standing_on_the_g1() {
    let _one = serial();
    if installed("g1").is_none() {
        return;
    }
    let starved = |s: &Scratch| participant_starved(&s.dir.join("run/c1/bus.json"));
    again_if_starved("bus_run", starved, |s| {
        let (dir, c, bus) = c1_on_the_bus(s, 22, &[]);
        // A fall in real time on a shared machine: the bus's view (a controller silent past
        // `bus.command_timeout` is damped, a new hand-over) says whether the controller starved.
        assert_eq!(u(&c, "falls"), 0, "controller: {c}\nbus: {bus}");
        assert_eq!(u(&c, "tick_errors"), 0, "{c}");
        assert!(u(&bus, "states") > 1500, "{bus}");
        // The bus announces the scenario as its robot is pushed (scaled to the G1's weight): the
        // one the controller was started for, and the forecaster's forces.
        assert_eq!(
            c["plant_scenario_mismatch"],
            serde_json::Value::Bool(false),
            "{c}"
        );
        // The controller kept the robot until its run was over: each loss but its exit was followed
        // by a hand-over back, or by its torques at once after a stall of a few ms. Without
        // real-time scheduling a 2-core machine stalls it past the bus's 6 ms now and then (damped,
        // then handed back: the designed behaviour), each counted. How often is the machine's: on
        // a loaded 2-core VM 4–13 losses in a 12 s run, the same before and after a change to the
        // tick (13 in 12.1 s failed a bound of one per second on a CI machine, 12 of them resumed
        // at once). The bound, two per second of the bus's run, still catches a controller that
        // starves (a loss every few of its ~6000 answers: hundreds).
        let (handovers, losses) = (u(&bus, "handovers"), u(&bus, "losses"));
        let bound = 2 * f(&bus, "wall_time").max(3.0) as u64;
        assert!(
            handovers >= 1 && handovers + u(&bus, "resumes") == losses && losses <= bound,
            "{bus}"
        );
        if losses > 1 {
            eprintln!(
                "note: {} transient loss(es) of the controller, each handed back (no real-time \
             scheduling)",
                losses - 1
            );
        }
        // The scenario started after the controller had the robot.
        assert!(
            f(&bus, "scenario_start") > f(&bus, "control_start"),
            "{bus}"
        );
        let sim = json(&dir.join("sim.json"));
        assert_eq!(u(&sim, "bad_crc_commands"), 0, "{sim}");
        assert_eq!(u(&sim, "feedforward_over_limit"), 0, "{sim}");
        // Both recordings, the plant's ground truth among them.
        for rrd in ["sim.rrd", "controller.rrd"] {
            let len = std::fs::metadata(dir.join(rrd)).map_or(0, |m| m.len());
            assert!(len > 10_000, "{rrd}: {len} bytes");
        }
    });
}

/// The G1 on the bus with only what it measures: `--sensing realistic` makes the plant publish
/// encoders, the IMU and the drives' torque estimates (MT-1) in `tau_est`, and the lab topic
/// carries no base or forces. The controller estimates the base and the contact and hand
/// wrenches from them (docs/estimation.md) and C1 stands.
#[test]
fn upc_run_through_the_bus_on_what_a_g1_measures_keeps_c1_standing() {
    let _one = serial();
    if installed("g1").is_none() {
        return;
    }
    let starved = |s: &Scratch| participant_starved(&s.dir.join("run/c1/bus.json"));
    again_if_starved("bus_run_g1_sensing", starved, |s| {
        let (_, c, bus) = c1_on_the_bus(s, 25, &["--sensing", "realistic"]);
        assert_eq!(u(&c, "falls"), 0, "controller: {c}\nbus: {bus}");
        assert_eq!(u(&c, "tick_errors"), 0, "{c}");
        // The base from the IMU and the encoders, the feet and the hand from the torques: on
        // (nearly) every tick, the stance found.
        let ticks = u(&c["base_estimation"], "ticks");
        assert!(ticks > 1500, "{c}");
        assert!(u(&c["base_estimation"], "no_stance") < ticks / 100, "{c}");
        let wo = &c["wrench_observer"];
        for k in ["feet_ticks", "cop_ticks", "hand_ticks"] {
            assert!(u(wo, k) + 10 >= ticks, "{k}: {c}");
        }
        assert_eq!(
            u(wo, "commanded_torque_ticks"),
            0,
            "the drives' estimates arrived: {c}"
        );
    });
}

/// `upc run --robot g1 --bus unitree --controller c1` for 4 s on DDS domain `d` with `extra`
/// arguments, into `s`: C1's directory, its `controller.json` and `bus.json`.
fn c1_on_the_bus(
    s: &Scratch,
    d: u16,
    extra: &[&str],
) -> (PathBuf, serde_json::Value, serde_json::Value) {
    let out = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([
            "run",
            "--robot",
            "g1",
            "--bus",
            "unitree",
            "--controller",
            "c1",
        ])
        .args(extra)
        .args(["--duration", "4", "--bus-set", &domain(d)])
        .args(["--quiet", "--name", "run", "--out"])
        .arg(&s.dir)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = s.dir.join("run/c1");
    let c = json(&dir.join("controller.json"));
    let bus = json(&dir.join("bus.json"));
    (dir, c, bus)
}

/// The robot venv's Python when it has CycloneDDS 0.10.2, else `None` (a failure under CI).
fn cyclone_python() -> Option<PathBuf> {
    let venv = std::env::var_os("UPC_ROBOT_VENV")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache/upc/robot-venv"))
        });
    let py = venv.map(|v| v.join("bin/python"));
    let ok = py.as_ref().is_some_and(|py| {
        Command::new(py)
            .args([
                "-c",
                "import importlib.metadata as m, cyclonedds.core; \
                 assert m.version('cyclonedds') == '0.10.2'",
            ])
            .status()
            .is_ok_and(|s| s.success())
    });
    if !ok {
        support::prereq::missing(
            "CycloneDDS 0.10.2's Python binding in the robot venv",
            support::prereq::SETUP,
        );
        return None;
    }
    py
}

fn peer() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/g1_bus_peer.py").into()
}

#[test]
fn a_cyclone_dds_g1_gets_sealed_echoed_commands_and_its_bad_states_are_refused() {
    let _one = serial();
    let Some(py) = cyclone_python() else {
        return;
    };
    if installed("g1").is_none() {
        return;
    }
    // The robot here is the test's own: below 95 % of its 500 Hz, or silent where it is not
    // told to be, the machine starved it (once: 469 Hz and a 22 ms silence, the bus damping
    // from then on).
    let starved = |s: &Scratch| {
        let robot = summary(&s.path("robot.json"))?;
        let bus = summary(&s.path("bus.json"))?;
        let rate = robot["achieved_rate_hz"].as_f64()?;
        let silences = bus["robot_silences"].as_u64()?;
        (rate < 475.0 || silences > 0)
            .then(|| format!("its robot at {rate:.0} Hz of 500, {silences} silence(s)"))
    };
    again_if_starved("bus_cyclone", starved, |s| {
        let mut p = Procs::default();
        let (robot_report, listen_report) = (s.path("robot.json"), s.path("listen.json"));
        let mut robot = Command::new(&py);
        robot
            .args([
                &peer(),
                "robot",
                "--domain",
                "23",
                "--rate",
                "500",
                "--duration",
                "7",
            ])
            .args([
                "--bad-crc-every",
                "5",
                "--stale-every",
                "7",
                "--mode-machine",
                "6",
            ])
            .arg("--report")
            .arg(&robot_report);
        let mut listen = Command::new(&py);
        listen
            .args([
                &peer(),
                "listen",
                "--domain",
                "23",
                "--duration",
                "6",
                "--report",
            ])
            .arg(&listen_report);
        let mut robot = robot.spawn().expect("cyclone robot");
        let mut listen = listen.spawn().expect("cyclone listener");
        let bus_summary = s.path("bus.json").display().to_string();
        let scenario = s.scenario();
        p.start(
            s,
            "bus",
            &[
                "bus",
                "--robot",
                "g1",
                "--scenario",
                &scenario,
                "--duration",
                "4",
                "--prefix",
                &s.prefix,
                "--summary",
                &bus_summary,
                "--bus-set",
                &domain(23),
            ],
        );
        let status = p.wait("bus", Duration::from_secs(30));
        // Both Cyclone peers end (their own durations) before any verdict: a retry on the same
        // domain must not meet this run's robot.
        let (robot, listen) = (robot.wait(), listen.wait());
        assert!(status.success(), "upc bus: {status}");
        assert!(robot.expect("robot").success());
        assert!(listen.expect("listener").success());
        let r = json(&robot_report);
        let bus = json(&s.path("bus.json"));
        // Every command reached the robot sealed with the CRC the robot computes itself, with
        // its mode_machine echoed.
        // The bus answers ~340 usable states a second for its 4 s (about 1370 commands); DDS
        // discovery between two processes on a loaded 2-core machine takes a second or two of it.
        let received = u(&r, "commands_received");
        assert!(received > 300, "{}", r["commands_received"]);
        assert_eq!(u(&r, "commands_crc_ok"), received);
        assert_eq!(r["mode_machine_seen"], serde_json::json!([6]));
        // Without a controller: the drives hold the start posture (kp > 0 on the knee, its target
        // the robot's own q), no feed-forward torque; the last command, at the end, damps.
        let cmds = r["commands"].as_array().expect("commands");
        let mid = &cmds[cmds.len() / 2];
        assert!(mid["kp"][3].as_f64().unwrap() > 0.0, "{mid}");
        assert!((mid["q"][3].as_f64().unwrap() - 0.03).abs() < 1e-6, "{mid}");
        assert_eq!(mid["tau"][3].as_f64().unwrap(), 0.0, "{mid}");
        let last = cmds.last().expect("a command");
        assert_eq!(last["kp"][3].as_f64().unwrap(), 0.0, "{last}");
        assert!(last["kd"][3].as_f64().unwrap() > 0.0, "{last}");
        assert_eq!(last["tau"][3].as_f64().unwrap(), 0.0, "{last}");
        // One state in five had a bad CRC, one in seven repeated its predecessor's tick: refused,
        // counted.
        let (refused, stale) = (u(&bus, "refused_bad_crc"), u(&bus, "refused_stale_tick"));
        let total = (refused + stale + u(&bus, "states")) as f64;
        assert!((refused as f64 / total - 0.2).abs() < 0.05, "{bus}");
        assert!(
            stale > 0 && (stale as f64 / total) < 1.0 / 7.0 + 0.03,
            "{bus}"
        );
        // The loop ran at the rate of the usable states: about 500 Hz × (1 − 1/5 − 1/7 × 4/5).
        assert!((f(&bus, "robot_rate") - 343.0).abs() < 45.0, "{bus}");
        // A ROS 2-typed reader saw the joints, by name, at the robot's positions.
        let l = json(&listen_report);
        assert!(u(&l, "joint_states_received") > 100, "{l}");
        assert_eq!(l["joint_names"][0], "left_hip_pitch_joint");
        assert_eq!(l["joint_names"][28], "right_wrist_yaw_joint");
        let q3 = l["joint_positions"][3].as_f64().unwrap();
        assert!((q3 - 0.03).abs() < 1e-6, "{l}");
    });
}

#[test]
fn upc_bus_refuses_to_start_beside_another_controller() {
    let _one = serial();
    let Some(py) = cyclone_python() else {
        return;
    };
    if installed("g1").is_none() {
        return;
    }
    let s = Scratch::new("bus_two_controllers");
    let mut other = Command::new(&py)
        .args([
            &peer(),
            "talk-cmd",
            "--domain",
            "24",
            "--rate",
            "500",
            "--duration",
            "8",
        ])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("second controller");
    std::thread::sleep(Duration::from_millis(500));
    let out = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([
            "bus",
            "--robot",
            "g1",
            "--duration",
            "2",
            "--prefix",
            &s.prefix,
        ])
        .args(["--bus-set", &domain(24), "--bus-set", "bus.discovery=3.0"])
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc bus");
    let _ = other.kill();
    let _ = other.wait();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("another participant writes rt/lowcmd"),
        "{err}"
    );
    assert!(err.contains("motion service"), "{err}");
}
