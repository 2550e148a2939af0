//! `upc sim`: the simulator process (humanoid on the ground, door at the right hand).

use std::path::{Path, PathBuf};

use upc::shutdown::stop_flag;
use upc::sim::process::{RunOptions, run};
use upc::sim::{Engine, SimConfig};

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};
use super::bus_settings::{BusChoice, BusSettingsArgs};
use super::common::RobotArg;
use upc::sim::sensors::Sensing;

#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum ModeChoice {
    Lockstep,
    Realtime,
}

/// Start the simulator: `upc sim` runs the embedded default scene (the robot, by default the
/// iCub-like humanoid, at its home posture on flat ground, the door held by its right hand, the hinge torque profile of the
/// default scenario, `multiple_impacts`) in lockstep with a controller on the `upc/*` services.
/// In real time (`--mode realtime`) the robot is held at its start posture until a controller's
/// torques arrive, and held again if they stop (`[sim.hold]`): start the processes in any order.
/// Which simulator plays the plant.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, clap::ValueEnum)]
pub enum PlantChoice {
    /// upc's own simulator (this process).
    #[default]
    Upc,
    /// MuJoCo (its C library, from the wheel `scripts/setup.sh` installs), under the same plant
    /// runtime: the scene generated from the same robot description and scenario (`upc mjcf`).
    Mujoco,
}

impl PlantChoice {
    pub fn name(self) -> &'static str {
        match self {
            PlantChoice::Upc => "upc",
            PlantChoice::Mujoco => "mujoco",
        }
    }
}

/// What a plant simulates and how it steps: shared by `upc sim` and `upc mjcf`.
#[derive(clap::Args, Debug, Clone)]
pub struct PlantArgs {
    /// Lockstep (wait for each answer; deterministic) or real-time (wall-clock rate).
    #[arg(long, value_enum)]
    pub mode: Option<ModeChoice>,
    /// Simulated seconds to run (0: until Ctrl-C). Default from sim.duration.
    #[arg(long)]
    pub duration: Option<f64>,
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
    /// What the published state is: the plant's truth, or through the sensor models
    /// (`sim.sensors.sensing`; docs/sensing.md).
    #[arg(long, value_enum)]
    pub sensing: Option<Sensing>,
    #[command(flatten)]
    pub robot: RobotArg,
}

/// Start the simulator: `upc sim` runs the embedded default scene (the robot, by default the
/// iCub-like humanoid, at its home posture on flat ground, the door held by its right hand, the hinge torque profile of the
/// default scenario, `multiple_impacts`) in lockstep with a controller on the `upc/*` services.
/// In real time (`--mode realtime`) the robot is held at its start posture until a controller's
/// torques arrive, and held again if they stop (`[sim.hold]`): start the processes in any order.
/// `--plant mujoco` runs the same scene in MuJoCo instead, on the same channels.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  upc sim                                   # lockstep, 10 s, waits for a controller\n  upc sim --mode realtime --duration 5 --rrd sim.rrd\n  upc sim --set sim.friction=0.5 --scenario multiple_impacts --prefix test1\n  upc sim --plant mujoco --robot icub      # MuJoCo as the plant (scripts/setup.sh installs it)"
)]
pub struct SimArgs {
    #[command(flatten)]
    pub plant: PlantArgs,
    /// The simulator: upc's own, or MuJoCo.
    #[arg(long = "plant", value_enum, default_value = "upc")]
    pub simulator: PlantChoice,
    /// MuJoCo: also write the generated scene (`scene.xml`, `plant.json`) here.
    #[arg(long)]
    pub bundle: Option<PathBuf>,
    /// Write the ground truth to this rerun recording.
    #[arg(long)]
    pub rrd: Option<PathBuf>,
    /// Rerun recording id (give the controller the same one to merge recordings).
    #[arg(long)]
    pub recording_id: Option<String>,
    /// Stream the recording to a live rerun viewer too, e.g. rerun+http://127.0.0.1:9876/proxy
    /// (needs --rrd; the file is written all the same).
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Write the run's figures (step time, contacts, IPC overhead) as JSON here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// Lockstep: write the ground truth (CoM, CoP, hand force, door, contact figures) every
    /// record period as CSV here: the same bytes on every rerun.
    #[arg(long)]
    pub truth_csv: Option<PathBuf>,
    /// Speak as the robot does on its own bus instead of upc's contract (a G1 on Unitree's DDS
    /// topics, for `upc bus`; real time; docs/bus.md).
    #[arg(long, value_enum)]
    pub bus: Option<BusChoice>,
    #[command(flatten)]
    pub bus_settings: BusSettingsArgs,
}

impl ToArgv for PlantArgs {
    fn write(&self, w: &mut Argv) {
        let PlantArgs {
            mode,
            duration,
            configs,
            sets,
            prefix,
            scenario,
            sensing,
            robot,
        } = self;
        fields!(w; opt_choice mode, opt duration, many configs, many sets, opt prefix, opt scenario,
                opt_choice sensing);
        w.nested(robot);
    }
}

impl ToArgv for SimArgs {
    fn write(&self, w: &mut Argv) {
        let SimArgs {
            plant,
            simulator,
            bundle,
            rrd,
            recording_id,
            connect,
            summary,
            truth_csv,
            bus,
            bus_settings,
        } = self;
        w.nested(plant);
        fields!(w; choice simulator, opt bundle, opt rrd, opt recording_id,
                opt connect, opt summary, opt truth_csv, opt_choice bus);
        w.nested(bus_settings);
    }
}

/// Write the MuJoCo scene of a plant: `upc mjcf --out DIR` writes `DIR/scene.xml` (open it in
/// MuJoCo's viewer: `python -m mujoco.viewer --mjcf DIR/scene.xml`) and `DIR/plant.json` (the
/// names and figures a plant of one's own needs), generated from the robot description, the
/// scenario and the simulator's config, as `upc sim --plant mujoco` does at its start.
#[derive(clap::Args)]
pub struct MjcfArgs {
    #[command(flatten)]
    pub plant: PlantArgs,
    /// Directory to write into (created).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn load_config(args: &PlantArgs) -> Result<SimConfig, upc::config::ConfigError> {
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
    if let Some(s) = args.sensing {
        sets.push(format!("sim.sensors.sensing={}", toml_str(s.name())));
    }
    SimConfig::load(&args.configs, &sets)
}

pub(super) const CHANNELS_PY: &str = include_str!("../../services/python/upc_channels.py");

/// Writes the MuJoCo scene of `args` into `dir`; returns the path of its `plant.json`.
fn write_bundle(
    args: &PlantArgs,
    dir: &Path,
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    let config = load_config(args)?;
    let robot = args.robot.load()?;
    let scenario = robot.scenario(&config.scenario)?;
    let scene = upc::sim::mujoco::build(&robot, &config, &scenario)?;
    std::fs::create_dir_all(dir).map_err(|e| format!("bundle directory {}: {e}", dir.display()))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text)
            .map_err(|e| format!("writing {}: {e}", dir.join(name).display()))
    };
    write("scene.xml", &scene.mjcf)?;
    write("plant.json", &serde_json::to_string_pretty(&scene.plant)?)?;
    Ok(dir.join("plant.json"))
}

pub fn mjcf_cli(args: MjcfArgs) -> CliResult {
    let plant = write_bundle(&args.plant, &args.out)?;
    println!(
        "wrote {}/scene.xml and {} (view it: python -m mujoco.viewer --mjcf {}/scene.xml)",
        args.out.display(),
        plant.display(),
        args.out.display()
    );
    Ok(())
}

pub fn run_cli(args: SimArgs) -> CliResult {
    let engine = match args.simulator {
        PlantChoice::Upc => Engine::Upc,
        PlantChoice::Mujoco if !upc::sim::mujoco::AVAILABLE => {
            return Err(upc::sim::mujoco::UNAVAILABLE.into());
        }
        PlantChoice::Mujoco => Engine::Mujoco,
    };
    if let Some(dir) = &args.bundle {
        write_bundle(&args.plant, dir)?;
    }
    let config = load_config(&args.plant)?;
    if args.bus.is_some() {
        return bus_robot(&args, config, engine);
    }
    let opts = RunOptions {
        node_name: format!("upc-sim-{}", std::process::id()),
        robot: std::sync::Arc::new(args.plant.robot.load()?),
        config,
        rrd: args.rrd.clone(),
        recording_id: args.recording_id.clone(),
        live: args.connect.clone(),
        truth_csv: args.truth_csv.clone(),
        engine,
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
    match s.error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

/// `upc sim --bus unitree`: the plant speaking as the robot on its bus, in real time.
fn bus_robot(args: &SimArgs, mut config: SimConfig, engine: Engine) -> CliResult {
    config.mode = upc::sim::Mode::Realtime;
    let opts = upc::sim::bus_robot::SimRobotOptions {
        rrd: args.rrd.clone(),
        recording_id: args.recording_id.clone(),
        bus: args.bus_settings.load()?,
        robot: std::sync::Arc::new(args.plant.robot.load()?),
        sim: config,
        engine,
    };
    let s = upc::sim::bus_robot::run(&opts, &stop_flag())?;
    if let Some(p) = &args.summary {
        std::fs::write(p, serde_json::to_string_pretty(&s)?)?;
    }
    println!(
        "sim on the bus: {} steps, {:.3} s; {} states at {:.0} Hz, {} commands ({} bad CRC, {} wrong \
         mode_machine, {} above an effort limit); harness steps {}, limp steps {}, damping steps {} \
         from {:?}; overruns {}{}",
        s.steps,
        s.sim_time,
        s.states,
        s.rate,
        s.commands,
        s.bad_crc_commands,
        s.wrong_mode_machine,
        s.over_limit_commands,
        s.harness_steps,
        s.limp_steps,
        s.damping_steps,
        s.damping_starts,
        s.overruns,
        s.error
            .as_ref()
            .map(|e| format!("; ended: {e}"))
            .unwrap_or_default()
    );
    Ok(())
}
