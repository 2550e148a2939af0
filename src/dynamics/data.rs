//! Preallocated workspace of the algorithms. Sized once from the model; the algorithms only
//! overwrite it, so a control tick never allocates.

use nalgebra::{DMatrix, DVector, Matrix6, Vector3, Vector6};

use super::model::Model;
use super::spatial::{Force, Inertia, Motion, SE3};

/// Results and scratch space of every algorithm, indexed like `Model::joints` / `Model::frames`.
/// Spatial quantities of a joint are expressed in its body frame unless the name starts with `o`
/// (world frame).
#[derive(Clone, Debug)]
pub struct Data {
    /// Parent body → body placement (`liMi`).
    pub li_m_i: Vec<SE3>,
    /// World placement of each body (`oMi`).
    pub o_m_i: Vec<SE3>,
    /// World placement of each frame (`oMf`).
    pub o_m_f: Vec<SE3>,
    /// Body twists (local).
    pub v: Vec<Motion>,
    /// Body spatial accelerations (local; include −gravity after RNEA/ABA).
    pub a: Vec<Motion>,
    /// Net body wrenches (RNEA) / articulated bias forces (ABA), local.
    pub f: Vec<Force>,
    /// Composite rigid-body inertias of a sub-tree (operational-space inertia), local.
    pub ycrb: Vec<Inertia>,
    /// CRBA: composite inertias in world axes at the world origin, and the column forces
    /// `F[k] = I^c S_k` (world) of every dof.
    pub(crate) oycrb: Vec<Inertia>,
    pub(crate) fcrb: Vec<Vector6<f64>>,
    /// Number of dofs of each joint's sub-tree (its dofs are `idx_v .. idx_v + nv_subtree`:
    /// joints are in depth-first order).
    pub(crate) nv_subtree: Vec<usize>,
    /// Joint-space inertia matrix `M(q)` (both triangles filled).
    pub m: DMatrix<f64>,
    /// Joint torques (RNEA output) or bias `h(q, v)` (nonlinear_effects output).
    pub tau: DVector<f64>,
    /// Joint accelerations (ABA output).
    pub ddq: DVector<f64>,
    /// World Jacobian of all joints (`J`, 6×nv, columns are `oMi · S` at the world origin).
    pub j: DMatrix<f64>,
    /// Frame Jacobian output (6×nv).
    pub frame_j: DMatrix<f64>,
    /// ABA: articulated inertias; for 1-dof joints `U = I^A S` and `D⁻¹`, for free-flyers the
    /// Cholesky factor of `D = I^A`; `u`; bias accelerations `c`.
    pub(crate) ia: Vec<Matrix6<f64>>,
    pub(crate) u_col: Vec<Vector6<f64>>,
    pub(crate) d_inv: Vec<f64>,
    pub(crate) d_chol: Vec<Matrix6<f64>>,
    pub(crate) u_vec: DVector<f64>,
    pub(crate) c: Vec<Motion>,
    /// CoM: subtree mass and subtree first moment (world frame).
    pub subtree_mass: Vec<f64>,
    pub(crate) subtree_h: Vec<Vector3<f64>>,
    /// Centre of mass, its velocity (world frame) and Jacobian (3×nv).
    pub com: Vector3<f64>,
    pub vcom: Vector3<f64>,
    pub jcom: DMatrix<f64>,
    /// What `li_m_i`, `o_m_i` hold: the model (its address) and the configuration (its bits)
    /// they were placed at (`None`: not placed, or invalidated), and whether `o_m_f` follows
    /// them. A tick runs several algorithms at one q; each placed the whole tree again
    /// (kinematics.rs, [`super::kinematics::placements_unchecked`]).
    pub(crate) placed_model: Option<usize>,
    pub(crate) placed_q: Vec<f64>,
    pub(crate) frames_placed: bool,
}

impl Data {
    /// Whether `li_m_i`, `o_m_i` are `model`'s placements at `q`, bit for bit (so that reuse
    /// is exact by construction: −0.0 == 0.0, yet sin(−0.0) is −0.0).
    #[inline]
    pub(crate) fn placed_at(&self, model: &Model, q: &[f64]) -> bool {
        self.placed_model == Some(model as *const Model as usize)
            && self.placed_q.len() == q.len()
            && self
                .placed_q
                .iter()
                .zip(q)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }

    /// `li_m_i`, `o_m_i` placed at `q` (after the caller wrote them all).
    #[inline]
    pub(crate) fn mark_placed(&mut self, model: &Model, q: &[f64]) {
        self.placed_model = Some(model as *const Model as usize);
        self.placed_q.copy_from_slice(q);
        self.frames_placed = false;
    }

    /// `li_m_i` or `o_m_i` written at another configuration than the one marked.
    #[inline]
    pub(crate) fn unmark_placed(&mut self) {
        self.placed_model = None;
        self.frames_placed = false;
    }

    pub fn new(model: &Model) -> Self {
        let n = model.njoints();
        let nf = model.frames.len();
        let nv = model.nv;
        let mut nv_subtree: Vec<usize> = model.joints.iter().map(|j| j.nv()).collect();
        for (i, j) in model.joints.iter().enumerate().rev() {
            if let Some(p) = j.parent {
                nv_subtree[p] += nv_subtree[i];
            }
        }
        Self {
            li_m_i: vec![SE3::identity(); n],
            o_m_i: vec![SE3::identity(); n],
            o_m_f: vec![SE3::identity(); nf],
            v: vec![Motion::zero(); n],
            a: vec![Motion::zero(); n],
            f: vec![Force::zero(); n],
            ycrb: vec![Inertia::zero(); n],
            oycrb: vec![Inertia::zero(); n],
            fcrb: vec![Vector6::zeros(); nv],
            nv_subtree,
            m: DMatrix::zeros(nv, nv),
            tau: DVector::zeros(nv),
            ddq: DVector::zeros(nv),
            j: DMatrix::zeros(6, nv),
            frame_j: DMatrix::zeros(6, nv),
            ia: vec![Matrix6::zeros(); n],
            u_col: vec![Vector6::zeros(); n],
            d_inv: vec![0.0; n],
            d_chol: vec![Matrix6::zeros(); n],
            u_vec: DVector::zeros(nv),
            c: vec![Motion::zero(); n],
            subtree_mass: vec![0.0; n],
            subtree_h: vec![Vector3::zeros(); n],
            com: Vector3::zeros(),
            vcom: Vector3::zeros(),
            jcom: DMatrix::zeros(3, nv),
            placed_model: None,
            placed_q: vec![0.0; model.nq],
            frames_placed: false,
        }
    }
}
