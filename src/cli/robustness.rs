//! `upc robustness`: how much forecast error each controller survives. For each controller and
//! impact duration, the largest single impact survived (`upc capability`'s bisection, full
//! simulation) over a grid of forecast errors — amplitude factor κ (the forecast is κ × the
//! force) and shift τ (the forecast τ late) — the largest phantom survived: a forecast
//! impact the plant never plays, up to twice C1's capability, and with `--shapes` forecasts of
//! the wrong shape (`upc run --forecast-error-shape`). Writes `robustness.md` (a table and a heat
//! map per controller and duration), `.csv` and `.json`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use upc::capability::{Capability, Criteria, Direction, Variant};
use upc::forecast::ForecastShape;

use super::capability::runs_bar;
use super::cell::{CellArgs, Outcome};
use super::common::CaseSetup;
use super::sim::PlantChoice;
use super::sweep_runner::{RunnerArgs, RunnerKind, SweepRunner};
use super::{BoxError, CliResult};

#[derive(clap::Args, Debug)]
pub struct RobustnessArgs {
    /// Controllers (see `upc capability --controllers`), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "c0,c0obs,c1raw,c1,c2")]
    pub controllers: Vec<String>,
    /// Impact durations (s), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.3,1.0")]
    pub durations: Vec<f64>,
    /// Forecast amplitude factors κ (the forecast is κ × the force).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0.25,0.5,0.75,1,1.25,1.5,2"
    )]
    pub scales: Vec<f64>,
    /// Forecast shifts τ (s; the forecast τ late, negative: early).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "-0.3,-0.15,0,0.15,0.3",
        allow_hyphen_values = true
    )]
    pub shifts: Vec<f64>,
    /// Skip the phantom forecasts.
    #[arg(long)]
    pub no_phantom: bool,
    /// Forecasts of the wrong shape, each a cell of its own at κ = 1, τ = 0 (`upc run
    /// --forecast-error-shape`), e.g. truncated:0.5,decaying:0.3,step,stretched:2,rotated:30.
    #[arg(long, value_delimiter = ',')]
    pub shapes: Vec<ForecastShape>,
    /// Upper bound of the search (N) for each duration, as DURATION=N (default 2.5 × the
    /// iCub-like's exact C1 capability: 0.1=700, 0.3=160, 1=100; others 300).
    #[arg(long, value_delimiter = ',')]
    pub max: Vec<String>,
    /// Bisection tolerance (N).
    #[arg(long, default_value_t = 2.0)]
    pub tol: f64,
    /// After each bisection, a grid of this step (N) up to its result, stopping at the first
    /// fall (`upc capability --monotone`): a pocket of survival above a fall is then shown as
    /// such. Costs up to result / step more cases per cell.
    #[arg(long, value_name = "STEP")]
    pub monotone: Option<f64>,
    /// Largest CoM drop (m) of a phantom case still survived.
    #[arg(long, default_value_t = 0.005)]
    pub phantom_com_drop: f64,
    #[command(flatten)]
    pub runner: RunnerArgs,
    /// The plant.
    #[arg(long, value_enum, default_value = "upc")]
    pub plant: PlantChoice,
    /// Output directory (default runs/robustness-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub setup: CaseSetup,
}

/// How a full-simulation case's forecast departs from the impact the plant plays.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ForecastCase {
    /// The forecast is `scale × F(t − shift)`.
    scale: f64,
    shift: f64,
    /// The plant does not push at all (`sim.push = "none"`): the forecast is a phantom.
    phantom: bool,
    /// The forecast's shape (`upc run --forecast-error-shape`; exact on the κ × τ map).
    shape: upc::forecast::ForecastShape,
}

impl ForecastCase {
    const EXACT: ForecastCase = ForecastCase {
        scale: 1.0,
        shift: 0.0,
        phantom: false,
        shape: upc::forecast::ForecastShape::Exact,
    };
}

/// One bisection of the sweep.
#[derive(Debug, Clone, Copy)]
struct Cell {
    variant: Variant,
    duration: f64,
    forecast: ForecastCase,
}

#[derive(Debug, Clone, serde::Serialize)]
struct Row {
    controller: &'static str,
    duration: f64,
    scale: f64,
    shift: f64,
    phantom: bool,
    /// The forecast's shape (exact on the κ × τ map).
    shape: ForecastShape,
    /// The search's upper bound (N).
    max: f64,
    #[serde(flatten)]
    capability: Capability,
    /// Phantom: the controller summary's CoM drop (m) and min CoP margin (m) at the bound.
    at_max: Option<(f64, f64)>,
    wall_time: f64,
}

fn default_max(duration: f64) -> f64 {
    match duration {
        d if (d - 0.1).abs() < 1e-9 => 700.0,
        d if (d - 0.3).abs() < 1e-9 => 160.0,
        d if (d - 1.0).abs() < 1e-9 => 100.0,
        _ => 300.0,
    }
}

pub fn run(args: RobustnessArgs) -> CliResult {
    let variants = checked_variants(&args)?;
    let max_for = max_bounds(&args.max)?;
    let max_of = |d: f64| {
        max_for
            .iter()
            .find(|(x, _)| (x - d).abs() < 1e-9)
            .map_or(default_max(d), |m| m.1)
    };
    let criteria = Criteria::default();
    let phantom_criteria = Criteria {
        max_com_drop: args.phantom_com_drop,
        ..criteria
    };
    let out = args.out.clone().unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        PathBuf::from(format!("runs/robustness-{secs}"))
    });
    std::fs::create_dir_all(out.join("cases"))?;
    let exe = std::env::current_exe()?;
    let start = Instant::now();

    // Phase 1: the error grid (C0 and C0+obs ignore the forecast: one bisection each).
    let mut cells = grid_cells(&args, &variants);
    // MuJoCo's scene pushes through the door only: it cannot play a phantom (no push at all).
    let no_phantom = args.no_phantom || args.plant == PlantChoice::Mujoco;
    if no_phantom && !args.no_phantom {
        eprintln!(
            "robustness: no phantoms on the MuJoCo plant (it pushes through the door only); run them on upc's plant"
        );
    }
    let forecasting = args.durations.len() * variants.iter().filter(|v| v.uses_forecast()).count();
    let phantoms = if no_phantom { 0 } else { forecasting };
    cells.extend(shape_cells(&args, &variants));
    let per_case = 1
        + ((args.max_bound() / args.tol).log2().ceil().max(0.0) as u64)
        + args
            .monotone
            .map_or(0, |step| (args.max_bound() / step).ceil() as u64);
    // The Ray driver prints its own progress.
    let bar = runs_bar(
        args.quiet || args.runner.engine == RunnerKind::Ray,
        (cells.len() + phantoms) as u64 * per_case,
    );
    let sweep = Sweep {
        args: &args,
        runner: SweepRunner {
            args: &args.runner,
            out: &out,
            exe: &exe,
            bar: &bar,
            per_cell: per_case,
            quiet: args.quiet,
        },
    };
    let mut failed = Vec::new();
    let mut rows = sweep.run_cells(
        cells
            .iter()
            .map(|c| (*c, max_of(c.duration), criteria))
            .collect(),
        &mut failed,
    )?;

    // Phase 2: phantoms up to twice C1's capability with an exact forecast (the forecast as
    // received, when swept; else the variant's own).
    if !no_phantom {
        let ph = phantom_cells(&args, &variants, &rows, max_of, phantom_criteria);
        rows.extend(sweep.run_cells(ph, &mut failed)?);
    }
    bar.finish_and_clear();
    let wall = start.elapsed().as_secs_f64();
    let order = |r: &Row| {
        (
            (r.duration * 1e6) as i64,
            variants.iter().position(|v| v.label() == r.controller),
            r.phantom,
            r.shape.to_string(),
            (r.scale * 1e6) as i64,
            (r.shift * 1e6) as i64,
        )
    };
    rows.sort_by_key(order);
    let engine = args.runner.describe(&out);
    write_outputs(&out, &args, &variants, &rows, &failed, wall, &engine)?;
    println!(
        "wrote {}/robustness.md ({wall:.0} s, {engine})",
        out.display()
    );
    super::sweep_runner::failed_cells(&failed)
}

/// The controllers named by `--controllers`, once the grid's values are checked.
fn checked_variants(args: &RobustnessArgs) -> Result<Vec<Variant>, BoxError> {
    let variants = args
        .controllers
        .iter()
        .map(|c| Variant::parse(c).ok_or_else(|| format!("unknown controller `{c}`")))
        .collect::<Result<Vec<_>, _>>()?;
    if args
        .durations
        .iter()
        .chain(&args.scales)
        .chain(&args.shifts)
        .any(|v| !v.is_finite())
        || args.durations.iter().any(|d| *d <= 0.0)
        || args.scales.iter().any(|k| *k < 0.0)
    {
        return Err("durations must be > 0, scales ≥ 0, all finite".into());
    }
    if let Some(step) = args.monotone
        && !(step.is_finite() && step > 0.0)
    {
        return Err(format!("--monotone must be > 0, got {step}").into());
    }
    Ok(variants)
}

/// `--max`'s DURATION=N pairs.
fn max_bounds(max: &[String]) -> Result<Vec<(f64, f64)>, BoxError> {
    let mut max_for = Vec::new();
    for m in max {
        let (d, n) = m
            .split_once('=')
            .ok_or_else(|| format!("--max takes DURATION=N, got `{m}`"))?;
        max_for.push((d.parse::<f64>()?, n.parse::<f64>()?));
    }
    Ok(max_for)
}

/// The κ × τ map's cells: every duration × controller × scale × shift, one cell for a
/// controller that ignores the forecast.
fn grid_cells(args: &RobustnessArgs, variants: &[Variant]) -> Vec<Cell> {
    let mut cells = Vec::new();
    for &duration in &args.durations {
        for &variant in variants {
            if !variant.uses_forecast() {
                cells.push(Cell {
                    variant,
                    duration,
                    forecast: ForecastCase::EXACT,
                });
                continue;
            }
            for &scale in &args.scales {
                for &shift in &args.shifts {
                    cells.push(Cell {
                        variant,
                        duration,
                        forecast: ForecastCase {
                            scale,
                            shift,
                            ..ForecastCase::EXACT
                        },
                    });
                }
            }
        }
    }
    cells
}

/// The shape cells: each forecasting controller and duration, each shape, κ = 1 and τ = 0.
fn shape_cells(args: &RobustnessArgs, variants: &[Variant]) -> Vec<Cell> {
    let mut cells = Vec::new();
    for &duration in &args.durations {
        for &variant in variants.iter().filter(|v| v.uses_forecast()) {
            for &shape in &args.shapes {
                cells.push(Cell {
                    variant,
                    duration,
                    forecast: ForecastCase {
                        shape,
                        ..ForecastCase::EXACT
                    },
                });
            }
        }
    }
    cells
}

/// The phantom cells, each searched up to twice C1's capability with an exact forecast from
/// phase 1 (C1 raw's, else C1's, else the variant's own; else the default bound's share).
fn phantom_cells(
    args: &RobustnessArgs,
    variants: &[Variant],
    rows: &[Row],
    max_of: impl Fn(f64) -> f64,
    criteria: Criteria,
) -> Vec<(Cell, f64, Criteria)> {
    let exact = |label: &str, d: f64| {
        rows.iter()
            .find(|r| {
                r.controller == label
                    && r.duration == d
                    && r.scale == 1.0
                    && r.shift == 0.0
                    && on_map(r)
            })
            .map(|r| r.capability.survived)
    };
    let mut ph = Vec::new();
    for &duration in &args.durations {
        for &variant in variants.iter().filter(|v| v.uses_forecast()) {
            let cap = exact(Variant::C1Raw.label(), duration)
                .or_else(|| exact(Variant::C1.label(), duration))
                .or_else(|| exact(variant.label(), duration))
                .unwrap_or(max_of(duration) / 2.5);
            let cell = Cell {
                variant,
                duration,
                forecast: ForecastCase {
                    phantom: true,
                    ..ForecastCase::EXACT
                },
            };
            ph.push((cell, (2.0 * cap).max(args.tol), criteria));
        }
    }
    ph
}

/// What every cell of the sweep shares, and the runner that runs them.
struct Sweep<'a> {
    args: &'a RobustnessArgs,
    runner: SweepRunner<'a>,
}

impl Sweep<'_> {
    /// Searches each cell (cell, upper bound, criteria); a cell that failed is kept aside with
    /// its reason.
    fn run_cells(
        &self,
        cells: Vec<(Cell, f64, Criteria)>,
        failed: &mut Vec<(String, String)>,
    ) -> Result<Vec<Row>, BoxError> {
        let specs: Vec<CellArgs> = cells
            .iter()
            .map(|(cell, max, crit)| self.cell_args(cell, *max, crit))
            .collect();
        let results = self.runner.run(&specs)?;
        let mut rows = Vec::new();
        for (((cell, max, _), spec), result) in cells.iter().zip(&specs).zip(results) {
            match result.outcome {
                Outcome::Searched { capability, at_max } => rows.push(Row {
                    controller: cell.variant.label(),
                    duration: cell.duration,
                    scale: cell.forecast.scale,
                    shift: cell.forecast.shift,
                    phantom: cell.forecast.phantom,
                    shape: cell.forecast.shape,
                    max: *max,
                    capability,
                    at_max,
                    wall_time: result.wall_time,
                }),
                Outcome::Failed { reason } => failed.push((spec.argv().join(" "), reason)),
            }
        }
        Ok(rows)
    }

    /// One cell's definition: its bisection up to `max` against `crit`.
    fn cell_args(&self, cell: &Cell, max: f64, crit: &Criteria) -> CellArgs {
        let args = self.args;
        CellArgs {
            variant: cell.variant,
            duration: cell.duration,
            direction: Direction::X,
            forecast_scale: cell.forecast.scale,
            forecast_shift: cell.forecast.shift,
            forecast_shape: cell.forecast.shape,
            phantom: cell.forecast.phantom,
            max,
            tol: args.tol,
            monotone: args.monotone,
            edge_time: crit.max_edge_time,
            com_drop: crit.max_com_drop,
            plant: args.plant,
            setup: args.setup.clone(),
        }
        .absolute()
    }
}

impl RobustnessArgs {
    fn max_bound(&self) -> f64 {
        self.durations
            .iter()
            .map(|&d| default_max(d))
            .fold(100.0, f64::max)
    }
}

fn write_outputs(
    out: &Path,
    args: &RobustnessArgs,
    variants: &[Variant],
    rows: &[Row],
    failed: &[(String, String)],
    wall: f64,
    engine: &str,
) -> Result<(), BoxError> {
    write_data(out, args, rows, failed, wall, engine)?;
    let fig_dir = out.join("figures");
    std::fs::create_dir_all(&fig_dir)?;
    let mut md = preamble(args, wall, engine);
    super::sweep_runner::failed_section(&mut md, failed);
    for &d in &args.durations {
        let _ = writeln!(md, "## {d} s impact\n");
        for &v in variants {
            if !v.uses_forecast() {
                if let Some(c) = map_capability(rows, v.label(), d) {
                    let _ = writeln!(
                        md,
                        "**{}**: {} N at every κ and τ (ignores the forecast).\n",
                        v.label(),
                        Capability::text(&c)
                    );
                }
                continue;
            }
            forecasting_section(&mut md, &fig_dir, args, rows, v, d)?;
        }
        shape_table(&mut md, &fig_dir, args, variants, rows, d)?;
    }
    std::fs::write(out.join("robustness.md"), md)?;
    Ok(())
}

/// `robustness.json` (the rows and the sweep's settings) and `robustness.csv`.
fn write_data(
    out: &Path,
    args: &RobustnessArgs,
    rows: &[Row],
    failed: &[(String, String)],
    wall: f64,
    engine: &str,
) -> Result<(), BoxError> {
    std::fs::write(
        out.join("robustness.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "robot": args.setup.robot.robot,
            "plant": args.plant.name(),
            "tol": args.tol,
            "wall_time": wall,
            "engine": engine,
            "rows": rows,
            "failed_cells": super::sweep_runner::failed_json(failed),
        }))?,
    )?;
    let mut csv = String::from(
        "controller,duration,scale,shift,phantom,shape,max,survived,failed,runs,monotone\n",
    );
    for r in rows {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{:.2},{},{},{}",
            r.controller,
            r.duration,
            r.scale,
            r.shift,
            r.phantom,
            r.shape,
            r.max,
            r.capability.survived,
            r.capability
                .failed
                .map_or(String::new(), |f| format!("{f:.2}")),
            r.capability.runs,
            r.capability
                .monotone
                .map_or(String::new(), |m| format!("{m:.2}")),
        );
    }
    std::fs::write(out.join("robustness.csv"), csv)?;
    Ok(())
}

/// The report's title, what its figures mean, and what the user layered over the defaults.
fn preamble(args: &RobustnessArgs, wall: f64, engine: &str) -> String {
    let mut md = format!(
        "# Robustness to forecast errors — robot `{}`, `{}` plant\n\n\
         Largest single impact along x survived (N; full simulation, `upc capability`'s \
         criteria, bisection to {} N), with the forecast κ × the force, τ late (negative: \
         early). C1 and C2 correct the forecast by the measured hand force (the default); \"C1 \
         raw\" previews it as received; C0 and C0+obs ignore the forecast (one search each, \
         the same at every κ, τ). Phantom: the plant does not push, the forecast announces \
         the impact; the largest phantom survived with a CoM drop under {} mm, searched up to \
         twice C1's exact-forecast capability. Wall time: {wall:.0} s, {engine}.\n\n",
        args.setup.robot.robot,
        args.plant.name(),
        args.tol,
        args.phantom_com_drop * 1e3
    );
    md += &args.setup.layers_md();
    if let Some(step) = args.monotone {
        let _ = writeln!(
            md,
            "Monotone check (`--monotone {step}`): after each bisection a grid of {step} N up to \
             its result, stopping at the first fall; \"(monotone M)\" where a fall lies below the \
             bisection's result. The heat maps show the bisection's.\n"
        );
    }
    md
}

/// The capability of controller `label` at duration `d` on the κ × τ map (the first such row:
/// a controller that ignores the forecast has one).
fn map_capability(rows: &[Row], label: &str, d: f64) -> Option<Capability> {
    rows.iter()
        .find(|r| r.controller == label && r.duration == d && on_map(r))
        .map(|r| r.capability)
}

/// A forecasting controller at duration `d`: its κ × τ table, its phantom, and its heat map
/// (written to `fig_dir`).
fn forecasting_section(
    md: &mut String,
    fig_dir: &Path,
    args: &RobustnessArgs,
    rows: &[Row],
    v: Variant,
    d: f64,
) -> Result<(), BoxError> {
    let _ = writeln!(md, "**{}**\n", v.label());
    let grid = kappa_tau_table(md, args, rows, v, d);
    if let Some(p) = rows
        .iter()
        .find(|r| r.controller == v.label() && r.duration == d && r.phantom)
    {
        let _ = write!(
            md,
            "\nPhantom: survived up to {} N of {:.0} N searched",
            Capability::text(&p.capability),
            p.max
        );
        if let Some((drop, margin)) = p.at_max {
            let _ = write!(
                md,
                " (at {:.0} N: CoM drop {:.1} mm, min CoP margin {:.1} mm)",
                p.max,
                drop * 1e3,
                margin * 1e3
            );
        }
        *md += ".\n";
    }
    let name = format!(
        "robustness_{}_{:.0}ms",
        v.label().replace(['+', ' '], "_").to_lowercase(),
        d * 1e3
    );
    let c0_cap = map_capability(rows, Variant::C0.label(), d).map(|c| c.survived);
    let shifts: Vec<String> = args
        .shifts
        .iter()
        .map(|s| format!("τ {:+.0} ms", s * 1e3))
        .collect();
    std::fs::write(
        fig_dir.join(format!("{name}.svg")),
        heat_map(
            &format!("{} — {d} s impact: largest survived (N)", v.label()),
            &args
                .scales
                .iter()
                .map(|k| format!("κ {k}"))
                .collect::<Vec<_>>(),
            &shifts,
            &grid,
            max_or(rows, d),
            &vec![c0_cap; shifts.len()],
            c0_cap.map(|c| format!("red outline: below C0's {c:.0} N")),
        ),
    )?;
    let _ = writeln!(md, "\n![{}](figures/{name}.svg)\n", v.label());
    Ok(())
}

/// The κ × τ table of controller `v` at duration `d`; returns the amplitudes survived, a line
/// per κ (the heat map's cells).
fn kappa_tau_table(
    md: &mut String,
    args: &RobustnessArgs,
    rows: &[Row],
    v: Variant,
    d: f64,
) -> Vec<Vec<Option<f64>>> {
    *md += "| κ \\ τ (ms) |";
    for s in &args.shifts {
        let _ = write!(md, " {:+.0} |", s * 1e3);
    }
    *md += "\n|---|";
    *md += &"---|".repeat(args.shifts.len());
    *md += "\n";
    let mut grid = Vec::new();
    for &k in &args.scales {
        let _ = write!(md, "| {k} |");
        let mut line = Vec::new();
        for &s in &args.shifts {
            let c = rows
                .iter()
                .find(|r| {
                    r.controller == v.label()
                        && r.duration == d
                        && on_map(r)
                        && r.scale == k
                        && r.shift == s
                })
                .map(|r| r.capability);
            let _ = write!(md, " {} |", c.map_or("–".into(), |c| Capability::text(&c)));
            line.push(c.map(|c| c.survived));
        }
        *md += "\n";
        grid.push(line);
    }
    grid
}

/// A row of the κ × τ map (not a phantom, not a shape error).
fn on_map(r: &Row) -> bool {
    !r.phantom && r.shape == ForecastShape::Exact
}

/// The share of the same controller's capability without a forecast that a forecast of the
/// wrong shape must keep: attaching a forecaster never makes the robot less safe, within a
/// bisection's noise (docs/results/robustness.md).
const SHAPE_PROMISE: f64 = 0.95;

/// The shape errors of duration `d`: each shape × each forecasting controller, beside the same
/// controller with an exact forecast and with none (κ = 0), when the sweep has those cells; as
/// a table and a heat map (`figures/robustness_shapes_<d>ms.svg`), its cells below
/// [`SHAPE_PROMISE`] of no forecast outlined.
fn shape_table(
    md: &mut String,
    fig_dir: &Path,
    args: &RobustnessArgs,
    variants: &[Variant],
    rows: &[Row],
    d: f64,
) -> Result<(), BoxError> {
    if args.shapes.is_empty() {
        return Ok(());
    }
    let forecasting: Vec<Variant> = variants
        .iter()
        .copied()
        .filter(|v| v.uses_forecast())
        .collect();
    let find = |v: Variant, pick: &dyn Fn(&Row) -> bool| {
        rows.iter()
            .find(|r| r.controller == v.label() && r.duration == d && pick(r))
            .map(|r| r.capability)
    };
    let cell = |v: Variant, pick: &dyn Fn(&Row) -> bool| {
        find(v, pick).map_or("–".into(), |c| Capability::text(&c))
    };
    let _ = writeln!(
        md,
        "**Forecasts of the wrong shape** (κ = 1, τ = 0; `upc run --forecast-error-shape`)\n"
    );
    *md += "| forecast |";
    for v in &forecasting {
        let _ = write!(md, " {} |", v.label());
    }
    *md += "\n|---|";
    *md += &"---|".repeat(forecasting.len());
    *md += "\n";
    let exact = |r: &Row| on_map(r) && r.scale == 1.0 && r.shift == 0.0;
    let none = |r: &Row| on_map(r) && r.scale == 0.0 && r.shift == 0.0;
    for (label, pick) in [
        ("exact", &exact as &dyn Fn(&Row) -> bool),
        ("none (κ = 0)", &none),
    ] {
        let _ = write!(md, "| {label} |");
        for &v in &forecasting {
            let _ = write!(md, " {} |", cell(v, pick));
        }
        *md += "\n";
    }
    let shaped = |s: ForecastShape| move |r: &Row| !r.phantom && r.shape == s;
    for &s in &args.shapes {
        let _ = write!(md, "| `{s}` |");
        for &v in &forecasting {
            let _ = write!(md, " {} |", cell(v, &shaped(s)));
        }
        *md += "\n";
    }
    *md += "\n";
    let mut labels = vec!["exact".to_string(), "none (κ = 0)".to_string()];
    labels.extend(args.shapes.iter().map(|s| s.to_string()));
    let line = |pick: &dyn Fn(&Row) -> bool| -> Vec<Option<f64>> {
        forecasting
            .iter()
            .map(|&v| find(v, pick).map(|c| c.survived))
            .collect()
    };
    let mut grid = vec![line(&exact), line(&none)];
    grid.extend(args.shapes.iter().map(|&s| line(&shaped(s))));
    let floor: Vec<Option<f64>> = forecasting
        .iter()
        .map(|&v| find(v, &none).map(|c| SHAPE_PROMISE * c.survived))
        .collect();
    let name = format!("robustness_shapes_{:.0}ms", d * 1e3);
    std::fs::write(
        fig_dir.join(format!("{name}.svg")),
        heat_map(
            &format!("Forecasts of the wrong shape — {d} s impact: largest survived (N)"),
            &labels,
            &forecasting
                .iter()
                .map(|v| v.label().to_string())
                .collect::<Vec<_>>(),
            &grid,
            max_or(rows, d),
            &floor,
            Some(format!(
                "red outline: below {:.0} % of the same controller without a forecast",
                SHAPE_PROMISE * 100.0
            )),
        ),
    )?;
    let _ = writeln!(md, "![Forecasts of the wrong shape](figures/{name}.svg)\n");
    Ok(())
}

fn max_or(rows: &[Row], d: f64) -> f64 {
    rows.iter()
        .filter(|r| r.duration == d && on_map(r))
        .map(|r| r.max)
        .fold(1.0, f64::max)
}

/// A heat map as SVG: one cell per row (κ, or a forecast's shape) and column (τ, or a
/// controller), its colour the amplitude survived over the search's bound (white → dark blue),
/// cells below their column's `floor` outlined in red (`legend` says what the floor is).
fn heat_map(
    title: &str,
    row_labels: &[String],
    col_labels: &[String],
    grid: &[Vec<Option<f64>>],
    max: f64,
    floor: &[Option<f64>],
    legend: Option<String>,
) -> String {
    let longest = row_labels
        .iter()
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0);
    let (cw, ch, top) = (70.0, 34.0, 50.0);
    let labels = (12.0 + 7.5 * longest as f64).max(70.0);
    let cells = labels + cw * col_labels.len() as f64 + 20.0;
    // Wide enough for the cells, the title (14 px) and the legend (12 px); the cells centred.
    let chars = |t: &str| t.chars().count() as f64;
    let w = cells
        .max(8.0 * chars(title) + 20.0)
        .max(legend.as_deref().map_or(0.0, |l| 6.8 * chars(l) + 20.0));
    let left = labels + 0.5 * (w - cells);
    let h = top + ch * row_labels.len() as f64 + 50.0;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{}\" y=\"20\" text-anchor=\"middle\" font-size=\"14\">{title}</text>\n",
        w / 2.0
    );
    for (i, label) in row_labels.iter().enumerate() {
        let y = top + ch * i as f64;
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{label}</text>",
            left - 6.0,
            y + ch / 2.0 + 4.0
        );
        for j in 0..col_labels.len() {
            let x = left + cw * j as f64;
            let v = grid.get(i).and_then(|l| l.get(j)).copied().flatten();
            let (fill, text) = match v {
                Some(v) => {
                    let f = (v / max).clamp(0.0, 1.0);
                    let c = |a: f64, b: f64| (a + (b - a) * f).round() as u8;
                    (
                        format!(
                            "rgb({},{},{})",
                            c(255.0, 8.0),
                            c(255.0, 48.0),
                            c(255.0, 107.0)
                        ),
                        format!("{v:.0}"),
                    )
                }
                None => ("rgb(220,220,220)".into(), "–".into()),
            };
            let below = matches!((v, floor.get(j).copied().flatten()), (Some(v), Some(c)) if v < c);
            let stroke = if below {
                "red\" stroke-width=\"3"
            } else {
                "gray"
            };
            let ink = if v.is_some_and(|v| v / max > 0.55) {
                "white"
            } else {
                "black"
            };
            let _ = writeln!(
                s,
                "<rect x=\"{x}\" y=\"{y}\" width=\"{cw}\" height=\"{ch}\" fill=\"{fill}\" stroke=\"{stroke}\"/>\
                 <text x=\"{}\" y=\"{}\" text-anchor=\"middle\" fill=\"{ink}\">{text}</text>",
                x + cw / 2.0,
                y + ch / 2.0 + 4.0
            );
        }
    }
    for (j, label) in col_labels.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{label}</text>",
            left + cw * j as f64 + cw / 2.0,
            top + ch * row_labels.len() as f64 + 18.0,
        );
    }
    if let Some(legend) = legend {
        let _ = writeln!(
            s,
            "<text x=\"10\" y=\"{}\">{legend}</text>",
            top + ch * row_labels.len() as f64 + 40.0
        );
    }
    s += "</svg>\n";
    s
}
