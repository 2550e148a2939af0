//! Arguments and config loading shared by the subcommands.

use std::path::{Path, PathBuf};

use upc::config::{Config, ConfigError};
use upc::robot::Robot;
use upc::scenario::Scenario;

use super::argv::{Argv, ToArgv, fields};

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
    /// Defaults ← the robot description's `[config]` ← config files ← the scenario's
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
        let config = layers.build()?;
        upc::control::parts::check(&config, &layers)?;
        Ok(config)
    }
}

impl ToArgv for ConfigArgs {
    fn write(&self, w: &mut Argv) {
        let ConfigArgs { configs, sets } = self;
        fields!(w; many configs, many sets);
    }
}

impl ToArgv for RobotArg {
    fn write(&self, w: &mut Argv) {
        let RobotArg { robot } = self;
        fields!(w; val robot);
    }
}

/// `--robot`: which robot (shared by the subcommands that build or control one).
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArg {
    /// Robot: embedded description name (icub_like, icub, talos, g1, romeo, romeo_locked) or path to a description
    /// TOML (config/robots/*.toml shows the format).
    #[arg(long, default_value = upc::robot::DEFAULT)]
    pub robot: String,
}

impl RobotArg {
    pub fn load(&self) -> Result<Robot, upc::robot::RobotError> {
        Robot::load(&self.robot)
    }
}

/// The Python of upc's Python participants (the MuJoCo plant, the remote forecaster): the
/// given one, `$UPC_PYTHON`, the `.venv` that `scripts/setup.sh` makes, else `python3`.
pub fn python(arg: &Option<PathBuf>) -> PathBuf {
    if let Some(p) = arg {
        return p.clone();
    }
    if let Some(p) = std::env::var_os("UPC_PYTHON") {
        return PathBuf::from(p);
    }
    // The working directory's venv, then the one of the source tree this binary was built from.
    [".", env!("CARGO_MANIFEST_DIR")]
        .iter()
        .map(|root| Path::new(root).join(".venv/bin/python"))
        .find(|p| p.exists())
        .unwrap_or_else(|| PathBuf::from("python3"))
}
