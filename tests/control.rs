//! The control server's pieces without IPC: one tick of the core on the humanoid, the C2 thread
//! behind its triple buffers.

mod support;

use std::time::{Duration, Instant};

use support::humanoid::{rig, rig_of};
use upc::config::{Config, ControllerKind};
use upc::control::GainHandoff;
use upc::robot::Robot;

/// One tick at home with a −40 N push announced 0.5 s ahead: each controller gives finite,
/// non-zero torques from a solved QP; C0 ignores the disturbance, while C1 and C2 preview it
/// and already lean into the push (a CoM acceleration toward +x, against the force, that C0's
/// does not have).
#[test]
fn a_tick_at_home_gives_finite_torques_for_each_controller() {
    let config = Config::embedded_default().expect("defaults");
    let fx = -40.0;
    let mut acc = Vec::new();
    for kind in [ControllerKind::C0, ControllerKind::C1, ControllerKind::C2] {
        let mut r = rig(&config, kind);
        r.offer_push(fx);
        let status = r.tick(None).expect("tick");
        assert_eq!(status, upc::wbc::WbcStatus::Solved, "{kind:?}");
        assert!(
            r.tau.iter().all(|t| t.is_finite()) && r.tau.iter().any(|t| t.abs() > 0.1),
            "{kind:?}: {:?}",
            r.tau
        );
        let rec = r.core.last;
        if kind == ControllerKind::C0 {
            assert_eq!(rec.f_dis, [0.0; 3], "C0 ignores the disturbance");
        }
        let sup = r.core.support().expect("latched support");
        assert!(sup[0][0] < rec.zmp_ref[0] && rec.zmp_ref[0] < sup[0][1]);
        acc.push(rec.com_acc_cmd[0]);
    }
    eprintln!("CoM acceleration x (C0, C1, C2): {acc:?}");
    for (kind, a) in [("C1", acc[1]), ("C2", acc[2])] {
        assert!(
            (a - acc[0]) * -fx.signum() > 1e-4,
            "{kind} does not lean into the announced push: {a} against C0's {}",
            acc[0]
        );
    }
}

/// Gravity has one home in the controller: `robot.gravity` of the config is the cart-table's
/// and the whole-body dynamics' alike. On the Moon (1.62 m/s²) the torques that hold the robot
/// at home shrink by about g_moon / g_earth (gravity is most of them at rest).
#[test]
fn robot_gravity_is_the_whole_controllers() {
    let earth = Config::embedded_default().expect("defaults");
    let robot = Robot::embedded_default().expect("robot");
    let mut layers = Config::layers_for(&robot).expect("layers");
    layers.push_override("robot.gravity=1.62").expect("set");
    let moon = layers.build().expect("config");
    assert_eq!(earth.robot.gravity, 9.81, "config/default.toml's gravity");
    let torque = |config: &Config| {
        let mut r = rig(config, ControllerKind::C1);
        assert_eq!(r.core.model.gravity.z, -config.robot.gravity);
        r.tick(None).expect("tick");
        r.tau.iter().map(|t| t * t).sum::<f64>().sqrt()
    };
    let ratio = torque(&moon) / torque(&earth);
    assert!(
        (ratio - 1.62 / 9.81).abs() < 0.05,
        "torque ratio {ratio}, gravity ratio {}",
        1.62 / 9.81
    );
}

/// The commanded CoM acceleration along x after 20 ticks on a frozen state, with a −60 N push
/// along x forecast from now.
fn lean_into_push(robot: &Robot, config: &Config, kind: ControllerKind) -> f64 {
    let mut r = rig_of(robot, config, kind);
    r.offer_push(-60.0);
    assert_eq!(r.tick_frozen(0..20), 0, "a tick failed");
    r.core.last.com_acc_cmd[0]
}

/// The reduced model's mass has one home, the robot's (computed from its model): the preview's
/// cart-table reads it as C2's search does. A robot whose mass is found twice as large leans
/// half as far into the same forecast push (the equivalent CoM offset is z_c F / (M g)),
/// measured against C0, which ignores it. No config key can set it apart.
#[test]
fn robot_mass_is_the_preview_s() {
    let normal = Robot::embedded_default().expect("robot");
    let mut heavy = normal.clone();
    heavy.derived.mass *= 2.0;
    let config = Config::embedded_default().expect("defaults");
    let lean = |r: &Robot, kind| lean_into_push(r, &config, kind);
    let lean_normal = lean(&normal, ControllerKind::C1) - lean(&normal, ControllerKind::C0);
    let lean_heavy = lean(&heavy, ControllerKind::C1) - lean(&heavy, ControllerKind::C0);
    let ratio = lean_heavy / lean_normal;
    assert!(
        lean_normal > 0.1 && (ratio - 0.5).abs() < 0.1,
        "lean {lean_normal} m/s² at the model's mass, {lean_heavy} at twice it: ratio {ratio}"
    );
}

#[test]
fn c1_leans_into_a_forecast_push_and_c0_does_not() {
    // Over 20 ticks on a frozen state, C1's commanded CoM acceleration turns toward the push
    // (+x against a −x force) well beyond what C0 commands to centre the CoM on the feet.
    let config = Config::embedded_default().expect("defaults");
    let robot = Robot::embedded_default().expect("robot");
    let acc = [ControllerKind::C0, ControllerKind::C1].map(|k| lean_into_push(&robot, &config, k));
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
    let mut r = rig(&config, ControllerKind::C1);
    r.state.v[7] = f64::NAN;
    assert!(r.tick(None).is_err());
    r.state.v[7] = 0.0;
    r.state.nq = 12;
    let e = r.tick(None).unwrap_err().to_string();
    assert!(e.contains("nq = 12"), "{e}");
}

/// A new plant session from another posture: after `reset`, the core latches the new posture
/// (the whole-body QP's posture and base-orientation references included) and computes what a
/// fresh core given that posture computes.
#[test]
fn reset_latches_the_posture_of_a_new_session() {
    let config = Config::embedded_default().expect("defaults");
    let mut a = rig(&config, ControllerKind::C1);
    for k in 0..5 {
        a.state.time = k as f64 * 0.001;
        a.tick(None).expect("first session");
    }
    // The second session: base turned by 0.3 rad about z, torso and arms moved.
    let mut second = a.state;
    let (s, c) = (0.15f64.sin(), 0.15f64.cos());
    second.q[3..7].copy_from_slice(&[0.0, 0.0, s, c]);
    for j in &a.core.model.joints[1..] {
        let leg = ["hip", "knee", "ankle"].iter().any(|n| j.name.contains(n));
        if !leg {
            second.q[j.idx_q] += 0.2;
        }
    }
    a.core.reset();
    let mut fresh = rig(&config, ControllerKind::C1);
    fresh.state = second;
    a.state = second;
    for k in 0..3 {
        a.state.time = k as f64 * 0.001;
        fresh.state.time = a.state.time;
        let sa = a.tick(None);
        let sf = fresh.tick(None);
        assert_eq!(sa.expect("reset core"), sf.expect("fresh core"));
        let d = a
            .tau
            .iter()
            .zip(&fresh.tau)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(
            d < 1e-9,
            "tick {k}: torques differ by {d} N·m from a fresh core's"
        );
    }
}

/// A state announcing more values than a message holds (a foreign plant, a model larger than
/// the channels) is an error value, never an out-of-bounds slice.
#[test]
fn a_state_larger_than_a_message_is_an_error() {
    use upc::channels::{MAX_DOF, StateMsg};
    let robot = larger_than_a_message();
    let (nq, nv) = (robot.model.nq, robot.model.nv);
    assert!(nq > MAX_DOF && nv > MAX_DOF);
    let mut core = upc::control::ControllerCore::new(
        &robot,
        &Config::embedded_default().expect("defaults"),
        ControllerKind::C0,
        0.001,
        [100.0, 20.0],
        [0.0, 0.0],
    )
    .expect("core");
    let state = StateMsg {
        nq: nq as u32,
        nv: nv as u32,
        ..Default::default()
    };
    // Read at the process's edge as the loop reads it: refused, never sliced beyond the message.
    let mut sensed = upc::robot::RobotState::new(nq, nv);
    let e = upc::control::contract::read_state(&state, 0, &mut sensed)
        .expect_err("a state beyond the message's capacity")
        .to_string();
    assert!(e.contains(&format!("nq = {nq}")), "{e}");
    // And a robot state of other sizes than the model's is the tick's error value.
    let window = upc::control::ForecastWindow::new(1.0, 1.0, 0.2, 300.0);
    let mut tau = vec![0.0; nv - 6];
    let small = upc::robot::RobotState::new(nq - 1, nv);
    let e = core
        .tick(&small, &window, None, &mut tau)
        .expect_err("a state of other sizes")
        .to_string();
    assert!(e.contains(&format!("nq = {}", nq - 1)), "{e}");
}

/// The humanoid with a chain of extra joints on its last body: nv = MAX_DOF + 12 (more than a
/// state or torque message holds).
fn larger_than_a_message() -> Robot {
    use upc::dynamics::{Inertia, JointKind, SE3};
    let mut robot = Robot::embedded_default().expect("robot");
    let model = &mut robot.model;
    let mut parent = model.joints.len() - 1;
    let extra = upc::channels::MAX_DOF + 12 - model.nv;
    for i in 0..extra {
        parent = model
            .add_joint(
                format!("extra_{i}"),
                Some(parent),
                SE3::identity(),
                JointKind::Revolute {
                    axis: nalgebra::Vector3::z(),
                },
                Inertia::from_com(
                    0.01,
                    nalgebra::Vector3::zeros(),
                    nalgebra::Matrix3::identity() * 1e-4,
                ),
                format!("extra_body_{i}"),
            )
            .expect("extra joint");
    }
    robot
}

/// The server refuses such a model before its loop (which slices its MAX_DOF buffers by the
/// model's sizes) rather than panicking at the first state.
#[test]
fn the_server_refuses_a_model_larger_than_a_message() {
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    use upc::control::server::{ServerOptions, run_server};
    let opts = ServerOptions {
        prefix: format!("upc_test_big_model_{}", std::process::id()),
        duration: Some(0.1),
        rrd: None,
        recording_id: "big".into(),
        live: None,
        zmp_offset: [0.0, 0.0],
        startup_timeout: 0.5,
        csv: None,
        scenario_hash: None,
        robot_hash: None,
        robot_name: "big".into(),
        held_mass: nalgebra::Matrix3::zeros(),
    };
    let config = Config::embedded_default().expect("defaults");
    let e = run_server(
        &config,
        &larger_than_a_message(),
        &opts,
        Arc::new(AtomicBool::new(false)),
    )
    .expect_err("a model beyond the channels' capacity")
    .to_string();
    assert!(
        e.contains(&format!("at most {}", upc::channels::MAX_DOF)) && e.contains("locked"),
        "{e}"
    );
}

#[test]
fn c2_thread_hands_over_time_stamped_schedules_without_blocking() {
    let mut config = Config::embedded_default().expect("defaults");
    config.preview.horizon = 200;
    let n = config.preview.horizon;
    let mut r = rig(&config, ControllerKind::C2);
    r.offer_push(-50.0);
    r.tick(None).expect("tick");
    let robot = Robot::embedded_default().expect("robot").reduced();
    let mut handoff = GainHandoff::spawn(&config, &robot).expect("thread");
    assert_eq!(
        handoff.latest().seq,
        0,
        "no schedule before the first snapshot"
    );
    // What offering and reading cost the loop is a criterion bench (`cargo bench --bench
    // control`: `c2_handoff_offer`, `c2_handoff_latest`), not a timed assertion.
    handoff.offer(|s| r.core.snapshot(s, 7));
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
    r.tick(Some(&s)).expect("tick");
    assert!((r.core.last.kp - s.schedule.kp[0]).abs() < 1e-9);
}

/// A fallen robot (its CoM sunk by more than `controller.fall_drop` of its height) gets joint
/// damping without preview or QP, counted, until the plant restarts: a fallen robot's QP is
/// mostly infeasible and costly, and its controller must not starve the machine.
#[test]
fn a_fallen_robot_is_held_in_joint_damping_until_the_plant_restarts() {
    use upc::wbc::{FallbackReason, WbcStatus};
    let config = Config::embedded_default().expect("defaults");
    let mut r = rig(&config, ControllerKind::C1);
    let standing = r.state.q[2];
    let status = r.tick(None);
    assert_eq!(status.expect("tick"), WbcStatus::Solved);
    let solves = r.core.wbc_counters().ticks;
    // Sunk by 40 % of the CoM height (the threshold is 25 %), moving.
    let height = r.core.last.com[2];
    r.state.q[2] = standing - 0.4 * height;
    r.state.time = 0.001;
    for (i, v) in r.state.v.iter_mut().enumerate().take(r.tau.len() + 6) {
        *v = 0.1 * (i as f64).sin();
    }
    let damping = config.wbc.fallback_damping;
    for k in 0..3 {
        // Back at the standing height from the second tick: still fallen (latched).
        if k == 1 {
            r.state.q[2] = standing;
        }
        let status = r.tick(None);
        assert_eq!(
            status.expect("tick"),
            WbcStatus::Fallback(FallbackReason::Fallen)
        );
        for (i, t) in r.tau.iter().enumerate() {
            assert_eq!(*t, -damping * r.state.v[6 + i], "joint {i}");
        }
        assert!(r.core.last.fallen);
    }
    assert_eq!((r.core.info().falls, r.core.info().fallen_ticks), (1, 3));
    assert_eq!(r.core.wbc_counters().ticks, solves, "no QP while fallen");
    // A plant restart (a new session) stands it up again: balance control resumes.
    r.core.reset();
    r.state.v.iter_mut().for_each(|v| *v = 0.0);
    let status = r.tick(None);
    assert_eq!(status.expect("tick"), WbcStatus::Solved);
    assert_eq!(r.core.info().falls, 1);
}

/// `controller.fall_drop = 0` turns the detector off: the same sunk state runs the QP.
#[test]
fn the_fall_detector_can_be_turned_off() {
    let mut config = Config::embedded_default().expect("defaults");
    config.controller.fall_drop = 0.0;
    let mut r = rig(&config, ControllerKind::C1);
    r.tick(None).expect("tick");
    r.state.q[2] -= 0.4 * r.core.last.com[2];
    r.tick(None).expect("tick");
    assert_eq!(r.core.info().falls, 0);
    assert!(!r.core.last.fallen);
}

/// Feet that creep (MuJoCo's soft friction moves them a fraction of a millimetre a push) take
/// the support and the ZMP reference with them through `controller.support_follow`'s low-pass;
/// with it at 0 both stay where the first tick latched them.
#[test]
fn the_support_and_the_zmp_reference_follow_feet_that_creep() {
    let shift = 0.02; // the whole robot slid 20 mm sideways, feet included
    for follow in [0.0, 0.02] {
        let mut config = Config::embedded_default().expect("defaults");
        config.controller.support_follow = follow;
        let mut r = rig(&config, ControllerKind::C1);
        r.tick(None).expect("first tick");
        let (ref0, sup0) = (r.core.last.zmp_ref, r.core.support().expect("latched"));
        r.state.q[1] += shift;
        // Five time constants of the low-pass: 1 − e⁻⁵ of the shift.
        for k in 1..=100 {
            r.state.time = k as f64 * 0.001;
            r.tick(None).expect("tick");
        }
        let moved = r.core.last.zmp_ref[1] - ref0[1];
        let sup = r.core.support().expect("support");
        let expect = if follow > 0.0 {
            shift * (1.0 - (-5.0f64).exp())
        } else {
            0.0
        };
        assert!(
            (moved - expect).abs() < 2e-4,
            "follow {follow} s: the ZMP reference moved {moved} m, expected {expect}"
        );
        for b in 0..2 {
            let d = sup[1][b] - sup0[1][b];
            assert!(
                (d - expect).abs() < 2e-4,
                "follow {follow} s: the support's y bound {b} moved {d} m, expected {expect}"
            );
            assert!((sup[0][b] - sup0[0][b]).abs() < 1e-9, "x bounds stay");
        }
    }
}
