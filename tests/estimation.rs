//! The floating-base estimator against the plant's ground truth (docs/estimation.md), through
//! `upc run` as a user runs it: lockstep, upc's plant, the estimate from the controller's log
//! against the truth from the plant's (`base_estimate_error` of the run's summary).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("upc-estimation-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// `upc run --controller c1` with `extra`; returns the run's entry of `summary.json`.
fn run(out: &Path, extra: &[&str]) -> Value {
    let st = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([
            "run",
            "--quiet",
            "--controller",
            "c1",
            "--name",
            "run",
            "--out",
        ])
        .arg(out)
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
    s["runs"][0].clone()
}

fn f(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{key}` in {v:#}"))
}

/// On exact sensors the estimate is the truth: the filter, the leg kinematics and the frame
/// convention agree with the plant's own integration (the estimator forced on over a measured
/// base).
#[test]
fn on_exact_sensors_the_estimate_is_the_truth() {
    let out = scratch("exact");
    let e = run(
        &out,
        &[
            "--duration",
            "2",
            "--set",
            "controller.estimator.mode=\"on\"",
        ],
    );
    let a = &e["base_estimate_error"];
    eprintln!("{a:#}");
    assert!(f(a, "samples") >= 190.0);
    assert!(f(a, "position_max") < 1e-3, "{a:#}");
    assert!(f(a, "velocity_rms") < 5e-3, "{a:#}");
    assert!(f(a, "orientation_max_deg") < 1e-3, "{a:#}");
}

/// On the sensor models (docs/sensing.md), through the multiple-impact scenario: the estimate
/// meets the goals (base velocity RMS ≤ 2 cm/s, orientation RMS ≤ 0.5°), C1 stands, and
/// the estimator never lost its IMU for good nor restarted.
#[test]
fn on_realistic_sensors_the_estimate_meets_its_goals() {
    let out = scratch("realistic");
    let e = run(&out, &["--sensing", "realistic"]);
    let a = &e["base_estimate_error"];
    let c = &e["controller_summary"];
    eprintln!("{a:#}\n{:#}", c["estimator"]);
    assert!(f(a, "samples") >= 690.0);
    assert!(f(a, "velocity_rms") <= 0.02, "{a:#}");
    assert!(f(a, "orientation_rms_deg") <= 0.5, "{a:#}");
    assert!(f(a, "position_rms") < 5e-3, "{a:#}");
    assert_eq!(f(&c["estimator"], "imu_lost"), 0.0);
    assert_eq!(f(&c["estimator"], "divergences"), 0.0);
    assert_eq!(f(c, "falls"), 0.0);
    assert!(f(c, "com_height_drop") < 5e-3, "{c:#}");
}

/// Standing on the sensor models: the base height does not drift (the feet on the floor pin
/// it) beyond 5 mm.
#[test]
fn standing_the_base_height_does_not_drift() {
    let out = scratch("standing");
    let e = run(
        &out,
        &[
            "--sensing",
            "realistic",
            "--scenario",
            "standing",
            "--duration",
            "30",
        ],
    );
    let a = &e["base_estimate_error"];
    eprintln!("{a:#}");
    assert!(f(a, "height_max") < 5e-3, "{a:#}");
    assert!(f(a, "position_rms") < 5e-3, "{a:#}");
}
