//! `upc capability`: how hard the robot can be pushed. For each controller, impact duration
//! and direction, the largest single impact survived, by bisection over the amplitude
//! (`upc::capability`), on the reduced models (in-process) and on the full simulation (each
//! case an `upc run` of its own, run `--jobs` at a time). Writes `capability.md`, `.csv`,
//! `.json` and one figure per model and direction.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use upc::capability::{
    Capability, Criteria, Direction, Variant, impact_toml, search, survived_full, survives_reduced,
};
use upc::config::ControllerKind;
use upc::report::figures::{Figure, Line, Panel, write_figure};
use upc::report::series::{Quantity, Series, SeriesSource};

use super::CliResult;
use super::argv::Argv;
use super::common::{ConfigArgs, RobotArg};
use super::run::{RunArgs, Which};
use super::sim::PlantChoice;

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
    /// Cases run at once (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Full simulation's plant.
    #[arg(long, value_enum, default_value = "upc")]
    pub plant: PlantChoice,
    /// Output directory (default runs/capability-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// What the plant publishes: its truth, or through the sensor models (docs/sensing.md).
    #[arg(long, value_enum)]
    pub sensing: Option<upc::sim::sensors::Sensing>,
    /// Every case's plant config key (`upc run --sim-set`), e.g. `sim.sensors.seed=2`.
    #[arg(long = "sim-set", value_name = "KEY=VALUE")]
    pub sim_sets: Vec<String>,
    #[command(flatten)]
    pub robot: RobotArg,
    /// Config files and `--set` keys for every case's controller (the variant's own key last).
    #[command(flatten)]
    pub config: ConfigArgs,
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

pub(super) type BoxError = Box<dyn std::error::Error + Send + Sync>;

pub fn run(args: CapabilityArgs) -> CliResult {
    let (variants, directions) = checked_lists(&args)?;
    let criteria = Criteria {
        max_edge_time: args.edge_time,
        max_com_drop: args.com_drop,
    };
    let robot = args.robot.load()?;
    let config = args.config.load(&robot, None, &[])?;
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
    let bar = runs_bar(args.quiet, cases.len() as u64 * per_case);
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let exe = std::env::current_exe()?;
    let sweep = Sweep {
        args: &args,
        config: &config,
        reduced,
        criteria: &criteria,
        exe: &exe,
        out: &out,
        per_case,
        bar: &bar,
    };
    let start = Instant::now();
    let rows = sweep.run(cases, jobs);
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
    write_outputs(
        &out,
        &args,
        &robot,
        &criteria,
        &rows,
        &variants,
        &directions,
        wall,
        jobs,
    )?;
    println!(
        "wrote {}/capability.md ({wall:.0} s, {jobs} at a time)",
        out.display()
    );
    Ok(())
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
/// simulation as an `upc run` each.
struct Sweep<'a> {
    args: &'a CapabilityArgs,
    config: &'a upc::config::Config,
    reduced: upc::robot::ReducedModel,
    criteria: &'a Criteria,
    exe: &'a Path,
    out: &'a Path,
    /// Runs the progress bar counts per case (the longest search).
    per_case: u64,
    bar: &'a ProgressBar,
}

impl Sweep<'_> {
    /// Searches every case, `jobs` at a time, taken from the end of `cases`; the first error
    /// stops the sweep.
    fn run(&self, cases: Vec<Case>, jobs: usize) -> Result<Vec<Row>, BoxError> {
        let queue = Mutex::new(cases);
        let rows = Mutex::new(Vec::<Row>::new());
        let first_error = Mutex::new(None::<String>);
        std::thread::scope(|scope| {
            for _ in 0..jobs {
                scope.spawn(|| {
                    loop {
                        let Some(case) = queue.lock().unwrap_or_else(|p| p.into_inner()).pop()
                        else {
                            return;
                        };
                        match self.search_case(case) {
                            Ok(row) => rows.lock().unwrap_or_else(|p| p.into_inner()).push(row),
                            Err(e) => {
                                let mut first =
                                    first_error.lock().unwrap_or_else(|p| p.into_inner());
                                first.get_or_insert(format!("{case:?}: {e}"));
                                return;
                            }
                        }
                    }
                });
            }
        });
        if let Some(e) = first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e.into());
        }
        Ok(rows.into_inner().unwrap_or_else(|p| p.into_inner()))
    }

    /// One case's bisection over [0, `--max`].
    fn search_case(&self, case: Case) -> Result<Row, BoxError> {
        let args = self.args;
        let t0 = Instant::now();
        let mut survives = |a: f64| -> Result<bool, BoxError> {
            self.bar.inc(1);
            match case.model {
                Model::Reduced => Ok(survives_reduced(
                    self.config,
                    self.reduced,
                    case.variant,
                    a,
                    case.duration,
                    case.direction,
                )?),
                Model::Full => full_case(
                    self.exe,
                    &FullCase {
                        robot: &args.robot.robot,
                        plant: args.plant,
                        variant: case.variant,
                        duration: case.duration,
                        direction: case.direction,
                        forecast: ForecastCase::EXACT,
                        config: &args.config,
                        sensing: args.sensing,
                        sim_sets: &args.sim_sets,
                    },
                    self.out,
                    a,
                    self.criteria,
                )
                .map(|r| r.survived),
            }
        };
        let c = search(args.max, args.tol, args.monotone, &mut survives)?;
        // The bar counted the longest search: settle the difference.
        self.bar.inc(self.per_case.saturating_sub(c.runs as u64));
        Ok(Row {
            model: case.model,
            controller: case.variant.label(),
            duration: case.duration,
            direction: case.direction.label(),
            capability: c,
            wall_time: t0.elapsed().as_secs_f64(),
        })
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

/// How a full-simulation case's forecast departs from the impact the plant plays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ForecastCase {
    /// The forecast is `scale × F(t − shift)`.
    pub scale: f64,
    pub shift: f64,
    /// The plant does not push at all (`sim.push = "none"`): the forecast is a phantom.
    pub phantom: bool,
    /// The forecast's shape (`upc run --forecast-error-shape`; exact on the κ × τ map).
    pub shape: upc::forecast::ForecastShape,
}

impl ForecastCase {
    pub const EXACT: ForecastCase = ForecastCase {
        scale: 1.0,
        shift: 0.0,
        phantom: false,
        shape: upc::forecast::ForecastShape::Exact,
    };
}

/// One full-simulation case.
pub(super) struct FullCase<'a> {
    pub robot: &'a str,
    pub plant: PlantChoice,
    pub variant: Variant,
    pub duration: f64,
    pub direction: Direction,
    pub forecast: ForecastCase,
    /// The user's config files and `--set` keys.
    pub config: &'a ConfigArgs,
    pub sensing: Option<upc::sim::sensors::Sensing>,
    /// The user's plant config keys.
    pub sim_sets: &'a [String],
}

/// What a full-simulation case gave: survived, and the controller's summary when it wrote one.
pub(super) struct CaseResult {
    pub survived: bool,
    pub summary: Option<serde_json::Value>,
}

/// One full-simulation case: `upc run` of the impact with the variant's controller.
pub(super) fn full_case(
    exe: &Path,
    case: &FullCase,
    out: &Path,
    amplitude: f64,
    criteria: &Criteria,
) -> Result<CaseResult, BoxError> {
    let f = case.forecast;
    let name = format!(
        "{}_{}_{:.0}ms_{amplitude:.2}N_k{}_s{:.0}ms{}{}",
        case.variant.label().replace(['+', ' '], "_"),
        case.direction.label(),
        case.duration * 1e3,
        f.scale,
        f.shift * 1e3,
        if f.phantom { "_phantom" } else { "" },
        match f.shape {
            upc::forecast::ForecastShape::Exact => String::new(),
            s => format!("_{}", s.to_string().replace([':', '.', '-'], "_")),
        }
    );
    let dir = out.join("cases");
    let scenario = dir.join(format!("{name}.toml"));
    std::fs::write(
        &scenario,
        impact_toml(amplitude, case.duration, case.direction),
    )?;
    let kind = case.variant.kind();
    let run = case_run_args(case, &name, &scenario, &dir);
    let mut cmd = Command::new(exe);
    cmd.args(Argv::of("run", &run)).env("RUST_LOG", "warn");
    let status = cmd.output()?;
    let run_dir = dir.join(&name).join(kind.name());
    let result = case_result(case, &name, &run_dir, status.status, criteria)?;
    // Keep the directory only for inspection of the last cases; the sweep makes hundreds.
    let _ = std::fs::remove_dir_all(dir.join(&name));
    let _ = std::fs::remove_file(&scenario);
    Ok(result)
}

/// The `upc run` of a case named `name`, its scenario written at `scenario`, its run directory
/// under `dir`.
fn case_run_args(case: &FullCase, name: &str, scenario: &Path, dir: &Path) -> RunArgs {
    let f = case.forecast;
    let mut sim_sets = case.sim_sets.to_vec();
    if case.direction == Direction::Y {
        sim_sets.push("sim.push=\"hand\"".to_string());
    }
    if f.phantom {
        sim_sets.push("sim.push=\"none\"".to_string());
    }
    RunArgs {
        scenario: scenario.display().to_string(),
        controller: match case.variant.kind() {
            ControllerKind::C0 => Which::C0,
            ControllerKind::C1 => Which::C1,
            ControllerKind::C2 => Which::C2,
        },
        realtime: false,
        duration: None,
        name: Some(name.to_owned()),
        out: dir.to_path_buf(),
        forecaster: None,
        forecaster_over_zenoh: false,
        no_forecaster: false,
        viewer: false,
        connect: None,
        quiet: true,
        forecast_error_scale: f.scale,
        forecast_error_shift: f.shift,
        forecast_error_shape: f.shape,
        config: ConfigArgs {
            configs: case.config.configs.clone(),
            sets: case
                .config
                .sets
                .iter()
                .cloned()
                .chain(case.variant.config_set().map(str::to_owned))
                .collect(),
        },
        sim_sets,
        plant: case.plant,
        sensing: case.sensing,
        robot: RobotArg {
            robot: case.robot.to_owned(),
        },
        bus: None,
        bus_settings: Default::default(),
    }
}

/// What a finished case's run directory `run_dir` says, the process having ended with
/// `status`; an error when the case never ran or was killed (the sweep cannot go on).
fn case_result(
    case: &FullCase,
    name: &str,
    run_dir: &Path,
    status: std::process::ExitStatus,
    criteria: &Criteria,
) -> Result<CaseResult, BoxError> {
    let summary = std::fs::read_to_string(run_dir.join("controller.json"));
    let parsed: Option<serde_json::Value> = match &summary {
        Ok(text) => Some(serde_json::from_str(text)?),
        Err(_) => None,
    };
    let num = |v: &serde_json::Value, k: &str| {
        v.get(k).and_then(serde_json::Value::as_f64).unwrap_or(0.0)
    };
    // A case the plant refused never ran: its controller got no state. It wrote a summary of
    // zeros (which would read as a robot that stood), or none when `upc run` stopped it first
    // (which would read as a fall). Either way the sweep cannot go on. Whether any tick ran is
    // read from the summary, else from the controller's CSV (a header only: none did).
    let ticked = match &parsed {
        Some(v) => num(v, "ticks") > 0.0,
        None => std::fs::read_to_string(run_dir.join("controller.csv"))
            .map(|t| t.lines().nth(1).is_some())
            .unwrap_or(false),
    };
    if !ticked {
        let last = std::fs::read_to_string(run_dir.join("sim.log"))
            .ok()
            .and_then(|t| {
                t.lines()
                    .rev()
                    .find(|l| !l.trim().is_empty())
                    .map(str::to_owned)
            })
            .unwrap_or_default();
        return Err(format!(
            "{name}: the case never ran (no state reached the controller); the plant said: {last}"
        )
        .into());
    }
    let result = match parsed {
        Some(v) => {
            // A run that stopped before the scenario's end (a simulation that diverged) did not
            // survive, however little the robot had moved by then.
            let end = upc::capability::IMPACT_START + case.duration + upc::capability::RECOVERY;
            let complete = num(&v, "sim_time") >= end - 0.01;
            CaseResult {
                survived: complete && survived_full(&v, criteria),
                summary: Some(v),
            }
        }
        // A run whose controller ticked but wrote no summary: a failure of the case, not of the
        // sweep, when the process ran (a simulation that diverged); otherwise the sweep cannot
        // go on.
        None if status.code().is_some() => {
            tracing::debug!("{name}: no controller summary");
            CaseResult {
                survived: false,
                summary: None,
            }
        }
        None => return Err(format!("{name}: the run was killed by a signal").into()),
    };
    Ok(result)
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
    wall: f64,
    jobs: usize,
) -> Result<(), BoxError> {
    write_data(out, args, criteria, rows, wall, jobs)?;
    let fig_dir = out.join("figures");
    std::fs::create_dir_all(&fig_dir)?;
    let mut md = preamble(args, robot, criteria, wall, jobs);
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
    wall: f64,
    jobs: usize,
) -> Result<(), BoxError> {
    std::fs::write(
        out.join("capability.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "robot": args.robot.robot,
            "plant": args.plant.name(),
            "criteria": criteria,
            "max": args.max,
            "tol": args.tol,
            "wall_time": wall,
            "jobs": jobs,
            "rows": rows,
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
    jobs: usize,
) -> String {
    let mut md = format!(
        "# Balance capability — robot `{}`, full simulation on the `{}` plant\n\n\
         Largest single impact on the hand survived (N), by bisection over [0, {}] N to {} N. \
         The impact: one raised-cosine pulse (half its duration rising, half falling) at t = \
         {} s, then {} s of recovery. Survived: on the reduced models, the ZMP never outside \
         the support (the linear model has no tipping to recover from); on the full simulation, standing at the end (CoM drop < {} mm), \
         at most {} s on the support edge, no whole-body QP fallback. \"≥\": the search's upper \
         bound was survived. C1+ZMP: C1 with the predicted ZMP kept inside the support by hard \
         constraints. Wall time of the sweep: {wall:.0} s, {jobs} cases at a time.\n\n",
        robot.name(),
        args.plant.name(),
        args.max,
        args.tol,
        upc::capability::IMPACT_START,
        upc::capability::RECOVERY,
        criteria.max_com_drop * 1e3,
        criteria.max_edge_time,
    );
    // What the user layered over the defaults, so a table is never read as the defaults'.
    for f in &args.config.configs {
        md += &format!("Config file: `{}`\n\n", f.display());
    }
    for kv in &args.config.sets {
        md += &format!("Config: `--set {kv}`\n\n");
    }
    if let Some(s) = args.sensing {
        md += &format!("Sensing: `{}` (docs/sensing.md)\n\n", s.name());
    }
    for kv in &args.sim_sets {
        md += &format!("Plant: `--sim-set {kv}`\n\n");
    }
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
