//! The per-tick path allocates nothing: a counting global allocator watches C0, the hand
//! previewer, C1 and the plan rollout after construction.

mod support;

use nalgebra::Vector3;
use support::counting_alloc::allocations;
use upc::config::{Config, LqSolverKind};
use upc::preview::{GainSchedule, HandPreviewer, HandState, PreviewPlan, ZmpPreview};

#[test]
fn per_tick_preview_path_does_not_allocate() {
    let c = Config::embedded_default().unwrap();
    let n = c.preview.horizon;
    let robot = upc::robot::Robot::embedded_default().unwrap().reduced();
    let model = robot.cart_table(c.preview.period, c.robot.gravity);
    let mut zmp = ZmpPreview::new(model, c.preview.q_e, c.preview.r, n, LqSolverKind::Riccati);
    let m_e = robot.effective_mass;
    let mut hand = HandPreviewer::new(c.preview.period, m_e, n).unwrap();
    let gains = GainSchedule::constant(n, c.hand.kp, c.nominal_kd(c.hand.kp));
    let des = HandState {
        pos: Vector3::new(0.3, -0.15, 0.75),
        ..Default::default()
    };
    let desired = vec![des; n];
    let refs = vec![[0.01, -0.02]; n];
    let forces: Vec<[f64; 3]> = (0..n)
        .map(|i| [-40.0 * (i as f64 * 0.02).sin().max(0.0), 3.0, 0.0])
        .collect();
    let mut plan = PreviewPlan::with_capacity(n);
    let mut state = [Vector3::new(0.0, 0.01, 0.0), Vector3::zeros()];

    let mut checksum = 0.0;
    let n_alloc = allocations(|| {
        for k in 0..50 {
            let u0 = zmp.solve_c0(&state, &refs).unwrap();
            hand.predict(&des, &desired, &gains, &forces, n).unwrap();
            let u1 = zmp.solve_c1(&state, &refs, hand.disturbance()).unwrap();
            zmp.plan(&state, &mut plan);
            // Error paths too: a bad forecast is an error value without allocating.
            let mut bad = forces[0];
            bad[0] = f64::NAN;
            let _ = zmp.solve_c1(&state, &refs, &[bad; 1]);
            state[0][0] += 1e-4 * k as f64;
            checksum += u0[0] + u1[1] + plan.zmp[0][n - 1];
        }
    });
    assert!(checksum.is_finite());
    assert_eq!(n_alloc, 0, "the tick path allocated {n_alloc} times");
}
