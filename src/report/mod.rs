//! `upc compare`: a Markdown report with figures (the paper's Figs. 7–14: ZMP with the support
//! bounds, hand tracking error, CoM, K_p, C0 / C1 / C2 overlaid) and metrics tables, for run
//! directories of `upc run`, plus the same on the reduced models run in-process.
//!
//! - [`series`]: time series behind one trait, from `controller.csv` or the reduced loop;
//! - [`figures`]: SVG and PNG figures (plotters);
//! - [`rundir`]: reading a run directory; [`reduced`]: the reduced-model runs;
//! - [`markdown`]: the report's text;
//! - [`csv`]: the one reader of the runs' CSV logs.
//!
//! And the after-run analysis of a lockstep run's two logs (`controller.csv` against the
//! plant's truth in `sim.csv`), which `upc run` writes to `run.json`: the base estimate's error
//! ([`base_accuracy`]), the contact and hand wrenches' ([`wrench_accuracy`]) and the true
//! centre of pressure's margin ([`true_margin`]).

mod base_accuracy;
pub mod csv;
pub mod figures;
pub mod markdown;
pub mod reduced;
pub mod rundir;
pub mod series;
mod true_margin;
mod wrench_accuracy;

use std::fmt::Write;
use std::path::PathBuf;

use crate::config::ConfigError;
use crate::preview::PreviewError;
use crate::robot::Robot;
use crate::scenario::Scenario;
pub use base_accuracy::{BaseAccuracy, base_accuracy};
pub use reduced::ConfigLayers;
use rundir::RunDir;
use series::{Series, SeriesSource};
pub use true_margin::{TrueMargin, true_margin};
pub use wrench_accuracy::{ErrorStats, HandSource, WrenchAccuracy, wrench_accuracy};

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}, line {line}: {message}", path.display())]
    Csv {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{}: {message}", path.display())]
    Summary { path: PathBuf, message: String },
    #[error("cannot draw {}: {message}", path.display())]
    Plot { path: PathBuf, message: String },
    #[error("reduced models, scenario {scenario}, {controller}: {source}")]
    Preview {
        scenario: String,
        controller: String,
        source: PreviewError,
    },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("no run directory given")]
    NoRuns,
    #[error("robot of the run: {0}")]
    Robot(#[from] crate::robot::RobotError),
}

/// What `compare` does beyond the run directories.
#[derive(Debug, Clone)]
pub struct CompareOptions {
    /// Where `report.md` and `figures/` go.
    pub out: PathBuf,
    /// Config layers added to each run's own (files after the run's files, sets after its sets).
    pub config: ConfigLayers,
    /// Run and report the reduced models.
    pub reduced: bool,
    /// Write PNGs besides the SVGs (when the font loads).
    pub png: bool,
    /// Overlay every run's controllers in one section (the conditions of one experiment).
    pub overlay: bool,
}

/// What `compare` wrote.
#[derive(Debug, Clone)]
pub struct CompareOutput {
    pub report: PathBuf,
    /// Every figure file written (SVG and PNG).
    pub figures: Vec<PathBuf>,
    /// Whether PNGs were written (false when the font is missing or PNGs were not asked for).
    pub png: bool,
}

/// The scenario of a run, as the run loaded it (its recorded source first, then its name),
/// its forces scaled to the run's robot, cut to the simulated duration so that both test beds
/// cover the same time.
fn run_scenario(run: &RunDir, robot: &Robot) -> Result<Scenario, String> {
    let mut scenario = match &run.scenario_source {
        Some(src) => robot
            .scenario(src)
            .or_else(|_| robot.scenario(&run.scenario)),
        None => robot.scenario(&run.scenario),
    }
    .map_err(|e| e.to_string())?;
    scenario.duration = run.duration;
    Ok(scenario)
}

/// How a section with several runs names each: by its plant, or by its name.
type RunLabel = fn(&RunDir) -> String;

/// A file-name-safe tag.
fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Write `<out>/report.md` and `<out>/figures/` for the given run directories.
pub fn compare(runs: &[PathBuf], opts: &CompareOptions) -> Result<CompareOutput, ReportError> {
    if runs.is_empty() {
        return Err(ReportError::NoRuns);
    }
    // Read everything first: a bad input fails before any file is written.
    let dirs = runs
        .iter()
        .map(|p| RunDir::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let fig_dir = opts.out.join("figures");
    std::fs::create_dir_all(&fig_dir).map_err(|source| ReportError::Io {
        path: fig_dir.clone(),
        source,
    })?;
    let png = opts.png && figures::font_available();
    let mut figs = FigureWriter {
        dir: fig_dir,
        png,
        files: Vec::new(),
    };
    let scenarios = scenarios_of(&dirs);
    let mut md = preamble(&scenarios);
    md += &side_by_side_section(&dirs, opts, &scenarios, &mut figs)?;
    let mut used_tags = Vec::<String>::new();
    // Reduced sections already written: (scenario, duration and config layers, the run).
    let mut reduced_done: Vec<(String, String)> = Vec::new();
    for run in &dirs {
        let mut tag = slug(&run.name);
        while used_tags.contains(&tag) {
            tag.push('_');
        }
        used_tags.push(tag.clone());
        let robot = Robot::load(&run.robot)?;
        let scenario = run_scenario(run, &robot);
        md += &full_section(run, &tag, scenario.as_ref().ok(), &mut figs)?;
        if opts.reduced {
            md += &reduced_section(
                run,
                &tag,
                &robot,
                scenario,
                opts,
                &mut reduced_done,
                &mut figs,
            )?;
        }
    }
    if !png {
        md += "\nFigures are SVG only: no PNG was written (PNGs not asked for, or the font \
               could not be loaded).\n";
    }
    let report = opts.out.join("report.md");
    std::fs::write(&report, md).map_err(|source| ReportError::Io {
        path: report.clone(),
        source,
    })?;
    Ok(CompareOutput {
        report,
        figures: figs.files,
        png,
    })
}

/// Writes the standard figures into `dir`, keeping the files written.
struct FigureWriter {
    dir: PathBuf,
    /// PNGs besides the SVGs.
    png: bool,
    /// Every figure file written (SVG and PNG).
    files: Vec<PathBuf>,
}

impl FigureWriter {
    /// The standard figures of `sources` (file names from `prefix`, titles naming `what`), and
    /// the report's block showing them.
    fn write(
        &mut self,
        prefix: &str,
        what: &str,
        sources: &[&dyn SeriesSource],
    ) -> Result<String, ReportError> {
        let mut written = Vec::new();
        for fig in figures::standard_figures(prefix, what) {
            if let Some(w) = figures::write_figure(&self.dir, &fig, sources, self.png)? {
                self.files.push(self.dir.join(&w.svg));
                if let Some(p) = &w.png {
                    self.files.push(self.dir.join(p));
                }
                written.push(w);
            }
        }
        Ok(markdown::figures_block(&written))
    }
}

/// The runs' scenarios, each once, in the runs' order.
fn scenarios_of(dirs: &[RunDir]) -> Vec<String> {
    let mut v: Vec<String> = Vec::new();
    for d in dirs {
        if !v.contains(&d.scenario) {
            v.push(d.scenario.clone());
        }
    }
    v
}

/// The report's title and what its controllers and test beds are.
fn preamble(scenarios: &[String]) -> String {
    let mut md = format!("# upc compare — {}\n\n", scenarios.join(", "));
    md += "C0: ZMP preview control, disturbance ignored. C1: with the hand force forecast turned \
           into a CoM disturbance by the hand previewer. C2: C1 with the hand gains optimised \
           over the horizon. Full simulation: the multibody humanoid and door simulator, the \
           controller process and whole-body QP, as run by `upc run`. Reduced models: the \
           controllers' own cart-table and hand impedance models as plants (`upc preview`).\n\n";
    md
}

/// One scenario and robot on several plants: the comparison the runs were made for; or any
/// runs overlaid when asked (the conditions of one experiment). Empty otherwise.
fn side_by_side_section(
    dirs: &[RunDir],
    opts: &CompareOptions,
    scenarios: &[String],
    figs: &mut FigureWriter,
) -> Result<String, ReportError> {
    let mut plants: Vec<&str> = Vec::new();
    for d in dirs {
        if !plants.contains(&d.plant.as_str()) {
            plants.push(&d.plant);
        }
    }
    let side_by_side: Option<(&str, RunLabel)> = if plants.len() > 1 {
        Some(("plant", |d| d.plant.clone()))
    } else if opts.overlay && dirs.len() > 1 {
        Some(("run", |d| d.name.clone()))
    } else {
        None
    };
    let Some((what, label)) = side_by_side else {
        return Ok(String::new());
    };
    let mut md = String::new();
    let labels: Vec<String> = dirs.iter().map(label).collect();
    let _ = writeln!(md, "## Side by side, by {what}: {}\n", labels.join(", "));
    let all: Vec<&RunDir> = dirs.iter().collect();
    md += &markdown::side_by_side_table(&all, what, label);
    md += "\n";
    let relabelled: Vec<Series> = dirs
        .iter()
        .flat_map(|d| {
            d.controllers.iter().map(move |c| {
                let mut s = c.csv.series.clone();
                s.label = format!("{} ({})", c.name.to_uppercase(), label(d));
                s
            })
        })
        .collect();
    let sources: Vec<&dyn SeriesSource> =
        relabelled.iter().map(|s| s as &dyn SeriesSource).collect();
    md += &figs.write(
        "side_by_side",
        &format!("{}, every {what}", scenarios.join(", ")),
        &sources,
    )?;
    Ok(md)
}

/// A run's section: its scenario, and its full simulation's metrics and figures.
fn full_section(
    run: &RunDir,
    tag: &str,
    scenario: Option<&Scenario>,
    figs: &mut FigureWriter,
) -> Result<String, ReportError> {
    let mut md = String::new();
    let _ = writeln!(md, "## {} — `{}`\n", run.scenario, run.path.display());
    md += &markdown::scenario_block(run, scenario);

    md += "### Full simulation: metrics\n\n";
    md += &markdown::full_metrics_table(run);
    md += "\n### Full simulation: figures\n\n";
    if run
        .controllers
        .iter()
        .all(|c| c.csv.series.support().is_none())
    {
        md += "The CSVs of this run have no support columns: the ZMP figures show no \
               support bounds.\n\n";
    }
    let sources: Vec<&dyn SeriesSource> = run
        .controllers
        .iter()
        .map(|c| &c.csv.series as &dyn SeriesSource)
        .collect();
    md += &figs.write(tag, &format!("{}, full simulation", run.scenario), &sources)?;
    Ok(md)
}

/// A run's reduced-model section: its scenario run in-process on C0, C1 and C2 under the
/// run's config layers and the added ones; once per scenario, duration and config (`done`).
fn reduced_section(
    run: &RunDir,
    tag: &str,
    robot: &Robot,
    scenario: Result<Scenario, String>,
    opts: &CompareOptions,
    done: &mut Vec<(String, String)>,
    figs: &mut FigureWriter,
) -> Result<String, ReportError> {
    let mut md = String::from("### Reduced models\n\n");
    let scenario = match scenario {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!("no reduced-model section for {}: {e}", run.path.display());
            let _ = writeln!(md, "Not run: the scenario cannot be loaded ({e}).\n");
            return Ok(md);
        }
    };
    let layers = ConfigLayers {
        files: run
            .config_files
            .iter()
            .chain(&opts.config.files)
            .cloned()
            .collect(),
        sets: run
            .config_sets
            .iter()
            .chain(&opts.config.sets)
            .cloned()
            .collect(),
    };
    let key = format!(
        "{}|{}|{}|{:?}|{:?}",
        run.robot,
        run.scenario_source.as_deref().unwrap_or(&run.scenario),
        run.duration,
        layers.files,
        layers.sets
    );
    if let Some((_, anchor)) = done.iter().find(|(k, _)| *k == key) {
        let _ = writeln!(
            md,
            "Same scenario, duration and config as `{anchor}`: see its reduced-model section.\n"
        );
        return Ok(md);
    }
    done.push((key, run.path.display().to_string()));
    let config = layers.load(robot, &scenario)?;
    tracing::info!(
        "reduced models: {} for {:.2} s, C0, C1, C2",
        scenario.name,
        scenario.duration
    );
    let reduced = reduced::run_reduced(&config, robot.reduced(), &scenario)?;
    md += &markdown::reduced_config_line(&config, &robot.reduced(), &scenario);
    md += "\n";
    md += &markdown::reduced_metrics_table(&reduced);
    md += "\n";
    let sources: Vec<&dyn SeriesSource> = reduced
        .iter()
        .map(|r| &r.series as &dyn SeriesSource)
        .collect();
    md += &figs.write(
        &format!("{tag}_reduced"),
        &format!("{}, reduced models", run.scenario),
        &sources,
    )?;
    Ok(md)
}

/// The default output directory: the run directory itself for one run, `<parent>/compare`
/// beside the first run for several.
pub fn default_out(runs: &[PathBuf]) -> PathBuf {
    match runs {
        [one] => one.clone(),
        [first, ..] => first
            .parent()
            .map_or_else(|| PathBuf::from("compare"), |p| p.join("compare")),
        [] => PathBuf::from("."),
    }
}
