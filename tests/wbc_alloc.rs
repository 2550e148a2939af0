//! Allocations of a whole-body QP tick: the solvers are built at construction, the controller's
//! own assembly is allocation-free; whatever remains is clarabel's solve.

mod support;

use nalgebra::{DVector, Vector3};
use support::counting_alloc::{allocations, allocations_so_far};
use upc::config::{Config, WbcFormulation};
use upc::dynamics::{Data, forward_kinematics, icub_like};
use upc::wbc::{WbcCommand, WbcStatus, WholeBodyController};

/// The iCub-like's contact, sole and hand frames (its description names them).
fn frames() -> upc::robot::BodyFrames {
    upc::robot::Robot::embedded_default()
        .expect("robot")
        .frames()
}

#[test]
fn wbc_tick_allocations_after_the_first() {
    let cfg = Config::embedded_default().unwrap().wbc;
    let model = icub_like::load().unwrap();
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &q).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let mut wbc = WholeBodyController::new(&model, &cfg, &frames()).unwrap();
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
    let mut solved = 0;
    let count = allocations(|| {
        for k in 0..ticks {
            cmd.com_acc = Vector3::new(0.001 * k as f64, 0.0, 0.0);
            let out = wbc.solve(&model, &mut data, &q, &v, &cmd);
            solved += usize::from(out.status == WbcStatus::Solved);
        }
    });
    assert_eq!(solved, ticks);
    let per_tick = count as f64 / ticks as f64;
    eprintln!("whole-body tick: {per_tick} allocations per tick (clarabel's solve)");
    // Bounded and small (measured: 1 per tick, inside clarabel's solve).
    assert!(per_tick <= 2.0, "{per_tick} allocations per tick");
}

/// Every clarabel solver is built at construction: from the very first tick, neither the
/// torque-limited path (the full problem with its torque rows, after the screening solve) nor
/// `formulation = "full"` builds one (a build allocates hundreds of times). What remains is
/// clarabel's one allocation per solve, at most three solves a tick.
#[test]
fn no_tick_builds_a_solver_torque_limited_or_full() {
    let model = icub_like::load().unwrap();
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &q).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let v = DVector::zeros(model.nv);
    for formulation in [WbcFormulation::Condensed, WbcFormulation::Full] {
        let mut cfg = Config::embedded_default().unwrap().wbc;
        cfg.formulation = formulation;
        let mut wbc = WholeBodyController::new(&model, &cfg, &frames()).unwrap();
        let built = wbc.counters().solver_builds;
        let mut cmd = WbcCommand {
            hand_pos_des: hand,
            kp: 100.0,
            kd: 20.0,
            ..WbcCommand::default()
        };
        let ticks = 40;
        let mut solved = 0;
        let mut worst = 0;
        let count = allocations(|| {
            for k in 0..ticks {
                // Bursts of a CoM request beyond the torque limits, then a normal one.
                cmd.com_acc = if k % 10 < 5 {
                    Vector3::new(50.0, 0.0, 0.0)
                } else {
                    Vector3::new(0.01, 0.0, 0.0)
                };
                let before = allocations_so_far();
                let out = wbc.solve(&model, &mut data, &q, &v, &cmd);
                solved += usize::from(out.status == WbcStatus::Solved);
                worst = worst.max(allocations_so_far() - before);
            }
        });
        let c = wbc.counters();
        eprintln!(
            "{formulation:?}: {count} allocations in {ticks} ticks (worst tick {worst}), {c:?}"
        );
        assert_eq!(solved, ticks, "{formulation:?}");
        assert!(
            c.torque_limited > 0,
            "{formulation:?}: no torque-limited tick"
        );
        assert_eq!(
            c.solver_builds, built,
            "{formulation:?}: a tick built a solver"
        );
        assert!(
            worst <= 3,
            "{formulation:?}: a tick allocated {worst} times"
        );
    }
}
