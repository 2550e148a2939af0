//! Joint models: the joint transform `jMc(q)` and the motion subspace `S` (RBDA Table 4.1).
//!
//! Only the joints the project needs exist; 1-DoF joints carry their unit axis so that `S` is a
//! single 6-vector and `Sᵀf` a 3-term dot product.

use nalgebra::{Matrix3, Vector3};

use super::spatial::{Force, Motion, SE3};

/// Kind of a (non-fixed) joint. Fixed URDF joints never become joints: they are merged into the
/// parent body and leave a frame behind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointKind {
    /// Rotation about a unit axis of the joint frame; URDF `revolute` and `continuous` (the
    /// latter stores its angle directly: nq = nv = 1, unbounded).
    Revolute { axis: Vector3<f64> },
    /// Translation along a unit axis of the joint frame.
    Prismatic { axis: Vector3<f64> },
    /// Free-flyer root (Pinocchio convention): `q = [p_world(3), quat xyzw(4)]`,
    /// `v = [v_body_linear(3), ω_body(3)]`, both velocities in the root's local frame.
    FreeFlyer,
}

impl JointKind {
    /// Configuration size.
    pub fn nq(&self) -> usize {
        match self {
            JointKind::FreeFlyer => 7,
            _ => 1,
        }
    }

    /// Velocity size.
    pub fn nv(&self) -> usize {
        match self {
            JointKind::FreeFlyer => 6,
            _ => 1,
        }
    }

    /// Joint transform `jMc(q)` (placement of the child frame in the joint frame). `q` is this
    /// joint's slice of the configuration (precondition: length `nq`).
    #[inline]
    pub fn transform(&self, q: &[f64]) -> SE3 {
        match self {
            JointKind::Revolute { axis } => SE3::new(axis_rotation(axis, q[0]), Vector3::zeros()),
            JointKind::Prismatic { axis } => SE3::new(Matrix3::identity(), axis * q[0]),
            JointKind::FreeFlyer => {
                let (x, y, z, w) = (q[3], q[4], q[5], q[6]);
                // Normalise here so that a slightly drifted quaternion still yields a rotation.
                let n2 = x * x + y * y + z * z + w * w;
                let s = if n2 > 0.0 { 2.0 / n2 } else { 0.0 };
                let rot = Matrix3::new(
                    1.0 - s * (y * y + z * z),
                    s * (x * y - z * w),
                    s * (x * z + y * w),
                    s * (x * y + z * w),
                    1.0 - s * (x * x + z * z),
                    s * (y * z - x * w),
                    s * (x * z - y * w),
                    s * (y * z + x * w),
                    1.0 - s * (x * x + y * y),
                );
                SE3::new(rot, Vector3::new(q[0], q[1], q[2]))
            }
        }
    }

    /// Joint velocity `S q̇` in the child frame.
    #[inline]
    pub fn motion(&self, v: &[f64]) -> Motion {
        match self {
            JointKind::Revolute { axis } => Motion::new(Vector3::zeros(), axis * v[0]),
            JointKind::Prismatic { axis } => Motion::new(axis * v[0], Vector3::zeros()),
            JointKind::FreeFlyer => Motion::new(
                Vector3::new(v[0], v[1], v[2]),
                Vector3::new(v[3], v[4], v[5]),
            ),
        }
    }

    /// Column `k` of the motion subspace `S`, in the child frame.
    #[inline]
    pub fn subspace_column(&self, k: usize) -> Motion {
        match self {
            JointKind::Revolute { axis } => Motion::new(Vector3::zeros(), *axis),
            JointKind::Prismatic { axis } => Motion::new(*axis, Vector3::zeros()),
            JointKind::FreeFlyer => {
                let mut m = Motion::zero();
                if k < 3 {
                    m.lin[k] = 1.0;
                } else {
                    m.ang[k - 3] = 1.0;
                }
                m
            }
        }
    }

    /// `Sᵀ f` written into `out` (length `nv`).
    #[inline]
    pub fn project_force(&self, f: &Force, out: &mut [f64]) {
        match self {
            JointKind::Revolute { axis } => out[0] = axis.dot(&f.ang),
            JointKind::Prismatic { axis } => out[0] = axis.dot(&f.lin),
            JointKind::FreeFlyer => {
                out[..3].copy_from_slice(f.lin.as_slice());
                out[3..6].copy_from_slice(f.ang.as_slice());
            }
        }
    }

    /// Name for tables and messages.
    pub fn label(&self) -> &'static str {
        match self {
            JointKind::Revolute { .. } => "revolute",
            JointKind::Prismatic { .. } => "prismatic",
            JointKind::FreeFlyer => "free-flyer",
        }
    }
}

/// Rodrigues' formula for a unit axis.
#[inline]
fn axis_rotation(a: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    let (x, y, z) = (a.x, a.y, a.z);
    Matrix3::new(
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    )
}
