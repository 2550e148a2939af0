//! Balance capability: the largest single impact on the hand a controller survives, found by
//! bisection over the impact's amplitude, for a given impact duration and direction.
//!
//! The impact is one raised-cosine pulse (rise and fall of half the duration each, no plateau)
//! starting at [`IMPACT_START`], followed by [`RECOVERY`] seconds to come back. A case is
//! survived when, on the reduced models, the ZMP never leaves the support (the linear cart-table
//! has no tipping to recover from: a ZMP outside is a fall); on the full simulation, when the
//! robot is standing at the end (CoM height drop under `max_com_drop`), the CoP spent at most
//! `max_edge_time` on the support edge (a foot tipping and landing back), and the whole-body QP
//! never fell back. Survival is assumed monotone in the amplitude (a harder push is never
//! easier), which bisection needs.

use crate::config::{Config, ControllerKind};
use crate::offline::ReducedLoop;
use crate::preview::PreviewError;
use crate::robot::ReducedModel;
use crate::scenario::{ForceProfile, Impact, Scenario};

/// Time of the impact's start (s): the controller has settled by then.
pub const IMPACT_START: f64 = 1.0;
/// Simulated time after the impact's end (s).
pub const RECOVERY: f64 = 2.0;

/// The controllers compared (on the command line by [`Variant::parse`]'s names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    C0,
    C1,
    C2,
    /// C1 with the predicted ZMP kept inside the support by hard constraints
    /// (`preview.zmp_constraints`).
    #[value(name = "c1zmp")]
    C1Zmp,
    /// C0 with the CoM disturbance observer (`controller.com_observer`): the baseline of a robot
    /// without any forecast.
    #[value(name = "c0obs")]
    C0Obs,
    /// C1 previewing the forecast as received: without the correction by the measured hand
    /// force (`controller.forecast_correction.enabled = false`) nor taking it along the held
    /// door's path (`controller.forecast_on_free_direction = false`).
    #[value(name = "c1raw")]
    C1Raw,
}

impl Variant {
    pub const ALL: [Variant; 6] = [
        Variant::C0,
        Variant::C1,
        Variant::C2,
        Variant::C1Zmp,
        Variant::C0Obs,
        Variant::C1Raw,
    ];

    pub fn kind(self) -> ControllerKind {
        match self {
            Variant::C0 | Variant::C0Obs => ControllerKind::C0,
            Variant::C1 | Variant::C1Zmp | Variant::C1Raw => ControllerKind::C1,
            Variant::C2 => ControllerKind::C2,
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Variant::C0 => "C0",
            Variant::C1 => "C1",
            Variant::C2 => "C2",
            Variant::C1Zmp => "C1+ZMP",
            Variant::C0Obs => "C0+obs",
            Variant::C1Raw => "C1 raw",
        }
    }

    /// The config overrides this variant needs besides its controller kind.
    pub fn config_set(self) -> &'static [&'static str] {
        match self {
            Variant::C1Zmp => &["preview.zmp_constraints=true"],
            Variant::C0Obs => &["controller.com_observer.enabled=true"],
            Variant::C1Raw => &[
                "controller.forecast_correction.enabled=false",
                "controller.forecast_on_free_direction=false",
            ],
            Variant::C0 | Variant::C1 | Variant::C2 => &[],
        }
    }

    /// Whether the variant reads the forecast at all (C0's preview ignores it).
    pub fn uses_forecast(self) -> bool {
        !matches!(self, Variant::C0 | Variant::C0Obs)
    }

    pub fn parse(s: &str) -> Option<Variant> {
        match s.to_ascii_lowercase().as_str() {
            "c0" => Some(Variant::C0),
            "c1" => Some(Variant::C1),
            "c2" => Some(Variant::C2),
            "c1zmp" | "c1+zmp" | "c1_zmp" => Some(Variant::C1Zmp),
            "c0obs" | "c0+obs" | "c0_obs" => Some(Variant::C0Obs),
            "c1raw" | "c1_raw" => Some(Variant::C1Raw),
            _ => None,
        }
    }
}

/// Direction of the push on the hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Toward the robot (−x), as the door pushes in the paper's scenarios.
    X,
    /// To the robot's left (+y).
    Y,
}

impl Direction {
    pub fn unit(self) -> [f64; 3] {
        match self {
            Direction::X => [-1.0, 0.0, 0.0],
            Direction::Y => [0.0, 1.0, 0.0],
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Direction::X => "x",
            Direction::Y => "y",
        }
    }
}

/// One impact of `amplitude` N lasting `duration` s along `direction`, then recovery.
pub fn impact_scenario(amplitude: f64, duration: f64, direction: Direction) -> Scenario {
    let force = direction.unit().map(|u| u * amplitude);
    Scenario {
        name: format!(
            "impact_{}_{:.0}ms_{amplitude:.1}N",
            direction.label(),
            duration * 1e3
        ),
        description: format!(
            "One {amplitude:.1} N impact along {}, {duration} s long",
            direction.label()
        ),
        duration: IMPACT_START + duration + RECOVERY,
        zmp_reference: [0.0, 0.0],
        force: ForceProfile::Impacts(vec![Impact {
            start: IMPACT_START,
            rise: 0.5 * duration,
            hold: 0.0,
            fall: 0.5 * duration,
            force,
        }]),
        config: None,
        origin: "<capability impact>".into(),
        force_scale: 1.0,
    }
}

/// The same impact as a scenario file, for processes (`upc run --scenario path`).
pub fn impact_toml(amplitude: f64, duration: f64, direction: Direction) -> String {
    let s = impact_scenario(amplitude, duration, direction);
    let f = direction.unit().map(|u| u * amplitude);
    format!(
        "name = \"{}\"\ndescription = \"{}\"\nduration = {:?}\nzmp_reference = [0.0, 0.0]\n\n[force]\nkind = \"impacts\"\n\n[[force.impacts]]\nstart = {IMPACT_START:?}\nrise = {:?}\nhold = 0.0\nfall = {:?}\nforce = [{:?}, {:?}, {:?}]\n",
        s.name,
        s.description,
        s.duration,
        0.5 * duration,
        0.5 * duration,
        f[0],
        f[1],
        f[2]
    )
}

/// What counts as surviving an impact.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Criteria {
    /// Longest time (s) the CoP may spend on the support edge (full simulation).
    pub max_edge_time: f64,
    /// Largest CoM height drop (m) of a robot still standing (full simulation).
    pub max_com_drop: f64,
}

impl Default for Criteria {
    fn default() -> Self {
        Self {
            max_edge_time: 0.25,
            max_com_drop: 0.05,
        }
    }
}

/// The result of one bisection.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Capability {
    /// Largest amplitude survived (N); 0 if not even the smallest tried.
    pub survived: f64,
    /// Smallest amplitude failed (N); `None` if the search's upper bound was survived.
    pub failed: Option<f64>,
    /// Cases run.
    pub runs: usize,
    /// With a monotone check ([`monotone_below`]): the largest amplitude of its grid below which
    /// every grid point was survived. Below `survived` where survival has a pocket.
    pub monotone: Option<f64>,
}

impl Capability {
    /// The figure as the reports print it: "≥ 300" when the search's bound was survived,
    /// "138 (monotone 130)" when the monotone check found a fall below the bisection's result.
    pub fn text(&self) -> String {
        let at_least = if self.failed.is_none() { "≥ " } else { "" };
        match self.monotone {
            Some(m) if m < self.survived => {
                format!("{at_least}{:.0} (monotone {m:.0})", self.survived)
            }
            _ => format!("{at_least}{:.0}", self.survived),
        }
    }
}

/// Bisection over the amplitude in `[0, max]` down to `tol` N. `survives(a)` runs a case.
pub fn bisect<E>(
    max: f64,
    tol: f64,
    mut survives: impl FnMut(f64) -> Result<bool, E>,
) -> Result<Capability, E> {
    let mut runs = 1;
    if survives(max)? {
        return Ok(Capability {
            survived: max,
            failed: None,
            runs,
            monotone: None,
        });
    }
    let (mut lo, mut hi) = (0.0, max);
    while hi - lo > tol {
        let mid = 0.5 * (lo + hi);
        runs += 1;
        if survives(mid)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(Capability {
        survived: lo,
        failed: Some(hi),
        runs,
        monotone: None,
    })
}

/// [`bisect`], then with `monotone = Some(step)` the [`monotone_below`] check up to its result
/// (its cases added to the count).
pub fn search<E>(
    max: f64,
    tol: f64,
    monotone: Option<f64>,
    mut survives: impl FnMut(f64) -> Result<bool, E>,
) -> Result<Capability, E> {
    let mut c = bisect(max, tol, &mut survives)?;
    if let Some(step) = monotone {
        let (m, runs) = monotone_below(c.survived, step, &mut survives)?;
        c.monotone = Some(m);
        c.runs += runs;
    }
    Ok(c)
}

/// Survival need not be monotone in the amplitude: near the limit a push can stand where a
/// weaker one fell (a pocket: the fall depends on where the push catches the robot's own
/// sway), and a bisection that lands in a pocket reads it as the capability. This scans
/// `step`, 2 `step`, … up to `upto` (a bisection's result, itself survived) and stops at the
/// first failure. Returns the last amplitude survived before it (`upto` when none failed) and
/// the cases run.
pub fn monotone_below<E>(
    upto: f64,
    step: f64,
    mut survives: impl FnMut(f64) -> Result<bool, E>,
) -> Result<(f64, usize), E> {
    let mut last = 0.0;
    let mut runs = 0;
    let mut a = step;
    // A grid point within a thousandth of a step of `upto` is `upto` itself, known survived.
    while a < upto - 1e-3 * step {
        runs += 1;
        if !survives(a)? {
            return Ok((last, runs));
        }
        last = a;
        a += step;
    }
    Ok((upto, runs))
}

/// Whether `variant` survives the impact on `robot`'s reduced models (`config`: the robot's,
/// without the variant's own override, which is applied here).
pub fn survives_reduced(
    config: &Config,
    robot: ReducedModel,
    variant: Variant,
    amplitude: f64,
    duration: f64,
    direction: Direction,
) -> Result<bool, PreviewError> {
    let mut config = config.clone();
    if variant == Variant::C1Zmp {
        config.preview.zmp_constraints = true;
    }
    let scenario = impact_scenario(amplitude, duration, direction);
    let result = ReducedLoop::new(&config, robot, &scenario, variant.kind()).run()?;
    Ok(result.metrics.time_outside_support == 0.0)
}

/// Whether a full-simulation run survived, from its controller's summary (`controller.json`).
pub fn survived_full(summary: &serde_json::Value, criteria: &Criteria) -> bool {
    let num = |k: &str| summary.get(k).and_then(serde_json::Value::as_f64);
    let (Some(drop), Some(edge), Some(fallbacks), Some(errors)) = (
        num("com_height_drop"),
        num("time_at_support_edge"),
        num("wbc_fallbacks"),
        num("tick_errors"),
    ) else {
        return false;
    };
    drop < criteria.max_com_drop
        && edge <= criteria.max_edge_time
        && fallbacks == 0.0
        && errors == 0.0
        && num("falls").unwrap_or(0.0) == 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bisection_brackets_the_threshold() {
        let c = bisect::<()>(200.0, 1.0, |a| Ok(a <= 73.2)).unwrap();
        assert!(c.survived <= 73.2 && c.failed.unwrap() > 73.2);
        assert!(c.failed.unwrap() - c.survived <= 1.0);
        assert_eq!(c.runs, 1 + 8);
        let all = bisect::<()>(200.0, 1.0, |_| Ok(true)).unwrap();
        assert_eq!((all.survived, all.failed, all.runs), (200.0, None, 1));
    }

    #[test]
    fn a_pocket_above_the_limit_is_not_the_monotone_capability() {
        // Stands up to 55 N, falls 60–70 N, stands 75 N (a pocket), falls above: the case of
        // C1 with the forecast as received on the 1 s impact.
        let stands = |a: f64| a <= 55.0 || (74.0..=76.0).contains(&a);
        let mut calls = Vec::new();
        let (m, runs) = monotone_below::<()>(75.0, 5.0, |a| {
            calls.push(a);
            Ok(stands(a))
        })
        .unwrap();
        assert_eq!(m, 55.0);
        assert_eq!(runs, 12, "5 … 60 N, stopping at the first fall: {calls:?}");
        // Monotone survival: the grid confirms the bisection's result.
        let (m, runs) = monotone_below::<()>(73.2, 5.0, |a| Ok(a <= 73.2)).unwrap();
        assert_eq!((m, runs), (73.2, 14));
        let c = Capability {
            survived: 75.0,
            failed: Some(77.0),
            runs: 20,
            monotone: Some(55.0),
        };
        assert_eq!(c.text(), "75 (monotone 55)");
        assert_eq!(
            Capability {
                failed: None,
                monotone: Some(75.0),
                ..c
            }
            .text(),
            "≥ 75"
        );
        // Nothing survived: nothing to scan.
        assert_eq!(
            monotone_below::<()>(0.0, 5.0, |_| Ok(false)).unwrap(),
            (0.0, 0)
        );
    }

    #[test]
    fn the_impact_file_is_the_impact() {
        let text = impact_toml(42.5, 0.3, Direction::Y);
        let parsed = Scenario::parse(&text, "test", std::path::Path::new(".")).unwrap();
        let built = impact_scenario(42.5, 0.3, Direction::Y);
        assert_eq!(parsed.content_hash(), built.content_hash());
        assert_eq!(parsed.force.at(IMPACT_START + 0.15), [0.0, 42.5, 0.0]);
    }
}
