//! The whole system on robots nobody here wrote: `upc run --robot R` (simulator, forecaster,
//! controller as processes, lockstep) on the official iCub, TALOS and the G1 through the first
//! push of the multiple-impact scenario, with its forces scaled to each robot's mass; and a
//! controller given another robot than the plant's refuses its states. Without the robot
//! packages: a failure under CI, a visible skip elsewhere (`support::prereq`).

mod support;

use std::process::Command;

use support::procs::*;
use support::robots::installed;

#[test]
fn each_robot_rides_out_the_first_push_with_c1() {
    let _one = serial();
    // Romeo with its fingers (nq = 62: beyond the contract's former 48) and with them locked.
    for name in ["icub", "talos", "g1", "romeo", "romeo_locked"] {
        let Some(robot) = installed(name) else {
            continue;
        };
        let s = Scratch::new(&format!("robot_{name}"));
        // 2 s: the first impact (peak at 1.4 s) and its fall.
        let out = Command::new(env!("CARGO_BIN_EXE_upc"))
            .args([
                "run",
                "--robot",
                name,
                "--controller",
                "c1",
                "--duration",
                "2",
            ])
            .args(["--quiet", "--name", "run", "--out"])
            .arg(&s.dir)
            .env("RUST_LOG", "warn")
            .output()
            .expect("upc run");
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let dir = s.dir.join("run");
        let summary = json(&dir.join("summary.json"));
        assert_eq!(summary["robot"], name);
        let scale = f(&summary, "force_scale");
        let (mass, capacity) = upc::robot::reference().expect("reference");
        let d = &robot.derived;
        let want = (d.mass / mass).min(d.hand_force_capacity / capacity);
        assert!((scale - want).abs() < 1e-12, "{name}: forces × {scale}");
        let c = json(&dir.join("c1/controller.json"));
        assert_eq!(c["robot"], name);
        assert_eq!(u(&c, "tick_errors"), 0, "{name}");
        assert_eq!(u(&c, "wbc_fallbacks"), 0, "{name}");
        // Standing, the push ridden out: the CoM height held within 5 mm, the CoP inside the
        // support (positive margin), the plant's contacts not sliding.
        assert!(f(&c, "com_height_drop") < 5e-3, "{name}: {c}");
        assert!(f(&c, "min_zmp_margin") > 0.0, "{name}: {c}");
        let sim = json(&dir.join("c1/sim.json"));
        assert_eq!(sim["robot"], name);
        assert!(f(&sim, "max_slip_speed") < 0.05, "{name}: {sim}");
    }
}

#[test]
fn a_controller_for_another_robot_refuses_the_plant_states() {
    let _one = serial();
    // The iCub and the iCub-like humanoid have the same nq and nv: only the robot hash tells.
    let Some(_) = installed("icub") else { return };
    let s = Scratch::new("robot_mismatch");
    let mut p = Procs::default();
    let pre = s.prefix.clone();
    p.start(
        &s,
        "sim",
        &[
            "sim",
            "--robot",
            "icub",
            "--prefix",
            &pre,
            "--duration",
            "0.3",
        ],
    );
    p.start(
        &s,
        "forecast",
        &["forecast", "--prefix", &pre, "--until", "0.3"],
    );
    let summary = s.path("controller.json").display().to_string();
    p.start(
        &s,
        "controller",
        &[
            "controller",
            "--prefix",
            &pre,
            "--duration",
            "0.3",
            "--summary",
            &summary,
            "--set",
            "controller.state_timeout=0.5",
        ],
    );
    p.wait("controller", std::time::Duration::from_secs(60));
    p.kill_all();
    let c = json(&s.path("controller.json"));
    assert!(u(&c, "tick_errors") > 0, "{c}");
    let text = log(&s, "controller");
    assert!(text.contains("another robot"), "{text}");
}
