//! The scene of the paper's experiments (its Sec. IV; docs/results/claims.md): a robot (the
//! iCub-like humanoid by default, any [`Robot`]) standing on flat ground on the four contact points
//! of each foot, its hand holding the door's handle through a spherical joint, and the door's hinge
//! driven by the scenario's torque profile.
//!
//! Door placement: the door (`assets/door/door.urdf`) is turned by −90° about z so that its leaf
//! faces the robot (its −y side, where the handle sticks out, points to world −x), and translated
//! so that at hinge angle 0 the handle frame coincides with the robot's hand at home.
//! The hinge is then 0.72 m to the robot's left of the handle (+y) and its vertical axis passes
//! 7 cm beyond the handle (+x); the door floats a little below the ground, which does not matter
//! (it only touches the hand).
//!
//! Hinge torque: the scenario gives the force `F(t)` the door applies to the hand (world). If
//! the hand holds still, the door is in equilibrium when the hinge torque balances the hand's
//! reaction: `τ(t) = ((p_handle − p_hinge) × F(t)) · z`, with the lever taken at the home
//! placement (0.72 m). A force towards the robot (−x) is a negative (closing) torque.

use nalgebra::{DVector, Matrix3, Vector3};

use crate::dynamics::{BaseJoint, Data, Model, SE3, crba, forward_kinematics, icub_like};
use crate::robot::Robot;
use crate::scenario::{ForceProfile, Scenario};

use super::config::SimConfig;
use super::physics::SimError;
use super::world::{DoorSpec, PhysicsParams, Plane, World, WorldSpec};

/// The door frame the robot's hand holds.
pub const HANDLE_FRAME: &str = "handle";

/// The hinge torque profile derived from the scenario's hand force.
#[derive(Clone, Debug)]
pub struct DoorDrive {
    pub profile: ForceProfile,
    /// Lever from the hinge axis to the handle (world, at the home placement).
    pub lever: Vector3<f64>,
    /// Hinge axis (world).
    pub axis: Vector3<f64>,
}

impl DoorDrive {
    /// Hinge torque at time `t` (N·m).
    pub fn torque(&self, t: f64) -> f64 {
        self.torque_of(self.profile.at(t))
    }

    /// The hinge torque of hand force `f`.
    fn torque_of(&self, f: [f64; 3]) -> f64 {
        self.lever
            .cross(&Vector3::new(f[0], f[1], f[2]))
            .dot(&self.axis)
    }

    /// The scenario's hand force at `t` (N, world): what the door pushes with, if held still.
    pub fn hand_force(&self, t: f64) -> [f64; 3] {
        self.profile.at(t)
    }

    /// A drive that applies no torque.
    pub fn none() -> Self {
        Self {
            profile: ForceProfile::Samples(Vec::new()),
            lever: Vector3::zeros(),
            axis: Vector3::z(),
        }
    }
}

/// A scene built: the world, its initial state and the door drive.
pub struct Scene {
    pub world: World,
    pub drive: DoorDrive,
    /// Home configuration of the robot (also the initial state).
    pub q_home: DVector<f64>,
    /// Frames whose supporting joints carry the body (the soles, the arm chain's root): a
    /// posture hold stiffens those joints ([`PosturePd::with_floor`]).
    pub carrying: Vec<usize>,
}

/// World placement of the door's base that puts the handle on `hand` (hinge angle 0).
pub fn door_base_for(door: &Model, hand: &Vector3<f64>) -> Result<SE3, SimError> {
    let mut data = Data::new(door);
    forward_kinematics(door, &mut data, &door.neutral())?;
    let h0 = data.o_m_f[door.frame_id(HANDLE_FRAME)?].trans;
    let rot =
        *nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -std::f64::consts::FRAC_PI_2)
            .matrix();
    Ok(SE3::new(rot, hand - rot * h0))
}

/// Builds the default robot (+ door if `config.door`) at its home configuration, at rest.
pub fn humanoid_scene(
    config: &SimConfig,
    profile: Option<ForceProfile>,
) -> Result<Scene, SimError> {
    humanoid_scene_with(PhysicsParams::from_config(config), config.door, profile)
}

/// As [`humanoid_scene`] with explicit parameters.
pub fn humanoid_scene_with(
    params: PhysicsParams,
    with_door: bool,
    profile: Option<ForceProfile>,
) -> Result<Scene, SimError> {
    let robot = Robot::embedded_default().map_err(|e| SimError::Scene(e.to_string()))?;
    robot_scene(&robot, params, with_door, profile)
}

/// The door placed at `robot`'s hand at home: its model, the world placement of its base, and
/// the hinge's lever to the handle and axis (world), which turn the scenario's hand force into
/// the hinge torque ([`DoorDrive`]). Every plant builds its door from this.
pub struct PlacedDoor {
    pub model: Model,
    pub base: SE3,
    pub lever: Vector3<f64>,
    pub axis: Vector3<f64>,
}

impl PlacedDoor {
    /// The door's apparent mass at the handle (world, kg): what its inertia opposes to the
    /// hand's acceleration a, f = −Λ a. The leaf turns about its hinge only, so the handle moves
    /// along e = axis × lever / r and Λ = I_hinge / r² e eᵀ (I_hinge from the composite-rigid-body
    /// algorithm at the door's neutral angle, r the lever). Used by the controller's forecast
    /// correction (docs/forecast_correction.md, FC-1).
    pub fn apparent_mass(&self) -> Result<Matrix3<f64>, SimError> {
        let mut data = Data::new(&self.model);
        let inertia = crba(&self.model, &mut data, &self.model.neutral())?[(0, 0)];
        let r2 = self.lever.norm_squared();
        if r2 <= 1e-12 {
            return Err(SimError::Scene(
                "the door's handle is on its hinge axis".into(),
            ));
        }
        let e = self.axis.cross(&self.lever) / r2.sqrt();
        Ok(e * e.transpose() * (inertia / r2))
    }
}

/// Places the door (`assets/door/door.urdf`) so that its handle is on `robot`'s hand at home.
pub fn place_door(robot: &Robot) -> Result<PlacedDoor, SimError> {
    let door = Model::from_urdf_str(icub_like::DOOR_URDF, BaseJoint::Fixed)?;
    let mut data = Data::new(&robot.model);
    forward_kinematics(&robot.model, &mut data, &robot.home)?;
    let hand = data.o_m_f[robot.model.frame_id(&robot.description.hand.frame)?].trans;
    let base = door_base_for(&door, &hand)?;
    // Lever: from the hinge axis (through the hinge joint origin) to the handle.
    let hinge = door
        .joints
        .first()
        .ok_or_else(|| SimError::Scene("the door has no joint".into()))?;
    let hinge_origin = base.compose(&hinge.placement).trans;
    let axis = match hinge.kind {
        crate::dynamics::JointKind::Revolute { axis } => base.compose(&hinge.placement).rot * axis,
        _ => {
            return Err(SimError::Scene(
                "the door's first joint must be revolute".into(),
            ));
        }
    };
    let mut lever = hand - hinge_origin;
    lever -= axis * axis.dot(&lever);
    Ok(PlacedDoor {
        model: door,
        base,
        lever,
        axis,
    })
}

/// `robot` at its home configuration, at rest, on the ground; with the door at its hand when
/// `with_door` (driven by `profile`).
pub fn robot_scene(
    robot: &Robot,
    params: PhysicsParams,
    with_door: bool,
    profile: Option<ForceProfile>,
) -> Result<Scene, SimError> {
    let q_home = robot.home.clone();
    let hand_frame = robot.description.hand.frame.clone();
    let robot_model = robot.model.clone();
    let mut drive = DoorDrive::none();
    let door = if with_door {
        let placed = place_door(robot)?;
        if let Some(p) = profile {
            drive = DoorDrive {
                profile: p,
                lever: placed.lever,
                axis: placed.axis,
            };
        }
        Some(DoorSpec {
            model: placed.model,
            base: placed.base,
            handle_frame: HANDLE_FRAME.into(),
            hand_frame,
        })
    } else {
        // No door: the profile is the hand push's (`DoorDrive::hand_force`), no hinge torque.
        if let Some(p) = profile {
            drive.profile = p;
        }
        None
    };
    let spec = WorldSpec {
        robot: robot_model,
        contact_frames: robot.contacts.to_vec(),
        ground: Plane::ground(),
        door,
        params,
    };
    let v0 = DVector::zeros(spec.robot.nv);
    let world = World::new(spec, q_home.clone(), v0)?;
    Ok(Scene {
        world,
        drive,
        q_home,
        carrying: robot.carrying_frames(),
    })
}

/// Loads the scenario named in the config (embedded name or path), scales its forces to
/// `robot` ([`Robot::force_scale`]) and builds the scene.
pub fn default_scene(
    config: &SimConfig,
    robot: &Robot,
) -> Result<(Scene, Scenario), Box<dyn std::error::Error + Send + Sync>> {
    let scenario = robot.scenario(&config.scenario)?;
    let scene = robot_scene(
        robot,
        PhysicsParams::from_config(config),
        config.door && config.push != super::config::Push::Hand,
        (config.push != super::config::Push::None).then(|| scenario.force.clone()),
    )?;
    Ok((scene, scenario))
}

/// A posture-holding joint PD for tests, demos and the benchmark: `τ = Kp (q_ref − q) − Kd q̇`
/// with per-joint gains scaled by the joint-space inertia diagonal at `q_ref` (natural frequency
/// `freq` Hz, damping ratio `zeta`), so light wrists and heavy hips behave alike.
#[derive(Clone, Debug)]
pub struct PosturePd {
    pub q_ref: DVector<f64>,
    pub kp: DVector<f64>,
    pub kd: DVector<f64>,
    /// Effective joint inertias `1 / (M⁻¹)_jj` at `q_ref`.
    pub inertia: DVector<f64>,
    floating: bool,
}

impl PosturePd {
    pub fn new(
        model: &Model,
        q_ref: &DVector<f64>,
        freq: f64,
        zeta: f64,
    ) -> Result<Self, SimError> {
        let mut data = Data::new(model);
        let m = crate::dynamics::crba(model, &mut data, q_ref)?.clone();
        let minv = m
            .cholesky()
            .ok_or(SimError::Dynamics(
                crate::dynamics::DynamicsError::Singular("M(q_ref)"),
            ))?
            .inverse();
        let floating = model.has_floating_base();
        let start = if floating { 6 } else { 0 };
        let n = model.nv - start;
        // Effective inertia of each joint when the rest of the body is free: 1 / (M⁻¹)_jj.
        let inertia = DVector::from_fn(n, |i, _| 1.0 / minv[(start + i, start + i)]);
        let w = 2.0 * std::f64::consts::PI * freq;
        let kp = inertia.map(|i| i * w * w);
        let kd = inertia.map(|i| 2.0 * zeta * i * w);
        Ok(Self {
            q_ref: q_ref.clone(),
            kp,
            kd,
            inertia,
            floating,
        })
    }

    /// Raises the gains of the joints that support one of the frames `carrying` (the soles and
    /// the arm chain's root: legs and torso) to at least (`kp`, `kd`). The inertia diagonal
    /// underestimates what a standing leg carries (the ankle's subtree is the foot alone, but it
    /// holds the whole body up), so legs and torso need floors.
    pub fn with_floor(mut self, model: &Model, carrying: &[usize], kp: f64, kd: f64) -> Self {
        let start = if self.floating { 6 } else { 0 };
        for i in 0..self.kp.len() {
            let joint = model.dof_joint[start + i];
            let supports = |&f: &usize| {
                model
                    .frames
                    .get(f)
                    .and_then(|fr| fr.parent)
                    .is_some_and(|p| model.is_ancestor(joint, p))
            };
            if carrying.iter().any(supports) {
                self.kp[i] = self.kp[i].max(kp);
                self.kd[i] = self.kd[i].max(kd);
            }
        }
        self
    }

    /// Caps the gains to what an explicit PD evaluated once per step of `dt` keeps stable on
    /// each joint's effective inertia even with the foot in the air (`kd ≤ I/(2dt)`,
    /// `kp ≤ I/(2dt²)`).
    pub fn capped(mut self, dt: f64) -> Self {
        for i in 0..self.kp.len() {
            let inertia = self.inertia[i];
            self.kp[i] = self.kp[i].min(0.5 * inertia / (dt * dt));
            self.kd[i] = self.kd[i].min(0.5 * inertia / dt);
        }
        self
    }

    /// The posture PD the tests and the benchmark use for the humanoid: 6 Hz critically damped
    /// on the effective inertias, legs and torso raised to 800 N·m/rad and 10 N·m·s/rad, all
    /// capped for stability at the 1 ms step.
    pub fn standing(
        model: &Model,
        q_ref: &DVector<f64>,
        carrying: &[usize],
    ) -> Result<Self, SimError> {
        Ok(Self::new(model, q_ref, 6.0, 1.0)?
            .with_floor(model, carrying, 800.0, 10.0)
            .capped(1e-3))
    }

    /// The plant's hold (`[sim.hold]`): `cfg.frequency` and `cfg.damping_ratio` on the
    /// effective inertias at `q_ref`, legs and torso floored to `cfg.leg_kp`/`leg_kd`, capped for
    /// the step `dt`.
    pub fn hold(
        model: &Model,
        q_ref: &DVector<f64>,
        carrying: &[usize],
        cfg: &super::config::HoldConfig,
        dt: f64,
    ) -> Result<Self, SimError> {
        Ok(Self::new(model, q_ref, cfg.frequency, cfg.damping_ratio)?
            .with_floor(model, carrying, cfg.leg_kp, cfg.leg_kd)
            .capped(dt))
    }

    /// Torques into `out` (length nv − 6 or nv).
    pub fn torques(&self, q: &DVector<f64>, v: &DVector<f64>, out: &mut DVector<f64>) {
        let (sq, sv) = if self.floating { (7, 6) } else { (0, 0) };
        for i in 0..out.len() {
            out[i] = self.kp[i] * (self.q_ref[sq + i] - q[sq + i]) - self.kd[i] * v[sv + i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Λ from the door's URDF by hand: the leaf (12 kg, I_zz 0.6416 kg·m² at 0.4 m from the
    /// hinge) and the handle (0.2 kg at (0.72, −0.045) m, I_zz 1.7e-4), over r² of the handle
    /// frame at (0.72, −0.07) m. Rank one, along the handle's path (x at the home placement).
    #[test]
    fn the_doors_apparent_mass_at_the_handle_is_its_hinge_inertia_over_r_squared() {
        let robot = Robot::embedded_default().unwrap();
        let door = place_door(&robot).unwrap();
        let lambda = door.apparent_mass().unwrap();
        let inertia =
            0.6416 + 12.0 * 0.4f64.powi(2) + 1.7e-4 + 0.2 * (0.72f64.powi(2) + 0.045f64.powi(2));
        let r2 = 0.72f64.powi(2) + 0.07f64.powi(2);
        assert!((lambda.trace() - inertia / r2).abs() < 1e-9, "{lambda}");
        let e = door.axis.cross(&door.lever).normalize();
        assert!((lambda * e - e * (inertia / r2)).norm() < 1e-9);
        assert!((lambda * door.lever).norm() < 1e-9 && (lambda * door.axis).norm() < 1e-9);
        assert!(e.x.abs() > 0.99, "the handle moves along x: {e}");
    }
}
