//! The control server's pieces without IPC: one tick of the core on the humanoid, the C2 thread
//! behind its triple buffers, the forecast window, the ticker.

use std::time::{Duration, Instant};

use upc::channels::{ForecastMsg, StateMsg};
use upc::config::{Config, ControllerKind};
use upc::control::{ControllerCore, ForecastWindow, GainHandoff};
use upc::dynamics::icub_like;

fn home_state(model: &upc::dynamics::Model) -> StateMsg {
    let q = icub_like::home_configuration(model).expect("home");
    let mut s = StateMsg {
        nq: model.nq as u32,
        nv: model.nv as u32,
        ..Default::default()
    };
    s.q[..model.nq].copy_from_slice(q.as_slice());
    s
}

fn forecast(t0: f64, f: f64) -> Box<ForecastMsg> {
    let mut m: Box<ForecastMsg> = Box::default();
    m.seq = 1;
    m.t0 = t0;
    m.dt = 0.005;
    m.len = 500;
    for (i, s) in m.forces.iter_mut().enumerate().take(500) {
        *s = [if i > 100 { f } else { 0.0 }, 0.0, 0.0];
    }
    m
}

#[test]
fn a_tick_at_home_gives_finite_torques_for_each_controller() {
    let config = Config::embedded_default().expect("defaults");
    for kind in [ControllerKind::C0, ControllerKind::C1, ControllerKind::C2] {
        let model = icub_like::load().expect("model");
        let state = home_state(&model);
        let n = model.nv - 6;
        let mut core = ControllerCore::new(model, &config, kind, 0.001, [100.0, 20.0], [0.0, 0.0])
            .expect("core");
        let mut window = ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
        window
            .offer(&forecast(0.0, -40.0), 0.0)
            .expect("valid forecast");
        let mut tau = vec![0.0; n];
        let status = core.tick(&state, &window, None, &mut tau).expect("tick");
        assert_eq!(status, upc::wbc::WbcStatus::Solved, "{kind:?}");
        assert!(
            tau.iter().all(|t| t.is_finite()) && tau.iter().any(|t| t.abs() > 0.1),
            "{kind:?}: {tau:?}"
        );
        let rec = core.last;
        // C1 sees the coming push in its disturbance forecast; C0 ignores it.
        if kind == ControllerKind::C0 {
            assert_eq!(rec.f_dis, [0.0; 3]);
        }
        assert!(
            rec.hand_err < 1e-9,
            "the hand set-point is latched at the first tick"
        );
        let sup = core.support().expect("latched support");
        assert!(sup[0][0] < rec.zmp_ref[0] && rec.zmp_ref[0] < sup[0][1]);
    }
}

#[test]
fn c1_leans_into_a_forecast_push_and_c0_does_not() {
    // Over 20 ticks on a frozen state, C1's commanded CoM acceleration turns toward the push
    // (+x against a −x force) well beyond what C0 commands to centre the CoM on the feet.
    let config = Config::embedded_default().expect("defaults");
    let mut acc = Vec::new();
    for kind in [ControllerKind::C0, ControllerKind::C1] {
        let model = icub_like::load().expect("model");
        let mut state = home_state(&model);
        let n = model.nv - 6;
        let mut core = ControllerCore::new(model, &config, kind, 0.001, [100.0, 20.0], [0.0, 0.0])
            .expect("core");
        let mut window = ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
        window
            .offer(&forecast(0.0, -60.0), 0.0)
            .expect("valid forecast");
        let mut tau = vec![0.0; n];
        for k in 0..20 {
            state.time = k as f64 * 0.001;
            core.tick(&state, &window, None, &mut tau).expect("tick");
        }
        acc.push(core.last.com_acc_cmd[0]);
    }
    eprintln!(
        "commanded CoM acceleration along x: C0 {} C1 {}",
        acc[0], acc[1]
    );
    assert!(
        acc[1] > acc[0] + 0.1 && acc[1] > 0.0,
        "C0 {} C1 {}",
        acc[0],
        acc[1]
    );
}

#[test]
fn bad_state_is_an_error_value() {
    let config = Config::embedded_default().expect("defaults");
    let model = icub_like::load().expect("model");
    let mut state = home_state(&model);
    let n = model.nv - 6;
    let mut core = ControllerCore::new(
        model,
        &config,
        ControllerKind::C1,
        0.001,
        [100.0, 20.0],
        [0.0, 0.0],
    )
    .expect("core");
    let window = ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
    let mut tau = vec![0.0; n];
    state.v[7] = f64::NAN;
    assert!(core.tick(&state, &window, None, &mut tau).is_err());
    state.v[7] = 0.0;
    state.nq = 12;
    let e = core
        .tick(&state, &window, None, &mut tau)
        .unwrap_err()
        .to_string();
    assert!(e.contains("nq = 12"), "{e}");
}

#[test]
fn c2_thread_hands_over_time_stamped_schedules_without_blocking() {
    let mut config = Config::embedded_default().expect("defaults");
    config.preview.horizon = 200;
    let n = config.preview.horizon;
    let model = icub_like::load().expect("model");
    let state = home_state(&model);
    let mut core = ControllerCore::new(
        model,
        &config,
        ControllerKind::C2,
        0.001,
        [100.0, 20.0],
        [0.0, 0.0],
    )
    .expect("core");
    let mut window = ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
    window
        .offer(&forecast(0.0, -50.0), 0.0)
        .expect("valid forecast");
    let mut tau = vec![0.0; core.model.nv - 6];
    core.tick(&state, &window, None, &mut tau).expect("tick");
    let mut handoff = GainHandoff::spawn(&config).expect("thread");
    assert_eq!(
        handoff.latest().seq,
        0,
        "no schedule before the first snapshot"
    );
    // Offering and reading never wait for the worker.
    let t = Instant::now();
    handoff.offer(|s| core.snapshot(s, 7));
    let _ = handoff.latest();
    assert!(t.elapsed() < Duration::from_millis(50));
    let deadline = Instant::now() + Duration::from_secs(20);
    while handoff.latest().seq == 0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    let s = handoff.latest().clone();
    assert_eq!(s.seq, 7);
    assert_eq!(s.schedule.kp.len(), n);
    assert!(s.cost <= s.nominal_cost, "{} > {}", s.cost, s.nominal_cost);
    let [lo, hi] = config.gain_search.kp_bounds;
    assert!(
        s.schedule
            .kp
            .iter()
            .all(|k| *k >= lo - 1e-9 && *k <= hi + 1e-9)
    );
    assert!(handoff.alive());
    // The tick uses a fresh schedule's first gain.
    core.tick(&state, &window, Some(&s), &mut tau)
        .expect("tick");
    assert!((core.last.kp - s.schedule.kp[0]).abs() < 1e-9);
}
