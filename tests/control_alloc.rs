//! The controller's tick allocates nothing of its own: the preview, hand previewer, kinematics
//! and M_e allocate nothing; the one allocation per tick is clarabel's solve.

mod support;

use support::counting_alloc::allocations;
use support::humanoid::{push_forecast, rig};
use upc::config::{Config, ControllerKind};

#[test]
fn controller_tick_allocations() {
    let config = Config::embedded_default().expect("defaults");
    let mut r = rig(&config, ControllerKind::C1);
    r.window
        .offer(&push_forecast(0.0, -40.0), 0.0)
        .expect("forecast");
    for k in 0..5 {
        r.state.time = k as f64 * 0.001;
        r.core
            .tick(&r.state, &r.window, None, &mut r.tau)
            .expect("warm-up tick");
    }
    let count = allocations(|| {
        for k in 5..25 {
            r.state.time = k as f64 * 0.001;
            let _ = r.core.tick(&r.state, &r.window, None, &mut r.tau);
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
