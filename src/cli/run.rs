//! `upc run`: the one-command launcher. Starts the simulator, the forecaster and the controller
//! as separate processes for each controller asked for, shows progress, stops them cleanly and
//! writes `runs/<name>/` (per controller: `sim.rrd`, `controller.rrd`, `controller.csv`,
//! `controller.json`, the processes' logs, and in lockstep the simulator's ground truth as
//! `sim.csv`) with a `summary.json` and a metrics table.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use upc::channels::{ContractNode, StateMsg};
use upc::config::ControllerKind;
use upc::control::server::ServerSummary;
use upc::realtime::ControlCpu;
use upc::scenario::Scenario;
use upc::sim::sensors::Sensing;

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};
use super::bridge::BridgeArgs;
use super::common::{ConfigArgs, RobotArg};
use super::controller::ControllerArgs;
use super::forecast::ForecastArgs;
use super::sim::{ModeChoice, PlantArgs, PlantChoice, SimArgs};

#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum Which {
    C0,
    C1,
    C2,
    All,
}

/// Where the run's processes may run (`--cpus`).
#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum CpuLayout {
    /// Lockstep: the control thread on a CPU of its own when the machine has two or more and
    /// no other launcher claimed it, every other process on the rest
    /// (`upc::realtime::ControlCpu`), the plant polling for the torques.
    Auto,
    /// Every process wherever the scheduler puts it.
    Shared,
}

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario: embedded name (single_impact, multiple_impacts, standing) or TOML path.
    #[arg(long, default_value = upc::scenario::DEFAULT)]
    pub scenario: String,
    /// Controller(s) to run, one after the other.
    #[arg(long, value_enum, default_value = "all")]
    pub controller: Which,
    /// Wall-clock mode instead of lockstep.
    #[arg(long)]
    pub realtime: bool,
    /// Simulated seconds (default: the scenario's duration).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Run name (default: <scenario>-<unix time>).
    #[arg(long)]
    pub name: Option<String>,
    /// Parent directory of the run directories.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Run this command (through `sh -c`) as the forecaster instead of `upc forecast`; it gets
    /// UPC_PREFIX, UPC_DURATION and UPC_SCENARIO in its environment.
    #[arg(long)]
    pub forecaster: Option<String>,
    /// The forecast crosses Zenoh: start `upc bridge` on loopback, with mutual TLS and a
    /// throwaway CA as on a lab network, and the remote forecaster
    /// (`examples/python/zenoh_forecaster.py`, or the --forecaster command, which gets the
    /// bridge's endpoint in UPC_ZENOH_CONNECT and its certificate in UPC_ZENOH_CA,
    /// UPC_ZENOH_CERT, UPC_ZENOH_KEY and UPC_ZENOH_NAME) on the Zenoh side of it.
    #[arg(long)]
    pub forecaster_over_zenoh: bool,
    /// No forecaster at all: the controller forecasts from the measured hand force alone
    /// (the forecast correction with no prior) and does not wait for windows in lockstep.
    #[arg(long, conflicts_with_all = ["forecaster", "forecaster_over_zenoh"])]
    pub no_forecaster: bool,
    /// Spawn the rerun viewer (`rerun`: the one of `.venv`, which scripts/setup.sh installs,
    /// else from PATH; an open one is reused) and stream the recordings to it live, besides
    /// the `.rrd` files.
    #[arg(long)]
    pub viewer: bool,
    /// Stream the recordings live to the rerun viewer (or `rerun --serve-grpc`) at this URL,
    /// e.g. rerun+http://HOST:9876/proxy, besides the `.rrd` files.
    #[arg(long, value_name = "URL", conflicts_with = "viewer")]
    pub connect: Option<String>,
    /// No progress bar (logs only).
    #[arg(long)]
    pub quiet: bool,
    /// The control thread's CPU: `auto` gives it one of its own in lockstep, `shared` leaves
    /// every process to the scheduler (a `controller.realtime.cpu` of the config is kept).
    #[arg(long, value_enum, default_value = "auto")]
    pub cpus: CpuLayout,
    /// A wrong forecast on purpose (the built-in forecaster): forces × this.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub forecast_error_scale: f64,
    /// A wrong forecast on purpose: the force forecast this many seconds late (negative: early).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub forecast_error_shift: f64,
    /// A wrong forecast on purpose: the push's shape (`upc forecast --error-shape`: exact,
    /// truncated:F, decaying:T, step, stretched:K, rotated:D).
    #[arg(long, default_value = "exact", allow_hyphen_values = true)]
    pub forecast_error_shape: upc::forecast::ForecastShape,
    /// Controller config (files and --set), passed to `upc controller`.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Simulator config overrides (`upc sim --set`), e.g. --sim-set sim.friction=0.5.
    #[arg(long = "sim-set", value_name = "KEY=VALUE")]
    pub sim_sets: Vec<String>,
    /// The plant: upc's own simulator or MuJoCo (`upc sim --plant`), on the same channels.
    #[arg(long, value_enum, default_value = "upc")]
    pub plant: PlantChoice,
    /// What the plant publishes: its truth, or through the sensor models (`upc sim --sensing`).
    #[arg(long, value_enum)]
    pub sensing: Option<Sensing>,
    /// The robot, given to the simulator and the controller (the scenario's forces are scaled
    /// to its mass: `upc::robot::Robot::force_scale`).
    #[command(flatten)]
    pub robot: RobotArg,
    /// Through the robot's own bus: the plant speaks as the robot does (`upc sim --bus`), and
    /// `upc bus` stands between it and the controller (real time; docs/bus.md).
    #[arg(long, value_enum)]
    pub bus: Option<super::bus::BusChoice>,
    #[command(flatten)]
    pub bus_settings: super::bus::BusSettingsArgs,
}

/// One controller's run in the summary.
impl ToArgv for RunArgs {
    fn write(&self, w: &mut Argv) {
        let RunArgs {
            scenario,
            controller,
            realtime,
            duration,
            name,
            out,
            forecaster,
            forecaster_over_zenoh,
            no_forecaster,
            viewer,
            connect,
            quiet,
            cpus,
            forecast_error_scale,
            forecast_error_shift,
            forecast_error_shape,
            config,
            sim_sets,
            plant,
            sensing,
            robot,
            bus,
            bus_settings,
        } = self;
        w.nested(bus_settings);
        fields!(w; opt_choice bus);
        fields!(w; val scenario, choice controller, switch realtime, opt duration, opt name,
                val out, opt forecaster, switch forecaster_over_zenoh, switch no_forecaster,
                switch viewer, opt connect, switch quiet, choice cpus, val forecast_error_scale,
                val forecast_error_shift, val forecast_error_shape, many sim_sets, choice plant, opt_choice sensing);
        w.nested(config);
        w.nested(robot);
    }
}

#[derive(Debug, serde::Serialize)]
struct Entry {
    controller: String,
    dir: String,
    wall_time: f64,
    controller_summary: Option<ServerSummary>,
    sim_summary: Option<serde_json::Value>,
    sim_exit: Option<i32>,
    /// `--bus`: the bus participant's exit code and summary (`bus.json`).
    #[serde(skip_serializing_if = "Option::is_none")]
    bus_exit: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bus_summary: Option<serde_json::Value>,
    forecaster_exit: Option<i32>,
    controller_exit: Option<i32>,
    /// Why this controller's run failed (`None`: it did not): a participant's error exit with
    /// its last log line, no controller summary, or no tick at all. A run that never
    /// controlled the robot keeps no controller figures: zeros would read as a robot that
    /// stood.
    failure: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bridge_summary: Option<serde_json::Value>,
    /// The base estimate against the plant's truth (lockstep runs whose base was estimated).
    #[serde(skip_serializing_if = "Option::is_none")]
    base_estimate_error: Option<upc::report::BaseAccuracy>,
    /// The hand force, foot loads and CoP the controller had against the plant's truth
    /// (lockstep runs).
    #[serde(skip_serializing_if = "Option::is_none")]
    wrench_estimate_error: Option<upc::report::WrenchAccuracy>,
    /// The plant's true CoP against the support the controller had (lockstep runs): the
    /// controller's `min_zmp_margin` is its measured CoP's.
    #[serde(skip_serializing_if = "Option::is_none")]
    true_cop_margin: Option<upc::report::TrueMargin>,
}

pub fn run(mut args: RunArgs) -> CliResult {
    // A robot's bus runs at the robot's pace: real time.
    args.realtime |= args.bus.is_some();
    let robot = args.robot.load()?;
    let scenario = robot.scenario(&args.scenario)?;
    // Fail early on a bad config, before starting processes.
    let config = args.config.load(&robot, Some(&scenario), &[])?;
    upc::sim::SimConfig::load(&[], &args.sim_sets)?;
    args.forecast_error_shape.apply(&scenario.force)?;
    let mut duration = args.duration.unwrap_or(scenario.duration);
    if args.bus.is_some() {
        // The plant on the bus starts the push this long after the robot is first commanded.
        duration += args.bus_settings.load()?.sim.scenario_delay;
    }
    let name = args.name.clone().unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        format!("{}-{secs}", scenario.name)
    });
    let root = args.out.join(&name);
    std::fs::create_dir_all(&root)?;
    let kinds: Vec<ControllerKind> = match args.controller {
        Which::C0 => vec![ControllerKind::C0],
        Which::C1 => vec![ControllerKind::C1],
        Which::C2 => vec![ControllerKind::C2],
        Which::All => vec![ControllerKind::C0, ControllerKind::C1, ControllerKind::C2],
    };
    let exe = std::env::current_exe()?;
    let live = match (&args.connect, args.viewer) {
        (Some(url), _) => Some(url.clone()),
        (None, true) => Some(spawn_viewer()?),
        (None, false) => None,
    };
    // An unreachable viewer would cost each process a flush time-out at its exit: say so now.
    if let Some(url) = &live {
        wait_reachable(url, Duration::from_secs(if args.viewer { 10 } else { 2 }))?;
    }
    // Held until the run ends: the claim is the lock.
    let control_cpu = control_cpu(&args, &config);
    let cpu = control_cpu.as_ref().map(ControlCpu::cpu);
    let mut entries = Vec::new();
    for kind in kinds {
        let plan = RunPlan {
            exe: &exe,
            args: &args,
            duration,
            root: &root,
            name: &name,
            live: live.as_deref(),
            control_cpu: cpu,
        };
        entries.push(run_one(&plan, kind)?);
    }
    write_summary(&args, &robot, &scenario, duration, &root, &entries, cpu)?;
    print_table(&entries);
    println!(
        "\nwrote {}/ (open the logs with: rerun {}/<controller>/*.rrd)",
        root.display(),
        root.display()
    );
    let failures: Vec<String> = entries
        .iter()
        .filter_map(|e| e.failure.as_ref().map(|f| format!("{}: {f}", e.controller)))
        .collect();
    let failed = entries.iter().any(|e| e.controller_summary.is_none());
    if args.controller == Which::All {
        report(&root, failed)?;
    }
    if !failures.is_empty() {
        return Err(format!("the run failed: {}", failures.join("; ")).into());
    }
    Ok(())
}

/// The plant polls this long (µs) for the torques when the control thread has a CPU of its
/// own: the controller's tick on the default run, 50 µs p50 and 70 µs p90, with room. Blocked
/// instead, the plant is woken by the torques' notify, which then costs the controller 15–20 µs
/// (p50) of the tick; its polling costs only the other CPUs' time.
const TORQUE_SPIN_US: f64 = 150.0;

/// The control thread's CPU under `--cpus auto` in lockstep: claimed, and this process (so
/// every participant it starts from now on) kept off it. `None` in real time (the deadlines
/// are the config's to place: `config/realtime.toml`), with a CPU the config pins the control
/// thread to, on a single CPU, or when another launcher holds every candidate.
fn control_cpu(args: &RunArgs, config: &upc::config::Config) -> Option<ControlCpu> {
    if args.cpus != CpuLayout::Auto || args.realtime || config.controller.realtime.cpu.is_some() {
        return None;
    }
    let claim = ControlCpu::claim()?;
    match claim.leave_to_control() {
        Ok(()) => {
            tracing::info!(
                "the control thread runs on CPU {} of its own, every other process on the \
                 others (`--cpus shared`: wherever the scheduler puts them)",
                claim.cpu()
            );
            Some(claim)
        }
        Err(e) => {
            tracing::warn!(
                "cannot keep the other processes off CPU {}: {e}",
                claim.cpu()
            );
            None
        }
    }
}

/// Why one controller's run failed, if it did: a participant that exited with an error (the
/// last line of its log says why), a controller that wrote no summary, or one that never
/// controlled the robot (no tick).
fn failure_of(e: &Entry) -> Option<String> {
    let line = |log: &str| last_log_line(&Path::new(&e.dir).join(log));
    for (what, exit, log) in [
        ("simulator", e.sim_exit, "sim.log"),
        ("bus participant", e.bus_exit, "bus.log"),
        ("forecaster", e.forecaster_exit, "forecaster.log"),
        ("controller", e.controller_exit, "controller.log"),
    ] {
        if let Some(code) = exit.filter(|&c| c != 0) {
            return Some(format!("the {what} exited with {code}: {}", line(log)));
        }
    }
    match &e.controller_summary {
        None => Some(format!(
            "the controller wrote no summary: {}",
            line("controller.log")
        )),
        Some(s) if s.figures.ticks == 0 => Some(format!(
            "the controller never controlled the robot (no tick); the simulator said: {}",
            line("sim.log")
        )),
        Some(_) => None,
    }
}

/// The run's `summary.json`: what was run (the arguments `upc compare` reloads) and each
/// controller's entry.
fn write_summary(
    args: &RunArgs,
    robot: &upc::robot::Robot,
    scenario: &Scenario,
    duration: f64,
    root: &Path,
    entries: &[Entry],
    control_cpu: Option<usize>,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let summary = serde_json::json!({
        "scenario": scenario.name,
        // What --robot and --scenario were given and the config layers: `upc compare` reloads
        // them.
        "robot": args.robot.robot,
        "plant": args.plant.name(),
        "robot_mass": robot.derived.mass,
        "force_scale": scenario.force_scale,
        "forecast_error": {
            "scale": args.forecast_error_scale,
            "shift": args.forecast_error_shift,
            "shape": args.forecast_error_shape.to_string(),
        },
        "scenario_source": args.scenario,
        "config_files": args.config.configs,
        "config_sets": args.config.sets,
        "sim_sets": args.sim_sets,
        "description": scenario.description,
        "duration": duration,
        "mode": if args.realtime { "realtime" } else { "lockstep" },
        // The control thread's own CPU (`--cpus auto`), or null: shared.
        "control_cpu": control_cpu,
        // Lockstep runs whose every controller kept its inputs on simulated time reproduce
        // byte for byte (services/CHANNELS.md).
        "reproducible": entries.iter().all(|e| {
            e.controller_summary.as_ref().is_some_and(|s| s.reproducible)
        }),
        // Any controller's run that failed (each entry's `failure` says why).
        "failed": entries.iter().any(|e| e.failure.is_some()),
        "runs": entries,
    });
    std::fs::write(
        root.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    Ok(())
}

/// The report of C0, C1 and C2 side by side (`upc compare` of this run).
fn report(root: &Path, failed: bool) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    // The run's config layers are in summary.json already: none added here.
    let report = super::compare::compare(
        &[root.to_path_buf()],
        root.to_path_buf(),
        &super::common::ConfigArgs::default(),
        true,
        true,
        false,
    );
    match report {
        Ok(path) => println!(
            "wrote {} (figures in {}/figures/)",
            path.display(),
            root.display()
        ),
        // A failed controller explains a failed report: report the controller first.
        Err(e) if failed => tracing::warn!("no report: {e}"),
        Err(e) => return Err(format!("report: {e}").into()),
    }
    Ok(())
}

/// What each controller's run of one `upc run` shares.
#[derive(Clone, Copy)]
struct RunPlan<'a> {
    exe: &'a Path,
    args: &'a RunArgs,
    duration: f64,
    root: &'a Path,
    name: &'a str,
    live: Option<&'a str>,
    /// The control thread's own CPU (`control_cpu`).
    control_cpu: Option<usize>,
}

/// One controller's run: the plant, the forecaster (and a bridge) and the controller as child
/// processes, watched until the controller ends or another participant dies.
fn run_one(
    plan: &RunPlan,
    kind: ControllerKind,
) -> Result<Entry, Box<dyn std::error::Error + Send + Sync>> {
    let RunPlan {
        exe,
        args,
        duration,
        root,
        name,
        live,
        control_cpu,
    } = *plan;
    let dir = root.join(kind.name());
    std::fs::create_dir_all(&dir)?;
    let ctx = Launch {
        exe,
        args,
        duration,
        root,
        dir: &dir,
        prefix: format!("upc_{}_{}", std::process::id(), kind.name()),
        recording: format!("{name}-{}", kind.name()),
        live,
        control_cpu,
    };
    let start = Instant::now();
    let mut running = ctx.start(kind)?;
    let (controller_exit, died) = ctx.watch(
        kind,
        &mut running.controller,
        &mut running.sim,
        running.forecaster.as_deref_mut(),
        running.bus.as_deref_mut(),
    )?;
    let exits = running.stop(died.is_some(), ctx.bus_grace());
    let entry = entry_of(kind, &dir, start, controller_exit, exits, died);
    // Any participant still running is killed (as `running` drops) once its files are read.
    drop(running);
    Ok(entry)
}

/// The participants of one controller's run, running.
struct Running {
    sim: Participant,
    bus: Option<Participant>,
    forecaster: Option<Participant>,
    bridge: Option<Participant>,
    controller: Participant,
}

/// How the participants other than the controller ended (their exit codes).
struct Exits {
    sim: Option<i32>,
    bus: Option<i32>,
    forecaster: Option<i32>,
}

impl Running {
    /// The controller is done: give the others a moment, then ask them to stop (at once when
    /// one of them `died`). A bus participant gets `bus_grace`, to brace then damp the robot
    /// its controller left (what a robot would get); the plant on a bus, which runs beyond the
    /// controller's time, is stopped after it at once.
    fn stop(&mut self, died: bool, bus_grace: Duration) -> Exits {
        let grace = |d: Duration| if died { Duration::ZERO } else { d };
        let bus = self.bus.as_mut().and_then(|b| stop(b, grace(bus_grace)));
        let sim_grace = if self.bus.is_some() {
            Duration::ZERO
        } else {
            Duration::from_secs(5)
        };
        let sim = stop(&mut self.sim, grace(sim_grace));
        let forecaster = self
            .forecaster
            .as_mut()
            .and_then(|f| stop(f, grace(Duration::from_secs(2))));
        if let Some(b) = &mut self.bridge {
            // SAFETY: signalling our own child; SIGTERM makes it write its summary.
            unsafe { libc::kill(b.id() as libc::pid_t, libc::SIGTERM) };
            stop(b, Duration::from_secs(5));
        }
        Exits {
            sim,
            bus,
            forecaster,
        }
    }
}

/// One controller's entry of the run's summary, from what its participants left in `dir`
/// (their summaries and logs) and how they ended; the run began at `start`.
fn entry_of(
    kind: ControllerKind,
    dir: &Path,
    start: Instant,
    controller_exit: Option<i32>,
    exits: Exits,
    died: Option<&'static str>,
) -> Entry {
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).ok();
    let controller_summary = read("controller.json").and_then(|t| serde_json::from_str(&t).ok());
    let sim_summary = read("sim.json").and_then(|t| serde_json::from_str(&t).ok());
    let mut entry = Entry {
        controller: kind.name().into(),
        dir: dir.display().to_string(),
        wall_time: start.elapsed().as_secs_f64(),
        controller_summary,
        sim_summary,
        sim_exit: exits.sim,
        bus_exit: exits.bus,
        bus_summary: read("bus.json").and_then(|t| serde_json::from_str(&t).ok()),
        forecaster_exit: exits.forecaster,
        controller_exit,
        failure: None,
        bridge_summary: read("bridge.json").and_then(|t| serde_json::from_str(&t).ok()),
        base_estimate_error: upc::report::base_accuracy(
            &dir.join("controller.csv"),
            &dir.join("sim.csv"),
        ),
        wrench_estimate_error: upc::report::wrench_accuracy(
            &dir.join("controller.csv"),
            &dir.join("sim.csv"),
        ),
        true_cop_margin: upc::report::true_margin(
            &dir.join("controller.csv"),
            &dir.join("sim.csv"),
        ),
    };
    entry.failure = failure_of(&entry).or_else(|| {
        // A clean exit of a participant that should have outlived the controller (the bus).
        died.map(|what| {
            format!(
                "the {what} ended before the controller: {}",
                last_log_line(&dir.join(log_of(what)))
            )
        })
    });
    // A run without a tick keeps no figures (its failure says so).
    entry.controller_summary = entry
        .controller_summary
        .take()
        .filter(|s| s.figures.ticks > 0);
    entry
}

/// s the plant on a bus runs beyond the run (it is stopped when the controller is done).
const BUS_PLANT_MARGIN: f64 = 30.0;

/// What one controller's run launches its children with.
struct Launch<'a> {
    exe: &'a Path,
    args: &'a RunArgs,
    duration: f64,
    root: &'a Path,
    dir: &'a Path,
    prefix: String,
    recording: String,
    live: Option<&'a str>,
    /// The control thread's own CPU (`control_cpu`).
    control_cpu: Option<usize>,
}

impl Launch<'_> {
    /// One open file for a child's stdout and stderr: two opens of the same path would each
    /// write from offset 0 over the other's lines.
    /// Starts the participants: the plant (and the robot's bus participant), the forecaster
    /// (and a bridge), then the controller.
    fn start(
        &self,
        kind: ControllerKind,
    ) -> Result<Running, Box<dyn std::error::Error + Send + Sync>> {
        let exe = self.exe;
        let (out, err) = self.log("sim.log")?;
        let sim = Participant::spawn(
            "simulator",
            Command::new(exe)
                .args(Argv::of("sim", &self.sim_args()))
                .stdout(out)
                .stderr(err),
        )?;
        let bus = match self.args.bus {
            Some(_) => {
                let (out, err) = self.log("bus.log")?;
                Some(Participant::spawn(
                    "bus",
                    Command::new(exe)
                        .args(Argv::of("bus", &self.bus_args()))
                        .stdout(out)
                        .stderr(err),
                )?)
            }
            None => None,
        };
        let (forecaster, bridge) = self.forecaster()?;
        let (out, err) = self.log("controller.log")?;
        let controller = Participant::spawn(
            "controller",
            Command::new(exe)
                .args(Argv::of("controller", &self.controller_args(kind)))
                .stdout(out)
                .stderr(err),
        )?;
        Ok(Running {
            sim,
            bus,
            forecaster,
            bridge,
            controller,
        })
    }

    fn log(&self, file: &str) -> std::io::Result<(Stdio, Stdio)> {
        let f = std::fs::File::create(self.dir.join(file))?;
        Ok((Stdio::from(f.try_clone()?), Stdio::from(f)))
    }

    fn sim_args(&self) -> SimArgs {
        let args = self.args;
        SimArgs {
            plant: PlantArgs {
                mode: Some(if args.realtime {
                    ModeChoice::Realtime
                } else {
                    ModeChoice::Lockstep
                }),
                // On a bus the plant outlives the participant (stopped with the run): a robot
                // does not go away when its controller is done.
                duration: Some(if args.bus.is_some() {
                    self.duration + BUS_PLANT_MARGIN
                } else {
                    self.duration
                }),
                configs: vec![],
                // The user's --sim-set still has the last word.
                sets: self
                    .control_cpu
                    .map(|_| format!("sim.process.ipc_spin_us={TORQUE_SPIN_US:?}"))
                    .into_iter()
                    .chain(args.sim_sets.iter().cloned())
                    .collect(),
                prefix: Some(self.prefix.clone()),
                scenario: Some(args.scenario.clone()),
                sensing: args.sensing,
                robot: args.robot.clone(),
            },
            simulator: args.plant,
            // MuJoCo's generated scene is kept with the run.
            bundle: (args.plant == PlantChoice::Mujoco).then(|| self.dir.join("mujoco")),
            rrd: Some(self.dir.join("sim.rrd")),
            recording_id: Some(self.recording.clone()),
            connect: self.live.map(str::to_owned),
            summary: Some(self.dir.join("sim.json")),
            truth_csv: (!args.realtime).then(|| self.dir.join("sim.csv")),
            bus: args.bus,
            bus_settings: args.bus_settings.clone(),
        }
    }

    /// How long the bus participant is left running once the controller is done: its time-out
    /// for the controller's silence, the brace, then 0.2 s of damping.
    fn bus_grace(&self) -> Duration {
        let b = self.args.bus_settings.load().ok();
        let s = b.map_or(1.0, |b| b.command_timeout + b.hold.brace + 0.2);
        Duration::from_secs_f64(s.clamp(0.0, 5.0))
    }

    /// `upc bus` between the plant on the bus and the controller.
    fn bus_args(&self) -> super::bus::BusArgs {
        // The participant is the plant on the contract: it outlives the controller's run too.
        super::bus::BusArgs {
            plant: self.sim_args().plant,
            settings: self.args.bus_settings.clone(),
            summary: Some(self.dir.join("bus.json")),
        }
    }

    /// The forecaster (none with `--no-forecaster`) and, over Zenoh, the bridge it talks to.
    #[allow(clippy::type_complexity)]
    fn forecaster(
        &self,
    ) -> Result<(Option<Participant>, Option<Participant>), Box<dyn std::error::Error + Send + Sync>>
    {
        let (args, dur) = (self.args, format!("{}", self.duration));
        let mut bridge = None;
        let mut cmd = match &args.forecaster {
            _ if args.forecaster_over_zenoh => {
                let bridge_log = self.log("bridge.log")?;
                let (b, mut c) = over_zenoh(
                    self.exe,
                    args,
                    self.root,
                    self.dir,
                    &self.prefix,
                    bridge_log,
                )?;
                bridge = Some(b);
                c.env("UPC_SCENARIO_DIR", self.root.join("remote"));
                c
            }
            Some(cmd) => shell(cmd),
            None => {
                let forecast = ForecastArgs {
                    scenario: Some(args.scenario.clone()),
                    dt: 0.005,
                    window: 2.5,
                    period: 0.01,
                    until: Some(self.duration),
                    prefix: self.prefix.clone(),
                    error_scale: args.forecast_error_scale,
                    error_shift: args.forecast_error_shift,
                    error_shape: args.forecast_error_shape,
                };
                let mut c = Command::new(self.exe);
                c.args(Argv::of("forecast", &forecast));
                c
            }
        };
        if args.forecaster.is_some() || args.forecaster_over_zenoh {
            cmd.env("UPC_PREFIX", &self.prefix)
                .env("UPC_DURATION", &dur)
                .env("UPC_SCENARIO", &args.scenario);
        }
        let (out, err) = self.log("forecaster.log")?;
        if args.no_forecaster {
            return Ok((None, bridge));
        }
        let mut forecaster = Participant::spawn("forecaster", cmd.stdout(out).stderr(err))?;
        if bridge.is_some() {
            // A remote forecaster takes a while to start and connect: the controller starts once
            // its first window is here, and a forecaster that dies first is reported at once.
            first_forecast(&self.prefix, &mut forecaster, Duration::from_secs(30))?;
        }
        Ok((Some(forecaster), bridge))
    }

    fn controller_args(&self, kind: ControllerKind) -> ControllerArgs {
        let args = self.args;
        let mut sets = args.config.sets.clone();
        if args.no_forecaster {
            sets.push("controller.lockstep_forecast_wait=0".into());
        }
        // On a bus the robot's rate governs: the controller ticks at the rate it publishes.
        if args.bus.is_some()
            && let Ok(b) = args.bus_settings.load()
        {
            sets.insert(0, format!("controller.rate_hz={:?}", b.sim.rate));
        }
        // A plant without the door in the hand (none, or the push applied at the hand) holds
        // nothing whose inertia the wrist sensor feels; the user's --set still has the last word.
        let held = upc::sim::SimConfig::load(&[], &args.sim_sets)
            .is_ok_and(|s| s.door && s.push != upc::sim::Push::Hand);
        if !held {
            sets.insert(0, "controller.held_object=\"none\"".into());
        }
        if let Some(cpu) = self.control_cpu {
            sets.insert(0, format!("controller.realtime.cpu={cpu}"));
        }
        ControllerArgs {
            scenario: args.scenario.clone(),
            controller: Some(kind),
            realtime: args.realtime,
            robot: args.robot.clone(),
            prefix: self.prefix.clone(),
            rrd: Some(self.dir.join("controller.rrd")),
            recording_id: self.recording.clone(),
            connect: self.live.map(str::to_owned),
            csv: Some(self.dir.join("controller.csv")),
            summary: Some(self.dir.join("controller.json")),
            duration: Some(self.duration),
            // The estimator follows the plant's BASE_UNMEASURED flag (a `--sim-set
            // sim.sensors.mocap=true` run keeps a measured base).
            sensing: None,
            config: ConfigArgs {
                configs: args.config.configs.clone(),
                sets,
            },
        }
    }

    /// Progress from the plant's state stream until the controller exits; a participant that
    /// dies ends the run at once (the controller would otherwise wait out its own time-outs, a
    /// minute for a vanished simulator). The controller's exit code, and which one died.
    fn watch(
        &self,
        kind: ControllerKind,
        controller: &mut Child,
        sim: &mut Child,
        mut forecaster: Option<&mut Child>,
        mut bus: Option<&mut Child>,
    ) -> Result<Watched, Box<dyn std::error::Error + Send + Sync>> {
        let bar = progress_bar(self.args.quiet, self.duration, kind);
        let watcher = ContractNode::open(&self.prefix, "launcher")
            .and_then(|b| b.subscriber::<StateMsg>().map(|s| (b, s)));
        loop {
            if let Ok((_, states)) = &watcher
                && let Ok(Some(s)) = states.latest()
            {
                bar.set_position((s.time * 1000.0) as u64);
                bar.set_message(format!("{:.2}/{:.2} s", s.time, self.duration));
            }
            if let Some(status) = controller.try_wait()? {
                bar.finish_and_clear();
                return Ok((status.code(), None));
            }
            let mut others: Vec<(&'static str, &mut Child)> = vec![("simulator", &mut *sim)];
            if let Some(f) = forecaster.as_deref_mut() {
                others.push(("forecaster", f));
            }
            if let Some(b) = bus.as_deref_mut() {
                others.push(("bus", b));
            }
            if let Some((what, status)) = failed_participant(&mut others)? {
                let log = self.dir.join(log_of(what));
                bar.suspend(|| {
                    eprintln!(
                        "{}: the {what} died ({status}): {}  ({}); stopping the run",
                        kind.name(),
                        last_log_line(&log),
                        log.display()
                    )
                });
                let code = terminate(controller, Duration::from_secs(10));
                bar.finish_and_clear();
                return Ok((code, Some(what)));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// How a watched run ended: the controller's exit code, and the participant that ended first.
type Watched = (Option<i32>, Option<&'static str>);

fn progress_bar(quiet: bool, duration: f64, kind: ControllerKind) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((duration * 1000.0) as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix:>3} [{bar:40}] {msg} sim time, {elapsed} wall")
            .map(|s| s.progress_chars("=> "))
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_prefix(kind.name());
    bar
}

/// `cmd` through `sh -c`, with `exec` so that the command itself, not the shell, gets our
/// SIGTERM at the end.
fn shell(cmd: &str) -> Command {
    let mut c = Command::new("sh");
    c.args(["-c", &format!("exec {cmd}")]);
    c
}

/// Spawn rerun's viewer (or reuse the one open on its default port); its gRPC proxy URL.
fn spawn_viewer() -> Result<String, Box<dyn std::error::Error + Send + Sync>> {
    let venv = [".", env!("CARGO_MANIFEST_DIR")]
        .iter()
        .map(|root| Path::new(root).join(".venv/bin/rerun"))
        .find(|p| p.exists());
    let opts = rerun::SpawnOptions {
        executable_path: venv.map(|p| p.display().to_string()),
        ..Default::default()
    };
    let info = rerun::spawn(&opts).map_err(|e| {
        format!("--viewer: {e} (scripts/setup.sh installs the viewer in .venv; or give --connect)")
    })?;
    Ok(format!("rerun+http://127.0.0.1:{}/proxy", info.port))
}

/// Wait until the gRPC endpoint of a rerun URL (`rerun+http://HOST:PORT/proxy`) accepts
/// connections.
fn wait_reachable(
    url: &str,
    limit: Duration,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let addr = url
        .split("://")
        .nth(1)
        .and_then(|rest| rest.split('/').next())
        .ok_or_else(|| format!("--connect {url}: expected rerun+http://HOST:PORT/proxy"))?;
    let until = Instant::now() + limit;
    loop {
        if std::net::TcpStream::connect(addr).is_ok() {
            return Ok(());
        }
        if Instant::now() >= until {
            return Err(format!(
                "no rerun viewer answers at {url} (a viewer needs a display; `rerun --serve-grpc` runs without one)"
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A TCP port free on loopback now (the OS picks it; the bridge binds it a moment later).
fn free_loopback_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

/// The forecast across Zenoh on loopback, secured as on a lab network: a throwaway CA, a
/// certificate for the bridge and one for the forecaster (`root/remote/pki/`), the bridge on
/// mutual TLS with the forecaster as its only forecaster identity. Returns the started bridge
/// and the forecaster's command (the script, or `--forecaster`), with the endpoint and its
/// certificate in UPC_ZENOH_{CONNECT,CA,CERT,KEY,NAME}.
fn over_zenoh(
    exe: &Path,
    args: &RunArgs,
    root: &Path,
    dir: &Path,
    prefix: &str,
    (out, err): (Stdio, Stdio),
) -> Result<(Participant, Command), Box<dyn std::error::Error + Send + Sync>> {
    const NAME: &str = "forecaster";
    let pki = loopback_pki(root, &["bridge", NAME])?;
    let pem = |f: &str| pki.join(f).display().to_string();
    let conf = dir.join("bridge.toml");
    let mut security = toml::Table::new();
    security.insert("tls".into(), true.into());
    for (k, f) in [
        ("ca", "ca.pem"),
        ("certificate", "bridge.pem"),
        ("private_key", "bridge.key"),
    ] {
        security.insert(k.into(), pem(f).into());
    }
    security.insert("forecasters".into(), vec![NAME.to_string()].into());
    let mut bridge = toml::Table::new();
    bridge.insert("security".into(), security.into());
    let mut file = toml::Table::new();
    file.insert("bridge".into(), bridge.into());
    std::fs::write(&conf, file.to_string())?;
    let endpoint = format!("tls/127.0.0.1:{}", free_loopback_port()?);
    let bridge_args = BridgeArgs {
        config: ConfigArgs {
            configs: vec![conf],
            sets: vec![],
        },
        prefix: Some(prefix.to_owned()),
        key_prefix: Some(prefix.to_owned()),
        listen: vec![endpoint.clone()],
        connect: vec![],
        insecure: false,
        summary: Some(dir.join("bridge.json")),
    };
    let bridge = Participant::spawn(
        "bridge",
        Command::new(exe)
            .args(Argv::of("bridge", &bridge_args))
            .stdout(out)
            .stderr(err),
    )?;
    let mut c = match &args.forecaster {
        Some(cmd) => shell(cmd),
        None => {
            let mut c = Command::new(super::common::python(&None));
            c.arg(remote_forecaster(root)?);
            c
        }
    };
    c.env("UPC_ZENOH_CONNECT", &endpoint)
        .env("UPC_ZENOH_CA", pem("ca.pem"))
        .env("UPC_ZENOH_CERT", pem(&format!("{NAME}.pem")))
        .env("UPC_ZENOH_KEY", pem(&format!("{NAME}.key")))
        .env("UPC_ZENOH_NAME", NAME);
    Ok((bridge, c))
}

/// A CA and a certificate per name in `root/remote/pki/`, made once per run directory by the
/// lab's own script (scripts/lab-pki.sh, embedded).
fn loopback_pki(
    root: &Path,
    names: &[&str],
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    const SCRIPT: &str = include_str!("../../scripts/lab-pki.sh");
    let dir = root.join("remote").join("pki");
    if dir.join("ca.pem").is_file() && names.iter().all(|n| dir.join(format!("{n}.pem")).is_file())
    {
        return Ok(dir);
    }
    let _ = std::fs::remove_dir_all(&dir);
    let script = root.join("remote").join("lab-pki.sh");
    std::fs::create_dir_all(root.join("remote"))?;
    std::fs::write(&script, SCRIPT)?;
    let steps = std::iter::once(vec!["ca"]).chain(names.iter().map(|n| vec!["issue", n]));
    for step in steps {
        let out = Command::new("bash")
            .arg(&script)
            .arg(step[0])
            .arg(&dir)
            .args(&step[1..])
            .output()
            .map_err(|e| format!("running bash for the loopback certificates: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "making the loopback certificates ({}): {}",
                step.join(" "),
                String::from_utf8_lossy(&out.stderr).trim()
            )
            .into());
        }
    }
    Ok(dir)
}

/// The remote forecaster and what it reads, written into `root/remote/` (it runs from there
/// as it would on another host): the script, the contract's Python mirror, and the embedded
/// scenarios' files.
fn remote_forecaster(root: &Path) -> std::io::Result<PathBuf> {
    const SCRIPT: &str = include_str!("../../examples/python/zenoh_forecaster.py");
    let dir = root.join("remote");
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join("zenoh_forecaster.py"), SCRIPT)?;
    std::fs::write(dir.join("upc_channels.py"), super::sim::CHANNELS_PY)?;
    for (name, text) in upc::scenario::EMBEDDED {
        std::fs::write(dir.join(format!("{name}.toml")), text)?;
    }
    Ok(dir.join("zenoh_forecaster.py"))
}

/// Wait until a forecast window is on `prefix`'s forecast service, or fail with the
/// forecaster's fate.
fn first_forecast(
    prefix: &str,
    forecaster: &mut Child,
    timeout: Duration,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let node = ContractNode::open(prefix, &format!("upc-launcher-{}", std::process::id()))?;
    let forecasts = node.subscriber::<upc::channels::ForecastMsg>()?;
    let until = Instant::now() + timeout;
    loop {
        if forecasts.has_samples() {
            return Ok(());
        }
        if let Some(status) = forecaster.try_wait()? {
            return Err(format!("the remote forecaster exited ({status}) before its first window: see forecaster.log").into());
        }
        if Instant::now() >= until {
            return Err(format!(
                "no forecast crossed the bridge within {} s: see forecaster.log and bridge.log",
                timeout.as_secs()
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A started child process that is stopped (SIGKILL, reaped) when dropped before it exited: an
/// error anywhere in `upc run` leaves no participant behind, and neither does `upc run` killed
/// itself (the child dies with it).
struct Participant(Child);

impl Participant {
    fn spawn(what: &str, cmd: &mut Command) -> Result<Self, String> {
        super::child::dies_with_parent(cmd);
        cmd.spawn()
            .map(Participant)
            .map_err(|e| format!("cannot start the {what} ({:?}): {e}", cmd.get_program()))
    }
}

impl std::ops::Deref for Participant {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Participant {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Participant {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// The first of `children` that has exited without success (an error exit, a signal), with its
/// status. One that exited with success has finished its part (a forecaster past its horizon).
fn failed_participant(
    children: &mut [(&'static str, &mut Child)],
) -> std::io::Result<Option<(&'static str, ExitStatus)>> {
    for (what, child) in children.iter_mut() {
        // The bus participant outlives the controller's run (its duration has a margin): its
        // end before the controller's, even a clean one, leaves the controller without a plant.
        if let Some(status) = child.try_wait()?
            && (!status.success() || *what == "bus")
        {
            return Ok(Some((what, status)));
        }
    }
    Ok(None)
}

/// The log file of a participant the run watches.
fn log_of(what: &str) -> &'static str {
    match what {
        "simulator" => "sim.log",
        "bus" => "bus.log",
        _ => "forecaster.log",
    }
}

/// The last non-empty line of a log file (empty when it cannot be read).
fn last_log_line(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("")
        .trim()
        .to_string()
}

/// SIGTERM a child now (it writes its summary), SIGKILL it if it has not exited within `grace`.
fn terminate(child: &mut Child, grace: Duration) -> Option<i32> {
    terminate_status(child, grace).and_then(|s| s.code())
}

/// [`terminate`]'s exit status: a signal that ended the child says which (SIGTERM, or SIGKILL
/// after `grace`).
fn terminate_status(child: &mut Child, grace: Duration) -> Option<std::process::ExitStatus> {
    if let Ok(Some(s)) = child.try_wait() {
        return Some(s);
    }
    // SAFETY: sending a signal to our own child process.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
    let deadline = Instant::now() + grace;
    while Instant::now() < deadline {
        if let Ok(Some(s)) = child.try_wait() {
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().ok()
}

/// Wait up to `grace` for a child to exit, then SIGTERM it, then SIGKILL.
fn stop(child: &mut Child, grace: Duration) -> Option<i32> {
    let deadline = Instant::now() + grace;
    let mut signalled = false;
    loop {
        match child.try_wait() {
            Ok(Some(s)) => return s.code(),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            Ok(None) if !signalled => {
                // SAFETY: sending a signal to our own child process.
                unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
                signalled = true;
                std::thread::sleep(Duration::from_millis(500));
            }
            _ => {
                let _ = child.kill();
                return child.wait().ok().and_then(|s| s.code());
            }
        }
    }
}

/// The run's table: a row per controller, then what the estimates missed and which
/// participants failed.
fn print_table(entries: &[Entry]) {
    print_header();
    for e in entries {
        print_row(e);
    }
    for e in entries {
        print_estimate_errors(e);
    }
    for e in entries {
        print_participant_failure(e);
    }
}

/// The table's two header lines.
fn print_header() {
    println!(
        "\n{:<4} {:>11} {:>10} {:>11} {:>10} {:>10} {:>9} {:>9} {:>9} {:>8} {:>9} {:>8} {:>8}",
        "ctrl",
        "ZMP margin",
        "true CoP",
        "at edge",
        "hand RMS",
        "hand peak",
        "tick p50",
        "tick p99",
        "tick max",
        "misses",
        "C2 solve",
        "IPC p99",
        "wall"
    );
    println!(
        "{:<4} {:>11} {:>10} {:>11} {:>10} {:>10} {:>9} {:>9} {:>9} {:>8} {:>9} {:>8} {:>8}",
        "",
        "min (mm)",
        "min (mm)",
        "(s)",
        "(mm)",
        "(mm)",
        "(µs)",
        "(µs)",
        "(µs)",
        "",
        "mean(ms)",
        "(µs)",
        "(s)"
    );
}

/// A controller's row: its figures, or why it failed.
fn print_row(e: &Entry) {
    match &e.controller_summary {
        Some(s) => println!(
            "{:<4} {:>11.1} {:>10.1} {:>11.3} {:>10.2} {:>10.2} {:>9.0} {:>9.0} {:>9.0} {:>8} {:>9.2} {:>8.1} {:>8.1}",
            e.controller,
            s.figures.min_zmp_margin * 1e3,
            e.true_cop_margin.map_or(f64::NAN, |m| m.min * 1e3),
            s.figures.time_at_support_edge,
            s.figures.hand_rms_error * 1e3,
            s.figures.hand_peak_error * 1e3,
            s.figures.tick_p50_us,
            s.figures.tick_p99_us,
            s.figures.tick_max_us,
            s.deadlines.deadline_misses,
            s.figures.c2_solve_mean_ms,
            e.sim_summary
                .as_ref()
                .and_then(|j| j["ipc_overhead_p99"].as_f64())
                .unwrap_or(f64::NAN)
                * 1e6,
            e.wall_time
        ),
        None => println!(
            "{:<4} failed: {}  (see {}/)",
            e.controller,
            e.failure.as_deref().unwrap_or("no controller summary"),
            e.dir
        ),
    }
}

/// What the controller's estimates missed against the plant's truth: the base estimate, when
/// the base was estimated, and the wrenches.
fn print_estimate_errors(e: &Entry) {
    if let Some(a) = &e.base_estimate_error {
        println!(
            "{}: base estimate vs truth: position RMS {:.1} mm (height max {:.1} mm), \
             velocity RMS {:.1} mm/s (max {:.1}), orientation RMS {:.2}° (tilt {:.2}°, max {:.2}°)",
            e.controller,
            a.position_rms * 1e3,
            a.height_max * 1e3,
            a.velocity_rms * 1e3,
            a.velocity_max * 1e3,
            a.orientation_rms_deg,
            a.tilt_rms_deg,
            a.orientation_max_deg
        );
    }
    // The wrenches, where the controller did not have them exactly (an observer, or
    // force sensors with their errors).
    if let Some(w) = e.wrench_estimate_error.as_ref().filter(|w| {
        w.hand_source == upc::report::HandSource::Observer
            || w.hand_x_push.rms > 1e-3
            || w.cop_x_standing.rms > 1e-5
    }) {
        let feet = w.foot_load.map_or(String::new(), |f| {
            format!(", foot load RMS {:.1} N (p99 {:.1})", f.rms, f.p99)
        });
        println!(
            "{}: {} hand force vs truth: x RMS {:.1} N during pushes (p99 {:.1}), {:.1} standing, \
             lag {:.0} ms; CoP RMS x/y {:.1}/{:.1} mm standing, {:.1}/{:.1} mm during pushes{feet}",
            e.controller,
            w.hand_source,
            w.hand_x_push.rms,
            w.hand_x_push.p99,
            w.hand_x_standing.rms,
            w.hand_lag * 1e3,
            w.cop_x_standing.rms * 1e3,
            w.cop_y_standing.rms * 1e3,
            w.cop_x_push.rms * 1e3,
            w.cop_y_push.rms * 1e3,
        );
    }
}

/// A simulator or forecaster that failed (a diverging simulation, a crashed plant or
/// forecaster) says why in the last line of its log.
fn print_participant_failure(e: &Entry) {
    for (what, exit, log) in [
        ("simulator", e.sim_exit, "sim.log"),
        ("forecaster", e.forecaster_exit, "forecaster.log"),
    ] {
        if let Some(code) = exit.filter(|&c| c != 0) {
            let path = Path::new(&e.dir).join(log);
            println!(
                "{}: the {what} exited with {code}: {}  ({})",
                e.controller,
                last_log_line(&path),
                path.display()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sh(script: &str) -> Child {
        Command::new("sh").args(["-c", script]).spawn().expect("sh")
    }

    #[test]
    fn a_dead_participant_is_found_and_the_controller_stopped_at_once() {
        let mut finished = sh("exit 0");
        let mut crashed = sh("exit 3");
        let mut running = sh("exec sleep 30");
        finished.wait().expect("wait");
        crashed.wait().expect("wait");
        // One that finished its part is not dead.
        let mut others = [("forecaster", &mut finished), ("simulator", &mut running)];
        assert!(failed_participant(&mut others).expect("try_wait").is_none());
        let mut others = [
            ("forecaster", &mut finished),
            ("simulator", &mut crashed),
            ("bridge", &mut running),
        ];
        let (what, status) = failed_participant(&mut others)
            .expect("try_wait")
            .expect("a dead participant");
        assert_eq!((what, status.code()), ("simulator", Some(3)));
        // The survivor (standing for the controller) is stopped now, by SIGTERM, not killed
        // after the grace period: the signal that ended it says which.
        use std::os::unix::process::ExitStatusExt;
        let status = terminate_status(&mut running, Duration::from_secs(60)).expect("status");
        assert_eq!(status.signal(), Some(libc::SIGTERM), "{status:?}");
    }

    #[test]
    fn the_last_log_line_skips_trailing_blank_lines() {
        let path = std::env::temp_dir().join(format!("upc_last_line_{}.log", std::process::id()));
        std::fs::write(
            &path,
            "INFO start\nERROR simulation diverged at t = 1.2 s\n\n  \n",
        )
        .expect("write");
        assert_eq!(
            last_log_line(&path),
            "ERROR simulation diverged at t = 1.2 s"
        );
        let _ = std::fs::remove_file(&path);
        assert_eq!(last_log_line(&path), "");
    }
}
