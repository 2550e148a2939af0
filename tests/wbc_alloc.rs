//! Allocations of a whole-body QP tick after the first (which builds the clarabel solver): the
//! controller's own assembly is allocation-free; whatever remains is clarabel's solve.

mod support;

use nalgebra::{DVector, Vector3};
use support::counting_alloc::allocations;
use upc::config::Config;
use upc::dynamics::{Data, forward_kinematics, icub_like};
use upc::wbc::{WbcCommand, WbcStatus, WholeBodyController};

#[test]
fn wbc_tick_allocations_after_the_first() {
    let cfg = Config::embedded_default().unwrap().wbc;
    let model = icub_like::load().unwrap();
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
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
