//! `upc preview`: the reduced-model closed loop on a scenario, with a metrics table and CSV.

use std::io::Write;
use std::path::PathBuf;

use upc::config::{Config, ControllerKind};
use upc::offline::{ReducedLoop, RunResult};
use upc::scenario::Scenario;

use super::CliResult;

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerChoice {
    C0,
    C1,
    C2,
    All,
}

#[derive(clap::Args)]
pub struct PreviewArgs {
    /// Scenario: an embedded name (single_impact, multiple_impacts, standing) or a path to a TOML file.
    #[arg(long, default_value = upc::scenario::DEFAULT)]
    pub scenario: String,
    /// Controller to run; `all` runs C0, C1 and C2 and compares them.
    #[arg(long, value_enum, default_value = "all")]
    pub controller: ControllerChoice,
    /// Write one CSV row per step (with `all`, one file per controller: name-c0.csv, …).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub config: super::common::ConfigArgs,
    #[command(flatten)]
    pub robot: super::common::RobotArg,
    /// Shorthand for --set preview.horizon=N.
    #[arg(long)]
    pub horizon: Option<usize>,
    /// Shorthand for --set preview.solver=…
    #[arg(long, value_parser = ["riccati", "dense"])]
    pub solver: Option<String>,
    /// Shorthand for --set gain_search.solver=…
    #[arg(long, value_parser = ["gauss-newton", "nelder-mead"])]
    pub gain_solver: Option<String>,
    /// Shorthand for --set preview.zmp_constraints=true.
    #[arg(long)]
    pub zmp_constraints: bool,
}

/// The config of a preview run: the layers plus the shorthand flags.
pub fn load_config(
    args: &PreviewArgs,
    robot: &upc::robot::Robot,
    scenario: &Scenario,
) -> Result<Config, upc::config::ConfigError> {
    let mut sets = Vec::new();
    if let Some(h) = args.horizon {
        sets.push(format!("preview.horizon={h}"));
    }
    if let Some(s) = &args.solver {
        sets.push(format!("preview.solver=\"{s}\""));
    }
    if let Some(s) = &args.gain_solver {
        sets.push(format!("gain_search.solver=\"{s}\""));
    }
    if args.zmp_constraints {
        sets.push("preview.zmp_constraints=true".into());
    }
    args.config.load(robot, Some(scenario), &sets)
}

pub fn run(args: PreviewArgs) -> CliResult {
    let robot = args.robot.load()?;
    let scenario = robot.scenario(&args.scenario)?;
    let config = load_config(&args, &robot, &scenario)?;
    let controllers: &[ControllerKind] = match args.controller {
        ControllerChoice::C0 => &[ControllerKind::C0],
        ControllerChoice::C1 => &[ControllerKind::C1],
        ControllerChoice::C2 => &[ControllerKind::C2],
        ControllerChoice::All => &[ControllerKind::C0, ControllerKind::C1, ControllerKind::C2],
    };
    println!(
        "robot {} (M = {:.2} kg, z_c = {:.3} m, forces × {:.3}); scenario {} — {} ({} s); T = {} s, N = {} ({:.2} s preview), R/Q_e = {:e}",
        robot.name(),
        robot.derived.mass,
        robot.derived.com_height,
        scenario.force_scale,
        scenario.name,
        scenario.description,
        scenario.duration,
        config.preview.period,
        config.preview.horizon,
        config.preview.period * config.preview.horizon as f64,
        config.preview.r / config.preview.q_e
    );
    let mut results = Vec::new();
    for &kind in controllers {
        let result = ReducedLoop::new(&config, robot.reduced(), &scenario, kind).run()?;
        if let Some(out) = &args.out {
            let path = if controllers.len() > 1 {
                suffixed(out, kind.name())
            } else {
                out.clone()
            };
            write_csv(&path, &result)?;
            tracing::info!("wrote {}", path.display());
        }
        results.push(result);
    }
    print_table(&results);
    Ok(())
}

fn suffixed(path: &std::path::Path, tag: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("preview");
    path.with_file_name(format!("{stem}-{tag}.csv"))
}

fn write_csv(path: &std::path::Path, result: &RunResult) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        w,
        "t,com_x,com_y,zmp_x,zmp_y,zmp_ref_x,zmp_ref_y,hand_error,kp,kd,f_ext_x,f_ext_y,f_ext_z,f_dis_x,f_dis_y,f_dis_z,solve_time"
    )?;
    for r in &result.rows {
        writeln!(
            w,
            "{:.4},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3e}",
            r.t,
            r.com[0],
            r.com[1],
            r.zmp[0],
            r.zmp[1],
            r.zmp_ref[0],
            r.zmp_ref[1],
            r.hand_error,
            r.kp,
            r.kd,
            r.f_ext[0],
            r.f_ext[1],
            r.f_ext[2],
            r.f_dis[0],
            r.f_dis[1],
            r.f_dis[2],
            r.solve_time
        )?;
    }
    w.flush()
}

fn print_table(results: &[RunResult]) {
    println!(
        "\n{:<4} {:>12} {:>12} {:>13} {:>11} {:>11} {:>10} {:>10} {:>10}",
        "ctrl",
        "max ZMP err",
        "out of supp",
        "max excursion",
        "hand RMS",
        "hand peak",
        "solve p50",
        "solve p99",
        "C2 iters"
    );
    println!(
        "{:<4} {:>12} {:>12} {:>13} {:>11} {:>11} {:>10} {:>10} {:>10}",
        "", "(mm)", "(s)", "(mm)", "(mm)", "(mm)", "(µs)", "(µs)", "(mean)"
    );
    for r in results {
        let m = &r.metrics;
        let iters = if r.gain_search.is_empty() {
            "-".to_string()
        } else {
            format!(
                "{:.1}",
                r.gain_search
                    .iter()
                    .map(|g| g.iterations as f64)
                    .sum::<f64>()
                    / r.gain_search.len() as f64
            )
        };
        println!(
            "{:<4} {:>12.2} {:>12.3} {:>13.2} {:>11.2} {:>11.2} {:>10.1} {:>10.1} {:>10}",
            r.controller.name(),
            m.max_zmp_error * 1e3,
            m.time_outside_support,
            m.max_support_excursion * 1e3,
            m.hand_rms_error * 1e3,
            m.hand_peak_error * 1e3,
            m.solve_p50 * 1e6,
            m.solve_p99 * 1e6,
            iters
        );
    }
}
