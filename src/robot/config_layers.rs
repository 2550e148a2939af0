//! The config every command starts from for a robot: the embedded defaults, then its
//! description's `[config]` ([`Robot::config_layers`]). Here, not in `crate::config`, so that
//! the config knows nothing of robots.

use super::Robot;
use crate::config::{Config, ConfigError, DEFAULT_TOML, Layers};

impl Config {
    /// The embedded defaults with the default robot's layers, typed and validated.
    pub fn embedded_default() -> Result<Config, ConfigError> {
        Self::default_layers()?.build()
    }

    /// [`Config::layers_for`] the embedded default robot.
    pub fn default_layers() -> Result<Layers, ConfigError> {
        let robot = Robot::embedded_default().map_err(|e| ConfigError::Robot {
            message: e.to_string(),
        })?;
        Self::layers_for(&robot)
    }

    /// The embedded defaults with `robot`'s `[config]`.
    pub fn for_robot(robot: &Robot) -> Result<Config, ConfigError> {
        Self::layers_for(robot)?.build()
    }

    /// The layers every config starts from: the embedded defaults, then the robot's.
    pub fn layers_for(robot: &Robot) -> Result<Layers, ConfigError> {
        let mut layers = Layers::new();
        layers.push_str("<embedded config/default.toml>", DEFAULT_TOML)?;
        robot.push_config(&mut layers);
        Ok(layers)
    }
}
