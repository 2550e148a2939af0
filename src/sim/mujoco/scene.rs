//! The scene of `upc sim --plant mujoco`: an MJCF model and a plant description ([`PlantFile`],
//! written as `plant.json` by `upc mjcf`) generated from the same robot description, URDF, door
//! and scenario as [`crate::sim::scene`], for MuJoCo stepped by the plant runtime
//! ([`super::MujocoPlant`]).
//!
//! What carries over, and how:
//! - bodies, joint placements, axes, inertias, armatures and position limits from the [`Model`]
//!   (the URDF as upc reads it: fixed links merged, locked joints fixed, repaired inertias), a
//!   free joint at the root;
//! - contacts: one small sphere per contact point of the robot description, touching the
//!   ground at the point when the sole is flat; only those spheres collide, with the floor
//!   (upc's own simulator has the same eight point contacts and no other collisions);
//! - `sim.friction` on spheres and floor, `sim.joint_damping` and `sim.door_damping` as joint
//!   damping (MuJoCo's `implicitfast` integrates it implicitly, as upc does);
//! - the door placed by [`place_door`], joined to the hand by a `connect` equality between a
//!   site at the hand frame and one at the handle frame; its hinge torque sampled from the
//!   scenario ([`DoorDrive::torque`]) at the plant's step;
//! - the hold's gains ([`PosturePd::hold`]), effort limits, timeouts and the contract's
//!   identifiers (robot and scenario hashes, force factor) in `plant.json`.
//!
//! Not carried over: MuJoCo's soft constraints (its default `solimp`, and its `solref` except
//! at the contact spheres, `sim.mujoco.contact_timeconst`) in place of upc's hard contacts and
//! loop closure, with the friction cone, impratio and no-slip iterations of `[sim.mujoco]`; visual meshes (the links are drawn as capsules between joint origins).

use std::fmt::Write as _;

use nalgebra::{DVector, Vector3};
use serde::Serialize;

use crate::dynamics::{Data, JointKind, Model, SE3, forward_kinematics};
use crate::robot::Robot;
use crate::scenario::Scenario;

use crate::sim::config::{Cone, HoldKind, Push, SimConfig};
use crate::sim::physics::SimError;
use crate::sim::scene::{DoorDrive, HANDLE_FRAME, PlacedDoor, PosturePd, place_door};

/// Radius of the contact spheres (m): small against the foot, large enough for MuJoCo's
/// sphere–plane collision to be well conditioned.
pub const CONTACT_RADIUS: f64 = 0.005;
/// Name of the hand–handle equality, and of the sites it joins.
pub const CONNECT: &str = "hand_handle";
const HAND_SITE: &str = "hand";
const HANDLE_SITE: &str = "handle";
const DOOR_PREFIX: &str = "door_";
const BASE_JOINT: &str = "root";

/// `plant.json`: what the MuJoCo plant needs besides the MJCF (format 2): identifiers, the
/// step and the loop's timeouts, the hold's gains, the MJCF names of the base, the actuated
/// joints and the contact spheres (contract order), sites and door hinge, the home
/// configuration. The plant runtime reads it in memory; `upc mjcf` writes it for a plant of
/// one's own.
#[derive(Debug, Clone, Serialize)]
pub struct PlantFile {
    pub format: u32,
    pub robot: String,
    pub robot_hash: String,
    pub force_scale: f64,
    pub scenario: String,
    pub scenario_hash: String,
    pub sim: PlantSim,
    pub hold: PlantHold,
    pub scene: String,
    pub base_joint: String,
    pub base_body: String,
    /// Actuated joints in the contract's order.
    pub joints: Vec<String>,
    /// Effort limits (N·m or N), `None`: unbounded.
    pub effort: Vec<Option<f64>>,
    /// Contact spheres in the contract's order.
    pub contacts: Vec<String>,
    pub contact_radius: f64,
    pub hand_site: String,
    pub handle_site: Option<String>,
    pub door_joint: Option<String>,
    /// Contract configuration at home: base position, quaternion x y z w, joints.
    pub home: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PlantSim {
    pub dt: f64,
    pub mode: String,
    pub duration: f64,
    pub prefix: String,
    pub effort_limits: bool,
    pub record_period: f64,
    pub lockstep_timeout: f64,
    pub command_timeout: f64,
    pub first_command_timeout: f64,
    pub safe_damping: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct PlantHold {
    pub kind: String,
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
    pub handover: f64,
    pub feedforward_fade: f64,
    pub lost_timeout: f64,
}

/// A generated MuJoCo scene.
pub struct MujocoScene {
    pub mjcf: String,
    pub plant: PlantFile,
    /// The door as placed in the scene (upc's model of it), and its hinge torque.
    pub door: Option<PlacedDoor>,
    pub drive: DoorDrive,
}

/// Builds the MuJoCo scene of `robot` under `cfg` playing `scenario` (its forces already scaled
/// to the robot).
pub fn build(robot: &Robot, cfg: &SimConfig, scenario: &Scenario) -> Result<MujocoScene, SimError> {
    let model = &robot.model;
    let joint0 = model
        .joints
        .first()
        .ok_or_else(|| SimError::Scene("the robot has no joints".into()))?;
    if !matches!(joint0.kind, JointKind::FreeFlyer) {
        return Err(SimError::Scene(
            "the MuJoCo scene needs a floating-base robot".into(),
        ));
    }
    if cfg.push != Push::Door {
        return Err(SimError::Scene(
            "sim.push must be \"door\" on the MuJoCo plant: it pushes through the door only (upc's own simulator applies hand pushes and phantom runs, \"hand\" and \"none\")".into(),
        ));
    }
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &robot.home)?;

    let mut x = Mjcf {
        s: String::new(),
        joint_limits: cfg.joint_limits,
        friction: cfg.friction,
        contact_timeconst: cfg.mujoco.contact_timeconst,
    };
    x.header(robot, cfg)?;
    x.robot(robot, &data, cfg.joint_damping)?;
    // The door placed once: its bodies here, its hinge torque below.
    let placed = if cfg.door {
        Some(place_door(robot)?)
    } else {
        None
    };
    let door_joint = match &placed {
        Some(placed) => Some(x.door(placed, cfg.door_damping)?),
        None => None,
    };
    x.footer(robot, cfg)?;

    let hold = PosturePd::hold(
        model,
        &robot.home,
        &robot.carrying_frames(),
        &cfg.hold,
        cfg.dt,
    )?;
    let drive = match &placed {
        Some(placed) => DoorDrive {
            profile: scenario.force.clone(),
            lever: placed.lever,
            axis: placed.axis,
        },
        None => DoorDrive::none(),
    };
    let plant = plant_file(robot, cfg, scenario, &hold, door_joint);
    Ok(MujocoScene {
        mjcf: x.s,
        plant,
        door: placed,
        drive,
    })
}

/// The plant description of the scene (`plant.json`): what the runtime needs besides the MJCF.
fn plant_file(
    robot: &Robot,
    cfg: &SimConfig,
    scenario: &Scenario,
    hold: &PosturePd,
    door_joint: Option<String>,
) -> PlantFile {
    let model = &robot.model;
    let actuated: Vec<&crate::dynamics::Joint> = model
        .joints
        .iter()
        .filter(|j| !matches!(j.kind, JointKind::FreeFlyer))
        .collect();
    PlantFile {
        format: 2,
        robot: robot.name().to_string(),
        robot_hash: format!("{:016x}", robot.hash),
        force_scale: scenario.force_scale,
        scenario: cfg.scenario.clone(),
        scenario_hash: format!("{:016x}", scenario.content_hash()),
        sim: PlantSim {
            dt: cfg.dt,
            mode: format!("{:?}", cfg.mode).to_lowercase(),
            duration: cfg.duration,
            prefix: cfg.process.prefix.clone(),
            effort_limits: cfg.effort_limits,
            record_period: cfg.record_period,
            lockstep_timeout: cfg.process.lockstep_timeout,
            command_timeout: cfg.process.command_timeout,
            first_command_timeout: cfg.process.first_command_timeout,
            safe_damping: cfg.process.safe_damping,
        },
        hold: PlantHold {
            kind: match cfg.hold.kind {
                HoldKind::PosturePd => "posture_pd",
                HoldKind::Damping => "damping",
            }
            .into(),
            kp: hold.kp.iter().copied().collect(),
            kd: hold.kd.iter().copied().collect(),
            handover: cfg.hold.handover,
            feedforward_fade: cfg.hold.feedforward_fade,
            lost_timeout: cfg.hold.lost_timeout,
        },
        scene: "scene.xml".into(),
        base_joint: BASE_JOINT.into(),
        base_body: model.joints[0].body.clone(),
        joints: actuated.iter().map(|j| j.name.clone()).collect(),
        effort: actuated
            .iter()
            .map(|j| j.limits.effort.is_finite().then_some(j.limits.effort))
            .collect(),
        contacts: robot.contacts.to_vec(),
        contact_radius: CONTACT_RADIUS,
        hand_site: HAND_SITE.into(),
        handle_site: cfg.door.then(|| HANDLE_SITE.into()),
        door_joint,
        home: robot.home.iter().copied().collect(),
    }
}

/// The MJCF being written, and the simulator settings every body shares.
struct Mjcf {
    s: String,
    joint_limits: bool,
    friction: f64,
    contact_timeconst: f64,
}

impl From<std::fmt::Error> for SimError {
    fn from(e: std::fmt::Error) -> Self {
        SimError::Scene(format!("writing the MJCF: {e}"))
    }
}

impl Mjcf {
    /// The document's head: compiler, options (step, cone, gravity), visual defaults, the floor.
    fn header(&mut self, robot: &Robot, cfg: &SimConfig) -> Result<(), SimError> {
        let model = &robot.model;
        writeln!(
            self.s,
            "<mujoco model=\"upc {}\">\n  <!-- Generated by `upc mjcf` from the robot description `{}` and the scenario `{}`: edit those, not this file. -->",
            esc(robot.name()),
            esc(robot.name()),
            esc(&cfg.scenario)
        )?;
        writeln!(
            self.s,
            "  <compiler angle=\"radian\" inertiafromgeom=\"false\" autolimits=\"true\"/>\n  <option timestep=\"{}\" integrator=\"implicitfast\" cone=\"{}\" impratio=\"{}\" noslip_iterations=\"{}\" gravity=\"{} {} {}\"/>",
            cfg.dt,
            match cfg.mujoco.cone {
                Cone::Elliptic => "elliptic",
                Cone::Pyramidal => "pyramidal",
            },
            cfg.mujoco.impratio,
            cfg.mujoco.noslip_iterations,
            model.gravity.x,
            model.gravity.y,
            model.gravity.z
        )?;
        writeln!(
            self.s,
            "  <visual><global offwidth=\"1280\" offheight=\"720\"/></visual>\n  <default>\n    <geom contype=\"0\" conaffinity=\"0\" rgba=\"0.7 0.7 0.75 1\"/>\n  </default>\n  <worldbody>\n    <light pos=\"0 0 3\" dir=\"0 0 -1\" directional=\"true\"/>\n    <geom name=\"floor\" type=\"plane\" size=\"0 0 1\" conaffinity=\"1\" friction=\"{} 0.005 0.0001\" rgba=\"0.85 0.85 0.8 1\"/>",
            cfg.friction
        )?;
        Ok(())
    }

    /// The robot's bodies from the base, with a contact sphere at each contact point and the
    /// hand's site; `data`: its kinematics at home.
    fn robot(&mut self, robot: &Robot, data: &Data, damping: f64) -> Result<(), SimError> {
        let model = &robot.model;
        // Contact spheres per body: centred a radius above each point along the world's z at
        // home (the soles are flat there), so that they touch the ground at the points.
        let mut spheres: Vec<Vec<(String, Vector3<f64>)>> = vec![Vec::new(); model.joints.len()];
        for name in &robot.contacts {
            let f = model.frame_id(name)?;
            let body = model.frames[f].parent.ok_or_else(|| {
                SimError::Scene(format!("contact frame `{name}` is not on a moving body"))
            })?;
            let o_m_b = &data.o_m_i[body];
            let centre = data.o_m_f[f].trans + Vector3::z() * CONTACT_RADIUS;
            spheres[body].push((name.clone(), o_m_b.rot.transpose() * (centre - o_m_b.trans)));
        }
        let hand_frame = model.frame_id(&robot.description.hand.frame)?;
        let mut sites: Vec<Vec<(String, Vector3<f64>)>> = vec![Vec::new(); model.joints.len()];
        let hand_body = model.frames[hand_frame]
            .parent
            .ok_or_else(|| SimError::Scene("the hand frame is not on a moving body".into()))?;
        sites[hand_body].push((HAND_SITE.into(), model.frames[hand_frame].placement.trans));
        let base = SE3::new(data.o_m_i[0].rot, data.o_m_i[0].trans);
        self.body_tree(model, 0, &base, "", damping, &spheres, &sites, 2)?;
        Ok(())
    }

    /// The door's bodies under a body at its base, the handle's site on its leaf; the name of
    /// its hinge.
    fn door(&mut self, placed: &PlacedDoor, damping: f64) -> Result<String, SimError> {
        let door = &placed.model;
        let handle = door.frame_id(HANDLE_FRAME)?;
        let mut door_sites = vec![Vec::new(); door.joints.len()];
        let handle_body = door.frames[handle]
            .parent
            .ok_or_else(|| SimError::Scene("the door's handle is not on its leaf".into()))?;
        door_sites[handle_body].push((HANDLE_SITE.into(), door.frames[handle].placement.trans));
        writeln!(
            self.s,
            "    <body name=\"{DOOR_PREFIX}base\" {}>",
            pose_attrs(&placed.base)
        )?;
        let no_spheres = vec![Vec::new(); door.joints.len()];
        for (j, joint) in door.joints.iter().enumerate() {
            if joint.parent.is_none() {
                self.body_tree(
                    door,
                    j,
                    &joint.placement,
                    DOOR_PREFIX,
                    damping,
                    &no_spheres,
                    &door_sites,
                    3,
                )?;
            }
        }
        writeln!(self.s, "    </body>")?;
        Ok(format!("{DOOR_PREFIX}{}", door.joints[0].name))
    }

    /// The document's tail: the world body closed, the hand–handle connect, the home keyframe.
    fn footer(&mut self, robot: &Robot, cfg: &SimConfig) -> Result<(), SimError> {
        writeln!(self.s, "  </worldbody>")?;
        if cfg.door {
            writeln!(
                self.s,
                "  <equality>\n    <connect name=\"{CONNECT}\" site1=\"{HAND_SITE}\" site2=\"{HANDLE_SITE}\"/>\n  </equality>"
            )?;
        }
        // The home posture as a keyframe, for a user who opens the scene in MuJoCo's viewer.
        let mut key = mujoco_qpos(&robot.home);
        if cfg.door {
            key.push(0.0);
        }
        writeln!(
            self.s,
            "  <keyframe>\n    <key name=\"home\" qpos=\"{}\"/>\n  </keyframe>",
            join(&key)
        )?;
        writeln!(self.s, "</mujoco>")?;
        Ok(())
    }
}

impl Mjcf {
    /// Body `j` of `model` and its subtree, placed at `pose` in its parent body.
    #[allow(clippy::too_many_arguments)]
    fn body_tree(
        &mut self,
        model: &Model,
        j: usize,
        pose: &SE3,
        prefix: &str,
        damping: f64,
        spheres: &[Vec<(String, Vector3<f64>)>],
        sites: &[Vec<(String, Vector3<f64>)>],
        depth: usize,
    ) -> Result<(), SimError> {
        let pad = "  ".repeat(depth);
        let joint = &model.joints[j];
        writeln!(
            self.s,
            "{pad}<body name=\"{prefix}{}\" {}>",
            esc(&joint.body),
            pose_attrs(pose)
        )?;
        self.joint_element(joint, &pad, prefix, damping)?;
        self.inertial(joint, &pad)?;
        // Drawn as capsules to each child's origin (no collision).
        for child in model.joints.iter().filter(|c| c.parent == Some(j)) {
            let to = child.placement.trans;
            if to.norm() > 1e-4 {
                writeln!(
                    self.s,
                    "{pad}  <geom type=\"capsule\" size=\"0.015\" fromto=\"0 0 0 {}\" group=\"1\"/>",
                    vec3(&to)
                )?;
            }
        }
        for (name, p) in &spheres[j] {
            writeln!(
                self.s,
                "{pad}  <geom name=\"{}\" type=\"sphere\" size=\"{CONTACT_RADIUS}\" pos=\"{}\" contype=\"1\" solref=\"{} 1\" friction=\"{} 0.005 0.0001\" rgba=\"0.9 0.3 0.2 1\"/>",
                esc(name),
                vec3(p),
                self.contact_timeconst,
                self.friction
            )?;
        }
        for (name, p) in &sites[j] {
            writeln!(
                self.s,
                "{pad}  <site name=\"{name}\" pos=\"{}\" size=\"0.02\" rgba=\"0.2 0.6 0.9 1\"/>",
                vec3(p)
            )?;
        }
        let children: Vec<usize> = (0..model.joints.len())
            .filter(|&c| model.joints[c].parent == Some(j))
            .collect();
        for c in children {
            let placement = model.joints[c].placement;
            self.body_tree(
                model,
                c,
                &placement,
                prefix,
                damping,
                spheres,
                sites,
                depth + 1,
            )?;
        }
        writeln!(self.s, "{pad}</body>")?;
        Ok(())
    }

    /// The joint of body `joint` (a free joint for the base, a hinge or slide with its range,
    /// armature and damping otherwise).
    fn joint_element(
        &mut self,
        joint: &crate::dynamics::Joint,
        pad: &str,
        prefix: &str,
        damping: f64,
    ) -> Result<(), SimError> {
        let name = format!("{prefix}{}", esc(&joint.name));
        match joint.kind {
            JointKind::FreeFlyer => writeln!(self.s, "{pad}  <freejoint name=\"{BASE_JOINT}\"/>")?,
            JointKind::Revolute { axis } | JointKind::Prismatic { axis } => {
                let kind = if matches!(joint.kind, JointKind::Revolute { .. }) {
                    "hinge"
                } else {
                    "slide"
                };
                let l = &joint.limits;
                let range = if self.joint_limits && l.lower.is_finite() && l.upper.is_finite() {
                    format!(" range=\"{} {}\"", l.lower, l.upper)
                } else {
                    String::new()
                };
                let armature = if joint.armature > 0.0 {
                    format!(" armature=\"{}\"", joint.armature)
                } else {
                    String::new()
                };
                writeln!(
                    self.s,
                    "{pad}  <joint name=\"{name}\" type=\"{kind}\" axis=\"{}\"{range}{armature} damping=\"{}\"/>",
                    vec3(&axis),
                    damping
                )?;
            }
        }
        Ok(())
    }

    /// The inertia of body `joint` about its centre of mass.
    fn inertial(&mut self, joint: &crate::dynamics::Joint, pad: &str) -> Result<(), SimError> {
        let inertia = &joint.inertia;
        let (mass, c, i) = (inertia.mass, inertia.com(), inertia.inertia_com());
        if mass > 0.0 {
            writeln!(
                self.s,
                "{pad}  <inertial pos=\"{}\" mass=\"{mass}\" fullinertia=\"{} {} {} {} {} {}\"/>",
                vec3(&c),
                i[(0, 0)],
                i[(1, 1)],
                i[(2, 2)],
                i[(0, 1)],
                i[(0, 2)],
                i[(1, 2)]
            )?;
        } else {
            // MuJoCo refuses a moving body without mass or inertia (a URDF's massless finger
            // links, whose dynamics the joint's armature carries): a nanogram and 1e-15 kg·m²,
            // nothing against any armature.
            writeln!(
                self.s,
                "{pad}  <inertial pos=\"0 0 0\" mass=\"1e-9\" diaginertia=\"1e-15 1e-15 1e-15\"/>"
            )?;
        }
        Ok(())
    }
}

fn pose_attrs(p: &SE3) -> String {
    let q = p.quaternion();
    format!(
        "pos=\"{}\" quat=\"{} {} {} {}\"",
        vec3(&p.trans),
        q.w,
        q.i,
        q.j,
        q.k
    )
}

fn vec3(v: &Vector3<f64>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn join(v: &[f64]) -> String {
    v.iter().map(f64::to_string).collect::<Vec<_>>().join(" ")
}

/// XML attribute escaping (names come from URDFs).
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A contract configuration in MuJoCo's order (base quaternion w x y z).
pub fn mujoco_qpos(q: &DVector<f64>) -> Vec<f64> {
    let mut v = vec![q[0], q[1], q[2], q[6], q[3], q[4], q[5]];
    v.extend(q.iter().skip(7));
    v
}
