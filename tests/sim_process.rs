//! The simulator process over iceoryx2: a lockstep controller in the test answers every state
//! with posture-PD torques; malformed commands are rejected and counted; reruns are
//! bit-identical. Also the pure validation of torque commands.

mod support;

use std::sync::atomic::AtomicBool;

use support::pd_driver::{drive, state_bits};
use upc::channels::{MAX_DOF, StateMsg};
use upc::plant::{CommandGate, CommandOrigin, Rejection, validate_command};
use upc::sim::SimConfig;
use upc::sim::process::{RunOptions, RunSummary, run};

#[test]
fn commands_with_wrong_length_nan_or_old_seq_are_rejected() {
    let tau = [0.0; MAX_DOF];
    assert_eq!(validate_command(None, 0, 32, &tau, 32), Ok(()));
    assert_eq!(
        validate_command(None, 0, 31, &tau, 32),
        Err(Rejection::WrongLength {
            expected: 32,
            got: 31
        })
    );
    // More torques than a message carries.
    let over = MAX_DOF as u32 + 12;
    assert!(matches!(
        validate_command(None, 0, over, &tau, over as usize),
        Err(Rejection::WrongLength { .. })
    ));
    let mut bad = tau;
    bad[7] = f64::NAN;
    assert_eq!(
        validate_command(None, 0, 32, &bad, 32),
        Err(Rejection::NonFinite { index: 7 })
    );
    bad[7] = f64::NEG_INFINITY;
    assert!(validate_command(None, 0, 32, &bad, 32).is_err());
    // Beyond n, garbage is ignored.
    bad[7] = 0.0;
    bad[40] = f64::NAN;
    assert_eq!(validate_command(None, 0, 32, &bad, 32), Ok(()));
    assert_eq!(
        validate_command(Some(5), 5, 32, &tau, 32),
        Err(Rejection::OutOfOrder { seq: 5, last: 5 })
    );
    assert!(validate_command(Some(5), 4, 32, &tau, 32).is_err());
    assert_eq!(validate_command(Some(5), 9, 32, &tau, 32), Ok(()));

    let mut gate = CommandGate::for_session(77);
    let me = CommandOrigin {
        session: 77,
        controller: 5,
    };
    assert!(gate.check(me, 1, 32, &tau, 32).is_ok());
    assert!(gate.check(me, 2, 30, &tau, 32).is_err());
    assert!(gate.check(me, 1, 32, &tau, 32).is_err());
    assert!(gate.check(me, 2, 32, &bad[..32], 32).is_ok());
    // Torques computed from another plant run's states: never applied, whatever their seq.
    let stale_run = CommandOrigin {
        session: 76,
        controller: 5,
    };
    assert_eq!(
        gate.check(stale_run, 3, 32, &tau, 32),
        Err(Rejection::ForeignSession {
            expected: 77,
            got: 76
        })
    );
    assert_eq!(gate.stats.accepted, 2);
    assert_eq!(gate.stats.wrong_length, 1);
    assert_eq!(gate.stats.out_of_order, 1);
    assert_eq!(gate.stats.foreign, 1);
    assert_eq!(gate.stats.rejected(), 3);
    assert_eq!(gate.last_seq, Some(2));
    // A restarted controller (another id) starts its seq over; its old seq does not come back.
    let next = CommandOrigin {
        session: 77,
        controller: 6,
    };
    assert!(gate.check(next, 1, 32, &tau, 32).is_ok());
    assert_eq!(gate.stats.controller_changes, 1);
    assert!(gate.check(next, 1, 32, &tau, 32).is_err());
    assert!(
        gate.check(me, 3, 32, &tau, 32).is_ok(),
        "the first controller's own seq"
    );
}

/// Runs the simulator in a thread and a PD controller here; returns the sim's summary and the
/// last state received.
fn lockstep_run(tag: &str, steps: u64, inject_bad: bool) -> (RunSummary, StateMsg) {
    let prefix = format!("upc_simtest_{}_{tag}", std::process::id());
    let mut config = SimConfig::load(&[], &["sim.mode=\"lockstep\"".into()]).unwrap();
    config.duration = steps as f64 * config.dt;
    config.process.prefix = prefix.clone();
    config.process.first_command_timeout = 20.0;
    config.process.lockstep_timeout = 20.0;
    let opts = RunOptions {
        config,
        robot: std::sync::Arc::new(upc::robot::Robot::embedded_default().unwrap()),
        rrd: None,
        recording_id: None,
        live: None,
        node_name: format!("sim_{tag}"),
        truth_csv: None,
        engine: Default::default(),
    };

    let sim = std::thread::spawn(move || {
        let stop = AtomicBool::new(false);
        run(&opts, &stop)
    });
    let last = drive(&prefix, tag, steps, inject_bad, || sim.is_finished());
    let summary = sim.join().unwrap().unwrap();
    assert_eq!(summary.error, None);
    (summary, last)
}

#[test]
fn lockstep_over_iceoryx2_rejects_bad_commands_and_reruns_identically() {
    let (a, sa) = lockstep_run("a", 300, true);
    assert_eq!(a.steps, 300);
    assert_eq!(a.commands.wrong_length, 1, "{a:?}");
    assert_eq!(a.commands.non_finite, 1, "{a:?}");
    assert_eq!(a.commands.out_of_order, 1, "{a:?}");
    // Accepted means applied: the second answer to step 9 is stale, whenever it arrives.
    assert_eq!(a.commands.accepted, 300, "{a:?}");
    assert_eq!(a.commands.stale, 1, "{a:?}");
    assert!(a.max_loop_error < 1e-3 && a.max_penetration < 1e-3, "{a:?}");
    let (b, sb) = lockstep_run("b", 300, false);
    assert_eq!(b.commands.rejected(), 0);
    assert_eq!(sa.step, 300);
    assert_eq!(state_bits(&sa), state_bits(&sb), "lockstep reruns differ");
}

/// A participant built with another contract (here: a state of the old 48-value layout under
/// the same type name) is refused when it meets this one on a service, with what to change.
#[test]
fn a_participant_with_another_contract_layout_is_refused_with_what_to_change() {
    use iceoryx2::prelude::*;
    #[repr(C)]
    #[derive(Debug, Clone, Copy, ZeroCopySend)]
    #[type_name("upc::StateMsg")]
    struct OldStateMsg {
        step: u64,
        q: [f64; 48],
    }
    let prefix = format!("upc_test_layout_{}", std::process::id());
    let node = NodeBuilder::new().create::<ipc::Service>().expect("node");
    let name: ServiceName = format!("{prefix}/state").as_str().try_into().expect("name");
    let _old = node
        .service_builder(&name)
        .publish_subscribe::<OldStateMsg>()
        .create()
        .expect("the old participant's service");
    let node =
        upc::channels::ContractNode::open(&prefix, "new_participant").expect("contract node");
    let e = match node.subscriber::<StateMsg>() {
        Ok(_) => panic!("a service of another layout was opened"),
        Err(e) => e,
    };
    // Typed: a program can tell this failure from the others.
    assert!(
        matches!(&e, upc::channels::ChannelError::IncompatibleLayout { payload, .. } if *payload == "StateMsg"),
        "{e:?}"
    );
    let e = e.to_string();
    assert!(
        e.contains("another layout")
            && e.contains(&format!("MAX_DOF = {MAX_DOF}"))
            && e.contains("same upc version"),
        "{e}"
    );
}
