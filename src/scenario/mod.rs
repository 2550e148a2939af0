//! Scenarios: the hand force profile the door applies (known ahead, so it is also the forecast),
//! the ZMP reference, the duration, and optional config overrides.
//!
//! ```toml
//! name = "single_impact"
//! duration = 5.0
//! zmp_reference = [0.0, 0.0]
//! [force]
//! kind = "impacts"                # or kind = "csv", path = "forces.csv" (t, fx, fy, fz)
//! [[force.impacts]]
//! start = 1.0                     # s
//! rise = 0.25                     # raised-cosine rise (s)
//! hold = 0.1                      # plateau (s)
//! fall = 0.35                     # raised-cosine fall (s)
//! force = [-50.0, 0.0, 0.0]       # peak force on the hand (N, feet frame)
//! [config]                        # optional: any config keys, e.g. preview.horizon = 300
//! ```

mod profile;

use std::path::{Path, PathBuf};

use serde::Deserialize;

pub use profile::{ForceProfile, Impact};

use crate::config::{ConfigError, Layers};

/// The scenario every process plays when started without `--scenario` (simulator, forecaster,
/// controller, `upc run`): one default, so processes started by hand or by the systemd units
/// agree.
pub const DEFAULT: &str = "multiple_impacts";

/// FNV-1a (64 bit) over the bytes fed to it: a stable content hash (no per-process keys, unlike
/// std's hasher), used to tell whether two processes play the same scenario.
#[derive(Debug, Clone, Copy)]
pub struct ContentHash(u64);

impl Default for ContentHash {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl ContentHash {
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    pub fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    /// The hash, never 0 (0 means "none" in the channel contract).
    pub fn finish(&self) -> u64 {
        self.0.max(1)
    }
}

/// The scenarios shipped with upc, embedded so they run without files: (name, TOML).
pub const EMBEDDED: [(&str, &str); 3] = [
    (
        "single_impact",
        include_str!("../../config/scenarios/single_impact.toml"),
    ),
    (
        "multiple_impacts",
        include_str!("../../config/scenarios/multiple_impacts.toml"),
    ),
    (
        "standing",
        include_str!("../../config/scenarios/standing.toml"),
    ),
];

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    name: String,
    #[serde(default)]
    description: String,
    duration: f64,
    zmp_reference: [f64; 2],
    force: ForceSpec,
    #[serde(default)]
    config: Option<toml::Table>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
enum ForceSpec {
    Impacts { impacts: Vec<Impact> },
    Csv { path: PathBuf },
}

/// A loaded scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub name: String,
    pub description: String,
    pub duration: f64,
    pub zmp_reference: [f64; 2],
    pub force: ForceProfile,
    /// Config overrides carried by the scenario (a layer over the defaults).
    pub config: Option<toml::Table>,
    /// Where it came from, for messages.
    pub origin: String,
    /// Factor the file's forces were multiplied by ([`Scenario::with_force_scale`]); 1 as written.
    pub force_scale: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("scenario file {path} cannot be read: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error(
        "no scenario named `{0}`: give a path to a .toml file, or one of: single_impact, multiple_impacts, standing"
    )]
    Unknown(String),
    #[error(transparent)]
    Key(#[from] ConfigError),
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
}

impl Scenario {
    /// Hash of what the processes must agree on: the force profile, the ZMP reference and the
    /// duration (not the name, nor the config overrides, which only the controller reads).
    pub fn content_hash(&self) -> u64 {
        let mut h = ContentHash::default();
        self.force.hash_into(&mut h);
        for v in self.zmp_reference {
            h.f64(v);
        }
        h.f64(self.duration);
        h.finish()
    }

    /// The scenario with its forces multiplied by `s` (a robot heavier than the one the
    /// scenarios were written for is pushed harder: [`crate::robot::Robot::force_scale`]).
    /// The content hash follows the forces; `s = 1` leaves the scenario as it is.
    pub fn with_force_scale(mut self, s: f64) -> Scenario {
        if s != 1.0 {
            self.force = self.force.scaled(s);
            self.force_scale *= s;
        }
        self
    }

    /// Load by embedded name (`single_impact`) or by path to a TOML file.
    pub fn load(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        if let Some((name, text)) = EMBEDDED.iter().find(|(n, _)| *n == name_or_path) {
            return Self::parse(
                text,
                &format!("<embedded scenario {name}>"),
                Path::new("config/scenarios"),
            );
        }
        let path = Path::new(name_or_path);
        if !path.exists() && !name_or_path.ends_with(".toml") && !name_or_path.contains('/') {
            return Err(ScenarioError::Unknown(name_or_path.to_string()));
        }
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(
            &text,
            &path.display().to_string(),
            path.parent().unwrap_or(Path::new(".")),
        )
    }

    /// Parse scenario text; relative CSV paths resolve against `dir`.
    pub fn parse(text: &str, origin: &str, dir: &Path) -> Result<Scenario, ScenarioError> {
        let mut layers = Layers::new();
        layers.push_str(origin, text)?;
        let file: ScenarioFile = layers.typed()?;
        let invalid = |message: String| ScenarioError::Invalid {
            origin: origin.to_string(),
            message,
        };
        if !(file.duration.is_finite() && file.duration > 0.0) {
            return Err(invalid(format!(
                "key `duration` must be > 0, got {}",
                file.duration
            )));
        }
        if file.zmp_reference.iter().any(|v| !v.is_finite()) {
            return Err(invalid("key `zmp_reference` must be finite".into()));
        }
        let force = match file.force {
            ForceSpec::Impacts { impacts } => {
                for (i, imp) in impacts.iter().enumerate() {
                    imp.validate()
                        .map_err(|m| invalid(format!("key `force.impacts[{i}]`: {m}")))?;
                }
                ForceProfile::Impacts(impacts)
            }
            ForceSpec::Csv { path } => {
                let full = if path.is_absolute() {
                    path
                } else {
                    dir.join(path)
                };
                ForceProfile::from_csv(&full)
                    .map_err(|m| invalid(format!("key `force.path`: {m}")))?
            }
        };
        Ok(Scenario {
            name: file.name,
            description: file.description,
            duration: file.duration,
            zmp_reference: file.zmp_reference,
            force,
            config: file.config,
            origin: origin.to_string(),
            force_scale: 1.0,
        })
    }
}
