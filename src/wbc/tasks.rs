//! The whole-body QP's tasks as data, and the layout of its variables and rows, both decided
//! once at construction and read by the full and the condensed formulations alike
//! (docs/whole_body_qp.md, "Tasks and layout").
//!
//! Two kinds of task, as the problem's structure has them:
//! - a [`PointTask`] asks a point (the CoM, or a frame's origin) for a 3-D acceleration,
//!   `½ w ‖J q̈ + J̇ v − a*‖²` in world axes. The full problem carries it as a residual variable
//!   `e` (rows `J q̈ − e = a* − J̇ v`, cost `½ w ‖e‖²`, which keeps P diagonal); the condensed one
//!   as `w JᵀJ` in H and `−w Jᵀ r` in g;
//! - a [`JointTask`] weighs a range of q̈ components against per-component targets,
//!   `½ w Σ (q̈_d − t_d)²`: a diagonal term of either formulation.
//!
//! Adding a task is one entry in [`TaskList::new`], its weight in the config and the line that
//! sets its target each tick; the sparsity, the dense assembly and the condensed problem follow
//! from the list.

use std::ops::Range;

use nalgebra::{DMatrix, Vector3};

use super::outcome::N_CONTACTS;

/// What a [`PointTask`] controls.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Point {
    /// The whole robot's centre of mass.
    Com,
    /// The origin of this frame (its linear, world-aligned rows).
    Frame(usize),
}

/// A 3-D acceleration task on a point: `½ w ‖J q̈ − r‖²`, `r = a* − J̇ v` (world axes).
#[derive(Clone, Debug)]
pub(crate) struct PointTask {
    pub point: Point,
    pub weight: f64,
    /// J (3 × nv), set each tick.
    pub jac: DMatrix<f64>,
    /// r, set each tick.
    pub target: Vector3<f64>,
}

/// A diagonal task on q̈'s components `dofs`: `½ w Σ_d (q̈_d − t_d)²`.
#[derive(Clone, Debug)]
pub(crate) struct JointTask {
    pub name: &'static str,
    pub dofs: Range<usize>,
    pub weight: f64,
    /// t, one per component of `dofs`, set each tick (zeros for a regularisation).
    pub target: Vec<f64>,
}

impl JointTask {
    fn new(name: &'static str, dofs: Range<usize>, weight: f64) -> Self {
        let target = vec![0.0; dofs.len()];
        Self {
            name,
            dofs,
            weight,
            target,
        }
    }
}

/// Weights of the tasks (from the config).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TaskWeights {
    pub com: f64,
    pub hand: f64,
    pub base_orientation: f64,
    pub posture: f64,
    pub acceleration: f64,
}

/// Every task of the QP, in the order of the full problem's residual variables and rows.
#[derive(Clone, Debug)]
pub(crate) struct TaskList {
    pub points: Vec<PointTask>,
    pub joints: Vec<JointTask>,
}

/// Indices of the tasks the controller sets each tick.
/// The point tasks: the CoM's and the hand's (the condensation's H has rank 3 each above its
/// diagonal, `condensed.rs`).
pub(crate) const POINT_TASKS: usize = 2;
pub(crate) const COM: usize = 0;
pub(crate) const HAND: usize = 1;
pub(crate) const BASE_ORIENTATION: usize = 1;
pub(crate) const POSTURE: usize = 2;

impl TaskList {
    /// The tasks of upc's controller (docs/whole_body_qp.md): the CoM acceleration of the
    /// preview, the hand's impedance acceleration at `hand`, the base orientation (the free
    /// flyer's angular components 3..6, body axes), the joint posture (6..nv) and the
    /// regularisation of every q̈ component (strict convexity).
    pub(crate) fn new(nv: usize, hand: usize, w: TaskWeights) -> Self {
        let point = |point, weight| PointTask {
            point,
            weight,
            jac: DMatrix::zeros(3, nv),
            target: Vector3::zeros(),
        };
        let points = vec![point(Point::Com, w.com), point(Point::Frame(hand), w.hand)];
        let joints = vec![
            JointTask::new("regularisation", 0..nv, w.acceleration),
            JointTask::new("base_orientation", 3..6, w.base_orientation),
            JointTask::new("posture", 6..nv, w.posture),
        ];
        let list = Self { points, joints };
        debug_assert_eq!(list.points.len(), POINT_TASKS);
        debug_assert_eq!(list.points[COM].point, Point::Com);
        debug_assert_eq!(list.joints[POSTURE].name, "posture");
        list
    }

    /// The joint tasks' diagonal Hessian D and linear term d: `½ q̈ᵀ D q̈ + dᵀ q̈` (+ const).
    pub(crate) fn diagonal(&self, diag: &mut [f64], lin: &mut [f64]) {
        diag.fill(0.0);
        lin.fill(0.0);
        for t in &self.joints {
            for (d, target) in t.dofs.clone().zip(&t.target) {
                diag[d] += t.weight;
                lin[d] -= t.weight * target;
            }
        }
    }

    /// Whether every weight and target is finite.
    pub(crate) fn is_finite(&self) -> bool {
        self.points
            .iter()
            .all(|t| t.weight.is_finite() && t.target.iter().all(|x| x.is_finite()))
            && self
                .joints
                .iter()
                .all(|t| t.weight.is_finite() && t.target.iter().all(|x| x.is_finite()))
    }
}

/// Where each block of the full problem lives: `z = [q̈ (nv); f (3·8); e (3 per point task)]`,
/// rows EoM (6) | soles (12) | point tasks (3 each) | torque limits (2 per limited joint) |
/// cones (3 per contact).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub nv: usize,
    /// First force variable (= nv) and first residual variable.
    pub force0: usize,
    pub residual0: usize,
    pub nz: usize,
    pub row_feet: usize,
    pub row_task: usize,
    pub row_tau: usize,
    pub row_soc: usize,
    pub n_rows: usize,
}

impl Layout {
    pub(crate) fn new(nv: usize, point_tasks: usize, limited_joints: usize) -> Self {
        let residual0 = nv + 3 * N_CONTACTS;
        let row_feet = 6;
        let row_task = row_feet + 12;
        let row_tau = row_task + 3 * point_tasks;
        let row_soc = row_tau + 2 * limited_joints;
        Self {
            nv,
            force0: nv,
            residual0,
            nz: residual0 + 3 * point_tasks,
            row_feet,
            row_task,
            row_tau,
            row_soc,
            n_rows: row_soc + 3 * N_CONTACTS,
        }
    }

    /// Residual variable of point task `t`, axis `k`; its row is `row_task + 3 t + k`.
    pub(crate) fn residual(&self, t: usize, k: usize) -> usize {
        self.residual0 + 3 * t + k
    }

    /// What a column is: a q̈ component, a contact's force, or a point task's residual.
    pub(crate) fn column(&self, c: usize) -> Column {
        if c < self.force0 {
            Column::Acceleration(c)
        } else if c < self.residual0 {
            Column::Force((c - self.force0) / 3)
        } else {
            Column::Residual(c - self.residual0)
        }
    }
}

/// A variable of the full problem, as [`Layout::column`] names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Column {
    Acceleration(usize),
    /// The contact index (0..8).
    Force(usize),
    /// `3 t + k` for point task t, axis k.
    Residual(usize),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weights() -> TaskWeights {
        TaskWeights {
            com: 1.0,
            hand: 2.0,
            base_orientation: 3.0,
            posture: 4.0,
            acceleration: 0.5,
        }
    }

    #[test]
    fn the_layout_follows_the_task_list() {
        let nv = 38;
        let tasks = TaskList::new(nv, 7, weights());
        let l = Layout::new(nv, tasks.points.len(), 5);
        assert_eq!(l.nz, nv + 24 + 6);
        assert_eq!(l.n_rows, 6 + 12 + 6 + 10 + 24);
        assert_eq!(l.residual(HAND, 2), nv + 24 + 5);
        assert_eq!(l.column(nv - 1), Column::Acceleration(nv - 1));
        assert_eq!(l.column(nv + 23), Column::Force(7));
        assert_eq!(l.column(nv + 24 + 4), Column::Residual(4));
        // One more point task: three more variables and rows, the rest moves down.
        let l3 = Layout::new(nv, 3, 5);
        assert_eq!(l3.nz, l.nz + 3);
        assert_eq!(l3.row_tau, l.row_tau + 3);
        assert_eq!(l3.n_rows, l.n_rows + 3);
    }

    #[test]
    fn joint_tasks_add_up_on_the_diagonal() {
        let nv = 10;
        let mut tasks = TaskList::new(nv, 3, weights());
        tasks.joints[BASE_ORIENTATION]
            .target
            .copy_from_slice(&[1.0, 2.0, 3.0]);
        tasks.joints[POSTURE].target.fill(-1.0);
        let (mut diag, mut lin) = (vec![9.0; nv], vec![9.0; nv]);
        tasks.diagonal(&mut diag, &mut lin);
        // The minimiser of ½ D q̈² + d q̈ per component is the weighted mean of the targets.
        for d in 0..nv {
            let expected_diag =
                0.5 + if (3..6).contains(&d) { 3.0 } else { 0.0 } + if d >= 6 { 4.0 } else { 0.0 };
            assert_eq!(diag[d], expected_diag, "dof {d}");
        }
        assert_eq!(lin[0], 0.0);
        assert_eq!(lin[4], -3.0 * 2.0);
        assert_eq!(lin[7], 4.0);
        assert!(tasks.is_finite());
        tasks.points[COM].target[1] = f64::NAN;
        assert!(!tasks.is_finite());
    }
}
