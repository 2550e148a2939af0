//! Dynamics benchmarks: RNEA, CRBA, ABA, all joint/frame Jacobians and M_e on the project's
//! humanoid (38 DoF) and on the URDF named by `UPC_BENCH_URDF` if set
//! (`UPC_BENCH_OPSPACE=root,frame` adds M_e for that URDF).
//!
//! Run: `cargo bench --bench dynamics`. Pinocchio reference on this machine class for a 38-DoF
//! humanoid: RNEA ≈ 10 µs, CRBA ≈ 7 µs, ABA ≈ 22 µs.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DVector;
use upc::dynamics::{
    BaseJoint, Data, Model, OpSpaceWorkspace, ReferenceFrame, aba, compute_joint_jacobians, crba,
    get_frame_jacobian, icub_like, jacobian_center_of_mass, rnea,
};

/// Deterministic, non-trivial state (no randomness crate needed).
fn state(model: &Model) -> (DVector<f64>, DVector<f64>, DVector<f64>) {
    let mut q = model.neutral();
    let offset = if model.has_floating_base() { 7 } else { 0 };
    for k in offset..model.nq {
        q[k] = 0.3 * ((k as f64) * 1.7).sin();
    }
    let v = DVector::from_fn(model.nv, |k, _| ((k as f64) * 0.9).cos());
    let a = DVector::from_fn(model.nv, |k, _| ((k as f64) * 1.3).sin());
    (q, v, a)
}

fn bench_model(
    c: &mut Criterion,
    label: &str,
    model: &Model,
    q: DVector<f64>,
    op: Option<(&str, &str)>,
) {
    let (_, v, a) = state(model);
    let mut data = Data::new(model);
    let tau = match rnea(model, &mut data, &q, &v, &a) {
        Ok(t) => t.clone(),
        Err(e) => {
            eprintln!("{label}: {e}");
            return;
        }
    };
    let mut g = c.benchmark_group(label);
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(50);
    g.bench_function("rnea", |b| {
        b.iter(|| {
            let _ = black_box(rnea(model, &mut data, &q, &v, &a));
        })
    });
    g.bench_function("crba", |b| {
        b.iter(|| {
            let _ = black_box(crba(model, &mut data, &q));
        })
    });
    match aba(model, &mut data, &q, &v, &tau) {
        Ok(_) => {
            g.bench_function("aba", |b| {
                b.iter(|| {
                    let _ = black_box(aba(model, &mut data, &q, &v, &tau));
                })
            });
        }
        Err(e) => eprintln!("{label}: ABA skipped: {e}"),
    }
    g.bench_function("joint_jacobians", |b| {
        b.iter(|| {
            let _ = black_box(compute_joint_jacobians(model, &mut data, &q));
        })
    });
    // All frame Jacobians (every link frame, LOCAL_WORLD_ALIGNED) from one joint-Jacobian pass.
    let mut out = nalgebra::DMatrix::zeros(6, model.nv);
    g.bench_function("all_frame_jacobians", |b| {
        b.iter(|| {
            let _ = compute_joint_jacobians(model, &mut data, &q);
            for f in 0..model.frames.len() {
                let _ = get_frame_jacobian(
                    model,
                    &data,
                    f,
                    ReferenceFrame::LocalWorldAligned,
                    &mut out,
                );
            }
            black_box(&out);
        })
    });
    g.bench_function("com_jacobian", |b| {
        b.iter(|| {
            let _ = black_box(jacobian_center_of_mass(model, &mut data, &q));
        })
    });
    if let Some((root, frame)) = op {
        match OpSpaceWorkspace::new(model, root, frame) {
            Ok(mut ws) => {
                g.bench_function("m_e", |b| {
                    b.iter(|| {
                        let _ = black_box(ws.compute(model, &mut data, &q));
                    })
                });
            }
            Err(e) => eprintln!("{label}: M_e skipped: {e}"),
        }
    }
    g.finish();
}

fn benches(c: &mut Criterion) {
    match icub_like::load() {
        Ok(model) => {
            let home = upc::robot::Robot::embedded_default().expect("robot").home;
            bench_model(c, "icub_like_home", &model, home, Some(("chest", "r_hand")));
            let (q, _, _) = state(&model);
            bench_model(c, "icub_like_random", &model, q, Some(("chest", "r_hand")));
        }
        Err(e) => eprintln!("humanoid: {e}"),
    }
    if let Ok(path) = std::env::var("UPC_BENCH_URDF") {
        match Model::from_urdf_file(&path, BaseJoint::Auto) {
            Ok(model) => {
                let spec = std::env::var("UPC_BENCH_OPSPACE").ok();
                let op = spec.as_deref().and_then(|s| s.split_once(','));
                let (q, _, _) = state(&model);
                bench_model(c, "env_urdf", &model, q, op);
            }
            Err(e) => eprintln!("UPC_BENCH_URDF={path}: {e}"),
        }
    }
}

criterion_group!(dynamics, benches);
criterion_main!(dynamics);
