//! Configuration: layered TOML (embedded defaults ← files ← scenario overrides ← `--set`), typed with
//! serde, then range-checked. Every error names the offending key and the layer it came from.

mod controller_settings;
mod layers;
mod parts;
mod schema;

pub use controller_settings::RealtimeSettings;
pub use layers::{ConfigError, Layers};
pub use parts::{PartSettings, PartTables, embedded_part};
pub use schema::*;

/// The defaults shipped inside the binary, so `upc` runs with no files around it.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");
