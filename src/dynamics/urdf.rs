//! URDF → [`Model`] (parsing by urdf-rs, checks and tree building here).
//!
//! - Links are bodies; a link hanging from a `fixed` joint is merged into its parent body
//!   (inertia added, Pinocchio-style) and keeps a frame of its own name. Every link is a frame.
//! - `revolute`, `continuous` (angle coordinate, unbounded), `prismatic`, `fixed` are supported;
//!   `floating`, `planar`, `spherical` or unknown types are errors naming the joint.
//! - Floating base: a free-flyer joint `root_joint` carries the root link (see
//!   [`JointKind::FreeFlyer`] for the coordinates). [`BaseJoint::Auto`] picks a fixed base when
//!   the URDF root link is called `world`, a floating one otherwise.
//! - Locked joints ([`Model::from_urdf_str_locked`]) become fixed joints at their given value.
//! - Geometry (meshes included) is ignored: a missing mesh file is not an error.
//! - A zero `velocity`/`effort` limit (URDF 1.0's value for a missing attribute) reads as
//!   unbounded. A mimic joint stays an independent joint, as Pinocchio's parser has it by
//!   default (a load warning says so).
//! - Inertias: positive semi-definite ones are taken (point masses, rods, massless sensor and
//!   optical frames, as Pinocchio does). A tensor a little outside that cone (rounding, or the
//!   CAD export of a tiny part: its most negative principal moment within [`REPAIR_LIMIT`]) is
//!   repaired, its negative principal moments set to zero, with a load warning naming the link
//!   and the size of the repair; beyond that, or a negative mass, the model is refused.
//! - `<texture/>` without a file (visual only) is dropped before parsing.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::error::DynamicsError;
use super::joint::JointKind;
use super::model::{JointLimits, Model};
use super::spatial::{Inertia, SE3};

/// How the URDF root is attached to the world.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BaseJoint {
    /// Fixed when the root link is named `world`, floating otherwise.
    #[default]
    Auto,
    /// A free-flyer joint `root_joint` on the root link (if the root is a `world` link with a
    /// single child, the child becomes the floating root).
    Floating,
    /// The root link is welded to the world.
    Fixed,
}

/// Name of the free-flyer joint added for a floating base (as in Pinocchio).
pub const ROOT_JOINT_NAME: &str = "root_joint";

impl Model {
    /// Reads and builds a URDF file.
    pub fn from_urdf_file(path: impl AsRef<Path>, base: BaseJoint) -> Result<Model, DynamicsError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| DynamicsError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::from_urdf_str(&text, base)
    }

    /// Builds a model from URDF text.
    pub fn from_urdf_str(text: &str, base: BaseJoint) -> Result<Model, DynamicsError> {
        Self::from_urdf_str_locked(text, base, &HashMap::new())
    }

    /// Builds a model from URDF text with the joints of `locked` (name → coordinate) fixed at
    /// that value, as Pinocchio's `buildReducedModel`: the joint becomes a fixed one at its
    /// placement for the value (its child merged into the parent body, its frames kept).
    pub fn from_urdf_str_locked(
        text: &str,
        base: BaseJoint,
        locked: &HashMap<String, f64>,
    ) -> Result<Model, DynamicsError> {
        Self::from_urdf_robot_locked(&parse_urdf(text)?, base, locked)
    }

    /// [`Model::from_urdf_str_locked`] on a URDF already parsed (and perhaps turned upright by
    /// [`turn_root`]).
    pub fn from_urdf_robot_locked(
        robot: &urdf_rs::Robot,
        base: BaseJoint,
        locked: &HashMap<String, f64>,
    ) -> Result<Model, DynamicsError> {
        let model = build(robot, base, locked)?;
        for w in &model.load_warnings {
            tracing::warn!("URDF `{}`: {w}", model.name);
        }
        Ok(model)
    }
}

/// Parses URDF text (urdf-rs) with the loader's leniency and error messages, for readers of
/// what the model does not keep (collision geometry).
pub fn parse_urdf(text: &str) -> Result<urdf_rs::Robot, DynamicsError> {
    let text = without_empty_textures(text);
    urdf_rs::read_from_string(&text).map_err(|e| diagnose(&text, &e.to_string()))
}

/// The link [`turn_root`] adds above a URDF's root link: the floating base upc stands upright.
pub const UPRIGHT_BASE: &str = "upright_base";

/// Hangs the URDF's root link, turned by `rpy` (URDF's roll-pitch-yaw, rad), from a new massless
/// root link [`UPRIGHT_BASE`] by a fixed joint: for a URDF whose root link's z axis is not up
/// at the zero posture (a human model in the ISB convention has y up), the floating base is
/// then upright at the identity and the root link keeps its frame, its inertia merged.
pub fn turn_root(robot: &mut urdf_rs::Robot, rpy: [f64; 3]) -> Result<(), DynamicsError> {
    let children: std::collections::HashSet<&str> =
        robot.joints.iter().map(|j| j.child.link.as_str()).collect();
    let roots: Vec<String> = robot
        .links
        .iter()
        .filter(|l| !children.contains(l.name.as_str()))
        .map(|l| l.name.clone())
        .collect();
    let root = match roots.as_slice() {
        [] => return Err(DynamicsError::NoRoot),
        [r] if r == "world" => {
            return Err(DynamicsError::InvalidJoint {
                joint: UPRIGHT_BASE.into(),
                reason: "a URDF rooted at `world` cannot be turned: turn its child's joint".into(),
            });
        }
        [r] => r.clone(),
        many => return Err(DynamicsError::MultipleRoots(many.join(", "))),
    };
    if robot.links.iter().any(|l| l.name == UPRIGHT_BASE) {
        return Err(DynamicsError::DuplicateName {
            what: "link",
            name: UPRIGHT_BASE.into(),
        });
    }
    robot.links.insert(
        0,
        urdf_rs::Link {
            name: UPRIGHT_BASE.into(),
            inertial: Default::default(),
            visual: Vec::new(),
            collision: Vec::new(),
        },
    );
    robot.joints.insert(
        0,
        urdf_rs::Joint {
            name: format!("{UPRIGHT_BASE}_to_{root}"),
            joint_type: urdf_rs::JointType::Fixed,
            origin: urdf_rs::Pose {
                xyz: urdf_rs::Vec3([0.0; 3]),
                rpy: urdf_rs::Vec3(rpy),
            },
            parent: urdf_rs::LinkName {
                link: UPRIGHT_BASE.into(),
            },
            child: urdf_rs::LinkName { link: root },
            axis: Default::default(),
            limit: Default::default(),
            calibration: None,
            dynamics: None,
            mimic: None,
            safety_controller: None,
        },
    );
    Ok(())
}

/// Largest principal moment below zero (kg·m²) that a repair may remove: a gram at a
/// centimetre. Beyond it the tensor is not a rounding or export slip.
pub const REPAIR_LIMIT: f64 = 1e-6;

/// Drop `<texture/>` elements that name no file: urdf-rs requires the attribute, the URDF
/// files robots ship (iCub's) leave it out, and nothing here reads textures.
fn without_empty_textures(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.contains("<texture") {
        return text.into();
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("<texture") {
        out.push_str(&rest[..at]);
        let tail = &rest[at..];
        let end = tail.find('>').map_or(tail.len(), |e| e + 1);
        let tag = &tail[..end];
        if tag.ends_with("/>") && attribute(tag, "filename").is_none() {
            rest = &tail[end..];
        } else {
            out.push_str(tag);
            rest = &tail[end..];
        }
    }
    out.push_str(rest);
    out.into()
}

const KNOWN_TYPES: [&str; 7] = [
    "revolute",
    "continuous",
    "prismatic",
    "fixed",
    "floating",
    "planar",
    "spherical",
];

/// urdf-rs reports an unknown joint type without naming the joint: find it in the raw text.
fn diagnose(text: &str, message: &str) -> DynamicsError {
    for chunk in text.split("<joint").skip(1) {
        let tag = chunk.split('>').next().unwrap_or_default();
        let (Some(name), Some(kind)) = (attribute(tag, "name"), attribute(tag, "type")) else {
            continue;
        };
        if !KNOWN_TYPES.contains(&kind) {
            return DynamicsError::UnsupportedJointType {
                joint: name.to_owned(),
                kind: kind.to_owned(),
            };
        }
    }
    match locate(text) {
        Some(culprit) => DynamicsError::Parse(format!("{culprit} ({message})")),
        None => DynamicsError::Parse(message.to_owned()),
    }
}

/// Numeric attributes of URDF elements and how many numbers each holds.
const NUMERIC: [(&str, &[&str], usize); 14] = [
    ("mass", &["value"], 1),
    ("inertia", &["ixx", "ixy", "ixz", "iyy", "iyz", "izz"], 1),
    ("origin", &["xyz", "rpy"], 3),
    ("axis", &["xyz"], 3),
    ("limit", &["lower", "upper", "effort", "velocity"], 1),
    ("dynamics", &["damping", "friction"], 1),
    ("box", &["size"], 3),
    ("cylinder", &["radius", "length"], 1),
    ("sphere", &["radius"], 1),
    ("mesh", &["scale"], 3),
    ("color", &["rgba"], 4),
    ("mimic", &["multiplier", "offset"], 1),
    ("calibration", &["rising", "falling"], 1),
    (
        "safety_controller",
        &[
            "soft_lower_limit",
            "soft_upper_limit",
            "k_position",
            "k_velocity",
        ],
        1,
    ),
];

/// Attributes without which urdf-rs refuses an element, and the element it must sit in (`""`:
/// anywhere). A `<parent>` of a `<sensor>` or a Gazebo tag is none of urdf-rs's business.
const REQUIRED: [(&str, &str, &[&str]); 6] = [
    ("link", "robot", &["name"]),
    ("joint", "robot", &["name", "type"]),
    ("parent", "joint", &["link"]),
    ("child", "joint", &["link"]),
    ("mass", "inertial", &["value"]),
    ("mesh", "", &["filename"]),
];

/// urdf-rs's parse errors name no element: find the first one at fault in the raw text (a
/// number that does not parse, a missing required attribute, an element not closed or closed
/// by the wrong tag), described with the link or joint it belongs to.
fn locate(text: &str) -> Option<String> {
    // Open elements: (tag name, its `name` attribute).
    let mut open: Vec<OpenElement> = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find('<') {
        rest = &rest[at..];
        if let Some(n) = markup_len(rest) {
            rest = &rest[n..];
            continue;
        }
        let Some(end) = rest.find('>') else {
            let tag = rest[1..].split_whitespace().next().unwrap_or_default();
            return Some(format!(
                "element <{tag}>{} has no closing `>`",
                owner(&open)
            ));
        };
        let tag = &rest[1..end];
        rest = &rest[end + 1..];
        if let Some(closing) = tag.strip_prefix('/') {
            match close(&mut open, closing.trim()) {
                None => continue,
                fault => return fault,
            }
        }
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let name = tag.split_whitespace().next().unwrap_or_default();
        let id = attribute(tag, "name");
        let at_line = || line_of(text, rest);
        if let Some(fault) = attribute_fault(tag, (name, id), &open, at_line) {
            return Some(fault);
        }
        if !self_closing {
            open.push((name, id));
        }
    }
    open.pop().map(|(name, id)| {
        format!(
            "<{name}{}>{} is not closed",
            id.map(|i| format!(" name=\"{i}\"")).unwrap_or_default(),
            owner(&open)
        )
    })
}

/// An element being read: its tag name and its `name` attribute.
type OpenElement<'t> = (&'t str, Option<&'t str>);

/// " of link 'x'" for the innermost link or joint among the open elements ("" if none).
fn owner(open: &[OpenElement]) -> String {
    open.iter()
        .rev()
        .find_map(|(tag, name)| {
            matches!(*tag, "link" | "joint").then(|| format!(" of {tag} '{}'", name.unwrap_or("?")))
        })
        .unwrap_or_default()
}

/// The length of the comment, CDATA section, declaration or processing instruction `rest`
/// starts with (`None`: an element, or markup not closed).
fn markup_len(rest: &str) -> Option<usize> {
    let skip_to = |end: &str| rest.find(end).map(|i| i + end.len());
    if rest.starts_with("<!--") {
        skip_to("-->")
    } else if rest.starts_with("<![CDATA[") {
        skip_to("]]>")
    } else if rest.starts_with("<?") || rest.starts_with("<!") {
        skip_to(">")
    } else {
        None
    }
}

/// The closing tag `</closing>` against the innermost open element: `None` if it closes it,
/// else what is wrong.
fn close(open: &mut Vec<OpenElement>, closing: &str) -> Option<String> {
    match open.pop() {
        Some((name, _)) if name == closing => None,
        Some((name, id)) => Some(format!(
            "</{closing}> closes <{name}{}>{}",
            id.map(|i| format!(" name=\"{i}\"")).unwrap_or_default(),
            owner(open)
        )),
        None => Some(format!("</{closing}> closes no open element")),
    }
}

/// What is wrong with the attributes of the opening tag `tag` (the element `element`, inside
/// the `open` ones; at line `at_line()`): a required one missing, or a number that is not one
/// or not as many as expected.
fn attribute_fault(
    tag: &str,
    element: OpenElement,
    open: &[OpenElement],
    at_line: impl Fn() -> usize,
) -> Option<String> {
    let name = element.0;
    let mut context = open.to_vec();
    context.push(element);
    let inside = open.last().map_or("", |(t, _)| *t);
    for (required, within, attrs) in REQUIRED {
        if required == name
            && (within.is_empty() || within == inside)
            && let Some(a) = attrs.iter().find(|a| attribute(tag, a).is_none())
        {
            return Some(format!(
                "line {}: <{name}>{} lacks the attribute `{a}`",
                at_line(),
                owner(&context)
            ));
        }
    }
    for (numeric, attrs, count) in NUMERIC {
        if numeric != name {
            continue;
        }
        for a in attrs {
            let Some(v) = attribute(tag, a) else { continue };
            let numbers: Vec<&str> = v.split_whitespace().collect();
            let bad = numbers.iter().find(|x| x.parse::<f64>().is_err());
            if let Some(x) = bad {
                return Some(format!(
                    "line {}: <{name} {a}=\"{v}\">{}: `{x}` is not a number",
                    at_line(),
                    owner(&context)
                ));
            }
            if numbers.len() != count {
                return Some(format!(
                    "line {}: <{name} {a}=\"{v}\">{}: expected {count} number(s), found {}",
                    at_line(),
                    owner(&context),
                    numbers.len()
                ));
            }
        }
    }
    None
}

/// Line number (1-based) of the element that ends just before `rest` in `text`.
fn line_of(text: &str, rest: &str) -> usize {
    let consumed = text.len() - rest.len();
    let start = text[..consumed].rfind('<').unwrap_or(0);
    text[..start].matches('\n').count() + 1
}

fn attribute<'t>(tag: &'t str, key: &str) -> Option<&'t str> {
    for quote in ['"', '\''] {
        let pat = format!("{key}={quote}");
        let mut rest = tag;
        while let Some(at) = rest.find(&pat) {
            // Require a word boundary so `name` does not match inside `xname`.
            let boundary = at == 0 || rest[..at].ends_with(char::is_whitespace);
            let after = &rest[at + pat.len()..];
            if boundary {
                return after.split(quote).next();
            }
            rest = after;
        }
    }
    None
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn pose(p: &urdf_rs::Pose) -> SE3 {
    SE3::from_xyz_rpy(p.xyz.0, p.rpy.0)
}

/// Spatial inertia of a link in its own frame, after checking it is physical (repaired if
/// barely not: a note goes to `warnings`).
fn link_inertia(
    link: &urdf_rs::Link,
    warnings: &mut Vec<String>,
) -> Result<Inertia, DynamicsError> {
    let bad = |reason: String| DynamicsError::InvalidInertia {
        link: link.name.clone(),
        reason,
    };
    let inl = &link.inertial;
    let m = inl.mass.value;
    if !m.is_finite() || m < 0.0 {
        return Err(bad(format!("mass {m} is not a finite non-negative number")));
    }
    if !finite3(&inl.origin.xyz.0) || !finite3(&inl.origin.rpy.0) {
        return Err(bad("inertial origin is not finite".into()));
    }
    let i = &inl.inertia;
    let vals = [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
    if vals.iter().any(|x| !x.is_finite()) {
        return Err(bad(format!(
            "inertia tensor has a non-finite entry {vals:?}"
        )));
    }
    let mut tensor = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    let eig = SymmetricEigen::new(tensor);
    let min = eig.eigenvalues.min();
    if min < 0.0 {
        if -min > REPAIR_LIMIT {
            return Err(bad(format!(
                "inertia tensor is not positive definite, by more than a repair may change \
                 ({REPAIR_LIMIT:e} kg·m²): eigenvalues {:.3e}, {:.3e}, {:.3e}",
                eig.eigenvalues[0], eig.eigenvalues[1], eig.eigenvalues[2]
            )));
        }
        // The nearest positive semi-definite tensor (Frobenius): negative moments to zero.
        let clamped = eig.eigenvalues.map(|x| x.max(0.0));
        tensor = eig.eigenvectors * Matrix3::from_diagonal(&clamped) * eig.eigenvectors.transpose();
        warnings.push(format!(
            "link '{}': inertia tensor repaired to positive semi-definite, principal moments \
             {:.3e}, {:.3e}, {:.3e} → {:.3e}, {:.3e}, {:.3e} (largest change {:.1e} kg·m²)",
            link.name,
            eig.eigenvalues[0],
            eig.eigenvalues[1],
            eig.eigenvalues[2],
            clamped[0],
            clamped[1],
            clamped[2],
            -min
        ));
    }
    let origin = pose(&inl.origin);
    let inertia_com = origin.rot * tensor * origin.rot.transpose();
    Ok(Inertia::from_com(m, origin.trans, inertia_com))
}

fn joint_kind(j: &urdf_rs::Joint) -> Result<Option<(JointKind, JointLimits)>, DynamicsError> {
    use urdf_rs::JointType as T;
    let invalid = |reason: String| DynamicsError::InvalidJoint {
        joint: j.name.clone(),
        reason,
    };
    if !finite3(&j.origin.xyz.0) || !finite3(&j.origin.rpy.0) {
        return Err(invalid("origin is not finite".into()));
    }
    let axis = Vector3::from(j.axis.xyz.0);
    let unit_axis = || {
        let n = axis.norm();
        if n.is_finite() && n > 1e-12 {
            Ok(axis / n)
        } else {
            Err(invalid(format!(
                "axis {:?} is not a non-zero finite vector",
                j.axis.xyz.0
            )))
        }
    };
    let l = &j.limit;
    let unbounded_if_zero = |x: f64| if x > 0.0 { x } else { f64::INFINITY };
    let mut limits = JointLimits {
        lower: l.lower,
        upper: l.upper,
        velocity: unbounded_if_zero(l.velocity),
        effort: unbounded_if_zero(l.effort),
    };
    if limits.lower.is_nan() || limits.upper.is_nan() || limits.lower > limits.upper {
        return Err(invalid(format!(
            "position limits [{}, {}] are not an interval",
            l.lower, l.upper
        )));
    }
    let kind = match j.joint_type {
        T::Fixed => return Ok(None),
        T::Revolute => JointKind::Revolute { axis: unit_axis()? },
        T::Continuous => {
            limits.lower = f64::NEG_INFINITY;
            limits.upper = f64::INFINITY;
            JointKind::Revolute { axis: unit_axis()? }
        }
        T::Prismatic => JointKind::Prismatic { axis: unit_axis()? },
        T::Floating | T::Planar | T::Spherical => {
            return Err(DynamicsError::UnsupportedJointType {
                joint: j.name.clone(),
                kind: format!("{:?}", j.joint_type).to_lowercase(),
            });
        }
    };
    Ok(Some((kind, limits)))
}

fn build(
    robot: &urdf_rs::Robot,
    base: BaseJoint,
    locked: &HashMap<String, f64>,
) -> Result<Model, DynamicsError> {
    if robot.links.is_empty() {
        return Err(DynamicsError::Empty);
    }
    let link_index = link_indices(robot)?;
    let mut warnings = Vec::new();
    let inertias = robot
        .links
        .iter()
        .map(|l| link_inertia(l, &mut warnings))
        .collect::<Result<Vec<_>, _>>()?;
    warnings.extend(mimic_warnings(robot, locked));
    let tree = Tree::of(robot, &link_index)?;
    let root = tree.root(robot)?;

    let mut model = Model::new(robot.name.clone());
    model.load_warnings = warnings;
    let root_name = robot.links[root].name.as_str();
    let floating = match base {
        BaseJoint::Auto => root_name != "world",
        BaseJoint::Floating => true,
        BaseJoint::Fixed => false,
    };
    // A `world` root with one child: that child is the robot's real root.
    let mut start = root;
    if floating && root_name == "world" && tree.children[root].len() == 1 {
        start = link_index[robot.joints[tree.children[root][0]].child.link.as_str()];
    }
    let walk = Walk {
        robot,
        tree: &tree,
        link_index: &link_index,
        inertias: &inertias,
        locked,
        floating,
    };
    let visited = walk.run(&mut model, start)?;
    // Links never reached hang on a cycle (each link has at most one parent joint).
    if let Some(k) = (0..robot.links.len()).find(|&k| !visited[k] && k != root) {
        return Err(DynamicsError::Cycle {
            link: robot.links[k].name.clone(),
        });
    }
    Ok(model)
}

/// Each link's index by name; a name given twice is an error.
fn link_indices(robot: &urdf_rs::Robot) -> Result<HashMap<&str, usize>, DynamicsError> {
    let mut link_index: HashMap<&str, usize> = HashMap::new();
    for (k, l) in robot.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), k).is_some() {
            return Err(DynamicsError::DuplicateName {
                what: "link",
                name: l.name.clone(),
            });
        }
    }
    Ok(link_index)
}

/// A load warning for each mimic joint not locked: it is taken as an independent joint.
fn mimic_warnings(robot: &urdf_rs::Robot, locked: &HashMap<String, f64>) -> Vec<String> {
    robot
        .joints
        .iter()
        .filter_map(|j| {
            let m = j.mimic.as_ref().filter(|_| !locked.contains_key(&j.name))?;
            Some(format!(
                "joint '{}' mimics '{}': taken as an independent joint (as Pinocchio does by default)",
                j.name, m.joint
            ))
        })
        .collect()
}

/// The links' tree as the joints draw it (indices into the URDF's lists).
struct Tree {
    /// Parent joint of each link.
    parent_joint: Vec<Option<usize>>,
    /// Child joints of each link, in listing order.
    children: Vec<Vec<usize>>,
}

impl Tree {
    /// The tree of `robot`'s joints; a joint name given twice, a link missing, a link with two
    /// parents or its own parent is an error.
    fn of(
        robot: &urdf_rs::Robot,
        link_index: &HashMap<&str, usize>,
    ) -> Result<Tree, DynamicsError> {
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        let mut joint_names: HashMap<&str, ()> = HashMap::new();
        for (k, j) in robot.joints.iter().enumerate() {
            if joint_names.insert(j.name.as_str(), ()).is_some() {
                return Err(DynamicsError::DuplicateName {
                    what: "joint",
                    name: j.name.clone(),
                });
            }
            let find = |role: &'static str, name: &str| {
                link_index
                    .get(name)
                    .copied()
                    .ok_or_else(|| DynamicsError::MissingLink {
                        joint: j.name.clone(),
                        role,
                        link: name.to_owned(),
                    })
            };
            let p = find("parent", &j.parent.link)?;
            let c = find("child", &j.child.link)?;
            if let Some(first) = parent_joint[c] {
                return Err(DynamicsError::MultipleParents {
                    link: j.child.link.clone(),
                    first: robot.joints[first].name.clone(),
                    second: j.name.clone(),
                });
            }
            if p == c {
                return Err(DynamicsError::Cycle {
                    link: j.child.link.clone(),
                });
            }
            parent_joint[c] = Some(k);
            children[p].push(k);
        }
        Ok(Tree {
            parent_joint,
            children,
        })
    }

    /// The one link without a parent joint.
    fn root(&self, robot: &urdf_rs::Robot) -> Result<usize, DynamicsError> {
        let roots: Vec<usize> = (0..robot.links.len())
            .filter(|&k| self.parent_joint[k].is_none())
            .collect();
        match roots.as_slice() {
            [] => Err(DynamicsError::NoRoot),
            [r] => Ok(*r),
            many => {
                let names: Vec<&str> = many.iter().map(|&k| robot.links[k].name.as_str()).collect();
                Err(DynamicsError::MultipleRoots(names.join(", ")))
            }
        }
    }
}

/// The walk down the tree that adds the model's joints, bodies and frames.
struct Walk<'a> {
    robot: &'a urdf_rs::Robot,
    tree: &'a Tree,
    link_index: &'a HashMap<&'a str, usize>,
    inertias: &'a [Inertia],
    locked: &'a HashMap<String, f64>,
    floating: bool,
}

impl Walk<'_> {
    /// Depth-first from `start`, preorder, children in listing order, so each sub-tree gets
    /// contiguous joint indices (legs, arms… stay together in q). Returns the links visited;
    /// a link reached twice is a cycle.
    fn run(&self, model: &mut Model, start: usize) -> Result<Vec<bool>, DynamicsError> {
        let robot = self.robot;
        let mut visited = vec![false; robot.links.len()];
        // Stack items: (link, URDF joint reaching it, carrying body of its parent, link
        // placement in that body).
        let mut stack: Vec<(usize, Option<usize>, Option<usize>, SE3)> =
            vec![(start, None, None, SE3::identity())];
        while let Some((link, via, parent_body, x)) = stack.pop() {
            if visited[link] {
                return Err(DynamicsError::Cycle {
                    link: robot.links[link].name.clone(),
                });
            }
            visited[link] = true;
            let (body, link_in_body) = match via {
                None => self.add_root(model, link)?,
                Some(k) => self.add_joint(model, link, k, parent_body, x)?,
            };
            for &k in self.tree.children[link].iter().rev() {
                let j = &robot.joints[k];
                let child = self.link_index[j.child.link.as_str()];
                stack.push((child, Some(k), body, link_in_body.compose(&pose(&j.origin))));
            }
        }
        Ok(visited)
    }

    /// The root link: on a free-flyer, or a frame of the world. Returns the body carrying it
    /// and its placement in that body.
    fn add_root(
        &self,
        model: &mut Model,
        link: usize,
    ) -> Result<(Option<usize>, SE3), DynamicsError> {
        let name = self.robot.links[link].name.clone();
        if self.floating {
            let id = model.add_joint(
                ROOT_JOINT_NAME,
                None,
                SE3::identity(),
                JointKind::FreeFlyer,
                self.inertias[link],
                name,
            )?;
            Ok((Some(id), SE3::identity()))
        } else {
            model.add_frame(name, None, SE3::identity())?;
            Ok((None, SE3::identity()))
        }
    }

    /// `link`, reached by URDF joint `k` at placement `x` in `parent_body`: a moving joint and
    /// its body, or (fixed, or locked at its value) merged into the parent body. Returns the
    /// body carrying the link and its placement in that body.
    fn add_joint(
        &self,
        model: &mut Model,
        link: usize,
        k: usize,
        parent_body: Option<usize>,
        x: SE3,
    ) -> Result<(Option<usize>, SE3), DynamicsError> {
        let name = self.robot.links[link].name.clone();
        let j = &self.robot.joints[k];
        let mut kind = joint_kind(j)?;
        let mut x = x;
        if let (Some((k, limits)), Some(&value)) = (&kind, self.locked.get(&j.name)) {
            if k.nq() != 1 || !(limits.lower..=limits.upper).contains(&value) {
                return Err(DynamicsError::InvalidJoint {
                    joint: j.name.clone(),
                    reason: format!(
                        "locked at {value}, outside its limits [{}, {}]",
                        limits.lower, limits.upper
                    ),
                });
            }
            // Locked: a fixed joint at the placement the value gives.
            x = x.compose(&k.transform(&[value]));
            kind = None;
        }
        match kind {
            Some((kind, limits)) => {
                let id = model.add_joint(
                    j.name.clone(),
                    parent_body,
                    x,
                    kind,
                    self.inertias[link],
                    name,
                )?;
                model.set_limits(id, limits);
                Ok((Some(id), SE3::identity()))
            }
            None => {
                // Fixed joint: merge into the parent body (Pinocchio-style).
                if let Some(b) = parent_body {
                    let merged = x.act_inertia(&self.inertias[link]);
                    model.joints[b].inertia += merged;
                }
                model.add_frame(name, parent_body, x)?;
                Ok((parent_body, x))
            }
        }
    }
}
