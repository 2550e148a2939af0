//! One cell of a full-simulation sweep (`upc capability --models full`, `upc robustness`): the
//! bisection of one controller × impact × forecast over the amplitude, each case an `upc run`.
//! The one definition of a cell ([`CellArgs`], its command line) and of its result
//! ([`CellResult`]) whichever engine runs it (docs/sweeps.md): the local pool calls [`search`]
//! in-process, a Ray task runs `upc sweep-cell` on a worker and hands its JSON back.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use upc::capability::{Capability, Criteria, Direction, Variant, impact_toml, survived_full};
use upc::config::ControllerKind;
use upc::forecast::ForecastShape;

use super::argv::{Argv, ToArgv, fields};
use super::common::{CaseSetup, ConfigArgs};
use super::run::{CpuLayout, RunArgs, Which};
use super::sim::PlantChoice;
use super::{BoxError, CliResult};

/// One cell: what is searched, against which criteria, on which robot, plant and config.
#[derive(clap::Args, Debug, Clone)]
pub struct CellArgs {
    /// The controller.
    #[arg(long = "controller", value_enum)]
    pub variant: Variant,
    /// Impact duration (s).
    #[arg(long)]
    pub duration: f64,
    /// Push direction.
    #[arg(long, value_enum, default_value = "x")]
    pub direction: Direction,
    /// The forecast is `scale × F(t − shift)` (`upc run --forecast-error-scale`).
    #[arg(long, default_value_t = 1.0)]
    pub forecast_scale: f64,
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub forecast_shift: f64,
    /// The forecast's shape (`upc run --forecast-error-shape`).
    #[arg(long, default_value = "exact")]
    pub forecast_shape: ForecastShape,
    /// The plant does not push at all (`sim.push = "none"`): the forecast is a phantom, and the
    /// result keeps the summary of the case at `--max`.
    #[arg(long)]
    pub phantom: bool,
    /// Upper bound of the search (N).
    #[arg(long)]
    pub max: f64,
    /// Bisection tolerance (N).
    #[arg(long)]
    pub tol: f64,
    /// Step of the monotone check below the bisection's result (N; `upc capability --monotone`).
    #[arg(long)]
    pub monotone: Option<f64>,
    /// Longest time on the support edge still survived (s).
    #[arg(long)]
    pub edge_time: f64,
    /// Largest CoM drop of a robot still standing (m).
    #[arg(long)]
    pub com_drop: f64,
    #[arg(long, value_enum, default_value = "upc")]
    pub plant: PlantChoice,
    #[command(flatten)]
    pub setup: CaseSetup,
}

impl ToArgv for CellArgs {
    fn write(&self, w: &mut Argv) {
        let CellArgs {
            variant,
            duration,
            direction,
            forecast_scale,
            forecast_shift,
            forecast_shape,
            phantom,
            max,
            tol,
            monotone,
            edge_time,
            com_drop,
            plant,
            setup,
        } = self;
        fields!(w; choice variant, val duration, choice direction, val forecast_scale,
                val forecast_shift, val forecast_shape, switch phantom, val max, val tol,
                opt monotone, val edge_time, val com_drop, choice plant);
        w.nested(setup);
    }
}

impl CellArgs {
    pub fn criteria(&self) -> Criteria {
        Criteria {
            max_edge_time: self.edge_time,
            max_com_drop: self.com_drop,
        }
    }

    /// The cell as `upc sweep-cell` is given it: its identity in the saved results.
    pub fn argv(&self) -> Vec<String> {
        Argv::of("sweep-cell", self)
            .into_iter()
            .map(|w| w.to_string_lossy().into_owned())
            .collect()
    }

    /// Paths made absolute, so that the cell means the same from any working directory (a
    /// worker of a cluster on a shared filesystem).
    pub fn absolute(mut self) -> Self {
        let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        for c in &mut self.setup.config.configs {
            *c = abs(c);
        }
        if Path::new(&self.setup.robot.robot).is_file() {
            self.setup.robot.robot = abs(Path::new(&self.setup.robot.robot))
                .display()
                .to_string();
        }
        self
    }
}

/// `upc sweep-cell`: one cell searched, its [`CellResult`] as JSON on stdout (the engine's task).
#[derive(clap::Args, Debug)]
pub struct SweepCellArgs {
    #[command(flatten)]
    pub cell: CellArgs,
    /// Where the cases' scenarios and run directories go (each removed once read).
    #[arg(long)]
    pub scratch: PathBuf,
}

/// What a cell gave.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The search's result; a phantom's keeps the CoM drop (m) and least CoP margin (m) of its
    /// case at the bound.
    Searched {
        capability: Capability,
        at_max: Option<(f64, f64)>,
    },
    /// A case of the cell could not run (the plant refused it, a process crashed): the cell is
    /// reported with this reason, never counted as survived and never retried (it would fail
    /// again).
    Failed { reason: String },
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CellResult {
    pub outcome: Outcome,
    /// The search's own wall time (s), cases included.
    pub wall_time: f64,
}

pub fn run(args: SweepCellArgs) -> CliResult {
    std::fs::create_dir_all(&args.scratch)?;
    let result = search(&std::env::current_exe()?, &args.cell, &args.scratch, &|| {});
    println!("{}", serde_json::to_string(&result)?);
    Ok(())
}

/// The cell's bisection over `[0, max]` (with its monotone check), each case an `upc run` of
/// `exe` under `scratch`; `on_run` is called before each case.
pub fn search(exe: &Path, cell: &CellArgs, scratch: &Path, on_run: &dyn Fn()) -> CellResult {
    let t0 = Instant::now();
    let criteria = cell.criteria();
    let mut at_max = None;
    let mut survives = |a: f64| -> Result<bool, BoxError> {
        on_run();
        let r = full_case(exe, cell, scratch, a, &criteria)?;
        if a == cell.max && cell.phantom {
            let num = |k: &str| {
                r.summary
                    .as_ref()
                    .and_then(|s| s.get(k))
                    .and_then(serde_json::Value::as_f64)
                    .unwrap_or(f64::NAN)
            };
            at_max = Some((num("com_height_drop"), num("min_zmp_margin")));
        }
        Ok(r.survived)
    };
    let outcome = match upc::capability::search(cell.max, cell.tol, cell.monotone, &mut survives) {
        Ok(capability) => Outcome::Searched { capability, at_max },
        Err(e) => Outcome::Failed {
            reason: e.to_string(),
        },
    };
    CellResult {
        outcome,
        wall_time: t0.elapsed().as_secs_f64(),
    }
}

/// What a case gave: survived, and the controller's summary when it wrote one.
struct CaseResult {
    survived: bool,
    summary: Option<serde_json::Value>,
}

/// One case of `cell`: `upc run` of its impact of `amplitude` N, under `scratch`.
fn full_case(
    exe: &Path,
    cell: &CellArgs,
    scratch: &Path,
    amplitude: f64,
    criteria: &Criteria,
) -> Result<CaseResult, BoxError> {
    let name = format!(
        "{}_{}_{:.0}ms_{amplitude:.2}N_k{}_s{:.0}ms{}{}",
        cell.variant.label().replace(['+', ' '], "_"),
        cell.direction.label(),
        cell.duration * 1e3,
        cell.forecast_scale,
        cell.forecast_shift * 1e3,
        if cell.phantom { "_phantom" } else { "" },
        match cell.forecast_shape {
            ForecastShape::Exact => String::new(),
            s => format!("_{}", s.to_string().replace([':', '.', '-'], "_")),
        }
    );
    let scenario = scratch.join(format!("{name}.toml"));
    std::fs::write(
        &scenario,
        impact_toml(amplitude, cell.duration, cell.direction),
    )?;
    let run = case_run_args(cell, &name, &scenario, scratch);
    let mut cmd = Command::new(exe);
    cmd.args(Argv::of("run", &run)).env("RUST_LOG", "warn");
    super::child::dies_with_parent(&mut cmd);
    let status = cmd.output()?;
    let run_dir = scratch.join(&name).join(cell.variant.kind().name());
    let result = case_result(cell, &name, &run_dir, status.status, criteria);
    // The sweep makes hundreds of run directories: none is kept.
    let _ = std::fs::remove_dir_all(scratch.join(&name));
    let _ = std::fs::remove_file(&scenario);
    result
}

/// The `upc run` of a case named `name`, its scenario written at `scenario`, its run directory
/// under `dir`.
fn case_run_args(cell: &CellArgs, name: &str, scenario: &Path, dir: &Path) -> RunArgs {
    let mut sim_sets = cell.setup.sim_sets.clone();
    if cell.direction == Direction::Y {
        sim_sets.push("sim.push=\"hand\"".to_string());
    }
    if cell.phantom {
        sim_sets.push("sim.push=\"none\"".to_string());
    }
    RunArgs {
        scenario: scenario.display().to_string(),
        controller: match cell.variant.kind() {
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
        // Cells run side by side and are judged on their outcome, not their tick.
        cpus: CpuLayout::Shared,
        forecast_error_scale: cell.forecast_scale,
        forecast_error_shift: cell.forecast_shift,
        forecast_error_shape: cell.forecast_shape,
        config: ConfigArgs {
            configs: cell.setup.config.configs.clone(),
            sets: cell
                .setup
                .config
                .sets
                .iter()
                .cloned()
                .chain(cell.variant.config_set().iter().map(|s| s.to_string()))
                .collect(),
        },
        sim_sets,
        plant: cell.plant,
        sensing: cell.setup.sensing,
        robot: cell.setup.robot.clone(),
        bus: None,
        bus_settings: Default::default(),
    }
}

/// What a finished case's run directory `run_dir` says, the process having ended with
/// `status`; an error when the case never ran or was killed (the cell fails).
fn case_result(
    cell: &CellArgs,
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
    // (which would read as a fall). Either way the cell fails. Whether any tick ran is read
    // from the summary, else from the controller's CSV (a header only: none did).
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
            let end = upc::capability::IMPACT_START + cell.duration + upc::capability::RECOVERY;
            let complete = num(&v, "sim_time") >= end - 0.01;
            CaseResult {
                survived: complete && survived_full(&v, criteria),
                summary: Some(v),
            }
        }
        // A run whose controller ticked but wrote no summary: a fall of the case (a simulation
        // that diverged) when the process exited; killed by a signal, the cell fails.
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
