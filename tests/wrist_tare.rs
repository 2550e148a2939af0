//! The wrist sensor's tare (`src/control/wrist_tare.rs`, docs/sensing.md "The wrist's
//! offset"), through `upc run` as a user runs it: every sensor exact but the wrist, which
//! carries a constant 2 N offset per axis. Fed back to the QP untared, the offset is rendered
//! as a push: the hand walks the door away before any force comes (and, on
//! `multiple_impacts`, C2 then fell). Tared, the hand holds its place.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

const BIAS: f64 = 2.0;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("upc-wrist-tare-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// Every sensor model at zero but the wrist's constant offset.
fn only_the_wrist_offset() -> Vec<String> {
    let zero = [
        "wrist.noise",
        "wrist.drift",
        "wrist.resolution",
        "wrist.dropout",
        "wrist.latency",
        "soles.noise",
        "soles.bias",
        "soles.drift",
        "soles.resolution",
        "soles.dropout",
        "soles.latency",
        "imu.gyro_noise_density",
        "imu.gyro_bias",
        "imu.gyro_bias_drift",
        "imu.accel_noise_density",
        "imu.accel_bias",
        "imu.accel_bias_drift",
        "imu.tilt_error",
        "imu.orientation_noise",
        "imu.yaw_drift",
        "imu.dropout",
        "imu.latency",
        "encoders.bits",
        "encoders.velocity_noise",
    ];
    let mut args = vec!["--sensing".to_string(), "realistic".to_string()];
    for k in zero {
        args.push("--sim-set".into());
        args.push(format!("sim.sensors.{k}=0"));
    }
    args.push("--sim-set".into());
    args.push(format!("sim.sensors.wrist.bias={BIAS}"));
    // Seed 2 draws the offset +2 N along the door's swing (x), which the door does not resist.
    args.push("--sim-set".into());
    args.push("sim.sensors.seed=2".into());
    args
}

/// C1 until just before the first push (0.85 s); the controller's part of `summary.json`.
fn run(out: &Path, extra: &[&str]) -> Value {
    let st = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["run", "--quiet", "--controller", "c1", "--duration", "0.8"])
        .args(["--name", "run", "--out"])
        .arg(out)
        .args(only_the_wrist_offset())
        .args(extra)
        .stdout(Stdio::null())
        .status()
        .expect("upc run");
    let dir = out.join("run");
    assert!(
        st.success(),
        "upc run failed: {st}\n{}",
        std::fs::read_to_string(dir.join("c1/controller.log")).unwrap_or_default()
    );
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("summary JSON");
    s["runs"][0]["controller_summary"].clone()
}

fn f(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{key}` in {v:#}"))
}

#[test]
fn a_tared_wrist_offset_is_not_rendered_as_a_push() {
    let out = scratch("tared");
    let tared = run(&out, &[]);
    let offset: Vec<f64> = tared["wrist_tare_offset"]
        .as_array()
        .expect("wrist_tare_offset")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    eprintln!(
        "tare {offset:?}, hand peak error {}",
        tared["hand_peak_error"]
    );
    // The sensor model draws each axis's sign from the seed.
    for b in &offset {
        assert!((b.abs() - BIAS).abs() < 0.1, "offset {offset:?}");
    }
    assert_eq!(f(&tared, "wrist_tare_refusals"), 0.0);
    assert!(f(&tared, "hand_peak_error") < 1e-3, "{tared:#}");

    // The same without the tare: the hand yields to the offset.
    let out = scratch("untared");
    let untared = run(&out, &["--set", "controller.wrist_tare.duration=0"]);
    eprintln!("untared hand peak error {}", untared["hand_peak_error"]);
    assert!(f(&untared, "hand_peak_error") > 5e-3, "{untared:#}");
}
