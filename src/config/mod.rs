//! Configuration: layered TOML (embedded defaults ← files ← scenario overrides ← `--set`), typed with
//! serde, then range-checked. Every error names the offending key and the layer it came from.

mod layers;
mod schema;

pub use layers::{ConfigError, Layers};
pub use schema::*;

/// The defaults shipped inside the binary, so `upc` runs with no files around it.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

impl Config {
    /// The embedded defaults, typed and validated.
    pub fn embedded_default() -> Result<Config, ConfigError> {
        let mut layers = Layers::new();
        layers.push_str("<embedded config/default.toml>", DEFAULT_TOML)?;
        layers.build()
    }
}
