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

    /// `placement · jMc(q)`: the parent-to-child placement of a joint whose frame sits at
    /// `placement` in the parent body (equal to `placement.compose(&self.transform(q))`). A
    /// revolute joint about a coordinate axis (±x, ±y, ±z: most URDF joints) mixes two columns
    /// of the placement's rotation (12 products instead of Rodrigues' formula and 27).
    #[inline(always)]
    pub fn placed_transform(&self, placement: &SE3, q: &[f64]) -> SE3 {
        match self {
            JointKind::Revolute { axis } => {
                let (s, c) = q[0].sin_cos();
                let p = &placement.rot;
                let (p0, p1, p2) = (p.column(0), p.column(1), p.column(2));
                let rot = if axis.y == 0.0 && axis.z == 0.0 && axis.x.abs() == 1.0 {
                    // R_x(θ) = [e_x, (0, c, s), (0, −s, c)]; a −x axis turns by −θ.
                    let s = s * axis.x;
                    Matrix3::from_columns(&[p0.into(), c * p1 + s * p2, c * p2 - s * p1])
                } else if axis.x == 0.0 && axis.z == 0.0 && axis.y.abs() == 1.0 {
                    // R_y(θ) = [(c, 0, −s), e_y, (s, 0, c)].
                    let s = s * axis.y;
                    Matrix3::from_columns(&[c * p0 - s * p2, p1.into(), s * p0 + c * p2])
                } else if axis.x == 0.0 && axis.y == 0.0 && axis.z.abs() == 1.0 {
                    // R_z(θ) = [(c, s, 0), (−s, c, 0), e_z].
                    let s = s * axis.z;
                    Matrix3::from_columns(&[c * p0 + s * p1, c * p1 - s * p0, p2.into()])
                } else {
                    p * axis_rotation_sc(axis, s, c)
                };
                SE3::new(rot, placement.trans)
            }
            JointKind::Prismatic { axis } => SE3::new(
                placement.rot,
                placement.rot * (axis * q[0]) + placement.trans,
            ),
            JointKind::FreeFlyer => placement.compose(&self.transform(q)),
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
    axis_rotation_sc(a, s, c)
}

/// Rodrigues' formula from the angle's sine and cosine.
#[inline]
fn axis_rotation_sc(a: &Vector3<f64>, s: f64, c: f64) -> Matrix3<f64> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placed_transform_is_the_placement_composed_with_the_joint_transform() {
        let placement = SE3::from_xyz_rpy([0.1, -0.2, 0.3], [0.4, -0.5, 0.6]);
        let mut axes: Vec<Vector3<f64>> = Vec::new();
        for k in 0..3 {
            for sign in [1.0, -1.0] {
                let mut a = Vector3::zeros();
                a[k] = sign;
                axes.push(a);
            }
        }
        axes.push(Vector3::new(0.3, -0.4, 0.5).normalize());
        let mut kinds: Vec<JointKind> = axes
            .iter()
            .flat_map(|&axis| [JointKind::Revolute { axis }, JointKind::Prismatic { axis }])
            .collect();
        kinds.push(JointKind::FreeFlyer);
        for kind in kinds {
            for q0 in [-2.5, 0.0, 0.7] {
                let ff = [0.2, -0.1, q0, 0.1, -0.3, 0.2, 0.9];
                let q = if kind.nq() == 7 { &ff[..] } else { &ff[2..3] };
                let expected = placement.compose(&kind.transform(q));
                let got = kind.placed_transform(&placement, q);
                assert!(
                    (got.rot - expected.rot).abs().max() < 1e-15
                        && (got.trans - expected.trans).abs().max() < 1e-15,
                    "{kind:?} at {q0}"
                );
            }
        }
    }
}
