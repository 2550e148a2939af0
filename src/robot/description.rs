//! The robot description file (`config/robots/<name>.toml`): what a user writes to bring a
//! humanoid. Everything that follows from the model (mass, CoM height, support, M_e) is not in
//! it: [`super::Robot`] computes it.
//!
//! ```toml
//! extends = "g1_base.toml"                 # optional: a description this one layers over
//! name = "g1"
//! description = "Unitree G1, 29 DoF (example-robot-data)"
//! [urdf]
//! package = "example-robot-data"           # a registry package (scripts/setup.sh), or none:
//! path = "robots/g1_description/urdf/g1_29dof_rev_1_0.urdf"   # relative to the package / this file
//! root_rpy = [1.5708, 0.0, 0.0]            # optional: the root link turned, for a URDF not z-up
//! [feet.left]
//! frame = "left_sole"                      # the sole frame (z: the ground's normal)
//! link = "left_ankle_roll_link"            # created on this link when the URDF has no such frame
//! contacts = "collision"                   # or "frames", or [[x, y, z], …] × 4 in the sole frame
//! [hand]
//! frame = "right_rubber_hand"              # holds the door
//! chain_root = "torso_link"                # M_e: chain root → hand (docs/hand_previewer.md)
//! [imu]                                    # optional: the IMU's frame (its axes the sensor's);
//! frame = "imu_in_pelvis"                  # without it, on the base and aligned with it
//! [home]                                   # joint = angle (rad); the others at 0
//! left_knee_joint = 0.3
//! [locked]                                 # fixed at their home value (Pinocchio's reduced
//! joints = ["*_hand_*", "head_*"]          # model): names or glob patterns
//! [armature]                               # reflected rotor inertia (kg·m²), by name or
//! "*_wrist_*" = 0.001                      # pattern; the URDF has none (0 elsewhere)
//! inertia_floor = 1e-6                     # (top level) a point-mass link's moments (kg·m²)
//! [config]                                 # robot-dependent values of config/default.toml
//! hand.kp = 400.0
//! ```

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Deserialize;

/// A robot description as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDescription {
    /// A description this one layers over (embedded name, or path relative to this file):
    /// its keys are this one's unless set here (a variant of a robot in a few lines).
    #[serde(default)]
    pub extends: Option<String>,
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub urdf: UrdfSource,
    pub feet: Feet,
    pub hand: HandSpec,
    /// Where the IMU is, when not on the base and aligned with it (docs/sensing.md, "The IMU's
    /// mounting").
    #[serde(default)]
    pub imu: Option<ImuSpec>,
    /// Joint angles of the standing posture (rad); unlisted joints are at 0. With `[stance]`,
    /// the guess the solved posture starts from and stays near.
    #[serde(default)]
    pub home: BTreeMap<String, f64>,
    /// The standing posture solved by inverse kinematics (`super::stance`) instead of typed.
    #[serde(default)]
    pub stance: Option<super::stance::StanceSpec>,
    /// Joints fixed at their home value: neither simulated nor controlled (fingers, eyes…).
    #[serde(default)]
    pub locked: Locked,
    /// Reflected rotor inertia of joints (kg·m², kg for a prismatic one), by name or glob
    /// pattern: what a URDF leaves out and real drives have. A joint chain without mass (a
    /// URDF's fingers) needs it to have a non-singular M.
    #[serde(default)]
    pub armature: BTreeMap<String, f64>,
    /// The smallest principal moment of inertia (kg·m²) a body with mass gets about its CoM:
    /// for a URDF whose links are point masses (zero inertia), which no physical body is and
    /// MuJoCo refuses. Absent: such a body is refused with its name.
    #[serde(default)]
    pub inertia_floor: Option<f64>,
    /// Config keys layered over `config/default.toml` for this robot (gains, torque scale).
    #[serde(default)]
    pub config: Option<toml::Table>,
    /// The robot's own low-level bus (`upc bus`, docs/bus.md), if upc can drive it there.
    #[serde(default)]
    pub bus: Option<BusSpec>,
    /// What the robot measures besides its joints and its IMU (docs/sensing.md, "What a robot
    /// measures"): a plant on `realistic` sensing publishes exactly that.
    #[serde(default)]
    pub sensors: SensorSpec,
}

/// How the robot's own bus addresses its drives.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusSpec {
    /// The message set: `unitree_hg` (Unitree's `rt/lowstate` / `rt/lowcmd`, G1 and H1-2).
    pub kind: String,
    /// The joint each motor slot drives, slot 0 first (checked against the URDF at start-up).
    pub slots: Vec<String>,
    /// The drives' hold gains, one per slot (N·m/rad, N·m·s/rad): the stiffness that holds the
    /// start posture before the controller has the robot, and the posture it has while its
    /// controller is silent (docs/bus.md, "Safety"). The robot's, not upc's: a joint that carries
    /// the body needs more than a wrist, and only the description knows which is which.
    pub hold_kp: Vec<f64>,
    pub hold_kd: Vec<f64>,
}

/// Where the URDF is.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrdfSource {
    /// A registry package installed by `scripts/setup.sh` (`example-robot-data`,
    /// `icub-models`); `path` is then inside it.
    #[serde(default)]
    pub package: Option<String>,
    /// Path of the URDF: inside the package, or relative to the description file (then to the
    /// repository root, where the embedded robot's assets are).
    pub path: PathBuf,
    /// The URDF's root link turned by this roll-pitch-yaw (rad) in the robot's base, for a
    /// URDF whose z axis is not up at the zero posture (y up: `[1.5708, 0, 0]`).
    #[serde(default)]
    pub root_rpy: Option<[f64; 3]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Feet {
    pub left: FootSpec,
    pub right: FootSpec,
}

/// One foot: its sole frame and the four points that touch the ground.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FootSpec {
    /// The sole frame: origin on the sole, z the outward normal of the ground (up when flat).
    pub frame: String,
    /// The link the sole belongs to, when `frame` is not in the URDF (it is then created on the
    /// link, at the centroid of the contact points, with the link's orientation) or when the
    /// contacts come from this link's collision geometry.
    #[serde(default)]
    pub link: Option<String>,
    /// Where a made sole frame sits on `link` (the link's axes and origin when absent): its
    /// placement in the link's frame, for a link whose axes are not the sole's (z out of the
    /// sole, x toward the toes). A sole made from collision geometry sits at its contact
    /// points' centroid: only `rpy` applies there.
    #[serde(default)]
    pub origin: Option<SoleOrigin>,
    pub contacts: ContactSpec,
}

/// A made sole frame's placement in its link's frame, as a URDF joint's `<origin>`.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoleOrigin {
    #[serde(default)]
    pub xyz: [f64; 3],
    #[serde(default)]
    pub rpy: [f64; 3],
}

/// The four contact points of a sole.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum ContactSpec {
    /// `"frames"`: the URDF has `<frame>_fl`, `_fr`, `_rl`, `_rr`; `"collision"`: from the
    /// link's collision geometry (the bottom face of a box, or four spheres' lowest points).
    Keyword(String),
    /// Four points in the sole frame (m), any order.
    Points(Vec<[f64; 3]>),
}

/// The hand that holds the door.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandSpec {
    pub frame: String,
    /// The body the arm chain of M_e starts from (its joints are the chain's, exclusive).
    pub chain_root: String,
}

/// How a robot measures its feet's loads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FootSensors {
    /// A force sensor under each sole corner.
    Corners,
    /// A six-axis force/torque sensor per ankle.
    SixAxis,
    /// None (the Unitree G1): the controller estimates the feet's wrenches.
    None,
}

/// `[sensors]`: what a robot measures besides its joint encoders and its IMU (`[imu]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// The feet; absent: as the plant's `sim.sensors.feet` says.
    #[serde(default)]
    pub feet: Option<FootSensors>,
    /// A six-axis force/torque sensor at the hand's wrist.
    #[serde(default = "yes")]
    pub wrist: bool,
    /// Each drive's torque estimate (from its motor current).
    #[serde(default = "yes")]
    pub joint_torques: bool,
}

fn yes() -> bool {
    true
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            feet: None,
            wrist: true,
            joint_torques: true,
        }
    }
}

/// The IMU's mounting.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSpec {
    /// A frame of the URDF whose axes are the sensor's: on the base's link or beyond joints
    /// (a head's IMU).
    pub frame: String,
}

/// The joints a description locks.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Locked {
    /// Joint names or glob patterns (`*`, `?`, `[…]`); each must match a moving joint.
    #[serde(default)]
    pub joints: Vec<String>,
}
