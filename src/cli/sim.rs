//! `upc sim`: the simulator process (humanoid on the ground, door at the right hand).

use std::path::PathBuf;

use upc::shutdown::stop_flag;
use upc::sim::SimConfig;
use upc::sim::process::{RunOptions, run};

use super::CliResult;
use super::common::RobotArg;

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeChoice {
    Lockstep,
    Realtime,
}

/// Start the simulator: `upc sim` runs the embedded default scene (the robot, by default the
/// iCub-like humanoid, at its home posture on flat ground, the door held by its right hand, the hinge torque profile of the
/// default scenario, `multiple_impacts`) in lockstep with a controller on the `upc/*` services.
/// In real time (`--mode realtime`) the robot is held at its start posture until a controller's
/// torques arrive, and held again if they stop (`[sim.hold]`): start the processes in any order.
#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  upc sim                                   # lockstep, 10 s, waits for a controller\n  upc sim --mode realtime --duration 5 --rrd sim.rrd\n  upc sim --set sim.friction=0.5 --scenario multiple_impacts --prefix test1"
)]
pub struct SimArgs {
    /// Lockstep (wait for each answer; deterministic) or real-time (wall-clock rate).
    #[arg(long, value_enum)]
    pub mode: Option<ModeChoice>,
    /// Simulated seconds to run (0: until Ctrl-C). Default from sim.duration.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Write the ground truth to this rerun recording.
    #[arg(long)]
    pub rrd: Option<PathBuf>,
    /// Rerun recording id (give the controller the same one to merge recordings).
    #[arg(long)]
    pub recording_id: Option<String>,
    /// Write the run's figures (step time, contacts, IPC overhead) as JSON here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// Extra config files (layout of config/sim.toml) over the embedded defaults, in order.
    #[arg(long = "config")]
    pub configs: Vec<PathBuf>,
    /// Override any config key, e.g. --set sim.friction=0.6 (applied last, in order).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// iceoryx2 service prefix (default sim.process.prefix, "upc").
    #[arg(long)]
    pub prefix: Option<String>,
    /// Door torque profile: embedded scenario name (single_impact, multiple_impacts, standing) or a path.
    #[arg(long)]
    pub scenario: Option<String>,
    /// Lockstep: write the ground truth (CoM, CoP, hand force, door, contact figures) every
    /// record period as CSV here: the same bytes on every rerun.
    #[arg(long)]
    pub truth_csv: Option<PathBuf>,
    #[command(flatten)]
    pub robot: RobotArg,
}

pub fn load_config(args: &SimArgs) -> Result<SimConfig, upc::config::ConfigError> {
    let mut sets = args.sets.clone();
    let toml_str = |s: &str| format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""));
    if let Some(m) = args.mode {
        let m = match m {
            ModeChoice::Lockstep => "lockstep",
            ModeChoice::Realtime => "realtime",
        };
        sets.push(format!("sim.mode={}", toml_str(m)));
    }
    if let Some(d) = args.duration {
        sets.push(format!("sim.duration={d:?}"));
    }
    if let Some(p) = &args.prefix {
        sets.push(format!("sim.process.prefix={}", toml_str(p)));
    }
    if let Some(s) = &args.scenario {
        sets.push(format!("sim.scenario={}", toml_str(s)));
    }
    SimConfig::load(&args.configs, &sets)
}

pub fn run_cli(args: SimArgs) -> CliResult {
    let config = load_config(&args)?;
    let opts = RunOptions {
        node_name: format!("upc-sim-{}", std::process::id()),
        robot: std::sync::Arc::new(args.robot.load()?),
        config,
        rrd: args.rrd.clone(),
        recording_id: args.recording_id.clone(),
        truth_csv: args.truth_csv.clone(),
    };
    let stop = stop_flag();
    let s = run(&opts, &stop)?;
    if let Some(p) = &args.summary {
        std::fs::write(p, serde_json::to_string_pretty(&s)?)?;
    }
    println!(
        "sim: {} steps, {:.3} s simulated in {:.3} s; step time p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs; \
         overruns {}; commands accepted {}, rejected {} (length {}, non-finite {}, order {}, foreign {}), stale {}; \
         hold steps {}, hand-overs {}, controller losses {}, safe-mode steps {}; max penetration {:.2e} m, max slip {:.2e} m/s, max loop error {:.2e} m; \
         rerun frames {} written, {} dropped",
        s.steps,
        s.sim_time,
        s.wall_time,
        s.step_time_p50 * 1e6,
        s.step_time_p99 * 1e6,
        s.step_time_max * 1e6,
        s.overruns,
        s.commands.accepted,
        s.commands.rejected(),
        s.commands.wrong_length,
        s.commands.non_finite,
        s.commands.out_of_order,
        s.commands.foreign,
        s.commands.stale,
        s.hold.hold_steps,
        s.hold.handovers,
        s.hold.losses,
        s.safe_mode_steps,
        s.max_penetration,
        s.max_slip_speed,
        s.max_loop_error,
        s.recorder.written,
        s.recorder.dropped
    );
    if s.ipc_overhead_p50 > 0.0 {
        println!(
            "sim: IPC round-trip overhead (excluding controller compute) p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs",
            s.ipc_overhead_p50 * 1e6,
            s.ipc_overhead_p99 * 1e6,
            s.ipc_overhead_max * 1e6
        );
    }
    Ok(())
}
