//! Preview core against independent truths: the dense condensed solve, analytic steady states,
//! closed-loop eigenvalues, finite differences of eq. (26). Equations: docs/preview_control.md,
//! docs/disturbance.md, docs/hand_previewer.md, docs/gain_search.md.

use nalgebra::{Matrix3, Vector3};
use upc::config::{Config, ControllerKind, GainSolverKind, LqSolverKind};
use upc::offline::ReducedLoop;
use upc::preview::dense::CondensedHorizon;
use upc::preview::gain_search::{GainSearch, GainSearchInputs};
use upc::preview::{
    AxisState, CartTable, GainSchedule, HandPreviewer, HandState, PreviewError, PreviewPlan,
    Riccati, ZmpPreview,
};
use upc::robot::ReducedModel;
use upc::scenario::{ForceProfile, Impact, Scenario};

fn config_with(sets: &[&str]) -> Config {
    let mut l = upc::config::Config::default_layers().unwrap();
    for s in sets {
        l.push_override(s).unwrap();
    }
    l.build().unwrap()
}

/// The iCub-like's reduced models (computed from its model once).
fn robot() -> ReducedModel {
    static ROBOT: std::sync::OnceLock<ReducedModel> = std::sync::OnceLock::new();
    *ROBOT.get_or_init(|| upc::robot::Robot::embedded_default().unwrap().reduced())
}

fn model(c: &Config) -> CartTable {
    robot().cart_table(c.preview.period, c.robot.gravity)
}

/// The preview as `c` sets it (PC-T's tail as `preview.terminal_cost` says).
fn preview(c: &Config, n: usize, solver: LqSolverKind) -> ZmpPreview {
    ZmpPreview::new(model(c), c.preview.q_e, c.preview.r, n, solver)
        .with_terminal_cost(c.preview.terminal_cost)
}

/// A ZMP reference with a step and a lateral sway, and a state off the reference.
fn busy_problem(n: usize) -> ([AxisState; 2], Vec<[f64; 2]>) {
    let state = [
        Vector3::new(0.01, -0.02, 0.3),
        Vector3::new(-0.005, 0.04, -0.2),
    ];
    let refs = (0..n)
        .map(|i| {
            [
                if i > n / 3 { 0.05 } else { 0.0 },
                0.03 * (i as f64 * 0.02).sin(),
            ]
        })
        .collect();
    (state, refs)
}

/// A disturbance forecast with a vertical component, so α0 varies along the horizon.
fn busy_forces(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let s = (i as f64 * 0.03).sin();
            [-40.0 * s.max(0.0), 8.0 * s, 60.0 * s]
        })
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

#[test]
fn riccati_and_dense_give_the_same_first_input_c0_and_c1_n300() {
    for tail in ["true", "false"] {
        let c = config_with(&[&format!("preview.terminal_cost={tail}")]);
        same_first_input(&c);
    }
}

fn same_first_input(c: &Config) {
    let c = c.clone();
    let n = 300;
    let (state, refs) = busy_problem(n);
    let forces = busy_forces(n);
    for c1 in [false, true] {
        let mut ric = preview(&c, n, LqSolverKind::Riccati);
        let mut den = preview(&c, n, LqSolverKind::Dense);
        let (ur, ud) = if c1 {
            (
                ric.solve_c1(&state, &refs, &forces).unwrap(),
                den.solve_c1(&state, &refs, &forces).unwrap(),
            )
        } else {
            (
                ric.solve_c0(&state, &refs).unwrap(),
                den.solve_c0(&state, &refs).unwrap(),
            )
        };
        for a in 0..2 {
            assert!(
                rel(ur[a], ud[a]) < 1e-9,
                "c1={c1} axis {a}: riccati {} dense {}",
                ur[a],
                ud[a]
            );
        }
    }
}

#[test]
fn riccati_rollout_matches_the_whole_dense_input_horizon() {
    // Beyond the first input: the whole optimal sequence, from the condensed matrices directly
    // (with PC-T's tail, the default).
    let c = config_with(&[]);
    let n = 120;
    let m = model(&c);
    let (state, refs) = busy_problem(n);
    let forces = busy_forces(n);
    let mut ric = preview(&c, n, LqSolverKind::Riccati);
    ric.solve_c1(&state, &refs, &forces).unwrap();
    let mut plan = PreviewPlan::with_capacity(n);
    ric.plan(&state, &mut plan);
    let c2: Vec<f64> = forces
        .iter()
        .map(|f| m.output_acc_coeff(1.0 / (m.mass * m.gravity - f[2])))
        .collect();
    let targets: Vec<Vec<f64>> = (0..2)
        .map(|a| {
            (0..n)
                .map(|i| {
                    refs[i][a] - m.com_height * forces[i][a] / (m.mass * m.gravity - forces[i][2])
                })
                .collect()
        })
        .collect();
    let dense = CondensedHorizon::build(
        &m,
        &c2,
        Some(&m.infinite_tail(c.preview.q_e, c.preview.r)).filter(|_| c.preview.terminal_cost),
    );
    let u = dense
        .solve(
            c.preview.q_e,
            c.preview.r,
            [&state[0], &state[1]],
            [&targets[0], &targets[1]],
        )
        .unwrap();
    let scale = u[0].iter().fold(0.0f64, |s, v| s.max(v.abs()));
    for i in 0..n {
        assert!((plan.jerk[0][i] - u[0][i]).abs() < 1e-8 * scale, "step {i}");
    }
    // And the predicted ZMP equals P_x x̂ + P_u û + D (eq. 11).
    for i in 0..n {
        let mut p = dense.px[(i, 0)] * state[0][0]
            + dense.px[(i, 1)] * state[0][1]
            + dense.px[(i, 2)] * state[0][2];
        for j in 0..=i {
            p += dense.pu[(i, j)] * u[0][j];
        }
        p += refs[i][0] - targets[0][i];
        assert!(
            (plan.zmp[0][i] - p).abs() < 1e-9,
            "zmp step {i}: {} vs {p}",
            plan.zmp[0][i]
        );
    }
}

#[test]
fn condensed_matrices_match_the_state_space_model() {
    // eq. (5)/(12) closed forms against propagating A, B, C step by step.
    let c = config_with(&[]);
    let m = model(&c);
    let c2: Vec<f64> = (0..40)
        .map(|i| -m.com_height / m.gravity * (1.0 + 0.01 * i as f64))
        .collect();
    let h = CondensedHorizon::build(&m, &c2, None);
    let (a, b) = (m.a(), m.b());
    let mut ai = Matrix3::identity();
    for i in 0..40 {
        ai = a * ai;
        let row = Vector3::new(1.0, 0.0, c2[i]).transpose();
        let px = row * ai;
        for k in 0..3 {
            assert!((h.px[(i, k)] - px[k]).abs() < 1e-12);
        }
        let mut aj = Matrix3::identity();
        for j in (0..=i).rev() {
            let pu = (row * aj * b)[0];
            assert!((h.pu[(i, j)] - pu).abs() < 1e-14, "({i},{j})");
            aj = a * aj;
        }
    }
}

#[test]
fn reused_factorisation_is_invalidated_when_alpha0_changes() {
    let c = config_with(&[]);
    let n = 150;
    let (state, refs) = busy_problem(n);
    let a = busy_forces(n);
    let b: Vec<[f64; 3]> = a.iter().map(|f| [f[0], f[1], -f[2]]).collect();
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    p.solve_c1(&state, &refs, &a).unwrap();
    let again = p.solve_c1(&state, &refs, &b).unwrap();
    let fresh = preview(&c, n, LqSolverKind::Riccati)
        .solve_c1(&state, &refs, &b)
        .unwrap();
    assert_eq!(again, fresh);
    let back = p.solve_c1(&state, &refs, &a).unwrap();
    let fresh = preview(&c, n, LqSolverKind::Riccati)
        .solve_c1(&state, &refs, &a)
        .unwrap();
    assert_eq!(back, fresh);
}

/// The controller's case: α0 moves every tick (the forecast's vertical force slides along the
/// horizon), sometimes not (the fused pass then hands over to the stored preview gains). The
/// first inputs agree with a dense solve of each tick's problem, and the plan rolled out from
/// the stored gains starts with the input returned.
#[test]
fn alpha0_varying_every_tick_matches_the_dense_solve() {
    let c = config_with(&[]);
    let n = 300;
    let (mut state, refs) = busy_problem(n);
    let mut ric = preview(&c, n, LqSolverKind::Riccati);
    let mut plan = upc::preview::PreviewPlan::with_capacity(n);
    let mut worst = 0.0f64;
    for k in 0..24 {
        // Every third tick repeats the last forecast (same α0 rows).
        let shift = k - k / 3;
        let forces: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let s = ((i + shift) as f64 * 0.03).sin();
                [-40.0 * s.max(0.0), 8.0 * s, 60.0 * s]
            })
            .collect();
        let ur = ric.solve_c1(&state, &refs, &forces).unwrap();
        let ud = preview(&c, n, LqSolverKind::Dense)
            .solve_c1(&state, &refs, &forces)
            .unwrap();
        // Relative to the tick's larger input: an axis whose input nearly cancels (1e-3 of
        // the other's) is not measured against its own size.
        let scale = ud[0].abs().max(ud[1].abs());
        for a in 0..2 {
            let err = (ur[a] - ud[a]).abs() / scale;
            worst = worst.max(err);
            assert!(
                err < 1e-9,
                "tick {k} axis {a}: riccati {} dense {}",
                ur[a],
                ud[a]
            );
        }
        ric.plan(&state, &mut plan);
        for a in 0..2 {
            assert!(
                rel(plan.jerk[a][0], ur[a]) < 1e-9,
                "tick {k} axis {a}: plan"
            );
            state[a] = model(&c).step(&state[a], ur[a]);
        }
    }
    eprintln!("worst relative difference to the dense solve: {worst:.2e}");
}

#[test]
fn c1_with_zero_disturbance_equals_c0() {
    let c = config_with(&[]);
    let n = 300;
    let (state, refs) = busy_problem(n);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let u0 = p.solve_c0(&state, &refs).unwrap();
    let u1 = p.solve_c1(&state, &refs, &vec![[0.0; 3]; n]).unwrap();
    // The first solve runs the fused backward pass, the second (same α0 rows) the preview
    // gains: the same numbers summed in another order.
    for a in 0..2 {
        assert!(rel(u1[a], u0[a]) < 1e-12, "axis {a}: {u0:?} {u1:?}");
    }
}

fn constant_force_scenario(f: [f64; 3]) -> Scenario {
    Scenario {
        name: "constant".into(),
        description: String::new(),
        duration: 12.0,
        zmp_reference: [0.0, 0.0],
        force: ForceProfile::Samples(vec![(-1.0, f), (1e9, f)]),
        config: None,
        origin: "test".into(),
        force_scale: 1.0,
    }
}

#[test]
fn constant_lateral_force_shifts_the_zmp_by_the_analytic_amount() {
    // A constant hand force, held since before t = 0, reaches the CoM fully (F_dis = F_ext at rest).
    // C0 ignores it: the ZMP sits at p_ref + z_c F_y / (M g − F_z) (eq. 10).
    // C1 compensates: the CoM settles at −z_c F_y / (M g − F_z) and the ZMP returns to p_ref.
    let c = config_with(&[]);
    let f = [0.0, 25.0, 40.0];
    let scenario = constant_force_scenario(f);
    let shift = robot().com_height * f[1] / (robot().mass * c.robot.gravity - f[2]);
    let c0 = ReducedLoop::new(&c, robot(), &scenario, ControllerKind::C0)
        .run()
        .unwrap();
    let c1 = ReducedLoop::new(&c, robot(), &scenario, ControllerKind::C1)
        .run()
        .unwrap();
    let (l0, l1) = (c0.rows.last().unwrap(), c1.rows.last().unwrap());
    assert!(
        (l0.zmp[1] - shift).abs() < 1e-4 * shift,
        "C0 ZMP {} vs analytic {shift}",
        l0.zmp[1]
    );
    assert!(l0.com[1].abs() < 1e-9, "C0 does not move the CoM");
    assert!(l1.zmp[1].abs() < 1e-4 * shift, "C1 ZMP {}", l1.zmp[1]);
    assert!(
        (l1.com[1] + shift).abs() < 1e-4 * shift,
        "C1 CoM {} vs {}",
        l1.com[1],
        -shift
    );
}

/// The hand previewer of the iCub-like's M_e and nominal gains, a set-point and a push
/// ([`hold_against`] predicts `n` steps of it).
struct HandCase {
    hp: HandPreviewer,
    m_e: Matrix3<f64>,
    gains: GainSchedule,
    des: HandState,
    f: Vector3<f64>,
    n: usize,
}

fn hand_case(n: usize) -> HandCase {
    let c = config_with(&[]);
    let m_e = robot().effective_mass;
    HandCase {
        hp: HandPreviewer::new(c.preview.period, m_e, n).unwrap(),
        m_e,
        gains: GainSchedule::constant(n, c.hand.kp, c.nominal_kd(c.hand.kp)),
        des: HandState {
            pos: Vector3::new(0.3, -0.1, 0.8),
            ..Default::default()
        },
        f: Vector3::new(-30.0, 7.0, 4.0),
        n,
    }
}

/// The case's hand from `x0` under its constant push, set-point and gains.
fn hold_against(h: &mut HandCase, x0: &HandState) {
    let n = h.n;
    h.hp.predict(x0, &vec![h.des; n], &h.gains, &vec![h.f.into(); n], n)
        .unwrap();
}

#[test]
fn hand_at_rest_transmits_the_external_force() {
    let mut h = hand_case(200);
    let (kp, f) = (h.gains.kp[0], h.f);
    // Static equilibrium: K_p M_e (x − x_des) = F_ext.
    let x0 = HandState {
        pos: h.des.pos + h.m_e.try_inverse().unwrap() * f / kp,
        ..Default::default()
    };
    hold_against(&mut h, &x0);
    let hp = &h.hp;
    for (i, fd) in hp.disturbance().iter().enumerate() {
        for k in 0..3 {
            assert!(
                (fd[k] - f[k]).abs() < 1e-9,
                "step {i} axis {k}: {} vs {}",
                fd[k],
                f[k]
            );
        }
    }
}

/// HP-1: a held door keeps the hand on its path e. From rest the hand accelerates along e as
/// the push on e over the arm's and the leaf's mass along e; at equilibrium the arm holds the
/// push along e, F_dis = F_e M_e e / (eᵀ M_e e), whose part across e the hinge takes; the
/// push's own part across e never moves the hand.
#[test]
fn a_held_door_keeps_the_hand_on_its_path_and_its_hinge_takes_the_rest() {
    let mut h = hand_case(600);
    let (m_e, f, des, n) = (h.m_e, h.f, h.des, h.n);
    let e = Vector3::new(1.0, 0.1, -0.05).normalize();
    let m = 5.1;
    h.hp.set_held_path(Some((e, m)));
    // Started at rest with a stray velocity across e, which the door does not allow.
    let x0 = HandState {
        vel: e.cross(&Vector3::z()).normalize() * 0.2,
        ..des
    };
    hold_against(&mut h, &x0);
    let ee = e.dot(&(m_e * e));
    let first = h.hp.states()[0].acc;
    let expected = e * (e.dot(&f) / (ee + m));
    assert!((first - expected).norm() < 1e-12, "{first} vs {expected}");
    for (i, x) in h.hp.states().iter().enumerate() {
        let off = (x.pos - des.pos).cross(&e).norm() + x.vel.cross(&e).norm();
        assert!(off < 1e-12, "step {i}: the hand left the path by {off}");
    }
    let held = m_e * e * (e.dot(&f) / ee);
    let last = Vector3::from(h.hp.disturbance()[n - 1]);
    assert!((last - held).norm() < 1e-3, "{last} vs {held}");
    // Across e the door passes a force the free hand's model never shows.
    assert!((held - e * e.dot(&held)).norm() > 5.0);
    // Nothing held: eq. (24) again, the push passed whole.
    h.hp.set_held_path(None);
    hold_against(&mut h, &des);
    let last = Vector3::from(h.hp.disturbance()[n - 1]);
    assert!((last - f).norm() < 1e-3, "{last} vs {f}");
}

/// FC-0b against HP-1: a push F_e along the path, taken where the held hand feels it
/// (`felt_direction`) and previewed by the free hand of eq. (24), reaches the body at rest as
/// the same F_dis as the push itself previewed on the door's path (HP-1): two derivations of
/// the hinge's share, one in the forecast and one in the previewer.
#[test]
fn a_push_felt_at_the_held_hand_is_the_held_paths_disturbance_at_rest() {
    let mut h = hand_case(600);
    let (m_e, des, n) = (h.m_e, h.des, h.n);
    let e = Vector3::new(1.0, 0.1, -0.05).normalize();
    let push = e * -60.0;
    h.hp.set_held_path(Some((e, 0.0)));
    h.f = push;
    hold_against(&mut h, &des);
    let on_path = Vector3::from(h.hp.disturbance()[n - 1]);
    let d = upc::control::held_object::felt_direction(&e, &m_e).unwrap();
    assert!((e.dot(&d) - 1.0).abs() < 1e-12, "{d}");
    h.hp.set_held_path(None);
    h.f = d * e.dot(&push);
    hold_against(&mut h, &des);
    let felt = Vector3::from(h.hp.disturbance()[n - 1]);
    assert!((felt - on_path).norm() < 1e-3, "{felt} vs {on_path}");
    // The hinge's share is real here: the felt push leaves e by more than 5 N.
    assert!((felt - e * e.dot(&felt)).norm() > 5.0, "{felt}");
    // An isotropic stiffness pushes back along e itself: FC-0 again.
    let d = upc::control::held_object::felt_direction(&e, &Matrix3::identity()).unwrap();
    assert!((d - e).norm() < 1e-12, "{d}");
    assert!(upc::control::held_object::felt_direction(&e, &Matrix3::zeros()).is_none());
}

#[test]
fn softer_stiffness_delays_and_lowers_the_disturbance_peak() {
    let c = config_with(&[]);
    let m_e = robot().effective_mass;
    let t = c.preview.period;
    let n = 400;
    let impact = ForceProfile::Impacts(vec![Impact {
        start: 0.2,
        rise: 0.05,
        hold: 0.0,
        fall: 0.05,
        force: [-60.0, 0.0, 0.0],
    }]);
    let mut f = vec![[0.0; 3]; n];
    impact.sample_into(t, t, &mut f);
    let des = HandState::default();
    let peak = |kp: f64| {
        let mut hp = HandPreviewer::new(t, m_e, n).unwrap();
        hp.predict(
            &des,
            &vec![des; n],
            &GainSchedule::constant(n, kp, 2.0 * kp.sqrt()),
            &f,
            n,
        )
        .unwrap();
        let (i, v) = hp
            .disturbance()
            .iter()
            .enumerate()
            .map(|(i, d)| (i, d[0].abs()))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        (i, v)
    };
    let (i_stiff, p_stiff) = peak(2000.0);
    let (i_soft, p_soft) = peak(100.0);
    assert!(
        p_soft < 0.9 * p_stiff,
        "soft peak {p_soft} vs stiff {p_stiff}"
    );
    assert!(
        i_soft > i_stiff,
        "soft peak at step {i_soft}, stiff at {i_stiff}"
    );
}

#[test]
fn zmp_step_reference_settles_with_the_preview_transient() {
    // Kajita's preview control on a 5 cm step at t = 2 s: the CoM starts moving before the step
    // (preview), the ZMP follows the step closely, and everything settles.
    let c = config_with(&[]);
    let n = c.preview.horizon;
    let t = c.preview.period;
    let step_at = (2.0 / t) as usize;
    let total = (6.0 / t) as usize;
    let reference = |k: usize| if k >= step_at { 0.05 } else { 0.0 };
    let m = model(&c);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let mut state = [Vector3::zeros(), Vector3::zeros()];
    let mut refs = vec![[0.0; 2]; n];
    let mut zmp = Vec::new();
    let mut com = Vec::new();
    for k in 0..total {
        for (i, r) in refs.iter_mut().enumerate() {
            r[0] = reference(k + 1 + i);
        }
        let u = p.solve_c0(&state, &refs).unwrap();
        for a in 0..2 {
            state[a] = m.step(&state[a], u[a]);
        }
        zmp.push(m.zmp(&state[0], m.nominal_alpha0(), 0.0));
        com.push(state[0][0]);
    }
    // Anticipation: the CoM has moved well before the step.
    assert!(
        com[step_at - 40] > 1e-3,
        "CoM at 0.2 s before the step: {}",
        com[step_at - 40]
    );
    // Tracking: the ZMP cannot jump (ẍ is continuous), so it crosses over around the step
    // and tracks closely elsewhere.
    let window = (0.15 / t) as usize;
    let err = |k: usize| (zmp[k] - reference(k + 1)).abs();
    let near = (step_at - window..step_at + window)
        .map(err)
        .fold(0.0, f64::max);
    let far = (0..total)
        .filter(|k| k.abs_diff(step_at) >= window)
        .map(err)
        .fold(0.0, f64::max);
    eprintln!("ZMP error near the step {near}, elsewhere {far}");
    assert!(
        near < 0.5 * 0.05 && near > 0.1 * 0.05,
        "near the step {near}"
    );
    assert!(far < 0.05 * 0.05, "away from the step {far}");
    // Settled 2 s after the step: CoM and ZMP at 5 cm.
    let late = step_at + (2.0 / t) as usize;
    for k in late..total {
        assert!(
            (zmp[k] - 0.05).abs() < 1e-4 && (com[k] - 0.05).abs() < 1e-4,
            "k={k}"
        );
    }
}

#[test]
fn closed_loop_is_stable() {
    // The receding-horizon feedback u = K_0 x of C0 makes A + B K_0 Schur stable, and a 20 s
    // closed loop from an offset state converges to the reference.
    let c = config_with(&[]);
    let n = c.preview.horizon;
    let m = model(&c);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let zero = vec![[0.0; 2]; n];
    // K_0 from the solver: u at unit states with a zero reference.
    let mut k = [0.0; 3];
    for (j, kj) in k.iter_mut().enumerate() {
        let mut e = Vector3::zeros();
        e[j] = 1.0;
        *kj = p.solve_c0(&[e, e], &zero).unwrap()[0];
    }
    let closed = m.a() + m.b() * Vector3::from(k).transpose();
    let rho = closed
        .complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max);
    assert!(rho < 1.0, "spectral radius {rho}");
    let mut x = [
        Vector3::new(0.05, -0.1, 0.5),
        Vector3::new(-0.03, 0.2, -1.0),
    ];
    for _ in 0..(20.0 / c.preview.period) as usize {
        let u = p.solve_c0(&x, &zero).unwrap();
        for a in 0..2 {
            x[a] = m.step(&x[a], u[a]);
        }
    }
    assert!(x[0].norm() < 1e-8 && x[1].norm() < 1e-8, "{x:?}");
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let c = config_with(&[]);
    let n = 100;
    let (state, refs) = busy_problem(n);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let weight = robot().mass * c.robot.gravity;
    let mut lift = vec![[0.0; 3]; n];
    lift[17][2] = weight + 1.0;
    assert!(matches!(
        p.solve_c1(&state, &refs, &lift),
        Err(PreviewError::LiftOff { step: 18, .. })
    ));
    lift[17][2] = weight;
    assert!(matches!(
        p.solve_c1(&state, &refs, &lift),
        Err(PreviewError::LiftOff { .. })
    ));
    let mut nan = vec![[0.0; 3]; n];
    nan[3][0] = f64::NAN;
    assert!(matches!(
        p.solve_c1(&state, &refs, &nan),
        Err(PreviewError::NotFinite { step: 4, .. })
    ));
    nan[3][0] = f64::INFINITY;
    assert!(matches!(
        p.solve_c1(&state, &refs, &nan),
        Err(PreviewError::NotFinite { .. })
    ));
    // The first bad sample is the one reported, whatever its kind; F_z = −∞ is not finite
    // (not a lift-off); a finite force so large that α overflows is not finite either.
    nan[3][0] = 0.0;
    nan[40][2] = weight * 2.0;
    nan[60][1] = f64::NAN;
    assert!(matches!(
        p.solve_c1(&state, &refs, &nan),
        Err(PreviewError::LiftOff { step: 41, .. })
    ));
    nan[20][2] = f64::NEG_INFINITY;
    assert!(matches!(
        p.solve_c1(&state, &refs, &nan),
        Err(PreviewError::NotFinite { step: 21, .. })
    ));
    let mut huge = vec![[0.0; 3]; n];
    huge[9] = [f64::MAX, 0.0, weight - 0.5];
    assert!(matches!(
        p.solve_c1(&state, &refs, &huge),
        Err(PreviewError::NotFinite { step: 10, .. })
    ));
    let mut bad_refs = refs.clone();
    bad_refs[7][1] = f64::INFINITY;
    bad_refs[9][0] = f64::NAN;
    assert!(matches!(
        p.solve_c0(&state, &bad_refs),
        Err(PreviewError::NotFinite {
            what: "ZMP reference",
            step: 8
        })
    ));
    // After the errors, a valid forecast solves as before.
    assert!(p.solve_c1(&state, &refs, &busy_forces(n)).is_ok());
    let short = vec![[0.0; 3]; n - 1];
    assert!(matches!(
        p.solve_c1(&state, &refs, &short),
        Err(PreviewError::ForecastTooShort {
            got: 99,
            need: 100,
            ..
        })
    ));
    assert!(matches!(
        p.solve_c0(&state, &refs[..50]),
        Err(PreviewError::ForecastTooShort { .. })
    ));
    let bad_state = [Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros()];
    assert!(matches!(
        p.solve_c0(&bad_state, &refs),
        Err(PreviewError::NotFinite { .. })
    ));
    // The messages say what is wrong.
    let msg = p.solve_c1(&state, &refs, &lift).unwrap_err().to_string();
    assert!(
        msg.contains("lifts the robot") && msg.contains("step 18"),
        "{msg}"
    );
    // Hand previewer: bad M_e and gains.
    let not_spd = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    assert!(matches!(
        HandPreviewer::new(0.005, not_spd, n),
        Err(PreviewError::EffectiveMassNotSpd)
    ));
    let mut hp = HandPreviewer::new(0.005, Matrix3::identity(), n).unwrap();
    let x = HandState::default();
    let mut gains = GainSchedule::constant(n, 100.0, 20.0);
    gains.kp[5] = -1.0;
    assert!(matches!(
        hp.predict(&x, &vec![x; n], &gains, &vec![[0.0; 3]; n], n),
        Err(PreviewError::BadGain { step: 6, .. })
    ));
}

fn eq26_snapshot(
    scenario: &Scenario,
    c: &Config,
    time: f64,
) -> (Vec<[f64; 2]>, Vec<HandState>, Vec<[f64; 3]>) {
    let n = c.preview.horizon;
    let t = c.preview.period;
    let mut f = vec![[0.0; 3]; n];
    scenario.force.sample_into(time + t, t, &mut f);
    let des = HandState {
        pos: robot().hand_position,
        ..Default::default()
    };
    (vec![scenario.zmp_reference; n], vec![des; n], f)
}

#[test]
fn gauss_newton_gradient_matches_finite_differences() {
    // Jᵀr of the projected Jacobian is the exact gradient of eq. (26) with u re-optimised.
    for damping in ["critical", "free"] {
        let c = config_with(&[
            "preview.horizon=120",
            "gain_search.knots=7",
            &format!("hand.damping=\"{damping}\""),
        ]);
        let scenario = Scenario::load("single_impact").unwrap();
        let (refs, des, f) = eq26_snapshot(&scenario, &c, 0.9);
        // Non-trivial F_z so α0 varies with the gains too.
        let f: Vec<[f64; 3]> = f.iter().map(|v| [v[0], 0.2 * v[0], 0.5 * v[0]]).collect();
        let inp = GainSearchInputs {
            com: [
                Vector3::new(0.01, 0.02, -0.1),
                Vector3::new(0.0, -0.01, 0.05),
            ],
            zmp_ref: &refs,
            hand: HandState {
                pos: des[0].pos + Vector3::new(-0.01, 0.002, 0.0),
                vel: Vector3::new(-0.05, 0.0, 0.01),
                ..Default::default()
            },
            hand_desired: &des,
            f_ext: &f,
            applied: [c.hand.kp, c.nominal_kd(c.hand.kp)],
        };
        let mut search = GainSearch::from_config(&c, &robot()).unwrap();
        let (problem, knots) = search.problem_mut();
        let theta: Vec<f64> = (0..knots.dim()).map(|j| 300.0 + 40.0 * j as f64).collect();
        let theta: Vec<f64> = theta
            .iter()
            .enumerate()
            .map(|(j, v)| {
                if j >= knots.n_knots() {
                    30.0 + j as f64
                } else {
                    *v
                }
            })
            .collect();
        let grad = problem.gradient(knots, &theta, &inp).unwrap();
        for j in 0..theta.len() {
            let h = 1e-3 * theta[j];
            let mut tp = theta.clone();
            tp[j] += h;
            let cp = problem.evaluate(knots, &tp, &inp).unwrap();
            tp[j] -= 2.0 * h;
            let cm = problem.evaluate(knots, &tp, &inp).unwrap();
            let fd = (cp - cm) / (2.0 * h);
            assert!(
                (grad[j] - fd).abs()
                    < 1e-5
                        * fd.abs()
                            .max(grad.iter().fold(0.0f64, |m, g| m.max(g.abs()))),
                "{damping} θ_{j}: analytic {} fd {fd}",
                grad[j]
            );
        }
    }
}

#[test]
fn c2_default_beats_nominal_gains_and_the_nelder_mead_baseline() {
    for name in ["single_impact", "multiple_impacts"] {
        let scenario = Scenario::load(name).unwrap();
        let c = config_with(&[]);
        let impacts = match &scenario.force {
            ForceProfile::Impacts(v) => v.clone(),
            _ => unreachable!(),
        };
        // Snapshots before, at and during each impact, the robot at rest.
        for imp in &impacts {
            for time in [imp.start - 0.5, imp.start, imp.start + imp.rise] {
                let (refs, des, f) = eq26_snapshot(&scenario, &c, time);
                let inp = GainSearchInputs {
                    com: [Vector3::zeros(), Vector3::zeros()],
                    zmp_ref: &refs,
                    hand: des[0],
                    hand_desired: &des,
                    f_ext: &f,
                    applied: [c.hand.kp, c.nominal_kd(c.hand.kp)],
                };
                let mut gn =
                    GainSearch::with_solver(&c, &robot(), GainSolverKind::GaussNewton).unwrap();
                let mut nm =
                    GainSearch::with_solver(&c, &robot(), GainSolverKind::NelderMead).unwrap();
                let r_gn = gn.search(&inp, 1).unwrap();
                let r_nm = nm.search(&inp, 1).unwrap();
                assert!(
                    r_gn.cost <= r_gn.nominal_cost,
                    "{name} t={time}: GN {} > nominal {}",
                    r_gn.cost,
                    r_gn.nominal_cost
                );
                assert!(
                    r_gn.cost <= r_nm.cost * (1.0 + 1e-9),
                    "{name} t={time}: GN {} > NM {} (nominal {})",
                    r_gn.cost,
                    r_nm.cost,
                    r_gn.nominal_cost
                );
            }
        }
    }
}

#[test]
fn c2_closed_loop_never_costs_more_than_c1_per_solve() {
    let c = config_with(&["preview.horizon=200"]);
    let mut scenario = Scenario::load("single_impact").unwrap();
    scenario.duration = 2.5;
    let run = ReducedLoop::new(&c, robot(), &scenario, ControllerKind::C2)
        .run()
        .unwrap();
    assert!(!run.gain_search.is_empty());
    for r in &run.gain_search {
        assert!(r.cost <= r.nominal_cost * (1.0 + 1e-12));
    }
    // Some solves improve on the nominal gains by a real margin while the impact is previewed.
    assert!(
        run.gain_search
            .iter()
            .any(|r| r.cost < 0.95 * r.nominal_cost)
    );
}

#[test]
fn zmp_constraints_keep_the_predicted_zmp_inside_where_c1_cannot() {
    // With support bounds tightened to ±1 cm in x (a robot with short feet) and a heavier jerk
    // weight, unconstrained C1 (which only weighs ZMP error against jerk) lets the ZMP out
    // during the impact; the constrained QP keeps it inside.
    let mut narrow = robot();
    narrow.support[0] = [-0.01, 0.01];
    let tight = ["preview.horizon=150", "preview.r=1e-3"];
    let c = config_with(&tight);
    let mut cq = config_with(&tight);
    cq.preview.zmp_constraints = true;
    let mut scenario = Scenario::load("single_impact").unwrap();
    scenario.duration = 2.6;
    let free = ReducedLoop::new(&c, narrow, &scenario, ControllerKind::C1)
        .run()
        .unwrap();
    let bound = ReducedLoop::new(&cq, narrow, &scenario, ControllerKind::C1)
        .run()
        .unwrap();
    assert!(
        free.metrics.time_outside_support > 0.0,
        "{:?}",
        free.metrics
    );
    assert!(
        free.metrics.max_support_excursion > 5e-3,
        "{:?}",
        free.metrics
    );
    assert_eq!(
        bound.metrics.time_outside_support, 0.0,
        "{:?}",
        bound.metrics
    );
}

#[test]
fn config_errors_name_the_key_and_the_file() {
    let mut l = upc::config::Config::default_layers().unwrap();
    l.push_str("my.toml", "[preview]\nhorizonn = 3\n").unwrap();
    let e = l.build().unwrap_err().to_string();
    assert!(
        e.contains("preview.horizonn") && e.contains("my.toml"),
        "{e}"
    );
    let mut l = upc::config::Config::default_layers().unwrap();
    l.push_str("my.toml", "[preview]\nhorizon = \"long\"\n")
        .unwrap();
    let e = l.build().unwrap_err().to_string();
    assert!(
        e.contains("preview.horizon") && e.contains("my.toml"),
        "{e}"
    );
    let mut l = upc::config::Config::default_layers().unwrap();
    l.push_override("robot.gravity=-3").unwrap();
    let e = l.build().unwrap_err().to_string();
    assert!(
        e.contains("robot.gravity") && e.contains("--set") && e.contains("> 0"),
        "{e}"
    );
    // The robot's own facts are no settings: a key for one is refused by name.
    let mut l = upc::config::Config::default_layers().unwrap();
    l.push_override("robot.mass=31").unwrap();
    let e = l.build().unwrap_err().to_string();
    assert!(e.contains("mass"), "{e}");
    let e = Scenario::load("does/not/exist.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("does/not/exist.toml"), "{e}");
}

#[test]
fn csv_force_profiles_load_and_interpolate() {
    let s = Scenario::load("config/scenarios/csv_profile.toml").unwrap();
    let f = s.force.at(0.75);
    assert!((f[0] - (-50.0)).abs() < 1e-12, "{f:?}");
    assert_eq!(s.force.at(5.0), [0.0; 3]);
    assert!(
        ForceProfile::parse_csv("t,fx,fy,fz\n0,1,2,3\n0,1,2,3\n")
            .unwrap_err()
            .contains("does not increase")
    );
    assert!(ForceProfile::parse_csv("0,1,2\n1,1,2\n").is_err());
}

/// A workspace sized for 10 steps, factored for 10 and then for 7, reports the 7-step horizon
/// and answers it exactly as a fresh 7-step workspace does: nothing of the longer horizon
/// leaks into the shorter one.
#[test]
fn riccati_workspace_reports_its_horizon() {
    let c = config_with(&[]);
    let m = model(&c);
    let t: Vec<f64> = (0..10).map(|i| 0.01 * i as f64).collect();
    let x0 = nalgebra::Vector3::new(0.01, 0.02, -0.1);
    let mut r = Riccati::with_capacity(10);
    r.factor(&m, 1.0, 1e-6, &[-0.04; 10]);
    let long = r.first_input(&x0, &t);
    r.factor(&m, 1.0, 1e-6, &[-0.05; 7]);
    assert_eq!((r.len(), r.capacity()), (7, 10));
    let mut fresh = Riccati::with_capacity(7);
    fresh.factor(&m, 1.0, 1e-6, &[-0.05; 7]);
    assert_eq!(r.first_input(&x0, &t), fresh.first_input(&x0, &t));
    assert_ne!(
        long,
        r.first_input(&x0, &t),
        "the horizon changed the answer"
    );
}

#[test]
fn next_zmp_is_the_first_sample_of_the_plan() {
    let c = config_with(&[]);
    let n = 200;
    let (state, refs) = busy_problem(n);
    let forces = busy_forces(n);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let u = p.solve_c1(&state, &refs, &forces).unwrap();
    let next = p.next_zmp(&state, u);
    let mut plan = PreviewPlan::with_capacity(n);
    p.plan(&state, &mut plan);
    for a in 0..2 {
        assert!(
            (next[a] - plan.zmp[a][0]).abs() < 1e-12,
            "axis {a}: {} vs {}",
            next[a],
            plan.zmp[a][0]
        );
    }
}

#[test]
fn a_plan_before_any_solve_is_none_not_a_panic() {
    // A controller whose first states were bad logs a plan before its first solve.
    let c = config_with(&[]);
    let n = 200;
    let (state, refs) = busy_problem(n);
    let mut p = preview(&c, n, LqSolverKind::Riccati);
    let mut plan = PreviewPlan::with_capacity(n);
    assert!(!p.plan(&state, &mut plan), "a plan without gains");
    p.solve_c0(&state, &refs).unwrap();
    assert!(p.plan(&state, &mut plan));
    assert!(plan.zmp[0].iter().all(|z| z.is_finite()));
}

/// K_0 of C0's receding horizon (u = K_0 x at a zero reference), from the solver.
fn first_gain(p: &mut ZmpPreview) -> Vector3<f64> {
    let zero = vec![[0.0; 2]; p.horizon()];
    let mut k = Vector3::zeros();
    for j in 0..3 {
        let mut e = Vector3::zeros();
        e[j] = 1.0;
        k[j] = p.solve_c0(&[e, e], &zero).unwrap()[0];
    }
    k
}

/// The spectral radius of the receding-horizon closed loop A + B K_0.
fn closed_loop_radius(m: &CartTable, k: &Vector3<f64>) -> f64 {
    (m.a() + m.b() * k.transpose())
        .complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max)
}

/// PC-T is the infinite horizon: with the tail the backward recursion starts at its fixed
/// point, so the first gain does not depend on the horizon (N = 40 and N = 300 agree) and is
/// the infinite-horizon LQR gain from the algebraic Riccati equation solved in the state's
/// coordinates (the solver's recursion runs in another basis).
#[test]
fn the_tail_makes_the_horizon_infinite() {
    let c = config_with(&[]);
    let m = model(&c);
    let (q_e, r) = (c.preview.q_e, c.preview.r);
    let gain = |n: usize| {
        first_gain(
            &mut ZmpPreview::new(m, q_e, r, n, LqSolverKind::Riccati).with_terminal_cost(true),
        )
    };
    let (short, long) = (gain(40), gain(300));
    for j in 0..3 {
        assert!(
            rel(short[j], long[j]) < 1e-8,
            "K_0 N = 40 {short} against N = 300 {long}"
        );
    }
    // Without the tail a 40-step (0.2 s) horizon is another controller.
    let finite = first_gain(&mut ZmpPreview::new(m, q_e, r, 40, LqSolverKind::Riccati));
    assert!(rel(finite[0], long[0]) > 0.1, "{finite} {long}");
    // And it is the infinite horizon's LQR gain K∞ = −(R + Bᵀ P∞ B)⁻¹ Bᵀ P∞ A, P∞ of the
    // algebraic Riccati equation in the state's coordinates (the solver carried it into its own).
    let cbar = Vector3::new(1.0, 0.0, m.output_acc_coeff(m.nominal_alpha0()));
    let p_inf = m.infinite_tail(q_e, r) + cbar * cbar.transpose() * q_e;
    let (a, b) = (m.a(), m.b());
    let k_inf = -(b.transpose() * p_inf * a) / (r + b.dot(&(p_inf * b)));
    for j in 0..3 {
        assert!(
            rel(long[j], k_inf[j]) < 1e-8,
            "K_0 {long} against K∞ {k_inf}"
        );
    }
}

/// Why a tall robot fell with the paper's 1.5 s horizon (TALOS, CoM 0.88 m; docs/
/// preview_control.md, PC-T): the finite horizon's receding-horizon loop is unstable there
/// (spectral radius above 1: the first gain pushes the CoM away from the reference), and a
/// 2 cm offset grows, and the start-up check refuses it naming both fixes; with the tail the
/// loop is stable and the offset decays, for any height.
#[test]
fn a_tall_robot_diverges_on_the_finite_horizon_and_stands_on_its_tail() {
    let c = config_with(&[]);
    for z in [0.5, 0.88, 1.2] {
        let m = CartTable {
            period: c.preview.period,
            com_height: z,
            mass: 90.0,
            gravity: c.robot.gravity,
        };
        let n = c.preview.horizon;
        let run = |tail: bool| {
            let mut p = ZmpPreview::new(m, c.preview.q_e, c.preview.r, n, LqSolverKind::Riccati)
                .with_terminal_cost(tail);
            let rho = closed_loop_radius(&m, &first_gain(&mut p));
            let zero = vec![[0.0; 2]; n];
            let mut x = [Vector3::new(0.02, 0.0, 0.0), Vector3::zeros()];
            for _ in 0..(10.0 / c.preview.period) as usize {
                let u = p.solve_c0(&x, &zero).unwrap();
                x[0] = m.step(&x[0], u[0]);
            }
            (rho, x[0][0].abs())
        };
        let (rho, offset) = run(true);
        assert!(
            rho < 0.99 && offset < 1e-6,
            "z {z}, tail: radius {rho}, offset {offset}"
        );
        let (rho, offset) = run(false);
        let mut finite = ZmpPreview::new(m, c.preview.q_e, c.preview.r, n, LqSolverKind::Riccati);
        if z > 0.8 {
            assert!(
                rho > 1.0 && offset > 0.02,
                "z {z}, no tail: radius {rho}, offset {offset}"
            );
            // Refused at start-up, with the two fixes; the longer horizon named holds it.
            let e = finite.check_holds_the_com().unwrap_err();
            let PreviewError::UnstableHorizon {
                stable_from: Some(longer),
                ..
            } = e
            else {
                panic!("{e}");
            };
            let text = e.to_string();
            assert!(
                text.contains("preview.terminal_cost = true")
                    && text.contains(&format!("preview.horizon ≥ {longer}")),
                "{text}"
            );
            let mut enough =
                ZmpPreview::new(m, c.preview.q_e, c.preview.r, longer, LqSolverKind::Riccati);
            assert!(enough.closed_loop_radius() < 1.0, "{text}");
        } else {
            assert!(
                rho < 1.0 && offset < 1e-6,
                "z {z}, no tail: radius {rho}, offset {offset}"
            );
            assert_eq!(finite.check_holds_the_com(), Ok(()));
        }
        let mut with_tail =
            ZmpPreview::new(m, c.preview.q_e, c.preview.r, n, LqSolverKind::Riccati)
                .with_terminal_cost(true);
        assert_eq!(with_tail.check_holds_the_com(), Ok(()));
    }
}
