//! The controller's tick allocates nothing of its own: the preview, hand previewer, kinematics
//! and M_e allocate nothing; the one allocation per tick is clarabel's solve.

mod support;

use support::counting_alloc::allocations;
use support::humanoid::rig;
use upc::config::{Config, ControllerKind};

#[test]
fn controller_tick_allocations() {
    let config = Config::embedded_default().expect("defaults");
    let mut r = rig(&config, ControllerKind::C1);
    r.offer_push(-40.0);
    assert_eq!(r.tick_frozen(0..5), 0, "a warm-up tick failed");
    let count = allocations(|| {
        r.tick_frozen(5..25);
    });
    eprintln!(
        "controller tick: {} allocations per tick, {:?}",
        count as f64 / 20.0,
        r.core.wbc_counters()
    );
    // Everything but clarabel's interior-point solve is allocation-free; clarabel 0.11 makes
    // one allocation per solve (measured by tests/wbc_alloc.rs). Nothing else may add to it.
    assert!(count <= 20, "{count} allocations in 20 ticks");
}

/// From the very first tick (no warm-up), with `formulation = "full"` and torque limits low
/// enough to bind: no tick builds a clarabel solver (they are built with the core) or latches a
/// reference by allocating. At most clarabel's one allocation per solve remains (two solves a
/// tick here: the screening solve without torque rows, then the full problem).
#[test]
fn controller_first_ticks_torque_limited_full_formulation() {
    let mut config = Config::embedded_default().expect("defaults");
    config.wbc.formulation = upc::config::WbcFormulation::Full;
    config.wbc.torque_limit_scale = 0.1;
    let mut r = rig(&config, ControllerKind::C1);
    r.offer_push(-40.0);
    let built = r.core.wbc_counters().solver_builds;
    let ticks = 20;
    let count = allocations(|| {
        r.tick_frozen(0..ticks);
    });
    let c = r.core.wbc_counters();
    eprintln!("first {ticks} ticks: {count} allocations, {c:?}");
    assert!(c.torque_limited > 0, "no torque-limited tick: {c:?}");
    assert_eq!(c.solver_builds, built, "a tick built a solver");
    assert!(count <= 3 * ticks, "{count} allocations in {ticks} ticks");
}

/// The same with the base estimated (docs/estimation.md): the estimator's kinematics, Kalman
/// filter and centre of pressure add no allocation.
#[test]
fn controller_tick_with_the_base_estimator_allocations() {
    let config = Config::embedded_default().expect("defaults");
    let mut r = rig(&config, ControllerKind::C1);
    let robot = upc::robot::Robot::embedded_default().expect("robot");
    r.without_base(robot.derived.mass * 9.81);
    r.offer_push(-40.0);
    assert_eq!(r.tick_frozen(0..5), 0, "a warm-up tick failed");
    let count = allocations(|| {
        assert_eq!(r.tick_frozen(5..25), 0);
    });
    let mut summary = serde_json::Map::new();
    r.core.summarize(&mut summary);
    let e = summary.get("base_estimation").expect("the estimator ran");
    eprintln!("with the estimator: {count} allocations in 20 ticks, {e}");
    assert_eq!(e["ticks"].as_u64(), Some(25));
    assert!(count <= 20, "{count} allocations in 20 ticks");
}

/// The same on a robot without force sensors (docs/estimation.md, WO): the base estimated and
/// the feet's wrenches, the CoP and the hand force estimated from the joint torques every tick
/// add no allocation.
#[test]
fn controller_tick_with_the_wrench_observer_allocations() {
    let config = Config::embedded_default().expect("defaults");
    let mut r = rig(&config, ControllerKind::C1);
    let robot = upc::robot::Robot::embedded_default().expect("robot");
    r.without_base(robot.derived.mass * 9.81);
    // What a G1 publishes: no foot wrench, CoP or hand force; the drives' torques.
    r.state.foot_wrenches = [[f64::NAN; 6]; 2];
    r.state.zmp = [f64::NAN; 2];
    r.state.hand_force = [f64::NAN; 3];
    r.state.joint_torques[6..robot.model.nv].fill(1.0);
    r.offer_push(-40.0);
    assert_eq!(r.tick_frozen(0..5), 0, "a warm-up tick failed");
    let count = allocations(|| {
        assert_eq!(r.tick_frozen(5..25), 0);
    });
    let mut summary = serde_json::Map::new();
    r.core.summarize(&mut summary);
    let wo = &summary["wrench_observer"];
    eprintln!("with the wrench observer: {count} allocations in 20 ticks, {wo}");
    let n = |k: &str| wo[k].as_u64();
    assert_eq!(
        (n("updates"), n("hand_ticks"), n("feet_ticks")),
        (Some(25), Some(25), Some(25))
    );
    assert!(count <= 20, "{count} allocations in 20 ticks");
}
