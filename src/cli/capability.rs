//! `upc capability`: how hard the robot can be pushed. For each controller, impact duration
//! and direction, the largest single impact survived, by bisection over the amplitude
//! (`upc::capability`), on the reduced models (in-process) and on the full simulation (each
//! cell a bisection of `upc run`s, run by the sweep runner: `--jobs` at a time here, or on Ray).
//! Writes `capability.md`, `.csv`, `.json` and one figure per model and direction.

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use upc::capability::{Capability, Criteria, Direction, Variant, search, survives_reduced};
use upc::report::figures::{Figure, Line, Panel, write_figure};
use upc::report::series::{Quantity, Series, SeriesSource};

use super::cell::{CellArgs, Outcome};
use super::common::CaseSetup;
use super::sim::PlantChoice;
use super::sweep_runner::{RunnerArgs, RunnerKind, SweepRunner, pool};
use super::{BoxError, CliResult};

#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum Models {
    Reduced,
    Full,
    Both,
}

#[derive(clap::Args, Debug)]
pub struct CapabilityArgs {
    /// Controllers: c0, c1, c2, c1zmp (C1 with the ZMP constraints), c0obs (C0 with the CoM
    /// observer), c1raw (C1 without the forecast correction), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "c0,c1,c2,c1zmp")]
    pub controllers: Vec<String>,
    /// Impact durations (s), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.1,0.3,1.0")]
    pub durations: Vec<f64>,
    /// Push directions: x (toward the robot), y (to its left).
    #[arg(long, value_delimiter = ',', default_value = "x,y")]
    pub directions: Vec<String>,
    /// Which test bed.
    #[arg(long, value_enum, default_value = "both")]
    pub models: Models,
    /// Upper bound of the search (N).
    #[arg(long, default_value_t = 300.0)]
    pub max: f64,
    /// Bisection tolerance (N).
    #[arg(long, default_value_t = 2.0)]
    pub tol: f64,
    /// After each bisection, check survival on a grid of this step (N) from one step up to
    /// the bisection's result, stopping at the first fall: the largest amplitude below which
    /// every grid point stood ("monotone"), which a pocket of survival above a fall does not
    /// set. Costs up to result / step more cases each.
    #[arg(long, value_name = "STEP")]
    pub monotone: Option<f64>,
    /// Longest time on the support edge still survived (s, full simulation).
    #[arg(long, default_value_t = Criteria::default().max_edge_time)]
    pub edge_time: f64,
    /// Largest CoM height drop of a robot still standing (m, full simulation).
    #[arg(long, default_value_t = Criteria::default().max_com_drop)]
    pub com_drop: f64,
    #[command(flatten)]
    pub runner: RunnerArgs,
    /// Full simulation's plant.
    #[arg(long, value_enum, default_value = "upc")]
    pub plant: PlantChoice,
    /// Output directory (default runs/capability-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub setup: CaseSetup,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
enum Model {
    Reduced,
    Full,
}

#[derive(Debug, Clone, Copy)]
struct Case {
    model: Model,
    variant: Variant,
    duration: f64,
    direction: Direction,
}

#[derive(Debug, Clone, serde::Serialize)]
struct Row {
    model: Model,
    controller: &'static str,
    duration: f64,
    direction: &'static str,
    #[serde(flatten)]
    capability: Capability,
    wall_time: f64,
}

pub fn run(args: CapabilityArgs) -> CliResult {
    let (variants, directions) = checked_lists(&args)?;
    let criteria = Criteria {
        max_edge_time: args.edge_time,
        max_com_drop: args.com_drop,
    };
    let robot = args.setup.robot.load()?;
    let config = args.setup.config.load(&robot, None, &[])?;
    let reduced = robot.reduced();
    let out = args.out.clone().unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        PathBuf::from(format!("runs/capability-{secs}"))
    });
    std::fs::create_dir_all(out.join("cases"))?;
    let cases = sweep_cases(&args, &variants, &directions);
    let per_case = 1
        + ((args.max / args.tol).log2().ceil().max(0.0) as u64)
        + args
            .monotone
            .map_or(0, |step| (args.max / step).ceil() as u64);
    // The Ray driver prints its own progress.
    let bar = runs_bar(
        args.quiet || args.runner.engine == RunnerKind::Ray,
        cases.len() as u64 * per_case,
    );
    let exe = std::env::current_exe()?;
    let sweep = Sweep {
        args: &args,
        config: &config,
        reduced,
        criteria: &criteria,
        runner: SweepRunner {
            args: &args.runner,
            out: &out,
            exe: &exe,
            bar: &bar,
            per_cell: per_case,
            quiet: args.quiet,
        },
    };
    let start = Instant::now();
    let mut failed = Vec::new();
    let rows = sweep.run(&cases, &mut failed);
    bar.finish_and_clear();
    let mut rows = rows?;
    let wall = start.elapsed().as_secs_f64();
    let order = |r: &Row| {
        (
            r.model as u8,
            r.direction,
            variants.iter().position(|v| v.label() == r.controller),
        )
    };
    rows.sort_by(|a, b| {
        order(a)
            .cmp(&order(b))
            .then(a.duration.total_cmp(&b.duration))
    });
    let engine = args.runner.describe(&out);
    write_outputs(
        &out,
        &args,
        &robot,
        &criteria,
        &rows,
        &variants,
        &directions,
        &failed,
        wall,
        &engine,
    )?;
    println!(
        "wrote {}/capability.md ({wall:.0} s, {engine})",
        out.display()
    );
    super::sweep_runner::failed_cells(&failed)
}

/// The controllers and directions named on the command line, once the search's values are
/// checked.
fn checked_lists(args: &CapabilityArgs) -> Result<(Vec<Variant>, Vec<Direction>), BoxError> {
    let variants = args
        .controllers
        .iter()
        .map(|c| {
            Variant::parse(c).ok_or_else(|| {
                format!("unknown controller `{c}` (c0, c1, c2, c1zmp, c0obs, c1raw)")
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let directions = args
        .directions
        .iter()
        .map(|d| match d.as_str() {
            "x" => Ok(Direction::X),
            "y" => Ok(Direction::Y),
            _ => Err(format!("unknown direction `{d}` (x, y)")),
        })
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(d) = args
        .durations
        .iter()
        .find(|d| !(d.is_finite() && **d > 0.0))
    {
        return Err(format!("impact durations must be > 0, got {d}").into());
    }
    if !(args.max > 0.0 && args.tol > 0.0) {
        return Err("--max and --tol must be > 0".into());
    }
    if let Some(step) = args.monotone
        && !(step.is_finite() && step > 0.0)
    {
        return Err(format!("--monotone must be > 0, got {step}").into());
    }
    Ok((variants, directions))
}

/// Every model × controller × direction × duration the sweep searches.
fn sweep_cases(args: &CapabilityArgs, variants: &[Variant], directions: &[Direction]) -> Vec<Case> {
    let models: &[Model] = match args.models {
        Models::Reduced => &[Model::Reduced],
        Models::Full => &[Model::Full],
        Models::Both => &[Model::Reduced, Model::Full],
    };
    let mut cases = Vec::new();
    for &model in models {
        for &variant in variants {
            // The door pushes the hand through its hinge, along the tangent of the hinge's
            // circle (x at the handle); pushes along y are applied at the hand instead
            // (`sim.push = "hand"`), which only upc's own simulator does.
            for &direction in directions.iter().filter(|&&d| {
                model == Model::Reduced || d == Direction::X || args.plant == PlantChoice::Upc
            }) {
                for &duration in &args.durations {
                    cases.push(Case {
                        model,
                        variant,
                        duration,
                        direction,
                    });
                }
            }
        }
    }
    cases
}

/// What every case of the sweep shares: the reduced models run in-process, the full
/// simulation's cells by the sweep runner.
struct Sweep<'a> {
    args: &'a CapabilityArgs,
    config: &'a upc::config::Config,
    reduced: upc::robot::ReducedModel,
    criteria: &'a Criteria,
    runner: SweepRunner<'a>,
}

impl Sweep<'_> {
    /// Every case's row; a full-simulation cell that failed is kept aside with its reason.
    fn run(
        &self,
        cases: &[Case],
        failed: &mut Vec<(String, String)>,
    ) -> Result<Vec<Row>, BoxError> {
        let (reduced, full): (Vec<Case>, Vec<Case>) =
            cases.iter().partition(|c| c.model == Model::Reduced);
        let mut rows = pool(&reduced, self.runner.args.jobs(), |c| {
            self.search_reduced(c)
        })?;
        let cells: Vec<CellArgs> = full.iter().map(|c| self.cell_args(c)).collect();
        for ((case, cell), result) in full.iter().zip(&cells).zip(self.runner.run(&cells)?) {
            match result.outcome {
                Outcome::Searched { capability, .. } => rows.push(Row {
                    model: Model::Full,
                    controller: case.variant.label(),
                    duration: case.duration,
                    direction: case.direction.label(),
                    capability,
                    wall_time: result.wall_time,
                }),
                Outcome::Failed { reason } => failed.push((cell.argv().join(" "), reason)),
            }
        }
        Ok(rows)
    }

    /// One case's bisection over [0, `--max`] on the reduced models.
    fn search_reduced(&self, case: &Case) -> Result<Row, BoxError> {
        let args = self.args;
        let t0 = Instant::now();
        let bar = self.runner.bar;
        let c = search(args.max, args.tol, args.monotone, |a: f64| {
            bar.inc(1);
            survives_reduced(
                self.config,
                self.reduced,
                case.variant,
                a,
                case.duration,
                case.direction,
            )
        })?;
        // The bar counted the longest search: settle the difference.
        bar.inc(self.runner.per_cell.saturating_sub(c.runs as u64));
        Ok(Row {
            model: Model::Reduced,
            controller: case.variant.label(),
            duration: case.duration,
            direction: case.direction.label(),
            capability: c,
            wall_time: t0.elapsed().as_secs_f64(),
        })
    }

    /// A full-simulation case's cell.
    fn cell_args(&self, case: &Case) -> CellArgs {
        let args = self.args;
        CellArgs {
            variant: case.variant,
            duration: case.duration,
            direction: case.direction,
            forecast_scale: 1.0,
            forecast_shift: 0.0,
            forecast_shape: upc::forecast::ForecastShape::Exact,
            phantom: false,
            max: args.max,
            tol: args.tol,
            monotone: args.monotone,
            edge_time: self.criteria.max_edge_time,
            com_drop: self.criteria.max_com_drop,
            plant: args.plant,
            setup: args.setup.clone(),
        }
        .absolute()
    }
}

/// A progress bar counting `len` simulation runs (hidden when `quiet`).
pub(super) fn runs_bar(quiet: bool, len: u64) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("[{bar:40}] {pos}/{len} runs, {elapsed} ({eta} left) {msg}")
            .map(|s| s.progress_chars("=> "))
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

#[allow(clippy::too_many_arguments)]
fn write_outputs(
    out: &Path,
    args: &CapabilityArgs,
    robot: &upc::robot::Robot,
    criteria: &Criteria,
    rows: &[Row],
    variants: &[Variant],
    directions: &[Direction],
    failed: &[(String, String)],
    wall: f64,
    engine: &str,
) -> Result<(), BoxError> {
    write_data(out, args, criteria, rows, failed, wall, engine)?;
    let fig_dir = out.join("figures");
    std::fs::create_dir_all(&fig_dir)?;
    let mut md = preamble(args, robot, criteria, wall, engine);
    super::sweep_runner::failed_section(&mut md, failed);
    for model in [Model::Reduced, Model::Full] {
        let of_model: Vec<&Row> = rows.iter().filter(|r| r.model == model).collect();
        if of_model.is_empty() {
            continue;
        }
        model_section(&mut md, &fig_dir, model, &of_model, variants, directions)?;
    }
    std::fs::write(out.join("capability.md"), md)?;
    Ok(())
}

/// `capability.json` (the rows and the sweep's settings) and `capability.csv`.
fn write_data(
    out: &Path,
    args: &CapabilityArgs,
    criteria: &Criteria,
    rows: &[Row],
    failed: &[(String, String)],
    wall: f64,
    engine: &str,
) -> Result<(), BoxError> {
    std::fs::write(
        out.join("capability.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "robot": args.setup.robot.robot,
            "plant": args.plant.name(),
            "criteria": criteria,
            "max": args.max,
            "tol": args.tol,
            "wall_time": wall,
            "engine": engine,
            "rows": rows,
            "failed_cells": super::sweep_runner::failed_json(failed),
        }))?,
    )?;
    let mut csv =
        String::from("model,controller,direction,duration,survived,failed,runs,monotone\n");
    for r in rows {
        csv += &format!(
            "{:?},{},{},{},{:.2},{},{},{}\n",
            r.model,
            r.controller,
            r.direction,
            r.duration,
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
    std::fs::write(out.join("capability.csv"), csv)?;
    Ok(())
}

/// The report's title, the impact and the survival criteria, and what the user layered over
/// the defaults.
fn preamble(
    args: &CapabilityArgs,
    robot: &upc::robot::Robot,
    criteria: &Criteria,
    wall: f64,
    engine: &str,
) -> String {
    let mut md = format!(
        "# Balance capability — robot `{}`, full simulation on the `{}` plant\n\n\
         Largest single impact on the hand survived (N), by bisection over [0, {}] N to {} N. \
         The impact: one raised-cosine pulse (half its duration rising, half falling) at t = \
         {} s, then {} s of recovery. Survived: on the reduced models, the ZMP never outside \
         the support (the linear model has no tipping to recover from); on the full simulation, standing at the end (CoM drop < {} mm), \
         at most {} s on the support edge, no whole-body QP fallback. \"≥\": the search's upper \
         bound was survived. C1+ZMP: C1 with the predicted ZMP kept inside the support by hard \
         constraints. Wall time of the sweep: {wall:.0} s, {engine}.\n\n",
        robot.name(),
        args.plant.name(),
        args.max,
        args.tol,
        upc::capability::IMPACT_START,
        upc::capability::RECOVERY,
        criteria.max_com_drop * 1e3,
        criteria.max_edge_time,
    );
    md += &args.setup.layers_md();
    if let Some(step) = args.monotone {
        md += &format!(
            "Monotone check (`--monotone {step}`): after each bisection, a grid of {step} N from \
             {step} N up to its result, stopping at the first fall. \"(monotone M)\": a fall lies \
             below the bisection's result, and M is the last grid point stood before it; the \
             bisection's figure is then a pocket of survival above a fall.\n\n"
        );
    }
    md
}

/// One model's rows (`of_model`, not empty): its table, direction × duration against the
/// controllers, and a figure per direction (written to `fig_dir`).
fn model_section(
    md: &mut String,
    fig_dir: &Path,
    model: Model,
    of_model: &[&Row],
    variants: &[Variant],
    directions: &[Direction],
) -> Result<(), BoxError> {
    let title = match model {
        Model::Reduced => "Reduced models",
        Model::Full => "Full simulation",
    };
    *md += &format!("## {title}\n\n");
    if model == Model::Full && directions.contains(&Direction::Y) {
        *md += "Along x the door pushes, as in the paper's scenarios. It pushes the hand \
               through its hinge, along the tangent of the hinge's circle (x at the handle): \
               a force along y is along the lever and would reach the hand as a tenth of \
               itself. Along y the force is applied at the hand itself, without the door \
               (`sim.push = \"hand\"`, upc's simulator only).\n\n";
    }
    let mut durations: Vec<f64> = of_model.iter().map(|r| r.duration).collect();
    durations.sort_by(f64::total_cmp);
    durations.dedup();
    let cell = |d: Direction, dur: f64, v: Variant| {
        of_model
            .iter()
            .find(|r| r.direction == d.label() && r.duration == dur && r.controller == v.label())
            .map(|r| r.capability)
    };
    let present: Vec<Direction> = directions
        .iter()
        .copied()
        .filter(|d| of_model.iter().any(|r| r.direction == d.label()))
        .collect();
    capability_table(md, &present, &durations, variants, &cell);
    for &d in &present {
        let series: Vec<Series> = variants
            .iter()
            .map(|&v| {
                let pts: Vec<(f64, f64)> = durations
                    .iter()
                    .filter_map(|&dur| cell(d, dur, v).map(|c| (dur, c.survived)))
                    .collect();
                Series::from_columns(
                    v.label(),
                    pts.iter().map(|p| p.0).collect(),
                    vec![(Quantity::MaxForce, pts.iter().map(|p| p.1).collect())],
                )
            })
            .collect();
        let sources: Vec<&dyn SeriesSource> =
            series.iter().map(|s| s as &dyn SeriesSource).collect();
        let model_tag = match model {
            Model::Reduced => "reduced",
            Model::Full => "full",
        };
        let fig = Figure {
            name: format!("capability_{model_tag}_{}", d.label()),
            title: format!("Largest impact survived along {} — {title}", d.label()),
            x_label: "impact duration (s)",
            panels: vec![Panel {
                title: "largest impact survived",
                y_label: "force (N)",
                scale: 1.0,
                lines: vec![Line::PerSource(Quantity::MaxForce)],
                support_axis: None,
            }],
        };
        if let Some(w) = write_figure(fig_dir, &fig, &sources, true)? {
            *md += &format!("![{}](figures/{})\n\n", w.title, w.svg);
        }
    }
    Ok(())
}

/// The table of one model: a line per direction and duration, the capability of each
/// controller (`cell`), and the ratios C1/C0, C2/C1.
fn capability_table(
    md: &mut String,
    present: &[Direction],
    durations: &[f64],
    variants: &[Variant],
    cell: &dyn Fn(Direction, f64, Variant) -> Option<Capability>,
) {
    *md += "| direction | duration (s) |";
    for v in variants {
        *md += &format!(" {} (N) |", v.label());
    }
    *md += " C1/C0 | C2/C1 |\n|---|---|";
    *md += &"---|".repeat(variants.len() + 2);
    *md += "\n";
    for &d in present {
        for &dur in durations {
            *md += &format!("| {} | {dur} |", d.label());
            for &v in variants {
                *md += &match cell(d, dur, v) {
                    Some(c) => format!(" {} |", c.text()),
                    None => " – |".into(),
                };
            }
            let ratio = |a: Variant, b: Variant| match (cell(d, dur, a), cell(d, dur, b)) {
                (Some(x), Some(y)) if y.survived > 0.0 => {
                    format!(" {:.2} |", x.survived / y.survived)
                }
                _ => " – |".into(),
            };
            *md += &ratio(Variant::C1, Variant::C0);
            *md += &ratio(Variant::C2, Variant::C1);
            *md += "\n";
        }
    }
    *md += "\n";
}
