//! `upc robot init`: a robot description drafted from a URDF alone (README, "Bring your
//! robot"). On the five robots upc has descriptions for, the draft finds what those name (feet,
//! sole frames, hand, the arm chain's root) and solves a standing posture; on
//! example-robot-data's iCub, which upc had no description for (COLLADA feet, seven point-mass
//! links, a root link facing backward) and its human model (y up, feet from visual meshes,
//! ball joints split through massless links), the command's draft runs as written: C0 falls on
//! `multiple_impacts`, C1 stands. Without the robot packages: a failure under CI, a visible skip
//! elsewhere (`support::prereq`).

mod support;

use std::path::Path;
use std::process::Command;

use support::procs::*;
use support::robots::installed;
use upc::robot::init;

/// The shipped description's robot, its package and URDF path.
const ROBOTS: [(&str, Option<&str>, &str); 5] = [
    ("icub_like", None, "assets/icub_like/icub_like.urdf"),
    (
        "g1",
        Some("example-robot-data"),
        "robots/g1_description/urdf/g1_29dof_rev_1_0.urdf",
    ),
    (
        "talos",
        Some("example-robot-data"),
        "robots/talos_data/robots/talos_reduced.urdf",
    ),
    (
        "icub",
        Some("icub-models"),
        "robots/iCubGazeboV2_5/model.urdf",
    ),
    (
        "romeo",
        Some("example-robot-data"),
        "robots/romeo_description/urdf/romeo.urdf",
    ),
];

/// The draft names the bodies a person named: each foot on the body of the shipped sole frame
/// (the same frame where the URDF has one), the same hand frame and arm chain root; solved, it
/// stands flat with the CoM over its support, which lies within 15 mm of the shipped one's on
/// every side (Romeo's listed contacts were measured by hand; its drafted ones come from the
/// COLLADA collision meshes).
#[test]
fn drafts_of_the_package_robots_find_what_their_descriptions_name() {
    for (name, package, path) in ROBOTS {
        let Some(shipped) = installed(name) else {
            continue;
        };
        let path = match package {
            Some(_) => Path::new(path).to_path_buf(),
            None => Path::new(env!("CARGO_MANIFEST_DIR")).join(path),
        };
        let mut draft = init::draft(package, &path, name).expect(name);
        let sd = &shipped.description;
        for (f, want) in draft.feet.iter().zip([&sd.feet.left, &sd.feet.right]) {
            let body = |frame: &str| {
                let m = &shipped.model;
                m.frames[m.frame_id(frame).expect(frame)].parent
            };
            assert_eq!(body(&f.link), body(&want.frame), "{name}: foot {}", f.link);
            if f.urdf_frame {
                assert_eq!(f.frame, want.frame, "{name}");
            }
        }
        assert_eq!(draft.hand, sd.hand.frame, "{name}: hand");
        assert_eq!(draft.chain_root, sd.hand.chain_root, "{name}: chain root");
        let (text, robot) = init::solve(&mut draft).expect(name);
        assert!(!text.contains("wider"), "{name}: {text}");
        assert!(
            text.contains("[stance]") && text.contains("[home]"),
            "{text}"
        );
        let d = &robot.derived;
        assert!(d.sole_tilt < 1e-4, "{name}: tilt {}", d.sole_tilt);
        assert!(
            d.com_offset[0].abs() < 1e-4 && d.com_offset[1].abs() < 1e-4,
            "{name}: CoM {:?} from the support's centre",
            d.com_offset
        );
        let s = shipped.derived.support;
        for a in 0..2 {
            for k in 0..2 {
                assert!(
                    (d.support[a][k] - s[a][k]).abs() < 0.015,
                    "{name}: support {:?} vs shipped {s:?}",
                    d.support
                );
            }
        }
    }
}

/// A robot upc had no description for, brought by the command alone: example-robot-data's
/// iCub (the UPMC model: COLLADA collision meshes, point-mass links, its root link facing −x).
/// `upc robot init` writes a description `upc run` accepts unedited; on `multiple_impacts`
/// (lockstep, upc's plant) C0 falls and C1 stands.
#[test]
fn a_robot_drafted_by_the_command_runs_c0_falls_and_c1_stands() {
    drafted_robot_runs(
        "icub_upmc",
        "robots/icub_description/robots/icub_reduced.urdf",
        "point masses",
        &[
            "inertia_floor = 1e-6",
            "frame = \"l_sole\"",
            "frame = \"r_hand\"",
        ],
    );
}

/// A second robot upc had no description for: example-robot-data's human model (75 kg, 1.7 m,
/// the ISB convention: y up, so the root link is turned upright by `[urdf] root_rpy`; feet from
/// visual meshes only; hips, shoulders and wrists as ball joints split through massless links,
/// given armature so that the mass matrix stays invertible when a falling body aligns their
/// axes: the falling C0's plant runs to the end).
#[test]
fn a_y_up_human_model_drafted_by_the_command_runs_c0_falls_and_c1_stands() {
    drafted_robot_runs(
        "human",
        "robots/human_description/robots/human.urdf",
        "z axis is not up",
        &[
            "root_rpy = [1.570796, 0, 0]",
            "\"right_hip_X\" = 0.01",
            "frame = \"right_hand\"",
            "contacts = [[",
        ],
    );
}

/// `upc robot init example-robot-data PATH --name NAME`: the draft is written (and never
/// overwritten unasked), its notes say `note`, its text has `parts`; `upc run` on it unedited:
/// C0 falls and C1 stands on `multiple_impacts` (lockstep, upc's plant), both runs exit 0.
fn drafted_robot_runs(name: &str, path: &str, note: &str, parts: &[&str]) {
    let _one = serial();
    // The G1's description reads example-robot-data: installed, or the test says so.
    if installed("g1").is_none() {
        return;
    }
    let s = Scratch::new("robot_init");
    let file = s.dir.join(format!("{name}.toml"));
    let init = |force: bool| {
        Command::new(env!("CARGO_BIN_EXE_upc"))
            .args(["robot", "init", "example-robot-data", path, "--name", name])
            .arg("--out")
            .arg(&file)
            .args(force.then_some("--force"))
            .env("RUST_LOG", "error")
            .output()
            .expect("upc robot init")
    };
    let out = init(false);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains(note), "{stdout}");
    // It never overwrites a description unasked.
    let again = init(false);
    assert!(!again.status.success());
    assert!(
        String::from_utf8_lossy(&again.stderr).contains("--force"),
        "{again:?}"
    );
    let text = std::fs::read_to_string(&file).expect("the description");
    for part in parts {
        assert!(text.contains(part), "{part}:\n{text}");
    }
    for (controller, stands) in [("c0", false), ("c1", true)] {
        upc_ok([
            "run".as_ref(),
            "--controller".as_ref(),
            controller.as_ref(),
            "--quiet".as_ref(),
            "--robot".as_ref(),
            file.as_os_str(),
            "--name".as_ref(),
            controller.as_ref(),
            "--out".as_ref(),
            s.dir.as_os_str(),
        ]);
        let c = json(
            &s.dir
                .join(controller)
                .join(controller)
                .join("controller.json"),
        );
        let fell = u(&c, "falls") > 0;
        assert_eq!(fell, !stands, "{name} {controller}: {c}");
        if stands {
            assert!(f(&c, "com_height_drop") < 5e-3, "{c}");
            assert_eq!(u(&c, "wbc_fallbacks"), 0, "{c}");
        }
    }
}
