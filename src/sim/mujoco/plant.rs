//! MuJoCo as a [`Physics`] of the plant runtime: the generated scene ([`super::build`]) compiled
//! by MuJoCo's C library, stepped under the joint torques and the door's hinge torque, and read
//! back in the contract's conventions.
//!
//! - Before time 0 the robot settles for [`SETTLE_TIME`] onto MuJoCo's soft contacts, held at its
//!   home posture ([`MujocoPlant::settle`]): upc's contacts are hard, a robot placed on MuJoCo's
//!   first sinks about a millimetre into them.
//! - As upc's [`super::super::World`] reports a step, forces (contacts, CoP, hand) are those of
//!   the step's constraint solve, at the configuration it started from; geometry (CoM,
//!   penetration, loop error) and slip are those after it, with the state's q and v.
//! - The hinge torque is sampled on the step grid ([`Physics::sample_time`]): MuJoCo's clock
//!   accumulates `dt`.

use nalgebra::{DVector, Vector3};

use super::ffi::{Mj, Obj};
use super::scene::{CONNECT, MujocoScene, PlantFile};
use crate::channels::N_CONTACTS;
use crate::dynamics::kinematics::{placements_unchecked, update_frame_placements};
use crate::dynamics::{Data, Model, PressureLoad, SE3, center_of_pressure};
use crate::robot::Robot;
use crate::sim::physics::{Physics, SimError, StepReport, rebase};

/// Simulated time the robot settles onto its soft contacts before a run starts (s).
pub const SETTLE_TIME: f64 = 0.5;

/// The door's objects in the MuJoCo model.
struct DoorIds {
    handle_site: usize,
    /// Hinge qpos and dof addresses.
    hq: usize,
    hv: usize,
    /// The hand–handle `connect` equality.
    connect: usize,
    /// upc's door model placed in the world, for the recording's poses.
    model: Model,
    data: Data,
    q: DVector<f64>,
}

/// MuJoCo stepping upc's scene.
pub struct MujocoPlant {
    mj: Mj,
    dt: f64,
    at: Addresses,
    effort: Vec<f64>,
    clamp: bool,
    spheres: Vec<usize>,
    /// Contract slot of each geom (`None`: not a contact sphere).
    slot_of: Vec<Option<usize>>,
    radius: f64,
    hand_site: usize,
    door: Option<DoorIds>,
    robot: Model,
    robot_data: Data,
    q: DVector<f64>,
    v: DVector<f64>,
    forces: Vec<Vector3<f64>>,
    points: Vec<Vector3<f64>>,
    steps: u64,
    /// How far the base sank while settling (m).
    settled: f64,
    applied: DVector<f64>,
    last: StepReport,
}

fn lookup(mj: &Mj, kind: Obj, name: &str) -> Result<usize, SimError> {
    mj.id(kind, name).ok_or_else(|| {
        SimError::Scene(format!(
            "the MuJoCo scene has no {} `{name}`",
            format!("{kind:?}").to_lowercase()
        ))
    })
}

/// Where the contract's q and v live in MuJoCo's qpos and qvel: contract q ← qpos (base
/// position, quaternion x y z w, joints), v[3..] ← qvel; the base's linear velocity (`bv`) and
/// body; each actuated joint's qpos and dof address.
struct Addresses {
    q_from: Vec<usize>,
    v_from: Vec<usize>,
    bv: usize,
    base_body: usize,
    qadr: Vec<usize>,
    dadr: Vec<usize>,
}

fn addresses(mj: &Mj, p: &PlantFile, nv: usize) -> Result<Addresses, SimError> {
    let base = lookup(mj, Obj::Joint, &p.base_joint)?;
    let (free, bq, bv, base_joint_body) = mj.joint(base);
    let base_body = lookup(mj, Obj::Body, &p.base_body)?;
    if !free || base_joint_body != base_body {
        return Err(SimError::Scene(format!(
            "base joint `{}` is not a free joint of body `{}`",
            p.base_joint, p.base_body
        )));
    }
    let mut qadr = Vec::with_capacity(p.joints.len());
    let mut dadr = Vec::with_capacity(p.joints.len());
    for name in &p.joints {
        let (_, qa, da, _) = mj.joint(lookup(mj, Obj::Joint, name)?);
        qadr.push(qa);
        dadr.push(da);
    }
    let n = qadr.len();
    if nv != n + 6 || p.home.len() != n + 7 {
        return Err(SimError::Scene(format!(
            "{n} joints in the MuJoCo scene, {} in the robot",
            nv.saturating_sub(6)
        )));
    }
    // MuJoCo's quaternion is w x y z, the contract's x y z w.
    let q_from = [bq, bq + 1, bq + 2, bq + 4, bq + 5, bq + 6, bq + 3]
        .into_iter()
        .chain(qadr.iter().copied())
        .collect();
    let v_from = [bv + 3, bv + 4, bv + 5]
        .into_iter()
        .chain(dadr.iter().copied())
        .collect();
    Ok(Addresses {
        q_from,
        v_from,
        bv,
        base_body,
        qadr,
        dadr,
    })
}

/// The door's objects, and upc's model of it placed in the world (the recording's poses).
fn door_ids(mj: &Mj, scene: &MujocoScene) -> Result<Option<DoorIds>, SimError> {
    let p = &scene.plant;
    let (Some(joint), Some(handle), Some(placed)) = (&p.door_joint, &p.handle_site, &scene.door)
    else {
        return Ok(None);
    };
    let (_, hq, hv, _) = mj.joint(lookup(mj, Obj::Joint, joint)?);
    let connect = match mj.id(Obj::Equality, CONNECT) {
        Some(c) => c,
        None if mj.neq() == 1 => 0,
        None => {
            return Err(SimError::Scene(format!(
                "no equality `{}` joining hand and handle",
                CONNECT
            )));
        }
    };
    let mut model = placed.model.clone();
    rebase(&mut model, &placed.base);
    Ok(Some(DoorIds {
        handle_site: lookup(mj, Obj::Site, handle)?,
        hq,
        hv,
        connect,
        data: Data::new(&model),
        q: model.neutral(),
        model,
    }))
}

impl MujocoPlant {
    /// Compiles `scene` (of `robot`), settles the robot onto its contacts and takes the state
    /// of time 0.
    pub fn new(robot: &Robot, scene: &MujocoScene) -> Result<MujocoPlant, SimError> {
        let p = &scene.plant;
        let mj = Mj::load(&scene.mjcf).map_err(SimError::Scene)?;
        if (mj.timestep() - p.sim.dt).abs() > 1e-15 {
            return Err(SimError::Scene(format!(
                "timestep {} ≠ sim.dt {}",
                mj.timestep(),
                p.sim.dt
            )));
        }
        let at = addresses(&mj, p, robot.model.nv)?;
        let n = at.qadr.len();
        let spheres = p
            .contacts
            .iter()
            .map(|g| lookup(&mj, Obj::Geom, g))
            .collect::<Result<Vec<_>, _>>()?;
        if spheres.len() != N_CONTACTS {
            return Err(SimError::Scene(format!(
                "{} contacts, the contract has {N_CONTACTS}",
                spheres.len()
            )));
        }
        let mut slot_of = vec![None; mj.ngeom()];
        for (k, &g) in spheres.iter().enumerate() {
            slot_of[g] = Some(k);
        }
        let hand_site = lookup(&mj, Obj::Site, &p.hand_site)?;
        let door = door_ids(&mj, scene)?;
        let model = robot.model.clone();
        let mut plant = MujocoPlant {
            dt: p.sim.dt,
            at,
            effort: p
                .effort
                .iter()
                .map(|e| e.unwrap_or(f64::INFINITY))
                .collect(),
            clamp: p.sim.effort_limits,
            slot_of,
            radius: p.contact_radius,
            hand_site,
            door,
            robot_data: Data::new(&model),
            robot: model,
            q: DVector::zeros(n + 7),
            v: DVector::zeros(n + 6),
            forces: vec![Vector3::zeros(); N_CONTACTS],
            points: vec![Vector3::zeros(); N_CONTACTS],
            steps: 0,
            settled: 0.0,
            applied: DVector::zeros(n),
            last: StepReport::default(),
            spheres,
            mj,
        };
        for (k, &a) in plant.at.q_from.iter().enumerate() {
            plant.mj.qpos_mut()[a] = p.home[k];
        }
        if let Some(d) = &plant.door {
            let hq = d.hq;
            plant.mj.qpos_mut()[hq] = 0.0;
        }
        plant.settled = plant.settle(&p.hold.kp, &p.hold.kd)?;
        plant.last = plant.after_step(0.0);
        Ok(plant)
    }

    /// How far the base sank while the robot settled onto its contacts (m).
    pub fn settle_sink(&self) -> f64 {
        self.settled
    }

    /// Lets the robot settle onto its contacts, held at its home posture, then starts the run
    /// from there at rest, time 0. The hold is the posture PD of the hold's gains, plus gravity
    /// compensation on the joints with no contact point below them (torso, arms, head: what
    /// hangs on them is exactly MuJoCo's bias force); the PD alone, its gains scaled to each
    /// joint's inertia, lets the arms sag by up to 0.3 rad. The legs carry the body through
    /// the ground, which the bias force does not know: there the PD alone. Returns how far the
    /// base sank (m).
    fn settle(&mut self, kp: &[f64], kd: &[f64]) -> Result<f64, SimError> {
        let n = self.at.dadr.len();
        if kp.len() != n || kd.len() != n {
            return Err(SimError::Scene(format!(
                "hold gains for {}, {} joints, the robot has {n}",
                kp.len(),
                kd.len()
            )));
        }
        let z0 = self.mj.qpos()[self.at.q_from[2]];
        let q_home: Vec<f64> = self.at.qadr.iter().map(|&a| self.mj.qpos()[a]).collect();
        // Bodies with a contact sphere on them or below them.
        let mut carrying = std::collections::HashSet::new();
        for &g in &self.spheres {
            let mut b = self.mj.geom_body(g);
            while b > 0 {
                carrying.insert(b);
                b = self.mj.body_parent(b);
            }
        }
        let hanging: Vec<f64> = self
            .at
            .dadr
            .iter()
            .map(|&a| f64::from(u8::from(!carrying.contains(&self.mj.dof_body(a)))))
            .collect();
        let (qadr, dadr) = (self.at.qadr.clone(), self.at.dadr.clone());
        let hold = |mj: &mut Mj, with_damping: bool| {
            let tau: Vec<f64> = (0..n)
                .map(|i| {
                    let (qa, da) = (qadr[i], dadr[i]);
                    let mut t = kp[i] * (q_home[i] - mj.qpos()[qa]);
                    if with_damping {
                        t -= kd[i] * mj.qvel()[da];
                    }
                    t + hanging[i] * mj.qfrc_bias()[da]
                })
                .collect();
            let f = mj.qfrc_applied_mut();
            for (i, &da) in dadr.iter().enumerate() {
                f[da] = tau[i];
            }
        };
        for _ in 0..(SETTLE_TIME / self.dt).round() as usize {
            self.mj.forward(); // qfrc_bias (gravity, Coriolis) of this state
            hold(&mut self.mj, true);
            self.mj.step();
        }
        if self.mj.diverged() {
            return Err(SimError::Scene(
                "the robot does not stand in the scene: MuJoCo diverged while it settled onto \
                 its contacts, held at its home posture"
                    .into(),
            ));
        }
        // At rest where it settled, time 0. The forward pass has the hold's static torques, so
        // that the forces of state 0 are those of the robot held up, not collapsing.
        self.mj.qvel_mut().fill(0.0);
        self.mj.set_time(0.0);
        self.mj.forward();
        hold(&mut self.mj, false);
        self.mj.forward();
        self.mj.qfrc_applied_mut().fill(0.0);
        Ok(z0 - self.mj.qpos()[self.at.q_from[2]])
    }

    /// The figures and the state of the step just made (or of state 0's forward pass).
    fn after_step(&mut self, door_torque: f64) -> StepReport {
        // Forces: MuJoCo's constraint solve of the step, at the configuration it started from.
        self.read_contact_forces();
        let (total, zmp, active) = self.centre_of_pressure();
        let hand_force = self.hand_force();
        let solver_iterations = self.mj.solver_niter();
        // Geometry and velocities after the step.
        self.mj.positions_velocities();
        let (max_penetration, max_slip_speed) = self.contact_geometry();
        let loop_error = self.read_state();
        StepReport {
            step: self.steps,
            time: self.mj.time(),
            solver_iterations,
            solver_change: 0.0,
            active_contacts: active,
            active_limits: 0,
            max_penetration,
            max_slip_speed,
            loop_error,
            zmp,
            total_normal_force: total,
            hand_force,
            door_torque,
            com: self.mj.subtree_com(self.at.base_body),
        }
    }

    /// Each contact sphere's force (world frame, ground on robot): the sum of its contacts'.
    fn read_contact_forces(&mut self) {
        for f in &mut self.forces {
            *f = Vector3::zeros();
        }
        for i in 0..self.mj.ncon() {
            let (geom, a) = self.mj.contact(i);
            // The contact frame's rows are the normal (geom 0 → geom 1) and two tangents; the
            // force in it acts on geom 1, its opposite on geom 0.
            let slot = |g: i32| usize::try_from(g).ok().and_then(|g| self.slot_of[g]);
            let (k, sign) = match (slot(geom[1]), slot(geom[0])) {
                (Some(k), _) => (k, 1.0),
                (None, Some(k)) => (k, -1.0),
                (None, None) => continue,
            };
            let f = self.mj.contact_force(i);
            let (fn_, f1, f2) = (f[0], f[1], f[2]);
            let c = &mut self.forces[k];
            c.x += sign * (a[0] * fn_ + a[3] * f1 + a[6] * f2);
            c.y += sign * (a[1] * fn_ + a[4] * f1 + a[7] * f2);
            c.z += sign * (a[2] * fn_ + a[5] * f1 + a[8] * f2);
        }
    }

    /// The CoP of the loaded points, at the spheres' lowest points (their centres in x, y):
    /// the total normal force, the CoP if any load, and the loaded points. A load ≤ 0 carries
    /// nothing.
    fn centre_of_pressure(&self) -> (f64, Option<[f64; 2]>, u32) {
        let loaded = self
            .spheres
            .iter()
            .enumerate()
            .filter(|&(k, _)| self.forces[k].z > 0.0);
        let p = center_of_pressure(loaded.map(|(k, &g)| {
            let p = self.mj.geom_xpos(g);
            PressureLoad::point(self.forces[k].z, Vector3::new(p[0], p[1], 0.0))
        }));
        (p.total, (p.loads > 0).then(|| p.point()), p.loads)
    }

    /// The door's force on the hand. Equality rows come first; the connect's residual is
    /// p_hand − p_handle, so its force (3 rows, world frame) acts on the hand.
    fn hand_force(&self) -> [f64; 3] {
        let Some(d) = &self.door else {
            return [0.0; 3];
        };
        match (0..self.mj.ne()).find(|&r| self.mj.efc_id(r) == d.connect) {
            Some(r) => [
                self.mj.efc_force(r),
                self.mj.efc_force(r + 1),
                self.mj.efc_force(r + 2),
            ],
            None => [0.0; 3],
        }
    }

    /// The contact points after the step; the deepest penetration below the ground (the
    /// plane z = 0) and the fastest loaded point's speed: a sphere's lowest point moves at
    /// v + ω × (−r ẑ).
    fn contact_geometry(&mut self) -> (f64, f64) {
        let mut lowest = f64::INFINITY;
        let mut fastest: f64 = 0.0;
        for (k, &g) in self.spheres.iter().enumerate() {
            let p = self.mj.geom_xpos(g);
            lowest = lowest.min(p[2]);
            self.points[k] = Vector3::new(p[0], p[1], p[2] - self.radius);
            if self.forces[k].z > 0.0 {
                let w = self.mj.geom_velocity(g);
                let (vx, vy) = (w[3] - w[1] * self.radius, w[4] + w[0] * self.radius);
                fastest = fastest.max(vx * vx + vy * vy);
            }
        }
        ((self.radius - lowest).max(0.0), fastest.sqrt())
    }

    /// q and v in the contract's conventions, the door's angle; the hand–handle distance.
    fn read_state(&mut self) -> f64 {
        let mut loop_error = 0.0;
        if let Some(d) = &mut self.door {
            let (a, b) = (
                self.mj.site_xpos(self.hand_site),
                self.mj.site_xpos(d.handle_site),
            );
            loop_error =
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            d.q[0] = self.mj.qpos()[d.hq];
        }
        let qpos = self.mj.qpos();
        for (k, &a) in self.at.q_from.iter().enumerate() {
            self.q[k] = qpos[a];
        }
        // MuJoCo's free joint: linear velocity in the world frame, angular in the body's.
        let (r, qvel) = (self.mj.xmat(self.at.base_body), self.mj.qvel());
        let lin = [qvel[self.at.bv], qvel[self.at.bv + 1], qvel[self.at.bv + 2]];
        for i in 0..3 {
            self.v[i] = lin[0] * r[i] + lin[1] * r[3 + i] + lin[2] * r[6 + i];
        }
        for (k, &a) in self.at.v_from.iter().enumerate() {
            self.v[3 + k] = qvel[a];
        }
        loop_error
    }
}

impl Physics for MujocoPlant {
    fn engine(&self) -> &'static str {
        "mujoco"
    }
    fn robot(&self) -> &Model {
        &self.robot
    }
    fn q(&self) -> &DVector<f64> {
        &self.q
    }
    fn v(&self) -> &DVector<f64> {
        &self.v
    }
    fn time(&self) -> f64 {
        self.mj.time()
    }
    fn steps(&self) -> u64 {
        self.steps
    }
    fn n_actuated(&self) -> usize {
        self.at.dadr.len()
    }
    fn contact_forces(&self) -> &[Vector3<f64>] {
        &self.forces
    }
    fn contact_points(&self) -> &[Vector3<f64>] {
        &self.points
    }
    fn last_report(&self) -> &StepReport {
        &self.last
    }
    fn door_angle(&self) -> f64 {
        self.door.as_ref().map_or(0.0, |d| self.mj.qpos()[d.hq])
    }
    fn door_velocity(&self) -> f64 {
        self.door.as_ref().map_or(0.0, |d| self.mj.qvel()[d.hv])
    }
    fn door_model(&self) -> Option<&Model> {
        self.door.as_ref().map(|d| &d.model)
    }
    fn sample_time(&self, t: f64) -> f64 {
        (t / self.dt).round() * self.dt
    }
    fn set_push(&mut self, _frame: usize, _force: Vector3<f64>) -> Result<(), SimError> {
        Err(SimError::Scene(
            "the MuJoCo plant pushes through the door only (sim.push = \"door\")".into(),
        ))
    }
    fn step(&mut self, tau: &DVector<f64>, door_torque: f64) -> Result<StepReport, SimError> {
        let n = self.at.dadr.len();
        if tau.len() != n {
            return Err(SimError::TorqueLength {
                expected: n,
                got: tau.len(),
            });
        }
        for i in 0..n {
            self.applied[i] = if self.clamp {
                tau[i].clamp(-self.effort[i], self.effort[i])
            } else {
                tau[i]
            };
        }
        let t_before = self.mj.time();
        let f = self.mj.qfrc_applied_mut();
        for (i, &da) in self.at.dadr.iter().enumerate() {
            f[da] = self.applied[i];
        }
        if let Some(d) = &self.door {
            f[d.hv] = door_torque;
        }
        self.mj.step();
        if self.mj.diverged() {
            // MuJoCo has reset the state to the model's zero pose: stop rather than publish it.
            return Err(SimError::Engine(format!(
                "the simulation diverged at t = {t_before:.3} s (MuJoCo: bad accelerations; \
                 typically a fall under torques the effort limits allow)"
            )));
        }
        self.steps += 1;
        self.last = self.after_step(door_torque);
        Ok(self.last)
    }
    fn robot_frame_placements(&mut self) -> &[SE3] {
        placements_unchecked(&self.robot, &mut self.robot_data, self.q.as_slice());
        update_frame_placements(&self.robot, &mut self.robot_data);
        &self.robot_data.o_m_f
    }
    fn door_frame_placements(&mut self) -> Option<&[SE3]> {
        let d = self.door.as_mut()?;
        placements_unchecked(&d.model, &mut d.data, d.q.as_slice());
        update_frame_placements(&d.model, &mut d.data);
        Some(&d.data.o_m_f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::SimConfig;

    fn plant(sets: &[&str]) -> (Robot, MujocoPlant) {
        let robot = Robot::embedded_default().expect("robot");
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        let cfg = SimConfig::load(&[], &sets).expect("config");
        let scenario = robot.scenario(&cfg.scenario).expect("scenario");
        let scene = super::super::scene::build(&robot, &cfg, &scenario).expect("scene");
        let plant = MujocoPlant::new(&robot, &scene).expect("plant");
        (robot, plant)
    }

    /// State 0, after the settle: at rest, the feet carry the robot's weight and the door's
    /// pull on the hand (the vertical forces balance m g within the hand's share), the CoP
    /// between the feet, the base a millimetre or so below home.
    #[test]
    fn the_settled_robot_stands_on_its_contacts_at_rest() {
        let (robot, p) = plant(&[]);
        let weight = robot.derived.mass * 9.81;
        let r = p.last_report();
        let hand_z = r.hand_force[2];
        let fz: f64 = p.contact_forces().iter().map(|f| f.z).sum();
        assert!(
            (fz + hand_z - weight).abs() < 0.02 * weight,
            "Σfz {fz} N + hand {hand_z} N vs m g {weight} N"
        );
        assert!((r.total_normal_force - fz).abs() < 1e-9);
        let zmp = r.zmp.expect("loaded");
        let xs: Vec<f64> = p.contact_points().iter().map(|c| c.x).collect();
        let ys: Vec<f64> = p.contact_points().iter().map(|c| c.y).collect();
        let inside = |v: f64, a: &[f64]| {
            a.iter().copied().fold(f64::INFINITY, f64::min) < v
                && v < a.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        };
        assert!(inside(zmp[0], &xs) && inside(zmp[1], &ys), "CoP {zmp:?}");
        assert!(p.v().amax() == 0.0, "at rest: {}", p.v().amax());
        let sink = p.settle_sink();
        assert!(sink > 0.0 && sink < 3e-3, "sank {sink} m");
        assert!((p.q()[2] - (robot.home[2] - sink)).abs() < 1e-12);
        // The contract's quaternion is x y z w and unit.
        let quat = p.q().fixed_rows::<4>(3).norm();
        assert!((quat - 1.0).abs() < 1e-9 && p.q()[6] > 0.99);
        assert_eq!((p.steps(), p.time()), (0, 0.0));
    }

    /// Torques far beyond what the robot can take, limits off: MuJoCo's divergence is an
    /// error of the step (no state of MuJoCo's reset is published), within a second.
    #[test]
    fn a_diverging_simulation_is_an_error_not_a_reset_state() {
        let (_, mut p) = plant(&["sim.effort_limits=false"]);
        let tau = DVector::from_fn(p.n_actuated(), |i, _| if i % 2 == 0 { 1e9 } else { -1e9 });
        let mut failed = None;
        for _ in 0..1000 {
            if let Err(e) = p.step(&tau, 0.0) {
                failed = Some(e);
                break;
            }
        }
        match failed {
            Some(SimError::Engine(m)) => assert!(m.contains("diverged"), "{m}"),
            other => panic!("expected MuJoCo to diverge: {other:?}"),
        }
    }

    /// The recording's poses come from upc's kinematics of the published q: the hand frame is
    /// where MuJoCo's hand site is, the handle where the handle site is (up to the loop's
    /// softness), after a few steps under the hold's posture torques.
    #[test]
    fn recorded_poses_are_mujocos() {
        let (robot, mut p) = plant(&[]);
        let tau = DVector::zeros(p.n_actuated());
        for _ in 0..50 {
            p.step(&tau, 0.0).expect("step");
        }
        let hand = robot
            .model
            .frame_id(&robot.description.hand.frame)
            .expect("hand");
        let site = p.mj.site_xpos(p.hand_site);
        let ours = p.robot_frame_placements()[hand].trans;
        let d = (ours - Vector3::from(site)).norm();
        assert!(d < 1e-9, "hand frame {d} m from MuJoCo's site");
        let handle_site = p.door.as_ref().expect("door").handle_site;
        let handle_mj = p.mj.site_xpos(handle_site);
        let handle = p
            .door_model()
            .expect("door")
            .frame_id(crate::sim::scene::HANDLE_FRAME)
            .expect("handle");
        let ours = p.door_frame_placements().expect("door")[handle].trans;
        let d = (ours - Vector3::from(handle_mj)).norm();
        assert!(d < 1e-9, "handle frame {d} m from MuJoCo's site");
    }
}
