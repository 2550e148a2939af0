//! Whole-body QP on the humanoid: each check uses an independent truth (Newton's law for the
//! CoM, the full equations of motion and ABA for the torques, finite differences for the
//! drifts, the URDF for the limits), not the controller's own matrices.

use nalgebra::{DMatrix, DVector, Vector3};
use upc::config::{Config, WbcConfig, WbcFormulation};
use upc::dynamics::spatial::Force;
use upc::dynamics::{
    Data, Model, ReferenceFrame, aba_with_external_forces, center_of_mass_velocity, crba,
    forward_kinematics, forward_kinematics_velocity, frame_jdot_v, frame_velocity, icub_like,
    integrate, nonlinear_effects,
};
use upc::wbc::com_bias::{com_drift, drift_pass, frame_drift_from_pass};
use upc::wbc::{FallbackReason, N_CONTACTS, WbcCommand, WbcStatus, WholeBodyController};

const G: f64 = 9.81;

fn config() -> WbcConfig {
    Config::embedded_default().unwrap().wbc
}

/// The iCub-like's contact, sole and hand frames (its description names them).
fn frames() -> upc::robot::BodyFrames {
    upc::robot::Robot::embedded_default()
        .expect("robot")
        .frames()
}

struct Setup {
    model: Model,
    data: Data,
    wbc: WholeBodyController,
    q: DVector<f64>,
    v: DVector<f64>,
}

fn setup_with(cfg: &WbcConfig) -> Setup {
    let model = icub_like::load().unwrap();
    let data = Data::new(&model);
    let wbc = WholeBodyController::new(&model, cfg, &frames()).unwrap();
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    let v = DVector::zeros(model.nv);
    Setup {
        model,
        data,
        wbc,
        q,
        v,
    }
}

fn setup() -> Setup {
    setup_with(&config())
}

fn hand_position(s: &Setup) -> Vector3<f64> {
    let mut d = Data::new(&s.model);
    forward_kinematics(&s.model, &mut d, &s.q).unwrap();
    d.o_m_f[s.model.frame_id("r_hand").unwrap()].trans
}

/// Holding the hand where it is, with the default gains.
fn hold(s: &Setup) -> WbcCommand<'static> {
    WbcCommand {
        hand_pos_des: hand_position(s),
        kp: 100.0,
        kd: 20.0,
        ..WbcCommand::default()
    }
}

/// Joint rates on the torso, arms and neck only (legs and base still: the feet stay at rest).
fn upper_body_velocity(model: &Model) -> DVector<f64> {
    let mut v = DVector::zeros(model.nv);
    for j in &model.joints[1..] {
        let leg = ["hip", "knee", "ankle"].iter().any(|n| j.name.contains(n));
        if !leg {
            v[j.idx_v] = 0.4 * ((j.idx_v as f64) * 1.3).sin();
        }
    }
    v
}

/// Torso and arm joints moved away from home (legs untouched: soles stay flat).
fn perturbed(model: &Model, q: &DVector<f64>) -> DVector<f64> {
    let mut q = q.clone();
    for j in &model.joints[1..] {
        let leg = ["hip", "knee", "ankle"].iter().any(|n| j.name.contains(n));
        if !leg {
            q[j.idx_q] += 0.15 * ((j.idx_q as f64) * 0.7).cos();
        }
    }
    q
}

struct Solution {
    status: WbcStatus,
    tau: DVector<f64>,
    ddq: DVector<f64>,
    forces: [Vector3<f64>; N_CONTACTS],
    iterations: u32,
}

fn solve(s: &mut Setup, cmd: &WbcCommand) -> Solution {
    let out = s.wbc.solve(&s.model, &mut s.data, &s.q, &s.v, cmd);
    Solution {
        status: out.status,
        tau: out.tau.clone(),
        ddq: out.ddq.clone(),
        forces: out.contact_forces,
        iterations: out.iterations,
    }
}

fn total_force(sol: &Solution) -> Vector3<f64> {
    sol.forces.iter().sum()
}

/// CoM acceleration implied by the contact forces (Newton: M c̈ = Σ f + M g).
fn newton_com_acc(model: &Model, sol: &Solution) -> Vector3<f64> {
    total_force(sol) / model.total_mass() - Vector3::new(0.0, 0.0, G)
}

/// Central finite difference of `vel(q ⊕ ±v dt, v)`: with v constant (q̈ = 0 in the
/// free-flyer's local convention) this is J̇ v.
fn fd_drift(
    model: &Model,
    q: &DVector<f64>,
    v: &DVector<f64>,
    vel: impl Fn(&DVector<f64>) -> Vector3<f64>,
) -> Vector3<f64> {
    let dt = 1e-6;
    let mut qp = q.clone();
    let mut qm = q.clone();
    integrate(model, q, v, dt, &mut qp).unwrap();
    integrate(model, q, v, -dt, &mut qm).unwrap();
    (vel(&qp) - vel(&qm)) / (2.0 * dt)
}

fn assert_cones_and_limits(s: &Setup, sol: &Solution, mu: f64) {
    for (c, f) in sol.forces.iter().enumerate() {
        // The soles are flat at these configurations: the normal is world z.
        let ft = (f.x * f.x + f.y * f.y).sqrt();
        assert!(f.z >= -1e-6, "contact {c}: negative normal force {f:?}");
        assert!(
            ft <= mu * f.z * (1.0 + 1e-6) + 1e-6,
            "contact {c}: outside the friction cone, |f_t| = {ft}, μ f_n = {}",
            mu * f.z
        );
    }
    for j in &s.model.joints[1..] {
        let t = sol.tau[j.idx_v - 6];
        assert!(
            t.abs() <= j.limits.effort * (1.0 + 1e-6) + 1e-6,
            "joint {}: |τ| = {} > {}",
            j.name,
            t.abs(),
            j.limits.effort
        );
    }
}

/// Residual of the full equations of motion `M q̈ + h − Sᵀτ − Σ J_cᵀ f` (all 38 rows),
/// with M, h and the corner Jacobians computed here.
fn eom_residual(s: &Setup, sol: &Solution) -> f64 {
    eom_residual_with_hand_force(s, sol, Vector3::zeros())
}

/// World-aligned linear Jacobian (3×nv) of a frame, from the dynamics library.
fn linear_jacobian(s: &Setup, frame: usize) -> DMatrix<f64> {
    let mut d = Data::new(&s.model);
    let mut jac = DMatrix::zeros(6, s.model.nv);
    upc::dynamics::compute_joint_jacobians(&s.model, &mut d, &s.q).unwrap();
    upc::dynamics::get_frame_jacobian(
        &s.model,
        &d,
        frame,
        ReferenceFrame::LocalWorldAligned,
        &mut jac,
    )
    .unwrap();
    jac.rows(0, 3).into_owned()
}

/// max |M q̈ + h − Sᵀτ − J_cᵀ f − J_hᵀ F| over the dofs, for a hand force F.
fn eom_residual_with_hand_force(s: &Setup, sol: &Solution, f_hand: Vector3<f64>) -> f64 {
    let model = &s.model;
    let mut d = Data::new(model);
    let m = crba(model, &mut d, &s.q).unwrap().clone();
    let h = nonlinear_effects(model, &mut d, &s.q, &s.v)
        .unwrap()
        .clone();
    let hand = model.frame_id("r_hand").unwrap();
    let mut r = &m * &sol.ddq + h - linear_jacobian(s, hand).transpose() * f_hand;
    for a in 0..model.nv - 6 {
        r[6 + a] -= sol.tau[a];
    }
    for (c, id) in s.wbc.contact_frames().iter().enumerate() {
        r -= linear_jacobian(s, *id).transpose() * sol.forces[c];
    }
    r.amax()
}

#[test]
fn a_known_hand_force_enters_the_equations_of_motion() {
    let mut s = setup();
    let f = Vector3::new(-30.0, 5.0, -10.0);
    let cmd = WbcCommand {
        hand_force: f,
        ..hold(&s)
    };
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    // M q̈ + h − Sᵀτ − J_cᵀ f_c = J_hᵀ F: the residual without the hand term is J_hᵀ F.
    let without = eom_residual(&s, &sol);
    assert!(without > 1.0, "the force was ignored: residual {without}");
    let with = eom_residual_with_hand_force(&s, &sol, f);
    assert!(with < 1e-5, "EoM residual with the hand force {with}");
    let model = &s.model;
    // Newton: the feet push back on the hand force, the CoM does not accelerate.
    let com_acc = (total_force(&sol) + f) / model.total_mass() - Vector3::new(0.0, 0.0, G);
    assert!(com_acc.norm() < 1e-2, "{com_acc:?}");
    assert!(
        (total_force(&sol).x + f.x).abs() < 0.5,
        "{:?}",
        total_force(&sol)
    );
}

#[test]
fn static_standing_forces_carry_the_weight() {
    let mut s = setup();
    let cmd = hold(&s);
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    let mg = s.model.total_mass() * G;
    let f = total_force(&sol);
    assert!(
        (f - Vector3::new(0.0, 0.0, mg)).norm() <= 0.01 * mg,
        "Σf = {f:?}, M g = {mg}"
    );
    // Both feet carry a share and every corner pushes.
    let left: f64 = sol.forces[..4].iter().map(|f| f.z).sum();
    assert!(
        left > 0.25 * mg && left < 0.75 * mg,
        "left foot carries {left} of {mg}"
    );
    assert!(sol.forces.iter().all(|f| f.z > 0.0), "{:?}", sol.forces);
    // Every corner loaded inside its cone: the cone solve decides, without clarabel.
    assert_eq!((s.wbc.counters().active_set, sol.iterations), (1, 0));
    assert_cones_and_limits(&s, &sol, config().friction);
    assert!(eom_residual(&s, &sol) < 1e-5, "{}", eom_residual(&s, &sol));
    assert_eq!(s.wbc.counters().solved, 1);
}

#[test]
fn feasible_com_acceleration_is_achieved() {
    let mut s = setup();
    s.v = upper_body_velocity(&s.model);
    let a_des = Vector3::new(0.3, -0.2, 0.1);
    let cmd = WbcCommand {
        com_acc: a_des,
        ..hold(&s)
    };
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    // Truth 1, Newton's law on the contact forces.
    let a_newton = newton_com_acc(&s.model, &sol);
    assert!(
        (a_newton - a_des).norm() < 1e-2,
        "{a_newton:?} vs {a_des:?}"
    );
    // Truth 2, kinematics: J_com q̈ + J̇_com v, the drift by finite differences.
    let model = &s.model;
    let mut d = Data::new(model);
    let jcom = upc::dynamics::jacobian_center_of_mass(model, &mut d, &s.q)
        .unwrap()
        .clone();
    let v = s.v.clone();
    let drift = fd_drift(model, &s.q, &s.v, |q| {
        let mut d = Data::new(model);
        center_of_mass_velocity(model, &mut d, q, &v).unwrap().1
    });
    assert!(drift.norm() > 1e-3, "the test needs a non-zero drift");
    let a_kin = &jcom * &sol.ddq + drift;
    assert!((a_kin - a_des).norm() < 1e-2, "{a_kin:?} vs {a_des:?}");
    assert!((a_kin - a_newton).norm() < 1e-4);
    assert_cones_and_limits(&s, &sol, config().friction);
}

#[test]
fn hand_acceleration_is_tracked() {
    let mut s = setup();
    s.q = perturbed(&s.model, &s.q);
    s.v = upper_body_velocity(&s.model);
    let hand = s.model.frame_id("r_hand").unwrap();
    let mut d = Data::new(&s.model);
    forward_kinematics_velocity(&s.model, &mut d, &s.q, &s.v).unwrap();
    let x = d.o_m_f[hand].trans;
    let xd = frame_velocity(&s.model, &d, hand, ReferenceFrame::LocalWorldAligned).lin;
    // Impedance law with an offset set-point: ẍ_cmd = K_p (x_des − x) + K_d (ẋ_des − ẋ) + ẍ_des.
    let (kp, kd) = (50.0, 10.0);
    let x_des = x + Vector3::new(0.01, -0.005, 0.008);
    let a_ff = Vector3::new(0.2, 0.0, -0.1);
    let cmd = WbcCommand {
        hand_pos_des: x_des,
        hand_vel_des: Vector3::zeros(),
        hand_acc_des: a_ff,
        kp,
        kd,
        ..WbcCommand::default()
    };
    let x_cmd = kp * (x_des - x) + kd * (-xd) + a_ff;
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    let mut jac = DMatrix::zeros(6, s.model.nv);
    upc::dynamics::compute_joint_jacobians(&s.model, &mut d, &s.q).unwrap();
    upc::dynamics::get_frame_jacobian(
        &s.model,
        &d,
        hand,
        ReferenceFrame::LocalWorldAligned,
        &mut jac,
    )
    .unwrap();
    let drift = frame_jdot_v(
        &s.model,
        &mut d,
        &s.q,
        &s.v,
        hand,
        ReferenceFrame::LocalWorldAligned,
    )
    .unwrap()
    .lin;
    let a_hand = jac.rows(0, 3) * &sol.ddq + drift;
    assert!(
        (a_hand - x_cmd).norm() < 0.02 * x_cmd.norm().max(0.1),
        "hand {a_hand:?} vs commanded {x_cmd:?}"
    );
    // The CoM request (zero) holds at the same time.
    assert!(newton_com_acc(&s.model, &sol).norm() < 1e-2);
    assert_cones_and_limits(&s, &sol, config().friction);
}

#[test]
fn torques_reproduce_the_accelerations_through_aba() {
    let mut s = setup();
    s.q = perturbed(&s.model, &s.q);
    s.v = upper_body_velocity(&s.model);
    let cmd = WbcCommand {
        com_acc: Vector3::new(-0.2, 0.1, 0.0),
        ..hold(&s)
    };
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    assert!(eom_residual(&s, &sol) < 1e-5, "{}", eom_residual(&s, &sol));
    // Forward dynamics: τ and the contact forces as external wrenches on the foot bodies.
    let model = &s.model;
    let mut d = Data::new(model);
    forward_kinematics(model, &mut d, &s.q).unwrap();
    let mut fext = vec![Force::zero(); model.njoints()];
    for (c, id) in s.wbc.contact_frames().iter().enumerate() {
        let body = model.frames[*id].parent.unwrap();
        let o = d.o_m_i[body];
        let p_local = o.inverse().act_point(&d.o_m_f[*id].trans);
        let f_local = o.rot.transpose() * sol.forces[c];
        fext[body] += Force::new(f_local, p_local.cross(&f_local));
    }
    let mut tau_full = DVector::zeros(model.nv);
    tau_full.rows_mut(6, model.nv - 6).copy_from(&sol.tau);
    let ddq = aba_with_external_forces(model, &mut d, &s.q, &s.v, &tau_full, &fext).unwrap();
    let err = (ddq - &sol.ddq).amax();
    assert!(err < 1e-4, "ABA q̈ differs from the QP's by {err}");
    // The soles do not accelerate (J_s q̈ + J̇_s v = 0; the feet are at rest so k J_s v = 0).
    for foot in s.wbc.foot_frames() {
        let mut jac = DMatrix::zeros(6, model.nv);
        upc::dynamics::compute_joint_jacobians(model, &mut d, &s.q).unwrap();
        upc::dynamics::get_frame_jacobian(
            model,
            &d,
            foot,
            ReferenceFrame::LocalWorldAligned,
            &mut jac,
        )
        .unwrap();
        let drift = frame_jdot_v(
            model,
            &mut d,
            &s.q,
            &s.v,
            foot,
            ReferenceFrame::LocalWorldAligned,
        )
        .unwrap()
        .to_vector();
        let acc = &jac * &sol.ddq + drift;
        assert!(acc.amax() < 1e-6, "sole {foot} accelerates: {acc:?}");
    }
    assert_cones_and_limits(&s, &sol, config().friction);
}

#[test]
fn infeasible_com_request_gives_the_best_feasible_solution() {
    let mut s = setup();
    let mu = config().friction;
    let mg = s.model.total_mass() * G;
    for ax in [Vector3::new(50.0, 0.0, 0.0), Vector3::new(0.0, -50.0, 50.0)] {
        for _ in 0..20 {
            let cmd = WbcCommand {
                com_acc: ax,
                ..hold(&s)
            };
            let sol = solve(&mut s, &cmd);
            assert_eq!(sol.status, WbcStatus::Solved, "request {ax:?}");
            assert_cones_and_limits(&s, &sol, mu);
            assert!(sol.tau.iter().all(|t| t.is_finite()));
            // Best effort: pushes towards the request as far as friction and torques allow,
            // never beyond it.
            let a = newton_com_acc(&s.model, &sol);
            assert!(a.dot(&ax) > 0.0, "{a:?} does not move towards {ax:?}");
            assert!(a.norm() < ax.norm());
            let f = total_force(&sol);
            assert!((f.x * f.x + f.y * f.y).sqrt() <= mu * f.z + 1e-6);
            assert!(f.z < 40.0 * mg);
        }
    }
    let c = s.wbc.counters();
    assert_eq!((c.ticks, c.solved, c.fallbacks), (40, 40, 0), "{c:?}");
    // The torque limits bind under these requests (the full QP decided), yet no tick built a
    // solver: the condensed one, the screening one (without torque rows) and the full one were
    // all built at construction.
    assert!(c.torque_limited > 0, "{c:?}");
    assert_eq!(c.solver_builds, 3);
    // Back to a normal request: solved as before.
    let cmd = hold(&s);
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    assert!((total_force(&sol) - Vector3::new(0.0, 0.0, mg)).norm() <= 0.01 * mg);
}

/// Limits no torque can keep: the whole robot rising at 2 m/s, whose soles' constraint
/// (−k J q̇, k = 10/s) asks them for 20 m/s² downward, which the ground cannot pull and legs at a
/// thousandth of the URDF's efforts cannot give. The QP is infeasible, and the tick commands the
/// optimum without limits, saturated at them, instead of gravity compensation
/// (docs/whole_body_qp.md, "Limits that cannot all hold").
#[test]
fn limits_that_cannot_all_hold_saturate_instead_of_falling_back() {
    let scale = 1e-3;
    let mut tight = setup_with(&WbcConfig {
        torque_limit_scale: scale,
        ..config()
    });
    tight.v[2] = 2.0;
    let cmd = hold(&tight);
    let sol = solve(&mut tight, &cmd);
    let c = tight.wbc.counters();
    assert_eq!(sol.status, WbcStatus::Solved, "{c:?}");
    assert_eq!((c.limits_saturated, c.fallbacks), (1, 0), "{c:?}");
    // The same tick without binding limits: its optimum, clamped, is what was commanded.
    let mut free = setup();
    free.v[2] = 2.0;
    let reference = solve(&mut free, &cmd);
    assert_eq!(free.wbc.counters().torque_limited, 0);
    let effort = tight.model.effort_limits();
    let mut saturated = 0;
    for (a, (t, r)) in sol.tau.iter().zip(reference.tau.iter()).enumerate() {
        let lim = scale * effort[6 + a];
        let want = r.clamp(-lim, lim);
        assert!(
            (t - want).abs() <= 1e-6 * (1.0 + r.abs()),
            "joint {a}: {t} vs {want}"
        );
        saturated += usize::from(r.abs() > lim);
    }
    assert!(saturated > 6, "only {saturated} joints beyond their limits");
    // Back within the limits' reach, nothing more is saturated.
    let mut s = setup();
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    assert_eq!(s.wbc.counters().limits_saturated, 0);
}

#[test]
fn invalid_input_falls_back_without_panicking() {
    let mut s = setup();
    let cmd = hold(&s);
    let good = solve(&mut s, &cmd);
    assert_eq!(good.status, WbcStatus::Solved);
    let q_good = s.q.clone();
    s.q[10] = f64::NAN;
    for _ in 0..100 {
        let sol = solve(&mut s, &cmd);
        assert_eq!(
            sol.status,
            WbcStatus::Fallback(FallbackReason::InvalidInput)
        );
        // Last good torque held.
        assert!((sol.tau.clone() - &good.tau).amax() < 1e-12);
    }
    s.q = q_good;
    let nan_cmd = WbcCommand {
        com_acc: Vector3::new(f64::NAN, 0.0, 0.0),
        ..cmd
    };
    let sol = solve(&mut s, &nan_cmd);
    assert_eq!(
        sol.status,
        WbcStatus::Fallback(FallbackReason::InvalidInput)
    );
    // A valid state with a bad command: gravity compensation, finite and within limits.
    assert!(sol.tau.iter().all(|t| t.is_finite()));
    assert_cones_and_limits(&s, &sol, 10.0);
    let sol = solve(&mut s, &cmd);
    assert_eq!(sol.status, WbcStatus::Solved);
    let c = s.wbc.counters();
    assert_eq!(
        (c.ticks, c.solved, c.fallbacks, c.consecutive_fallbacks),
        (103, 2, 101, 0)
    );
}

#[test]
fn fallback_torque_is_static_gravity_compensation() {
    let mut s = setup();
    let tau = s
        .wbc
        .fallback_torque(&s.model, &mut s.data, &s.q, &s.v)
        .unwrap()
        .clone();
    // M·0 + g = Sᵀτ + Σ J_cᵀ f with the fallback's own contact forces (v = 0: no damping).
    let sol = Solution {
        status: WbcStatus::Solved,
        tau,
        ddq: DVector::zeros(s.model.nv),
        forces: *s.wbc.last_contact_forces(),
        iterations: 0,
    };
    assert!(eom_residual(&s, &sol) < 1e-8, "{}", eom_residual(&s, &sol));
    let mg = s.model.total_mass() * G;
    assert!((total_force(&sol) - Vector3::new(0.0, 0.0, mg)).norm() < 1e-6 * mg);
    assert_cones_and_limits(&s, &sol, 1.0);
}

#[test]
fn reused_solver_matches_a_fresh_solver_each_tick() {
    // Clarabel on every tick: its solver reuse is what is checked.
    let clarabel = WbcConfig {
        active_set: false,
        ..config()
    };
    let mut warm = setup_with(&clarabel);
    let mut cfg = clarabel.clone();
    cfg.reuse_solver = false;
    let mut cold = setup_with(&cfg);
    let home = warm.q.clone();
    for k in 0..5 {
        let t = k as f64 * 0.3;
        let q = perturbed(&warm.model, &home);
        let q = &home + (q - &home) * t;
        warm.q = q.clone();
        cold.q = q;
        warm.v = upper_body_velocity(&warm.model) * t;
        cold.v = warm.v.clone();
        let cmd = WbcCommand {
            com_acc: Vector3::new(0.2 * t, -0.1, 0.05),
            ..hold(&warm)
        };
        let a = solve(&mut warm, &cmd);
        let b = solve(&mut cold, &cmd);
        assert_eq!(a.status, WbcStatus::Solved);
        assert_eq!(b.status, WbcStatus::Solved);
        // The task-level result is tight; the torques agree to the interior-point tolerance
        // (the load sharing among the 8 corners is only weakly determined by ‖f‖²).
        let df = (total_force(&a) - total_force(&b)).norm();
        assert!(df < 1e-3, "tick {k}: total contact forces differ by {df} N");
        let dt = (a.tau.clone() - &b.tau).amax();
        assert!(dt < 2e-2, "tick {k}: torques differ by {dt} N·m");
    }
    assert_eq!(
        warm.wbc.counters().solver_builds,
        3,
        "built at construction only"
    );
    assert!(cold.wbc.counters().solver_builds >= 5);
}

#[test]
fn com_and_frame_drifts_match_finite_differences() {
    let model = icub_like::load().unwrap();
    let mut d = Data::new(&model);
    let q = perturbed(
        &model,
        &upc::robot::Robot::embedded_default().expect("robot").home,
    );
    // A full velocity, base included: the drift formula must hold for any motion.
    let v = DVector::from_fn(model.nv, |k, _| 0.5 * ((k as f64) * 0.9 + 0.3).cos());
    let c = com_drift(&model, &mut d, &q, &v).unwrap();
    let fd = fd_drift(&model, &q, &v, |q| {
        let mut d = Data::new(&model);
        center_of_mass_velocity(&model, &mut d, q, &v).unwrap().1
    });
    assert!(
        (c - fd).norm() < 1e-5 * (1.0 + fd.norm()),
        "{c:?} vs {fd:?}"
    );
    // Frames read off the shared pass agree with the library's per-frame J̇v.
    let hand = model.frame_id("r_hand").unwrap();
    drift_pass(&model, &mut d, &q, &v, hand).unwrap();
    for name in ["l_sole", "r_sole", "r_sole_fl", "chest", "r_hand"] {
        let id = model.frame_id(name).unwrap();
        let shared = frame_drift_from_pass(&model, &d, id).to_vector();
        let mut d2 = Data::new(&model);
        let lib = frame_jdot_v(
            &model,
            &mut d2,
            &q,
            &v,
            id,
            ReferenceFrame::LocalWorldAligned,
        )
        .unwrap()
        .to_vector();
        assert!((shared - lib).amax() < 1e-10, "{name}");
    }
}

#[test]
fn config_section_is_checked_by_key() {
    let c = config();
    assert_eq!(frames().feet, ["l_sole".to_string(), "r_sole".to_string()]);
    assert!(c.reuse_solver);
    for (set, key) in [
        ("wbc.friction=-0.5", "wbc.friction"),
        ("wbc.torque_limit_scale=1.5", "wbc.torque_limit_scale"),
        ("wbc.w_reg_force=0", "wbc.w_reg_force"),
        ("wbc.max_iterations=0", "wbc.max_iterations"),
    ] {
        let mut l = upc::config::Config::default_layers().unwrap();
        l.push_override(set).unwrap();
        let e = l.build().unwrap_err().to_string();
        assert!(e.contains(key), "{set}: {e}");
    }
    let model = icub_like::load().unwrap();
    let mut bad = frames();
    bad.hand = "no_such_frame".into();
    let e = WholeBodyController::new(&model, &config(), &bad)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("no_such_frame"), "{e}");
}

/// Every joint (legs too) moved by up to `amp` and given a velocity: the soles tilt and move,
/// so the sole rows' drift and damping terms are exercised.
fn whole_body_state(
    model: &Model,
    home: &DVector<f64>,
    k: usize,
    amp: f64,
) -> (DVector<f64>, DVector<f64>) {
    let mut q = home.clone();
    let mut v = DVector::zeros(model.nv);
    let s = k as f64;
    for j in &model.joints[1..] {
        let i = j.idx_v as f64;
        q[j.idx_q] += amp * (0.37 * s + 1.7 * i).sin();
        v[j.idx_v] = 2.0 * amp * (0.23 * s + 0.9 * i).cos();
    }
    (q, v)
}

/// The condensed problem (q̈ eliminated, a QP in the contact forces) and the full one have the
/// same optimum: with and without active torque limits, soles flat and tilted.
#[test]
fn condensed_and_full_formulations_give_the_same_optimum() {
    for (limit_scale, amp) in [(1.0, 0.0), (1.0, 0.1), (0.2, 0.05)] {
        let tight = |f: WbcFormulation| WbcConfig {
            formulation: f,
            tolerance: 1e-9,
            torque_limit_scale: limit_scale,
            ..config()
        };
        let mut full = setup_with(&tight(WbcFormulation::Full));
        let mut cond = setup_with(&tight(WbcFormulation::Condensed));
        let home = full.q.clone();
        let mut at_limit = 0;
        for k in 0..6 {
            let t = k as f64 * 0.25;
            let (q, v) = if amp > 0.0 {
                whole_body_state(&full.model, &home, k, amp)
            } else {
                let q = perturbed(&full.model, &home);
                (
                    &home + (q - &home) * t,
                    upper_body_velocity(&full.model) * t,
                )
            };
            for s in [&mut full, &mut cond] {
                s.q = q.clone();
                s.v = v.clone();
            }
            let cmd = WbcCommand {
                com_acc: Vector3::new(0.3 * t, -0.2, 0.1),
                ..hold(&full)
            };
            let a = solve(&mut full, &cmd);
            let b = solve(&mut cond, &cmd);
            assert_eq!(a.status, WbcStatus::Solved);
            assert_eq!(b.status, WbcStatus::Solved);
            let dq = (a.ddq.clone() - &b.ddq).amax();
            let dt = (a.tau.clone() - &b.tau).amax();
            let df = (0..N_CONTACTS)
                .map(|c| (a.forces[c] - b.forces[c]).amax())
                .fold(0.0, f64::max);
            let lim = full.wbc.torque_limits();
            at_limit += (0..lim.len())
                .filter(|&i| a.tau[i].abs() > 0.999 * lim[i])
                .count();
            eprintln!(
                "limits ×{limit_scale}, amp {amp}, state {k}: |Δq̈| {dq:.2e}  |Δτ| {dt:.2e}  |Δf| {df:.2e}"
            );
            assert!(
                dq < 1e-4 && dt < 2e-2 && df < 5e-2,
                "state {k}: {dq} {dt} {df}"
            );
        }
        if limit_scale < 1.0 {
            assert!(
                at_limit > 0,
                "no torque limit was active: the case tests nothing"
            );
            // The condensed side held them itself (the cone solve with the limits' rows), not
            // through the full problem.
            let c = cond.wbc.counters();
            assert!(c.limits_condensed > 0, "{c:?}");
        }
    }
}

/// The cone solve (docs/whole_body_qp.md) returns clarabel's optimum: against clarabel on
/// every tick at a tight tolerance, over CoM requests and hand pushes that keep every corner
/// loaded, unload some corners (the apex of their cones) and put corners at their friction
/// limit (sliding on the cone's boundary), and hold torque limits at their bounds (the
/// reference's full problem with its torque rows). Each kind of tick must occur, or the check
/// tests nothing.
#[test]
fn the_cone_solve_is_clarabels_optimum() {
    let tight = WbcConfig {
        tolerance: 1e-9,
        ..config()
    };
    let mu = tight.friction;
    let mut fast = setup_with(&tight);
    let mut reference = setup_with(&WbcConfig {
        active_set: false,
        ..tight.clone()
    });
    let (mut by_newton, mut unloaded, mut sliding, mut full) = (0, 0, 0, 0);
    for ax in [0.0, 0.4, 0.8, 1.2, -1.2, 2.0, -2.5] {
        for fx in [0.0, -20.0, -40.0, -60.0] {
            let cmd = WbcCommand {
                com_acc: Vector3::new(ax, 0.1 * ax, 0.0),
                hand_force: Vector3::new(fx, 0.3 * fx, 0.0),
                ..hold(&fast)
            };
            let a = solve(&mut fast, &cmd);
            let b = solve(&mut reference, &cmd);
            assert_eq!(a.status, WbcStatus::Solved);
            assert_eq!(b.status, WbcStatus::Solved);
            assert_eq!(reference.wbc.counters().active_set, 0);
            let df = (0..N_CONTACTS)
                .map(|c| (a.forces[c] - b.forces[c]).amax())
                .fold(0.0, f64::max);
            let dt = (a.tau.clone() - &b.tau).amax();
            let dq = (a.ddq.clone() - &b.ddq).amax();
            let zeros = a.forces.iter().filter(|f| f.norm() == 0.0).count();
            // The soles are flat here: the normal is world z.
            let at_limit = a
                .forces
                .iter()
                .filter(|f| f.z > 1e-3 && f.x.hypot(f.y) >= mu * f.z * (1.0 - 1e-9))
                .count();
            eprintln!(
                "a_x {ax}, hand f_x {fx}: {zeros} corners unloaded, {at_limit} at their friction \
                 limit, {} clarabel iterations  |Δf| {df:.1e} N  |Δτ| {dt:.1e} N·m  |Δq̈| {dq:.1e}",
                a.iterations
            );
            if a.iterations == 0 {
                by_newton += 1;
                unloaded += usize::from(zeros > 0);
                sliding += usize::from(at_limit > 0);
                // Exact (its duality gap is closed: `condensed.rs`'s unit test) against a 1e-9
                // interior-point solve: the difference is the reference's own error, largest for
                // corners on their cone's boundary, which an interior point only approaches.
                let bound = if at_limit > 0 { 5e-3 } else { 1e-3 };
                assert!(
                    df < bound && dt < bound && dq < 1e-2 * bound,
                    "{df} {dt} {dq}"
                );
            } else {
                full += 1;
                assert!(df < 1e-6 && dt < 1e-6, "the same solve: {df} {dt}");
            }
        }
    }
    let held = fast.wbc.counters().limits_condensed;
    assert!(
        by_newton > 0 && unloaded > 0 && sliding > 0 && held > 0,
        "cone solve {by_newton} (with unloaded corners {unloaded}, sliding {sliding}, torque \
         limits held {held}), clarabel {full}"
    );
}
