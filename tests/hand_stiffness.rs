//! `hand.stiffness`: eq. (17)'s K_e = K_p M_e pushes the door's hinge along every axis M_e
//! couples to the push; "decoupled" pushes along the door's free direction only.
//! `hand.held_path`: the previewer that knows the hinge takes that push (HP-1) keeps the CoP off
//! the support's side edge.

mod support;

use serde_json::Value;
use support::procs::*;

/// The largest hand force along y and z (the directions the door's hinge holds) over C1's
/// `multiple_impacts` run on upc's plant with `setting`, the controller's summary and the run's
/// entry in `summary.json`.
fn held_direction_forces(s: &Scratch, name: &str, setting: &str) -> (f64, f64, Value, Value) {
    let out = s.dir.to_str().expect("utf-8");
    upc_ok([
        "run",
        "--controller",
        "c1",
        "--quiet",
        "--out",
        out,
        "--name",
        name,
        "--set",
        setting,
    ]);
    let dir = s.dir.join(name).join("c1");
    let text = std::fs::read_to_string(dir.join("sim.csv")).expect("sim.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |k: &str| header.iter().position(|h| *h == k).expect(k);
    let (fy, fz) = (col("hand_fy"), col("hand_fz"));
    let mut max = (0.0_f64, 0.0_f64);
    for l in lines {
        let v: Vec<f64> = l
            .split(',')
            .map(|x| x.parse().unwrap_or(f64::NAN))
            .collect();
        max = (max.0.max(v[fy].abs()), max.1.max(v[fz].abs()));
    }
    let run = json(&s.dir.join(name).join("summary.json"))["runs"][0].clone();
    (max.0, max.1, json(&dir.join("controller.json")), run)
}

/// The true CoP's smallest margin along y (m) of a run's `summary.json` entry.
fn side_margin(run: &Value) -> f64 {
    run["true_cop_margin"]["y"]
        .as_f64()
        .unwrap_or_else(|| panic!("no true CoP margin: {run}"))
}

#[test]
fn a_decoupled_stiffness_does_not_push_into_the_hinge() {
    let _one = serial();
    let s = Scratch::new("hand_stiffness");
    let (fy, fz, paper, paper_run) =
        held_direction_forces(&s, "paper", "hand.stiffness=\"operational_space\"");
    let (dy, dz, decoupled, _) =
        held_direction_forces(&s, "decoupled", "hand.stiffness=\"decoupled\"");
    let (py, _, path, path_run) = held_direction_forces(&s, "path", "hand.held_path=\"path\"");
    // Eq. (17): 34 N along y and 23 N along z at the 60 N push (M_e's off-diagonal terms);
    // decoupled: 8 and 2 N (the door's tangent is not exactly x).
    assert!(fy > 20.0 && fz > 15.0, "eq. (17): {fy:.1} / {fz:.1} N");
    assert!(
        dy < 0.5 * fy && dz < 0.25 * fz,
        "decoupled: {dy:.1} / {dz:.1} N"
    );
    for v in [&paper, &decoupled, &path] {
        assert_eq!(v["falls"].as_f64(), Some(0.0), "{v}");
        assert!(v["com_height_drop"].as_f64().expect("drop") < 0.005, "{v}");
    }
    // HP-1: the arm still pushes the hinge (the same eq. (17)), but C1 now expects it: the true
    // CoP's smallest distance to the side edges went from 20.7 to 52.5 mm.
    assert!(py > 20.0, "held path: {py:.1} N along y");
    let (free_y, path_y) = (side_margin(&paper_run), side_margin(&path_run));
    assert!(
        path_y > 1.8 * free_y && free_y > 0.0,
        "side margin: free {:.1} mm, held path {:.1} mm",
        free_y * 1e3,
        path_y * 1e3
    );
}
