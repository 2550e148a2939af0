//! Allocations of a whole-body QP tick after the first (which builds the clarabel solver): the
//! controller's own assembly is allocation-free; whatever remains is clarabel's solve.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{DVector, Vector3};
use upc::config::Config;
use upc::dynamics::{Data, forward_kinematics, icub_like};
use upc::wbc::{WbcCommand, WbcStatus, WholeBodyController};

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
fn wbc_tick_allocations_after_the_first() {
    let cfg = Config::embedded_default().unwrap().wbc;
    let model = icub_like::load().unwrap();
    let q = icub_like::home_configuration(&model).unwrap();
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &q).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let mut wbc = WholeBodyController::new(&model, &cfg).unwrap();
    let v = DVector::zeros(model.nv);
    let mut cmd = WbcCommand {
        hand_pos_des: hand,
        kp: 100.0,
        kd: 20.0,
        ..WbcCommand::default()
    };
    for _ in 0..3 {
        assert_eq!(
            wbc.solve(&model, &mut data, &q, &v, &cmd).status,
            WbcStatus::Solved
        );
    }
    let ticks = 100;
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    for k in 0..ticks {
        cmd.com_acc = Vector3::new(0.001 * k as f64, 0.0, 0.0);
        let out = wbc.solve(&model, &mut data, &q, &v, &cmd);
        assert_eq!(out.status, WbcStatus::Solved);
    }
    let per_tick = (ALLOCATIONS.load(Ordering::SeqCst) - before) as f64 / ticks as f64;
    eprintln!("whole-body tick: {per_tick} allocations per tick (clarabel's solve)");
    // Bounded and small (measured: 1 per tick, inside clarabel's solve).
    assert!(per_tick <= 2.0, "{per_tick} allocations per tick");
}
