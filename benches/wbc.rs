//! Whole-body QP benchmark: one tick (kinematics, dynamics, assembly, clarabel solve, torque
//! recovery) on the humanoid, at home and at perturbed configurations, for the fast path (one
//! solver updated in place) and the slow path (a new solver each tick).
//!
//! Run: `cargo bench --bench wbc`. Besides criterion's mean / median, the setup runs 1000 ticks
//! of each formulation (full, condensed) and tolerance and prints p50 / p99 / max of the tick
//! time, the interior-point iterations and the torques' distance to a tight reference solve
//! (criterion reports neither tail nor accuracy). `wbc/replay_exported` solves, in turn, the
//! 400 ticks whose QPs `UPC_QP_EXPORT=path` writes for the solver comparison
//! (`scripts/qp_compare.py`).

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DVector, Vector3};
use upc::config::{Config, WbcConfig, WbcFormulation};
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

/// The iCub-like's contact, sole and hand frames (its description names them).
fn frames() -> upc::robot::BodyFrames {
    upc::robot::Robot::embedded_default()
        .expect("robot")
        .frames()
}

fn percentiles(mut t: Vec<Duration>) -> (Duration, Duration, Duration) {
    t.sort();
    let p = |f: f64| t[((t.len() as f64 - 1.0) * f).round() as usize];
    (p(0.5), p(0.99), t[t.len() - 1])
}

/// The QP at perturbed states (amplitude `amp`): tick-time percentiles, iterations, and the
/// torques' distance to a reference solve (the full formulation at tolerance 1e-9), so that a
/// formulation or a tolerance is judged on speed and accuracy together.
fn tail_report(label: &str, cfg: &WbcConfig, amp: f64, n: usize) {
    let model = icub_like::load().unwrap();
    let home = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &home).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    let mut wbc = WholeBodyController::new(&model, cfg, &frames()).unwrap();
    wbc.set_posture_reference(&model, &home).unwrap();
    let mut ref_cfg = cfg.clone();
    ref_cfg.formulation = WbcFormulation::Full;
    ref_cfg.tolerance = 1e-9;
    let mut reference = WholeBodyController::new(&model, &ref_cfg, &frames()).unwrap();
    reference.set_posture_reference(&model, &home).unwrap();
    let mut times = Vec::with_capacity(n);
    let mut iters = Vec::with_capacity(n);
    let mut dtau: f64 = 0.0;
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
        let tau = out.tau.clone();
        if k >= 20 {
            // First ticks excluded: the solver build and cache warm-up.
            times.push(dt);
            iters.push(it);
            assert!(ok, "{label}: tick {k} fell back");
            if k % 10 == 0 {
                let r = reference.solve(&model, &mut data, &q, &v, &cmd);
                dtau = dtau.max((r.tau - &tau).amax());
            }
        }
    }
    let (p50, p99, max) = percentiles(times);
    iters.sort();
    let c = wbc.counters();
    eprintln!(
        "wbc {label}: {n} ticks  p50 {:.1} µs  p99 {:.1} µs  max {:.1} µs  | iterations p50 {} max {}  | \
         max |τ − τ_ref| {dtau:.1e} N·m  | fallbacks {}  solver builds {}",
        p50.as_secs_f64() * 1e6,
        p99.as_secs_f64() * 1e6,
        max.as_secs_f64() * 1e6,
        iters[iters.len() / 2],
        iters[iters.len() - 1],
        c.fallbacks,
        c.solver_builds,
    );
}

/// One exported tick: its kind, state and request.
struct Tick {
    kind: &'static str,
    q: DVector<f64>,
    v: DVector<f64>,
    cmd: WbcCommand<'static>,
}

/// The 400 ticks whose QPs `UPC_QP_EXPORT` writes and the `replay_exported` bench solves: 100
/// standing, 150 pushed at the hand (10–70 N), 150 at perturbed postures with pushes.
fn exported_ticks(model: &Model, home: &DVector<f64>) -> Vec<Tick> {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, home).unwrap();
    let hand = data.o_m_f[model.frame_id("r_hand").unwrap()].trans;
    (0..400)
        .map(|k| {
            let (kind, amp, push) = match k {
                0..100 => ("standing", 0.0, 0.0),
                100..250 => ("pushed", 0.0, -10.0 - 60.0 * ((k - 100) as f64 / 150.0)),
                _ => ("perturbed", 0.05, -40.0 * ((k as f64 * 0.3).sin()).abs()),
            };
            let (q, v, com) = state(model, home, k, amp);
            let cmd = WbcCommand {
                com_acc: com * 0.5,
                hand_pos_des: hand,
                kp: 100.0,
                kd: 20.0,
                hand_force: Vector3::new(push, 0.3 * push, 0.0),
                ..WbcCommand::default()
            };
            Tick { kind, q, v, cmd }
        })
        .collect()
}

/// With `UPC_QP_EXPORT=path`: the condensed QP of the [`exported_ticks`] written as JSON lines
/// for `scripts/qp_compare.py`, each with upc's answer: the active set's where it decides, and
/// clarabel's (iterations, solve time) from a second controller that runs clarabel on every
/// tick.
fn export_instances(path: &str) {
    let cfg = Config::embedded_default().unwrap().wbc;
    let model = icub_like::load().unwrap();
    let home = upc::robot::Robot::embedded_default().expect("robot").home;
    let mut data = Data::new(&model);
    let mut fast = WholeBodyController::new(&model, &cfg, &frames()).unwrap();
    let clarabel_cfg = WbcConfig {
        active_set: false,
        ..cfg.clone()
    };
    let mut slow = WholeBodyController::new(&model, &clarabel_cfg, &frames()).unwrap();
    for w in [&mut fast, &mut slow] {
        w.set_posture_reference(&model, &home).unwrap();
    }
    fast.record_condensed_instances();
    let mut out = String::new();
    for Tick { kind, q, v, cmd } in exported_ticks(&model, &home) {
        let (q, v, cmd) = (&q, &v, &cmd);
        let limited = fast.counters().torque_limited;
        let a = best_of_5(&mut fast, &model, &mut data, q, v, cmd);
        // A tick at a torque limit is decided by the full problem: its condensed QP (without
        // the limits) is exported all the same, marked.
        let limited = fast.counters().torque_limited > limited;
        let inst = fast.condensed_instance().expect("condensed");
        // Timed as the script times the wheels: the best of 5 solves of the tick.
        let b = best_of_5(&mut slow, &model, &mut data, q, v, cmd);
        let forces: Vec<f64> = a.1.iter().flat_map(|f| f.iter().copied()).collect();
        let line = serde_json::json!({
            "kind": kind, "n": inst.n, "m": inst.m, "zero": inst.zero, "soc": inst.soc,
            "force_unit": inst.force_unit, "P": inst.p, "q": inst.q, "A": inst.a, "b": inst.b,
            "active_set": a.0 == 0, "torque_limited": limited, "forces": forces,
            "tick_us": a.3 * 1e6, "solve_us": a.2 * 1e6,
            "clarabel_iterations": b.0, "clarabel_solve_us": b.2 * 1e6, "clarabel_tick_us": b.3 * 1e6,
            "clarabel_forces": b.1.iter().flat_map(|f| f.iter().copied()).collect::<Vec<f64>>(),
        });
        out.push_str(&line.to_string());
        out.push('\n');
    }
    std::fs::write(path, out).expect("write the instances");
    eprintln!("wrote 400 condensed QP instances to {path}");
}

/// One tick solved 5 times: the first solve's iterations and contact forces, and the least
/// clarabel solve time and whole-tick wall time (s) of the five.
fn best_of_5(
    w: &mut WholeBodyController,
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    cmd: &WbcCommand,
) -> (u32, Vec<Vector3<f64>>, f64, f64) {
    let mut best: Option<(u32, Vec<Vector3<f64>>, f64, f64)> = None;
    for _ in 0..5 {
        let t0 = Instant::now();
        let out = w.solve(model, data, q, v, cmd);
        let wall = t0.elapsed().as_secs_f64();
        assert_eq!(out.status, WbcStatus::Solved);
        let solve = out.solve_time.as_secs_f64();
        best = Some(match best {
            None => (out.iterations, out.contact_forces.to_vec(), solve, wall),
            Some((it, f, s, t)) => (it, f, s.min(solve), t.min(wall)),
        });
    }
    best.expect("five solves")
}

fn bench(c: &mut Criterion) {
    if let Ok(path) = std::env::var("UPC_QP_EXPORT") {
        export_instances(&path);
        return;
    }
    let cfg = Config::embedded_default().unwrap().wbc;
    let with = |f: WbcFormulation, tol: f64, reuse: bool| WbcConfig {
        formulation: f,
        tolerance: tol,
        reuse_solver: reuse,
        ..cfg.clone()
    };
    let (full, condensed) = (WbcFormulation::Full, WbcFormulation::Condensed);
    for amp in [0.02, 0.10] {
        for tol in [1e-8, 1e-6, 1e-4] {
            for f in [full, condensed] {
                let label = format!("{f:?} tol {tol:.0e}, home±{amp} rad, reused solver");
                tail_report(&label, &with(f, tol, true), amp, 1000);
            }
        }
    }
    for f in [full, condensed] {
        let label = format!("{f:?}, home±0.02 rad, new solver each tick");
        tail_report(&label, &with(f, cfg.tolerance, false), 0.02, 300);
    }
    let model = icub_like::load().unwrap();
    let size = WholeBodyController::new(&model, &with(full, 1e-6, true), &frames())
        .unwrap()
        .problem_size();
    eprintln!(
        "full QP: {} vars, {} rows, nnz P {}, A {}",
        size.0, size.1, size.2, size.3
    );

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
    let zero = DVector::zeros(model.nv);
    let states: Vec<_> = (0..64).map(|k| state(&model, &home, k, 0.05)).collect();
    for (name, f) in [("", condensed), ("_full", full)] {
        let mut wbc =
            WholeBodyController::new(&model, &with(f, cfg.tolerance, true), &frames()).unwrap();
        wbc.set_posture_reference(&model, &home).unwrap();
        g.bench_function(format!("tick_home{name}"), |b| {
            b.iter(|| {
                let out = wbc.solve(&model, &mut data, &home, &zero, &cmd);
                black_box(out.tau[0]);
            })
        });
        let mut k = 0;
        g.bench_function(format!("tick_perturbed{name}"), |b| {
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
    }
    let mut cold =
        WholeBodyController::new(&model, &with(condensed, cfg.tolerance, false), &frames())
            .unwrap();
    cold.set_posture_reference(&model, &home).unwrap();
    g.bench_function("tick_home_new_solver", |b| {
        b.iter(|| {
            let out = cold.solve(&model, &mut data, &home, &zero, &cmd);
            black_box(out.tau[0]);
        })
    });
    // The ticks of the solver comparison (docs/results/benchmarks.md), in turn, through upc's
    // path (the active set where it decides, clarabel updated in place elsewhere): one
    // iteration is one tick, the mean over the 400.
    let ticks = exported_ticks(&model, &home);
    let mut wbc = WholeBodyController::new(&model, &cfg, &frames()).unwrap();
    wbc.set_posture_reference(&model, &home).unwrap();
    let mut k = 0;
    g.bench_function("replay_exported", |b| {
        b.iter(|| {
            let t = &ticks[k % ticks.len()];
            k += 1;
            let out = wbc.solve(&model, &mut data, &t.q, &t.v, &t.cmd);
            black_box(out.tau[0]);
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
