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

/// What every case of a sweep runs on besides its own variant and impact (`upc capability`,
/// `upc robustness`, one cell of either): the robot, the plant's sensing and keys, and the
/// controller's config layers.
#[derive(clap::Args, Debug, Clone)]
pub struct CaseSetup {
    /// What the plant publishes: its truth, or through the sensor models (docs/sensing.md).
    #[arg(long, value_enum)]
    pub sensing: Option<upc::sim::sensors::Sensing>,
    /// Every case's plant config key (`upc run --sim-set`), e.g. `sim.sensors.seed=2`.
    #[arg(long = "sim-set", value_name = "KEY=VALUE")]
    pub sim_sets: Vec<String>,
    #[command(flatten)]
    pub robot: RobotArg,
    /// Config files and `--set` keys for every case's controller (the variant's own key last).
    #[command(flatten)]
    pub config: ConfigArgs,
}

impl CaseSetup {
    /// What the user layered over the defaults, a Markdown paragraph each, so that a sweep's
    /// table is never read as the defaults'.
    pub fn layers_md(&self) -> String {
        let mut md = String::new();
        for f in &self.config.configs {
            md += &format!("Config file: `{}`\n\n", f.display());
        }
        for kv in &self.config.sets {
            md += &format!("Config: `--set {kv}`\n\n");
        }
        if let Some(s) = self.sensing {
            md += &format!("Sensing: `{}` (docs/sensing.md)\n\n", s.name());
        }
        for kv in &self.sim_sets {
            md += &format!("Plant: `--sim-set {kv}`\n\n");
        }
        md
    }
}

impl ToArgv for CaseSetup {
    fn write(&self, w: &mut Argv) {
        let CaseSetup {
            sensing,
            sim_sets,
            robot,
            config,
        } = self;
        fields!(w; opt_choice sensing, many sim_sets);
        w.nested(robot);
        w.nested(config);
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
