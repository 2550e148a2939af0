//! `upc robot init`: a robot description drafted from a URDF alone (README, "Bring your
//! robot"). Everything is read from the kinematic tree and the geometry at the zero posture,
//! where a URDF stands straight with its arms down:
//! - which way is up: the root link's z, or, when no two feet stand level below the base along
//!   −z (a human model's URDF has y up), the root link's axis whose turn down puts two feet
//!   deepest below it, written as `[urdf] root_rpy`;
//! - the feet: the link whose collision geometry reaches lowest (the shallowest of those that
//!   reach it, so a foot before its toes), and the lowest on another leg (no moving joint in
//!   common); the visual geometry when the legs have no collision geometry;
//! - the robot's front: where its knees' flexion (their larger range) swings the ankles from,
//!   which also tells its left from its right;
//! - each sole frame: the URDF's own (a frame named `*sole*` on the foot, level, facing the
//!   toes; its corner frames as contacts when it has them) or one upc makes on the foot link,
//!   turned so that z is up and x points forward, its contacts the geometry's lowest face;
//! - the hands: on each side of the upper body, the arm whose chain goes deepest; the hand is
//!   where that chain branches into fingers or moves a gripper (or its last link), named by a
//!   fixed frame of it that says `hand`, `palm` or `gripper` when there is one; the arms' chain
//!   root is the link the two arms share (the torso after any waist joints);
//! - the joints below the hands (fingers) and those that move no mass are locked; links with
//!   mass and no rotational inertia get `inertia_floor`; joints whose body has no mass (ball
//!   joints split into one-axis joints) get `[armature]`, so that M stays invertible where
//!   their axes align;
//! - the IMU: a frame named `*imu*`, on the base if one is;
//! - the posture: `[stance]`, knees bent by 5 % of the base's height, the hand held forward and
//!   down of its shoulder, solved by [`super::stance`] and written out as `[home]`.
//!
//! The draft is loaded as any description is (every check of [`super::Robot::parse`]) before
//! it is written: what it writes, upc runs.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};

mod arms;
mod ground;
mod joints;
mod toml;
mod tree;

use super::{Robot, RobotError, packages};
use crate::dynamics::{BaseJoint, Model, forward_kinematics, turn_root};
use arms::{Arms, stance};
use ground::{FootFound, find_feet, robot_axes, sole_for, upright_turn};
use joints::{finger_joints, lock_inert_joints, massless_joints, point_masses};
use toml::list3;
use tree::{Pose, Tree};
/// The knees' bend of the drafted stance: the base this fraction of its height lower.
const CROUCH: f64 = 0.05;
/// The hand's target from its shoulder, in arm lengths (shoulder to hand frame): forward, out
/// to its side and down: 0.78 arm lengths away, the elbow bent. The hand-written descriptions
/// hold it 0.6–1.1 forward, 0.4–0.9 down; nearer full reach C1 fell on example-robot-data's
/// iCub, nearer the body on the iCub-like (docs/results/robots.md, "Drafted descriptions").
const HAND_FORWARD: f64 = 0.5;
const HAND_OUT: f64 = 0.05;
const HAND_DOWN: f64 = 0.6;
/// A link reaching within this of the lowest point on its side is on the ground (m).
const ON_GROUND: f64 = 5e-3;
/// A principal moment at or below this is none (MuJoCo's `mjMINVAL`), and the floor a draft
/// gives it (kg·m²: a radius of gyration of 1 mm for a 1 kg link).
const POINT_MASS: f64 = 1e-15;
const INERTIA_FLOOR: f64 = 1e-6;
/// The armature a draft gives a joint whose body has no mass (kg·m²): the order of a
/// humanoid joint's reflected rotor inertia (a 10 g·m² rotor-and-gear).
const ARMATURE: f64 = 0.01;
/// Names of the links a hand's fingers or gripper move.
const FINGER_NAMES: [&str; 3] = ["finger", "thumb", "gripper"];
/// Names of a hand's frame, best first.
const HAND_NAMES: [&str; 4] = ["hand", "palm", "gripper", "tool"];

/// What `upc robot init` found in a URDF, each choice with why (written as comments).
#[derive(Debug, Clone)]
pub struct Draft {
    pub name: String,
    pub package: Option<String>,
    pub path: PathBuf,
    /// Left, right.
    pub feet: [DraftFoot; 2],
    pub hand: String,
    pub chain_root: String,
    pub imu: Option<String>,
    /// Joints locked (fingers, joints that move no mass), with their value when not 0.
    pub locked: Vec<(String, f64)>,
    pub crouch: f64,
    /// The hand's target from the feet's centre on the ground (m; x forward, y left, z up).
    pub hand_target: [f64; 3],
    /// `inertia_floor`, when the URDF has point masses.
    pub inertia_floor: Option<f64>,
    /// `[urdf] root_rpy`, when the URDF's z is not up at the zero posture.
    pub root_rpy: Option<[f64; 3]>,
    /// Joints given [`ARMATURE`]: those whose body has no mass.
    pub armature: Vec<String>,
    /// What the reader should know about the choices.
    pub notes: Vec<String>,
}

/// One drafted foot.
#[derive(Debug, Clone)]
pub struct DraftFoot {
    pub link: String,
    pub frame: String,
    /// The made sole frame's rotation in the link (`None`: the URDF's frame, or the link's axes).
    pub rpy: Option<[f64; 3]>,
    /// The made sole frame's position in the link, when its contacts are listed.
    pub xyz: Option<[f64; 3]>,
    /// Contacts listed in the sole frame (from visual geometry); `None`: "collision".
    pub contacts: Option<Vec<[f64; 3]>>,
    /// The URDF has the sole's corner frames (`<sole>_fl`, …): contacts = "frames".
    pub corner_frames: bool,
    /// The URDF names the sole frame.
    pub urdf_frame: bool,
}

/// Drafts a description of the URDF at `path` (inside `package` when given) named `name`.
pub fn draft(package: Option<&str>, path: &Path, name: &str) -> Result<Draft, RobotError> {
    let urdf_err = |reason: String| RobotError::Urdf {
        robot: name.to_owned(),
        reason,
    };
    let file = match package {
        Some(p) => packages::package_root(p).map_err(urdf_err)?.join(path),
        None => path.to_path_buf(),
    };
    let urdf_dir = file.parent();
    let mut notes = Vec::new();
    let (urdf, root_rpy) = read_upright(&file, urdf_err, &mut notes)?;
    let tree = Tree::new(&urdf).map_err(urdf_err)?;
    let model = Model::from_urdf_robot_locked(&urdf, BaseJoint::Floating, &HashMap::new())?;
    let pose = Pose::zero(&model)?;

    let (feet_found, forward) = find_feet(&urdf, urdf_dir, &tree, &pose, &mut notes)?;
    // The robot's frame in the base's: x its front (the toes), y its left.
    let axes = robot_axes(&forward);
    let to_robot = axes.transpose();
    let [left, right] = left_and_right(feet_found, &to_robot);
    let feet = [
        sole_for(&left, "left", &tree, &pose, &axes, &mut notes)?,
        sole_for(&right, "right", &tree, &pose, &axes, &mut notes)?,
    ];
    let arms = Arms::find(&urdf, &tree, &pose, &to_robot, [&left, &right], &mut notes)?;
    let mut locked = finger_joints(&urdf, &tree, &model, &arms, &mut notes);
    let reduced = lock_inert_joints(&urdf, &model, &mut locked, &mut notes)?;
    let armature = massless_joints(&reduced, &locked, &mut notes);
    let inertia_floor = point_masses(&reduced, &mut notes);
    let imu = imu_frame(&model, &tree);
    let (crouch, hand_target) = stance(&tree, &pose, &to_robot, [&left, &right], &arms)?;
    Ok(Draft {
        name: name.to_owned(),
        package: package.map(str::to_owned),
        path: if package.is_some() {
            path.to_path_buf()
        } else {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
        },
        feet,
        hand: arms.hand,
        chain_root: arms.chain_root,
        imu,
        locked,
        crouch,
        hand_target,
        inertia_floor,
        root_rpy,
        armature,
        notes,
    })
}

/// The URDF in `file`, its root link turned upright when its z is not up (the turn, as
/// `[urdf] root_rpy`, and a note).
fn read_upright(
    file: &Path,
    urdf_err: impl Fn(String) -> RobotError,
    notes: &mut Vec<String>,
) -> Result<(urdf_rs::Robot, Option<[f64; 3]>), RobotError> {
    let text =
        std::fs::read_to_string(file).map_err(|e| urdf_err(format!("{}: {e}", file.display())))?;
    let mut urdf = crate::dynamics::parse_urdf(&text)?;
    let root_rpy = upright_turn(&urdf, file.parent())?;
    if let Some(rpy) = root_rpy {
        turn_root(&mut urdf, rpy)?;
        notes.push(format!(
            "the URDF's z axis is not up at the zero posture: its root link is turned by \
             [urdf] root_rpy = {}, which stands its feet under it",
            list3(rpy)
        ));
    }
    Ok((urdf, root_rpy))
}

/// The two feet as the robot's left and right (`to_robot`: the base's frame to the robot's).
fn left_and_right(feet: [FootFound; 2], to_robot: &Matrix3<f64>) -> [FootFound; 2] {
    let [a, b] = feet;
    if (to_robot * a.centroid).y > 0.0 {
        [a, b]
    } else {
        [b, a]
    }
}

/// The IMU: a frame named `*imu*`, the nearest the base.
fn imu_frame(model: &Model, tree: &Tree) -> Option<String> {
    model
        .frames
        .iter()
        .filter(|f| f.name.to_ascii_lowercase().contains("imu"))
        .min_by_key(|f| f.parent.map_or(0, |j| tree.depth(&model.joints[j].body)))
        .map(|f| f.name.clone())
}

/// Loads a draft as `upc run` would (solving its stance): its text with the solved posture as
/// `[home]`, and the robot.
pub fn solve(draft: &mut Draft) -> Result<(String, Robot), RobotError> {
    let first = draft.to_toml(&BTreeMap::new());
    let robot = Robot::parse(&first, "<drafted description>", None)?;
    // A target out of the arm's reach: the draft holds the hand where the arm reached.
    let reached = robot.derived.hand_position;
    let miss = (reached - Vector3::from(draft.hand_target)).norm();
    if miss > 5e-3 {
        draft.notes.push(format!(
            "the hand's first target was {:.0} mm out of the arm's reach: [stance] hand is \
             where it reached",
            miss * 1e3
        ));
        draft.hand_target = [reached.x, reached.y, reached.z].map(round3);
    }
    // A foot wider than long is a foot turned: most often a mesh whose COLLADA up axis the
    // URDF's author read otherwise (upc reads it as Assimp does, as Pinocchio and ROS do).
    let mut data = crate::dynamics::Data::new(&robot.model);
    forward_kinematics(&robot.model, &mut data, &robot.home)?;
    for (k, side) in ["left", "right"].iter().enumerate() {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for c in &robot.contacts[4 * k..4 * k + 4] {
            let p = data.o_m_f[robot.model.frame_id(c)?].trans;
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
        let (long, wide) = (hi.x - lo.x, hi.y - lo.y);
        if wide > long {
            draft.notes.push(format!(
                "the {side} foot's support is wider ({:.0} mm) than long ({:.0} mm): its \
                 geometry may be turned (a COLLADA mesh's up axis read otherwise by the URDF's \
                 author?); check it with upc model, or list the contacts",
                wide * 1e3,
                long * 1e3
            ));
        }
    }
    let mut home = BTreeMap::new();
    for j in robot.model.joints.iter().filter(|j| j.nq() == 1) {
        let v = robot.home[j.idx_q];
        if v.abs() > 5e-5 {
            home.insert(j.name.clone(), v);
        }
    }
    let text = draft.to_toml(&home);
    let robot = Robot::parse(&text, "<drafted description>", None)?;
    Ok((text, robot))
}

/// A locked joint's value: 0, or its nearer limit when 0 is outside them.
fn lock_value(model: &Model, joint: &str) -> f64 {
    model
        .joint_id(joint)
        .ok()
        .map(|i| &model.joints[i].limits)
        .map_or(0.0, |l| {
            if l.lower > 0.0 {
                l.lower
            } else if l.upper < 0.0 {
                l.upper
            } else {
                0.0
            }
        })
}

/// `x` to the nearest multiple of `step` (what the description shows: mm, 0.1 mm, µrad).
fn round_to(x: f64, step: f64) -> f64 {
    (x / step).round() * step
}

fn round3(x: f64) -> f64 {
    round_to(x, 1e-3)
}
