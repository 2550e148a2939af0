//! `upc bus`: upc on a robot's own bus — the plant on upc's contract, the controller on the
//! robot's DDS bus (docs/bus.md).

use std::path::PathBuf;

use upc::bus::participant::{BusOptions, run};
use upc::shutdown::stop_flag;

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};
pub use super::bus_settings::{BusChoice, BusSettingsArgs};
use super::sim::PlantArgs;

/// Drive a robot on its own bus: a participant that is the plant on upc's contract (start `upc
/// controller --realtime` and a forecaster beside it, as with `upc sim`) and the low-level
/// controller on the robot's DDS bus. It waits for the robot's first valid state, refuses to
/// start while another participant writes `rt/lowcmd`, holds the robot on its drives until the
/// controller's torques arrive, and damps it when they stop. The defaults are loopback only
/// (a simulator on this machine); on a G1 see docs/bus.md, "On the robot".
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  upc sim --bus unitree --robot g1 &        # a simulated G1 on the bus\n  upc bus --robot g1 --duration 20 --summary bus.json\n  upc bus --robot g1 --bus-set bus.domain=0 --bus-set 'bus.interface=\"192.168.123.222\"'   # a G1"
)]
pub struct BusArgs {
    #[command(flatten)]
    pub plant: PlantArgs,
    #[command(flatten)]
    pub settings: BusSettingsArgs,
    /// Write the run's counters and latencies as JSON here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
}

impl ToArgv for BusArgs {
    fn write(&self, w: &mut Argv) {
        let BusArgs {
            plant,
            settings,
            summary,
        } = self;
        w.nested(plant);
        w.nested(settings);
        fields!(w; opt summary);
    }
}

pub fn run_cli(args: BusArgs) -> CliResult {
    let sim = super::sim::load_config(&args.plant)?;
    let opts = BusOptions {
        bus: args.settings.load()?,
        robot: std::sync::Arc::new(args.plant.robot.load()?),
        lockstep: sim.mode == upc::sim::Mode::Lockstep,
        scenario: sim.scenario,
        prefix: sim.process.prefix,
        node_name: format!("upc-bus-{}", std::process::id()),
        duration: sim.duration,
    };
    let stop = stop_flag();
    let s = run(&opts, &stop)?;
    if let Some(p) = &args.summary {
        std::fs::write(p, serde_json::to_string_pretty(&s)?)?;
    }
    println!(
        "bus: {} states at {:.0} Hz, {} commands; refused: bad CRC {}, stale tick {}, non-finite {}; \
         late answers {}, clamped commands {}; hand-overs {}, losses {} (resumed {}), damping states {}; \
         state → command p50 {:.0} µs, p99 {:.0} µs (the bus's own share p50 {:.0} µs, p99 {:.0} µs); \
         CPU {:.1} % of a core{}",
        s.states,
        s.robot_rate,
        s.commands,
        s.refused_bad_crc,
        s.refused_stale_tick,
        s.refused_non_finite,
        s.late_answers,
        s.clamped_commands,
        s.handovers,
        s.losses,
        s.resumes,
        s.damping_states,
        s.state_to_command_p50 * 1e6,
        s.state_to_command_p99 * 1e6,
        s.adapter_p50 * 1e6,
        s.adapter_p99 * 1e6,
        s.cpu_share * 100.0,
        s.error
            .as_ref()
            .map(|e| format!("; ended: {e}"))
            .unwrap_or_default()
    );
    // The robot lost ends the run as a failure, its figures written: a service manager
    // restarts the participant (services/upc-bus.service), `upc run` stops.
    match s.error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
