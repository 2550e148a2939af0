//! Configuration: layered TOML (embedded defaults ← files ← scenario overrides ← `--set`), typed with
//! serde, then range-checked. Every error names the offending key and the layer it came from.

mod layers;
mod schema;

pub use layers::{ConfigError, Layers};
pub use schema::*;

/// The defaults shipped inside the binary, so `upc` runs with no files around it.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

impl Config {
    /// The embedded defaults with the default robot's layers, typed and validated.
    pub fn embedded_default() -> Result<Config, ConfigError> {
        Self::default_layers()?.build()
    }

    /// [`Config::layers_for`] the embedded default robot.
    pub fn default_layers() -> Result<Layers, ConfigError> {
        let robot = crate::robot::Robot::embedded_default().map_err(|e| ConfigError::Robot {
            message: e.to_string(),
        })?;
        Self::layers_for(&robot)
    }

    /// The embedded defaults with `robot`'s layers (computed values, then its `[config]`).
    pub fn for_robot(robot: &crate::robot::Robot) -> Result<Config, ConfigError> {
        Self::layers_for(robot)?.build()
    }

    /// The layers every config starts from: the embedded defaults, then the robot's.
    pub fn layers_for(robot: &crate::robot::Robot) -> Result<Layers, ConfigError> {
        let mut layers = Layers::new();
        layers.push_str("<embedded config/default.toml>", DEFAULT_TOML)?;
        robot.push_config(&mut layers);
        Ok(layers)
    }
}
