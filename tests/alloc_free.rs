//! The per-tick path allocates nothing: a counting global allocator watches C0, the hand
//! previewer, C1 and the plan rollout after construction.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Matrix3, Vector3};
use upc::config::{Config, LqSolverKind};
use upc::preview::{CartTable, GainSchedule, HandPreviewer, HandState, PreviewPlan, ZmpPreview};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn per_tick_preview_path_does_not_allocate() {
    let c = Config::embedded_default().unwrap();
    let n = c.preview.horizon;
    let model = CartTable {
        period: c.preview.period,
        com_height: c.robot.com_height,
        mass: c.robot.mass,
        gravity: c.robot.gravity,
    };
    let mut zmp = ZmpPreview::new(model, c.preview.q_e, c.preview.r, n, LqSolverKind::Riccati);
    let m_e = Matrix3::from_fn(|i, j| c.hand.effective_mass[i][j]);
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

    // The counter sees allocations (so a zero below means something).
    let probe = ALLOCATIONS.load(Ordering::SeqCst);
    let v = std::hint::black_box(vec![0u8; 64]);
    assert!(ALLOCATIONS.load(Ordering::SeqCst) > probe && v.len() == 64);

    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut checksum = 0.0;
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
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(checksum.is_finite());
    assert_eq!(
        after - before,
        0,
        "the tick path allocated {} times",
        after - before
    );
}
