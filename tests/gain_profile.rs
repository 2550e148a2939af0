//! Why C2's K_p follows the force instead of the paper's stiff/soft/stiff/soft
//! (docs/results/gain_profile.md; the problem: docs/gain_search.md, eq. (26)): on the reduced
//! models, the hand-tracking term of eq. (26) asks for stiffness where the force is large, the ZMP
//! term for softness while a fast impact lasts (the hand's impedance then low-passes the
//! disturbance the CoM must take). Each weighting alone shows its own pull on a 0.1 s, 250 N
//! impact.

use upc::capability::{Direction, impact_scenario};
use upc::config::{Config, ControllerKind};
use upc::offline::ReducedLoop;

/// Mean K_p of C2 over the impact (its 0.1 s) and the half second before it.
fn kp_during_and_before(config: &Config) -> (f64, f64) {
    let scenario = impact_scenario(250.0, 0.1, Direction::X);
    let robot = upc::robot::Robot::embedded_default()
        .expect("robot")
        .reduced();
    let run = ReducedLoop::new(config, robot, &scenario, ControllerKind::C2)
        .run()
        .expect("reduced loop");
    let mean = |a: f64, b: f64| {
        let v: Vec<f64> = run
            .rows
            .iter()
            .filter(|r| r.t >= a && r.t < b)
            .map(|r| r.kp)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    (mean(1.0, 1.1), mean(0.5, 0.95))
}

#[test]
fn the_hand_term_stiffens_with_the_force_the_zmp_term_softens_a_fast_impact() {
    let config = Config::embedded_default().expect("config");
    let [lo, hi] = config.gain_search.kp_bounds;
    let (during, before) = kp_during_and_before(&config);
    assert!(
        during > lo + 0.7 * (hi - lo),
        "default weights: K_p {during} during the impact"
    );
    assert!(
        before < lo + 0.1 * (hi - lo),
        "default weights: K_p {before} before it"
    );

    let mut zmp_only = config.clone();
    zmp_only.gain_search.q_t = [0.0; 3];
    zmp_only.gain_search.s = 0.0;
    let (during, _) = kp_during_and_before(&zmp_only);
    assert!(
        during < lo + 0.05 * (hi - lo),
        "ZMP term alone: K_p {during} during the impact"
    );
}
