//! Preview core timings: C0/C1 per solve (Riccati vs dense) at N = 100/300/600, the hand
//! previewer, and one C2 gain search (Gauss–Newton warm/cold, Nelder–Mead). Single-threaded.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use upc::config::{Config, GainSolverKind, LqSolverKind};
use upc::preview::gain_search::{GainSearch, GainSearchInputs};
use upc::preview::{CartTable, GainSchedule, HandPreviewer, HandState, ZmpPreview};
use upc::robot::ReducedModel;
use upc::scenario::Scenario;

fn config(sets: &[String]) -> Config {
    let mut l = upc::config::Config::default_layers().expect("embedded defaults parse");
    for s in sets {
        l.push_override(s).expect("override");
    }
    l.build().expect("valid config")
}

/// The iCub-like's reduced models (computed from its model once).
fn robot() -> ReducedModel {
    static ROBOT: std::sync::OnceLock<ReducedModel> = std::sync::OnceLock::new();
    *ROBOT.get_or_init(|| upc::robot::Robot::embedded_default().unwrap().reduced())
}

fn model(c: &Config) -> CartTable {
    robot().cart_table(c.preview.period, c.robot.gravity)
}

fn lq(c: &mut Criterion) {
    // Single-threaded faer, as the controller runs it (`control::server`): with faer's default
    // thread pool the dense solve's time depended on what the other core was doing (0.96 to
    // 2.2 ms between runs), and so did every "× the dense solve" ratio.
    faer::set_global_parallelism(faer::Par::Seq);
    let cfg = config(&[]);
    let state = [
        Vector3::new(0.01, -0.02, 0.3),
        Vector3::new(-0.005, 0.04, -0.2),
    ];
    for n in [100usize, 300, 600] {
        let refs: Vec<[f64; 2]> = (0..n)
            .map(|i| [if i > n / 3 { 0.05 } else { 0.0 }, 0.0])
            .collect();
        // A horizontal forecast (α0 constant: the factorisation is reused between ticks) and
        // two with a vertical component (α0 varies: every solve re-runs the Riccati recursion).
        let horizontal: Vec<[f64; 3]> = (0..n)
            .map(|i| [-40.0 * (i as f64 * 0.03).sin().max(0.0), 5.0, 0.0])
            .collect();
        let vertical: [Vec<[f64; 3]>; 2] = [0.0, 1.0].map(|s| {
            (0..n)
                .map(|i| [-40.0, 5.0, 30.0 * ((i as f64 + s) * 0.03).sin()])
                .collect()
        });
        // As the controller runs them (PC-T's tail as configured), and the paper's finite
        // horizon beside: the tail changes only the recursion's first step.
        let tail = cfg.preview.terminal_cost;
        for (name, solver, tail) in [
            ("riccati", LqSolverKind::Riccati, tail),
            ("riccati_finite", LqSolverKind::Riccati, false),
            ("dense", LqSolverKind::Dense, tail),
        ] {
            let mut p = ZmpPreview::new(model(&cfg), cfg.preview.q_e, cfg.preview.r, n, solver)
                .with_terminal_cost(tail);
            c.bench_with_input(BenchmarkId::new(format!("c0_{name}"), n), &n, |b, _| {
                b.iter(|| black_box(p.solve_c0(black_box(&state), &refs)))
            });
            c.bench_with_input(BenchmarkId::new(format!("c1_{name}"), n), &n, |b, _| {
                b.iter(|| black_box(p.solve_c1(black_box(&state), &refs, &horizontal)))
            });
            let mut k = 0usize;
            c.bench_with_input(
                BenchmarkId::new(format!("c1_{name}_varying_alpha0"), n),
                &n,
                |b, _| {
                    b.iter(|| {
                        k += 1;
                        black_box(p.solve_c1(black_box(&state), &refs, &vertical[k % 2]))
                    })
                },
            );
        }
    }
}

fn hand(c: &mut Criterion) {
    let cfg = config(&[]);
    let n = cfg.preview.horizon;
    let m_e = robot().effective_mass;
    let mut hp = HandPreviewer::new(cfg.preview.period, m_e, n).expect("SPD M_e");
    let gains = GainSchedule::constant(n, cfg.hand.kp, cfg.nominal_kd(cfg.hand.kp));
    let des = HandState::default();
    let desired = vec![des; n];
    let forces: Vec<[f64; 3]> = (0..n)
        .map(|i| [-40.0 * (i as f64 * 0.03).sin().max(0.0), 5.0, 0.0])
        .collect();
    c.bench_function("hand_previewer/300", |b| {
        b.iter(|| black_box(hp.predict(black_box(&des), &desired, &gains, &forces, n)))
    });
}

fn gain_search(c: &mut Criterion) {
    let mut group = c.benchmark_group("c2");
    group.sample_size(20);
    let scenario = Scenario::load("single_impact").expect("embedded scenario");
    for n in [300usize] {
        let cfg = config(&[format!("preview.horizon={n}")]);
        let t = cfg.preview.period;
        let mut f = vec![[0.0; 3]; n];
        // At the impact onset: the hardest moment for the gain search.
        scenario.force.sample_into(1.0 + t, t, &mut f);
        let des = HandState {
            pos: robot().hand_position,
            ..Default::default()
        };
        let desired = vec![des; n];
        let refs = vec![[0.0; 2]; n];
        let inputs = GainSearchInputs {
            com: [Vector3::zeros(), Vector3::zeros()],
            zmp_ref: &refs,
            hand: des,
            hand_desired: &desired,
            f_ext: &f,
            applied: [cfg.hand.kp, cfg.nominal_kd(cfg.hand.kp)],
        };
        for (name, kind) in [
            ("gauss_newton", GainSolverKind::GaussNewton),
            ("nelder_mead", GainSolverKind::NelderMead),
        ] {
            let mut s = GainSearch::with_solver(&cfg, &robot(), kind).expect("gain search");
            let report = s.search(&inputs, 1).expect("search");
            eprintln!(
                "{name} N={n}: cold cost {:.4e} (nominal {:.4e}), {} iterations, {} evaluations, {:?}",
                report.cost,
                report.nominal_cost,
                report.iterations,
                report.evaluations,
                report.elapsed
            );
            group.bench_with_input(BenchmarkId::new(format!("{name}_warm"), n), &n, |b, _| {
                b.iter(|| black_box(s.search(&inputs, 1)))
            });
            group.bench_with_input(BenchmarkId::new(format!("{name}_cold"), n), &n, |b, _| {
                b.iter(|| {
                    s.reset();
                    black_box(s.search(&inputs, 1))
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, lq, hand, gain_search);
criterion_main!(benches);
