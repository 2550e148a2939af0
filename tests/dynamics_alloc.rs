//! The per-tick algorithms must not allocate: count allocations with a wrapping global
//! allocator around warm calls.

mod support;

use nalgebra::{DMatrix, DVector};
use upc::dynamics::*;

use support::counting_alloc::allocations;

#[test]
fn hot_path_does_not_allocate() {
    let model = icub_like::load().expect("humanoid");
    let mut data = Data::new(&model);
    let q = upc::robot::Robot::embedded_default().expect("robot").home;
    let v = DVector::from_fn(model.nv, |k, _| (k as f64 * 0.7).sin());
    let a = DVector::from_fn(model.nv, |k, _| (k as f64 * 0.3).cos());
    let tau = DVector::from_element(model.nv, 0.1);
    let hand = model.frame_id("r_hand").expect("frame");
    let mut ws = OpSpaceWorkspace::new(&model, "chest", "r_hand").expect("chain");
    let mut jout = DMatrix::zeros(6, model.nv);
    let mut qn = DVector::zeros(model.nq);
    // The sanity check that counting works at all (must fail if the counter were dead).
    assert!(allocations(|| drop(std::hint::black_box(vec![1u8; 16]))) > 0);
    let n = allocations(|| {
        rnea(&model, &mut data, &q, &v, &a).expect("rnea");
        nonlinear_effects(&model, &mut data, &q, &v).expect("h");
        gravity_torques(&model, &mut data, &q).expect("g");
        crba(&model, &mut data, &q).expect("crba");
        aba(&model, &mut data, &q, &v, &tau).expect("aba");
        compute_joint_jacobians(&model, &mut data, &q).expect("J");
        get_frame_jacobian(
            &model,
            &data,
            hand,
            ReferenceFrame::LocalWorldAligned,
            &mut jout,
        )
        .expect("frame J");
        frame_jacobian(&model, &mut data, &q, hand, ReferenceFrame::Local).expect("frame J");
        frame_jdot_v(
            &model,
            &mut data,
            &q,
            &v,
            hand,
            ReferenceFrame::LocalWorldAligned,
        )
        .expect("drift");
        forward_kinematics_velocity(&model, &mut data, &q, &v).expect("fk");
        center_of_mass_velocity(&model, &mut data, &q, &v).expect("com");
        jacobian_center_of_mass(&model, &mut data, &q).expect("Jcom");
        ws.compute(&model, &mut data, &q).expect("M_e");
        integrate(&model, &q, &v, 1e-3, &mut qn).expect("integrate");
    });
    assert_eq!(n, 0, "hot-path allocations");
}
