//! The physics of the simulator, without any IPC: a robot (any URDF model, floating or fixed
//! base) standing on a plane through contact points, optionally a door joined to a robot frame
//! by a spherical joint, stepped at a fixed `dt`.
//!
//! One step (semi-implicit Euler at the velocity level, Moreau–Jean time stepping):
//! 1. `M(q)` (CRBA) of the robot and the door; joint damping `D` is integrated implicitly, so
//!    the factorised matrix is `M + dt D` (block-diagonal: robot, door), factorised by the
//!    tree-sparse `LᵀDL` ([`super::factor`]);
//! 2. free velocity `v* = v + dt (M + dt D)⁻¹ (Sᵀτ − D v − h(q, v̄))`, the velocity-dependent
//!    forces `h = C(q, ·)· + g` (RNEA) taken at the midpoint `v̄ = ½ (v + v*)` (below): a
//!    predictor with `v̄ = v`, then [`MIDPOINT_PASSES`] fixed-point passes, each one RNEA and
//!    one solve with the factor of step 1;
//! 3. constraint rows at `q`: every contact point (normal + 2 tangents of the plane), the three
//!    rows of the hand–handle point constraint, and the joint limits about to be crossed;
//!    velocity targets remove a fraction of the penetration / loop gap per step
//!    (`contact_stabilisation`, `loop_stabilisation`); a contact still above the plane may
//!    approach it by at most its gap in this step (speculative contact, so nothing tunnels);
//! 4. impulses `λ` from [`ConstraintSystem`]: a direct solve with every row at zero velocity
//!    (all contacts sticking) when its result is admissible, projected Gauss–Seidel from the
//!    previous step's impulses otherwise (Coulomb cones);
//! 5. `v⁺ = v* + (M + dt D)⁻¹ Jᵀ λ`, `q⁺ = q ⊕ v⁺ dt` (SE(3) for the free-flyer).
//!
//! Why `h` at the midpoint. At fixed `q` the kinetic energy changes by `v̄ᵀ M Δv`, exactly the
//! work of the forces at `v̄`; moving `q` along `v⁺` adds `½ v⁺ᵀ (M(q⁺) − M(q)) v⁺
//! ≈ dt v⁺ᵀ C(q, v⁺) v⁺` (`vᵀ (Ṁ − 2C) v = 0`). The Coriolis work `−dt v̄ᵀ C(q, v̄) v̄` cancels it
//! but for `dt (f(v⁺) − f(v̄)) ≈ ½ dt (f(v⁺) − f(v))` (`f` cubic in `v`): a difference of
//! consecutive steps, which telescopes into a bounded O(dt) oscillation of the energy, no drift.
//! `h` at `v` (explicit) leaves an O(dt²) per-step term that does not telescope: a drift of
//! O(dt) per unit time (+0.13 %/s on an undamped double pendulum at 1 ms; on a free body
//! `ω × Iω` gains `½ dt² |ω × Iω|²_{I⁻¹}` every step). `h` at `v*` (implicit Euler) leaves
//! `−½ Δvᵀ M Δv`, an artificial damping of the same size. On a single rigid body the midpoint
//! is the implicit midpoint rule, which conserves its quadratic invariants (kinetic energy,
//! `|angular momentum|`) exactly (Hairer, Lubich, Wanner, *Geometric Numerical Integration*,
//! §IV.2). The fixed point is iterated, not solved: one pass would be the explicit midpoint
//! rule (RK2), whose amplification on an oscillation, `|1 + z + z²/2| = √(1 + y⁴/4)` for
//! `z = iy = iω dt`, slowly gains energy; two passes give `|1 + z + z²/2 + z³/4|² = 1 − y⁴/4 +
//! y⁶/16 < 1` (y < 2): a dissipation of O(dt⁴), negligible. `M(q)` stays at the start of the
//! step (one CRBA and one factorisation per step, shared with the constraints). The constraint
//! rows and impulses (step 3–5) are unchanged: solved on the final velocity level `v⁺`.
//!
//! Forces reported are `λ / dt`. Construction allocates; [`World::step`] does not, never panics
//! on bad input (errors instead), and leaves the state untouched when it fails.

use nalgebra::{DMatrix, DVector, Vector3};

use crate::dynamics::{
    JointKind, Model, PressureLoad, SE3, center_of_pressure, crba, integrate, kinematics,
    nonlinear_effects,
};

use super::config::SimConfig;
use super::contact::{BlockKind, ConstraintSystem, SolverSettings};
use super::factor::LtdlFactor;
use super::physics::{Physics, SimError, StepReport, rebase};

/// Fixed-point passes of the midpoint evaluation of `h` after the predictor (module doc: one
/// pass is the explicit midpoint rule, which slowly gains energy; two lose a little).
const MIDPOINT_PASSES: usize = 2;

/// Normal force (N) above which a contact carries load (its impulse over `dt`).
const LOADED: f64 = 1e-9;

/// A plane `{x : n·x = offset}` (unit normal `n`, pointing out of the ground).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: Vector3<f64>,
    pub offset: f64,
}

impl Plane {
    /// The ground `z = 0`.
    pub fn ground() -> Self {
        Self {
            normal: Vector3::z(),
            offset: 0.0,
        }
    }

    /// A plane through the origin tilted by `angle` about the world y axis (it descends
    /// towards +x for a positive angle).
    pub fn slope(angle: f64) -> Self {
        Self {
            normal: Vector3::new(angle.sin(), 0.0, angle.cos()),
            offset: 0.0,
        }
    }

    /// The same plane with a unit normal; refused for a zero or non-finite normal or offset.
    fn normalised(self) -> Result<Self, SimError> {
        let n = self.normal.norm();
        if !(n > 0.0 && n.is_finite() && self.offset.is_finite()) {
            return Err(SimError::Scene(
                "ground normal must be a non-zero vector".into(),
            ));
        }
        Ok(Plane {
            normal: self.normal / n,
            offset: self.offset / n,
        })
    }

    /// Signed distance of a point (positive above).
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(p) - self.offset
    }

    /// Two unit tangents completing the normal to a right-handed basis (t₁ in the x–z plane
    /// when possible).
    pub fn tangents(&self) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.normal;
        let seed = if n.y.abs() < 0.9 {
            Vector3::y()
        } else {
            Vector3::x()
        };
        let t1 = seed.cross(&n).normalize();
        let t2 = n.cross(&t1);
        (t1, t2)
    }
}

/// Physical and numerical parameters of the stepping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhysicsParams {
    pub dt: f64,
    /// Coulomb friction coefficient of every contact.
    pub friction: f64,
    /// Viscous damping of every robot joint except the free-flyer (N·m·s/rad or N·s/m).
    pub joint_damping: f64,
    /// Viscous damping of the door's joints.
    pub door_damping: f64,
    pub joint_limits: bool,
    pub effort_limits: bool,
    pub solver: SolverSettings,
    pub contact_stabilisation: f64,
    pub loop_stabilisation: f64,
}

impl PhysicsParams {
    pub fn from_config(c: &SimConfig) -> Self {
        Self {
            dt: c.dt,
            friction: c.friction,
            joint_damping: c.joint_damping,
            door_damping: c.door_damping,
            joint_limits: c.joint_limits,
            effort_limits: c.effort_limits,
            solver: SolverSettings {
                max_iterations: c.solver.max_iterations,
                tolerance: c.solver.tolerance,
                regularisation: c.solver.regularisation,
            },
            contact_stabilisation: c.solver.contact_stabilisation,
            loop_stabilisation: c.solver.loop_stabilisation,
        }
    }
}

impl Default for PhysicsParams {
    #[allow(
        clippy::expect_used,
        reason = "the embedded config is a constant of the binary, checked by the config tests"
    )]
    fn default() -> Self {
        Self::from_config(&SimConfig::embedded().expect("the embedded sim config is valid"))
    }
}

/// A door (or any fixed-base mechanism) joined to the robot by a spherical joint.
#[derive(Clone, Debug)]
pub struct DoorSpec {
    /// Fixed-base model, in its own coordinates (placed by `base`).
    pub model: Model,
    /// World placement of the door model's root.
    pub base: SE3,
    /// Frame of the door model held by the robot (its origin is the joint centre).
    pub handle_frame: String,
    /// Frame of the robot holding the door.
    pub hand_frame: String,
}

/// Everything a [`World`] is built from.
#[derive(Clone, Debug)]
pub struct WorldSpec {
    pub robot: Model,
    /// Frames of the robot that touch the ground (their origins are the contact points).
    pub contact_frames: Vec<String>,
    pub ground: Plane,
    pub door: Option<DoorSpec>,
    pub params: PhysicsParams,
}

#[derive(Clone, Copy, Debug)]
struct ContactPoint {
    joint: usize,
    local: Vector3<f64>,
}

#[derive(Clone, Copy, Debug)]
struct LimitedDof {
    /// Index in the combined velocity vector.
    dof: usize,
    /// Door (true) or robot configuration index.
    door: bool,
    iq: usize,
    lower: f64,
    upper: f64,
}

struct Door {
    model: Model,
    data: crate::dynamics::Data,
    q: DVector<f64>,
    v: DVector<f64>,
    q_next: DVector<f64>,
    /// Velocity at which h is evaluated (corrector scratch).
    vh: DVector<f64>,
    handle: ContactPoint,
    hand: ContactPoint,
}

impl Door {
    /// The door of `spec` placed in the world, at its neutral configuration and at rest, joined
    /// to `robot`'s hand frame.
    fn new(spec: DoorSpec, robot: &Model) -> Result<Door, SimError> {
        let mut model = spec.model;
        if model.has_floating_base() {
            return Err(SimError::Scene(
                "the door model must have a fixed base".into(),
            ));
        }
        rebase(&mut model, &spec.base);
        let handle = point_of(&model, &spec.handle_frame)?;
        let hand = point_of(robot, &spec.hand_frame)?;
        let data = crate::dynamics::Data::new(&model);
        let q = model.neutral();
        let v = DVector::zeros(model.nv);
        let q_next = q.clone();
        let vh = v.clone();
        Ok(Door {
            model,
            data,
            q,
            v,
            q_next,
            vh,
            handle,
            hand,
        })
    }
}

/// The simulated scene and its preallocated workspace.
pub struct World {
    robot: Model,
    data: crate::dynamics::Data,
    q: DVector<f64>,
    v: DVector<f64>,
    q_next: DVector<f64>,
    door: Option<Door>,
    contacts: Vec<ContactPoint>,
    contact_names: Vec<String>,
    ground: Plane,
    tangents: (Vector3<f64>, Vector3<f64>),
    params: PhysicsParams,
    n_act: usize,
    effort: Vec<f64>,
    damping: DVector<f64>,
    limits: Vec<LimitedDof>,
    nvt: usize,
    factor: LtdlFactor,
    sys: ConstraintSystem,
    /// Combined-velocity scratch: force, v*, impulse.
    force: DVector<f64>,
    vstar: DVector<f64>,
    dv: DVector<f64>,
    /// Robot velocity at which h is evaluated (corrector scratch).
    vh: DVector<f64>,
    warm: DVector<f64>,
    /// Per contact: world point (at the start of the last step), force (N, world).
    points: Vec<Vector3<f64>>,
    /// The contact points of the step under way, committed to `points` with the state.
    step_points: Vec<Vector3<f64>>,
    forces: Vec<Vector3<f64>>,
    time: f64,
    steps: u64,
    last: StepReport,
    /// An external force on a robot point for the next steps (`sim.push = "hand"`): the point
    /// and the force (N, world).
    push: Option<(ContactPoint, Vector3<f64>)>,
    /// Tests: make the next steps fail at their last fallible stage (after the integration).
    #[cfg(test)]
    fail_after_integration: bool,
}

/// The viscous damping of each of the `nvt` combined dofs: the robot's `nv` joints (not a
/// floating base's six) then the door's.
fn joint_damping(params: &PhysicsParams, floating: bool, nv: usize, nvt: usize) -> DVector<f64> {
    let mut damping = DVector::zeros(nvt);
    for k in 0..nv {
        if !(floating && k < 6) {
            damping[k] = params.joint_damping;
        }
    }
    for k in nv..nvt {
        damping[k] = params.door_damping;
    }
    damping
}

fn dof_parents(model: &Model, offset: usize, out: &mut Vec<Option<usize>>) {
    for j in &model.joints {
        for k in 0..j.nv() {
            let p = if k > 0 {
                Some(offset + j.idx_v + k - 1)
            } else {
                j.parent.map(|p| {
                    let pj = &model.joints[p];
                    offset + pj.idx_v + pj.nv() - 1
                })
            };
            out.push(p);
        }
    }
}

fn point_of(model: &Model, frame: &str) -> Result<ContactPoint, SimError> {
    let f = &model.frames[model.frame_id(frame)?];
    let joint = f.parent.ok_or_else(|| {
        SimError::Scene(format!(
            "frame '{frame}' is fixed to the world, it cannot move"
        ))
    })?;
    Ok(ContactPoint {
        joint,
        local: f.placement.trans,
    })
}

fn limited_dofs(model: &Model, offset: usize, door: bool, out: &mut Vec<LimitedDof>) {
    for j in &model.joints {
        if j.kind == JointKind::FreeFlyer {
            continue;
        }
        let l = j.limits;
        if l.lower.is_finite() || l.upper.is_finite() {
            out.push(LimitedDof {
                dof: offset + j.idx_v,
                door,
                iq: j.idx_q,
                lower: l.lower,
                upper: l.upper,
            });
        }
    }
}

/// World position of a body point.
#[inline]
fn world_point(data: &crate::dynamics::Data, c: &ContactPoint) -> Vector3<f64> {
    let o = &data.o_m_i[c.joint];
    o.rot * c.local + o.trans
}

/// Writes `sign · axisᵀ · (v_point)` Jacobian entries of a body point into `jt[.., col]`, for
/// the dofs supporting `joint` (world Jacobian columns in `data.j`), at `offset`.
#[allow(clippy::too_many_arguments)]
fn point_rows(
    model: &Model,
    data: &crate::dynamics::Data,
    joint: usize,
    p: &Vector3<f64>,
    axes: &[Vector3<f64>],
    sign: f64,
    offset: usize,
    jt: &mut DMatrix<f64>,
    col: usize,
) {
    let mut cur = Some(joint);
    while let Some(a) = cur {
        let ja = &model.joints[a];
        for c in ja.idx_v..ja.idx_v + ja.nv() {
            let s = data.j.fixed_view::<6, 1>(0, c);
            let lin = Vector3::new(s[0], s[1], s[2]);
            let ang = Vector3::new(s[3], s[4], s[5]);
            let vel = lin + ang.cross(p);
            for (k, ax) in axes.iter().enumerate() {
                jt[(offset + c, col + k)] = sign * ax.dot(&vel);
            }
        }
        cur = ja.parent;
    }
}

impl World {
    /// Builds the world at state `(q, v)` of the robot (the door starts at its neutral
    /// configuration, at rest).
    pub fn new(spec: WorldSpec, q: DVector<f64>, v: DVector<f64>) -> Result<World, SimError> {
        let WorldSpec {
            robot,
            contact_frames,
            ground,
            door,
            params,
        } = spec;
        robot.check_q(&q)?;
        robot.check_v("v", &v)?;
        if !(params.dt > 0.0 && params.dt.is_finite()) {
            return Err(SimError::Scene(format!(
                "dt must be > 0, got {}",
                params.dt
            )));
        }
        let ground = ground.normalised()?;
        let floating = robot
            .joints
            .first()
            .is_some_and(|j| j.kind == JointKind::FreeFlyer);
        let n_act = if floating { robot.nv - 6 } else { robot.nv };
        let start = robot.nv - n_act;
        let effort: Vec<f64> = (start..robot.nv)
            .map(|k| robot.joints[robot.dof_joint[k]].limits.effort)
            .collect();
        let contacts = contact_frames
            .iter()
            .map(|f| point_of(&robot, f))
            .collect::<Result<Vec<_>, _>>()?;
        let mut parents = Vec::new();
        dof_parents(&robot, 0, &mut parents);
        let mut limits = Vec::new();
        if params.joint_limits {
            limited_dofs(&robot, 0, false, &mut limits);
        }
        let door = match door {
            None => None,
            Some(d) => {
                let door = Door::new(d, &robot)?;
                // The door's dofs follow the robot's in the combined velocity.
                dof_parents(&door.model, robot.nv, &mut parents);
                if params.joint_limits {
                    limited_dofs(&door.model, robot.nv, true, &mut limits);
                }
                Some(door)
            }
        };
        let nvt = parents.len();
        let factor = LtdlFactor::new(parents)
            .ok_or_else(|| SimError::Scene("joints are not ordered parents first".into()))?;
        let damping = joint_damping(&params, floating, robot.nv, nvt);
        let max_rows = 3 * contacts.len() + if door.is_some() { 3 } else { 0 } + limits.len();
        let nc = contacts.len();
        let data = crate::dynamics::Data::new(&robot);
        let q_next = q.clone();
        let nv_robot = robot.nv;
        let mut w = World {
            data,
            q,
            v,
            q_next,
            door,
            contact_names: contact_frames,
            tangents: ground.tangents(),
            ground,
            params,
            n_act,
            effort,
            damping,
            limits,
            nvt,
            factor,
            sys: ConstraintSystem::new(nvt, max_rows.max(1)),
            force: DVector::zeros(nvt),
            vstar: DVector::zeros(nvt),
            dv: DVector::zeros(nvt),
            vh: DVector::zeros(nv_robot),
            warm: DVector::zeros(3 * nc + 3),
            points: vec![Vector3::zeros(); nc],
            step_points: vec![Vector3::zeros(); nc],
            forces: vec![Vector3::zeros(); nc],
            contacts,
            robot,
            time: 0.0,
            steps: 0,
            last: StepReport::default(),
            push: None,
            #[cfg(test)]
            fail_after_integration: false,
        };
        w.refresh_points();
        Ok(w)
    }

    fn refresh_points(&mut self) {
        kinematics::placements_unchecked(&self.robot, &mut self.data, self.q.as_slice());
        for (p, c) in self.points.iter_mut().zip(&self.contacts) {
            *p = world_point(&self.data, c);
        }
        if let Some(d) = &mut self.door {
            kinematics::placements_unchecked(&d.model, &mut d.data, d.q.as_slice());
        }
        // Before the first step the report is the initial state's (its CoM, penetration, loop
        // error): the plant publishes it as state 0, and watchers measure from it.
        if self.steps == 0 {
            let mut report = StepReport::default();
            self.refresh_points_after(&mut report);
            self.last = report;
        }
    }

    /// Applies `force` (N, world) at the origin of the robot frame `frame` from the next step
    /// on, until changed: the scenario's hand force without a door (`sim.push = "hand"`).
    pub fn set_push(&mut self, frame: usize, force: Vector3<f64>) -> Result<(), SimError> {
        let f = self
            .robot
            .frames
            .get(frame)
            .ok_or_else(|| SimError::Scene(format!("no robot frame #{frame} to push")))?;
        let joint = f
            .parent
            .ok_or_else(|| SimError::Scene(format!("frame `{}` is not on a body", f.name)))?;
        if force.iter().any(|v| !v.is_finite()) {
            return Err(SimError::NonFinite {
                what: "hand push",
                index: 0,
            });
        }
        let point = ContactPoint {
            joint,
            local: f.placement.trans,
        };
        self.push = Some((point, force));
        Ok(())
    }

    /// Advances one step under joint torques `tau` (length [`World::n_actuated`]) and the
    /// door's hinge torque. On error the state (q, v, time, steps, the door's, the contact
    /// points and the warm start) is unchanged: every fallible stage writes scratch only, and
    /// the new state is committed after the last of them. The stages are the module doc's.
    pub fn step(&mut self, tau: &DVector<f64>, door_torque: f64) -> Result<StepReport, SimError> {
        self.check_inputs(tau, door_torque)?;
        // 1. M(q) (CRBA) of the robot and the door, and the factor of M + dt D.
        self.factor_mass_matrix()?;
        self.applied_forces(tau, door_torque);
        // 2. Free velocity with h(q, ·) at the midpoint v̄ = ½(v + v*).
        self.free_velocity()?;
        // 3. Constraint rows.
        self.sys.clear();
        self.contact_rows()?;
        let loop_row = self.loop_rows()?;
        let active_limits = self.limit_rows();
        // 4. Impulses.
        self.sys
            .assemble(&self.factor, self.params.solver.regularisation);
        let stats = self.sys.solve(&self.params.solver);
        // 5. Velocity update, checked before anything is committed.
        self.constrained_velocity()?;
        // 6. Positions from the new velocities, into scratch.
        self.integrate_positions()?;
        #[cfg(test)]
        if self.fail_after_integration {
            return Err(SimError::Diverged(0));
        }
        // 7. Commit: nothing below fails.
        self.commit();
        let mut report = StepReport {
            step: self.steps,
            time: self.time,
            solver_iterations: stats.iterations as u32,
            solver_change: stats.last_change,
            active_limits,
            door_torque,
            ..StepReport::default()
        };
        self.report_forces(&mut report, loop_row);
        self.refresh_points_after(&mut report);
        self.last = report;
        Ok(report)
    }

    /// Refuses torques of the wrong length and non-finite inputs before anything runs.
    fn check_inputs(&self, tau: &DVector<f64>, door_torque: f64) -> Result<(), SimError> {
        if tau.len() != self.n_act {
            return Err(SimError::TorqueLength {
                expected: self.n_act,
                got: tau.len(),
            });
        }
        if let Some(i) = tau.iter().position(|t| !t.is_finite()) {
            return Err(SimError::NonFinite {
                what: "joint torque",
                index: i,
            });
        }
        if !door_torque.is_finite() {
            return Err(SimError::NonFinite {
                what: "door torque",
                index: 0,
            });
        }
        Ok(())
    }

    /// Stage 1: `M + dt D` (block-diagonal: robot, door) into the factor, factorised. CRBA
    /// leaves the robot's world Jacobian columns in `data.j` for the push.
    fn factor_mass_matrix(&mut self) -> Result<(), SimError> {
        let dt = self.params.dt;
        let nv = self.robot.nv;
        crba(&self.robot, &mut self.data, &self.q)?;
        {
            let mm = self.factor.matrix_mut();
            mm.view_mut((0, 0), (nv, nv)).copy_from(&self.data.m);
        }
        if let Some(d) = &mut self.door {
            crba(&d.model, &mut d.data, &d.q)?;
            let nd = d.model.nv;
            self.factor
                .matrix_mut()
                .view_mut((nv, nv), (nd, nd))
                .copy_from(&d.data.m);
        }
        {
            let mm = self.factor.matrix_mut();
            for k in 0..self.nvt {
                mm[(k, k)] += dt * self.damping[k];
            }
        }
        self.factor.factor()?;
        Ok(())
    }

    /// Applied forces into `force`, independent of the velocity at which h is taken: Sᵀτ − D v
    /// (τ within the effort limits), the push's Jᵀ f and the hinge torque.
    fn applied_forces(&mut self, tau: &DVector<f64>, door_torque: f64) {
        let nv = self.robot.nv;
        let start = nv - self.n_act;
        for k in 0..nv {
            self.force[k] = -self.damping[k] * self.v[k];
        }
        for (i, t) in tau.iter().enumerate() {
            let t = if self.params.effort_limits {
                let e = self.effort[i];
                t.max(-e).min(e)
            } else {
                *t
            };
            self.force[start + i] += t;
        }
        // The push: τ += Jᵀ f at the point (CRBA left the world Jacobian columns in data.j).
        if let Some((c, f)) = &self.push {
            let p = world_point(&self.data, c);
            let mut cur = Some(c.joint);
            while let Some(a) = cur {
                let ja = &self.robot.joints[a];
                for col in ja.idx_v..ja.idx_v + ja.nv() {
                    let s = self.data.j.fixed_view::<6, 1>(0, col);
                    let lin = Vector3::new(s[0], s[1], s[2]);
                    let ang = Vector3::new(s[3], s[4], s[5]);
                    self.force[col] += (lin + ang.cross(&p)).dot(f);
                }
                cur = ja.parent;
            }
        }
        if let Some(d) = &self.door {
            let nd = d.model.nv;
            for k in 0..nd {
                self.force[nv + k] = -self.damping[nv + k] * d.v[k];
            }
            if nd > 0 {
                self.force[nv] += door_torque;
            }
        }
    }

    /// Stage 2: the free velocity `vstar` with h(q, ·) at the midpoint v̄ = ½(v + v*): predictor
    /// with h at v, then fixed-point passes with v̄ from the previous pass's v* (module doc).
    fn free_velocity(&mut self) -> Result<(), SimError> {
        let dt = self.params.dt;
        let nv = self.robot.nv;
        for pass in 0..=MIDPOINT_PASSES {
            if pass == 0 {
                nonlinear_effects(&self.robot, &mut self.data, &self.q, &self.v)?;
            } else {
                for k in 0..nv {
                    self.vh[k] = 0.5 * (self.v[k] + self.vstar[k]);
                }
                nonlinear_effects(&self.robot, &mut self.data, &self.q, &self.vh)?;
            }
            for k in 0..nv {
                self.dv[k] = self.force[k] - self.data.tau[k];
            }
            if let Some(d) = &mut self.door {
                let nd = d.model.nv;
                if pass == 0 {
                    nonlinear_effects(&d.model, &mut d.data, &d.q, &d.v)?;
                } else {
                    for k in 0..nd {
                        d.vh[k] = 0.5 * (d.v[k] + self.vstar[nv + k]);
                    }
                    nonlinear_effects(&d.model, &mut d.data, &d.q, &d.vh)?;
                }
                for k in 0..nd {
                    self.dv[nv + k] = self.force[nv + k] - d.data.tau[k];
                }
            }
            self.factor.solve(self.dv.as_mut_slice());
            for k in 0..nv {
                self.vstar[k] = self.v[k] + dt * self.dv[k];
            }
            if let Some(d) = &self.door {
                for k in 0..d.model.nv {
                    self.vstar[nv + k] = d.v[k] + dt * self.dv[nv + k];
                }
            }
        }
        Ok(())
    }

    /// Stage 3, contacts: normal and two tangent rows per contact point, warm-started from the
    /// last step's impulses; the points go to `step_points`.
    fn contact_rows(&mut self) -> Result<(), SimError> {
        let dt = self.params.dt;
        let n = self.ground.normal;
        let (t1, t2) = self.tangents;
        let beta = self.params.contact_stabilisation;
        let mu = self.params.friction;
        for (ci, c) in self.contacts.iter().enumerate() {
            let p = world_point(&self.data, c);
            self.step_points[ci] = p;
            let Some(r) = self.sys.push(BlockKind::Contact { mu }) else {
                return Err(SimError::Scene("constraint capacity exhausted".into()));
            };
            point_rows(
                &self.robot,
                &self.data,
                c.joint,
                &p,
                &[n, t1, t2],
                1.0,
                0,
                &mut self.sys.jt,
                r,
            );
            let phi = self.ground.distance(&p);
            let target = if phi >= 0.0 {
                -phi / dt
            } else {
                -beta * phi / dt
            };
            self.sys.bias[r] = self.sys.jt.column(r).dot(&self.vstar) - target;
            self.sys.bias[r + 1] = self.sys.jt.column(r + 1).dot(&self.vstar);
            self.sys.bias[r + 2] = self.sys.jt.column(r + 2).dot(&self.vstar);
            for k in 0..3 {
                self.sys.lambda[r + k] = self.warm[3 * ci + k];
            }
        }
        Ok(())
    }

    /// Stage 3, the door: the hand–handle point constraint's three rows; their first row.
    fn loop_rows(&mut self) -> Result<Option<usize>, SimError> {
        let Some(d) = &self.door else {
            return Ok(None);
        };
        let (dt, nv, nc) = (self.params.dt, self.robot.nv, self.contacts.len());
        let ph = world_point(&self.data, &d.hand);
        let pd = world_point(&d.data, &d.handle);
        let Some(r) = self.sys.push(BlockKind::Bilateral3) else {
            return Err(SimError::Scene("constraint capacity exhausted".into()));
        };
        let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
        point_rows(
            &self.robot,
            &self.data,
            d.hand.joint,
            &ph,
            &axes,
            1.0,
            0,
            &mut self.sys.jt,
            r,
        );
        point_rows(
            &d.model,
            &d.data,
            d.handle.joint,
            &pd,
            &axes,
            -1.0,
            nv,
            &mut self.sys.jt,
            r,
        );
        let e = ph - pd;
        let gamma = self.params.loop_stabilisation;
        for k in 0..3 {
            let target = -gamma * e[k] / dt;
            self.sys.bias[r + k] = self.sys.jt.column(r + k).dot(&self.vstar) - target;
            self.sys.lambda[r + k] = self.warm[3 * nc + k];
        }
        Ok(Some(r))
    }

    /// Stage 3, joint limits: a row for each limit the free motion is about to cross; how
    /// many.
    fn limit_rows(&mut self) -> u32 {
        let dt = self.params.dt;
        let beta = self.params.contact_stabilisation;
        let mut active_limits = 0;
        for l in &self.limits {
            let qk = match (&self.door, l.door) {
                (Some(d), true) => d.q[l.iq],
                _ => self.q[l.iq],
            };
            let vk = self.vstar[l.dof];
            // Nearer side only; engaged when the free motion would come within 0.02 rad/m.
            let (gap, sign) = if qk - l.lower <= l.upper - qk {
                (qk - l.lower, 1.0)
            } else {
                (l.upper - qk, -1.0)
            };
            if gap + dt * sign * vk >= 0.02 || gap.is_nan() {
                continue;
            }
            let Some(r) = self.sys.push(BlockKind::Unilateral) else {
                break;
            };
            active_limits += 1;
            self.sys.jt[(l.dof, r)] = sign;
            let target = if gap >= 0.0 {
                -gap / dt
            } else {
                -beta * gap / dt
            };
            self.sys.bias[r] = sign * vk - target;
        }
        active_limits
    }

    /// Stage 5: `vstar` ← v* + (M + dt D)⁻¹ Jᵀ λ, refused if not finite.
    fn constrained_velocity(&mut self) -> Result<(), SimError> {
        self.sys.generalized_impulse(&mut self.dv);
        self.factor.solve(self.dv.as_mut_slice());
        for k in 0..self.nvt {
            let x = self.vstar[k] + self.dv[k];
            if !x.is_finite() {
                return Err(SimError::Diverged(k));
            }
            self.vstar[k] = x;
        }
        Ok(())
    }

    /// Stage 6: positions from the new velocities, into scratch (`vh`, `q_next`): the
    /// integration may fail, and nothing is committed before it has succeeded for robot and
    /// door.
    fn integrate_positions(&mut self) -> Result<(), SimError> {
        let dt = self.params.dt;
        let nv = self.robot.nv;
        for k in 0..nv {
            self.vh[k] = self.vstar[k];
        }
        integrate(&self.robot, &self.q, &self.vh, dt, &mut self.q_next)?;
        if let Some(d) = &mut self.door {
            for k in 0..d.model.nv {
                d.vh[k] = self.vstar[nv + k];
            }
            integrate(&d.model, &d.q, &d.vh, dt, &mut d.q_next)?;
        }
        Ok(())
    }

    /// Stage 7: the new state, the contact points of the step, time.
    fn commit(&mut self) {
        self.v.copy_from(&self.vh);
        std::mem::swap(&mut self.q, &mut self.q_next);
        if let Some(d) = &mut self.door {
            d.v.copy_from(&d.vh);
            std::mem::swap(&mut d.q, &mut d.q_next);
        }
        self.points.copy_from_slice(&self.step_points);
        self.time += self.params.dt;
        self.steps += 1;
    }

    /// The report's forces, at q: the warm start kept, each contact's force, the loaded
    /// contacts, their slip and centre of pressure; the hand's force (door and push).
    fn report_forces(&mut self, report: &mut StepReport, loop_row: Option<usize>) {
        let dt = self.params.dt;
        let n = self.ground.normal;
        let (t1, t2) = self.tangents;
        let nc = self.contacts.len();
        for ci in 0..nc {
            let r = 3 * ci;
            let l = &self.sys.lambda;
            self.warm[r] = l[r];
            self.warm[r + 1] = l[r + 1];
            self.warm[r + 2] = l[r + 2];
            let f = (n * l[r] + t1 * l[r + 1] + t2 * l[r + 2]) / dt;
            self.forces[ci] = f;
            if l[r] / dt > LOADED {
                report.active_contacts += 1;
                let ut1 = self.sys.jt.column(r + 1).dot(&self.vstar);
                let ut2 = self.sys.jt.column(r + 2).dot(&self.vstar);
                report.max_slip_speed = report.max_slip_speed.max(ut1.hypot(ut2));
            }
        }
        let loads = (0..nc)
            .map(|ci| (self.sys.lambda[3 * ci] / dt, self.points[ci]))
            .filter(|&(normal, _)| normal > LOADED)
            .map(|(normal, at)| PressureLoad::point(normal, at));
        let pressure = center_of_pressure(loads);
        report.total_normal_force = pressure.total;
        if pressure.loads > 0 {
            report.zmp = Some(pressure.point());
        }
        if let Some(r) = loop_row {
            for k in 0..3 {
                self.warm[3 * nc + k] = self.sys.lambda[r + k];
                report.hand_force[k] = self.sys.lambda[r + k] / dt;
            }
        }
        if let Some((_, f)) = &self.push {
            for k in 0..3 {
                report.hand_force[k] += f[k];
            }
        }
    }

    /// Post-step kinematics: penetration, loop error, CoM.
    fn refresh_points_after(&mut self, report: &mut StepReport) {
        kinematics::placements_unchecked(&self.robot, &mut self.data, self.q.as_slice());
        for c in &self.contacts {
            let p = world_point(&self.data, c);
            report.max_penetration = report.max_penetration.max(-self.ground.distance(&p));
        }
        let mut h = Vector3::zeros();
        let mut mass = 0.0;
        for (i, j) in self.robot.joints.iter().enumerate() {
            let o = &self.data.o_m_i[i];
            h += o.rot * j.inertia.h + j.inertia.mass * o.trans;
            mass += j.inertia.mass;
        }
        if mass > 0.0 {
            report.com = (h / mass).into();
        }
        if let Some(d) = &mut self.door {
            kinematics::placements_unchecked(&d.model, &mut d.data, d.q.as_slice());
            let ph = world_point(&self.data, &d.hand);
            let pd = world_point(&d.data, &d.handle);
            report.loop_error = (ph - pd).norm();
        }
    }

    pub fn robot(&self) -> &Model {
        &self.robot
    }
    pub fn q(&self) -> &DVector<f64> {
        &self.q
    }
    pub fn v(&self) -> &DVector<f64> {
        &self.v
    }
    pub fn time(&self) -> f64 {
        self.time
    }
    pub fn steps(&self) -> u64 {
        self.steps
    }
    pub fn params(&self) -> &PhysicsParams {
        &self.params
    }
    pub fn ground(&self) -> &Plane {
        &self.ground
    }
    /// Number of torques [`World::step`] expects (nv − 6 with a floating base, nv otherwise).
    pub fn n_actuated(&self) -> usize {
        self.n_act
    }
    /// The last step's report (that of the initial state before the first step).
    pub fn last_report(&self) -> &StepReport {
        &self.last
    }
    /// Contact frame names, in the order of [`World::contact_forces`].
    pub fn contact_names(&self) -> &[String] {
        &self.contact_names
    }
    /// Contact forces of the last step (N, world; ground on robot).
    pub fn contact_forces(&self) -> &[Vector3<f64>] {
        &self.forces
    }
    /// Contact points where the last step's forces applied (m, world).
    pub fn contact_points(&self) -> &[Vector3<f64>] {
        &self.points
    }
    /// Hinge angle and rate of a 1-DoF door (0 without a door).
    pub fn door_angle(&self) -> f64 {
        self.door
            .as_ref()
            .map_or(0.0, |d| d.q.get(0).copied().unwrap_or(0.0))
    }
    pub fn door_velocity(&self) -> f64 {
        self.door
            .as_ref()
            .map_or(0.0, |d| d.v.get(0).copied().unwrap_or(0.0))
    }
    /// The door model (placed in the world) and its configuration.
    pub fn door(&self) -> Option<(&Model, &DVector<f64>)> {
        self.door.as_ref().map(|d| (&d.model, &d.q))
    }

    /// World placements of every robot frame (URDF links included) at the current state.
    pub fn robot_frame_placements(&mut self) -> &[SE3] {
        kinematics::placements_unchecked(&self.robot, &mut self.data, self.q.as_slice());
        kinematics::update_frame_placements(&self.robot, &mut self.data);
        &self.data.o_m_f
    }

    /// World placements of every door frame at the current state.
    pub fn door_frame_placements(&mut self) -> Option<&[SE3]> {
        let d = self.door.as_mut()?;
        kinematics::placements_unchecked(&d.model, &mut d.data, d.q.as_slice());
        kinematics::update_frame_placements(&d.model, &mut d.data);
        Some(&d.data.o_m_f)
    }

    /// Total mechanical energy (kinetic + gravitational) of the robot and the door (J).
    pub fn energy(&mut self) -> Result<f64, SimError> {
        fn one(
            model: &Model,
            data: &mut crate::dynamics::Data,
            q: &DVector<f64>,
            v: &DVector<f64>,
        ) -> Result<f64, SimError> {
            if model.nv == 0 {
                return Ok(0.0);
            }
            let m = crba(model, data, q)?.clone();
            let kin = 0.5 * v.dot(&(m * v));
            let mut pot = 0.0;
            for (i, j) in model.joints.iter().enumerate() {
                let o = &data.o_m_i[i];
                let c = o.rot * j.inertia.h + j.inertia.mass * o.trans;
                pot -= model.gravity.dot(&c);
            }
            Ok(kin + pot)
        }
        let mut e = one(&self.robot, &mut self.data, &self.q, &self.v)?;
        if let Some(d) = &mut self.door {
            e += one(&d.model, &mut d.data, &d.q, &d.v)?;
        }
        Ok(e)
    }
}

impl Physics for World {
    fn engine(&self) -> &'static str {
        "upc"
    }
    fn robot(&self) -> &Model {
        World::robot(self)
    }
    fn q(&self) -> &DVector<f64> {
        World::q(self)
    }
    fn v(&self) -> &DVector<f64> {
        World::v(self)
    }
    fn time(&self) -> f64 {
        World::time(self)
    }
    fn steps(&self) -> u64 {
        World::steps(self)
    }
    fn n_actuated(&self) -> usize {
        World::n_actuated(self)
    }
    fn contact_forces(&self) -> &[Vector3<f64>] {
        World::contact_forces(self)
    }
    fn contact_points(&self) -> &[Vector3<f64>] {
        World::contact_points(self)
    }
    fn last_report(&self) -> &StepReport {
        World::last_report(self)
    }
    fn door_angle(&self) -> f64 {
        World::door_angle(self)
    }
    fn door_velocity(&self) -> f64 {
        World::door_velocity(self)
    }
    fn door_model(&self) -> Option<&Model> {
        self.door().map(|(m, _)| m)
    }
    fn set_push(&mut self, frame: usize, force: Vector3<f64>) -> Result<(), SimError> {
        World::set_push(self, frame, force)
    }
    fn step(&mut self, tau: &DVector<f64>, door_torque: f64) -> Result<StepReport, SimError> {
        World::step(self, tau, door_torque)
    }
    fn robot_frame_placements(&mut self) -> &[SE3] {
        World::robot_frame_placements(self)
    }
    fn door_frame_placements(&mut self) -> Option<&[SE3]> {
        World::door_frame_placements(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Everything a step commits, as bits.
    fn state_bits(w: &World) -> Vec<u64> {
        let mut out: Vec<u64> = w
            .q()
            .iter()
            .chain(w.v().iter())
            .map(|x| x.to_bits())
            .collect();
        if let Some(d) = &w.door {
            out.extend(d.q.iter().chain(d.v.iter()).map(|x| x.to_bits()));
        }
        out.extend(w.warm.iter().map(|x| x.to_bits()));
        out.extend(
            w.contact_points()
                .iter()
                .flat_map(|p| p.iter().map(|x| x.to_bits())),
        );
        out.push(w.time().to_bits());
        out.push(w.steps());
        out
    }

    #[test]
    fn a_failed_step_leaves_the_state_unchanged() {
        let mut scene =
            crate::sim::scene::humanoid_scene_with(PhysicsParams::default(), true, None)
                .expect("scene");
        let w = &mut scene.world;
        assert!(w.door.is_some());
        let mut tau = DVector::zeros(w.n_actuated());
        for k in 0..tau.len() {
            tau[k] = 0.5 * ((k as f64) * 0.7).sin();
        }
        for _ in 0..5 {
            w.step(&tau, 0.3).expect("step");
        }
        let before = state_bits(w);
        // A step failing at its last fallible stage, once the integration has run.
        w.fail_after_integration = true;
        assert!(w.step(&tau, 0.3).is_err());
        assert_eq!(
            state_bits(w),
            before,
            "a failing integration changed the state"
        );
        w.fail_after_integration = false;
        // A non-finite torque is refused before anything runs.
        let mut bad = tau.clone();
        bad[3] = f64::NAN;
        assert!(w.step(&bad, 0.3).is_err());
        assert_eq!(state_bits(w), before);
        // And the world steps on as if the failures never happened.
        let mut twin = crate::sim::scene::humanoid_scene_with(PhysicsParams::default(), true, None)
            .expect("scene");
        for _ in 0..6 {
            twin.world.step(&tau, 0.3).expect("step");
        }
        w.step(&tau, 0.3).expect("step after the failures");
        assert_eq!(state_bits(w), state_bits(&twin.world));
    }
}
