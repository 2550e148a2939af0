//! `upc bridge`: forward the contract's services between iceoryx2 and Zenoh.

use std::path::PathBuf;

use upc::bridge::{BridgeConfig, run};
use upc::shutdown::stop_flag;

use super::CliResult;
use super::argv::{Argv, ToArgv, fields};
use super::common::ConfigArgs;

#[derive(clap::Args, Debug)]
pub struct BridgeArgs {
    /// Files (layout of `config/bridge.toml`) and `--set bridge.key=value` overrides.
    #[command(flatten)]
    pub config: ConfigArgs,
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
    /// Accept plain TCP beyond loopback (no TLS: any host that reaches the port can read the
    /// robot's state and publish forecasts). Logged, and in the summary.
    #[arg(long)]
    pub insecure: bool,
    /// Write the bridge's counters here as JSON when it stops.
    #[arg(long)]
    pub summary: Option<PathBuf>,
}

impl ToArgv for BridgeArgs {
    fn write(&self, w: &mut Argv) {
        let BridgeArgs {
            config,
            prefix,
            key_prefix,
            listen,
            connect,
            insecure,
            summary,
        } = self;
        fields!(w; opt prefix, opt key_prefix, many listen, many connect, switch insecure,
                opt summary);
        w.nested(config);
    }
}

pub fn run_cli(args: BridgeArgs) -> CliResult {
    let mut sets = args.config.sets.clone();
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
    if args.insecure {
        sets.push("bridge.security.insecure=true".into());
    }
    let cfg = BridgeConfig::load(&args.config.configs, &sets)?;
    // Before Zenoh starts its threads: they inherit the blocked signals, this one handles them.
    let stop = stop_flag();
    let summary = run(&cfg, stop)?;
    tracing::info!(
        "bridge stopped ({}): {} forecasts forwarded, {} refused, {} dropped, {} from a second source, {} over the rate; {} states, {} ground truth, {} torques out; CPU {:.1} %",
        summary.security,
        summary.forecasts_forwarded,
        summary.forecasts_refused,
        summary.forecasts_dropped,
        summary.forecasts_second_source,
        summary.forecasts_rate_limited,
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
