//! `upc model` end to end: the JSON dump agrees with the library, errors name the culprit.

use std::process::Command;

use nalgebra::DVector;
use upc::dynamics::*;

fn upc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_upc"))
}

fn list(v: &DVector<f64>) -> String {
    v.iter()
        .map(|x| format!("{x:e}"))
        .collect::<Vec<_>>()
        .join(",")
}

#[test]
fn json_dump_matches_the_library() {
    let model = icub_like::load().expect("humanoid");
    let mut q = upc::robot::Robot::embedded_default().expect("robot").home;
    q[model.joints[model.joint_id("r_elbow").expect("joint")].idx_q] = 1.1;
    let v = DVector::from_fn(model.nv, |k, _| 0.1 * (k as f64).sin());
    let urdf = icub_like::urdf_path();
    let out = upc()
        .args(["model", urdf.to_str().expect("utf-8 path"), "--json"])
        .args(["--q", &list(&q), "--v", &list(&v), "--frame", "r_hand"])
        .output()
        .expect("run upc");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let mut data = Data::new(&model);
    let m = crba(&model, &mut data, &q).expect("crba").clone();
    let h = nonlinear_effects(&model, &mut data, &q, &v)
        .expect("h")
        .clone();
    let f = model.frame_id("r_hand").expect("frame");
    let j = frame_jacobian(&model, &mut data, &q, f, ReferenceFrame::LocalWorldAligned)
        .expect("J")
        .clone();
    let com = center_of_mass(&model, &mut data, &q).expect("com");
    let num = |x: &serde_json::Value| x.as_f64().expect("number");
    assert_eq!(json["nv"], 38);
    for r in 0..model.nv {
        assert!((num(&json["h"][r]) - h[r]).abs() < 1e-9);
        for c in 0..model.nv {
            assert!((num(&json["M"][r][c]) - m[(r, c)]).abs() < 1e-9);
        }
    }
    for r in 0..6 {
        for c in 0..model.nv {
            let got = num(&json["frame"]["jacobian_local_world_aligned"][r][c]);
            assert!((got - j[(r, c)]).abs() < 1e-9);
        }
    }
    for k in 0..3 {
        assert!((num(&json["com"][k]) - com[k]).abs() < 1e-9);
    }
}

#[test]
fn table_input_file_and_errors() {
    let urdf = icub_like::door_urdf_path();
    let urdf = urdf.to_str().expect("utf-8 path");
    let out = upc().args(["model", urdf]).output().expect("run upc");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        text.contains("hinge") && text.contains("total mass: 12.2000 kg"),
        "{text}"
    );

    let dir = std::env::temp_dir().join(format!("upc-model-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let input = dir.join("in.json");
    std::fs::write(&input, r#"{"q": [0.5], "v": [2.0], "frame": "handle"}"#).expect("write");
    let out = upc()
        .args([
            "model",
            urdf,
            "--json",
            "--input",
            input.to_str().expect("utf-8"),
        ])
        .output()
        .expect("run upc");
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(json["q"][0], 0.5);
    assert_eq!(json["frame"]["name"], "handle");

    let out = upc()
        .args(["model", urdf, "--json", "--frame", "knob"])
        .output()
        .expect("run upc");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("'knob'"));

    let out = upc()
        .args(["model", urdf, "--json", "--q", "0.1,0.2"])
        .output()
        .expect("run upc");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("q has length 2"));
    let _ = std::fs::remove_dir_all(&dir);
}
