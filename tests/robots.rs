//! Robot descriptions: what upc computes from a description (mass, CoM height, support, M_e,
//! hand set-point) against independent computations, the contact points derived from collision
//! geometry, the config layer, the force scaling, and the three robots of the registry packages
//! (without them: a failure under CI, a visible skip elsewhere; `support::prereq`).

mod support;

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use support::robots::installed;
use upc::config::Config;
use upc::dynamics::{
    BaseJoint, Data, Model, OpSpaceWorkspace, center_of_mass, forward_kinematics,
    update_frame_placements,
};
use upc::robot::description::{ContactSpec, FootSpec};
use upc::robot::{Robot, RobotError, feet};
use upc::scenario::Scenario;

#[test]
fn the_default_robot_computes_what_was_typed_before() {
    let r = Robot::embedded_default().expect("default robot");
    let d = &r.derived;
    // Mass: the sum of the URDF's link masses (assets/README.md: 29.8 kg).
    assert!((d.mass - 29.8).abs() < 1e-9, "mass {}", d.mass);
    // Soles 0.14 × 0.065 m, 0.14 m apart (iCub facts the URDF was drawn from:
    // docs/reduced_models.md).
    assert!((d.support[0][0] + 0.07).abs() < 1e-12 && (d.support[0][1] - 0.07).abs() < 1e-12);
    assert!((d.support[1][1] - 0.1025).abs() < 1e-12, "{:?}", d.support);
    assert!((d.feet_distance - 0.14).abs() < 1e-12);
    assert!(d.sole_tilt < 1e-6, "{}", d.sole_tilt);
    // CoM height with knees slightly bent: 0.50–0.54 m (docs/reduced_models.md).
    assert!((0.50..0.54).contains(&d.com_height), "{}", d.com_height);
    // Independent: the CoM of the home configuration, and M_e of the chest → hand chain there.
    let model = upc::dynamics::icub_like::load().expect("model");
    let mut data = Data::new(&model);
    let com = center_of_mass(&model, &mut data, &r.home).expect("com");
    assert!((com.z - d.com_height).abs() < 1e-12);
    let mut op = OpSpaceWorkspace::new(&model, "chest", "r_hand").expect("chain");
    let m_e = *op.compute(&model, &mut data, &r.home).expect("M_e");
    assert!((m_e - d.effective_mass).norm() < 1e-12);
    // The contacts lie on z = 0 around the origin.
    forward_kinematics(&model, &mut data, &r.home).expect("fk");
    let mut c = Vector3::zeros();
    for n in &r.contacts {
        let p = data.o_m_f[model.frame_id(n).expect("frame")].trans;
        assert!(p.z.abs() < 1e-12, "{n} at {p:?}");
        c += p / 8.0;
    }
    assert!(c.norm() < 1e-12);
}

/// What follows from the robot is a value computed from its model, never a config layer: the
/// reduced models and the frames come from the robot, its config layers are its description's
/// `[config]` only, and no config key can set a robot fact apart.
#[test]
fn robot_facts_are_values_not_config_layers() {
    let r = Robot::embedded_default().expect("robot");
    let m = r.reduced();
    assert_eq!(m.mass, r.model.total_mass());
    assert_eq!(m.com_height, r.derived.com_height);
    assert_eq!(m.support, r.derived.support);
    assert_eq!(m.effective_mass, r.derived.effective_mass);
    assert_eq!(m.hand_position, r.derived.hand_position);
    let f = r.frames();
    assert_eq!(f.feet, ["l_sole".to_string(), "r_sole".to_string()]);
    assert_eq!(
        (f.hand.as_str(), f.hand_chain_root.as_str()),
        ("r_hand", "chest")
    );
    assert!(r.config_layers().is_empty(), "{:?}", r.config_layers());
    let tuned = Robot::parse(
        "extends = \"icub_like\"\nname = \"tuned\"\n[config]\npreview.horizon = 400\n",
        "tuned.toml",
        None,
    )
    .expect("a description with a [config] table");
    let layers = tuned.config_layers();
    assert_eq!(layers.len(), 1);
    assert_eq!(layers[0].1.keys().collect::<Vec<_>>(), ["preview"]);
    for key in [
        "robot.mass=31",
        "robot.com_height=0.5",
        "support.x=[-0.1, 0.1]",
    ] {
        let mut l = Config::layers_for(&r).expect("layers");
        l.push_override(key).expect("parses");
        assert!(l.build().is_err(), "{key} is no setting");
    }
}

#[test]
fn forces_scale_with_the_robot_mass() {
    let r = Robot::embedded_default().expect("robot");
    assert_eq!(r.force_scale().expect("scale"), 1.0);
    // Another posture under the default's name is another arm: its own scale (a description
    // drafted from the default's URDF is named so).
    let bent = Robot::parse(
        "extends = \"icub_like\"\nname = \"icub_like\"\n[home]\nr_elbow = 0.3\n",
        "<test>",
        None,
    )
    .expect("a variant");
    let (mass, capacity) = upc::robot::reference().expect("reference");
    let want = (bent.derived.mass / mass).min(bent.derived.hand_force_capacity / capacity);
    assert!(
        (want - 1.0).abs() > 0.01,
        "the variant's arm holds as much: {want}"
    );
    assert_eq!(bent.force_scale().expect("scale"), want);
    // The scenario as the variant is pushed: every plant and process takes it so.
    let pushed = bent.scenario("multiple_impacts").expect("scenario");
    assert_eq!(pushed.force_scale, want);
    let s = Scenario::load("multiple_impacts").expect("scenario");
    assert_eq!(
        pushed.content_hash(),
        s.clone().with_force_scale(want).content_hash()
    );
    let same = s.clone().with_force_scale(1.0);
    assert_eq!(same.content_hash(), s.content_hash());
    let double = s.clone().with_force_scale(2.0);
    assert_eq!(double.force_scale, 2.0);
    assert_ne!(double.content_hash(), s.content_hash());
    for k in 0..700 {
        let t = k as f64 * 0.01;
        let (a, b) = (s.force.at(t), double.force.at(t));
        for i in 0..3 {
            assert!((b[i] - 2.0 * a[i]).abs() <= 1e-12 * (1.0 + a[i].abs()));
        }
    }
}

/// A foot on a floating base, with the given collision elements on its link.
fn foot_urdf(collision: &str) -> String {
    format!(
        r#"<robot name="foot">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="ankle" type="revolute">
    <parent link="base"/><child link="foot"/><origin xyz="0 0 -0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/>
  </joint>
  <link name="foot"><inertial><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    {collision}
  </link>
</robot>"#
    )
}

fn contact_points(urdf: &str, spec: &FootSpec) -> Result<Vec<Vector3<f64>>, RobotError> {
    contact_points_in(urdf, None, spec)
}

/// [`contact_points`] with the URDF in `dir` (a collision mesh's relative path starts there).
fn contact_points_in(
    urdf: &str,
    dir: Option<&std::path::Path>,
    spec: &FootSpec,
) -> Result<Vec<Vector3<f64>>, RobotError> {
    let mut model = Model::from_urdf_str(urdf, BaseJoint::Floating).expect("model");
    let parsed = upc::dynamics::parse_urdf(urdf).expect("parse");
    let names = feet::attach(&mut model, &parsed, dir, spec)?;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &model.neutral()).expect("fk");
    Ok(names
        .iter()
        .map(|n| data.o_m_f[model.frame_id(n).expect("contact frame")].trans)
        .collect())
}

#[test]
fn contact_points_come_from_a_box_or_spheres_and_a_missing_mesh_is_refused() {
    let spec = |contacts: ContactSpec| FootSpec {
        frame: "sole".into(),
        link: Some("foot".into()),
        origin: None,
        contacts,
    };
    // A 0.2 × 0.1 × 0.02 box 3 cm below the ankle, shifted 2 cm forward: its bottom corners,
    // front-left first, at z = −0.5 − 0.03 − 0.01.
    let boxed = foot_urdf(
        r#"<collision><origin xyz="0.02 0 -0.03" rpy="0 0 0"/><geometry><box size="0.2 0.1 0.02"/></geometry></collision>"#,
    );
    let p = contact_points(&boxed, &spec(ContactSpec::Keyword("collision".into()))).expect("box");
    let want = [[0.12, 0.05], [0.12, -0.05], [-0.08, 0.05], [-0.08, -0.05]];
    for (q, w) in p.iter().zip(want) {
        assert!(
            (q - Vector3::new(w[0], w[1], -0.54)).norm() < 1e-12,
            "{q:?} vs {w:?}"
        );
    }
    // The same, the made sole frame turned by `origin` (yaw 90°: its x along the link's y):
    // the same four points on the ground, the sole's axes the turned ones.
    let turned = FootSpec {
        origin: Some(upc::robot::description::SoleOrigin {
            xyz: [0.0; 3],
            rpy: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
        }),
        ..spec(ContactSpec::Keyword("collision".into()))
    };
    let q = contact_points(&boxed, &turned).expect("turned box");
    for w in want {
        let w = Vector3::new(w[0], w[1], -0.54);
        assert!(
            q.iter().any(|q| (q - w).norm() < 1e-12),
            "{w:?} not in {q:?}"
        );
    }
    // Front-left first in the turned frame: the corner furthest along the link's +y, then +x.
    assert!(
        (q[0] - Vector3::new(-0.08, 0.05, -0.54)).norm() < 1e-12,
        "{q:?}"
    );
    // Four spheres of radius 1 cm: their lowest points.
    let spheres: String = [[-0.05, 0.025], [-0.05, -0.025], [0.12, 0.03], [0.12, -0.03]]
        .iter()
        .map(|[x, y]| {
            format!(r#"<collision><origin xyz="{x} {y} -0.03" rpy="0 0 0"/><geometry><sphere radius="0.01"/></geometry></collision>"#)
        })
        .collect();
    let p = contact_points(
        &foot_urdf(&spheres),
        &spec(ContactSpec::Keyword("collision".into())),
    )
    .expect("spheres");
    assert!(
        (p[0] - Vector3::new(0.12, 0.03, -0.54)).norm() < 1e-12,
        "{p:?}"
    );
    assert!(
        (p[3] - Vector3::new(-0.05, -0.025, -0.54)).norm() < 1e-12,
        "{p:?}"
    );
    // Points given in the sole frame (made at the link's origin), in any order.
    let given = ContactSpec::Points(vec![
        [-0.1, -0.04, 0.0],
        [0.1, 0.04, 0.0],
        [0.1, -0.04, 0.0],
        [-0.1, 0.04, 0.0],
    ]);
    let p = contact_points(&boxed, &spec(given)).expect("points");
    assert!(
        (p[0] - Vector3::new(0.1, 0.04, -0.5)).norm() < 1e-12,
        "{p:?}"
    );
    assert!(
        (p[3] - Vector3::new(-0.1, -0.04, -0.5)).norm() < 1e-12,
        "{p:?}"
    );
    // A mesh that is not there: the error says where upc looked and what else to do.
    let mesh = foot_urdf(
        r#"<collision><geometry><mesh filename="package://x/foot.stl"/></geometry></collision>"#,
    );
    let e = contact_points(&mesh, &spec(ContactSpec::Keyword("collision".into())))
        .expect_err("mesh")
        .to_string();
    assert!(
        e.contains("package://x/foot.stl") && e.contains("looked") && e.contains("contacts = [["),
        "{e}"
    );
    // Three points are not a sole.
    let e = contact_points(&boxed, &spec(ContactSpec::Points(vec![[0.0; 3]; 3])))
        .expect_err("three")
        .to_string();
    assert!(e.contains("four"), "{e}");
}

#[test]
fn a_description_that_does_not_stand_is_refused_with_its_figures() {
    let text = upc::robot::EMBEDDED[0]
        .1
        .replace("l_ankle_pitch = 0.25", "l_ankle_pitch = -0.25");
    let e = Robot::parse(&text, "bent.toml", None)
        .expect_err("tilted sole")
        .to_string();
    assert!(e.contains("not flat") && e.contains("28.6°"), "{e}");
    let e = Robot::load("no_such_robot")
        .expect_err("unknown")
        .to_string();
    assert!(e.contains("icub_like, icub, talos, g1"), "{e}");
}

#[test]
fn the_package_robots_stand_flat_facing_x_with_their_published_mass() {
    // (name, dof, mass range kg: iCub 2.5 ≈ 33 kg, TALOS ≈ 90–100 kg, G1 ≈ 33–35 kg)
    for (name, nv, mass) in [
        ("icub", 38, 30.0..36.0),
        ("talos", 38, 85.0..100.0),
        ("g1", 35, 30.0..37.0),
        // Romeo ≈ 37–41 kg; with its fingers (massless links) and with them locked.
        ("romeo", 61, 37.0..42.0),
        ("romeo_locked", 37, 37.0..42.0),
    ] {
        let Some(r) = installed(name) else {
            continue;
        };
        let d = &r.derived;
        assert_eq!(r.model.nv, nv, "{name}");
        assert!(mass.contains(&d.mass), "{name}: {} kg", d.mass);
        assert!(
            d.sole_tilt < 0.5f64.to_radians(),
            "{name}: tilt {}",
            d.sole_tilt
        );
        // Toes along +x: every left contact is left of every right one, fronts ahead of rears.
        let mut data = Data::new(&r.model);
        forward_kinematics(&r.model, &mut data, &r.home).expect("fk");
        let at = |k: usize| data.o_m_f[r.model.frame_id(&r.contacts[k]).expect("c")].trans;
        for k in 0..4 {
            assert!(at(k).y > at(4 + k).y, "{name}: left/right");
        }
        for foot in [0, 4] {
            assert!(
                at(foot).x > at(foot + 2).x && at(foot + 1).x > at(foot + 3).x,
                "{name}"
            );
            assert!(at(foot).y > at(foot + 1).y, "{name}: fl left of fr");
        }
        // The hand in front of the body, the CoM over the support.
        assert!(
            d.hand_position.x > 0.1,
            "{name}: hand {:?}",
            d.hand_position
        );
        assert!(
            d.com_offset[0].abs() < 0.05 && d.com_offset[1].abs() < 0.03,
            "{name}"
        );
        Config::for_robot(&r).expect("config");
        assert_eq!(r.reduced().mass, d.mass);
        // Pushed by its mass, capped by what its arm holds, relative to the default robot.
        let (m0, c0) = upc::robot::reference().expect("reference");
        let scale = r.force_scale().expect("scale");
        assert_eq!(
            scale,
            (d.mass / m0).min(d.hand_force_capacity / c0),
            "{name}"
        );
        assert!(d.mass > m0, "{name} is heavier than the default");
    }
}

#[test]
fn mesh_files_resolve_in_the_packages_and_next_to_the_urdf() {
    use upc::robot::packages::resolve_mesh;
    let dir = std::env::temp_dir().join(format!("upc-mesh-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).expect("dir");
    std::fs::write(dir.join("meshes/foot.stl"), b"solid foot\nendsolid foot\n").expect("mesh");
    assert_eq!(
        resolve_mesh("meshes/foot.stl", Some(&dir)),
        Some(dir.join("meshes/foot.stl"))
    );
    assert_eq!(resolve_mesh("meshes/hand.stl", Some(&dir)), None);
    assert_eq!(resolve_mesh("package://no-such-package/a.stl", None), None);
    let _ = std::fs::remove_dir_all(&dir);
    // Every visual mesh of the package robots is found (the recorder draws them).
    for name in ["icub", "talos", "g1"] {
        let Some(r) = installed(name) else { continue };
        let urdf = upc::dynamics::parse_urdf(&r.urdf).expect("parse");
        let dir = r.urdf_path.as_deref().and_then(std::path::Path::parent);
        let meshes: Vec<&str> = urdf
            .links
            .iter()
            .flat_map(|l| &l.visual)
            .filter_map(|v| match &v.geometry {
                urdf_rs::Geometry::Mesh { filename, .. } => Some(filename.as_str()),
                _ => None,
            })
            .collect();
        assert!(meshes.len() > 20, "{name}: {} meshes", meshes.len());
        for m in meshes {
            assert!(resolve_mesh(m, dir).is_some(), "{name}: {m} not found");
        }
    }
}

/// `extends` layers a variant over a description; `[locked]` fixes joints at their home value
/// (names or patterns, each matching some joint); `[armature]` sets rotor inertias.
#[test]
fn a_variant_locks_joints_by_pattern_and_sets_armatures() {
    let base = Robot::embedded_default().expect("default");
    let variant = "extends = \"icub_like\"\nname = \"icub_like_still_head\"\n\
                   [home]\nneck_pitch = 0.2\n\
                   [locked]\njoints = [\"neck_*\", \"l_wrist_yaw\"]\n\
                   [armature]\n\"r_*\" = 0.01\n";
    let r = Robot::parse(variant, "variant.toml", None).expect("variant");
    assert_eq!(r.name(), "icub_like_still_head");
    assert_eq!(r.model.nq, base.model.nq - 4);
    assert_eq!(r.locked.len(), 4);
    assert_eq!(r.locked["neck_pitch"], 0.2, "locked at its home value");
    assert_eq!(r.locked["neck_yaw"], 0.0);
    assert_ne!(r.hash, base.hash);
    // The base's feet, hand and posture carry over: the robot stands as the base does.
    assert!((r.derived.mass - base.derived.mass).abs() < 1e-12);
    assert!((r.derived.com_height - base.derived.com_height).abs() < 1e-3);
    let armed: Vec<&str> = r
        .model
        .joints
        .iter()
        .filter(|j| j.armature > 0.0)
        .map(|j| j.name.as_str())
        .collect();
    assert!(
        !armed.is_empty() && armed.iter().all(|n| n.starts_with("r_")),
        "{armed:?}"
    );
    for (bad, what) in [
        ("[locked]\njoints = [\"nose_*\"]\n", "`nose_*` matches no"),
        ("[armature]\n\"nose\" = 0.1\n", "`nose` matches no"),
        ("[armature]\n\"r_knee\" = -1.0\n", "armature -1"),
    ] {
        let text = format!("extends = \"icub_like\"\n{bad}");
        let e = Robot::parse(&text, "bad.toml", None)
            .expect_err(what)
            .to_string();
        assert!(e.contains(what), "{e}");
    }
}

/// Romeo written from the README without `[armature]`: its fingers move only massless links.
/// Loading names them and both fixes (before, the plant stopped at start-up on "M(q_ref) is
/// singular or not positive definite").
#[test]
fn a_description_whose_joints_move_no_mass_names_them_and_both_fixes() {
    let Some(_) = installed("romeo") else { return };
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/robots");
    let text = std::fs::read_to_string(dir.join("romeo.toml")).expect("romeo.toml");
    let (a, b) = (
        text.find("[armature]").expect("[armature]"),
        text.find("[home]").expect("[home]"),
    );
    let stripped = format!("{}{}", &text[..a], &text[b..]);
    let err = match Robot::parse(&stripped, "romeo without [armature]", Some(&dir)) {
        Err(e @ RobotError::InertJoints { .. }) => e.to_string(),
        Err(e) => panic!("another error: {e}"),
        Ok(_) => panic!("Romeo's massless fingers were accepted"),
    };
    for part in [
        "move no mass",
        "[armature]",
        "[locked]",
        "Finger",
        "singular",
    ] {
        assert!(err.contains(part), "{part}: {err}");
    }
    // The description as shipped (with its rotor inertias) loads.
    Robot::parse(&text, "romeo", Some(&dir)).expect("romeo with [armature]");
}

/// The embedded iCub-like with its root link's `<inertia>` replaced by `inertia`: a URDF and
/// a description named `name` in `dir` (the description's path and text).
fn with_root_inertia(dir: &Path, inertia: &str, name: &str) -> (PathBuf, String) {
    std::fs::create_dir_all(dir).expect("dir");
    let urdf = upc::dynamics::icub_like::URDF;
    let good =
        r#"<inertia ixx="0.0145833" ixy="0" ixz="0" iyy="0.00478333" iyz="0" izz="0.0135333"/>"#;
    assert_eq!(urdf.matches(good).count(), 1, "the root link's inertia");
    std::fs::write(
        dir.join(format!("{name}.urdf")),
        urdf.replace(good, inertia),
    )
    .expect("urdf");
    let text =
        format!("extends = \"icub_like\"\nname = \"{name}\"\n\n[urdf]\npath = \"{name}.urdf\"\n");
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, &text).expect("description");
    (path, text)
}

/// `upc sim` on `plant` with the robot `description` and `args`, to its end.
fn sim(plant: &str, description: &Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["sim", "--plant", plant, "--robot"])
        .arg(description)
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("upc sim")
}

/// The plants to run: upc's, and MuJoCo's when it is built in (a visible skip otherwise).
fn plants() -> Vec<&'static str> {
    let mut plants = vec!["upc"];
    if upc::sim::mujoco::AVAILABLE {
        plants.push("mujoco");
    } else {
        support::prereq::missing(upc::sim::mujoco::UNAVAILABLE, support::prereq::SETUP);
    }
    plants
}

/// A body whose principal moments break the triangle inequality (a URDF's inertia typed by
/// hand) is refused at load, naming the link, on both plants with the same message: before,
/// upc's plant ran it and MuJoCo refused it from the depth of its log.
#[test]
fn a_non_physical_inertia_is_refused_with_the_same_message_on_both_plants() {
    let dir = std::env::temp_dir().join(format!("upc-bad-inertia-{}", std::process::id()));
    // 0.001 + 0.002 < 0.0135: no body has these moments.
    let bad = r#"<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.0135333"/>"#;
    let (description, _) = with_root_inertia(&dir, bad, "bad_inertia");
    let err = match Robot::load(description.to_str().expect("utf-8")) {
        Err(e @ RobotError::Inertia { .. }) => e.to_string(),
        Err(e) => panic!("another error: {e}"),
        Ok(_) => panic!("a non-physical inertia was accepted"),
    };
    for part in ["link 'root_link'", "A + B ≥ C", "1.000e-3, 2.000e-3"] {
        assert!(err.contains(part), "{part}: {err}");
    }
    for plant in plants() {
        let out = sim(
            plant,
            &description,
            &["--mode", "lockstep", "--duration", "0.01"],
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{plant}: {stderr}");
        assert!(stderr.contains(&err), "{plant}: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A link with mass and no rotational inertia (a point mass, as example-robot-data's iCub has
/// seven) is refused by both plants with the same message, which names `inertia_floor`; with it,
/// both plants run the robot and the bodies that had inertia keep theirs.
#[test]
fn a_point_mass_is_refused_on_both_plants_and_runs_with_an_inertia_floor() {
    let dir = std::env::temp_dir().join(format!("upc-point-mass-{}", std::process::id()));
    let point = r#"<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>"#;
    let (refused, text) = with_root_inertia(&dir, point, "point_mass");
    let err = match Robot::load(refused.to_str().expect("utf-8")) {
        Err(e @ RobotError::PointMass { .. }) => e.to_string(),
        Err(e) => panic!("another error: {e}"),
        Ok(_) => panic!("a point mass was accepted"),
    };
    for part in ["link 'root_link'", "point mass", "inertia_floor = 1e-6"] {
        assert!(err.contains(part), "{part}: {err}");
    }
    let floored = dir.join("floored.toml");
    std::fs::write(
        &floored,
        text.replace("name = ", "inertia_floor = 1e-6\nname = "),
    )
    .expect("toml");
    let r = Robot::load(floored.to_str().expect("utf-8")).expect("floored");
    let reference = Robot::load("icub_like").expect("icub_like");
    for (a, b) in r.model.joints.iter().zip(&reference.model.joints) {
        let (ia, ib) = (a.inertia.inertia_com(), b.inertia.inertia_com());
        if a.body == "root_link" {
            let m = nalgebra::SymmetricEigen::new(ia).eigenvalues;
            assert!(m.iter().all(|x| (x - 1e-6).abs() < 1e-12), "{m:?}");
        } else {
            assert!((ia - ib).norm() < 1e-15, "{}: {ia} vs {ib}", a.body);
        }
    }
    for plant in plants() {
        for (description, runs) in [(&refused, false), (&floored, true)] {
            // Real time for 50 steps: without a controller the plant holds the robot, and
            // has built and stepped the model.
            let prefix = format!("pointmass{}", std::process::id());
            let out = sim(
                plant,
                description,
                &[
                    "--mode",
                    "realtime",
                    "--duration",
                    "0.05",
                    "--prefix",
                    &prefix,
                ],
            );
            let stderr = String::from_utf8_lossy(&out.stderr);
            if runs {
                assert!(out.status.success(), "{plant}: {stderr}");
                let stdout = String::from_utf8_lossy(&out.stdout);
                assert!(
                    stdout.contains("sim: 50 steps"),
                    "{plant}: {stdout}{stderr}"
                );
            } else {
                assert!(!out.status.success(), "{plant}: {stderr}");
                assert!(stderr.contains(&err), "{plant}: {stderr}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every robot upc ships passes the physical checks (the five run on both plants).
#[test]
fn the_shipped_robots_have_physical_inertias() {
    Robot::embedded_default().expect("icub_like");
    for name in ["icub", "talos", "g1", "romeo", "romeo_locked"] {
        if let Some(r) = installed(name) {
            upc::robot::physical::check_inertias(&r.model, name).expect(name);
        }
    }
}

/// `package://` resolves in ROS 1 package paths, ROS 2 prefixes (their `share/`) and the robot
/// environment, in that order, each variable a list of directories.
#[test]
fn package_urls_resolve_in_ros_paths_ament_prefixes_and_the_robot_environment() {
    use upc::robot::packages::{resolve_mesh_in, search_dirs};
    let root = std::env::temp_dir().join(format!("upc-pkgs-{}", std::process::id()));
    let file = |rel: &str| {
        let p = root.join(rel);
        std::fs::create_dir_all(p.parent().expect("parent")).expect("dir");
        std::fs::write(&p, b"solid m\nendsolid m\n").expect("mesh");
        p
    };
    let ros = file("ros/ws/arm/meshes/a.stl");
    let both_ros = file("ros/ws/both/m.stl");
    let ament = file("ament/install/share/hand/b.stl");
    file("ament/install/share/both/m.stl");
    let joined =
        |a: &std::path::Path, b: &std::path::Path| std::env::join_paths([a, b]).expect("join");
    let dirs = search_dirs(
        Some(&joined(&root.join("ros/none"), &root.join("ros/ws"))),
        Some(&joined(
            &root.join("ament/nothing"),
            &root.join("ament/install"),
        )),
        None,
    );
    let find = |url: &str| resolve_mesh_in(url, None, &dirs);
    assert_eq!(find("package://arm/meshes/a.stl"), Some(ros));
    assert_eq!(find("package://hand/b.stl"), Some(ament));
    assert_eq!(
        find("package://both/m.stl"),
        Some(both_ros),
        "ROS paths first"
    );
    assert_eq!(find("package://arm/meshes/missing.stl"), None);
    assert_eq!(find("package://nowhere/a.stl"), None);
    let _ = std::fs::remove_dir_all(&root);
}

/// Placeholders a description may carry are flagged: the same effort limit on every joint (the
/// arm then "holds" whatever it says), an effort limit no motor of the robot's size gives, a
/// link of 1 kg·m² about each axis. The iCub-like has none.
#[test]
fn placeholder_limits_and_inertias_are_flagged() {
    use upc::robot::physical::placeholder_warnings;
    let joint = |n: usize, parent: &str| {
        format!(
            r#"<joint name="j{n}" type="revolute"><parent link="{parent}"/><child link="l{n}"/>
  <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="240" velocity="1"/></joint>"#
        )
    };
    let link = |name: &str, i: f64| {
        format!(
            r#"<link name="{name}"><inertial><mass value="1"/>
  <inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial></link>"#
        )
    };
    let urdf = format!(
        "<robot name=\"p\">{}{}{}{}{}{}{}</robot>",
        link("base", 0.01),
        link("l1", 1.0),
        link("l2", 0.01),
        link("l3", 0.01),
        joint(1, "base"),
        joint(2, "l1"),
        joint(3, "l2")
    );
    let model = Model::from_urdf_str(&urdf, BaseJoint::Floating).expect("model");
    let w = placeholder_warnings(&model);
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w[0].contains("effort limit 240"), "{w:?}");
    assert!(w[1].contains("link 'l1' has a unit inertia"), "{w:?}");
    let r = Robot::embedded_default().expect("icub_like");
    assert!(placeholder_warnings(&r.model).is_empty());
    // One joint's effort far beyond any motor of a 4 kg robot (icub-models has 50000 N·m on
    // twenty joints of a 33 kg one): flagged by name, the others not.
    let huge = urdf.replacen(
        "<limit lower=\"-1\" upper=\"1\" effort=\"240\"",
        "<limit lower=\"-1\" upper=\"1\" effort=\"50000\"",
        1,
    );
    let model = Model::from_urdf_str(&huge, BaseJoint::Floating).expect("model");
    let w = placeholder_warnings(&model);
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].contains("weight at a metre") && w[0].contains("j1 (50000)"),
        "{w:?}"
    );
}

/// A sole made on a link whose z axis points forward (as some ankle links' do): the error
/// names the rotation that brings the frame's z up, and with it as the sole's `origin` the
/// robot is the iCub-like again (the same mass, support, CoM height and hand).
#[test]
fn a_made_sole_frame_on_a_tilted_link_is_turned_by_its_origin() {
    let dir = std::env::temp_dir().join(format!("upc-tilted-sole-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let urdf = upc::dynamics::icub_like::URDF;
    // A link on the left foot whose z axis points forward and x down (pitch +90°).
    let tilted = r#"  <joint name="l_foot_z_forward_fixed" type="fixed">
    <origin xyz="0 0 0" rpy="0 1.5707963267948966 0"/>
    <parent link="l_foot"/>
    <child link="l_foot_z_forward"/>
  </joint>
  <link name="l_foot_z_forward"/>
</robot>"#;
    let urdf = urdf.replacen("</robot>", tilted, 1);
    std::fs::write(dir.join("tilted.urdf"), urdf).expect("urdf");
    // The made sole in the tilted link's frame: at l_sole's place, (0.02, 0, −0.06) in
    // l_foot's frame, i.e. (0.06, 0, 0.02) in the tilted one; the corners as l_sole's.
    let write = |origin: &str| {
        let path = dir.join("tilted.toml");
        std::fs::write(
            &path,
            format!(
                "extends = \"icub_like\"\nname = \"tilted\"\n\n[urdf]\npath = \"tilted.urdf\"\n\n\
                 [feet.left]\nframe = \"l_made_sole\"\nlink = \"l_foot_z_forward\"\n{origin}\
                 contacts = [[0.07, 0.0325, 0.0], [0.07, -0.0325, 0.0], [-0.07, 0.0325, 0.0], \
                 [-0.07, -0.0325, 0.0]]\n"
            ),
        )
        .expect("description");
        Robot::load(path.to_str().expect("utf-8"))
    };
    let err = match write("origin = { xyz = [0.06, 0.0, 0.02] }\n") {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a sole frame with z forward was accepted"),
    };
    eprintln!("{err}");
    for part in [
        "l_made_sole",
        "90.0°",
        "[feet.left] origin = { rpy = [",
        "-1.5708",
    ] {
        assert!(err.contains(part), "{part}: {err}");
    }
    assert!(!err.contains("adjust [home]"), "{err}");
    let r = write("origin = { xyz = [0.06, 0.0, 0.02], rpy = [0.0, -1.5707963267948966, 0.0] }\n")
        .expect("the turned sole frame");
    let d0 = Robot::embedded_default().expect("icub_like").derived;
    let d = r.derived;
    assert!((d.mass - d0.mass).abs() < 1e-12);
    assert!(
        (d.com_height - d0.com_height).abs() < 1e-9,
        "{} {}",
        d.com_height,
        d0.com_height
    );
    assert!((d.hand_position - d0.hand_position).norm() < 1e-9);
    for a in 0..2 {
        for b in 0..2 {
            assert!(
                (d.support[a][b] - d0.support[a][b]).abs() < 1e-9,
                "{:?}",
                d.support
            );
        }
    }
    // acos near 1 turns rounding into ~1e-8 rad.
    assert!(d.sole_tilt < 1e-6, "{}", d.sole_tilt);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A sole of pads as a collision mesh (the heel's and the ball's flat at the bottom, a toe
/// 3.6 mm higher), as a binary STL next to the URDF, as an OBJ and as COLLADA (its units, its
/// up axis and its nodes' transforms applied), placed by the collision's origin and scale: the contacts are the pads' outer corners on the ground, the toe is off it.
#[test]
fn contact_points_come_from_a_collision_mesh() {
    let dir = std::env::temp_dir().join(format!("upc_sole_mesh_{}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).expect("dir");
    // Boxes in millimetres (the URDF scales by 1e-3): [x0, x1, y half-width, z0, z1].
    let pads = [
        [-80.0, -20.0, 30.0, 0.0, 20.0],
        [0.0, 90.0, 40.0, 0.0, 20.0],
        [100.0, 130.0, 35.0, 3.6, 20.0],
    ];
    let mut triangles = Vec::new();
    let mut obj = String::new();
    let mut n = 0;
    for [x0, x1, w, z0, z1] in pads {
        let v = |i: usize| {
            let pick = |b: usize, lo: f64, hi: f64| if i & b == 0 { lo } else { hi };
            [pick(1, x0, x1), pick(2, -w, w), pick(4, z0, z1)]
        };
        // Each face as two triangles (winding does not matter here).
        for (a, b, c, d) in [
            (0, 1, 3, 2),
            (4, 5, 7, 6),
            (0, 1, 5, 4),
            (2, 3, 7, 6),
            (0, 2, 6, 4),
            (1, 3, 7, 5),
        ] {
            for tri in [[a, b, c], [a, c, d]] {
                let vs = tri.map(|i| {
                    let p = v(i);
                    stl_io::Vector::new([p[0] as f32, p[1] as f32, p[2] as f32])
                });
                triangles.push(stl_io::Triangle {
                    normal: stl_io::Vector::new([0.0, 0.0, 1.0]),
                    vertices: vs,
                });
            }
        }
        for i in 0..8 {
            let p = v(i);
            obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
        }
        for (a, b, c, d) in [(0, 1, 3, 2), (4, 5, 7, 6)] {
            obj.push_str(&format!(
                "f {} {} {} {}\n",
                n + a + 1,
                n + b + 1,
                n + c + 1,
                n + d + 1
            ));
        }
        n += 8;
    }
    let mut file = std::fs::File::create(dir.join("meshes/sole.stl")).expect("stl");
    stl_io::write_stl(&mut file, triangles.iter()).expect("write stl");
    std::fs::write(dir.join("meshes/sole.obj"), obj).expect("obj");
    // The same vertices as COLLADA, written as exporters do: in millimetres (`<unit>`), y up,
    // under a node moved 10 mm along x holding a node scaled by ½ (so each coordinate stored
    // is the inverse of those: x' = 2 (x − 10), and (x, y, z) z-up is (x, z, −y) y-up).
    let mut positions = Vec::new();
    for [x0, x1, w, z0, z1] in pads {
        for i in 0..8 {
            let pick = |b: usize, lo: f64, hi: f64| if i & b == 0 { lo } else { hi };
            let (x, y, z) = (pick(1, x0, x1), pick(2, -w, w), pick(4, z0, z1));
            positions.extend([2.0 * (x - 10.0), 2.0 * z, -2.0 * y]);
        }
    }
    let floats: Vec<String> = positions.iter().map(|x| x.to_string()).collect();
    let dae = format!(
        r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="0.001" name="millimeter"/><up_axis>Y_UP</up_axis></asset>
  <library_geometries><geometry id="sole-mesh"><mesh>
    <source id="sole-positions"><float_array id="sole-positions-array" count="{}">{}</float_array>
      <technique_common><accessor source="#sole-positions-array" count="{}" stride="3"/></technique_common></source>
    <vertices id="sole-vertices"><input semantic="POSITION" source="#sole-positions"/></vertices>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="scene">
    <node id="moved"><translate>10 0 0</translate>
      <node id="halved"><scale>0.5 0.5 0.5</scale><instance_geometry url="#sole-mesh"/></node>
    </node>
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>"##,
        positions.len(),
        floats.join(" "),
        positions.len() / 3
    );
    std::fs::write(dir.join("meshes/sole.dae"), dae).expect("dae");
    let spec = FootSpec {
        frame: "sole".into(),
        link: Some("foot".into()),
        origin: None,
        contacts: ContactSpec::Keyword("collision".into()),
    };
    // The pads' bottom 4 cm below the ankle's link frame: the contacts at z = −0.5 − 0.04.
    let want = [[0.09, 0.04], [0.09, -0.04], [-0.08, 0.03], [-0.08, -0.03]];
    for (file, scale) in [
        ("meshes/sole.stl", "0.001"),
        ("meshes/sole.obj", "0.001"),
        ("meshes/sole.dae", "1"),
    ] {
        let urdf = foot_urdf(&format!(
            r#"<collision><origin xyz="0 0 -0.04" rpy="0 0 0"/><geometry><mesh filename="{file}" scale="{scale} {scale} {scale}"/></geometry></collision>"#
        ));
        let p = contact_points_in(&urdf, Some(&dir), &spec).expect(file);
        for (q, w) in p.iter().zip(want) {
            assert!(
                (q - Vector3::new(w[0], w[1], -0.54)).norm() < 1e-6,
                "{file}: {q:?} vs {w:?}"
            );
        }
    }
    // A format upc does not read: named, with the way out.
    std::fs::write(dir.join("meshes/sole.ply"), "ply\n").expect("ply");
    let urdf = foot_urdf(
        r#"<collision><geometry><mesh filename="meshes/sole.ply"/></geometry></collision>"#,
    );
    let e = contact_points_in(&urdf, Some(&dir), &spec)
        .expect_err("ply")
        .to_string();
    assert!(
        e.contains("STL, OBJ and COLLADA") && e.contains("contacts = [["),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// TALOS's feet collide through STL meshes: the support upc derives from them agrees with the
/// contact points its description lists (measured by hand from the same meshes) within 6 mm on
/// every side (the listed ones sit a few mm inside the sole's edge).
#[test]
fn talos_contacts_from_its_foot_meshes_match_the_listed_ones() {
    let dir = std::env::temp_dir().join(format!("upc_talos_mesh_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("talos_mesh.toml");
    let foot = |side: &str| {
        format!(
            "[feet.{side}]\nframe = \"{side}_sole_link\"\nlink = \"leg_{side}_6_link\"\n\
             contacts = \"collision\"\n"
        )
    };
    std::fs::write(
        &path,
        format!(
            "extends = \"talos\"\nname = \"talos_mesh\"\n{}{}",
            foot("left"),
            foot("right")
        ),
    )
    .expect("description");
    let (Some(listed), Some(meshed)) = (installed("talos"), installed(&path.display().to_string()))
    else {
        return;
    };
    let (a, b) = (listed.derived.support, meshed.derived.support);
    for axis in 0..2 {
        for side in 0..2 {
            assert!(
                (a[axis][side] - b[axis][side]).abs() < 6e-3,
                "support listed {a:?}, from the meshes {b:?}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `[stance]` solves the standing posture on a robot whose hip pitch axes are diagonal (30°
/// toward the vertical: no "hip + knee + ankle pitch = 0" rule holds), from straight legs (a
/// singular guess): the soles flat on the ground facing x, the CoM over the feet's centre, the
/// base `crouch` lower and upright, every joint within its limits, the hand near its target.
#[test]
fn a_stance_is_solved_for_diagonal_hip_axes_from_straight_legs() {
    let dir = std::env::temp_dir().join(format!("upc-stance-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let urdf = upc::dynamics::icub_like::URDF;
    let diagonal = urdf
        .replacen(
            "<child link=\"l_hip_1\"/>\n    <axis xyz=\"0 -1 0\"/>",
            "<child link=\"l_hip_1\"/>\n    <axis xyz=\"0 -0.8660254 0.5\"/>",
            1,
        )
        .replacen(
            "<child link=\"r_hip_1\"/>\n    <axis xyz=\"0 -1 0\"/>",
            "<child link=\"r_hip_1\"/>\n    <axis xyz=\"0 -0.8660254 -0.5\"/>",
            1,
        );
    assert_eq!(diagonal.matches("0.8660254").count(), 2, "the hips' axes");
    std::fs::write(dir.join("diagonal.urdf"), diagonal).expect("urdf");
    // The iCub-like's description without its legs' posture, the arms' kept as the guess.
    let text = include_str!("../config/robots/icub_like.toml");
    let mut description: String = text
        .lines()
        .filter(|l| {
            !["hip", "knee", "ankle"]
                .iter()
                .any(|j| l.contains(j) && l.contains('='))
        })
        .map(|l| {
            if l.starts_with("path = ") {
                "path = \"diagonal.urdf\"".to_string()
            } else if l.starts_with("name = ") {
                "name = \"diagonal_hips\"".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let (crouch, hand) = (0.03, [0.2, -0.1, 0.55]);
    description.push_str(&format!(
        "\n[stance]\ncrouch = {crouch}\nhand = [{}, {}, {}]\n",
        hand[0], hand[1], hand[2]
    ));
    let path = dir.join("diagonal.toml");
    std::fs::write(&path, description).expect("description");
    let r = Robot::load(path.to_str().expect("utf-8")).expect("a solved stance");
    let d = &r.derived;
    assert!(d.sole_tilt < 0.01f64.to_radians(), "tilt {}", d.sole_tilt);
    assert!(
        d.com_offset[0].abs() < 1e-4 && d.com_offset[1].abs() < 1e-4,
        "CoM off the feet's centre by {:?}",
        d.com_offset
    );
    for j in r.model.joints.iter().filter(|j| j.nq() == 1) {
        let x = r.home[j.idx_q];
        assert!(
            x >= j.limits.lower - 1e-12 && x <= j.limits.upper + 1e-12,
            "{} = {x} outside [{}, {}]",
            j.name,
            j.limits.lower,
            j.limits.upper
        );
    }
    // The knees bent (the base sank by bending them, the legs did not splay).
    let knee = |n: &str| r.home[r.model.joints[r.model.joint_id(n).expect("knee")].idx_q];
    assert!(
        knee("l_knee") > 0.3 && knee("r_knee") > 0.3,
        "knees {} {}",
        knee("l_knee"),
        knee("r_knee")
    );
    // The base `crouch` below its zero-posture height above the soles, and upright.
    let root = r
        .model
        .joints
        .iter()
        .position(|j| j.nv() == 6)
        .expect("a floating base");
    let mut data = Data::new(&r.model);
    let sole_id = r.model.frame_id("l_sole").expect("sole");
    let mut base_over_sole = |q: &nalgebra::DVector<f64>| {
        forward_kinematics(&r.model, &mut data, q).expect("fk");
        update_frame_placements(&r.model, &mut data);
        data.o_m_i[root].trans.z - data.o_m_f[sole_id].trans.z
    };
    let (zero, home) = (base_over_sole(&r.model.neutral()), base_over_sole(&r.home));
    assert!(
        (zero - home - crouch).abs() < 1e-5,
        "the base sank {} m",
        zero - home
    );
    let tilt = (data.o_m_i[root].rot * Vector3::z()).z.acos();
    assert!(tilt < 1e-4, "base tilt {tilt}");
    // The hand near its target (relative to the feet's centre on the ground).
    let soles = ["l_sole", "r_sole"].map(|s| data.o_m_f[r.model.frame_id(s).expect("sole")].trans);
    let centre = (soles[0] + soles[1]) / 2.0;
    let h = data.o_m_f[r.model.frame_id("r_hand").expect("hand")].trans - centre;
    assert!((h - Vector3::from(hand)).norm() < 0.01, "hand at {h:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
