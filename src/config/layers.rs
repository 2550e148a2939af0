//! Merging TOML layers while remembering which layer set each key, so errors can name the file.

use std::collections::BTreeMap;
use std::path::Path;

use serde::de::DeserializeOwned;

/// A configuration error that names the key (dotted path) and where its value came from.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config file {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{origin}: TOML syntax error: {message}")]
    Syntax { origin: String, message: String },
    #[error("config key `{key}` (from {origin}): {message}")]
    Key {
        key: String,
        origin: String,
        message: String,
    },
    #[error("bad override `{text}`: expected key=value, e.g. preview.horizon=300")]
    Override { text: String },
    #[error("robot: {message}")]
    Robot { message: String },
}

/// Ordered TOML layers merged into one table; later layers win key by key.
#[derive(Default)]
pub struct Layers {
    merged: toml::Table,
    origin: BTreeMap<String, String>,
}

impl Layers {
    pub fn new() -> Self {
        Self::default()
    }

    /// Embedded defaults, then `files`, then `--set` overrides: the stack of a process's own
    /// config file (`config/sim.toml`, `config/bridge.toml`).
    pub fn stack(
        origin: &str,
        defaults: &str,
        files: &[std::path::PathBuf],
        sets: &[String],
    ) -> Result<Self, ConfigError> {
        let mut layers = Self::new();
        layers.push_str(origin, defaults)?;
        for f in files {
            layers.push_file(f)?;
        }
        for s in sets {
            layers.push_override(s)?;
        }
        Ok(layers)
    }

    /// Add a layer from TOML text; `origin` names it in errors (a path, or `<embedded …>`).
    pub fn push_str(&mut self, origin: &str, text: &str) -> Result<(), ConfigError> {
        let table: toml::Table =
            text.parse()
                .map_err(|e: toml::de::Error| ConfigError::Syntax {
                    origin: origin.to_string(),
                    message: e.to_string(),
                })?;
        self.push_table(origin, table);
        Ok(())
    }

    /// Add a layer from a TOML file.
    pub fn push_file(&mut self, path: &Path) -> Result<(), ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        self.push_str(&path.display().to_string(), &text)
    }

    /// Add an already-parsed table (for example a scenario's `[config]` section).
    pub fn push_table(&mut self, origin: &str, table: toml::Table) {
        merge(&mut self.merged, table, "", origin, &mut self.origin);
    }

    /// Apply a `key.path=value` override from the command line. The value is parsed as TOML
    /// (numbers, booleans, arrays); anything else is taken as a string.
    pub fn push_override(&mut self, text: &str) -> Result<(), ConfigError> {
        let (key, value) = text
            .split_once('=')
            .filter(|(k, _)| !k.trim().is_empty())
            .ok_or_else(|| ConfigError::Override {
                text: text.to_string(),
            })?;
        let value = value.trim();
        let parsed: toml::Value = format!("v = {value}")
            .parse::<toml::Table>()
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut table = toml::Table::new();
        let parts: Vec<&str> = key.trim().split('.').collect();
        let mut cursor = &mut table;
        for part in &parts[..parts.len() - 1] {
            cursor = cursor
                .entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .ok_or_else(|| ConfigError::Override {
                    text: text.to_string(),
                })?;
        }
        cursor.insert(parts[parts.len() - 1].to_string(), parsed);
        self.push_table("--set", table);
        Ok(())
    }

    /// Whether any layer sets `key` (a dotted path).
    pub fn has(&self, key: &str) -> bool {
        let mut t = &self.merged;
        let mut parts = key.split('.').peekable();
        while let Some(p) = parts.next() {
            match (t.get(p), parts.peek()) {
                (Some(_), None) => return true,
                (Some(toml::Value::Table(inner)), Some(_)) => t = inner,
                _ => return false,
            }
        }
        false
    }

    /// Where the value at `key` came from.
    pub fn origin_of(&self, key: &str) -> String {
        // The deepest recorded prefix of the key: unknown keys are recorded too.
        let mut k = key;
        loop {
            if let Some(o) = self.origin.get(k) {
                return o.clone();
            }
            match k.rsplit_once('.') {
                Some((head, _)) => k = head,
                None => return "<merged config>".to_string(),
            }
        }
    }

    /// Deserialize the merged table into `T`, naming the key path on failure.
    pub fn typed<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let value = toml::Value::Table(self.merged.clone());
        serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            ConfigError::Key {
                origin: self.origin_of(&key),
                message: e.inner().to_string(),
                key,
            }
        })
    }

    /// Build an error for a key whose value is out of range.
    pub fn range_error(&self, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Key {
            key: key.to_string(),
            origin: self.origin_of(key),
            message: message.into(),
        }
    }
}

fn merge(
    into: &mut toml::Table,
    from: toml::Table,
    prefix: &str,
    origin: &str,
    origins: &mut BTreeMap<String, String>,
) {
    for (k, v) in from {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match (into.get_mut(&k), v) {
            (Some(toml::Value::Table(dst)), toml::Value::Table(src)) => {
                merge(dst, src, &path, origin, origins)
            }
            (_, v) => {
                if let toml::Value::Table(t) = &v {
                    record_all(t, &path, origin, origins);
                }
                origins.insert(path, origin.to_string());
                into.insert(k, v);
            }
        }
    }
}

fn record_all(t: &toml::Table, prefix: &str, origin: &str, origins: &mut BTreeMap<String, String>) {
    for (k, v) in t {
        let path = format!("{prefix}.{k}");
        if let toml::Value::Table(sub) = v {
            record_all(sub, &path, origin, origins);
        }
        origins.insert(path, origin.to_string());
    }
}
