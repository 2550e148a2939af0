//! Rigid-body dynamics against independent truths: finite differences of the kinematics, the
//! ABA∘RNEA identity, energy conservation, analytic pendulums, and the URDF files themselves.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use upc::dynamics::spatial::log3;
use upc::dynamics::*;

/// Small deterministic generator (xorshift64*), enough for test states.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        lo + (hi - lo) * (x as f64 / (1u64 << 53) as f64)
    }

    fn vector(&mut self, n: usize, scale: f64) -> DVector<f64> {
        DVector::from_fn(n, |_, _| self.uniform(-scale, scale))
    }

    /// Random configuration: joints within ±1 rad (or limits), random base pose.
    fn configuration(&mut self, model: &Model) -> DVector<f64> {
        let mut q = model.neutral();
        for j in &model.joints {
            match j.kind {
                JointKind::FreeFlyer => {
                    for k in 0..3 {
                        q[j.idx_q + k] = self.uniform(-1.0, 1.0);
                    }
                    let quat = nalgebra::UnitQuaternion::from_euler_angles(
                        self.uniform(-3.0, 3.0),
                        self.uniform(-1.5, 1.5),
                        self.uniform(-3.0, 3.0),
                    );
                    let c = quat.quaternion().coords;
                    for k in 0..4 {
                        q[j.idx_q + 3 + k] = c[k];
                    }
                }
                _ => {
                    let lo = j.limits.lower.max(-1.0);
                    let hi = j.limits.upper.min(1.0);
                    q[j.idx_q] = self.uniform(lo, hi);
                }
            }
        }
        q
    }
}

fn humanoid() -> Model {
    icub_like::load().expect("the project's humanoid loads")
}

fn humanoid_fixed() -> Model {
    Model::from_urdf_file(icub_like::urdf_path(), BaseJoint::Fixed).expect("fixed-base humanoid")
}

fn max_abs(m: &DMatrix<f64>) -> f64 {
    m.iter().fold(0.0, |a, x| a.max(x.abs()))
}

use upc::dynamics::icub_like;

// ---------------------------------------------------------------------------------------------
// Structure of the assets

#[test]
fn humanoid_structure_matches_the_issue() {
    let model = humanoid();
    let revolute = model
        .joints
        .iter()
        .filter(|j| matches!(j.kind, JointKind::Revolute { .. }))
        .count();
    assert_eq!(revolute, 32);
    assert!(model.has_floating_base());
    assert_eq!(model.nv, 38);
    assert_eq!(model.nq, 39);
    let names = [
        "hip_pitch",
        "hip_roll",
        "hip_yaw",
        "knee",
        "ankle_pitch",
        "ankle_roll",
        "shoulder_pitch",
        "shoulder_roll",
        "shoulder_yaw",
        "elbow",
        "wrist_prosup",
        "wrist_pitch",
        "wrist_yaw",
    ];
    for side in ["l_", "r_"] {
        for n in names {
            model.joint_id(&format!("{side}{n}")).expect("limb joint");
        }
        for f in ["sole", "sole_fl", "sole_fr", "sole_rl", "sole_rr", "hand"] {
            model.frame_id(&format!("{side}{f}")).expect("frame");
        }
    }
    for n in [
        "torso_pitch",
        "torso_roll",
        "torso_yaw",
        "neck_pitch",
        "neck_roll",
        "neck_yaw",
    ] {
        model.joint_id(n).expect("trunk joint");
    }
    model.frame_id("chest").expect("chest frame");
    model.frame_id("root_link").expect("root frame");
    for j in model.joints.iter().skip(1) {
        let l = j.limits;
        assert!(l.lower.is_finite() && l.upper.is_finite() && l.lower < l.upper);
        assert!(l.velocity.is_finite() && l.effort.is_finite(), "{}", j.name);
    }
    assert!(matches!(
        model.frame_id("no_such_frame"),
        Err(DynamicsError::UnknownFrame(n)) if n == "no_such_frame"
    ));
}

/// Total mass and inertia validity straight from the URDF text, independently of the loader.
#[test]
fn humanoid_masses_and_inertias_are_physical() {
    let robot = urdf_rs::read_file(icub_like::urdf_path()).expect("parse");
    let mut total = 0.0;
    for l in &robot.links {
        let i = &l.inertial.inertia;
        total += l.inertial.mass.value;
        if l.inertial.mass.value > 0.0 {
            let t = Matrix3::new(
                i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
            );
            let e = t.symmetric_eigenvalues();
            assert!(e.min() > 0.0, "{}", l.name);
            // Triangle inequality on the principal moments.
            let (a, b, c) = (e[0], e[1], e[2]);
            assert!(
                a + b >= c && a + c >= b && b + c >= a,
                "triangle inequality fails for {}",
                l.name
            );
        }
    }
    assert!((27.0..=33.0).contains(&total), "total {total}");
    let model = humanoid();
    assert!((model.total_mass() - total).abs() < 1e-9);
}

#[test]
fn humanoid_home_posture_matches_spec_section_7() {
    let model = humanoid();
    let mut data = Data::new(&model);
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    for j in model.joints.iter().skip(1) {
        let x = q[j.idx_q];
        assert!(x >= j.limits.lower && x <= j.limits.upper, "{}", j.name);
    }
    forward_kinematics(&model, &mut data, &q).expect("fk");
    let at = |d: &Data, n: &str| d.o_m_f[model.frame_id(n).expect("frame")];
    let (l, r) = (at(&data, "l_sole"), at(&data, "r_sole"));
    // Soles flat on the ground, 0.14 m apart.
    assert!(l.trans.z.abs() < 1e-9 && r.trans.z.abs() < 1e-9);
    assert!((l.rot - Matrix3::identity()).norm() < 1e-9);
    assert!(((l.trans - r.trans).norm() - 0.14).abs() < 0.01);
    // Sole 0.13–0.16 × 0.055–0.072.
    let fl = at(&data, "l_sole_fl").trans;
    let rr = at(&data, "l_sole_rr").trans;
    assert!((0.13..=0.16).contains(&(fl.x - rr.x)));
    assert!((0.055..=0.072).contains(&(fl.y - rr.y)));
    // Height about 1 m (head top: head frame + sphere radius), CoM 0.50–0.54 m.
    let head = at(&data, "head").trans.z + 0.09 + 0.075;
    assert!((0.95..=1.05).contains(&head), "height {head}");
    let com = center_of_mass(&model, &mut data, &q).expect("com");
    assert!((0.50..=0.54).contains(&com.z), "CoM height {}", com.z);
    eprintln!(
        "home: CoM {com:?}, root height {:.4}, head top {head:.4}",
        q[2]
    );
    // CoM above the support polygon.
    let (lf, rr2) = (at(&data, "l_sole_fl").trans, at(&data, "r_sole_rr").trans);
    assert!(com.x < lf.x && com.x > rr2.x && com.y < lf.y && com.y > rr2.y);
}

#[test]
fn door_model() {
    let model = Model::from_urdf_file(icub_like::door_urdf_path(), BaseJoint::Auto).expect("door");
    assert!(!model.has_floating_base());
    assert_eq!((model.nq, model.nv), (1, 1));
    assert!((model.total_mass() - 12.2).abs() < 1e-12);
    let handle = model.frame_id("handle").expect("handle");
    let mut data = Data::new(&model);
    let q = DVector::from_element(1, std::f64::consts::FRAC_PI_2);
    forward_kinematics(&model, &mut data, &q).expect("fk");
    // Opening by 90° about +z swings the handle from +x to +y of the hinge.
    let p = data.o_m_f[handle].trans;
    assert!(
        (p - Vector3::new(0.02 + 0.07, 0.72, 1.0)).norm() < 1e-9,
        "{p}"
    );
}

// ---------------------------------------------------------------------------------------------
// Dynamics identities

#[test]
fn aba_inverts_rnea() {
    let mut rng = Rng(7);
    for model in [humanoid(), humanoid_fixed()] {
        let mut data = Data::new(&model);
        for _ in 0..5 {
            let q = rng.configuration(&model);
            let v = rng.vector(model.nv, 2.0);
            let a = rng.vector(model.nv, 5.0);
            let tau = rnea(&model, &mut data, &q, &v, &a).expect("rnea").clone();
            let ddq = aba(&model, &mut data, &q, &v, &tau).expect("aba").clone();
            let err = (&ddq - &a).amax();
            assert!(err < 1e-8 * (1.0 + a.amax()), "ABA∘RNEA error {err}");
        }
    }
}

/// Bit for bit: a stale placement differs from a fresh one at least in a zero's sign.
fn same_bits(a: &[SE3], b: &[SE3]) -> bool {
    let bits = |x: &SE3| {
        x.rot
            .iter()
            .chain(x.trans.iter())
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    };
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| bits(x) == bits(y))
}

/// The placements are computed once per configuration and shared by the algorithms run at it
/// (kinematics.rs): whatever ran before on the same `Data`, at another configuration or at
/// this one, every algorithm gives the bits a fresh `Data` gives.
#[test]
fn shared_placements_give_what_a_fresh_workspace_gives() {
    let mut rng = Rng(11);
    let model = humanoid();
    let mut data = Data::new(&model);
    let q1 = rng.configuration(&model);
    let q2 = rng.configuration(&model);
    let v = rng.vector(model.nv, 2.0);
    let frames = |data: &mut Data, q: &DVector<f64>| {
        forward_kinematics(&model, data, q).expect("fk");
        data.o_m_f.clone()
    };
    let fresh = |q: &DVector<f64>| frames(&mut Data::new(&model), q);
    // CRBA at q1, RNEA at q2 (which places the joints only), then the frames at q1 and q2.
    crba(&model, &mut data, &q1).expect("crba");
    let h2 = nonlinear_effects(&model, &mut data, &q2, &v)
        .expect("rnea")
        .clone();
    let h2_fresh = nonlinear_effects(&model, &mut Data::new(&model), &q2, &v)
        .expect("rnea")
        .clone();
    assert_eq!(h2, h2_fresh);
    // RNEA at q1 now: the joints it placed at q2 are not q1's.
    let h = |data: &mut Data, q: &DVector<f64>| {
        nonlinear_effects(&model, data, q, &v)
            .expect("rnea")
            .clone()
    };
    assert_eq!(h(&mut data, &q1), h(&mut Data::new(&model), &q1));
    assert!(same_bits(&frames(&mut data, &q1), &fresh(&q1)));
    assert!(same_bits(&frames(&mut data, &q2), &fresh(&q2)));
    // ABA at q1 after placements at q2, then the CoM Jacobian at q2.
    let tau = rng.vector(model.nv, 3.0);
    let a1 = aba(&model, &mut data, &q1, &v, &tau).expect("aba").clone();
    let a1_fresh = aba(&model, &mut Data::new(&model), &q1, &v, &tau)
        .expect("aba")
        .clone();
    assert_eq!(a1, a1_fresh);
    assert_eq!(h(&mut data, &q2), h(&mut Data::new(&model), &q2));
    let jcom = jacobian_center_of_mass(&model, &mut data, &q2)
        .expect("jcom")
        .clone();
    let jcom_fresh = jacobian_center_of_mass(&model, &mut Data::new(&model), &q2)
        .expect("jcom")
        .clone();
    assert_eq!(jcom, jcom_fresh);
    let joint = model
        .joints
        .iter()
        .rposition(|j| j.nq() == 1)
        .expect("a joint");
    // Another model of the same shape (a link 1 cm longer) with the same workspace: its own
    // placements.
    let mut other = humanoid();
    other.joints[joint].placement.trans.x += 0.01;
    assert!(same_bits(
        &{
            forward_kinematics(&other, &mut data, &q2).expect("fk");
            data.o_m_i.clone()
        },
        &{
            let mut d = Data::new(&other);
            forward_kinematics(&other, &mut d, &q2).expect("fk");
            d.o_m_i.clone()
        }
    ));
}

#[test]
fn crba_equals_rnea_column_by_column_and_is_spd() {
    let mut rng = Rng(11);
    let model = humanoid();
    let mut data = Data::new(&model);
    let q = rng.configuration(&model);
    let zero = DVector::zeros(model.nv);
    let g = gravity_torques(&model, &mut data, &q).expect("g").clone();
    let g2 = rnea(&model, &mut data, &q, &zero, &zero)
        .expect("rnea")
        .clone();
    assert!((&g - &g2).amax() < 1e-12);
    let m = crba(&model, &mut data, &q).expect("crba").clone();
    for k in 0..model.nv {
        let mut e = DVector::zeros(model.nv);
        e[k] = 1.0;
        let col = rnea(&model, &mut data, &q, &zero, &e)
            .expect("rnea")
            .clone()
            - &g;
        let diff = (&col - m.column(k)).amax();
        assert!(diff < 1e-10, "column {k}: {diff}");
    }
    assert!(max_abs(&(&m - m.transpose())) < 1e-12);
    assert!(
        m.clone().cholesky().is_some(),
        "M must be positive definite"
    );
    // M·a + h = RNEA(q, v, a).
    let v = rng.vector(model.nv, 1.0);
    let a = rng.vector(model.nv, 1.0);
    let h = nonlinear_effects(&model, &mut data, &q, &v)
        .expect("h")
        .clone();
    let tau = rnea(&model, &mut data, &q, &v, &a).expect("rnea").clone();
    assert!((&m * &a + h - tau).amax() < 1e-10);
}

/// Kinetic energy ½ vᵀ M v equals the sum of body energies ½ vᵢᵀ Iᵢ vᵢ.
#[test]
fn kinetic_energy_two_ways() {
    let mut rng = Rng(5);
    let model = humanoid();
    let mut data = Data::new(&model);
    let q = rng.configuration(&model);
    let v = rng.vector(model.nv, 1.0);
    let m = crba(&model, &mut data, &q).expect("crba").clone();
    forward_kinematics_velocity(&model, &mut data, &q, &v).expect("fk");
    let bodies: f64 = model
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| 0.5 * data.v[i].dot(&j.inertia.mul_motion(&data.v[i])))
        .sum();
    let joint_space = 0.5 * v.dot(&(&m * &v));
    assert!((bodies - joint_space).abs() < 1e-10 * joint_space.abs().max(1.0));
}

// ---------------------------------------------------------------------------------------------
// Jacobians against finite differences

fn perturbed(model: &Model, q: &DVector<f64>, dir: &DVector<f64>, eps: f64) -> DVector<f64> {
    let mut out = DVector::zeros(model.nq);
    integrate(model, q, dir, eps, &mut out).expect("integrate");
    out
}

fn frame_pose(model: &Model, data: &mut Data, q: &DVector<f64>, f: usize) -> SE3 {
    forward_kinematics(model, data, q).expect("fk");
    data.o_m_f[f]
}

#[test]
fn frame_jacobians_match_finite_differences() {
    let mut rng = Rng(3);
    let model = humanoid();
    let mut data = Data::new(&model);
    let eps = 1e-6;
    for name in ["r_hand", "l_sole_fl", "chest", "head"] {
        let f = model.frame_id(name).expect("frame");
        let q = rng.configuration(&model);
        compute_joint_jacobians(&model, &mut data, &q).expect("J");
        let mut jw = DMatrix::zeros(6, model.nv);
        let mut jl = DMatrix::zeros(6, model.nv);
        get_frame_jacobian(&model, &data, f, ReferenceFrame::LocalWorldAligned, &mut jw)
            .expect("J");
        get_frame_jacobian(&model, &data, f, ReferenceFrame::Local, &mut jl).expect("J");
        let single = frame_jacobian(&model, &mut data, &q, f, ReferenceFrame::LocalWorldAligned)
            .expect("J")
            .clone();
        assert!(max_abs(&(&single - &jw)) < 1e-12);
        for k in 0..model.nv {
            let mut e = DVector::zeros(model.nv);
            e[k] = 1.0;
            let p = frame_pose(&model, &mut data, &perturbed(&model, &q, &e, eps), f);
            let m = frame_pose(&model, &mut data, &perturbed(&model, &q, &e, -eps), f);
            let lin_w = (p.trans - m.trans) / (2.0 * eps);
            let ang_w = log3(&(p.rot * m.rot.transpose())) / (2.0 * eps);
            let r0 = frame_pose(&model, &mut data, &q, f).rot;
            let ang_l = log3(&(m.rot.transpose() * p.rot)) / (2.0 * eps);
            let lin_l = r0.transpose() * lin_w;
            for r in 0..3 {
                assert!(
                    (jw[(r, k)] - lin_w[r]).abs() < 1e-6,
                    "{name} LWA lin ({r},{k})"
                );
                assert!(
                    (jw[(r + 3, k)] - ang_w[r]).abs() < 1e-6,
                    "{name} LWA ang ({r},{k}) {} vs {}",
                    jw[(r + 3, k)],
                    ang_w[r]
                );
                assert!((jl[(r, k)] - lin_l[r]).abs() < 1e-6, "{name} LOCAL lin");
                assert!((jl[(r + 3, k)] - ang_l[r]).abs() < 1e-6, "{name} LOCAL ang");
            }
        }
    }
}

#[test]
fn jdot_v_matches_finite_differences() {
    let mut rng = Rng(9);
    let model = humanoid();
    let mut data = Data::new(&model);
    let eps = 1e-6;
    for name in ["r_hand", "l_sole_rr"] {
        let f = model.frame_id(name).expect("frame");
        let q = rng.configuration(&model);
        let v = rng.vector(model.nv, 1.5);
        for rf in [ReferenceFrame::LocalWorldAligned, ReferenceFrame::Local] {
            let drift = frame_jdot_v(&model, &mut data, &q, &v, f, rf).expect("drift");
            let jv = |data: &mut Data, qq: &DVector<f64>| {
                frame_jacobian(&model, data, qq, f, rf).expect("J") * &v
            };
            let plus = jv(&mut data, &perturbed(&model, &q, &v, eps));
            let minus = jv(&mut data, &perturbed(&model, &q, &v, -eps));
            let fd = (plus - minus) / (2.0 * eps);
            let got = drift.to_vector();
            for r in 0..6 {
                assert!(
                    (fd[r] - got[r]).abs() < 1e-5 * (1.0 + fd[r].abs()),
                    "{name} {rf:?} row {r}: fd {} vs {}",
                    fd[r],
                    got[r]
                );
            }
            // The frame velocity agrees with J v.
            forward_kinematics_velocity(&model, &mut data, &q, &v).expect("fk");
            let vel = frame_velocity(&model, &data, f, rf).to_vector();
            let jvq = jv(&mut data, &q);
            assert!((vel - jvq).amax() < 1e-10);
        }
    }
}

#[test]
fn com_jacobian_and_velocity_match_finite_differences() {
    let mut rng = Rng(21);
    let model = humanoid();
    let mut data = Data::new(&model);
    let q = rng.configuration(&model);
    let jc = jacobian_center_of_mass(&model, &mut data, &q)
        .expect("Jcom")
        .clone();
    let c0 = data.com;
    assert!((center_of_mass(&model, &mut data, &q).expect("com") - c0).norm() < 1e-12);
    let eps = 1e-6;
    for k in 0..model.nv {
        let mut e = DVector::zeros(model.nv);
        e[k] = 1.0;
        let p = center_of_mass(&model, &mut data, &perturbed(&model, &q, &e, eps)).expect("com");
        let m = center_of_mass(&model, &mut data, &perturbed(&model, &q, &e, -eps)).expect("com");
        let fd = (p - m) / (2.0 * eps);
        for r in 0..3 {
            assert!((jc[(r, k)] - fd[r]).abs() < 1e-7, "Jcom ({r},{k})");
        }
    }
    let v = rng.vector(model.nv, 1.0);
    let (_, vcom) = center_of_mass_velocity(&model, &mut data, &q, &v).expect("vcom");
    let jv = &jc * &v;
    assert!((vcom - Vector3::new(jv[0], jv[1], jv[2])).norm() < 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Integration

fn energy(model: &Model, data: &mut Data, q: &DVector<f64>, v: &DVector<f64>) -> f64 {
    let m = crba(model, data, q).expect("crba").clone();
    let com = center_of_mass(model, data, q).expect("com");
    0.5 * v.dot(&(&m * v)) - model.total_mass() * model.gravity.dot(&com)
}

/// Passive swing of the fixed-base humanoid under gravity, RK4 with ABA: energy is conserved.
#[test]
fn energy_is_conserved_in_a_passive_swing() {
    let mut rng = Rng(2);
    let model = humanoid_fixed();
    let mut data = Data::new(&model);
    let mut q = rng.configuration(&model);
    let mut v = rng.vector(model.nv, 1.0);
    let tau = DVector::zeros(model.nv);
    let e0 = energy(&model, &mut data, &q, &v);
    let dt = 5e-4;
    let mut acc = |q: &DVector<f64>, v: &DVector<f64>| {
        aba(&model, &mut data, q, v, &tau).expect("aba").clone()
    };
    let mut moved = 0.0_f64;
    let q_start = q.clone();
    for _ in 0..1000 {
        let k1v = acc(&q, &v);
        let k1q = v.clone();
        let k2q = &v + &k1v * (dt / 2.0);
        let k2v = acc(&(&q + &k1q * (dt / 2.0)), &k2q);
        let k3q = &v + &k2v * (dt / 2.0);
        let k3v = acc(&(&q + &k2q * (dt / 2.0)), &k3q);
        let k4q = &v + &k3v * dt;
        let k4v = acc(&(&q + &k3q * dt), &k4q);
        q += (k1q + k2q * 2.0 + k3q * 2.0 + k4q) * (dt / 6.0);
        v += (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (dt / 6.0);
        moved = moved.max((&q - &q_start).amax());
    }
    let mut data = Data::new(&model);
    let e1 = energy(&model, &mut data, &q, &v);
    assert!(moved > 0.05, "the swing must actually move ({moved})");
    assert!(
        (e1 - e0).abs() < 1e-6 * e0.abs().max(1.0),
        "energy drift {e0} → {e1}"
    );
}

/// Floating base in free fall: the quaternion stays unit, and with gravity off the spatial
/// momentum magnitude and the kinetic energy are conserved (semi-implicit Lie-group Euler, small dt).
#[test]
fn free_flyer_integration_keeps_the_quaternion_unit() {
    let mut rng = Rng(4);
    let mut model = humanoid();
    model.gravity = Vector3::zeros();
    let mut data = Data::new(&model);
    let mut q = rng.configuration(&model);
    let mut v = rng.vector(model.nv, 2.0);
    for k in 0..6 {
        v[k] *= 3.0; // a fast tumble
    }
    let tau = DVector::zeros(model.nv);
    let e0 = energy(&model, &mut data, &q, &v);
    let mut next = DVector::zeros(model.nq);
    let dt = 2e-5;
    for _ in 0..5000 {
        let a = aba(&model, &mut data, &q, &v, &tau).expect("aba").clone();
        v += a * dt;
        integrate(&model, &q, &v, dt, &mut next).expect("integrate");
        std::mem::swap(&mut q, &mut next);
        let n = (q[3] * q[3] + q[4] * q[4] + q[5] * q[5] + q[6] * q[6]).sqrt();
        assert!((n - 1.0).abs() < 1e-12);
    }
    let e1 = energy(&model, &mut data, &q, &v);
    assert!((e1 - e0).abs() < 1e-3 * e0, "kinetic energy {e0} → {e1}");
}

#[test]
fn integrate_and_difference_are_consistent_on_se3() {
    let mut rng = Rng(8);
    let model = humanoid();
    let q = rng.configuration(&model);
    let v = rng.vector(model.nv, 1.0);
    let mut once = DVector::zeros(model.nq);
    let mut half = DVector::zeros(model.nq);
    let mut twice = DVector::zeros(model.nq);
    integrate(&model, &q, &v, 1.0, &mut once).expect("integrate");
    integrate(&model, &q, &v, 0.5, &mut half).expect("integrate");
    integrate(&model, &half, &v, 0.5, &mut twice).expect("integrate");
    // exp(v) = exp(v/2)·exp(v/2) for a constant twist (quaternions up to sign).
    let sign = if once[6] * twice[6] < 0.0 { -1.0 } else { 1.0 };
    for k in 0..model.nq {
        let s = if (3..7).contains(&k) { sign } else { 1.0 };
        assert!((once[k] - s * twice[k]).abs() < 1e-12, "index {k}");
    }
    let mut back = DVector::zeros(model.nv);
    difference(&model, &q, &once, &mut back).expect("difference");
    assert!((back - v).amax() < 1e-10);
}

// ---------------------------------------------------------------------------------------------
// Analytic cases

const PENDULUM: &str = r#"<robot name="pendulum">
  <link name="world"/>
  <joint name="pivot" type="continuous">
    <parent link="world"/><child link="bob"/>
    <origin xyz="0 0 2" rpy="0 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <link name="bob">
    <inertial><origin xyz="0 0 -0.5"/><mass value="2"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.1"/></inertial>
  </link>
</robot>"#;

#[test]
fn single_pendulum_is_analytic() {
    let model = Model::from_urdf_str(PENDULUM, BaseJoint::Auto).expect("pendulum");
    assert_eq!((model.nq, model.nv), (1, 1));
    let mut data = Data::new(&model);
    let (m, l, iyy, g) = (2.0, 0.5, 0.05, 9.81);
    for &theta in &[0.0, 0.3, -1.2, 2.5] {
        let q = DVector::from_element(1, theta);
        let mm = crba(&model, &mut data, &q).expect("crba")[(0, 0)];
        assert!((mm - (iyy + m * l * l)).abs() < 1e-12);
        // Bob below the pivot; rotation by θ about +y moves it to x = −l sin θ: gravity torque
        // about +y is m g l sin θ.
        let gq = gravity_torques(&model, &mut data, &q).expect("g")[0];
        assert!((gq - m * g * l * theta.sin()).abs() < 1e-12, "θ = {theta}");
        let v = DVector::from_element(1, 1.3);
        let tau = DVector::zeros(1);
        let acc = aba(&model, &mut data, &q, &v, &tau).expect("aba")[0];
        assert!((acc + m * g * l * theta.sin() / (iyy + m * l * l)).abs() < 1e-12);
    }
}

/// The same pendulum built programmatically, and a prismatic slider: M = m, g-force = m g.
#[test]
fn programmatic_model_and_prismatic_joint() {
    let mut model = Model::new("slider");
    let body = Inertia::from_com(3.0, Vector3::new(0.1, 0.0, 0.0), Matrix3::identity() * 0.01);
    model
        .add_joint(
            "slide",
            None,
            SE3::identity(),
            JointKind::Prismatic { axis: Vector3::z() },
            body,
            "carriage",
        )
        .expect("joint");
    let mut data = Data::new(&model);
    let q = DVector::from_element(1, 0.4);
    assert!((crba(&model, &mut data, &q).expect("crba")[(0, 0)] - 3.0).abs() < 1e-12);
    assert!((gravity_torques(&model, &mut data, &q).expect("g")[0] - 3.0 * 9.81).abs() < 1e-12);
    forward_kinematics(&model, &mut data, &q).expect("fk");
    assert!((data.o_m_i[0].trans.z - 0.4).abs() < 1e-15);
}

// ---------------------------------------------------------------------------------------------
// Operational-space inertia (docs/hand_previewer.md, eq. (21)–(23))

#[test]
fn operational_space_inertia_of_the_arm() {
    let mut rng = Rng(13);
    let model = humanoid();
    let mut data = Data::new(&model);
    let mut ws = OpSpaceWorkspace::new(&model, "chest", "r_hand").expect("chain");
    assert_eq!(ws.n(), 7);
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    for q in [q, rng.configuration(&model)] {
        let m_e = *ws.compute(&model, &mut data, &q).expect("M_e");
        // Independent recomputation from the full CRBA and the frame Jacobian.
        let m_full = crba(&model, &mut data, &q).expect("crba").clone();
        let f = model.frame_id("r_hand").expect("frame");
        let j_full = frame_jacobian(&model, &mut data, &q, f, ReferenceFrame::LocalWorldAligned)
            .expect("J")
            .clone();
        let n = ws.n();
        let h = DMatrix::from_fn(n, n, |r, c| m_full[(ws.dofs[r], ws.dofs[c])]);
        let j = DMatrix::from_fn(3, n, |r, c| j_full[(r, ws.dofs[c])]);
        // The chain's other Jacobian columns are exactly the non-arm joints.
        for name in [
            "r_shoulder_pitch",
            "r_shoulder_roll",
            "r_shoulder_yaw",
            "r_elbow",
            "r_wrist_prosup",
            "r_wrist_pitch",
            "r_wrist_yaw",
        ] {
            let jid = model.joint_id(name).expect("joint");
            assert!(ws.dofs.contains(&model.joints[jid].idx_v));
        }
        assert!(max_abs(&(&h - &ws.h_tilde)) < 1e-12);
        assert!(max_abs(&(&j - &ws.j_e)) < 1e-12);
        let h_inv = h.clone().try_inverse().expect("H̃ invertible");
        let li = &j * &h_inv * j.transpose();
        let expected = li.try_inverse().expect("Λ⁻¹ invertible");
        for r in 0..3 {
            for c in 0..3 {
                assert!((m_e[(r, c)] - expected[(r, c)]).abs() < 1e-9 * expected.amax());
            }
        }
        // M_e symmetric positive definite; J J̄ = 1; J̄ = H̃⁻¹ Jᵀ M_e.
        assert!((m_e - m_e.transpose()).amax() < 1e-12 * m_e.amax());
        assert!(m_e.cholesky().is_some());
        let jjbar = &j * &ws.j_bar;
        assert!((jjbar - DMatrix::identity(3, 3)).amax() < 1e-9);
    }
}

#[test]
fn operational_space_errors() {
    let model = humanoid();
    let mut data = Data::new(&model);
    // Not an ancestor.
    assert!(matches!(
        OpSpaceWorkspace::new(&model, "l_upper_arm", "r_hand"),
        Err(DynamicsError::NotAnAncestor { .. })
    ));
    assert!(matches!(
        OpSpaceWorkspace::new(&model, "chest", "r_handle"),
        Err(DynamicsError::UnknownFrame(n)) if n == "r_handle"
    ));
    // One joint cannot span three directions: J H̃⁻¹ Jᵀ is rank one.
    let mut ws = OpSpaceWorkspace::new(&model, "r_wrist_2", "r_hand").expect("chain");
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    assert!(matches!(
        ws.compute(&model, &mut data, &q),
        Err(DynamicsError::Singular(_))
    ));
}

// ---------------------------------------------------------------------------------------------
// Input checking and URDF robustness

#[test]
fn wrong_lengths_are_errors_not_panics() {
    let model = humanoid();
    let mut data = Data::new(&model);
    let q = model.neutral();
    let short = DVector::zeros(3);
    let v = DVector::zeros(model.nv);
    assert!(matches!(
        rnea(&model, &mut data, &short, &v, &v),
        Err(DynamicsError::DimensionMismatch {
            what: "q",
            expected: 39,
            got: 3
        })
    ));
    assert!(aba(&model, &mut data, &q, &short, &v).is_err());
    assert!(crba(&model, &mut data, &short).is_err());
    let mut nan = q.clone();
    nan[5] = f64::NAN;
    assert!(matches!(
        crba(&model, &mut data, &nan),
        Err(DynamicsError::NonFinite {
            what: "q",
            index: 5
        })
    ));
    let mut zero_quat = q.clone();
    zero_quat[6] = 0.0;
    assert!(matches!(
        crba(&model, &mut data, &zero_quat),
        Err(DynamicsError::InvalidJoint { joint, .. }) if joint == "root_joint"
    ));
    let mut out = DMatrix::zeros(6, 3);
    assert!(get_frame_jacobian(&model, &data, 0, ReferenceFrame::Local, &mut out).is_err());
}

/// A URDF in the style of real robot descriptions: meshes that do not exist here, continuous,
/// prismatic and fixed joints, zero-mass links, a root not called "base", joints out of order.
const REALISTIC: &str = r#"<?xml version="1.0"?>
<robot name="mobile_manipulator">
  <joint name="wrist" type="continuous">
    <parent link="forearm"/><child link="gripper"/>
    <origin xyz="0.3 0 0" rpy="0 1.5707963 0"/><axis xyz="0 0 1"/>
    <limit effort="10" velocity="3"/>
  </joint>
  <link name="gripper">
    <inertial><origin xyz="0 0 0.05" rpy="0.1 0.2 0.3"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0.0001" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/></inertial>
    <visual><geometry><mesh filename="package://robot_description/meshes/gripper.dae" scale="1 1 1"/></geometry></visual>
    <collision><geometry><mesh filename="file:///nonexistent/gripper.stl"/></geometry></collision>
  </link>
  <link name="chassis">
    <inertial><mass value="20"/><inertia ixx="0.5" ixy="0" ixz="0" iyy="0.8" iyz="0" izz="1.0"/></inertial>
    <visual><geometry><mesh filename="package://robot_description/meshes/chassis.dae"/></geometry></visual>
  </link>
  <joint name="lift" type="prismatic">
    <parent link="chassis"/><child link="mast"/>
    <origin xyz="0.1 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.5" effort="200" velocity="0.3"/>
  </joint>
  <link name="mast">
    <inertial><origin xyz="0 0 0.2"/><mass value="3"/>
      <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="camera_mount" type="fixed">
    <parent link="mast"/><child link="camera_link"/><origin xyz="0 0 0.45" rpy="0 0.3 0"/>
  </joint>
  <link name="camera_link"/>
  <joint name="camera_optical" type="fixed">
    <parent link="camera_link"/><child link="camera_optical_frame"/>
    <origin xyz="0 0 0" rpy="-1.5707963 0 -1.5707963"/>
  </joint>
  <link name="camera_optical_frame"/>
  <joint name="shoulder" type="revolute">
    <parent link="mast"/><child link="upper_arm"/>
    <origin xyz="0.05 0 0.4"/><axis xyz="0 1 1"/>
    <limit lower="-2" upper="2" effort="50" velocity="2"/>
  </joint>
  <link name="upper_arm">
    <inertial><origin xyz="0.15 0 0"/><mass value="1.5"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.012"/></inertial>
  </link>
  <joint name="arm_fixed_extension" type="fixed">
    <parent link="upper_arm"/><child link="forearm"/><origin xyz="0.3 0 0"/>
  </joint>
  <link name="forearm">
    <inertial><origin xyz="0.15 0 0"/><mass value="0"/>
      <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
</robot>"#;

#[test]
fn realistic_urdf_loads_and_is_consistent() {
    let model = Model::from_urdf_str(REALISTIC, BaseJoint::Auto).expect("realistic URDF");
    assert!(
        model.has_floating_base(),
        "root 'chassis' is not attached to world"
    );
    assert_eq!((model.nq, model.nv), (10, 9));
    let order: Vec<&str> = model.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(order, ["root_joint", "lift", "shoulder", "wrist"]);
    for f in [
        "chassis",
        "mast",
        "camera_link",
        "camera_optical_frame",
        "forearm",
        "gripper",
    ] {
        model.frame_id(f).expect("every link is a frame");
    }
    assert!((model.total_mass() - 25.0).abs() < 1e-12);
    let wrist = &model.joints[model.joint_id("wrist").expect("wrist")];
    assert_eq!(wrist.limits.upper, f64::INFINITY);
    let lift = &model.joints[model.joint_id("lift").expect("lift")];
    assert_eq!((lift.limits.lower, lift.limits.upper), (0.0, 0.5));

    let mut rng = Rng(17);
    let mut data = Data::new(&model);
    for _ in 0..3 {
        let q = rng.configuration(&model);
        let v = rng.vector(model.nv, 1.0);
        let a = rng.vector(model.nv, 1.0);
        let tau = rnea(&model, &mut data, &q, &v, &a).expect("rnea").clone();
        let ddq = aba(&model, &mut data, &q, &v, &tau).expect("aba").clone();
        assert!((ddq - &a).amax() < 1e-9);
    }
    // Fixed base on demand; the frame through two fixed joints sits where the URDF says.
    let fixed = Model::from_urdf_str(REALISTIC, BaseJoint::Fixed).expect("fixed");
    assert_eq!(fixed.nv, 3);
    let mut data = Data::new(&fixed);
    forward_kinematics(&fixed, &mut data, &fixed.neutral()).expect("fk");
    let cam = data.o_m_f[fixed.frame_id("camera_optical_frame").expect("frame")];
    assert!((cam.trans - Vector3::new(0.1, 0.0, 0.75)).norm() < 1e-12);
}

fn err_of(urdf: &str) -> DynamicsError {
    match Model::from_urdf_str(urdf, BaseJoint::Auto) {
        Ok(_) => panic!("malformed URDF accepted"),
        Err(e) => e,
    }
}

const LINK_A: &str = r#"<link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>"#;

fn two_links(joint: &str, link_b_inertial: &str) -> String {
    format!(r#"<robot name="r">{LINK_A}<link name="b">{link_b_inertial}</link>{joint}</robot>"#)
}

const GOOD_JOINT: &str = r#"<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"#;

#[test]
fn malformed_urdfs_yield_errors_naming_the_culprit() {
    // Sanity: the template itself is fine.
    Model::from_urdf_str(&two_links(GOOD_JOINT, ""), BaseJoint::Auto).expect("template");

    let e = err_of(&two_links(
        r#"<joint name="j" type="revolute"><parent link="nowhere"/><child link="b"/><axis xyz="0 0 1"/></joint>"#,
        "",
    ));
    assert_eq!(
        e,
        DynamicsError::MissingLink {
            joint: "j".into(),
            role: "parent",
            link: "nowhere".into()
        }
    );
    assert!(e.to_string().contains("nowhere") && e.to_string().contains("'j'"));

    let e = err_of(&two_links(
        r#"<joint name="hinge9" type="ball"><parent link="a"/><child link="b"/></joint>"#,
        "",
    ));
    assert_eq!(
        e,
        DynamicsError::UnsupportedJointType {
            joint: "hinge9".into(),
            kind: "ball".into()
        }
    );
    let e = err_of(&two_links(
        r#"<joint name="p" type="planar"><parent link="a"/><child link="b"/></joint>"#,
        "",
    ));
    assert!(matches!(e, DynamicsError::UnsupportedJointType { joint, .. } if joint == "p"));

    let nan = r#"<inertial><mass value="1"/><inertia ixx="nan" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let e = err_of(&two_links(GOOD_JOINT, nan));
    assert!(
        matches!(&e, DynamicsError::InvalidInertia { link, .. } if link == "b"),
        "{e}"
    );

    let nan_mass = r#"<inertial><mass value="NaN"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let e = err_of(&two_links(GOOD_JOINT, nan_mass));
    assert!(
        matches!(&e, DynamicsError::InvalidInertia { link, .. } if link == "b"),
        "{e}"
    );

    let not_pd = r#"<inertial><mass value="1"/><inertia ixx="1" ixy="2" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let e = err_of(&two_links(GOOD_JOINT, not_pd));
    assert!(
        matches!(&e, DynamicsError::InvalidInertia { link, reason } if link == "b" && reason.contains("positive definite")),
        "{e}"
    );

    let negative_mass = r#"<inertial><mass value="-1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    assert!(matches!(
        err_of(&two_links(GOOD_JOINT, negative_mass)),
        DynamicsError::InvalidInertia { .. }
    ));

    // Cycle: a → b → c → b is impossible with one parent per link, so the cycle is b ↔ c
    // detached from the root a.
    let cycle = format!(
        r#"<robot name="r">{LINK_A}<link name="b"/><link name="c"/>
        <joint name="j1" type="fixed"><parent link="b"/><child link="c"/></joint>
        <joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint></robot>"#
    );
    assert!(matches!(err_of(&cycle), DynamicsError::Cycle { link } if link == "b" || link == "c"));
    // Cycle through every link: no root at all.
    let full_cycle = r#"<robot name="r"><link name="b"/><link name="c"/>
        <joint name="j1" type="fixed"><parent link="b"/><child link="c"/></joint>
        <joint name="j2" type="fixed"><parent link="c"/><child link="b"/></joint></robot>"#;
    assert_eq!(err_of(full_cycle), DynamicsError::NoRoot);

    let two_parents = format!(
        r#"<robot name="r">{LINK_A}<link name="b"/><link name="c"/>
        <joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>
        <joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint></robot>"#
    );
    assert!(matches!(
        err_of(&two_parents),
        DynamicsError::MultipleParents { link, .. } if link == "c"
    ));

    let zero_axis = two_links(
        r#"<joint name="jz" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"#,
        "",
    );
    assert!(
        matches!(err_of(&zero_axis), DynamicsError::InvalidJoint { joint, .. } if joint == "jz")
    );

    assert!(matches!(
        err_of("<robot name='r'><link name='a'/><link name='a'/></robot>"),
        DynamicsError::DuplicateName { what: "link", .. }
    ));
    assert!(matches!(err_of("<robot name='r'"), DynamicsError::Parse(_)));
    assert!(matches!(
        Model::from_urdf_file("/nonexistent/robot.urdf", BaseJoint::Auto),
        Err(DynamicsError::Io { .. })
    ));
}

/// Zero-mass links are legal; a massless terminal body on a moving joint makes forward dynamics
/// singular, which is reported (not a NaN).
#[test]
fn zero_mass_links() {
    let massless_tip = two_links(GOOD_JOINT, "");
    let model = Model::from_urdf_str(&massless_tip, BaseJoint::Fixed).expect("legal");
    let mut data = Data::new(&model);
    let z = DVector::zeros(1);
    assert!(matches!(
        aba(&model, &mut data, &z, &z, &z),
        Err(DynamicsError::SingularJoint { joint }) if joint == "j"
    ));
    // RNEA and CRBA are still fine (M = 0 for that joint).
    assert_eq!(crba(&model, &mut data, &z).expect("crba")[(0, 0)], 0.0);
}

/// What real robots ship: point masses and zero inertias (sensor and optical frames), inertias
/// a rounding away from positive semi-definite, a tiny part's slightly invalid tensor, textures
/// without a file, `<parent>` elements of sensors, mimic joints. Taken (repaired where needed,
/// with a warning naming the link and the size of the repair); a tensor far from physical is
/// refused.
#[test]
fn real_world_urdf_quirks_load_with_warnings_and_meaningless_inertias_are_refused() {
    let inertial = |m: f64, d: [f64; 6]| {
        format!(
            r#"<inertial><mass value="{m}"/><inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/></inertial>"#,
            d[0], d[1], d[2], d[3], d[4], d[5]
        )
    };
    // A point mass on a fixed joint (an optical frame): loads, merged into its parent, no
    // warning; its mass counts.
    let fixed = r#"<joint name="j" type="fixed"><parent link="a"/><child link="b"/><origin xyz="0 0 1"/></joint>"#;
    let m = Model::from_urdf_str(
        &two_links(fixed, &inertial(0.01, [0.0; 6])),
        BaseJoint::Floating,
    )
    .expect("point mass");
    assert!(m.load_warnings.is_empty(), "{:?}", m.load_warnings);
    assert!((m.total_mass() - 1.01).abs() < 1e-12);
    assert!(m.frame_id("b").is_ok());
    // Rounding: a product of inertia one part in 1e11 too large, one principal moment
    // ≈ −1e-17 (ANYmal's base has −2.2e-22). Repaired, warned, naming the link.
    let rounding = r#"<inertial><mass value="1"/><inertia ixx="1e-6" ixy="1.00000000001e-6" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/></inertial>"#;
    let m = Model::from_urdf_str(&two_links(GOOD_JOINT, rounding), BaseJoint::Fixed)
        .expect("rounding-level indefinite inertia");
    assert_eq!(m.load_warnings.len(), 1, "{:?}", m.load_warnings);
    assert!(
        m.load_warnings[0].contains("link 'b': inertia tensor repaired"),
        "{:?}",
        m.load_warnings
    );
    // A tiny part's tensor, a principal moment 2e-8 kg·m² below zero (TIAGo's antenna has
    // −3.5e-8): repaired to positive semi-definite.
    let tiny = inertial(0.01, [6.0e-8, 8.0e-8, 0.0, 6.0e-8, 0.0, 3.5e-8]);
    let m =
        Model::from_urdf_str(&two_links(GOOD_JOINT, &tiny), BaseJoint::Fixed).expect("tiny part");
    assert_eq!(m.load_warnings.len(), 1, "{:?}", m.load_warnings);
    let w = &m.load_warnings[0];
    assert!(
        w.contains("link 'b'") && w.contains("largest change 2.0e-8"),
        "{w}"
    );
    let i = m.joints[m.joint_id("j").unwrap()].inertia;
    let eig = nalgebra::SymmetricEigen::new(i.inertia_com()).eigenvalues;
    assert!(eig.min() >= -1e-20, "repaired tensor {eig:?}");
    // Far from physical (eigenvalues 3, −1, 1): refused, naming the link.
    let far = inertial(1.0, [1.0, 2.0, 0.0, 1.0, 0.0, 1.0]);
    let e = err_of(&two_links(GOOD_JOINT, &far));
    assert!(
        matches!(&e, DynamicsError::InvalidInertia { link, reason } if link == "b" && reason.contains("more than a repair")),
        "{e}"
    );
    // A texture without a file, a sensor's <parent joint=…>, a mimic joint.
    let extras = format!(
        r#"<robot name="r">{LINK_A}<link name="b"><visual><geometry><box size="1 1 1"/></geometry>
        <material name="m"><texture /></material></visual></link>{GOOD_JOINT}
        <link name="c"/>
        <joint name="k" type="revolute"><parent link="b"/><child link="c"/><axis xyz="1 0 0"/>
          <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="j" multiplier="2"/></joint>
        <sensor name="ft" type="force_torque"><parent joint="j"/></sensor></robot>"#
    );
    let m = Model::from_urdf_str(&extras, BaseJoint::Fixed).expect("quirks");
    assert_eq!(m.nv, 2);
    assert!(
        m.load_warnings.iter().any(|w| w.contains("'k' mimics 'j'")),
        "{:?}",
        m.load_warnings
    );
    // A mesh without a file is an error that says so, with its line.
    let no_file = format!(
        "<robot name=\"r\">{LINK_A}\n<link name=\"b\">\n<visual><geometry><mesh/></geometry></visual></link>{GOOD_JOINT}</robot>"
    );
    let e = err_of(&no_file).to_string();
    assert!(
        e.contains("line 3") && e.contains("<mesh> of link 'b' lacks the attribute `filename`"),
        "{e}"
    );
}

/// A locked joint (Pinocchio's reduced model) is the full model frozen at the value: same mass,
/// CoM and frame placements, and `M` equal to the full `M` without the locked rows and columns.
#[test]
fn a_locked_joint_is_the_full_model_at_its_value() {
    let full = humanoid();
    let lock: std::collections::HashMap<String, f64> =
        [("l_elbow", 0.7), ("neck_yaw", -0.3), ("torso_roll", 0.1)]
            .into_iter()
            .map(|(n, v)| (n.to_string(), v))
            .collect();
    let reduced = Model::from_urdf_str_locked(icub_like::URDF, BaseJoint::Floating, &lock)
        .expect("reduced model");
    assert_eq!(reduced.nq, full.nq - 3);
    assert_eq!(reduced.nv, full.nv - 3);
    assert!((reduced.total_mass() - full.total_mass()).abs() < 1e-12);
    let locked_dofs: Vec<usize> = lock
        .keys()
        .map(|n| full.joints[full.joint_id(n).expect("joint")].idx_v)
        .collect();
    let mut rng = Rng(23);
    let (mut df, mut dr) = (Data::new(&full), Data::new(&reduced));
    for _ in 0..3 {
        let mut qf = rng.configuration(&full);
        for (n, &v) in &lock {
            qf[full.joints[full.joint_id(n).expect("joint")].idx_q] = v;
        }
        // The reduced configuration: the full one without the locked coordinates.
        let mut qr = reduced.neutral();
        for j in &reduced.joints {
            let jf = &full.joints[full.joint_id(&j.name).expect("same joint")];
            for k in 0..j.nq() {
                qr[j.idx_q + k] = qf[jf.idx_q + k];
            }
        }
        let cf = center_of_mass(&full, &mut df, &qf).expect("com");
        let cr = center_of_mass(&reduced, &mut dr, &qr).expect("com");
        assert!((cf - cr).norm() < 1e-12, "CoM {cf} vs {cr}");
        forward_kinematics(&full, &mut df, &qf).expect("fk");
        forward_kinematics(&reduced, &mut dr, &qr).expect("fk");
        for f in &full.frames {
            let a = &df.o_m_f[full.frame_id(&f.name).expect("frame")];
            let b = &dr.o_m_f[reduced.frame_id(&f.name).expect("every frame is kept")];
            assert!(
                (a.trans - b.trans).norm() < 1e-12 && (a.rot - b.rot).amax() < 1e-12,
                "frame {}",
                f.name
            );
        }
        let mf = crba(&full, &mut df, &qf).expect("crba").clone();
        let mr = crba(&reduced, &mut dr, &qr).expect("crba").clone();
        let kept: Vec<usize> = (0..full.nv).filter(|k| !locked_dofs.contains(k)).collect();
        let sub = DMatrix::from_fn(kept.len(), kept.len(), |r, c| mf[(kept[r], kept[c])]);
        assert!(max_abs(&(&sub - &mr)) < 1e-10, "M differs");
    }
    // A value outside the joint's limits is refused, naming the joint.
    let bad: std::collections::HashMap<String, f64> = [("l_elbow".to_string(), 10.0)].into();
    let e = Model::from_urdf_str_locked(icub_like::URDF, BaseJoint::Floating, &bad)
        .expect_err("outside the limits")
        .to_string();
    assert!(e.contains("l_elbow") && e.contains("locked at 10"), "{e}");
}

/// Armature (reflected rotor inertia) adds to `M`'s diagonal, and CRBA, RNEA and ABA agree
/// with it; a massless chain that would make `M` singular is invertible with it.
#[test]
fn armature_is_on_the_diagonal_and_the_algorithms_agree() {
    let plain = humanoid();
    let mut model = plain.clone();
    let mut rng = Rng(31);
    let mut arm = DVector::zeros(model.nv);
    for i in 0..model.joints.len() {
        if model.joints[i].nv() == 1 {
            let a = rng.uniform(0.001, 0.05);
            model.set_armature(i, a).expect("armature");
            arm[model.joints[i].idx_v] = a;
        }
    }
    assert!(model.set_armature(0, 0.1).is_err(), "not on the free flyer");
    let (mut d, mut dp) = (Data::new(&model), Data::new(&plain));
    let q = rng.configuration(&model);
    let m = crba(&model, &mut d, &q).expect("crba").clone();
    let mp = crba(&plain, &mut dp, &q).expect("crba").clone();
    assert!(max_abs(&(&m - &mp - DMatrix::from_diagonal(&arm))) < 1e-12);
    let v = rng.vector(model.nv, 1.0);
    let a = rng.vector(model.nv, 3.0);
    let h = nonlinear_effects(&model, &mut d, &q, &v)
        .expect("h")
        .clone();
    let tau = rnea(&model, &mut d, &q, &v, &a).expect("rnea").clone();
    assert!((&m * &a + &h - &tau).amax() < 1e-10, "RNEA ≠ M a + h");
    let ddq = aba(&model, &mut d, &q, &v, &tau).expect("aba").clone();
    assert!((&ddq - &a).amax() < 1e-8 * (1.0 + a.amax()), "ABA∘RNEA");
    // A massless link on a revolute joint: singular without armature, regular with it.
    let mut chain = Model::new("massless");
    let j = chain
        .add_joint(
            "j",
            None,
            SE3::identity(),
            JointKind::Revolute { axis: Vector3::z() },
            Inertia::from_com(0.0, Vector3::zeros(), Matrix3::zeros()),
            "b",
        )
        .expect("joint");
    let one = DVector::from_element(1, 1.0);
    let mut dc = Data::new(&chain);
    assert!(aba(&chain, &mut dc, &one, &one, &one).is_err());
    chain.set_armature(j, 0.01).expect("armature");
    let mut dc = Data::new(&chain);
    let ddq = aba(&chain, &mut dc, &one, &one, &one).expect("aba").clone();
    assert!((ddq[0] - 100.0).abs() < 1e-9, "τ / armature: {}", ddq[0]);
}

/// A hand whose two finger joints carry only massless links: M(q) is singular (its Cholesky
/// factorisation fails), and `inert_joints` names exactly those joints; with a rotor inertia on
/// each, M factors and none is named.
#[test]
fn joints_that_move_no_mass_are_found_and_make_m_singular() {
    const HAND: &str = r#"<robot name="hand">
  <link name="palm"><inertial><mass value="0.5"/><origin xyz="0 0 0"/>
    <inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger1"/>
  <link name="finger2"/>
  <joint name="wrist" type="revolute"><parent link="palm"/><child link="finger1"/>
    <origin xyz="0.05 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="tip" type="revolute"><parent link="finger1"/><child link="finger2"/>
    <origin xyz="0.03 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"#;
    let mut model = Model::from_urdf_str(HAND, BaseJoint::Floating).expect("hand");
    let names = |m: &Model| -> Vec<String> {
        m.inert_joints()
            .iter()
            .map(|&i| m.joints[i].name.clone())
            .collect()
    };
    let factors = |m: &Model| {
        let mut data = Data::new(m);
        crba(m, &mut data, &m.neutral())
            .expect("crba")
            .clone()
            .cholesky()
            .is_some()
    };
    assert_eq!(names(&model), ["wrist", "tip"]);
    assert!(!factors(&model), "M is singular");
    // One rotor inertia leaves the other joint inert: still singular.
    let wrist = model.joint_id("wrist").expect("wrist");
    model.set_armature(wrist, 1e-3).expect("armature");
    assert_eq!(names(&model), ["tip"]);
    assert!(!factors(&model));
    let tip = model.joint_id("tip").expect("tip");
    model.set_armature(tip, 1e-3).expect("armature");
    assert!(names(&model).is_empty());
    assert!(factors(&model), "M factors with both rotor inertias");
}

/// `[urdf] root_rpy`: the root link hung turned from an upright base is the same robot. At a
/// base orientation turned back by the same rotation, every frame, the CoM and the joints'
/// mass matrix are the original model's.
#[test]
fn a_turned_root_is_the_same_robot_on_an_upright_base() {
    let original = humanoid();
    let rpy = [std::f64::consts::FRAC_PI_2, 0.0, 0.3];
    let mut urdf = parse_urdf(icub_like::URDF).expect("the humanoid's URDF parses");
    let root = urdf
        .links
        .iter()
        .find(|l| urdf.joints.iter().all(|j| j.child.link != l.name))
        .expect("a root link")
        .name
        .clone();
    turn_root(&mut urdf, rpy).expect("the root turns");
    let turned = Model::from_urdf_robot_locked(&urdf, BaseJoint::Floating, &Default::default())
        .expect("the turned model builds");
    assert_eq!(turned.nv, original.nv);
    assert!((turned.total_mass() - original.total_mass()).abs() < 1e-12);
    let r0 = SE3::from_xyz_rpy([0.0; 3], rpy);
    // At the neutral posture the root link's frame is the turn itself.
    let mut d = Data::new(&turned);
    forward_kinematics(&turned, &mut d, &turned.neutral()).unwrap();
    update_frame_placements(&turned, &mut d);
    let at = d.o_m_f[turned.frame_id(&root).unwrap()];
    assert!((at.rot - r0.rot).abs().max() < 1e-12, "{at:?}");

    let mut rng = Rng(0x5eed_7a11);
    for _ in 0..5 {
        let q = rng.configuration(&original);
        // The same joints; the base turned back: R_turned = R_original R0ᵀ.
        let mut qt = q.clone();
        let quat = |q: &DVector<f64>| {
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                q[6], q[3], q[4], q[5],
            ))
        };
        let rot = quat(&q).to_rotation_matrix().into_inner() * r0.rot.transpose();
        let c = nalgebra::UnitQuaternion::from_matrix(&rot)
            .quaternion()
            .coords;
        for k in 0..4 {
            qt[3 + k] = c[k];
        }
        let (mut a, mut b) = (Data::new(&original), Data::new(&turned));
        forward_kinematics(&original, &mut a, &q).unwrap();
        forward_kinematics(&turned, &mut b, &qt).unwrap();
        update_frame_placements(&original, &mut a);
        update_frame_placements(&turned, &mut b);
        for (k, f) in original.frames.iter().enumerate() {
            let g = b.o_m_f[turned.frame_id(&f.name).unwrap()];
            let e = (a.o_m_f[k].trans - g.trans).norm() + (a.o_m_f[k].rot - g.rot).abs().max();
            assert!(e < 1e-12, "frame {}: {e:e}", f.name);
        }
        let ca = center_of_mass(&original, &mut a, &q).unwrap();
        let cb = center_of_mass(&turned, &mut b, &qt).unwrap();
        assert!((ca - cb).norm() < 1e-12);
        let ma = crba(&original, &mut a, &q).unwrap().clone();
        let mb = crba(&turned, &mut b, &qt).unwrap().clone();
        let n = original.nv - 6;
        let joints = (ma.view((6, 6), (n, n)) - mb.view((6, 6), (n, n)))
            .abs()
            .max();
        assert!(joints < 1e-10, "joints' mass matrix differs by {joints:e}");
    }
}
