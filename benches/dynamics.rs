//! Dynamics benchmarks: RNEA, CRBA, ABA, all joint/frame Jacobians and M_e on the project's
//! humanoid (38 DoF) and on the URDF named by `UPC_BENCH_URDF` if set
//! (`UPC_BENCH_OPSPACE=root,frame` adds M_e for that URDF).
//!
//! Run: `cargo bench --bench dynamics`. The `*_random` and `env_urdf` groups cycle through 64
//! random states drawn as scripts/bench_pinocchio.cpp draws Pinocchio's, which that script
//! compares against (`~/.cache/upc/robot-venv/bin/python scripts/bench_pinocchio.py`).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DVector, Vector4};
use upc::dynamics::{
    BaseJoint, Data, JointKind, Model, OpSpaceWorkspace, ReferenceFrame, aba,
    compute_joint_jacobians, crba, get_frame_jacobian, icub_like, jacobian_center_of_mass, rnea,
};

/// One benchmarked state; `tau = rnea(q, v, a)` is ABA's input.
struct State {
    q: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    tau: DVector<f64>,
}

/// splitmix64 (no randomness crate needed): uniform in [lo, hi).
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// `n` random states: q uniform within the joint limits (±π where unbounded; the free-flyer's
/// translation within ±1 m and a uniformly random orientation), v and a uniform in [-1, 1].
fn random_states(model: &Model, n: usize) -> Vec<(DVector<f64>, DVector<f64>, DVector<f64>)> {
    let mut rng = Rng(0x5eed);
    (0..n)
        .map(|_| {
            let mut q = model.neutral();
            for j in &model.joints {
                let qj = &mut q.as_mut_slice()[j.idx_q..j.idx_q + j.nq()];
                match j.kind {
                    JointKind::FreeFlyer => {
                        for x in &mut qj[..3] {
                            *x = rng.uniform(-1.0, 1.0);
                        }
                        // Rejection sampling in the unit ball: a uniform rotation.
                        let quat = loop {
                            let c = Vector4::from_fn(|_, _| rng.uniform(-1.0, 1.0));
                            let n2 = c.norm_squared();
                            if n2 > 1e-6 && n2 <= 1.0 {
                                break c / n2.sqrt();
                            }
                        };
                        qj[3..].copy_from_slice(quat.as_slice());
                    }
                    _ => {
                        let (lo, hi) = (j.limits.lower, j.limits.upper);
                        qj[0] = if lo.is_finite() && hi.is_finite() {
                            rng.uniform(lo, hi)
                        } else {
                            rng.uniform(-std::f64::consts::PI, std::f64::consts::PI)
                        };
                    }
                }
            }
            let v = DVector::from_fn(model.nv, |_, _| rng.uniform(-1.0, 1.0));
            let a = DVector::from_fn(model.nv, |_, _| rng.uniform(-1.0, 1.0));
            (q, v, a)
        })
        .collect()
}

fn bench_model(
    c: &mut Criterion,
    label: &str,
    model: &Model,
    qva: Vec<(DVector<f64>, DVector<f64>, DVector<f64>)>,
    op: Option<(&str, &str)>,
) {
    let mut data = Data::new(model);
    let mut states = Vec::with_capacity(qva.len());
    for (q, v, a) in qva {
        match rnea(model, &mut data, &q, &v, &a) {
            Ok(t) => {
                let tau = t.clone();
                states.push(State { q, v, a, tau });
            }
            Err(e) => {
                eprintln!("{label}: {e}");
                return;
            }
        }
    }
    let n = states.len();
    let mut g = c.benchmark_group(label);
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(50);
    let mut k = 0;
    g.bench_function("rnea", |b| {
        b.iter(|| {
            let s = &states[k % n];
            k += 1;
            let _ = black_box(rnea(model, &mut data, &s.q, &s.v, &s.a));
        })
    });
    g.bench_function("crba", |b| {
        b.iter(|| {
            k += 1;
            let _ = black_box(crba(model, &mut data, &states[k % n].q));
        })
    });
    match states
        .iter()
        .try_for_each(|s| aba(model, &mut data, &s.q, &s.v, &s.tau).map(|_| ()))
    {
        Ok(()) => {
            g.bench_function("aba", |b| {
                b.iter(|| {
                    let s = &states[k % n];
                    k += 1;
                    let _ = black_box(aba(model, &mut data, &s.q, &s.v, &s.tau));
                })
            });
        }
        Err(e) => eprintln!("{label}: ABA skipped: {e}"),
    }
    let q = states[0].q.clone();
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
            let op = Some(("chest", "r_hand"));
            let (_, v, a) = random_states(&model, 1).remove(0);
            bench_model(c, "icub_like_home", &model, vec![(home, v, a)], op);
            bench_model(c, "icub_like_random", &model, random_states(&model, 64), op);
        }
        Err(e) => eprintln!("humanoid: {e}"),
    }
    if let Ok(path) = std::env::var("UPC_BENCH_URDF") {
        match Model::from_urdf_file(&path, BaseJoint::Auto) {
            Ok(model) => {
                let spec = std::env::var("UPC_BENCH_OPSPACE").ok();
                let op = spec.as_deref().and_then(|s| s.split_once(','));
                bench_model(c, "env_urdf", &model, random_states(&model, 64), op);
            }
            Err(e) => eprintln!("UPC_BENCH_URDF={path}: {e}"),
        }
    }
}

criterion_group!(dynamics, benches);
criterion_main!(dynamics);
