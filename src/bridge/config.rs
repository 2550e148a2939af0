//! The bridge's configuration (`config/bridge.toml`, embedded), layered like the rest of upc:
//! embedded defaults ← `--config` files ← `--set key=value`. Errors name the key and its layer.

use std::path::PathBuf;

use serde::Deserialize;

use super::security::{Posture, SecurityConfig};
use crate::config::{ConfigError, Layers};

/// The defaults shipped inside the binary.
pub const BRIDGE_TOML: &str = include_str!("../../config/bridge.toml");

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct BridgeFile {
    bridge: BridgeConfig,
}

/// Zenoh's role for this process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ZenohMode {
    Peer,
    Client,
    Router,
}

impl ZenohMode {
    pub fn name(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeConfig {
    pub prefix: String,
    pub key_prefix: String,
    pub mode: ZenohMode,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub multicast_scouting: bool,
    pub decimation: u32,
    pub forecast_in: bool,
    pub state_out: bool,
    pub ground_truth_out: bool,
    pub torques_out: bool,
    pub inbound_queue: usize,
    pub forecast_rate_hz: f64,
    pub forecast_burst: u32,
    pub source_takeover: f64,
    pub security: SecurityConfig,
}

impl BridgeConfig {
    pub fn load(files: &[PathBuf], sets: &[String]) -> Result<BridgeConfig, ConfigError> {
        let layers = Layers::stack("<embedded config/bridge.toml>", BRIDGE_TOML, files, sets)?;
        let file: BridgeFile = layers.typed()?;
        file.bridge.validate(&layers)?;
        Ok(file.bridge)
    }

    fn validate(&self, l: &Layers) -> Result<(), ConfigError> {
        if self.decimation == 0 {
            return Err(l.range_error("bridge.decimation", "must be ≥ 1"));
        }
        if self.inbound_queue == 0 {
            return Err(l.range_error("bridge.inbound_queue", "must be ≥ 1"));
        }
        if !(self.forecast_rate_hz > 0.0 && self.forecast_rate_hz.is_finite()) {
            return Err(l.range_error("bridge.forecast_rate_hz", "must be > 0"));
        }
        if self.forecast_burst == 0 {
            return Err(l.range_error("bridge.forecast_burst", "must be ≥ 1"));
        }
        if !(self.source_takeover >= 0.0 && self.source_takeover.is_finite()) {
            return Err(l.range_error("bridge.source_takeover", "must be ≥ 0 s"));
        }
        for (key, v) in [
            ("bridge.key_prefix", &self.key_prefix),
            ("bridge.prefix", &self.prefix),
        ] {
            // A key expression's chunks: no wildcards, no empty chunk (Zenoh would refuse it
            // later, with a message that does not name the key).
            if v.is_empty()
                || v.split('/')
                    .any(|c| c.is_empty() || c.contains(['*', '$', '?', '#']))
            {
                return Err(l.range_error(key, format!("`{v}` is not a plain key prefix")));
            }
        }
        let posture = self
            .posture()
            .map_err(|e| l.range_error("bridge.security", e))?;
        if posture != Posture::PlainLoopback && self.mode != ZenohMode::Router {
            return Err(l.range_error(
                "bridge.mode",
                "must be \"router\" beyond plain loopback: participants connect to the bridge as clients, so that all traffic crosses its access control",
            ));
        }
        if posture != Posture::PlainLoopback && self.multicast_scouting {
            return Err(l.range_error(
                "bridge.multicast_scouting",
                "must be off beyond plain loopback (peers found by multicast could bypass the bridge)",
            ));
        }
        if self.mode == ZenohMode::Client && self.connect.is_empty() {
            return Err(l.range_error(
                "bridge.connect",
                "a client needs the endpoint of a router (or peer) to connect to",
            ));
        }
        Ok(())
    }

    /// Who may connect and how they are identified (refused: why).
    pub fn posture(&self) -> Result<Posture, String> {
        self.security.posture(&self.listen, &self.connect)
    }

    /// The Zenoh session's configuration.
    pub fn zenoh(&self) -> Result<zenoh::Config, String> {
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|e| format!("Zenoh config `{key}` = {value}: {e}"))
        };
        set(&mut c, "mode", json(self.mode.name()))?;
        set(&mut c, "listen/endpoints", json(&self.listen))?;
        set(&mut c, "connect/endpoints", json(&self.connect))?;
        set(
            &mut c,
            "scouting/multicast/enabled",
            self.multicast_scouting.to_string(),
        )?;
        self.security
            .apply(self.posture()?, &self.key_prefix, &mut c)?;
        Ok(c)
    }
}

/// JSON of a config value, for Zenoh's `insert_json5` (strings and lists of strings: cannot fail).
fn json<T: serde::Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_load_and_bad_values_name_their_key() {
        let c = BridgeConfig::load(&[], &[]).unwrap();
        assert_eq!(c.mode, ZenohMode::Router);
        assert_eq!(c.posture(), Ok(Posture::PlainLoopback));
        assert_eq!(c.listen, vec!["tcp/127.0.0.1:7447".to_string()]);
        c.zenoh().unwrap();
        let e = BridgeConfig::load(&[], &["bridge.decimation=0".into()]).unwrap_err();
        assert!(e.to_string().contains("bridge.decimation"), "{e}");
        let e = BridgeConfig::load(&[], &["bridge.key_prefix=\"a/*\"".into()]).unwrap_err();
        assert!(e.to_string().contains("bridge.key_prefix"), "{e}");
        let e =
            BridgeConfig::load(&[], &["bridge.listen=[\"tcp/0.0.0.0:7447\"]".into()]).unwrap_err();
        assert!(e.to_string().contains("--insecure"), "{e}");
        let e = BridgeConfig::load(
            &[],
            &[
                "bridge.listen=[\"tcp/0.0.0.0:7447\"]".into(),
                "bridge.security.insecure=true".into(),
                "bridge.mode=\"peer\"".into(),
            ],
        )
        .unwrap_err();
        assert!(e.to_string().contains("bridge.mode"), "{e}");
        let e = BridgeConfig::load(&[], &["bridge.mode=\"client\"".into()]).unwrap_err();
        assert!(e.to_string().contains("bridge.connect"), "{e}");
        let e = BridgeConfig::load(
            &[],
            &[
                "bridge.listen=[\"nonsense\"]".into(),
                "bridge.security.insecure=true".into(),
            ],
        )
        .unwrap()
        .zenoh()
        .unwrap_err();
        assert!(e.contains("listen/endpoints"), "{e}");
    }
}
