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

/// The simulator's recording on the stepping loop: a frame offered every step allocates and
/// frees nothing once the pool's frames have their sizes (a frame freed by the logger thread,
/// idle class, once held the allocator's lock from the real-time loop for 0.66 s).
#[test]
fn offering_a_frame_to_the_recording_does_not_allocate() {
    let config = upc::sim::SimConfig::embedded().unwrap();
    let scene = upc::sim::humanoid_scene(&config, None).unwrap();
    let mut world = scene.world;
    let robot = upc::robot::Robot::embedded_default().unwrap();
    let dir = std::env::temp_dir().join(format!("upc_alloc_rec_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut rec =
        upc::sim::record::Recorder::spawn(&dir.join("sim.rrd"), None, None, &world, &robot, false)
            .unwrap();
    let hand = [1.0, -2.0, 3.0];
    // The first round of the pool sizes its frames (once each, at most).
    for _ in 0..64 {
        rec.offer(&mut world, &hand);
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let n_alloc = allocations(|| {
        for _ in 0..200 {
            rec.offer(&mut world, &hand);
        }
    });
    let stats = rec.finish();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(n_alloc, 0, "{n_alloc} allocations offering 200 frames");
    assert!(stats.written > 0, "{stats:?}");
}
