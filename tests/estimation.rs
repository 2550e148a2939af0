//! The floating-base estimator against the plant's ground truth (docs/estimation.md), through
//! `upc run` as a user runs it: lockstep, upc's plant, the estimate from the controller's log
//! against the truth from the plant's (`base_estimate_error` of the run's summary).

mod support;

use std::path::Path;
use std::time::Duration;

use serde_json::Value;
use support::procs::{Procs, Scratch, json, start_lockstep_controller, start_plant};
use support::upc_run::{num as f, scratch, upc_run};

/// `upc run --controller c1` with `extra`; returns the run's entry of `summary.json`.
fn run(out: &Path, extra: &[&str]) -> Value {
    upc_run(out, "c1", extra)
}

/// On exact sensors the estimate is the truth: the filter, the leg kinematics and the frame
/// convention agree with the plant's own integration (the estimator forced on over a measured
/// base).
#[test]
fn on_exact_sensors_the_estimate_is_the_truth() {
    let out = scratch("estimation", "exact");
    let e = run(
        &out,
        &[
            "--duration",
            "2",
            "--set",
            "controller.base_estimation.mode=\"on\"",
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
    let out = scratch("estimation", "realistic");
    let e = run(&out, &["--sensing", "realistic"]);
    assert_meets_goals(&e);
    let a = &e["base_estimate_error"];
    assert!(f(a, "samples") >= 690.0);
    assert!(f(a, "position_rms") < 5e-3, "{a:#}");
    assert_eq!(
        f(&e["controller_summary"]["base_estimation"], "imu_lost"),
        0.0
    );
}

/// The goals on `multiple_impacts` (base velocity RMS ≤ 2 cm/s, orientation RMS ≤
/// 0.5°), no restart of the estimator, and C1 standing.
fn assert_meets_goals(e: &Value) {
    let a = &e["base_estimate_error"];
    let c = &e["controller_summary"];
    eprintln!("{a:#}\n{:#}", c["base_estimation"]);
    assert!(f(a, "velocity_rms") <= 0.02, "{a:#}");
    assert!(f(a, "orientation_rms_deg") <= 0.5, "{a:#}");
    assert_eq!(f(&c["base_estimation"], "divergences"), 0.0);
    assert_eq!(f(c, "falls"), 0.0);
    assert!(f(c, "com_height_drop") < 5e-3, "{c:#}");
}

/// Standing on the sensor models: the base height does not drift (the feet on the floor pin
/// it) beyond 5 mm. The horizontal position is not observed: the gyro's bias (1e-3 rad/s)
/// times the legs' lever reads as a base velocity of ≈ 0.3 mm/s (6.5 mm RMS over 30 s, 13 mm
/// over 60 s); with its estimate (EST-6, `gyro_bias_time`) 1.4 mm over 30 s.
#[test]
fn standing_the_base_height_does_not_drift() {
    let standing = [
        "--sensing",
        "realistic",
        "--scenario",
        "standing",
        "--duration",
        "30",
    ];
    // With the gyro's bias estimated or not: two lockstep runs, side by side.
    let mut with_bias = standing.to_vec();
    with_bias.extend(["--set", "controller.base_estimation.gyro_bias_time=10"]);
    let (e, g) = std::thread::scope(|t| {
        let e = t.spawn(|| run(&scratch("estimation", "standing"), &standing));
        let g = run(&scratch("estimation", "standing-gyro-bias"), &with_bias);
        (e.join().expect("the run without the bias estimate"), g)
    });
    let a = &e["base_estimate_error"];
    eprintln!("{a:#}");
    assert!(f(a, "height_max") < 5e-3, "{a:#}");
    assert!(f(a, "position_rms") < 1e-2, "{a:#}");
    // The gyro's bias taken out: the drift goes with it.
    let b = &g["base_estimate_error"];
    eprintln!("{b:#}");
    assert!(f(b, "height_max") < 5e-3, "{b:#}");
    assert!(f(b, "position_rms") < 3e-3, "{b:#}");
    assert!(
        f(b, "position_rms") < 0.5 * f(a, "position_rms"),
        "{a:#}\n{b:#}"
    );
}

/// An attitude filter off by 2° (`imu.tilt_error`; it toppled C1 before EST-5): the soles of
/// the stance feet level it, the estimate meets the goals and C1 stands; with the levelling
/// off, the tilt is the estimate's.
#[test]
fn an_attitude_filter_off_by_two_degrees_is_levelled_by_the_soles() {
    let out = scratch("estimation", "tilt");
    let tilted = [
        "--sensing",
        "realistic",
        "--sim-set",
        "sim.sensors.imu.tilt_error=0.035",
    ];
    let e = run(&out, &tilted);
    assert_meets_goals(&e);
    let a = &e["base_estimate_error"];
    assert!(f(a, "tilt_rms_deg") < 0.1, "{a:#}");
    let out = scratch("estimation", "tilt-off");
    let mut args = tilted.to_vec();
    args.extend([
        "--duration",
        "1",
        "--set",
        "controller.base_estimation.tilt_time=0",
    ]);
    let b = &run(&out, &args)["base_estimate_error"];
    assert!(f(b, "tilt_rms_deg") > 1.5, "{b:#}");
}

/// Feet measured by one six-axis force/torque sensor each (`sim.sensors.feet = "six_axis"`,
/// no corner forces published): the estimator takes the CoP and the stance from the wrenches
/// alone; on `multiple_impacts` it meets the same goals and C1 stands.
#[test]
fn on_six_axis_foot_sensors_c1_stands() {
    let out = scratch("estimation", "six-axis");
    let e = run(
        &out,
        &[
            "--sensing",
            "realistic",
            "--sim-set",
            "sim.sensors.feet=\"six_axis\"",
        ],
    );
    assert_meets_goals(&e);
}

/// `upc controller --sensing`: `realistic` estimates the base even from a plant that publishes
/// it (a motion-capture lab checking its estimator); `truth` refuses, tick by tick, a plant
/// that does not measure it, and says why.
#[test]
fn the_controller_sensing_flag_chooses_the_estimator() {
    let cases: [(&str, &[&str], bool); 2] = [
        (
            "realistic",
            &["--sensing", "realistic", "--set", "sim.sensors.mocap=true"],
            true,
        ),
        ("truth", &["--sensing", "realistic"], false),
    ];
    for (sensing, plant, estimates) in cases {
        let s = Scratch::new(&format!("sensing_{sensing}"));
        let mut p = Procs::default();
        // Lockstep, one second of plant time: every state is answered, so the counts below are
        // the plant's, whatever the machine's load (no sleep, no rate).
        // No forecaster in this test: the controller does not wait for one's first window.
        start_lockstep_controller(
            &mut p,
            &s,
            &[
                "--sensing",
                sensing,
                "--set",
                "controller.lockstep_first_forecast_wait=0.0",
            ],
        );
        let mut plant = plant.to_vec();
        plant.extend(["--mode", "lockstep", "--duration", "1.0"]);
        start_plant(&mut p, &s, "sim", &plant);
        let st = p.wait("sim", Duration::from_secs(120));
        assert!(
            st.success(),
            "sim: {st}\n{}",
            support::procs::log(&s, "sim")
        );
        p.stop(&s, "controller", libc::SIGTERM);
        let c = json(&s.path("controller.json"));
        let steps = f(&json(&s.path("sim.json")), "steps");
        assert!(steps >= 1000.0, "{steps} plant steps");
        let log = support::procs::log(&s, "controller");
        if estimates {
            // The estimator ran on every state the plant published, and no tick failed.
            assert!(
                f(&c["base_estimation"], "ticks") >= steps - 1.0,
                "{steps}: {c:#}"
            );
            assert_eq!(f(&c, "tick_errors"), 0.0, "{c:#}");
        } else {
            // Every state refused, tick by tick, saying why.
            assert!(c["base_estimation"].is_null(), "{c:#}");
            assert!(f(&c, "tick_errors") >= steps - 1.0, "{steps}: {c:#}");
            assert!(log.contains("--sensing realistic"), "{log}");
        }
    }
}
