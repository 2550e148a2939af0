//! A lockstep controller in the test process: answers every state of a plant with posture-PD
//! torques (optionally a few malformed commands first), for the plant tests of both simulators.

use std::time::Duration;

use nalgebra::DVector;
use upc::channels::{ContractNode, ServiceKind, StateMsg, TorqueMsg};
use upc::sim::PosturePd;

/// Drives the plant on `prefix` until its state `steps` (or until `done()`); returns the last
/// state received. `inject_bad`: at step 5 a command of the wrong length and one with a NaN, at
/// step 7 one whose seq does not increase (each to be rejected, one of each), and the answer to
/// step 9 sent twice (the second valid but stale, never applied).
pub fn drive(
    prefix: &str,
    tag: &str,
    steps: u64,
    inject_bad: bool,
    done: impl Fn() -> bool,
) -> StateMsg {
    let node = ContractNode::open(prefix, &format!("ctrl_{tag}")).unwrap();
    let states = node.subscriber::<StateMsg>().unwrap();
    let torques = node.publisher::<TorqueMsg>().unwrap();
    let wake_sim = node.notifier(ServiceKind::Torques).unwrap();
    let wake_me = node.listener(ServiceKind::State).unwrap();

    let robot = upc::robot::Robot::embedded_default().expect("robot");
    let (model, q_home) = (&robot.model, &robot.home);
    let pd = PosturePd::standing(model, q_home, &robot.carrying_frames()).unwrap();
    let n = model.nv - 6;
    let mut tau = DVector::zeros(n);
    let mut seq = 0u64;
    let mut last = StateMsg::default();
    let send = |seq: u64, st: &StateMsg, n: u32, tau: &[f64]| {
        torques
            .send_with(|m| {
                m.seq = seq;
                m.state_step = st.step;
                m.session = st.session;
                m.n = n;
                m.tau[..tau.len()].copy_from_slice(tau);
            })
            .unwrap();
        wake_sim.notify().unwrap();
    };
    'outer: loop {
        wake_me.wait(Duration::from_millis(100)).unwrap();
        while let Some(s) = states.receive().unwrap() {
            // A state sent again (the plant's wait timed out on a loaded machine) is answered
            // once, as the controller does.
            let repeated = seq > 0 && s.step == last.step && s.session == last.session;
            last = s;
            if s.step >= steps {
                break 'outer;
            }
            if repeated {
                continue;
            }
            let q = DVector::from_column_slice(&s.q[..s.nq as usize]);
            let v = DVector::from_column_slice(&s.v[..s.nv as usize]);
            pd.torques(&q, &v, &mut tau);
            if inject_bad && s.step == 5 {
                send(seq + 1, &s, n as u32 - 1, tau.as_slice()); // wrong length
                let mut nan = tau.clone();
                nan[3] = f64::NAN;
                send(seq + 1, &s, n as u32, nan.as_slice()); // NaN
            }
            if inject_bad && s.step == 7 {
                send(seq, &s, n as u32, tau.as_slice()); // seq not increasing
            }
            seq += 1;
            send(seq, &s, n as u32, tau.as_slice());
            if inject_bad && s.step == 9 {
                // Answered again, as a controller re-answers a state after a stopped plant:
                // valid, but stale when it arrives (the plant has stepped on).
                seq += 1;
                send(seq, &s, n as u32, tau.as_slice());
            }
        }
        if done() {
            break;
        }
    }
    last
}

/// The bits of a state's physics (q, v, contact forces, hand force): equal bits, equal runs.
pub fn state_bits(s: &StateMsg) -> Vec<u64> {
    s.q.iter()
        .chain(s.v.iter())
        .chain(s.contact_forces.iter().flatten())
        .chain(s.hand_force.iter())
        .map(|x| x.to_bits())
        .collect()
}
