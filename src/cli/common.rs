//! Arguments and config loading shared by the subcommands.

use std::path::PathBuf;

use upc::config::{Config, ConfigError};
use upc::robot::Robot;
use upc::scenario::Scenario;

/// `--config` files and `--set` overrides, layered over the embedded defaults.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ConfigArgs {
    /// Extra config files layered over the defaults, in order.
    #[arg(long = "config")]
    pub configs: Vec<PathBuf>,
    /// Override any config key, e.g. --set preview.horizon=200 (applied last, in order).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

impl ConfigArgs {
    /// Defaults ← the robot's (computed, then its `[config]`) ← config files ← the scenario's
    /// `[config]` ← `extra` ← `--set`.
    pub fn load(
        &self,
        robot: &Robot,
        scenario: Option<&Scenario>,
        extra: &[String],
    ) -> Result<Config, ConfigError> {
        let mut layers = Config::layers_for(robot)?;
        for path in &self.configs {
            layers.push_file(path)?;
        }
        if let Some(table) = scenario.and_then(|s| s.config.as_ref()) {
            layers.push_table(
                &format!("{} [config]", scenario.map_or("", |s| &s.origin)),
                table.clone(),
            );
        }
        for s in extra.iter().chain(&self.sets) {
            layers.push_override(s)?;
        }
        layers.build()
    }

    /// The same arguments as a command line, to hand them to a child process.
    pub fn to_args(&self) -> Vec<String> {
        let mut v = Vec::new();
        for c in &self.configs {
            v.push("--config".into());
            v.push(c.display().to_string());
        }
        for s in &self.sets {
            v.push("--set".into());
            v.push(s.clone());
        }
        v
    }
}

/// `--robot`: which robot (shared by the subcommands that build or control one).
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArg {
    /// Robot: embedded description name (icub_like, icub, talos, g1) or path to a description
    /// TOML (config/robots/*.toml shows the format).
    #[arg(long, default_value = upc::robot::DEFAULT)]
    pub robot: String,
}

impl RobotArg {
    pub fn load(&self) -> Result<Robot, upc::robot::RobotError> {
        Robot::load(&self.robot)
    }
}
