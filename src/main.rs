//! The `upc` command line: one binary, one subcommand per job.

// Outside tests, no unwrap or expect (as in the library).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

use clap::{Parser, Subcommand};

mod cli;

#[derive(Parser)]
#[command(
    name = "upc",
    version,
    about = "Unified preview control for humanoid balance and hand interaction"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Launch simulator, forecaster and controller as processes on a scenario; write runs/<name>/.
    Run(cli::run::RunArgs),
    /// Write report.md with figures and metrics tables for run directories of `upc run`.
    Compare(cli::compare::CompareArgs),
    /// Run the closed loop of the reduced models (cart-table + hand impedance) on a scenario.
    Preview(cli::preview::PreviewArgs),
    /// Run the control server: state and forecast in, joint torques out, over iceoryx2.
    Controller(cli::controller::ControllerArgs),
    /// Publish a scenario's hand force forecast on the forecast channel.
    Forecast(cli::forecast::ForecastArgs),
    /// Inspect a URDF: joints, DoF, mass, CoM; dump M(q), h(q, v), CoM and a frame Jacobian as JSON.
    Model(cli::model::ModelArgs),
    /// Bring a robot: `upc robot init [PACKAGE] URDF --out FILE` drafts its description from the URDF.
    Robot(cli::robot::RobotArgs),
    /// Forward the channels between this host's iceoryx2 and Zenoh (forecasters and viewers elsewhere).
    Bridge(cli::bridge::BridgeArgs),
    /// Run the simulator: the humanoid on the ground and the door, over iceoryx2 (see --help).
    Sim(cli::sim::SimArgs),
    /// Drive a robot on its own DDS bus (Unitree G1): the plant on upc's contract, the controller on the bus.
    Bus(cli::bus::BusArgs),
    /// Largest impact each controller survives, by bisection, on the reduced models and the full simulation.
    Capability(cli::capability::CapabilityArgs),
    /// Largest impact survived against forecast errors (factor, shift, phantom), full simulation.
    Robustness(cli::robustness::RobustnessArgs),
    /// Write the MuJoCo scene (MJCF, plant description, plant process) of a robot and scenario.
    Mjcf(cli::sim::MjcfArgs),
    /// One cell of a sweep, its result as JSON on stdout: the task a sweep engine runs.
    #[command(hide = true)]
    SweepCell(cli::cell::SweepCellArgs),
}

fn main() -> std::process::ExitCode {
    // Lines go to stderr from a background thread (a full pipe never stalls a loop); the guard
    // writes out the queue when main returns.
    let log = upc::logging::init_stderr();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => cli::run::run(args),
        Command::Preview(args) => cli::preview::run(args),
        Command::Compare(args) => cli::compare::run(args),
        Command::Model(args) => cli::model::run(args),
        Command::Robot(args) => cli::robot::run(args),
        Command::Sim(args) => cli::sim::run_cli(args),
        Command::Bus(args) => cli::bus::run_cli(args),
        Command::Mjcf(args) => cli::sim::mjcf_cli(args),
        Command::Capability(args) => cli::capability::run(args),
        Command::Robustness(args) => cli::robustness::run(args),
        Command::Forecast(args) => cli::forecast::run_cli(args),
        Command::Bridge(args) => cli::bridge::run_cli(args),
        Command::Controller(args) => cli::controller::run(args),
        Command::SweepCell(args) => cli::cell::run(args),
    };
    // Queued log lines first, then the error (which goes to stderr directly).
    drop(log);
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
