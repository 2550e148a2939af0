//! The controller's compute per tick without IPC (`ControllerCore::tick`): kinematics, M_e,
//! the hand previewer, the ZMP preview, the whole-body QP; C0 and C1 at home with a forecast
//! push arriving over the horizon (so C1's disturbance and α0 vary every tick, as in a run);
//! C1 on a robot's sensors, its base estimated (docs/estimation.md).
//! Profile it with `perf record` on this bench to see where a tick's time goes.
//!
//! Run: `cargo bench --bench control`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use upc::config::{Config, ControllerKind};
use upc::control::CorrectionSettings;

// The tests' rig; the bench uses a part of it.
#[allow(dead_code)]
#[path = "../tests/support/humanoid.rs"]
mod humanoid;

fn bench(c: &mut Criterion) {
    let config = Config::embedded_default().expect("defaults");
    let mut g = c.benchmark_group("control");
    g.warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3))
        .sample_size(50);
    // C1 with and without the forecast correction (docs/forecast_correction.md): the state's
    // hand force is the forecast's, so the estimator runs its full window every 5th tick.
    let parts = &config.controller.parts;
    let correction: CorrectionSettings = parts.get().expect("defaults");
    let mut uncorrected = config.clone();
    uncorrected
        .controller
        .parts
        .set(&CorrectionSettings {
            enabled: false,
            ..correction
        })
        .expect("settings");
    // Without the forecast's record (FC-5): its cost is c1_tick's less this one's.
    let mut no_record = config.clone();
    no_record
        .controller
        .parts
        .set(&CorrectionSettings {
            skill_time: 0.0,
            ..correction
        })
        .expect("settings");
    // Every force sensor replaced by the wrench observer (docs/estimation.md, WO): what a
    // robot without them pays per tick.
    let mut wrenches = config.clone();
    let mut wo: upc::control::parts::wrench_observer::WrenchObserverSettings =
        parts.get().expect("defaults");
    wo.mode = upc::control::parts::wrench_observer::WrenchMode::On;
    wrenches.controller.parts.set(&wo).expect("settings");
    let weight = upc::robot::Robot::embedded_default()
        .expect("robot")
        .derived
        .mass
        * 9.81;
    // (name, controller, settings, estimated base, hand force measured as forecast; else none:
    // a phantom, whose forecast FC-5 discounts and blends toward measurement only).
    let case = std::env::var("UPC_BENCH_CASE").ok();
    let only = case.as_deref();
    for (name, kind, config, estimated, measured) in [
        ("c0_tick", ControllerKind::C0, &config, false, true),
        ("c1_tick", ControllerKind::C1, &config, false, true),
        (
            "c1_tick_uncorrected",
            ControllerKind::C1,
            &uncorrected,
            false,
            true,
        ),
        (
            "c1_tick_no_record",
            ControllerKind::C1,
            &no_record,
            false,
            true,
        ),
        ("c1_tick_phantom", ControllerKind::C1, &config, false, false),
        (
            "c1_tick_estimated_wrenches",
            ControllerKind::C1,
            &wrenches,
            false,
            true,
        ),
        (
            "c1_tick_estimated_base",
            ControllerKind::C1,
            &config,
            true,
            true,
        ),
        // What a G1 measures (docs/sensing.md): the base estimated from the IMU and the
        // encoders, every wrench from the joint torques.
        (
            "c1_tick_joint_sensing",
            ControllerKind::C1,
            &wrenches,
            true,
            true,
        ),
    ] {
        let mut r = humanoid::rig(config, kind);
        if estimated {
            r.without_base(weight);
        }
        r.window
            .offer(&humanoid::push_forecast(0.0, -40.0), 0.0)
            .expect("forecast");
        // Walk time through the first second of the forecast (the push enters the horizon at
        // 0.5 s), then start over: every tick sees a different horizon. The last joint moves by
        // a nanoradian every other tick, as encoders do: a robot's tick never sees the last
        // tick's configuration, whose placements the dynamics would reuse.
        let mut k = 0u64;
        let last = r.state.nq as usize - 1;
        let q_last = r.state.q[last];
        let mut tick = || {
            r.state.q[last] = q_last + (k % 2) as f64 * 1e-9;
            r.state.time = (k % 1000) as f64 * 0.001;
            r.state.stamps = [r.state.time; 4];
            r.state.hand_force = if measured {
                r.window.at(r.state.time)
            } else {
                [0.0; 3]
            };
            k += 1;
            let out = r.tick(None);
            black_box((out.is_ok(), r.tau[0]));
        };
        match fixed_ticks() {
            Some(n) if only.is_none_or(|o| o == name) => (0..n).for_each(|_| tick()),
            Some(_) => continue,
            None => {
                g.bench_function(name, |b| b.iter(&mut tick));
            }
        }
        let c = r.core.wbc_counters();
        eprintln!(
            "{name}: {} ticks, cone solve {} ({} Newton steps), left to clarabel {}, torque-limited {} \
             ({} held by the cone solve)",
            c.ticks,
            c.active_set,
            c.cone_steps,
            c.cone_unsettled,
            c.torque_limited,
            c.limits_condensed
        );
    }
    if fixed_ticks().is_some() {
        return;
    }
    offers(&mut g);
    handoff(&mut g, &config);
    g.finish();
}

/// `UPC_BENCH_TICKS=N`: each case (or only `UPC_BENCH_CASE`'s) runs N ticks and no criterion
/// measurement, for `valgrind --tool=callgrind --toggle-collect='*ControllerCore::tick'`, whose
/// instruction count per tick does not move with this VM's speed as its times do.
fn fixed_ticks() -> Option<u64> {
    std::env::var("UPC_BENCH_TICKS").ok()?.parse().ok()
}

/// What the loop pays to hand C2 a snapshot and to read its newest schedule while the search
/// runs in its thread (`tests/control.rs` checks what is handed over; how long it takes, here).
fn handoff(g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>, config: &Config) {
    let mut config = config.clone();
    config.preview.horizon = 200;
    let mut r = humanoid::rig(&config, ControllerKind::C2);
    r.window
        .offer(&humanoid::push_forecast(0.0, -50.0), 0.0)
        .expect("forecast");
    r.tick(None).expect("tick");
    let robot = upc::robot::Robot::embedded_default()
        .expect("robot")
        .reduced();
    let mut handoff = upc::control::GainHandoff::spawn(&config, &robot).expect("thread");
    let mut seq = 0u64;
    g.bench_function("c2_handoff_offer", |b| {
        b.iter(|| {
            seq += 1;
            handoff.offer(|s| r.core.snapshot(s, seq));
        })
    });
    g.bench_function("c2_handoff_latest", |b| {
        b.iter(|| black_box(handoff.latest().seq))
    });
}

/// What the forecast intake costs per window: a valid one taken (its samples copied), and bad
/// ones refused (a NaN force found at the last sample, a lift-off, a window far in the future):
/// a rejection must cost no more than a take, so that a flood of bad windows leaves the tick
/// alone (`tests/faults.rs`, `bad_forecasts_are_rejected_…`).
fn offers(g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>) {
    let valid = humanoid::push_forecast(0.0, -40.0);
    let mut nan = valid.clone();
    let last = nan.len as usize - 1;
    nan.forces[last][0] = f64::NAN;
    let mut lift = valid.clone();
    lift.forces[last][2] = 1e4;
    let mut future = valid.clone();
    future.t0 = 100.0;
    let mut window = upc::control::ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
    for (name, msg) in [
        ("forecast_offer_valid", &valid),
        ("forecast_offer_rejected_nan", &nan),
        ("forecast_offer_rejected_lift", &lift),
        ("forecast_offer_rejected_future", &future),
    ] {
        // A new seq each time: a valid window is taken, never refused as a replay.
        let mut m = msg.clone();
        g.bench_function(name, |b| {
            b.iter(|| {
                m.seq += 1;
                black_box(window.offer(black_box(&m), 0.0).is_ok())
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
