//! The immutable kinematic tree: joints (one moving body each), their inertias, and named frames.
//!
//! Joints are numbered in depth-first order, so a parent always precedes its children and every
//! forward pass is a plain loop over `0..njoints`. There is no "universe" joint: a joint whose
//! `parent` is `None` hangs from the world.

use nalgebra::{DVector, Vector3};

use super::error::DynamicsError;
use super::joint::JointKind;
use super::spatial::{Inertia, SE3};

/// Position, velocity and effort bounds of one joint (infinite when unbounded).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    pub lower: f64,
    pub upper: f64,
    pub velocity: f64,
    pub effort: f64,
}

impl JointLimits {
    pub const UNBOUNDED: JointLimits = JointLimits {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
        velocity: f64::INFINITY,
        effort: f64::INFINITY,
    };
}

/// One moving joint and the body it carries.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    /// Parent joint (`None`: attached to the world).
    pub parent: Option<usize>,
    /// Placement of the joint frame in the parent body's frame (at q = 0 the child body frame).
    pub placement: SE3,
    pub kind: JointKind,
    pub idx_q: usize,
    pub idx_v: usize,
    pub limits: JointLimits,
    /// Spatial inertia of the body (child link plus every link fixed to it), in the body frame.
    pub inertia: Inertia,
    /// Name of the URDF link that is this joint's child (the body's own name).
    pub body: String,
    /// Reflected rotor inertia of a one-dof joint (kg·m² or kg), added to `M`'s diagonal (as
    /// Pinocchio's `armature`, MuJoCo's joint `armature`); 0 for the free flyer.
    pub armature: f64,
}

impl Joint {
    #[inline]
    pub fn nq(&self) -> usize {
        self.kind.nq()
    }
    #[inline]
    pub fn nv(&self) -> usize {
        self.kind.nv()
    }
}

/// A named frame rigidly attached to a joint's body (or to the world).
#[derive(Clone, Debug)]
pub struct Frame {
    pub name: String,
    /// Carrying joint (`None`: the world).
    pub parent: Option<usize>,
    /// Placement of the frame in the carrying body's frame.
    pub placement: SE3,
}

/// Immutable multibody model. Build it from URDF ([`Model::from_urdf_file`]) or programmatically
/// ([`Model::new`], [`Model::add_joint`], [`Model::add_frame`]).
#[derive(Clone, Debug)]
pub struct Model {
    pub name: String,
    pub joints: Vec<Joint>,
    pub frames: Vec<Frame>,
    pub nq: usize,
    pub nv: usize,
    /// Gravity acceleration in the world frame (default `[0, 0, −9.81]`).
    pub gravity: Vector3<f64>,
    /// Joint of each velocity index (for walking a column back to its joint).
    pub dof_joint: Vec<usize>,
    /// What the URDF loader repaired or took as is, one line each (also logged as warnings).
    pub load_warnings: Vec<String>,
}

impl Model {
    /// Empty model (no joints, no frames) with standard gravity.
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            joints: Vec::new(),
            frames: Vec::new(),
            nq: 0,
            nv: 0,
            gravity: Vector3::new(0.0, 0.0, -9.81),
            dof_joint: Vec::new(),
            load_warnings: Vec::new(),
        }
    }

    /// Appends a joint carrying a body of inertia `inertia` (in the body frame). The parent
    /// must already exist; a body frame named `body` is added too. Joints come in depth-first
    /// preorder (the parent is the last joint or one of its ancestors), so that every sub-tree
    /// owns a contiguous range of joints and of dofs (CRBA fills M's rows over that range).
    pub fn add_joint(
        &mut self,
        name: impl Into<String>,
        parent: Option<usize>,
        placement: SE3,
        kind: JointKind,
        inertia: Inertia,
        body: impl Into<String>,
    ) -> Result<usize, DynamicsError> {
        let name = name.into();
        let body = body.into();
        if let Some(p) = parent
            && p >= self.joints.len()
        {
            return Err(DynamicsError::InvalidJoint {
                joint: name,
                reason: format!("parent joint index {p} does not exist yet"),
            });
        }
        if let Some(p) = parent {
            let mut cur = self.joints.len().checked_sub(1);
            while let Some(c) = cur
                && c != p
            {
                cur = self.joints[c].parent;
            }
            if cur.is_none() {
                return Err(DynamicsError::InvalidJoint {
                    joint: name,
                    reason: format!(
                        "parent joint index {p} is neither the last joint nor one of its \
                         ancestors (joints must be added depth-first)"
                    ),
                });
            }
        }
        if self.joints.iter().any(|j| j.name == name) {
            return Err(DynamicsError::DuplicateName {
                what: "joint",
                name,
            });
        }
        let id = self.joints.len();
        let joint = Joint {
            name,
            parent,
            placement,
            kind,
            idx_q: self.nq,
            idx_v: self.nv,
            limits: JointLimits::UNBOUNDED,
            inertia,
            body: body.clone(),
            armature: 0.0,
        };
        self.nq += kind.nq();
        self.nv += kind.nv();
        self.dof_joint.extend(std::iter::repeat_n(id, kind.nv()));
        self.joints.push(joint);
        self.add_frame(body, Some(id), SE3::identity())?;
        Ok(id)
    }

    /// Sets the armature of a one-dof joint (builder use); refused on a multi-dof joint or for a
    /// negative or non-finite value.
    pub fn set_armature(&mut self, joint: usize, armature: f64) -> Result<(), DynamicsError> {
        let j = self
            .joints
            .get_mut(joint)
            .ok_or_else(|| DynamicsError::InvalidJoint {
                joint: format!("#{joint}"),
                reason: "no such joint".into(),
            })?;
        if j.nv() != 1 || !armature.is_finite() || armature < 0.0 {
            return Err(DynamicsError::InvalidJoint {
                joint: j.name.clone(),
                reason: format!(
                    "armature {armature}: a finite value ≥ 0 on a one-dof joint is needed"
                ),
            });
        }
        j.armature = armature;
        Ok(())
    }

    /// Sets the limits of a joint (builder use).
    pub fn set_limits(&mut self, joint: usize, limits: JointLimits) {
        if let Some(j) = self.joints.get_mut(joint) {
            j.limits = limits;
        }
    }

    /// Adds a named frame on a joint's body (`None`: the world).
    pub fn add_frame(
        &mut self,
        name: impl Into<String>,
        parent: Option<usize>,
        placement: SE3,
    ) -> Result<usize, DynamicsError> {
        let name = name.into();
        if self.frames.iter().any(|f| f.name == name) {
            return Err(DynamicsError::DuplicateName {
                what: "frame",
                name,
            });
        }
        self.frames.push(Frame {
            name,
            parent,
            placement,
        });
        Ok(self.frames.len() - 1)
    }

    pub fn njoints(&self) -> usize {
        self.joints.len()
    }

    /// Index of the frame called `name`.
    pub fn frame_id(&self, name: &str) -> Result<usize, DynamicsError> {
        self.frames
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| DynamicsError::UnknownFrame(name.to_owned()))
    }

    /// Index of the joint called `name`.
    pub fn joint_id(&self, name: &str) -> Result<usize, DynamicsError> {
        self.joints
            .iter()
            .position(|j| j.name == name)
            .ok_or_else(|| DynamicsError::UnknownJoint(name.to_owned()))
    }

    /// Whether the first joint is a free-flyer (floating base).
    pub fn has_floating_base(&self) -> bool {
        self.joints
            .first()
            .is_some_and(|j| j.kind == JointKind::FreeFlyer)
    }

    /// One-dof joints whose motion moves no inertia: the bodies they carry (their own and every
    /// one below) have neither mass nor rotational inertia, and they have no armature. Each
    /// leaves a zero row and column in M(q), singular then whatever q.
    pub fn inert_joints(&self) -> Vec<usize> {
        // Preorder: a joint's children come after it, so a reverse pass sums each sub-tree.
        let mut carried = vec![0.0; self.joints.len()];
        for (i, j) in self.joints.iter().enumerate().rev() {
            carried[i] += j.inertia.mass + j.inertia.rot.trace().abs();
            if let Some(p) = j.parent {
                carried[p] += carried[i];
            }
        }
        (0..self.joints.len())
            .filter(|&i| {
                let j = &self.joints[i];
                j.nv() == 1 && carried[i] <= 1e-12 && j.armature <= 0.0
            })
            .collect()
    }

    /// Each velocity coordinate's effort limit (N·m or N), 0 where there is none (the floating
    /// base's coordinates, an unbounded joint): the scale of a drive's friction and noise.
    pub fn effort_limits(&self) -> Vec<f64> {
        (0..self.nv)
            .map(|k| {
                let e = self.joints[self.dof_joint[k]].limits.effort;
                if e.is_finite() && e > 0.0 { e } else { 0.0 }
            })
            .collect()
    }

    /// Sum of the body masses (bodies fixed to the world are not counted: they never move).
    pub fn total_mass(&self) -> f64 {
        self.joints.iter().map(|j| j.inertia.mass).sum()
    }

    /// Neutral configuration: joints at zero, free-flyer at the origin with identity quaternion.
    pub fn neutral(&self) -> DVector<f64> {
        let mut q = DVector::zeros(self.nq);
        for j in &self.joints {
            if matches!(j.kind, JointKind::FreeFlyer) {
                q[j.idx_q + 6] = 1.0;
            }
        }
        q
    }

    /// Configuration with each named joint set to a value (others neutral).
    pub fn configuration(&self, values: &[(&str, f64)]) -> Result<DVector<f64>, DynamicsError> {
        let mut q = self.neutral();
        for (name, value) in values {
            let j = &self.joints[self.joint_id(name)?];
            if j.nq() != 1 {
                return Err(DynamicsError::InvalidJoint {
                    joint: j.name.clone(),
                    reason: "only 1-DoF joints can be set by value".into(),
                });
            }
            q[j.idx_q] = *value;
        }
        Ok(q)
    }

    /// Is joint `ancestor` on the path from joint `joint` to the world (inclusive)?
    pub fn is_ancestor(&self, ancestor: usize, joint: usize) -> bool {
        let mut cur = Some(joint);
        while let Some(j) = cur {
            if j == ancestor {
                return true;
            }
            cur = self.joints[j].parent;
        }
        false
    }

    /// Checks `q` has length nq and finite entries.
    /// A free-flyer quaternion need not be exactly unit (it is normalised where used) but must
    /// not be zero.
    pub fn check_q(&self, q: &DVector<f64>) -> Result<(), DynamicsError> {
        check_vec("q", q, self.nq)?;
        // Only free-flyers have nq ≠ nv (one more each): stop once all are checked.
        let mut free_flyers = self.nq - self.nv;
        for j in &self.joints {
            if free_flyers == 0 {
                break;
            }
            if matches!(j.kind, JointKind::FreeFlyer) {
                let n2: f64 = (3..7).map(|k| q[j.idx_q + k] * q[j.idx_q + k]).sum();
                if n2 < 1e-12 {
                    return Err(DynamicsError::InvalidJoint {
                        joint: j.name.clone(),
                        reason: "the base quaternion in q is zero".into(),
                    });
                }
                free_flyers -= 1;
            }
        }
        Ok(())
    }

    /// Checks a velocity-sized vector (v, a, τ).
    pub fn check_v(&self, what: &'static str, v: &DVector<f64>) -> Result<(), DynamicsError> {
        check_vec(what, v, self.nv)
    }
}

fn check_vec(what: &'static str, x: &DVector<f64>, n: usize) -> Result<(), DynamicsError> {
    if x.len() != n {
        return Err(DynamicsError::DimensionMismatch {
            what,
            expected: n,
            got: x.len(),
        });
    }
    match x.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(DynamicsError::NonFinite { what, index }),
        None => Ok(()),
    }
}
