//! The controller's tick allocates nothing of its own: the preview, hand previewer, kinematics
//! and M_e allocate nothing; the one allocation per tick is clarabel's solve.

mod support;

use support::counting_alloc::allocations;
use upc::channels::{ForecastMsg, StateMsg};
use upc::config::{Config, ControllerKind};
use upc::control::{ControllerCore, ForecastWindow};
use upc::dynamics::icub_like;

#[test]
fn controller_tick_allocations() {
    let config = Config::embedded_default().expect("defaults");
    let model = icub_like::load().expect("model");
    let q = icub_like::home_configuration(&model).expect("home");
    let mut state = StateMsg {
        nq: model.nq as u32,
        nv: model.nv as u32,
        ..Default::default()
    };
    state.q[..model.nq].copy_from_slice(q.as_slice());
    let n = model.nv - 6;
    let mut core = ControllerCore::new(
        model,
        &config,
        ControllerKind::C1,
        0.001,
        [100.0, 20.0],
        [0.0, 0.0],
    )
    .expect("core");
    let mut window = ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
    let mut f: Box<ForecastMsg> = Box::default();
    f.seq = 1;
    f.dt = 0.005;
    f.len = 500;
    for (i, s) in f.forces.iter_mut().enumerate().take(500) {
        *s = [-(i as f64 * 0.01).sin().abs() * 40.0, 0.0, 0.0];
    }
    window.offer(&f, 0.0).expect("forecast");
    let mut tau = vec![0.0; n];
    for k in 0..5 {
        state.time = k as f64 * 0.001;
        core.tick(&state, &window, None, &mut tau)
            .expect("warm-up tick");
    }
    let count = allocations(|| {
        for k in 5..25 {
            state.time = k as f64 * 0.001;
            let _ = core.tick(&state, &window, None, &mut tau);
        }
    });
    eprintln!(
        "controller tick: {} allocations per tick",
        count as f64 / 20.0
    );
    // Everything but clarabel's interior-point solve is allocation-free; clarabel 0.11 makes
    // one allocation per solve (measured by tests/wbc_alloc.rs). Nothing else may add to it.
    assert!(count <= 20, "{count} allocations in 20 ticks");
}
