//! `upc forecast`: publish a scenario's hand force forecast.

use upc::channels::{ContractNode, DEFAULT_PREFIX};
use upc::forecast::{ForecastError, ForecastSettings, ForecastShape, Source, run};
use upc::scenario::Scenario;
use upc::shutdown::stop_flag;

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};

#[derive(clap::Args, Debug)]
pub struct ForecastArgs {
    /// Scenario whose hand force is forecast: embedded name or TOML path. Default: the one the
    /// plant announces in its states (followed when it changes).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Sample spacing (s).
    #[arg(long, default_value_t = 0.005)]
    pub dt: f64,
    /// Window length (s); keep it longer than the controller's preview horizon.
    #[arg(long, default_value_t = 2.5)]
    pub window: f64,
    /// Simulated time between windows (s).
    #[arg(long, default_value_t = 0.01)]
    pub period: f64,
    /// Stop at this simulated time (s); default: the scenario's duration with --scenario, never
    /// when following the plant.
    #[arg(long)]
    pub until: Option<f64>,
    /// Service prefix of the run.
    #[arg(long, default_value = DEFAULT_PREFIX)]
    pub prefix: String,
    /// Forecast error: publish this multiple of the scenario's force (1: exact).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub error_scale: f64,
    /// Forecast error: publish the force this many seconds late (negative: early).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub error_shift: f64,
    /// Forecast error: the push's shape wrong on purpose: exact, truncated:F (only the first
    /// fraction F of each push), decaying:T (its peak from the onset, decaying with time
    /// constant T s), step, stretched:K (K times as long), rotated:D (D degrees about z).
    #[arg(long, default_value = "exact", allow_hyphen_values = true)]
    pub error_shape: ForecastShape,
}

impl ToArgv for ForecastArgs {
    fn write(&self, w: &mut Argv) {
        let ForecastArgs {
            scenario,
            dt,
            window,
            period,
            until,
            prefix,
            error_scale,
            error_shift,
            error_shape,
        } = self;
        fields!(w; opt scenario, val dt, val window, val period, opt until, val prefix,
                val error_scale, val error_shift, val error_shape);
    }
}

pub fn run_cli(args: ForecastArgs) -> CliResult {
    let scenario = args.scenario.as_deref().map(Scenario::load).transpose()?;
    for (name, v) in [
        ("--dt", args.dt),
        ("--window", args.window),
        ("--period", args.period),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("{name} must be > 0, got {v}").into());
        }
    }
    if !(args.error_scale.is_finite() && args.error_shift.is_finite()) {
        return Err("--error-scale and --error-shift must be finite".into());
    }
    let settings = ForecastSettings {
        dt: args.dt,
        window: args.window,
        period: args.period,
        until: args.until.or(scenario.as_ref().map(|s| s.duration)),
        error: ForecastError {
            scale: args.error_scale,
            shift: args.error_shift,
            shape: args.error_shape,
        },
    };
    // A shape the scenario cannot take is refused now, not window by window.
    if let Some(s) = &scenario {
        args.error_shape.apply(&s.force)?;
    }
    if settings.error != ForecastError::NONE {
        tracing::warn!(
            "forecast error on purpose: forces × {}, {} s late, shape {}",
            args.error_scale,
            args.error_shift,
            args.error_shape
        );
    }
    let node = ContractNode::open(&args.prefix, "forecaster")?;
    tracing::info!(
        "forecasting {} on {}/forecast: {} samples every {} s of sim time",
        scenario
            .as_ref()
            .map_or("the plant's scenario".into(), |s| format!("`{}`", s.name)),
        args.prefix,
        settings.samples(),
        settings.period
    );
    let source = match scenario {
        Some(s) => Source::Fixed(s),
        None => Source::FollowPlant,
    };
    let sent = run(&node, &source, &settings, stop_flag())?;
    tracing::info!("forecaster stopped after {sent} windows");
    Ok(())
}
