//! Spatial algebra (RBDA ch. 2) on fixed-size nalgebra types.
//!
//! Ordering follows Pinocchio, not Featherstone: a motion is `[linear; angular]`, a force is
//! `[force; torque]`. Spatial quantities are expressed in some frame and taken at that frame's
//! origin. Transforms are a rotation matrix plus a translation (never a 6×6 matrix), which is
//! what keeps RNEA and CRBA cheap.

use nalgebra::{Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector3, Vector6};

/// Skew-symmetric matrix `[v]×` such that `[v]× w = v × w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// `R S Rᵀ` for a symmetric `S`: `T = R S`, then `(T Rᵀ)_ij = T_i · R_j` on the upper triangle
/// only, mirrored.
#[inline]
pub fn rotate_symmetric(r: &Matrix3<f64>, s: &Matrix3<f64>) -> Matrix3<f64> {
    let t = r * s;
    let e =
        |i: usize, j: usize| t[(i, 0)] * r[(j, 0)] + t[(i, 1)] * r[(j, 1)] + t[(i, 2)] * r[(j, 2)];
    let (xx, xy, xz, yy, yz, zz) = (e(0, 0), e(0, 1), e(0, 2), e(1, 1), e(1, 2), e(2, 2));
    Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
}

/// Rigid placement `aMb`: the pose of frame b in frame a (`x_a = rot · x_b + trans`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SE3 {
    pub rot: Matrix3<f64>,
    pub trans: Vector3<f64>,
}

impl Default for SE3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl SE3 {
    #[inline]
    pub fn identity() -> Self {
        Self {
            rot: Matrix3::identity(),
            trans: Vector3::zeros(),
        }
    }

    #[inline]
    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Self { rot, trans }
    }

    /// URDF `<origin xyz rpy>`: fixed-axis roll about x, then pitch about y, then yaw about z.
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        let rot = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner();
        Self::new(rot, Vector3::new(xyz[0], xyz[1], xyz[2]))
    }

    /// `self * other` (aMb · bMc = aMc).
    #[inline]
    pub fn compose(&self, other: &SE3) -> SE3 {
        SE3 {
            rot: self.rot * other.rot,
            trans: self.rot * other.trans + self.trans,
        }
    }

    #[inline]
    pub fn inverse(&self) -> SE3 {
        let rt = self.rot.transpose();
        SE3 {
            rot: rt,
            trans: -(rt * self.trans),
        }
    }

    /// Maps a point from frame b to frame a.
    #[inline]
    pub fn act_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }

    /// Motion expressed in b → expressed in a.
    #[inline]
    pub fn act_motion(&self, m: &Motion) -> Motion {
        let ang = self.rot * m.ang;
        Motion {
            lin: self.rot * m.lin + self.trans.cross(&ang),
            ang,
        }
    }

    /// Motion expressed in a → expressed in b.
    #[inline]
    pub fn act_inv_motion(&self, m: &Motion) -> Motion {
        let rt = self.rot.transpose();
        Motion {
            lin: rt * (m.lin - self.trans.cross(&m.ang)),
            ang: rt * m.ang,
        }
    }

    /// Force expressed in b → expressed in a.
    #[inline]
    pub fn act_force(&self, f: &Force) -> Force {
        let lin = self.rot * f.lin;
        Force {
            ang: self.rot * f.ang + self.trans.cross(&lin),
            lin,
        }
    }

    /// Force expressed in a → expressed in b.
    #[inline]
    pub fn act_inv_force(&self, f: &Force) -> Force {
        let rt = self.rot.transpose();
        Force {
            lin: rt * f.lin,
            ang: rt * (f.ang - self.trans.cross(&f.lin)),
        }
    }

    /// Rigid-body inertia expressed in b → expressed in a (parallel-axis theorem on the
    /// `(m, h, I_origin)` form; no 6×6 product). Only the upper triangle of the symmetric
    /// `I_O` is computed.
    #[inline]
    pub fn act_inertia(&self, y: &Inertia) -> Inertia {
        let r = &self.rot;
        let p = &self.trans;
        let m = y.mass;
        let h = r * y.h + m * p;
        let rot_i = rotate_symmetric(r, &y.rot);
        // I_O = R I Rᵀ + (2 hᵀp − m|p|²) 1 − (h pᵀ + p hᵀ − m p pᵀ), with h in a,
        //     = R I Rᵀ + 2 gᵀp 1 − (g pᵀ + p gᵀ) with g = h − m p / 2.
        let g = h - (0.5 * m) * p;
        let d = 2.0 * g.dot(p);
        let o = |i: usize, j: usize| g[i] * p[j] + p[i] * g[j];
        let (xx, yy, zz) = (
            rot_i[(0, 0)] + d - o(0, 0),
            rot_i[(1, 1)] + d - o(1, 1),
            rot_i[(2, 2)] + d - o(2, 2),
        );
        let (xy, xz, yz) = (
            rot_i[(0, 1)] - o(0, 1),
            rot_i[(0, 2)] - o(0, 2),
            rot_i[(1, 2)] - o(1, 2),
        );
        Inertia {
            mass: m,
            h,
            rot: Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
        }
    }

    /// Adds the articulated-body inertia `m` (a symmetric 6×6 map motion → force, blocks
    /// `[[A, B], [Bᵀ, C]]`) expressed in b to `out` expressed in a: `out += X* m X*ᵀ` (RBDA
    /// eq. 2.66) with `X* = [[R, 0], [P R, R]]`, `P = [p]×`. Block-wise: rotate the blocks
    /// (`A`, `C` symmetric: upper triangles only), then shift by `p`:
    /// `A' = A`, `B' = B − A P`, `C' = C + P B' + (P B)ᵀ` (rotated blocks; `Pᵀ = −P`).
    #[inline]
    pub fn add_act_matrix6(&self, m: &Matrix6<f64>, out: &mut Matrix6<f64>) {
        let r = &self.rot;
        let p = &self.trans;
        let a = rotate_symmetric(r, &m.fixed_view::<3, 3>(0, 0).into_owned());
        let b = r * m.fixed_view::<3, 3>(0, 3) * r.transpose();
        let c = rotate_symmetric(r, &m.fixed_view::<3, 3>(3, 3).into_owned());
        // Row i of A P is (A_i × p)ᵀ (A symmetric: column i = row i).
        let ap = Matrix3::from_rows(&[
            a.column(0).cross(p).transpose(),
            a.column(1).cross(p).transpose(),
            a.column(2).cross(p).transpose(),
        ]);
        let b_new = b - ap;
        // Column j of P X is p × X_j.
        let cross_cols = |x: &Matrix3<f64>| {
            Matrix3::from_columns(&[
                p.cross(&x.column(0)),
                p.cross(&x.column(1)),
                p.cross(&x.column(2)),
            ])
        };
        let c_new = c + cross_cols(&b_new) + cross_cols(&b).transpose();
        let mut o = out.fixed_view_mut::<3, 3>(0, 0);
        o += a;
        let mut o = out.fixed_view_mut::<3, 3>(0, 3);
        o += b_new;
        let mut o = out.fixed_view_mut::<3, 3>(3, 0);
        o += b_new.transpose();
        let mut o = out.fixed_view_mut::<3, 3>(3, 3);
        o += c_new;
    }

    /// Unit quaternion of the rotation (for reporting and the free-flyer configuration).
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_matrix(&self.rot)
    }
}

/// Spatial motion (twist or acceleration): `[lin; ang]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    pub lin: Vector3<f64>,
    pub ang: Vector3<f64>,
}

impl Motion {
    #[inline]
    pub fn zero() -> Self {
        Self {
            lin: Vector3::zeros(),
            ang: Vector3::zeros(),
        }
    }

    #[inline]
    pub fn new(lin: Vector3<f64>, ang: Vector3<f64>) -> Self {
        Self { lin, ang }
    }

    #[inline]
    pub fn from_vector(v: &Vector6<f64>) -> Self {
        Self {
            lin: Vector3::new(v[0], v[1], v[2]),
            ang: Vector3::new(v[3], v[4], v[5]),
        }
    }

    #[inline]
    pub fn to_vector(&self) -> Vector6<f64> {
        Vector6::new(
            self.lin.x, self.lin.y, self.lin.z, self.ang.x, self.ang.y, self.ang.z,
        )
    }

    /// Motion cross product `self × m` (RBDA eq. 2.31, reordered).
    #[inline]
    pub fn cross_motion(&self, m: &Motion) -> Motion {
        Motion {
            lin: self.ang.cross(&m.lin) + self.lin.cross(&m.ang),
            ang: self.ang.cross(&m.ang),
        }
    }

    /// Force cross product `self ×* f` (RBDA eq. 2.32, reordered).
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            lin: self.ang.cross(&f.lin),
            ang: self.ang.cross(&f.ang) + self.lin.cross(&f.lin),
        }
    }

    /// Power pairing `⟨self, f⟩ = vᵀf + ωᵀτ`.
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        self.lin.dot(&f.lin) + self.ang.dot(&f.ang)
    }
}

impl std::ops::Add for Motion {
    type Output = Motion;
    #[inline]
    fn add(self, o: Motion) -> Motion {
        Motion::new(self.lin + o.lin, self.ang + o.ang)
    }
}

impl std::ops::Sub for Motion {
    type Output = Motion;
    #[inline]
    fn sub(self, o: Motion) -> Motion {
        Motion::new(self.lin - o.lin, self.ang - o.ang)
    }
}

impl std::ops::Mul<f64> for Motion {
    type Output = Motion;
    #[inline]
    fn mul(self, s: f64) -> Motion {
        Motion::new(self.lin * s, self.ang * s)
    }
}

impl std::ops::AddAssign for Motion {
    #[inline]
    fn add_assign(&mut self, o: Motion) {
        self.lin += o.lin;
        self.ang += o.ang;
    }
}

/// Spatial force (wrench): `[force; torque]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Force {
    pub lin: Vector3<f64>,
    pub ang: Vector3<f64>,
}

impl Force {
    #[inline]
    pub fn zero() -> Self {
        Self {
            lin: Vector3::zeros(),
            ang: Vector3::zeros(),
        }
    }

    #[inline]
    pub fn new(lin: Vector3<f64>, ang: Vector3<f64>) -> Self {
        Self { lin, ang }
    }

    #[inline]
    pub fn to_vector(&self) -> Vector6<f64> {
        Vector6::new(
            self.lin.x, self.lin.y, self.lin.z, self.ang.x, self.ang.y, self.ang.z,
        )
    }

    #[inline]
    pub fn from_vector(v: &Vector6<f64>) -> Self {
        Self {
            lin: Vector3::new(v[0], v[1], v[2]),
            ang: Vector3::new(v[3], v[4], v[5]),
        }
    }
}

impl std::ops::Add for Force {
    type Output = Force;
    #[inline]
    fn add(self, o: Force) -> Force {
        Force::new(self.lin + o.lin, self.ang + o.ang)
    }
}

impl std::ops::Sub for Force {
    type Output = Force;
    #[inline]
    fn sub(self, o: Force) -> Force {
        Force::new(self.lin - o.lin, self.ang - o.ang)
    }
}

impl std::ops::AddAssign for Force {
    #[inline]
    fn add_assign(&mut self, o: Force) {
        self.lin += o.lin;
        self.ang += o.ang;
    }
}

impl std::ops::SubAssign for Force {
    #[inline]
    fn sub_assign(&mut self, o: Force) {
        self.lin -= o.lin;
        self.ang -= o.ang;
    }
}

/// Rigid-body inertia about the origin of the frame it is expressed in, stored as
/// `(m, h = m·c, I_O)`: mass, first moment and rotational inertia about the origin. This form
/// makes the composite-inertia sum of CRBA a plain addition.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertia {
    pub mass: f64,
    pub h: Vector3<f64>,
    pub rot: Matrix3<f64>,
}

impl Default for Inertia {
    fn default() -> Self {
        Self::zero()
    }
}

impl Inertia {
    #[inline]
    pub fn zero() -> Self {
        Self {
            mass: 0.0,
            h: Vector3::zeros(),
            rot: Matrix3::zeros(),
        }
    }

    /// From mass, centre of mass `com` and rotational inertia about the CoM (`inertia_com`), all
    /// in the body frame (RBDA eq. 2.63).
    pub fn from_com(mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) -> Self {
        let s = skew(&com);
        Self {
            mass,
            h: mass * com,
            rot: inertia_com - mass * s * s,
        }
    }

    /// Centre of mass (origin if the mass is zero).
    #[inline]
    pub fn com(&self) -> Vector3<f64> {
        if self.mass > 0.0 {
            self.h / self.mass
        } else {
            Vector3::zeros()
        }
    }

    /// Rotational inertia about the centre of mass.
    pub fn inertia_com(&self) -> Matrix3<f64> {
        let c = self.com();
        let s = skew(&c);
        self.rot + self.mass * s * s
    }

    /// `I · v`: momentum of the body moving with twist `v`.
    #[inline]
    pub fn mul_motion(&self, v: &Motion) -> Force {
        Force {
            lin: self.mass * v.lin - self.h.cross(&v.ang),
            ang: self.rot * v.ang + self.h.cross(&v.lin),
        }
    }

    /// The 6×6 matrix of the map motion → force (for the articulated inertias of ABA).
    #[inline]
    pub fn to_matrix(&self) -> Matrix6<f64> {
        let mut out = Matrix6::zeros();
        let hs = skew(&self.h);
        out.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::from_diagonal_element(self.mass));
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-hs));
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&hs);
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.rot);
        out
    }
}

impl std::ops::Add for Inertia {
    type Output = Inertia;
    #[inline]
    fn add(self, o: Inertia) -> Inertia {
        Inertia {
            mass: self.mass + o.mass,
            h: self.h + o.h,
            rot: self.rot + o.rot,
        }
    }
}

impl std::ops::AddAssign for Inertia {
    #[inline]
    fn add_assign(&mut self, o: Inertia) {
        self.mass += o.mass;
        self.h += o.h;
        self.rot += o.rot;
    }
}

/// `exp` of a twist over unit time (SE(3) exponential, closed form), used to integrate the
/// free-flyer: the result is the displacement in the body frame.
pub fn exp6(v: &Motion) -> SE3 {
    let w = v.ang;
    let t2 = w.norm_squared();
    let t = t2.sqrt();
    let wx = skew(&w);
    let wx2 = wx * wx;
    // Series below a small angle keeps the coefficients accurate (no 0/0).
    let (a, b, c) = if t < 1e-4 {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        let (s, co) = t.sin_cos();
        (s / t, (1.0 - co) / t2, (t - s) / (t2 * t))
    };
    let rot = Matrix3::identity() + a * wx + b * wx2;
    let vmat = Matrix3::identity() + b * wx + c * wx2;
    SE3::new(rot, vmat * v.lin)
}

/// `log` of a rotation matrix: the rotation vector (axis × angle). Uses `atan2` of the
/// skew part (`sin θ · axis`) and the trace, which stays accurate for tiny angles where an
/// `acos` of the trace loses half the digits (finite-difference Jacobians depend on it).
pub fn log3(r: &Matrix3<f64>) -> Vector3<f64> {
    let w = 0.5
        * Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
    let s = w.norm();
    let c = 0.5 * (r.trace() - 1.0);
    let theta = s.atan2(c);
    if theta > std::f64::consts::PI - 1e-6 {
        // Near π the skew part vanishes: fall back on nalgebra's eigen-based extraction.
        return Rotation3::from_matrix_unchecked(*r).scaled_axis();
    }
    if s < 1e-12 {
        return w;
    }
    w * (theta / s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `X*` of `x` as a dense 6×6 matrix (force b → a, `[force; torque]`).
    fn dense_force_transform(x: &SE3) -> Matrix6<f64> {
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&x.rot);
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&x.rot);
        out.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(skew(&x.trans) * x.rot));
        out
    }

    fn placement() -> SE3 {
        SE3::from_xyz_rpy([0.3, -0.7, 0.2], [0.5, -1.1, 2.0])
    }

    fn body() -> Inertia {
        let i_c = Matrix3::new(0.3, 0.02, -0.01, 0.02, 0.2, 0.03, -0.01, 0.03, 0.25);
        Inertia::from_com(2.5, Vector3::new(0.1, -0.05, 0.2), i_c)
    }

    #[test]
    fn inertia_transform_matches_the_dense_congruence() {
        let x = placement();
        let xs = dense_force_transform(&x);
        let expected = xs * body().to_matrix() * xs.transpose();
        let got = x.act_inertia(&body()).to_matrix();
        assert!((got - expected).abs().max() < 1e-12, "{got} vs {expected}");
    }

    #[test]
    fn articulated_inertia_transform_matches_the_dense_congruence() {
        // A symmetric matrix with all blocks full (an articulated inertia after a rank-one
        // update is no longer of the rigid-body form).
        let u = Vector6::new(0.3, -0.2, 0.5, 0.1, 0.7, -0.4);
        let m = body().to_matrix() - 0.8 * u * u.transpose() + Matrix6::identity();
        let x = placement();
        let xs = dense_force_transform(&x);
        let base = Matrix6::from_fn(|r, c| (r * 6 + c) as f64 * 0.01);
        let expected = base + xs * m * xs.transpose();
        let mut got = base;
        x.add_act_matrix6(&m, &mut got);
        assert!((got - expected).abs().max() < 1e-12, "{got} vs {expected}");
    }

    #[test]
    fn symmetric_rotation_is_r_s_rt() {
        let r = placement().rot;
        let s = body().rot;
        let got = rotate_symmetric(&r, &s);
        assert!((got - r * s * r.transpose()).abs().max() < 1e-14);
    }
}
