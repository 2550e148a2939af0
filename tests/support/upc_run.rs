//! `upc run` as a user runs it, from a test: a scratch directory, the run, its summary.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

/// A fresh directory for test `test`'s case `name`.
pub fn scratch(test: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("upc-{test}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// `upc run --quiet --controller <controller> --name run --out <out> <args>`; the run's entry
/// of `summary.json` (its `controller_summary`, `base_estimate_error`, …). A failed run panics
/// with the controller's log.
pub fn upc_run<S: AsRef<std::ffi::OsStr>>(out: &Path, controller: &str, args: &[S]) -> Value {
    let st = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["run", "--quiet", "--controller", controller])
        .args(["--name", "run", "--out"])
        .arg(out)
        .args(args)
        .stdout(Stdio::null())
        .status()
        .expect("upc run");
    let dir = out.join("run");
    assert!(
        st.success(),
        "upc run failed: {st}\n{}",
        std::fs::read_to_string(dir.join(controller).join("controller.log")).unwrap_or_default()
    );
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("summary JSON");
    s["runs"][0].clone()
}

/// The number at `key` of `v`.
pub fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{key}` in {v:#}"))
}

/// `--sensing realistic` with every sensor model at zero (`--sim-set sim.sensors.<key>=0`),
/// then `keep`'s settings: the sensor block exact but for what a test puts back.
pub fn exact_sensors_but(keep: &[&str]) -> Vec<String> {
    const MODELS: [&str; 24] = [
        "wrist.noise",
        "wrist.drift",
        "wrist.bias",
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
        "encoders.velocity_noise",
    ];
    let mut args = vec!["--sensing".to_string(), "realistic".to_string()];
    let sets = MODELS
        .iter()
        .map(|k| format!("sim.sensors.{k}=0"))
        .chain(["sim.sensors.encoders.bits=0".to_string()])
        .chain(keep.iter().map(|k| format!("sim.sensors.{k}")));
    for s in sets {
        args.extend(["--sim-set".to_string(), s]);
    }
    args
}
