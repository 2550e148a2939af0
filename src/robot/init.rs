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
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::{Robot, RobotError, feet, packages};
use crate::dynamics::{BaseJoint, Data, Model, SE3, forward_kinematics, turn_root};

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

/// The URDF's link tree (from its joints).
struct Tree {
    root: String,
    /// Link → (parent link, joint is moving).
    parent: HashMap<String, (String, bool)>,
    /// Link → (child link, joint is moving).
    children: HashMap<String, Vec<(String, bool)>>,
}

impl Tree {
    fn new(urdf: &urdf_rs::Robot) -> Result<Self, String> {
        use urdf_rs::JointType as T;
        let mut parent = HashMap::new();
        let mut children: HashMap<String, Vec<(String, bool)>> = HashMap::new();
        for j in &urdf.joints {
            let moving = !matches!(j.joint_type, T::Fixed);
            parent.insert(j.child.link.clone(), (j.parent.link.clone(), moving));
            children
                .entry(j.parent.link.clone())
                .or_default()
                .push((j.child.link.clone(), moving));
        }
        let root = urdf
            .links
            .iter()
            .find(|l| !parent.contains_key(&l.name))
            .map(|l| l.name.clone())
            .ok_or("the URDF's links form no tree (no root link)")?;
        Ok(Self {
            root,
            parent,
            children,
        })
    }

    /// `link`, its parent, … the root.
    fn ancestors<'a>(&'a self, link: &'a str) -> Vec<&'a str> {
        let mut out = vec![link];
        let mut cur = link;
        while let Some((p, _)) = self.parent.get(cur) {
            out.push(p);
            cur = p;
        }
        out
    }

    /// Moving joints between the root and `link`.
    fn depth(&self, link: &str) -> usize {
        let mut n = 0;
        let mut cur = link;
        while let Some((p, moving)) = self.parent.get(cur) {
            n += usize::from(*moving);
            cur = p;
        }
        n
    }

    /// The deepest link both `a` and `b` descend from.
    fn common<'a>(&'a self, a: &'a str, b: &'a str) -> &'a str {
        let up = self.ancestors(b);
        self.ancestors(a)
            .into_iter()
            .find(|l| up.contains(l))
            .unwrap_or(&self.root)
    }

    /// `link` and every link below it.
    fn subtree(&self, link: &str) -> Vec<String> {
        let mut out = vec![link.to_owned()];
        let mut k = 0;
        while k < out.len() {
            if let Some(c) = self.children.get(&out[k]) {
                out.extend(c.iter().map(|(l, _)| l.clone()));
            }
            k += 1;
        }
        out
    }

    /// `a` and `b` share no moving joint on their paths from the root (two legs).
    fn apart(&self, a: &str, b: &str) -> bool {
        let moved = |l: &str| -> Vec<String> {
            self.ancestors(l)
                .into_iter()
                .filter(|x| self.parent.get(*x).is_some_and(|p| p.1))
                .map(str::to_owned)
                .collect()
        };
        let (ma, mb) = (moved(a), moved(b));
        !ma.is_empty() && !mb.is_empty() && ma.iter().all(|x| !mb.contains(x))
    }

    /// A moving joint below `link`, or into it when `moving`.
    fn moves_below(&self, link: &str) -> bool {
        self.children
            .get(link)
            .is_some_and(|c| c.iter().any(|(l, m)| *m || self.moves_below(l)))
    }

    /// Branches below `link` that move (fingers).
    fn moving_branches(&self, link: &str) -> usize {
        self.children.get(link).map_or(0, |c| {
            c.iter().filter(|(l, m)| *m || self.moves_below(l)).count()
        })
    }

    /// A moving joint into a child of `link` that a gripper's or a hand's name says it is
    /// (a one-joint gripper: no branching tells it from the arm).
    fn grips(&self, link: &str) -> bool {
        self.children.get(link).is_some_and(|c| {
            c.iter().any(|(l, m)| {
                let n = l.to_ascii_lowercase();
                *m && FINGER_NAMES.iter().any(|f| n.contains(f))
            })
        })
    }

    /// The link's body: itself, or the first ancestor a moving joint carries.
    fn body<'a>(&'a self, link: &'a str) -> &'a str {
        let mut cur = link;
        while let Some((p, moving)) = self.parent.get(cur) {
            if *moving {
                break;
            }
            cur = p;
        }
        cur
    }
}

/// The zero posture's kinematics.
struct Pose<'a> {
    model: &'a Model,
    data: Data,
}

impl<'a> Pose<'a> {
    /// The zero posture, the base at the identity.
    fn zero(model: &'a Model) -> Result<Self, RobotError> {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &model.neutral())?;
        Ok(Pose { model, data })
    }

    fn link(&self, name: &str) -> Result<SE3, RobotError> {
        Ok(self.data.o_m_f[self.model.frame_id(name)?])
    }
}

/// A foot found on one side of the base (before knowing which is the robot's left).
struct FootFound {
    link: String,
    /// The ankle (the foot's last moving joint) and the support's centroid, base frame.
    ankle: Vector3<f64>,
    centroid: Vector3<f64>,
    lowest: f64,
    /// The visual geometry the contacts come from, when the URDF has no collision geometry.
    geometry: Option<feet::Collision>,
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

/// The arms found on the upper body: the right one's hand and the chain both share.
struct Arms {
    /// The link both arms share (the pelvis when there is one arm).
    chain_root: String,
    /// Where each arm's chain branches into fingers: the right's, the left's.
    right_palm: String,
    left_palm: Option<String>,
    /// The right hand's frame.
    hand: String,
}

impl Arms {
    /// The arms: the upper body is what the legs (below `feet`) are not; on each side the arm
    /// is the chain that goes deepest.
    fn find(
        urdf: &urdf_rs::Robot,
        tree: &Tree,
        pose: &Pose,
        to_robot: &Matrix3<f64>,
        feet: [&FootFound; 2],
        notes: &mut Vec<String>,
    ) -> Result<Arms, RobotError> {
        let [left, right] = feet;
        let pelvis = tree.common(&left.link, &right.link).to_owned();
        let mut legs = Vec::new();
        for f in feet {
            let up = tree.ancestors(&f.link);
            if let Some(k) = up.iter().position(|l| *l == pelvis)
                && k > 0
            {
                legs.extend(tree.subtree(up[k - 1]));
            }
        }
        let arm_tip = |side: f64| arm_tip(urdf, tree, pose, to_robot, &legs, side);
        let right_tip = arm_tip(-1.0)?.ok_or_else(|| {
            RobotError::Feet(
                "no right arm found (no link right of the base above the legs): write [hand] \
                 by hand"
                    .into(),
            )
        })?;
        let left_tip = arm_tip(1.0)?;
        let chain_root = match &left_tip {
            Some(l) => tree.common(&right_tip, l).to_owned(),
            None => {
                notes.push("no left arm found: the arm's chain starts at the pelvis".into());
                pelvis.clone()
            }
        };
        let right_palm = palm(tree, &chain_root, &right_tip);
        let hand = hand_frame(tree, &right_palm);
        let left_palm = left_tip.map(|l| palm(tree, &chain_root, &l));
        Ok(Arms {
            chain_root,
            right_palm,
            left_palm,
            hand,
        })
    }
}

/// The end of the arm on the robot's left (`side` 1) or right (−1): of the links off the
/// `legs` at least 2 cm to that side of the base, the deepest (then the furthest out).
fn arm_tip(
    urdf: &urdf_rs::Robot,
    tree: &Tree,
    pose: &Pose,
    to_robot: &Matrix3<f64>,
    legs: &[String],
    side: f64,
) -> Result<Option<String>, RobotError> {
    let root_at = pose.link(&tree.root)?.trans;
    let mut best: Option<(usize, f64, String)> = None;
    for l in &urdf.links {
        if legs.contains(&l.name) {
            continue;
        }
        let y = (to_robot * (pose.link(&l.name)?.trans - root_at)).y * side;
        if y < 0.02 {
            continue;
        }
        let d = tree.depth(&l.name);
        if best
            .as_ref()
            .is_none_or(|(bd, by, _)| d > *bd || (d == *bd && y > *by))
        {
            best = Some((d, y, l.name.clone()));
        }
    }
    Ok(best.map(|b| b.2))
}

/// The joints below the hands (fingers), locked at [`lock_value`] (a note says how many).
fn finger_joints(
    urdf: &urdf_rs::Robot,
    tree: &Tree,
    model: &Model,
    arms: &Arms,
    notes: &mut Vec<String>,
) -> Vec<(String, f64)> {
    let mut locked: Vec<(String, f64)> = Vec::new();
    let palms = std::iter::once(&arms.right_palm).chain(&arms.left_palm);
    for p in palms {
        for l in tree.subtree(p).iter().skip(1) {
            if let Some((_, true)) = tree.parent.get(l)
                && let Some(j) = urdf.joints.iter().find(|j| &j.child.link == l)
            {
                locked.push((j.name.clone(), lock_value(model, &j.name)));
            }
        }
    }
    if !locked.is_empty() {
        notes.push(format!(
            "{} joints below the hands (fingers) are locked: the door is held by the hand",
            locked.len()
        ));
    }
    locked
}

/// The joints that still move no mass with `locked` locked (M singular): locked too. Returns
/// the model with all of them locked.
fn lock_inert_joints(
    urdf: &urdf_rs::Robot,
    model: &Model,
    locked: &mut Vec<(String, f64)>,
    notes: &mut Vec<String>,
) -> Result<Model, RobotError> {
    let names: HashMap<String, f64> = locked.iter().cloned().collect();
    let reduced = Model::from_urdf_robot_locked(urdf, BaseJoint::Floating, &names)?;
    let inert: Vec<String> = reduced
        .inert_joints()
        .into_iter()
        .map(|i| reduced.joints[i].name.clone())
        .collect();
    if !inert.is_empty() {
        notes.push(format!(
            "{} joints move no mass (massless links in the URDF) and are locked: {}",
            inert.len(),
            inert.join(", ")
        ));
        for n in inert {
            let v = lock_value(model, &n);
            locked.push((n, v));
        }
    }
    Ok(reduced)
}

/// Joints whose body has no mass (a ball joint split into one-axis joints through massless
/// links), given [`ARMATURE`]: a rotor's inertia keeps M invertible where two of their axes
/// align (gimbal lock, which a falling robot reaches).
fn massless_joints(
    reduced: &Model,
    locked: &[(String, f64)],
    notes: &mut Vec<String>,
) -> Vec<String> {
    let armature: Vec<String> = reduced
        .joints
        .iter()
        .filter(|j| j.nv() == 1 && j.inertia.mass <= 0.0)
        .filter(|j| !locked.iter().any(|(n, _)| *n == j.name))
        .map(|j| j.name.clone())
        .collect();
    if !armature.is_empty() {
        notes.push(format!(
            "{} joints carry a link without mass (ball joints split into one-axis joints): \
             [armature] gives each {ARMATURE} kg·m², so that M stays invertible where their \
             axes align",
            armature.len()
        ));
    }
    armature
}

/// Point masses (MuJoCo refuses them): `inertia_floor` on their moments, when there are any.
fn point_masses(reduced: &Model, notes: &mut Vec<String>) -> Option<f64> {
    let points: Vec<String> = reduced
        .joints
        .iter()
        .filter(|j| {
            j.inertia.mass > 0.0
                && nalgebra::SymmetricEigen::new(j.inertia.inertia_com())
                    .eigenvalues
                    .min()
                    <= POINT_MASS
        })
        .map(|j| j.body.clone())
        .collect();
    (!points.is_empty()).then(|| {
        notes.push(format!(
            "{} links are point masses (no rotational inertia: {}): inertia_floor gives them \
             {INERTIA_FLOOR:e} kg·m² about each axis",
            points.len(),
            points.join(", ")
        ));
        INERTIA_FLOOR
    })
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

/// The stance: the base lower by [`CROUCH`] of its height (the crouch, m), the hand forward
/// and down of its shoulder (its target from the feet's centre on the ground).
fn stance(
    tree: &Tree,
    pose: &Pose,
    to_robot: &Matrix3<f64>,
    [left, right]: [&FootFound; 2],
    arms: &Arms,
) -> Result<(f64, [f64; 3]), RobotError> {
    let root_at = pose.link(&tree.root)?.trans;
    let ground = left.lowest.min(right.lowest);
    let base_height = root_at.z - ground;
    let centre = (left.centroid + right.centroid) / 2.0;
    let shoulder = first_moving(tree, &arms.chain_root, &arms.right_palm)
        .map(|l| pose.link(l).map(|p| p.trans))
        .transpose()?
        .unwrap_or(root_at);
    let arm = (pose.link(&arms.hand)?.trans - shoulder).norm();
    let s = to_robot * (shoulder - centre);
    let crouch = round3(CROUCH * base_height);
    let hand_target = [
        round3(s.x + HAND_FORWARD * arm),
        round3(s.y - HAND_OUT * arm),
        round3(shoulder.z - ground - crouch - HAND_DOWN * arm),
    ];
    Ok((crouch, hand_target))
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

/// The two feet (either side of the base) and the way the robot faces (a horizontal unit
/// vector in the base's frame).
fn find_feet(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    tree: &Tree,
    pose: &Pose,
    notes: &mut Vec<String>,
) -> Result<([FootFound; 2], Vector3<f64>), RobotError> {
    let mut search = FootSearch {
        urdf,
        urdf_dir,
        tree,
        pose,
        visual: false,
        found: Vec::new(),
    };
    search.found = search.candidates()?;
    let two_legs = |found: &[(String, f64)]| {
        found
            .iter()
            .any(|a| found.iter().any(|b| tree.apart(&a.0, &b.0)))
    };
    if !two_legs(&search.found) {
        // No collision geometry on the legs (a URDF made for drawing): the visual's.
        search.visual = true;
        search.found = search.candidates()?;
        notes.push(
            "the legs have no collision geometry: the feet and their contacts come from the \
             visual meshes (listed as points below)"
                .into(),
        );
    }
    let a = search.pick(None)?;
    let b = search.pick(Some(&a.link))?;
    if (a.lowest - b.lowest).abs() > 0.02 {
        return Err(RobotError::Feet(format!(
            "the feet found ({}, {}) are {:.0} mm apart in height at the zero posture: not a \
             robot standing straight there; write [feet] by hand",
            a.link,
            b.link,
            (a.lowest - b.lowest).abs() * 1e3
        )));
    }
    let forward = facing(pose, [&a, &b], notes)?;
    Ok(([a, b], forward))
}

/// The search for the feet among the links below the base.
struct FootSearch<'a> {
    urdf: &'a urdf_rs::Robot,
    urdf_dir: Option<&'a Path>,
    tree: &'a Tree,
    pose: &'a Pose<'a>,
    /// Whether the geometry read is the visual one (the collision one otherwise).
    visual: bool,
    /// The candidates: (link, lowest z).
    found: Vec<(String, f64)>,
}

impl FootSearch<'_> {
    /// Links below the base with geometry upc reads: (link, lowest z).
    fn candidates(&self) -> Result<Vec<(String, f64)>, RobotError> {
        let root = self.pose.link(&self.tree.root)?;
        let mut found = Vec::new();
        for l in &self.urdf.links {
            let at = self.pose.link(&l.name)?;
            if at.trans.z >= root.trans.z {
                continue;
            }
            // A link whose geometry cannot be read is not a foot upc can stand on.
            let Ok(c) = feet::geometry_points(self.urdf, self.urdf_dir, &l.name, self.visual)
            else {
                continue;
            };
            let lowest = c
                .points
                .iter()
                .zip(&c.radii)
                .map(|(p, r)| at.act_point(p).z - r)
                .fold(f64::INFINITY, f64::min);
            found.push((l.name.clone(), lowest));
        }
        Ok(found)
    }

    /// The foot: of the candidates reaching within [`ON_GROUND`] of the lowest (on another
    /// leg than `other`, no moving joint in common, when given), the shallowest in the tree.
    fn pick(&self, other: Option<&str>) -> Result<FootFound, RobotError> {
        let (tree, pose) = (self.tree, self.pose);
        let side: Vec<&(String, f64)> = self
            .found
            .iter()
            .filter(|f| other.is_none_or(|o| tree.apart(&f.0, o)))
            .collect();
        let low = side.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
        let link = side
            .iter()
            .filter(|f| f.1 < low + ON_GROUND)
            .min_by(|a, b| {
                tree.depth(&a.0)
                    .cmp(&tree.depth(&b.0))
                    .then(a.1.total_cmp(&b.1))
            })
            .map(|f| f.0.clone())
            .ok_or_else(|| {
                RobotError::Feet(format!(
                    "no {} foot found (no link below the base with collision or visual geometry \
                     upc reads{}): write [feet] by hand",
                    if other.is_some() { "second" } else { "" },
                    other.map_or(String::new(), |o| format!(" on another leg than `{o}`"))
                ))
            })?;
        let root = pose.link(&tree.root)?;
        let base_rot = root.rot;
        let at = pose.link(&link)?;
        let c = feet::geometry_points(self.urdf, self.urdf_dir, &link, self.visual)?;
        // The support in the base's axes about the link's origin.
        let to_base = SE3::new(base_rot.transpose() * at.rot, Vector3::zeros());
        let support = feet::lowest_four(&c, &to_base, &link)?;
        let centroid_rel = support.iter().sum::<Vector3<f64>>() / 4.0;
        let body = tree.body(&link);
        let ankle = base_rot.transpose() * (pose.link(body)?.trans - root.trans);
        let origin = base_rot.transpose() * (at.trans - root.trans);
        Ok(FootFound {
            ankle,
            centroid: origin + centroid_rel,
            lowest: low,
            geometry: self.visual.then_some(c),
            link,
        })
    }
}

/// The way the robot faces (a horizontal unit vector in the base's frame): where the knees
/// bend backward from; failing a knee, the toes: the support reaches further ahead of the
/// ankle than behind it (a note says so).
fn facing(
    pose: &Pose,
    [a, b]: [&FootFound; 2],
    notes: &mut Vec<String>,
) -> Result<Vector3<f64>, RobotError> {
    let knees = [knee_forward(pose, &a.link)?, knee_forward(pose, &b.link)?];
    let ahead = (a.centroid.x - a.ankle.x) + (b.centroid.x - b.ankle.x);
    Ok(match knees {
        [Some(x), Some(y)] if x.dot(&y) > 0.9 => (x + y).normalize(),
        _ => {
            let sign = if ahead < 0.0 { -1.0 } else { 1.0 };
            notes.push(format!(
                "no knee bends both legs the same way: the robot is taken to face the base's \
                 {}x, where the soles reach {:.0} mm beyond the ankles; check the feet's x axes \
                 with upc model",
                if sign > 0.0 { "+" } else { "−" },
                ahead.abs() / 2.0 * 1e3,
            ));
            Vector3::x() * sign
        }
    })
}

/// The turns [`upright_turn`] tries: the root link's x, −x, y, −y or z pointing down.
const TURNS: [[f64; 3]; 5] = [
    [0.0, FRAC_PI_2, 0.0],
    [0.0, -FRAC_PI_2, 0.0],
    [-FRAC_PI_2, 0.0, 0.0],
    [FRAC_PI_2, 0.0, 0.0],
    [PI, 0.0, 0.0],
];

/// The root link's turn that stands a URDF upright (`[urdf] root_rpy`): none when two feet are
/// found below the base along −z (as URDFs mostly have it); otherwise, of the turns that put
/// one of the root link's other axes down, the one whose two feet reach deepest below the base
/// (the wrong turns find no two feet level, or a shallower pair such as the toes).
fn upright_turn(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
) -> Result<Option<[f64; 3]>, RobotError> {
    let depth = |rpy: Option<[f64; 3]>| -> Result<f64, RobotError> {
        let mut turned = urdf.clone();
        if let Some(r) = rpy {
            turn_root(&mut turned, r)?;
        }
        let tree = Tree::new(&turned).map_err(RobotError::Feet)?;
        let model = Model::from_urdf_robot_locked(&turned, BaseJoint::Floating, &HashMap::new())?;
        let pose = Pose::zero(&model)?;
        let ([a, b], _) = find_feet(&turned, urdf_dir, &tree, &pose, &mut Vec::new())?;
        Ok(pose.link(&tree.root)?.trans.z - a.lowest.min(b.lowest))
    };
    let upright = match depth(None) {
        Ok(_) => return Ok(None),
        Err(e) => e,
    };
    TURNS
        .iter()
        .filter_map(|&r| depth(Some(r)).ok().map(|d| (d, r)))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, r)| Some(r))
        .ok_or(upright)
}

/// The way a leg faces (a horizontal unit vector in the base's frame), from its knee: the leg's
/// revolute joint with a horizontal axis nearest midway between hip and ankle, whose larger
/// range (flexion) swings the ankle backward. `None` without such a joint.
fn knee_forward(pose: &Pose, foot: &str) -> Result<Option<Vector3<f64>>, RobotError> {
    let model = pose.model;
    let mut chain = Vec::new();
    let mut cur = model.frames[model.frame_id(foot)?].parent;
    while let Some(j) = cur {
        if let crate::dynamics::JointKind::Revolute { axis } = model.joints[j].kind {
            chain.push((j, axis));
        }
        cur = model.joints[j].parent;
    }
    let (Some(ankle), Some(hip)) = (chain.first(), chain.last()) else {
        return Ok(None);
    };
    let at = |j: usize| pose.data.o_m_i[j].trans;
    let (za, zh) = (at(ankle.0).z, at(hip.0).z);
    let knee = chain
        .iter()
        .map(|&(j, axis)| (j, pose.data.o_m_i[j].rot * axis))
        .filter(|(j, w)| w.z.abs() < 0.3 && at(*j).z > za + 0.02 && at(*j).z < zh - 0.02)
        .min_by(|a, b| {
            let mid = (za + zh) / 2.0;
            (at(a.0).z - mid).abs().total_cmp(&(at(b.0).z - mid).abs())
        });
    let Some((k, w)) = knee else {
        return Ok(None);
    };
    let l = &model.joints[k].limits;
    let flexion = if l.upper.abs() >= l.lower.abs() {
        1.0
    } else {
        -1.0
    };
    let swing = flexion * w.cross(&(at(ankle.0) - at(k)));
    let back = pose.data.o_m_i[0].rot.transpose() * swing;
    let back = Vector3::new(back.x, back.y, 0.0);
    Ok((back.norm() > 1e-6).then(|| -back.normalize()))
}

/// The robot's axes in the base's frame (columns): x forward, y its left, z up.
fn robot_axes(forward: &Vector3<f64>) -> Matrix3<f64> {
    let z = Vector3::z();
    Matrix3::from_columns(&[*forward, z.cross(forward), z])
}

/// The sole frame of a found foot: the URDF's, when a level frame named `*sole*` on the foot
/// faces the toes; else made on the link, turned to face them with z up.
fn sole_for(
    f: &FootFound,
    side: &str,
    tree: &Tree,
    pose: &Pose,
    axes: &Matrix3<f64>,
    notes: &mut Vec<String>,
) -> Result<DraftFoot, RobotError> {
    let model = pose.model;
    let base = pose.link(&tree.root)?.rot;
    let body = model.frames[model.frame_id(&f.link)?].parent;
    let want = base * axes;
    for (k, fr) in model.frames.iter().enumerate() {
        if f.geometry.is_some()
            || fr.parent != body
            || !fr.name.to_ascii_lowercase().contains("sole")
        {
            continue;
        }
        let r = pose.data.o_m_f[k].rot;
        let off = Rotation3::from_matrix_unchecked(want.transpose() * r).angle();
        if off < 1f64.to_radians() {
            // The URDF's own corner frames, when it has them, are the contacts.
            let corners = super::CORNERS
                .iter()
                .all(|c| model.frame_id(&format!("{}_{c}", fr.name)).is_ok());
            return Ok(DraftFoot {
                link: f.link.clone(),
                frame: fr.name.clone(),
                rpy: None,
                xyz: None,
                contacts: None,
                corner_frames: corners,
                urdf_frame: true,
            });
        }
    }
    let link_rot = pose.link(&f.link)?.rot;
    let turn = Rotation3::from_matrix_unchecked(link_rot.transpose() * want);
    let rpy = (turn.angle() > 1e-9).then(|| {
        let (r, p, y) = turn.euler_angles();
        [r, p, y].map(|x| round_to(x, 1e-6))
    });
    if rpy.is_some() {
        notes.push(format!(
            "the {side} foot link `{}` is not level with its toes along x at the zero posture: \
             its sole frame is turned by `origin.rpy`",
            f.link
        ));
    }
    let mut frame = format!("{side}_sole");
    if model.frame_id(&frame).is_ok() {
        frame = format!("upc_{side}_sole");
    }
    // From visual geometry, the points are listed: the frame at their centroid.
    let (mut xyz, mut contacts) = (None, None);
    if let Some(g) = &f.geometry {
        let p = feet::lowest_four(
            g,
            &SE3::new(turn.matrix().transpose(), Vector3::zeros()),
            &f.link,
        )?;
        let c = p.iter().sum::<Vector3<f64>>() / 4.0;
        let at = turn * c;
        xyz = Some([at.x, at.y, at.z].map(|x| round_to(x, 1e-4)));
        contacts = Some(
            p.iter()
                .map(|x| {
                    let d = x - c;
                    [d.x, d.y, d.z].map(|v| round_to(v, 1e-4))
                })
                .collect(),
        );
    }
    Ok(DraftFoot {
        link: f.link.clone(),
        frame,
        rpy: rpy.or(xyz.map(|_| [0.0; 3])),
        xyz,
        contacts,
        corner_frames: false,
        urdf_frame: false,
    })
}

/// Where an arm's chain from `root` to `tip` branches into fingers (three moving joints or
/// more below `root`), or the tip's body when it never does.
fn palm(tree: &Tree, root: &str, tip: &str) -> String {
    let mut path: Vec<&str> = tree.ancestors(tip);
    let k = path.iter().position(|l| *l == root).unwrap_or(path.len());
    path.truncate(k);
    path.reverse();
    let mut joints = 0;
    for l in &path {
        if tree.parent.get(*l).is_some_and(|p| p.1) {
            joints += 1;
        }
        if joints >= 3 && (tree.moving_branches(l) >= 2 || tree.grips(l)) {
            return (*l).to_owned();
        }
    }
    tree.body(tip).to_owned()
}

/// The hand's frame: the palm, or a link fixed to it whose name says hand, palm, gripper.
fn hand_frame(tree: &Tree, palm: &str) -> String {
    let mut fixed = vec![palm.to_owned()];
    let mut k = 0;
    while k < fixed.len() {
        if let Some(c) = tree.children.get(&fixed[k]) {
            fixed.extend(c.iter().filter(|(_, m)| !m).map(|(l, _)| l.clone()));
        }
        k += 1;
    }
    let score = |n: &str| {
        let n = n.to_ascii_lowercase();
        HAND_NAMES
            .iter()
            .position(|h| n.contains(h))
            .map_or(0, |p| HAND_NAMES.len() - p)
    };
    // A name that ends with the word (`r_hand`) names the hand itself, not a part of it
    // (`r_hand_link`, `gripper_right_fingertip_1_link`).
    let ends = |n: &str| {
        let n = n.to_ascii_lowercase();
        HAND_NAMES.iter().any(|h| n.ends_with(h))
    };
    fixed
        .iter()
        .max_by_key(|n| (score(n), ends(n), n.as_str() == palm))
        .cloned()
        .unwrap_or_else(|| palm.to_owned())
}

/// The first link a moving joint carries on the way from `root` to `to` (the shoulder).
fn first_moving<'a>(tree: &'a Tree, root: &str, to: &'a str) -> Option<&'a str> {
    let path = tree.ancestors(to);
    let k = path.iter().position(|l| *l == root)?;
    path[..k]
        .iter()
        .rev()
        .find(|l| tree.parent.get(**l).is_some_and(|p| p.1))
        .copied()
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

/// A rounded value as the description shows it: at most six decimals, no trailing zeros, no
/// `-0`.
fn num(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// `[a, b, c]` with [`num`].
fn list3(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

impl Draft {
    /// The description as TOML, commented, with `home` as its `[home]` table.
    pub fn to_toml(&self, home: &BTreeMap<String, f64>) -> String {
        let mut s = String::new();
        self.write_header(&mut s);
        self.write_urdf(&mut s);
        for (side, f) in ["left", "right"].iter().zip(&self.feet) {
            write_foot(&mut s, side, f);
        }
        self.write_hand_and_imu(&mut s);
        self.write_locked_and_armature(&mut s);
        self.write_stance_and_home(&mut s, home);
        s
    }

    /// The comments (the notes), the name, the description, `inertia_floor`.
    fn write_header(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "# Drafted by `upc robot init` from the URDF alone (README, \"Bring your robot\").\n\
             # Check it with `upc model --robot <this file>`; every choice below may be edited."
        );
        for n in &self.notes {
            let _ = writeln!(s, "# - {n}");
        }
        let _ = writeln!(s, "name = {:?}", self.name);
        let _ = writeln!(
            s,
            "description = {:?}",
            format!("{} (drafted from {})", self.name, self.path.display())
        );
        if let Some(f) = self.inertia_floor {
            let _ = writeln!(s, "inertia_floor = {f:e}");
        }
    }

    /// `[urdf]`: the file, and the root link's turn.
    fn write_urdf(&self, s: &mut String) {
        let _ = writeln!(s, "\n[urdf]");
        if let Some(p) = &self.package {
            let _ = writeln!(s, "package = {p:?}");
        }
        let _ = writeln!(s, "path = {:?}", self.path.display().to_string());
        if let Some(rpy) = self.root_rpy {
            let _ = writeln!(
                s,
                "# The URDF's z axis is not up at its zero posture: its root link turned upright."
            );
            let _ = writeln!(s, "root_rpy = {}", list3(rpy));
        }
    }

    /// `[hand]`, and `[imu]` (or why there is none).
    fn write_hand_and_imu(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n# The right arm's end (where it branches into fingers); its chain from the link \
             both arms share.\n[hand]\nframe = {:?}\nchain_root = {:?}",
            self.hand, self.chain_root
        );
        match &self.imu {
            Some(i) => {
                let _ = writeln!(s, "\n[imu]\nframe = {i:?}");
            }
            None => {
                let _ = writeln!(
                    s,
                    "\n# No frame named *imu*: the IMU is taken on the base, aligned with it."
                );
            }
        }
    }

    /// `[locked]` and `[armature]`, when they list any joint.
    fn write_locked_and_armature(&self, s: &mut String) {
        if !self.locked.is_empty() {
            let names: Vec<String> = self.locked.iter().map(|(n, _)| format!("{n:?}")).collect();
            let _ = writeln!(
                s,
                "\n# Fingers and joints that move no mass.\n[locked]\njoints = [{}]",
                names.join(", ")
            );
        }
        if !self.armature.is_empty() {
            let _ = writeln!(
                s,
                "\n# Joints whose link has no mass (a ball joint split into one-axis joints): a \
                 rotor's inertia (kg·m²)\n# keeps the mass matrix invertible where their axes \
                 align.\n[armature]"
            );
            for j in &self.armature {
                let _ = writeln!(s, "{j:?} = {ARMATURE}");
            }
        }
    }

    /// `[stance]`, and `[home]`: `home` with the locked joints at their value.
    fn write_stance_and_home(&self, s: &mut String, home: &BTreeMap<String, f64>) {
        let _ = writeln!(
            s,
            "\n# The standing posture, solved at every load from [home] (soles flat, CoM over \
             the feet, base upright\n# and `crouch` lower, the hand at `hand` from the feet's \
             centre on the ground).\n[stance]\ncrouch = {}\nhand = {}",
            num(self.crouch),
            list3(self.hand_target)
        );
        let mut table: BTreeMap<&str, f64> = home.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        for (n, v) in &self.locked {
            if *v != 0.0 {
                table.insert(n, *v);
            }
        }
        let _ = writeln!(
            s,
            "\n# The solved posture (rad), the stance's starting guess; locked joints at their \
             value.\n[home]"
        );
        for (k, v) in table {
            let _ = writeln!(s, "{k} = {:.6}", v);
        }
    }
}

/// `[feet.<side>]`: the link, the sole frame, its contacts.
fn write_foot(s: &mut String, side: &str, f: &DraftFoot) {
    let contacts = if f.corner_frames {
        "the URDF's corner frames"
    } else if f.contacts.is_some() {
        "its visual mesh's lowest face's corners"
    } else {
        "its collision geometry's lowest face's corners"
    };
    let _ = writeln!(
        s,
        "\n# The link reaching lowest on this leg; contacts: {contacts}.\n[feet.{side}]"
    );
    let _ = writeln!(s, "frame = {:?}", f.frame);
    let _ = writeln!(s, "link = {:?}", f.link);
    match (f.xyz, f.rpy) {
        (Some(xyz), Some(rpy)) => {
            let _ = writeln!(
                s,
                "origin = {{ xyz = {}, rpy = {} }}",
                list3(xyz),
                list3(rpy)
            );
        }
        (None, Some(rpy)) => {
            let _ = writeln!(s, "origin = {{ rpy = {} }}", list3(rpy));
        }
        _ => {}
    }
    match &f.contacts {
        Some(c) => {
            let list: Vec<String> = c.iter().map(|p| list3(*p)).collect();
            let _ = writeln!(s, "contacts = [{}]", list.join(", "));
        }
        None if f.corner_frames => {
            let _ = writeln!(s, "contacts = \"frames\"");
        }
        None => {
            let _ = writeln!(s, "contacts = \"collision\"");
        }
    }
}
