//! The controller parts' tables (`[controller.<part>]`): each part declares its settings type
//! beside its code ([`PartSettings`]); the config keeps the tables as TOML until the part reads
//! its own, so adding a part adds no field here. Their defaults have one home, the embedded
//! `config/default.toml`: a part's `Default` is [`embedded_part`].

use std::collections::BTreeMap;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::{ConfigError, DEFAULT_TOML, Layers};

/// The settings of one controller part: its table's name under `[controller]` and its checks.
pub trait PartSettings: DeserializeOwned + Serialize {
    /// The table: `[controller.<TABLE>]`.
    const TABLE: &'static str;
    /// Why the settings are unusable, if they are: (key within the table, reason).
    fn check(&self) -> Result<(), (&'static str, String)> {
        Ok(())
    }
}

/// Parts' tables that were renamed (old, new), so that an old config is told what to write.
const RENAMED: &[(&str, &str)] = &[("estimator", "base_estimation")];

/// The `[controller]` tables that belong to parts, as TOML.
#[derive(Debug, Clone, Default, serde::Deserialize)]
#[serde(transparent)]
pub struct PartTables(BTreeMap<String, toml::Value>);

impl PartTables {
    /// The settings of part `S`, deserialized and checked; the error names the key.
    pub fn get<S: PartSettings>(&self) -> Result<S, ConfigError> {
        let key = |k: &str| format!("controller.{}{k}", S::TABLE);
        let value = self
            .0
            .get(S::TABLE)
            .cloned()
            .ok_or_else(|| ConfigError::Key {
                key: key(""),
                origin: "<merged config>".into(),
                message: "missing table".into(),
            })?;
        let s: S = serde_path_to_error::deserialize(value).map_err(|e| ConfigError::Key {
            key: key(&format!(".{}", e.path())),
            origin: "<merged config>".into(),
            message: e.inner().to_string(),
        })?;
        s.check().map_err(|(k, why)| ConfigError::Key {
            key: key(&format!(".{k}")),
            origin: "<merged config>".into(),
            message: why,
        })?;
        Ok(s)
    }

    /// Replace part `S`'s table (a sweep's variant, a bench's).
    pub fn set<S: PartSettings>(&mut self, settings: &S) -> Result<(), ConfigError> {
        let v = toml::Value::try_from(settings).map_err(|e| ConfigError::Key {
            key: format!("controller.{}", S::TABLE),
            origin: "<set in code>".into(),
            message: e.to_string(),
        })?;
        self.0.insert(S::TABLE.into(), v);
        Ok(())
    }

    /// Every key is a part's table of the embedded defaults, with keys the defaults know: a
    /// misspelt key is refused at load, as `deny_unknown_fields` does for the typed tables.
    pub(crate) fn check_keys(&self, l: &Layers) -> Result<(), ConfigError> {
        let defaults = embedded_controller_tables();
        for (name, value) in &self.0 {
            let key = format!("controller.{name}");
            let (Some(toml::Value::Table(known)), toml::Value::Table(given)) =
                (defaults.get(name), value)
            else {
                let why = match RENAMED.iter().find(|(old, _)| old == name) {
                    Some((_, new)) => format!("renamed: [controller.{new}]"),
                    None => "unknown key".into(),
                };
                return Err(l.range_error(&key, why));
            };
            if let Some(k) = given.keys().find(|k| !known.contains_key(*k)) {
                return Err(l.range_error(&format!("{key}.{k}"), "unknown key"));
            }
        }
        Ok(())
    }
}

/// The `[controller]` table of the embedded defaults.
// The embedded file is part of the binary, parsed by every test that loads a config: it cannot
// be malformed at run time.
#[allow(clippy::expect_used)]
fn embedded_controller_tables() -> toml::Table {
    let mut all: toml::Table = DEFAULT_TOML
        .parse()
        .expect("config/default.toml is valid TOML");
    match all.remove("controller") {
        Some(toml::Value::Table(t)) => t,
        _ => toml::Table::new(),
    }
}

/// Part `S`'s defaults: its table in the embedded `config/default.toml`, the one place they are
/// written (`tests/parts.rs` checks every part's table deserializes and passes its checks). Not
/// for the real-time path: it parses the file.
#[allow(clippy::panic)]
pub fn embedded_part<S: PartSettings>() -> S {
    let table = embedded_controller_tables()
        .remove(S::TABLE)
        .unwrap_or_else(|| panic!("config/default.toml has no [controller.{}]", S::TABLE));
    table
        .try_into()
        .unwrap_or_else(|e| panic!("config/default.toml [controller.{}]: {e}", S::TABLE))
}
