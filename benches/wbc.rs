//! Whole-body QP benchmark: one tick (kinematics, dynamics, assembly, clarabel solve, torque
//! recovery) on the humanoid, at home and at perturbed configurations, for the fast path (one
//! solver updated in place) and the slow path (a new solver each tick).
//!
//! Run: `cargo bench --bench wbc`. Besides criterion's mean / median, the setup runs 2000 ticks
//! of each case and prints p50 / p99 / max of the tick time and the interior-point iterations
//! (criterion reports neither tail). Target: p99 ≤ 0.5 ms.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DVector, Vector3};
use upc::config::Config;
use upc::dynamics::{Data, Model, forward_kinematics, icub_like};
use upc::wbc::{WbcCommand, WbcStatus, WholeBodyController};

/// Deterministic perturbation `k` of the home posture: every joint (legs too: the soles tilt a
/// little, which the QP handles through the sole normals), a small joint velocity, and a
/// varying CoM / hand request.
fn state(
    model: &Model,
    home: &DVector<f64>,
    k: usize,
    amp: f64,
) -> (DVector<f64>, DVector<f64>, Vector3<f64>) {
    let mut q = home.clone();
    let mut v = DVector::zeros(model.nv);
    let s = k as f64;
    for j in &model.joints[1..] {
        let i = j.idx_v as f64;
        q[j.idx_q] += amp * (0.37 * s + 1.7 * i).sin();
        v[j.idx_v] = 2.0 * amp * (0.23 * s + 0.9 * i).cos();
    }
    let com = Vector3::new(0.5 * (0.1 * s).sin(), 0.3 * (0.07 * s).cos(), 0.0);
    (q, v, com)
}

fn percentiles(mut t: Vec<Duration>) -> (Duration, Duration, Duration) {
    t.sort();
    let p = |f: f64| t[((t.len() as f64 - 1.0) * f).round() as usize];
    (p(0.5), p(0.99), t[t.len() - 1])
}

fn tail_report(label: &str, reuse: bool, amp: f64) {
    let mut cfg = Config::embedded_default().unwrap().wbc;
    cfg.reuse_solver = reuse;
    let model = icub_like::load().unwrap();
    let home = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &home).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let mut wbc = WholeBodyController::new(&model, &cfg).unwrap();
    wbc.set_posture_reference(&model, &home).unwrap();
    let n = if reuse { 2000 } else { 300 };
    let mut times = Vec::with_capacity(n);
    let mut iters = Vec::with_capacity(n);
    for k in 0..n + 20 {
        let (q, v, com) = state(&model, &home, k, amp);
        let cmd = WbcCommand {
            com_acc: com,
            hand_pos_des: hand,
            kp: 100.0,
            kd: 20.0,
            ..WbcCommand::default()
        };
        let t0 = Instant::now();
        let out = wbc.solve(&model, &mut data, &q, &v, &cmd);
        let dt = t0.elapsed();
        let ok = out.status == WbcStatus::Solved;
        let it = out.iterations;
        black_box(&out.tau);
        if k >= 20 {
            // First ticks excluded: the solver build and cache warm-up.
            times.push(dt);
            iters.push(it);
            assert!(ok, "{label}: tick {k} fell back");
        }
    }
    let (p50, p99, max) = percentiles(times);
    iters.sort();
    let c = wbc.counters();
    let (nz, rows, nnz_p, nnz_a) = wbc.problem_size();
    eprintln!(
        "wbc {label}: {n} ticks  p50 {:.1} µs  p99 {:.1} µs  max {:.1} µs  | iterations p50 {} max {}  | \
         fallbacks {}  solver builds {}  | QP {nz} vars, {rows} rows, nnz P {nnz_p}, A {nnz_a}",
        p50.as_secs_f64() * 1e6,
        p99.as_secs_f64() * 1e6,
        max.as_secs_f64() * 1e6,
        iters[iters.len() / 2],
        iters[iters.len() - 1],
        c.fallbacks,
        c.solver_builds,
    );
}

fn bench(c: &mut Criterion) {
    tail_report("home±0.02 rad, reused solver", true, 0.02);
    tail_report("home±0.10 rad, reused solver", true, 0.10);
    tail_report("home±0.02 rad, new solver each tick", false, 0.02);

    let cfg = Config::embedded_default().unwrap().wbc;
    let model = icub_like::load().unwrap();
    let home = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &home).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let cmd = WbcCommand {
        com_acc: Vector3::new(0.2, -0.1, 0.0),
        hand_pos_des: hand,
        kp: 100.0,
        kd: 20.0,
        ..WbcCommand::default()
    };
    let mut g = c.benchmark_group("wbc");
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3))
        .sample_size(50);
    let mut wbc = WholeBodyController::new(&model, &cfg).unwrap();
    wbc.set_posture_reference(&model, &home).unwrap();
    let zero = DVector::zeros(model.nv);
    g.bench_function("tick_home", |b| {
        b.iter(|| {
            let out = wbc.solve(&model, &mut data, &home, &zero, &cmd);
            black_box(out.tau[0]);
        })
    });
    let states: Vec<_> = (0..64).map(|k| state(&model, &home, k, 0.05)).collect();
    let mut k = 0;
    g.bench_function("tick_perturbed", |b| {
        b.iter(|| {
            let (q, v, com) = &states[k % states.len()];
            k += 1;
            let cmd = WbcCommand {
                com_acc: *com,
                ..cmd
            };
            let out = wbc.solve(&model, &mut data, q, v, &cmd);
            black_box(out.tau[0]);
        })
    });
    let mut cold_cfg = cfg.clone();
    cold_cfg.reuse_solver = false;
    let mut cold = WholeBodyController::new(&model, &cold_cfg).unwrap();
    cold.set_posture_reference(&model, &home).unwrap();
    g.bench_function("tick_home_new_solver", |b| {
        b.iter(|| {
            let out = cold.solve(&model, &mut data, &home, &zero, &cmd);
            black_box(out.tau[0]);
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
