//! The product as users meet it: `upc run` starts the simulator, the forecaster and the
//! controller as separate processes over iceoryx2 and writes a run directory.

use std::path::Path;
use std::process::Command;

fn upc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_upc"))
}

/// The processes of this machine whose command line contains `pattern`, as "pid: command
/// line", read from /proc (this process excluded). Fails rather than finding none when /proc
/// cannot be read: "nothing left running" must not hold by default.
fn processes_with(pattern: &str) -> Vec<String> {
    let me = std::process::id().to_string();
    let mut found = Vec::new();
    let mut seen = 0;
    for entry in std::fs::read_dir("/proc").expect("/proc lists the processes") {
        let entry = entry.expect("/proc entry");
        let pid = entry.file_name().to_string_lossy().into_owned();
        if !pid.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        seen += 1;
        // A process that ended since the listing has no cmdline: it is not running.
        let Ok(raw) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let cmdline = String::from_utf8_lossy(&raw).replace('\0', " ");
        if pid != me && cmdline.contains(pattern) {
            found.push(format!("{pid}: {}", cmdline.trim_end()));
        }
    }
    assert!(seen > 1, "/proc lists {seen} processes");
    found
}

/// Entity paths and timelines of every chunk in a `.rrd` file (it must decode to the end).
fn rrd_contents(
    p: &Path,
) -> (
    std::collections::BTreeSet<String>,
    std::collections::BTreeSet<String>,
) {
    let file = std::fs::File::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut entities = std::collections::BTreeSet::new();
    let mut timelines = std::collections::BTreeSet::new();
    for msg in re_log_encoding::DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
        let msg = msg.unwrap_or_else(|e| panic!("{} does not decode: {e}", p.display()));
        if let re_log_types::LogMsg::ArrowMsg(_, arrow) = msg {
            let chunk =
                re_chunk::Chunk::from_arrow_msg(&arrow).unwrap_or_else(|e| panic!("chunk: {e}"));
            entities.insert(chunk.entity_path().to_string());
            timelines.extend(chunk.timelines().keys().map(|t| t.to_string()));
        }
    }
    (entities, timelines)
}

fn read_json(p: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn launcher_runs_the_three_processes_and_writes_the_run() {
    let out = std::env::temp_dir().join(format!("upc-system-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let status = upc()
        .args([
            "run",
            "--scenario",
            "single_impact",
            "--duration",
            "1.6",
            "--controller",
            "c1",
            "--quiet",
            "--name",
            "t",
        ])
        .arg("--out")
        .arg(&out)
        .status()
        .expect("upc runs");
    assert!(status.success(), "upc run failed: {status}");
    let dir = out.join("t");
    let summary = read_json(&dir.join("summary.json"));
    let run = &summary["runs"][0];
    assert_eq!(run["controller"], "c1");
    let c = &run["controller_summary"];
    // 1.6 s at 1 kHz, answered tick by tick in lockstep.
    let ticks = c["ticks"].as_u64().unwrap_or(0);
    assert!((1590..=1602).contains(&ticks), "ticks {ticks}");
    assert!(c["forecasts_accepted"].as_u64().unwrap_or(0) > 100, "{c}");
    assert_eq!(c["forecasts_rejected"], 0);
    assert_eq!(c["tick_errors"], 0);
    // Balanced: the CoM height holds (no fall) and the hand stays near its set-point.
    let drop = c["com_height_drop"].as_f64().unwrap_or(1.0);
    assert!(drop < 0.03, "CoM dropped {drop} m");
    let peak = c["hand_peak_error"].as_f64().unwrap_or(1.0);
    assert!(peak < 0.1, "hand peak error {peak}");
    for (f, min_len) in [
        ("sim.rrd", 100_000),
        ("controller.rrd", 100_000),
        ("controller.csv", 10_000),
        ("controller.json", 200),
    ] {
        let p = dir.join("c1").join(f);
        let len = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
        assert!(
            len > min_len,
            "{} is missing or too short ({len} bytes)",
            p.display()
        );
    }
    // The logs open and hold what a user looks for, on the shared sim_time timeline.
    let (ctl, ctl_time) = rrd_contents(&dir.join("c1/controller.rrd"));
    for e in [
        "/controller/zmp/measured_x",
        "/controller/zmp/predicted_x",
        "/controller/hand/error",
        "/controller/gains/kp",
        "/controller/timing/tick_us",
        "/controller/plan/zmp",
    ] {
        assert!(ctl.contains(e), "controller.rrd lacks {e}: {ctl:?}");
    }
    assert!(ctl_time.contains("sim_time"), "{ctl_time:?}");
    let (sim, sim_time) = rrd_contents(&dir.join("c1/sim.rrd"));
    assert!(
        sim.iter().any(|e| e.contains("robot")),
        "sim.rrd entities: {sim:?}"
    );
    assert!(sim_time.contains("sim_time"), "{sim_time:?}");
    // The CSV holds the whole run: its last tick is at the end of the duration.
    let csv = std::fs::read_to_string(dir.join("c1/controller.csv")).unwrap_or_default();
    let last_t: f64 = csv
        .lines()
        .last()
        .and_then(|l| l.split(',').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or(0.0);
    assert!(last_t > 1.5, "last logged tick at {last_t} s");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn forecaster_and_controller_report_bad_arguments() {
    let o = upc().args(["forecast", "--dt=-1"]).output().expect("runs");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--dt must be > 0"));
    let o = upc()
        .args(["controller", "--set", "controller.rate_hz=0"])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("controller.rate_hz") && err.contains("--set"),
        "{err}"
    );
}

#[test]
fn python_forecaster_example_drives_a_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".venv/bin/python");
    assert!(
        python.exists(),
        "{} missing: run scripts/setup.sh (installs the iceoryx2 Python package)",
        python.display()
    );
    let out = std::env::temp_dir().join(format!("upc-system-py-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cmd = format!(
        "{} {}",
        python.display(),
        root.join("examples/python/forecaster.py").display()
    );
    let status = upc()
        .args([
            "run",
            "--scenario",
            "single_impact",
            "--duration",
            "1.3",
            "--controller",
            "c1",
            "--quiet",
            "--name",
            "py",
        ])
        .args(["--forecaster", &cmd])
        .arg("--out")
        .arg(&out)
        .status()
        .expect("upc runs");
    assert!(status.success(), "upc run failed: {status}");
    // The external forecaster ended with the run: no process of it is left behind.
    let script = root.join("examples/python/forecaster.py");
    let left = processes_with(&script.display().to_string());
    assert!(
        left.is_empty(),
        "forecaster processes left running: {left:?}"
    );
    let c = read_json(&out.join("py/c1/controller.json"));
    let accepted = c["forecasts_accepted"].as_u64().unwrap_or(0);
    assert!(
        accepted > 100,
        "the controller took {accepted} Python forecasts"
    );
    assert_eq!(c["forecasts_rejected"], 0);
    // The Python impact (50 N from t = 1 s) reached the hand: it moved off its set-point.
    let peak = c["hand_peak_error"].as_f64().unwrap_or(0.0);
    assert!(peak > 0.002 && peak < 0.1, "hand peak error {peak}");
    let _ = std::fs::remove_dir_all(&out);
}

/// `upc run` fails after starting some of its participants (here the remote forecaster exits
/// before its first window, once the simulator and the bridge run): it reports the cause and
/// leaves none of them running. Before, the simulator waited out its time-out and the bridge
/// ran until killed by hand.
#[test]
fn a_failed_start_leaves_no_participant_running() {
    let out = std::env::temp_dir().join(format!("upc-system-fail-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let child = upc()
        .args(["run", "--controller", "c1", "--duration", "1", "--quiet"])
        .args(["--name", "fail", "--forecaster-over-zenoh"])
        .args(["--forecaster", "sh -c 'exit 3'"])
        .arg("--out")
        .arg(&out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("upc runs");
    // The participants' service prefix names the launcher's pid.
    let prefix = format!("upc_{}_c1", child.id());
    let output = child.wait_with_output().expect("upc run");
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "upc run succeeded: {err}");
    assert!(err.contains("before its first window"), "{err}");
    let left = processes_with(&prefix);
    assert!(left.is_empty(), "participants left running: {left:?}");
    let _ = std::fs::remove_dir_all(&out);
}

/// `--forecast-error-shape` reaches the controller through the built-in forecaster: a forecast
/// rotated 30° about z arrives as such (the forecast as received, `f_raw`, points 30° off the
/// push); a shape the scenario cannot take, or an unknown one, is refused before any process
/// starts.
#[test]
fn a_forecast_of_the_wrong_shape_reaches_the_controller_as_asked() {
    let out = std::env::temp_dir().join(format!("upc-system-shape-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let status = upc()
        .args(["run", "--scenario", "single_impact", "--controller", "c1"])
        .args(["--duration", "2", "--quiet", "--name", "rotated"])
        .args(["--forecast-error-shape", "rotated:30"])
        // As the forecaster sent it, not along the door's path (FC-0).
        .args([
            "--set",
            "controller.forecast_on_free_direction=false",
            "--out",
        ])
        .arg(&out)
        .status()
        .expect("upc runs");
    assert!(status.success(), "upc run failed: {status}");
    let text = std::fs::read_to_string(out.join("rotated/c1/controller.csv")).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).expect(n);
    let (x, y) = (col("f_raw_x"), col("f_raw_y"));
    let peak = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .map(|c| [c[x], c[y]].map(|v| v.parse::<f64>().expect("number")))
        .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
        .expect("rows");
    let scenario = upc::scenario::Scenario::load("single_impact").expect("scenario");
    let push = (0..4000)
        .map(|k| scenario.force.at(k as f64 * 1e-3))
        .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
        .expect("push");
    let turned = (peak[1].atan2(peak[0]) - push[1].atan2(push[0])).to_degrees();
    let turned = (turned + 540.0) % 360.0 - 180.0;
    assert!(
        (turned - 30.0).abs() < 0.5,
        "turned {turned}°: {peak:?} vs {push:?}"
    );
    for (shape, why) in [
        ("wobbly", "unknown forecast shape"),
        ("step:2", "takes no value"),
    ] {
        let o = upc()
            .args(["run", "--quiet", "--forecast-error-shape", shape])
            .output()
            .expect("upc runs");
        assert!(!o.status.success(), "{shape}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(why), "{shape}: {err}");
    }
    let _ = std::fs::remove_dir_all(&out);
}
