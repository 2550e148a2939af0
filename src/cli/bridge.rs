//! `upc bridge`: forward the contract's services between iceoryx2 and Zenoh.

use std::path::PathBuf;

use upc::bridge::{BridgeConfig, run};
use upc::shutdown::stop_flag;

use super::CliResult;

#[derive(clap::Args)]
pub struct BridgeArgs {
    /// Config files layered over the embedded `config/bridge.toml`, in order.
    #[arg(long = "config")]
    pub configs: Vec<PathBuf>,
    /// Override a key, e.g. --set bridge.connect='["tcp/10.0.0.2:7447"]' (applied last).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// iceoryx2 service prefix (overrides bridge.prefix).
    #[arg(long)]
    pub prefix: Option<String>,
    /// Zenoh key prefix (overrides bridge.key_prefix; default with --prefix: the same prefix).
    #[arg(long)]
    pub key_prefix: Option<String>,
    /// Zenoh endpoints to listen on, e.g. tcp/0.0.0.0:7447 (repeatable; replaces bridge.listen).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to, e.g. tcp/10.0.0.1:7447 (repeatable; replaces
    /// bridge.connect).
    #[arg(long)]
    pub connect: Vec<String>,
    /// Write the bridge's counters here as JSON when it stops.
    #[arg(long)]
    pub summary: Option<PathBuf>,
}

pub fn run_cli(args: BridgeArgs) -> CliResult {
    let mut sets = args.sets.clone();
    for (key, v) in [
        ("bridge.prefix", &args.prefix),
        (
            "bridge.key_prefix",
            &args.key_prefix.as_ref().or(args.prefix.as_ref()).cloned(),
        ),
    ] {
        if let Some(v) = v {
            sets.push(format!("{key}={}", toml::Value::String(v.clone())));
        }
    }
    for (key, v) in [
        ("bridge.listen", &args.listen),
        ("bridge.connect", &args.connect),
    ] {
        if !v.is_empty() {
            let list = toml::Value::Array(v.iter().cloned().map(toml::Value::String).collect());
            sets.push(format!("{key}={list}"));
        }
    }
    let cfg = BridgeConfig::load(&args.configs, &sets)?;
    // Before Zenoh starts its threads: they inherit the blocked signals, this one handles them.
    let stop = stop_flag();
    let summary = run(&cfg, stop)?;
    tracing::info!(
        "bridge stopped: {} forecasts forwarded, {} refused, {} dropped; {} states, {} ground truth, {} torques out; CPU {:.1} %",
        summary.forecasts_forwarded,
        summary.forecasts_refused,
        summary.forecasts_dropped,
        summary.states_out,
        summary.ground_truth_out,
        summary.torques_out,
        summary.cpu_percent
    );
    if let Some(path) = &args.summary {
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)
            .map_err(|e| format!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}
