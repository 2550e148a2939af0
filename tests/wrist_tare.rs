//! The wrist sensor's tare (`src/control/parts/wrist_tare.rs`, docs/sensing.md "The wrist's
//! offset"), through `upc run` as a user runs it: every sensor exact but the wrist, which
//! carries a constant 2 N offset per axis. Fed back to the QP untared, the offset is rendered
//! as a push: the hand walks the door away before any force comes (and, on
//! `multiple_impacts`, C2 then fell). Tared, the hand holds its place.

mod support;

use std::path::Path;

use serde_json::Value;
use support::upc_run::{exact_sensors_but, num as f, scratch, upc_run};

const BIAS: f64 = 2.0;

/// C1 until just before the first push (0.8 s), every sensor exact but the wrist's constant
/// offset; the controller's part of `summary.json`.
fn run(out: &Path, extra: &[&str]) -> Value {
    // Seed 2 draws the offset +2 N along the door's swing (x), which the door does not resist.
    let mut args = exact_sensors_but(&[&format!("wrist.bias={BIAS}"), "seed=2"]);
    args.extend(["--duration".to_string(), "0.8".to_string()]);
    args.extend(extra.iter().map(|a| a.to_string()));
    upc_run(out, "c1", &args)["controller_summary"].clone()
}

#[test]
fn a_tared_wrist_offset_is_not_rendered_as_a_push() {
    let out = scratch("wrist-tare", "tared");
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
    let out = scratch("wrist-tare", "untared");
    let untared = run(&out, &["--set", "controller.wrist_tare.duration=0"]);
    eprintln!("untared hand peak error {}", untared["hand_peak_error"]);
    assert!(f(&untared, "hand_peak_error") > 5e-3, "{untared:#}");
}

/// A tare refused (the quiet hand measures more than `max_offset`: a load, or an offset too
/// large to be one) leaves the offset in the measured force; the controller then does not feed
/// the force back, so the hand does not yield to it.
#[test]
fn after_a_refused_tare_the_hand_does_not_yield_to_the_offset() {
    let out = scratch("wrist-tare", "refused");
    let refused = run(&out, &["--set", "controller.wrist_tare.max_offset=1"]);
    eprintln!(
        "refused: offset {}, hand peak error {}",
        refused["wrist_tare_offset"], refused["hand_peak_error"]
    );
    assert_eq!(f(&refused, "wrist_tare_refusals"), 1.0, "{refused:#}");
    assert!(f(&refused, "hand_peak_error") < 1e-3, "{refused:#}");
}
