//! Robots: a description ([`RobotDescription`], `config/robots/<name>.toml`) resolved into the
//! model with its sole and contact frames, the home configuration, and what follows from them
//! (mass, CoM height, support, M_e): values the simulator and the controller take from here, never
//! config keys.
//! The iCub-like humanoid is the embedded default; the others name a registry package.

mod collada;
mod config_layers;
pub mod description;
pub mod feet;
pub mod init;
pub mod packages;
pub mod physical;
mod reduced_model;
pub mod sole_mesh;
pub mod stance;
mod state;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{DVector, Matrix3, Vector3};

pub use description::{FootSensors, RobotDescription, SensorSpec};
pub use feet::{CORNERS, N_CONTACTS};
pub use reduced_model::ReducedModel;
pub use state::{RobotState, SensorStamps};

use crate::config::{ConfigError, Layers};
use crate::dynamics::{
    BaseJoint, Data, DynamicsError, Model, OpSpaceWorkspace, center_of_mass, forward_kinematics,
};
use crate::scenario::{ContentHash, Scenario};

/// The robot every process uses without `--robot`.
pub const DEFAULT: &str = "icub_like";

/// The descriptions shipped with upc (name, TOML): usable from any directory. Their URDFs are
/// embedded (the iCub-like) or come from a registry package (`scripts/setup.sh`).
pub const EMBEDDED: [(&str, &str); 7] = [
    (
        "icub_like",
        include_str!("../../config/robots/icub_like.toml"),
    ),
    ("icub", include_str!("../../config/robots/icub.toml")),
    ("talos", include_str!("../../config/robots/talos.toml")),
    ("g1", include_str!("../../config/robots/g1.toml")),
    ("romeo", include_str!("../../config/robots/romeo.toml")),
    (
        "romeo_locked",
        include_str!("../../config/robots/romeo_locked.toml"),
    ),
    (
        "icub_like_joint_torques",
        include_str!("../../config/robots/icub_like_joint_torques.toml"),
    ),
];

/// Files the embedded descriptions name, embedded with them.
const EMBEDDED_FILES: [(&str, &str); 1] = [(
    crate::dynamics::icub_like::URDF_PATH,
    crate::dynamics::icub_like::URDF,
)];

#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    #[error(
        "no robot named `{0}`: give a path to a .toml description, or one of: icub_like, icub, talos, g1, romeo, romeo_locked"
    )]
    Unknown(String),
    #[error("robot description {path} cannot be read: {reason}")]
    Read { path: String, reason: String },
    #[error(transparent)]
    Description(#[from] ConfigError),
    #[error("robot `{robot}`: its URDF: {reason}")]
    Urdf { robot: String, reason: String },
    #[error("feet: {0}")]
    Feet(String),
    #[error("{0}")]
    Dynamics(#[from] DynamicsError),
    #[error("robot `{robot}`: {reason}")]
    Home { robot: String, reason: String },
    #[error(
        "robot `{robot}`: the joints {joints} move no mass (every link they carry is massless in the URDF), so the mass matrix M(q) is singular: give them a rotor inertia under [armature] (e.g. \"{first}\" = 1e-3) or lock them under [locked] (joints = [\"{first}\"])"
    )]
    InertJoints {
        robot: String,
        joints: String,
        first: String,
    },
    #[error(
        "robot `{robot}`: link '{link}' has principal moments of inertia {moments} kg·m² about its CoM, which break the triangle inequality A + B ≥ C that every real body satisfies (MuJoCo refuses it too): correct the link's <inertia> in the URDF"
    )]
    Inertia {
        robot: String,
        link: String,
        moments: String,
    },
    #[error(
        "robot `{robot}`: link '{link}' has a mass of {mass} kg but principal moments of inertia {moments} kg·m² about its CoM: a point mass, which MuJoCo refuses (inertia must have positive eigenvalues): give it an <inertia> in the URDF, or set inertia_floor = 1e-6 (kg·m², top level of the description) to give such bodies that moment"
    )]
    PointMass {
        robot: String,
        link: String,
        mass: f64,
        moments: String,
    },
}

/// What follows from the model at the home configuration (nothing here is typed by hand).
#[derive(Debug, Clone, Copy)]
pub struct Derived {
    /// Total mass M (kg).
    pub mass: f64,
    /// CoM height above the contact points (m).
    pub com_height: f64,
    /// CoM ground projection relative to the feet centre (m).
    pub com_offset: [f64; 2],
    /// Axis-aligned bounds of the eight contact points about the feet centre,
    /// [[x_min, x_max], [y_min, y_max]] (m).
    pub support: [[f64; 2]; 2],
    /// Operational-space inertia of the chain root → hand (kg).
    pub effective_mass: Matrix3<f64>,
    /// Hand position in the feet frame (origin: feet centre on the ground).
    pub hand_position: Vector3<f64>,
    /// Largest push along the world x axis (N, either sign) the arm holds at home within its
    /// joints' effort limits: min over the chain joints of τ_max / |J_eᵀ x̂|.
    pub hand_force_capacity: f64,
    /// Largest angle between a sole's normal and the vertical (rad).
    pub sole_tilt: f64,
    /// Sole centres' distance (m).
    pub feet_distance: f64,
}

/// The frames the whole-body QP's contacts and hand task act on, named by the robot's description
/// ([`Robot::frames`]), not by the config.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BodyFrames {
    /// Sole frames of the two feet; the contact points are the frames `<foot>_fl`, `_fr`, `_rl`,
    /// `_rr` (the sole corners, [`CORNERS`]), the contact normal is the sole frame's z axis.
    pub feet: [String; 2],
    /// Frame of the hand impedance task.
    pub hand: String,
    /// The body the hand's arm chain starts from (M_e of the chain root → hand,
    /// docs/hand_previewer.md, eq. (21)–(23)).
    pub hand_chain_root: String,
}

/// A resolved robot: immutable after loading.
#[derive(Debug, Clone)]
pub struct Robot {
    pub description: RobotDescription,
    /// Where the description came from.
    pub origin: String,
    /// The URDF text and, when it is a file, its path (the recorder reads its geometry).
    pub urdf: String,
    pub urdf_path: Option<PathBuf>,
    /// The model with the sole and contact frames added.
    pub model: Model,
    /// Left and right sole frames.
    pub soles: [String; 2],
    /// The eight contact frames, in the channel contract's order (left fl, fr, rl, rr, right …).
    pub contacts: [String; 8],
    /// Home configuration: [`RobotDescription::home`], the contact points on z = 0 centred on
    /// the origin.
    pub home: DVector<f64>,
    pub derived: Derived,
    /// The joints the description locks and their values (rad or m), by name.
    pub locked: std::collections::BTreeMap<String, f64>,
    /// The IMU's frame in [`Robot::model`]; `None`: on the base, aligned with it.
    pub imu_frame: Option<usize>,
    /// Content hash of the description and the URDF: plant and controller must agree on it.
    pub hash: u64,
}

impl Robot {
    /// The embedded default robot (the iCub-like humanoid).
    pub fn embedded_default() -> Result<Robot, RobotError> {
        Self::load(DEFAULT)
    }

    /// Load by embedded name (`icub_like`, `icub`, `talos`, `g1`) or path to a description.
    pub fn load(name_or_path: &str) -> Result<Robot, RobotError> {
        if let Some((name, text)) = EMBEDDED.iter().find(|(n, _)| *n == name_or_path) {
            return Self::parse(text, &format!("<embedded robot {name}>"), None);
        }
        let path = Path::new(name_or_path);
        if !path.exists() && !name_or_path.ends_with(".toml") && !name_or_path.contains('/') {
            return Err(RobotError::Unknown(name_or_path.into()));
        }
        let text = std::fs::read_to_string(path).map_err(|e| RobotError::Read {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::parse(&text, &path.display().to_string(), path.parent())
    }

    /// Parse a description; a relative URDF path resolves against `dir` (the description's
    /// directory), then the repository root.
    pub fn parse(text: &str, origin: &str, dir: Option<&Path>) -> Result<Robot, RobotError> {
        let mut layers = Layers::new();
        let mut hashed = String::new();
        // `extends`: the base description (embedded name or path, relative to this file's
        // directory) is the layer under this one.
        if let Some(base) = text
            .parse::<toml::Table>()
            .ok()
            .and_then(|t| t.get("extends").and_then(|v| v.as_str().map(String::from)))
        {
            // A file next to this one first; else an embedded description of that name.
            let path = dir.map_or_else(|| PathBuf::from(&base), |d| d.join(&base));
            let stem = base.strip_suffix(".toml").unwrap_or(&base);
            let embedded = EMBEDDED.iter().find(|(n, _)| *n == stem);
            let (base_origin, base_text) = match embedded {
                Some((n, t)) if !path.is_file() => (format!("<embedded robot {n}>"), t.to_string()),
                _ => {
                    let t = std::fs::read_to_string(&path).map_err(|e| RobotError::Read {
                        path: path.display().to_string(),
                        reason: e.to_string(),
                    })?;
                    (path.display().to_string(), t)
                }
            };
            layers.push_str(&base_origin, &base_text)?;
            hashed.push_str(&base_text);
        }
        layers.push_str(origin, text)?;
        hashed.push_str(text);
        let description: RobotDescription = layers.typed()?;
        let name = description.name.clone();
        let urdf_err = |reason: String| RobotError::Urdf {
            robot: name.clone(),
            reason,
        };
        let (urdf, urdf_path) = read_urdf(&description, dir).map_err(urdf_err)?;
        let mut parsed = crate::dynamics::parse_urdf(&urdf)?;
        if let Some(rpy) = description.urdf.root_rpy {
            crate::dynamics::turn_root(&mut parsed, rpy)?;
        }
        let locked = locked_joints(&description, &parsed)?;
        let mut model = Model::from_urdf_robot_locked(&parsed, BaseJoint::Floating, &locked)?;
        set_armatures(&mut model, &description, &locked)?;
        if let Some(floor) = description.inertia_floor {
            if !(floor.is_finite() && floor > 0.0) {
                return Err(RobotError::Home {
                    robot: name.clone(),
                    reason: format!("inertia_floor must be a positive kg·m², got {floor}"),
                });
            }
            physical::apply_inertia_floor(&mut model, floor);
        }
        physical::check_inertias(&model, &description.name)?;
        physical::check_inert_joints(&model, &description.name)?;
        for w in physical::placeholder_warnings(&model) {
            tracing::warn!("robot `{}`: {w}", description.name);
        }
        let f = &description.feet;
        let urdf_dir = urdf_path.as_deref().and_then(std::path::Path::parent);
        let left = feet::attach(&mut model, &parsed, urdf_dir, &f.left)?;
        let right = feet::attach(&mut model, &parsed, urdf_dir, &f.right)?;
        let contacts: [String; 8] = std::array::from_fn(|k| {
            if k < 4 {
                left[k].clone()
            } else {
                right[k - 4].clone()
            }
        });
        let soles = [f.left.frame.clone(), f.right.frame.clone()];
        let home = home_configuration(&model, &description, &locked, &soles, &contacts)?;
        let derived = derive(&model, &description, &soles, &contacts, &home)?;
        let imu_frame = match &description.imu {
            Some(imu) => Some(model.frame_id(&imu.frame).map_err(|_| RobotError::Urdf {
                robot: description.name.clone(),
                reason: format!(
                    "the IMU's frame `{}` ([imu] frame) is not in the URDF: name one of its links or frames",
                    imu.frame
                ),
            })?),
            None => None,
        };
        let mut h = ContentHash::default();
        h.bytes(hashed.as_bytes());
        h.bytes(urdf.as_bytes());
        Ok(Robot {
            hash: h.finish(),
            origin: origin.into(),
            urdf,
            urdf_path,
            model,
            soles,
            contacts,
            home,
            derived,
            locked: locked.into_iter().collect(),
            imu_frame,
            description,
        })
    }

    /// The frames whose supporting joints carry the body: the soles (legs) and the arm chain's
    /// root (torso).
    pub fn carrying_frames(&self) -> Vec<usize> {
        self.soles
            .iter()
            .chain(std::iter::once(&self.description.hand.chain_root))
            .filter_map(|f| self.model.frame_id(f).ok())
            .collect()
    }

    pub fn name(&self) -> &str {
        &self.description.name
    }

    /// What the reduced models take from this robot ([`ReducedModel`]): computed from its
    /// model at home, never a config key.
    pub fn reduced(&self) -> ReducedModel {
        let d = &self.derived;
        ReducedModel {
            mass: d.mass,
            com_height: d.com_height,
            support: d.support,
            effective_mass: d.effective_mass,
            hand_position: d.hand_position,
        }
    }

    /// The frames the whole-body QP's contacts and hand task act on.
    pub fn frames(&self) -> BodyFrames {
        BodyFrames {
            feet: self.soles.clone(),
            hand: self.description.hand.frame.clone(),
            hand_chain_root: self.description.hand.chain_root.clone(),
        }
    }

    /// The config layer of this robot: its description's `[config]` table (layered over
    /// `config/default.toml`), settings tuned for it. What follows from its model is no layer:
    /// [`Robot::reduced`], [`Robot::frames`].
    pub fn config_layers(&self) -> Vec<(String, toml::Table)> {
        let c = self.description.config.as_ref();
        c.map(|c| (format!("{} [config]", self.origin), c.clone()))
            .into_iter()
            .collect()
    }

    /// Push [`Robot::config_layers`] onto `layers`.
    pub fn push_config(&self, layers: &mut Layers) {
        for (origin, table) in self.config_layers() {
            layers.push_table(&origin, table);
        }
    }

    /// Factor applied to the scenarios' forces on this robot (they were written for the
    /// embedded default): its mass over the default's, so that a push moves the CoM about as
    /// much on every robot, but no more than its arm's force capacity over the default's
    /// ([`Derived::hand_force_capacity`]), so that the arm holds the door as the default's does.
    /// 1 on the default robot (each ratio is a value over itself), and computed for any other,
    /// whatever its name.
    pub fn force_scale(&self) -> Result<f64, RobotError> {
        let (mass, capacity) = reference()?;
        Ok((self.derived.mass / mass).min(self.derived.hand_force_capacity / capacity))
    }

    /// The scenario `name_or_path` ([`Scenario::load`]) as this robot is pushed: its forces ×
    /// [`Self::force_scale`]. Every plant, process and report takes a scenario through here, so
    /// that none announces or forecasts the forces unscaled.
    pub fn scenario(&self, name_or_path: &str) -> Result<Scenario, RobotScenarioError> {
        let scale = self.force_scale()?;
        Ok(Scenario::load(name_or_path)?.with_force_scale(scale))
    }
}

/// Why [`Robot::scenario`] has no scenario.
#[derive(Debug, thiserror::Error)]
pub enum RobotScenarioError {
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    #[error(transparent)]
    Robot(#[from] RobotError),
}

/// Mass (kg) and arm force capacity (N) of the embedded default robot, computed once.
pub fn reference() -> Result<(f64, f64), RobotError> {
    static REF: std::sync::OnceLock<(f64, f64)> = std::sync::OnceLock::new();
    if let Some(r) = REF.get() {
        return Ok(*r);
    }
    let d = Robot::embedded_default()?.derived;
    Ok(*REF.get_or_init(|| (d.mass, d.hand_force_capacity)))
}

fn read_urdf(
    d: &RobotDescription,
    dir: Option<&Path>,
) -> Result<(String, Option<PathBuf>), String> {
    let rel = &d.urdf.path;
    let candidates: Vec<PathBuf> = match &d.urdf.package {
        Some(p) => vec![packages::package_root(p)?.join(rel)],
        None if rel.is_absolute() => vec![rel.clone()],
        None => {
            let mut c: Vec<PathBuf> = dir.map(|d| d.join(rel)).into_iter().collect();
            c.push(Path::new(env!("CARGO_MANIFEST_DIR")).join(rel));
            c
        }
    };
    if let Some(p) = candidates.iter().find(|p| p.is_file()) {
        let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
        return Ok((text, Some(p.clone())));
    }
    if d.urdf.package.is_none()
        && let Some((_, text)) = EMBEDDED_FILES.iter().find(|(p, _)| Path::new(p) == rel)
    {
        return Ok((text.to_string(), None));
    }
    Err(format!(
        "no file {} (looked in: {})",
        rel.display(),
        candidates
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    ))
}

/// The moving joints of the URDF that `[locked]` names, with their home values. A pattern that
/// matches no moving joint is an error (a typo would otherwise lock nothing, silently).
fn locked_joints(
    d: &RobotDescription,
    urdf: &urdf_rs::Robot,
) -> Result<HashMap<String, f64>, RobotError> {
    use urdf_rs::JointType as T;
    let err = |reason: String| RobotError::Home {
        robot: d.name.clone(),
        reason,
    };
    let mut locked = HashMap::new();
    for p in &d.locked.joints {
        let pattern =
            glob::Pattern::new(p).map_err(|e| err(format!("[locked] pattern `{p}`: {e}")))?;
        let mut matched = false;
        for j in &urdf.joints {
            let moving = matches!(j.joint_type, T::Revolute | T::Continuous | T::Prismatic);
            if moving && pattern.matches(&j.name) {
                matched = true;
                let value = d.home.get(&j.name).copied().unwrap_or(0.0);
                locked.insert(j.name.clone(), value);
            }
        }
        if !matched {
            return Err(err(format!(
                "[locked] `{p}` matches no revolute, continuous or prismatic joint of the URDF"
            )));
        }
    }
    Ok(locked)
}

/// `[armature]`: each pattern sets the joints it matches (a later pattern wins); one that
/// matches neither a one-dof joint of the model nor a locked joint is an error.
fn set_armatures(
    model: &mut Model,
    d: &RobotDescription,
    locked: &HashMap<String, f64>,
) -> Result<(), RobotError> {
    let err = |reason: String| RobotError::Home {
        robot: d.name.clone(),
        reason,
    };
    for (p, &value) in &d.armature {
        let pattern =
            glob::Pattern::new(p).map_err(|e| err(format!("[armature] pattern `{p}`: {e}")))?;
        let ids: Vec<usize> = (0..model.joints.len())
            .filter(|&i| model.joints[i].nv() == 1 && pattern.matches(&model.joints[i].name))
            .collect();
        if ids.is_empty() && !locked.keys().any(|n| pattern.matches(n)) {
            return Err(err(format!(
                "[armature] `{p}` matches no revolute, continuous or prismatic joint"
            )));
        }
        for i in ids {
            model.set_armature(i, value)?;
        }
    }
    Ok(())
}

/// The description's joint angles, the base turned so that the soles' x axes (toes) point
/// along world +x (iCub's root link, for one, faces −x) and placed so that the contact points'
/// centroid is at the origin (their mean height 0).
fn home_configuration(
    model: &Model,
    d: &RobotDescription,
    locked: &HashMap<String, f64>,
    soles: &[String; 2],
    contacts: &[String; 8],
) -> Result<DVector<f64>, RobotError> {
    let values: Vec<(&str, f64)> = d
        .home
        .iter()
        .filter(|(k, _)| !locked.contains_key(*k))
        .map(|(k, v)| (k.as_str(), *v))
        .collect();
    let mut q = model.configuration(&values)?;
    if let Some(spec) = &d.stance {
        let err = |reason: String| RobotError::Home {
            robot: d.name.clone(),
            reason,
        };
        let ids = [model.frame_id(&soles[0])?, model.frame_id(&soles[1])?];
        let hand = [
            model.frame_id(&d.hand.frame)?,
            model.frame_id(&d.hand.chain_root)?,
        ];
        let support: Vec<usize> = contacts
            .iter()
            .map(|c| model.frame_id(c))
            .collect::<Result<_, _>>()?;
        let solved = stance::solve(model, &q, ids, &support, hand, spec).map_err(err)?;
        if solved.hand_error > 0.01 {
            tracing::warn!(
                "robot `{}`: [stance] hand target missed by {:.0} mm (out of the arm's reach, \
                 or it would move the CoM or the soles)",
                d.name,
                solved.hand_error * 1e3
            );
        }
        q = solved.q;
    }
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &q)?;
    let mut toes = Vector3::zeros();
    for s in soles {
        toes += data.o_m_f[model.frame_id(s)?].rot * Vector3::x();
    }
    let yaw = toes.y.atan2(toes.x);
    if yaw.abs() > 1e-9 {
        // The base is at the identity here: turn it by −yaw about the vertical.
        let turn = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -yaw);
        let p = turn * Vector3::new(q[0], q[1], q[2]);
        let c = turn.coords;
        for k in 0..3 {
            q[k] = p[k];
        }
        q[3] = c.x;
        q[4] = c.y;
        q[5] = c.z;
        q[6] = c.w;
        forward_kinematics(model, &mut data, &q)?;
    }
    let mut c = Vector3::zeros();
    for n in contacts {
        c += data.o_m_f[model.frame_id(n)?].trans;
    }
    c /= 8.0;
    for a in 0..3 {
        q[a] -= c[a];
    }
    Ok(q)
}

fn derive(
    model: &Model,
    d: &RobotDescription,
    soles: &[String; 2],
    contacts: &[String; 8],
    home: &DVector<f64>,
) -> Result<Derived, RobotError> {
    let home_err = |reason: String| RobotError::Home {
        robot: d.name.clone(),
        reason,
    };
    let mut data = Data::new(model);
    let com = center_of_mass(model, &mut data, home)?;
    forward_kinematics(model, &mut data, home)?;
    let (support, heights) = contact_box(model, &data, contacts)?;
    let feet = FeetAtHome::of(model, &data, soles, contacts)?;
    feet.check_level(soles, heights).map_err(home_err)?;
    if !(support[0][0] < com.x
        && com.x < support[0][1]
        && support[1][0] < com.y
        && com.y < support[1][1])
    {
        return Err(home_err(format!(
            "the CoM at home ({:.3}, {:.3}) is outside the support [{:.3}, {:.3}] × [{:.3}, {:.3}]",
            com.x, com.y, support[0][0], support[0][1], support[1][0], support[1][1]
        )));
    }
    let hand_position = data.o_m_f[model.frame_id(&d.hand.frame)?].trans;
    let mut op = OpSpaceWorkspace::new(model, &d.hand.chain_root, &d.hand.frame)?;
    let effective_mass = *op.compute(model, &mut data, home)?;
    Ok(Derived {
        mass: model.total_mass(),
        com_height: com.z,
        com_offset: [com.x, com.y],
        support,
        effective_mass,
        hand_position,
        hand_force_capacity: hand_force_capacity(model, &op),
        sole_tilt: feet.tilt,
        feet_distance: (feet.centres[0] - feet.centres[1]).norm(),
    })
}

/// The contact points' box at the placements of `data`: the support rectangle
/// [[x_min, x_max], [y_min, y_max]], and the lowest and highest points' heights.
fn contact_box(
    model: &Model,
    data: &Data,
    contacts: &[String; 8],
) -> Result<([[f64; 2]; 2], [f64; 2]), RobotError> {
    let mut support = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
    let (mut zmin, mut zmax) = (f64::INFINITY, f64::NEG_INFINITY);
    for n in contacts {
        let p = data.o_m_f[model.frame_id(n)?].trans;
        for a in 0..2 {
            support[a] = [support[a][0].min(p[a]), support[a][1].max(p[a])];
        }
        zmin = zmin.min(p.z);
        zmax = zmax.max(p.z);
    }
    Ok((support, [zmin, zmax]))
}

/// The feet at home.
struct FeetAtHome {
    /// The soles' largest tilt from level (rad), and which sole it is with its rotation.
    tilt: f64,
    worst: (usize, Matrix3<f64>),
    /// Each foot's contact points' centroid.
    centres: [Vector3<f64>; 2],
}

impl FeetAtHome {
    fn of(
        model: &Model,
        data: &Data,
        soles: &[String; 2],
        contacts: &[String; 8],
    ) -> Result<FeetAtHome, RobotError> {
        let mut tilt: f64 = 0.0;
        let mut worst = (0, Matrix3::identity());
        let mut centres = [Vector3::zeros(); 2];
        for (k, s) in soles.iter().enumerate() {
            let m = data.o_m_f[model.frame_id(s)?];
            let t = (m.rot * Vector3::z()).z.clamp(-1.0, 1.0).acos();
            if t > tilt {
                (tilt, worst) = (t, (k, m.rot));
            }
            for c in &contacts[4 * k..4 * k + 4] {
                centres[k] += data.o_m_f[model.frame_id(c)?].trans / 4.0;
            }
        }
        Ok(FeetAtHome {
            tilt,
            worst,
            centres,
        })
    }

    /// Why the robot does not stand flat at home, if it does not: a sole frame whose axes are
    /// not the sole's, or soles tilted or at different heights (`heights`: the lowest and the
    /// highest contact point's).
    fn check_level(&self, soles: &[String; 2], [zmin, zmax]: [f64; 2]) -> Result<(), String> {
        let tilt = self.tilt;
        // A sole frame far from level is a frame whose axes are not the sole's (a made frame
        // takes its link's axes, and an ankle link's z may point forward): no posture fixes
        // that.
        if tilt > 45f64.to_radians() {
            let (k, rot) = self.worst;
            let side = if k == 0 { "left" } else { "right" };
            // The rotation about the sole frame's own axes that brings its z up: from z to the
            // world's vertical as seen in that frame.
            let up = rot.transpose() * Vector3::z();
            let fix =
                nalgebra::Rotation3::rotation_between(&Vector3::z(), &up).unwrap_or_else(|| {
                    nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
                });
            let (r, p, y) = fix.euler_angles();
            return Err(format!(
                "the sole frame `{}` points its z axis {:.1}° away from the vertical at home: its \
                 axes are not the sole's (z out of the sole, x toward the toes), which no [home] \
                 posture changes. A sole frame upc makes takes its link's axes: turn it with \
                 [feet.{side}] origin = {{ rpy = [{r:.4}, {p:.4}, {y:.4}] }} (that brings z up; \
                 check that x then points to the toes), or name a sole frame of the URDF",
                soles[k],
                tilt.to_degrees()
            ));
        }
        // A robot that does not stand flat on its eight points at home cannot be balanced by a
        // controller that assumes it: refuse it with the figures.
        if tilt > 2f64.to_radians() || zmax - zmin > 2e-3 {
            return Err(format!(
                "the soles are not flat on the ground at home (tilt {:.1}°, contact heights {:.1} mm \
                 apart): adjust [home] (hip, knee and ankle pitch)",
                tilt.to_degrees(),
                (zmax - zmin) * 1e3
            ));
        }
        Ok(())
    }
}

/// [`Derived::hand_force_capacity`]: min over the chain joints of τ_max / |J_eᵀ x̂| (`op`: the
/// hand's operational space, computed at home).
fn hand_force_capacity(model: &Model, op: &OpSpaceWorkspace) -> f64 {
    op.dofs
        .iter()
        .enumerate()
        .map(|(k, &dof)| {
            let lever = op.j_e[(0, k)].abs();
            let effort = model.joints[model.dof_joint[dof]].limits.effort;
            if lever > 1e-9 {
                effort / lever
            } else {
                f64::INFINITY
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// A sole's orientation from its corners (front-left, front-right, rear-left, rear-right): x
/// toward the toes, z its normal (as the plants define the foot wrench's frame).
pub fn sole_frame(
    fl: Vector3<f64>,
    fr: Vector3<f64>,
    rl: Vector3<f64>,
    rr: Vector3<f64>,
) -> Matrix3<f64> {
    let x = ((fl + fr) - (rl + rr)).normalize();
    let left = (fl + rl) - (fr + rr);
    let z = x.cross(&left).normalize();
    let y = z.cross(&x);
    Matrix3::from_columns(&[x, y, z])
}
