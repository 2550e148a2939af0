//! A lab's own controller: upc's, with one part of the lab's added, without editing upc.
//!
//! The part watches the hand force the controller uses and counts the ticks it exceeds a limit
//! (a column in `controller.csv`, an entry in the summary). Everything else is `upc
//! controller` on the default robot and scenario: start the plant and the forecaster beside it,
//!
//!     upc sim --prefix lab & upc forecast --prefix lab &
//!     cargo run --release --example lab_part -- lab runs/lab/controller.rrd
//!
//! and it prints the run's summary as JSON when the scenario ends.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use upc::col;
use upc::config::Config;
use upc::control::server::{Extensions, ServerOptions, run_server_with};
use upc::control::{ControllerPart, Stage, TickError, TickFrame, TickInputs};
use upc::record::Record;
use upc::robot::Robot;

/// Counts the ticks whose hand force is above `limit` (N).
struct HandForceMonitor {
    limit: f64,
    last: f64,
    over: u64,
}

impl ControllerPart for HandForceMonitor {
    fn name(&self) -> &'static str {
        "hand_force_monitor"
    }

    fn stages(&self) -> &'static [Stage] {
        // After the parts that estimate or tare the force.
        &[Stage::Forecast]
    }

    fn reset(&mut self) {
        self.last = 0.0;
    }

    fn update(
        &mut self,
        _: Stage,
        inputs: &TickInputs,
        frame: &mut TickFrame,
    ) -> Result<(), TickError> {
        let f = frame.hand().force_used(&inputs.sensed.hand_force);
        self.last = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        self.over += u64::from(self.last > self.limit);
        Ok(())
    }

    fn record(&self, out: &mut Record) {
        out.put(
            col!(fixed("lab_hand_force", 2).plot("lab/hand_force")),
            self.last,
        );
    }

    fn summarize(&self, out: &mut serde_json::Map<String, serde_json::Value>) {
        out.insert(
            "hand_force_monitor".into(),
            serde_json::json!({ "limit": self.limit, "ticks_over": self.over }),
        );
    }
}

fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let mut args = std::env::args().skip(1);
    let prefix = args.next().unwrap_or_else(|| "lab".into());
    let rrd = args.next().map(std::path::PathBuf::from);
    let robot = Robot::embedded_default()?;
    let scenario = robot.scenario(upc::scenario::DEFAULT)?;
    let config = Config::embedded_default()?;
    let opts = ServerOptions {
        prefix,
        duration: Some(scenario.duration),
        csv: rrd.as_ref().map(|p| p.with_extension("csv")),
        rrd,
        recording_id: "upc".into(),
        live: None,
        zmp_offset: scenario.zmp_reference,
        startup_timeout: 60.0,
        scenario_hash: Some(scenario.content_hash()),
        robot_hash: Some(robot.hash),
        robot_name: robot.name().to_string(),
        held_mass: upc::sim::scene::place_door(&robot)?.apparent_mass()?,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let monitor = HandForceMonitor {
        limit: 50.0,
        last: 0.0,
        over: 0,
    };
    let extensions = Extensions {
        parts: vec![Box::new(monitor)],
        ..Extensions::default()
    };
    let summary = run_server_with(&config, &robot, &opts, stop.clone(), extensions)?;
    stop.store(true, Ordering::Relaxed);
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}
