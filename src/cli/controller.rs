//! `upc controller`: the control server.

use std::path::PathBuf;

use upc::channels::DEFAULT_PREFIX;
use upc::config::{ControllerKind, HeldObject};
use upc::control::server::{ServerOptions, run_server};
use upc::shutdown::stop_flag;
use upc::sim::sensors::Sensing;

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};
use super::common::{ConfigArgs, RobotArg};

#[derive(clap::Args, Debug, Clone)]
pub struct ControllerArgs {
    /// Scenario: its ZMP reference and [config] overrides (the force comes from the forecaster).
    #[arg(long, default_value = upc::scenario::DEFAULT)]
    pub scenario: String,
    /// Controller (overrides controller.kind).
    #[arg(long, value_enum)]
    pub controller: Option<ControllerKind>,
    /// Run at wall-clock rate instead of lockstep (overrides controller.mode).
    #[arg(long)]
    pub realtime: bool,
    #[command(flatten)]
    pub robot: RobotArg,
    /// Service prefix of the run.
    #[arg(long, default_value = DEFAULT_PREFIX)]
    pub prefix: String,
    /// Write the controller's rerun log here.
    #[arg(long)]
    pub rrd: Option<PathBuf>,
    /// Rerun recording id (share it with the simulator's log for one timeline).
    #[arg(long, default_value = "upc")]
    pub recording_id: String,
    /// Stream the recording to a live rerun viewer too, e.g. rerun+http://127.0.0.1:9876/proxy
    /// (needs --rrd; the file is written all the same).
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Also write every logged tick as CSV here (needs --rrd; same decimation).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write the run's figures as JSON here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// Stop at this simulated time (s); default: the scenario's duration; 0: run until stopped
    /// (a deployed controller).
    #[arg(long)]
    pub duration: Option<f64>,
    /// What the plant's states carry: `truth` takes the published base as measured and refuses
    /// a plant that does not measure it; `realistic` estimates the base from the sensor block
    /// even when a base is published (overrides `controller.base_estimation.mode`, whose default
    /// `auto` follows the plant's `BASE_UNMEASURED` flag; docs/estimation.md).
    #[arg(long, value_enum)]
    pub sensing: Option<Sensing>,
    #[command(flatten)]
    pub config: ConfigArgs,
}

impl ToArgv for ControllerArgs {
    fn write(&self, w: &mut Argv) {
        let ControllerArgs {
            scenario,
            controller,
            realtime,
            robot,
            prefix,
            rrd,
            recording_id,
            connect,
            csv,
            summary,
            duration,
            sensing,
            config,
        } = self;
        fields!(w; val scenario, opt_choice controller, switch realtime, val prefix, opt rrd,
                val recording_id, opt connect, opt csv, opt summary, opt duration,
                opt_choice sensing);
        w.nested(robot);
        w.nested(config);
    }
}

pub fn run(args: ControllerArgs) -> CliResult {
    let robot = args.robot.load()?;
    // The forces the plant pushes this robot with (its hash is what the plant announces).
    let scenario = robot.scenario(&args.scenario)?;
    let mut extra = Vec::new();
    if let Some(k) = args.controller {
        extra.push(format!("controller.kind=\"{}\"", k.name()));
    }
    if args.realtime {
        extra.push("controller.mode=\"realtime\"".into());
    }
    if let Some(s) = args.sensing {
        let mode = match s {
            Sensing::Truth => "off",
            Sensing::Realistic => "on",
        };
        extra.push(format!("controller.base_estimation.mode=\"{mode}\""));
    }
    let config = args.config.load(&robot, Some(&scenario), &extra)?;
    let opts = ServerOptions {
        prefix: args.prefix.clone(),
        duration: match args.duration.unwrap_or(scenario.duration) {
            d if d > 0.0 => Some(d),
            _ => None,
        },
        rrd: args.rrd.clone(),
        recording_id: args.recording_id.clone(),
        live: args.connect.clone(),
        zmp_offset: scenario.zmp_reference,
        startup_timeout: 60.0,
        csv: args.csv.clone(),
        scenario_hash: Some(scenario.content_hash()),
        robot_hash: Some(robot.hash),
        robot_name: robot.name().to_string(),
        held_mass: match config.controller.held_object {
            HeldObject::Door => upc::sim::scene::place_door(&robot)?.apparent_mass()?,
            HeldObject::None => nalgebra::Matrix3::zeros(),
        },
    };
    tracing::info!(
        "controller {} ({:?}) for robot `{}` on {}/*, {} Hz",
        config.controller.kind.name(),
        config.controller.mode,
        robot.name(),
        args.prefix,
        config.controller.rate_hz
    );
    let summary = run_server(&config, &robot, &opts, stop_flag())?;
    tracing::info!(
        "controller stopped ({}): {} ticks, tick p50 {:.1} µs p99 {:.1} µs",
        summary.stopped_by,
        summary.figures.ticks,
        summary.figures.tick_p50_us,
        summary.figures.tick_p99_us
    );
    if let Some(p) = &args.summary {
        std::fs::write(p, serde_json::to_string_pretty(&summary)?)?;
    }
    Ok(())
}
