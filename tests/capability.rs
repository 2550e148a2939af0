//! Balance capability (`upc capability`): the bisection on the reduced models against the
//! reduced loop itself, and the command end to end on the full simulation, where C1's
//! forecast must let the robot take a larger push than C0, along x (through the door) and y
//! (at the hand).

mod support;

use support::procs::*;
use upc::capability::{Direction, Variant, bisect, survives_reduced};
use upc::config::Config;

/// On the reduced models the bracket is tight and true: the amplitude found is survived, the
/// one above it is not, and C1 takes a push several times larger than C0 (its forecast cancels
/// what C0 only reacts to).
#[test]
fn reduced_capability_brackets_the_threshold_and_c1_exceeds_c0() {
    let config = Config::embedded_default().expect("config");
    let robot = upc::robot::Robot::embedded_default()
        .expect("robot")
        .reduced();
    let cap = |v: Variant| {
        bisect(300.0, 1.0, |a| {
            survives_reduced(&config, robot, v, a, 0.3, Direction::X)
        })
        .expect("run")
    };
    let c0 = cap(Variant::C0);
    let failed = c0.failed.expect("C0 falls below 300 N");
    assert!(survives_reduced(&config, robot, Variant::C0, c0.survived, 0.3, Direction::X).unwrap());
    assert!(!survives_reduced(&config, robot, Variant::C0, failed, 0.3, Direction::X).unwrap());
    assert!(failed - c0.survived <= 1.0);
    let c1 = cap(Variant::C1);
    assert!(c1.survived > 3.0 * c0.survived, "C0 {c0:?}, C1 {c1:?}");
}

/// `--monotone`: on the reduced models the ZMP's excursion is linear in the amplitude, so
/// survival is monotone and the grid below each bisection must confirm it, point for point.
#[test]
fn the_monotone_check_confirms_a_monotone_search() {
    let s = Scratch::new("capability_monotone");
    let out = s.dir.to_str().expect("utf-8");
    upc_ok([
        "capability",
        "--models",
        "reduced",
        "--controllers",
        "c0,c1",
        "--durations",
        "0.3",
        "--directions",
        "x",
        "--tol",
        "1",
        "--monotone",
        "5",
        "--quiet",
        "--out",
        out,
    ]);
    let j = json(&s.path("capability.json"));
    let rows = j["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);
    for r in rows {
        let survived = r["survived"].as_f64().expect("survived");
        let monotone = r["monotone"].as_f64().expect("monotone");
        assert!(survived > 10.0, "{r}");
        assert_eq!(monotone, survived, "{r}");
        // The bisection's cases (at least one) plus one per grid point below the result.
        let grid = (survived / 5.0).ceil() as u64 - 1;
        assert!(r["runs"].as_u64().expect("runs") > grid, "{r}");
    }
    let csv = std::fs::read_to_string(s.path("capability.csv")).expect("csv");
    assert!(
        csv.lines().next().unwrap_or("").ends_with(",monotone"),
        "{csv}"
    );
}

#[test]
fn full_simulation_capability_of_c1_exceeds_c0() {
    let _one = serial();
    let s = Scratch::new("capability");
    let out = s.dir.to_str().expect("utf-8");
    upc_ok([
        "capability",
        "--models",
        "full",
        "--controllers",
        "c0,c1",
        "--durations",
        "0.3",
        "--directions",
        "x,y",
        "--max",
        "160",
        "--tol",
        "10",
        "--quiet",
        "--out",
        out,
    ]);
    let j = json(&s.path("capability.json"));
    let rows = j["rows"].as_array().expect("rows");
    let survived = |c: &str, d: &str| {
        rows.iter()
            .find(|r| r["controller"] == c && r["direction"] == d)
            .and_then(|r| r["survived"].as_f64())
            .unwrap_or_else(|| panic!("no {c} along {d} in {j}"))
    };
    // Along x through the door; along y at the hand (`sim.push = "hand"`).
    for d in ["x", "y"] {
        assert!(survived("C1", d) > survived("C0", d) + 10.0, "{d}: {j}");
    }
    assert!(s.path("capability.md").exists() && s.path("capability.csv").exists());
    assert!(s.path("figures/capability_full_x.svg").exists());
    assert!(s.path("figures/capability_full_y.svg").exists());
}
