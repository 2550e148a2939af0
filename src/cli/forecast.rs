//! `upc forecast`: publish a scenario's hand force forecast.

use upc::channels::{Bus, DEFAULT_PREFIX};
use upc::forecast::{ForecastSettings, run};
use upc::scenario::Scenario;
use upc::shutdown::stop_flag;

use super::CliResult;

#[derive(clap::Args)]
pub struct ForecastArgs {
    /// Scenario whose hand force is forecast: embedded name or TOML path.
    #[arg(long, default_value = "multiple_impacts")]
    pub scenario: String,
    /// Sample spacing (s).
    #[arg(long, default_value_t = 0.005)]
    pub dt: f64,
    /// Window length (s); keep it longer than the controller's preview horizon.
    #[arg(long, default_value_t = 2.5)]
    pub window: f64,
    /// Simulated time between windows (s).
    #[arg(long, default_value_t = 0.01)]
    pub period: f64,
    /// Stop at this simulated time (s); default: the scenario's duration.
    #[arg(long)]
    pub until: Option<f64>,
    /// Service prefix of the run.
    #[arg(long, default_value = DEFAULT_PREFIX)]
    pub prefix: String,
}

pub fn run_cli(args: ForecastArgs) -> CliResult {
    let scenario = Scenario::load(&args.scenario)?;
    for (name, v) in [
        ("--dt", args.dt),
        ("--window", args.window),
        ("--period", args.period),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("{name} must be > 0, got {v}").into());
        }
    }
    let settings = ForecastSettings {
        dt: args.dt,
        window: args.window,
        period: args.period,
        until: Some(args.until.unwrap_or(scenario.duration)),
    };
    let bus = Bus::open(&args.prefix, "forecaster")?;
    tracing::info!(
        "forecasting `{}` on {}/forecast: {} samples every {} s of sim time",
        scenario.name,
        args.prefix,
        settings.samples(),
        settings.period
    );
    let sent = run(&bus, &scenario.force, &settings, stop_flag())?;
    tracing::info!("forecaster stopped after {sent} windows");
    Ok(())
}
