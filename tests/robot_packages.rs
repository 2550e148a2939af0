//! The URDFs real robots ship, from the PyPI packages `example-robot-data` and `icub-models`
//! (installed with Pinocchio by `scripts/setup.sh` in `~/.cache/upc/robot-venv`, or
//! `UPC_ROBOT_VENV`): upc loads every one Pinocchio loads but one whose inertia is not physical,
//! and its M(q), h(q, v), CoM and frame Jacobians agree with Pinocchio's (`scripts/pin_check.py`).
//! Without the packages the tests fail under CI and skip visibly elsewhere (`support::prereq`).

mod support;

use std::path::PathBuf;
use std::process::Command;

use upc::dynamics::{BaseJoint, DynamicsError, Model};

/// URDFs upc refuses on purpose: the file name and what the error must say.
const REFUSED: [(&str, &str); 2] = [
    // A body whose principal moments are 0.099, −0.021, 0.052 kg·m²: no body has these.
    (
        "romeo_laas_small.urdf",
        "link 'body' has an invalid inertia",
    ),
    // No <link> at all (Pinocchio refuses it too).
    ("ur3.urdf", "no links"),
];

fn python() -> Option<PathBuf> {
    let Some(venv) = upc::robot::packages::robot_venv() else {
        support::prereq::missing(
            "no robot environment: neither UPC_ROBOT_VENV nor HOME is set",
            support::prereq::SETUP,
        );
        return None;
    };
    let py = venv.join("bin/python");
    let ok = Command::new(&py)
        .args(["-c", "import pinocchio, icub_models"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        support::prereq::missing(
            &format!("no Pinocchio and robot packages in {}", venv.display()),
            support::prereq::SETUP,
        );
    }
    ok.then_some(py)
}

fn script() -> String {
    format!("{}/scripts/pin_check.py", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn every_urdf_of_the_robot_packages_loads_but_the_unphysical_one() {
    let Some(py) = python() else { return };
    let out = Command::new(&py)
        .args([&script(), "--packages", "--list"])
        .output()
        .expect("pin_check.py --list");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let paths: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(str::to_owned)
        .collect();
    let (mut loaded, mut repaired) = (0, 0);
    for p in &paths {
        let file = p.rsplit('/').next().unwrap_or(p);
        match (
            Model::from_urdf_file(p, BaseJoint::Auto),
            REFUSED.iter().find(|(f, _)| *f == file),
        ) {
            (Ok(m), None) => {
                loaded += 1;
                repaired += usize::from(m.load_warnings.iter().any(|w| w.contains("repaired")));
            }
            (Err(e), Some((_, why))) => {
                let text = e.to_string();
                assert!(text.contains(why), "{p}: {text}");
                assert!(
                    matches!(
                        e,
                        DynamicsError::InvalidInertia { .. } | DynamicsError::Empty
                    ),
                    "{p}: {e:?}"
                );
            }
            (Ok(_), Some(_)) => panic!("{p} was expected to be refused"),
            (Err(e), None) => panic!("{p}: {e}"),
        }
    }
    eprintln!(
        "{loaded} of {} URDFs loaded, {repaired} with a repaired inertia",
        paths.len()
    );
    assert!(loaded >= 80, "only {loaded} URDFs");
    assert!(
        repaired >= 5,
        "the packages have rounding-level inertias: {repaired} repaired"
    );
}

#[test]
fn dynamics_agree_with_pinocchio_on_every_robot() {
    let Some(py) = python() else { return };
    let mut cmd = Command::new(&py);
    cmd.args([&script(), "--packages", "--configs", "2", "--upc"])
        .arg(env!("CARGO_BIN_EXE_upc"));
    for (file, _) in REFUSED {
        cmd.args(["--known-refusal", file]);
    }
    let out = cmd.output().expect("pin_check.py");
    let text = String::from_utf8_lossy(&out.stdout);
    let summary: Vec<&str> = text.lines().rev().take(6).collect();
    eprintln!(
        "{}",
        summary.into_iter().rev().collect::<Vec<_>>().join("\n")
    );
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("loaded and compared"), "{text}");
}
