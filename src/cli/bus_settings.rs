//! The robot's bus on a command line, shared by `upc bus`, `upc sim --bus` and `upc run --bus`:
//! which bus, and its settings (`config/bus.toml`).

use std::path::PathBuf;

use upc::bus::BusConfig;

use super::argv::{Argv, ToArgv, fields};

/// The bus a robot speaks.
#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum BusChoice {
    /// Unitree's low-level DDS interface (`rt/lowstate`, `rt/lowcmd`; G1).
    Unitree,
}

/// The bus's settings on a command line (`upc bus`, `upc sim --bus`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BusSettingsArgs {
    /// Extra bus config files (layout of config/bus.toml) over the embedded defaults, in order.
    #[arg(long = "bus-config")]
    pub bus_configs: Vec<PathBuf>,
    /// Override a bus key, e.g. --bus-set bus.domain=0 (applied last, in order).
    #[arg(long = "bus-set", value_name = "KEY=VALUE")]
    pub bus_sets: Vec<String>,
}

impl BusSettingsArgs {
    pub fn load(&self) -> Result<BusConfig, upc::config::ConfigError> {
        BusConfig::load(&self.bus_configs, &self.bus_sets)
    }
}

impl ToArgv for BusSettingsArgs {
    fn write(&self, w: &mut Argv) {
        let BusSettingsArgs {
            bus_configs,
            bus_sets,
        } = self;
        fields!(w; many bus_configs, many bus_sets);
    }
}
