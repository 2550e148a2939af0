//! Balance on what a G1 measures (docs/estimation.md, WO; docs/sensing.md): its joints, its
//! drives' torque estimates (MT-1: noise, friction, resolution, latency) and its IMU, no foot or
//! wrist force sensor. `upc run --robot g1 --sensing realistic`: the plant publishes no foot
//! wrench, CoP or hand force; the controller estimates them from the torques and the base from
//! the IMU and the joints. On `multiple_impacts`, C1 stands on both plants where C0 falls.
//! Without the G1's package or MuJoCo: a failure under CI, a visible skip elsewhere.

mod support;

use std::process::Command;

use support::procs::*;
use support::robots::installed;

/// One controller on the G1 with its own sensors; the run's controller summary.
fn run(s: &Scratch, plant: &str, controller: &str) -> serde_json::Value {
    let name = format!("{plant}_{controller}");
    let out = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args([
            "run",
            "--robot",
            "g1",
            "--sensing",
            "realistic",
            "--plant",
            plant,
        ])
        .args([
            "--controller",
            controller,
            "--quiet",
            "--name",
            &name,
            "--out",
        ])
        .arg(&s.dir)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc run");
    assert!(
        out.status.success(),
        "{plant} {controller}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    json(&s.dir.join(&name).join(controller).join("controller.json"))
}

#[test]
fn a_g1_on_its_own_sensors_stands_with_c1_where_c0_falls_on_both_plants() {
    let _one = serial();
    if installed("g1").is_none() {
        return;
    }
    let mut plants = vec!["upc"];
    if upc::sim::mujoco::AVAILABLE {
        plants.push("mujoco");
    } else {
        support::prereq::missing(
            upc::sim::mujoco::UNAVAILABLE,
            "scripts/setup.sh && cargo clean -p upc",
        );
    }
    let s = Scratch::new("g1_sensing");
    for plant in plants {
        let c1 = run(&s, plant, "c1");
        // The controller stood in for every force sensor, every tick, on the torque estimates
        // the plant published (not on its own commands), and estimated the base.
        let wo = &c1["wrench_observer"];
        let ticks = u(&c1, "ticks");
        for k in ["feet_ticks", "hand_ticks", "updates"] {
            assert!(u(wo, k) + 5 >= ticks, "{plant}: {k} {wo} of {ticks} ticks");
        }
        assert_eq!(u(wo, "commanded_torque_ticks"), 0, "{plant}: {wo}");
        assert!(u(&c1["estimator"], "ticks") + 5 >= ticks, "{plant}: {c1}");
        assert_eq!(u(&c1, "falls"), 0, "{plant}: C1 fell: {c1}");
        assert!(f(&c1, "com_height_drop") < 0.01, "{plant}: {c1}");
        let c0 = run(&s, plant, "c0");
        assert_eq!(u(&c0, "falls"), 1, "{plant}: C0 stood: {c0}");
    }
}
