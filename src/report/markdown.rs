//! The text of `report.md`: scenario, metrics tables and figure links. It states figures; the
//! reader draws the conclusions.

use std::fmt::Write;

use super::figures::Written;
use super::reduced::min_support_margin;
use super::rundir::RunDir;
use super::series::{Quantity, ReducedRun, SeriesSource};
use crate::config::Config;
use crate::robot::ReducedModel;
use crate::scenario::{ForceProfile, Scenario};

/// `v` with `prec` decimals, "–" when unknown or not finite.
pub fn num(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.prec$}"),
        _ => "–".into(),
    }
}

fn row(cells: &[String]) -> String {
    format!("| {} |\n", cells.join(" | "))
}

fn header(cells: &[&str]) -> String {
    let mut s = row(&cells.iter().map(|c| c.to_string()).collect::<Vec<_>>());
    s += &row(&cells
        .iter()
        .enumerate()
        .map(|(i, _)| if i == 0 { ":--".into() } else { "--:".into() })
        .collect::<Vec<_>>());
    s
}

/// The scenario: description, duration, and the force profile's impacts.
pub fn scenario_block(run: &RunDir, scenario: Option<&Scenario>) -> String {
    let mut s = String::new();
    if !run.description.is_empty() {
        let _ = writeln!(s, "{}.\n", run.description.trim_end_matches('.'));
    }
    let names: Vec<String> = run
        .controllers
        .iter()
        .map(|c| c.name.to_uppercase())
        .collect();
    let _ = writeln!(
        s,
        "Run directory `{}`: robot `{}` on the `{}` plant, {:.2} s simulated in {} mode; controllers {}.\n",
        run.path.display(),
        run.robot,
        run.plant,
        run.duration,
        run.mode,
        names.join(", ")
    );
    if let Some(sc) = scenario.filter(|sc| sc.force_scale != 1.0) {
        let _ = writeln!(
            s,
            "The scenario's forces are scaled by {:.3} for this robot (its mass over the \
             iCub-like humanoid's, capped by its arm's force capacity over the iCub-like's: \
             `upc model --robot`); the table shows the scaled forces.\n",
            sc.force_scale
        );
    }
    match scenario.map(|sc| &sc.force) {
        Some(ForceProfile::Impacts(impacts)) => {
            s += "Hand force profile (raised-cosine impacts, feet frame):\n\n";
            s += &header(&[
                "impact",
                "start (s)",
                "rise (s)",
                "hold (s)",
                "fall (s)",
                "peak F_x (N)",
                "peak F_y (N)",
                "peak F_z (N)",
                "peak ‖F‖ (N)",
                "within the run",
            ]);
            for (i, imp) in impacts.iter().enumerate() {
                let norm = imp.force.iter().map(|f| f * f).sum::<f64>().sqrt();
                s += &row(&[
                    format!("{}", i + 1),
                    num(Some(imp.start), 2),
                    num(Some(imp.rise), 2),
                    num(Some(imp.hold), 2),
                    num(Some(imp.fall), 2),
                    num(Some(imp.force[0]), 1),
                    num(Some(imp.force[1]), 1),
                    num(Some(imp.force[2]), 1),
                    num(Some(norm), 1),
                    if imp.start < run.duration {
                        "yes".into()
                    } else {
                        "no (starts after the end)".into()
                    },
                ]);
            }
            s += "\n";
        }
        Some(ForceProfile::Samples(samples)) => {
            let peak = samples
                .iter()
                .map(|(_, f)| f.iter().map(|x| x * x).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            let _ = writeln!(
                s,
                "Hand force profile: {} samples, peak ‖F‖ = {peak:.1} N.\n",
                samples.len()
            );
        }
        None => {
            let _ = writeln!(
                s,
                "The scenario `{}` could not be loaded here: its force profile is not listed.\n",
                run.scenario
            );
        }
    }
    s
}

/// Metrics of the full-simulation runs: the controllers' summaries, plus the predicted ZMP's
/// excursion beyond the support computed from the CSV.
pub fn full_metrics_table(run: &RunDir) -> String {
    let mut s = header(&[
        "controller",
        "min ZMP margin (mm)",
        "time at support edge (s)",
        "predicted ZMP beyond support, max (mm)",
        "hand RMS error (mm)",
        "hand peak error (mm)",
        "CoM height drop (mm)",
        "tick p50 (µs)",
        "tick p99 (µs)",
        "deadline misses",
        "WBC fallbacks",
        "C2 solve mean (ms)",
        "C2 iterations (mean)",
    ]);
    for c in &run.controllers {
        let excursion = match (
            c.csv.series.support(),
            c.csv.series.values(Quantity::ZmpPredX),
            c.csv.series.values(Quantity::ZmpPredY),
        ) {
            (Some(sup), Some(x), Some(y)) => min_support_margin(x, y, sup).map(|m| (-m).max(0.0)),
            _ => None,
        };
        let mm = |key: &str| c.stat(key).map(|v| v * 1e3);
        let is_c2 = c.name == "c2";
        s += &row(&[
            c.name.to_uppercase(),
            num(mm("min_zmp_margin"), 2),
            num(c.stat("time_at_support_edge"), 3),
            num(excursion.map(|v| v * 1e3), 1),
            num(mm("hand_rms_error"), 2),
            num(mm("hand_peak_error"), 2),
            num(mm("com_height_drop"), 1),
            num(c.stat("tick_p50_us"), 0),
            num(c.stat("tick_p99_us"), 0),
            num(c.stat("deadline_misses"), 0),
            num(c.stat("wbc_fallbacks"), 0),
            if is_c2 {
                num(c.stat("c2_solve_mean_ms"), 2)
            } else {
                "–".into()
            },
            if is_c2 {
                num(c.stat("c2_iterations_mean"), 1)
            } else {
                "–".into()
            },
        ]);
    }
    s += "\nMin ZMP margin: smallest distance of the measured ZMP (centre of pressure) to the \
          support edge, negative outside. Time at support edge: time the measured ZMP spends \
          within 1 mm of the edge. Predicted ZMP: the preview model's ZMP one preview step \
          ahead, from `controller.csv` (10 ms samples). Tick: controller compute time per 1 ms \
          tick. WBC fallbacks: ticks where the whole-body QP had no solution and gravity \
          compensation was sent. A dash: not recorded (or not applicable).\n";
    s
}

/// The same controllers in several runs, one row per controller and run, each run named by
/// `label` (its plant, or its name) in a column headed `what`.
pub fn side_by_side_table(runs: &[&RunDir], what: &str, label: fn(&RunDir) -> String) -> String {
    let mut s = header(&[
        "controller",
        what,
        "min ZMP margin (mm)",
        "time at support edge (s)",
        "hand RMS error (mm)",
        "hand peak error (mm)",
        "CoM height drop (mm)",
        "tick p50 (µs)",
        "tick p99 (µs)",
        "plant step p50 (µs)",
        "wall time (s)",
    ]);
    let mut names: Vec<&str> = Vec::new();
    for r in runs {
        for c in &r.controllers {
            if !names.contains(&c.name.as_str()) {
                names.push(&c.name);
            }
        }
    }
    for name in names {
        for r in runs {
            let Some(c) = r.controllers.iter().find(|c| c.name == name) else {
                continue;
            };
            let mm = |key: &str| c.stat(key).map(|v| v * 1e3);
            let step = c
                .sim_summary
                .as_ref()
                .and_then(|j| j.get("step_time_p50"))
                .and_then(serde_json::Value::as_f64);
            s += &row(&[
                name.to_uppercase(),
                label(r),
                num(mm("min_zmp_margin"), 2),
                num(c.stat("time_at_support_edge"), 3),
                num(mm("hand_rms_error"), 2),
                num(mm("hand_peak_error"), 2),
                num(mm("com_height_drop"), 1),
                num(c.stat("tick_p50_us"), 0),
                num(c.stat("tick_p99_us"), 0),
                num(step.map(|v| v * 1e6), 0),
                num(c.wall_time, 1),
            ]);
        }
    }
    s += "\nThe metrics are the controller's own (from the states each plant published), as in \
          the per-run tables. Plant step: wall time of one physics step (upc: the Rust \
          simulator; mujoco: `mj_step` alone). Wall time: the whole lockstep run of that \
          controller, processes started and stopped.\n";
    s
}

/// Metrics of the reduced-model runs (the same figures `upc preview` prints).
pub fn reduced_metrics_table(runs: &[ReducedRun]) -> String {
    let mut s = header(&[
        "controller",
        "max ZMP error (mm)",
        "min support margin (mm)",
        "time outside support (s)",
        "max excursion beyond support (mm)",
        "hand RMS error (mm)",
        "hand peak error (mm)",
        "solve p50 (µs)",
        "solve p99 (µs)",
        "C2 iterations (mean)",
    ]);
    for r in runs {
        let m = &r.result.metrics;
        let margin = match (
            r.series.values(Quantity::ZmpX),
            r.series.values(Quantity::ZmpY),
        ) {
            (Some(x), Some(y)) => r
                .series
                .support()
                .and_then(|sup| min_support_margin(x, y, sup)),
            _ => None,
        };
        let reports = &r.result.gain_search;
        let iterations = (!reports.is_empty()).then(|| {
            reports.iter().map(|g| g.iterations as f64).sum::<f64>() / reports.len() as f64
        });
        s += &row(&[
            r.series.label.clone(),
            num(Some(m.max_zmp_error * 1e3), 2),
            num(margin.map(|v| v * 1e3), 2),
            num(Some(m.time_outside_support), 3),
            num(Some(m.max_support_excursion * 1e3), 2),
            num(Some(m.hand_rms_error * 1e3), 2),
            num(Some(m.hand_peak_error * 1e3), 2),
            num(Some(m.solve_p50 * 1e6), 1),
            num(Some(m.solve_p99 * 1e6), 1),
            num(iterations, 1),
        ]);
    }
    s += "\nZMP error: distance to the ZMP reference. Support margin and excursion: against \
          `[support]` of the config. Solve: controller time per preview step, C2's gain search \
          included.\n";
    s
}

/// The reduced models' parameters, one line.
pub fn reduced_config_line(config: &Config, robot: &ReducedModel, scenario: &Scenario) -> String {
    let p = &config.preview;
    format!(
        "Reduced models: cart-table CoM (M = {:.2} kg, z_c = {:.3} m) and hand impedance model, \
         {:.2} s of the scenario, T = {} s, N = {} ({:.2} s preview), R/Q_e = {:e}, nominal \
         K_p = {}, support x ∈ [{:.3}, {:.3}] m, y ∈ [{:.3}, {:.3}] m.\n",
        robot.mass,
        robot.com_height,
        scenario.duration,
        p.period,
        p.horizon,
        p.period * p.horizon as f64,
        p.r / p.q_e,
        config.hand.kp,
        robot.support[0][0],
        robot.support[0][1],
        robot.support[1][0],
        robot.support[1][1],
    )
}

/// The figures, embedded as SVG with a link to each PNG.
pub fn figures_block(figures: &[Written]) -> String {
    let mut s = String::new();
    for f in figures {
        let _ = writeln!(s, "![{}](figures/{})\n", f.title, f.svg);
        if let Some(png) = &f.png {
            let _ = writeln!(s, "PNG: [figures/{png}](figures/{png})\n");
        }
    }
    s
}
