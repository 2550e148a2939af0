//! Who may talk to the robot through the bridge (services/BRIDGE_SECURITY.md).
//!
//! Transport: mutual TLS with the lab's own CA (every participant shows a certificate the CA
//! signed; its common name is its identity), user/password optionally on top. Access control,
//! default deny, enforced by Zenoh on the bridge itself (the router every participant connects
//! to as a client): a forecaster identity may put forecasts on its own key
//! `<key_prefix>/forecast/<name>` only, so the key of a forecast names who sent it; viewers and
//! forecasters may only subscribe to what the bridge sends out; nobody may put anything else
//! (states, torques) into the network. Without identities (plain TCP) the bridge listens on
//! loopback only, unless told `insecure`.

use std::net::IpAddr;
use std::path::Path;

use serde::Deserialize;
use serde_json::{Value, json};

/// `[bridge.security]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecurityConfig {
    pub tls: bool,
    pub ca: String,
    pub certificate: String,
    pub private_key: String,
    pub users: String,
    pub forecasters: Vec<String>,
    pub viewers: Vec<String>,
    pub insecure: bool,
}

/// How participants are identified, as the summary and the log say it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Posture {
    /// Mutual TLS: the certificate's common name is the identity.
    MutualTls,
    /// Mutual TLS, and the same name must log in with its password.
    MutualTlsAndPassword,
    /// User/password over plain TCP on loopback (or `insecure`).
    Password,
    /// No identity: plain TCP on loopback; every local process is a forecaster and a viewer,
    /// as it already is on iceoryx2.
    PlainLoopback,
    /// No identity on a non-loopback endpoint: `insecure` was given.
    Insecure,
}

impl Posture {
    pub fn name(self) -> &'static str {
        match self {
            Posture::MutualTls => "mutual TLS",
            Posture::MutualTlsAndPassword => "mutual TLS + user/password",
            Posture::Password => "user/password over plain TCP",
            Posture::PlainLoopback => "plain TCP, loopback only",
            Posture::Insecure => "INSECURE: plain TCP beyond loopback",
        }
    }

    fn identified(self) -> bool {
        !matches!(self, Posture::PlainLoopback | Posture::Insecure)
    }
}

/// Where a key of the Zenoh side belongs.
pub struct Keys<'a> {
    pub prefix: &'a str,
}

impl Keys<'_> {
    /// Forecasts: `<prefix>/forecast` (anonymous, plain loopback only) or
    /// `<prefix>/forecast/<name>`.
    pub fn forecasts(&self) -> String {
        format!("{}/forecast/**", self.prefix)
    }

    /// The source a forecast's key names: `""` for `<prefix>/forecast`, else the name.
    pub fn source<'k>(&self, key: &'k str) -> &'k str {
        key.strip_prefix(self.prefix)
            .and_then(|k| k.strip_prefix("/forecast"))
            .map(|k| k.trim_start_matches('/'))
            .unwrap_or(key)
    }
}

impl SecurityConfig {
    /// The posture these settings give on these endpoints, or why they are refused.
    pub fn posture(&self, listen: &[String], connect: &[String]) -> Result<Posture, String> {
        let endpoints = || listen.iter().chain(connect);
        let posture = match (self.tls, !self.users.is_empty()) {
            (true, false) => Posture::MutualTls,
            (true, true) => Posture::MutualTlsAndPassword,
            (false, true) => Posture::Password,
            (false, false) => Posture::PlainLoopback,
        };
        if self.tls {
            if let Some(e) = endpoints().find(|e| !e.starts_with("tls/")) {
                return Err(format!(
                    "`{e}` is not a TLS endpoint: with bridge.security.tls every endpoint is tls/HOST:PORT"
                ));
            }
            for (key, path) in [
                ("ca", &self.ca),
                ("certificate", &self.certificate),
                ("private_key", &self.private_key),
            ] {
                if path.is_empty() || !Path::new(path).is_file() {
                    return Err(format!(
                        "bridge.security.{key} = `{path}` is not a file (TLS needs the lab's CA, this bridge's certificate and its key, PEM)"
                    ));
                }
            }
        } else if let Some(e) = endpoints().find(|e| !is_loopback(e)) {
            if !self.insecure {
                return Err(format!(
                    "`{e}` is reachable from other hosts and the bridge has no TLS: anyone there could read the robot's state and publish forecasts. Set bridge.security.tls (services/BRIDGE_SECURITY.md), or pass --insecure to accept this"
                ));
            }
            if posture == Posture::PlainLoopback {
                return Ok(Posture::Insecure);
            }
        }
        if !self.users.is_empty() && !Path::new(&self.users).is_file() {
            return Err(format!(
                "bridge.security.users = `{}` is not a file of `user:password` lines",
                self.users
            ));
        }
        let names = self.forecasters.iter().chain(&self.viewers);
        if posture.identified() {
            if self.forecasters.is_empty() && self.viewers.is_empty() {
                return Err("bridge.security: no forecaster nor viewer is named, so nobody could use the bridge (list certificate common names in `forecasters` and `viewers`)".into());
            }
        } else if names.clone().next().is_some() {
            return Err("bridge.security.forecasters / viewers name identities, but without TLS or a users file nobody can prove one".into());
        }
        if let Some(n) = names.clone().find(|n| !plain_chunk(n)) {
            return Err(format!(
                "bridge.security: `{n}` cannot be an identity (one key chunk: no '/', '*', '$', '?', '#', not empty)"
            ));
        }
        Ok(posture)
    }

    /// Write the transport and access-control settings into Zenoh's configuration.
    pub fn apply(
        &self,
        posture: Posture,
        key_prefix: &str,
        c: &mut zenoh::Config,
    ) -> Result<(), String> {
        let mut set = |key: &str, value: Value| {
            c.insert_json5(key, &value.to_string())
                .map_err(|e| format!("Zenoh config `{key}` = {value}: {e}"))
        };
        // Nothing reaches a participant but through the bridge: no discovery of peers.
        set("scouting/gossip/enabled", json!(false))?;
        if self.tls {
            let tls = "transport/link/tls";
            set(&format!("{tls}/root_ca_certificate"), json!(self.ca))?;
            for side in ["listen", "connect"] {
                set(
                    &format!("{tls}/{side}_certificate"),
                    json!(self.certificate),
                )?;
                set(
                    &format!("{tls}/{side}_private_key"),
                    json!(self.private_key),
                )?;
            }
            set(&format!("{tls}/enable_mtls"), json!(true))?;
            set(&format!("{tls}/verify_name_on_connect"), json!(true))?;
        }
        if !self.users.is_empty() {
            set("transport/auth/usrpwd/dictionary_file", json!(self.users))?;
        }
        set("access_control", self.access_control(posture, key_prefix))
    }

    /// Default deny; what each role may do (Zenoh's ACL, on the bridge's node).
    fn access_control(&self, posture: Posture, prefix: &str) -> Value {
        let k = |s: &str| format!("{prefix}/{s}");
        let subject = |id: String, name: &str| {
            let mut s = json!({ "id": id });
            if self.tls {
                s["cert_common_names"] = json!([name]);
            }
            if !self.users.is_empty() {
                s["usernames"] = json!([name]);
            }
            s
        };
        let rule = |id: &str, messages: &[&str], flow: &str, keys: Vec<String>| {
            json!({ "id": id, "messages": messages, "flows": [flow], "key_exprs": keys,
                    "permission": "allow" })
        };
        let mut rules = vec![
            // The bridge's subscriber is announced to forecasters, its state to the followers.
            rule(
                "forecast_subscriber_out",
                &["declare_subscriber"],
                "egress",
                vec![k("forecast/**")],
            ),
            rule(
                "state_in",
                &["declare_subscriber"],
                "ingress",
                vec![k("state")],
            ),
            rule("state_out", &["put"], "egress", vec![k("state")]),
            rule(
                "telemetry_in",
                &["declare_subscriber"],
                "ingress",
                vec![k("ground_truth"), k("torques")],
            ),
            rule(
                "telemetry_out",
                &["put"],
                "egress",
                vec![k("ground_truth"), k("torques")],
            ),
        ];
        let mut subjects = vec![];
        let mut policies = vec![];
        if posture.identified() {
            let forecasters: Vec<String> = self
                .forecasters
                .iter()
                .map(|n| format!("forecaster_{n}"))
                .collect();
            let viewers: Vec<String> = self.viewers.iter().map(|n| format!("viewer_{n}")).collect();
            for (n, id) in self.forecasters.iter().zip(&forecasters) {
                subjects.push(subject(id.clone(), n));
                // Its own key only: the key a forecast arrives on names its sender.
                let r = format!("forecast_put_{n}");
                rules.push(rule(
                    &r,
                    &["put"],
                    "ingress",
                    vec![k(&format!("forecast/{n}"))],
                ));
                policies.push(
                    json!({ "rules": [r, "forecast_subscriber_out", "state_in", "state_out"],
                                      "subjects": [id] }),
                );
            }
            for (n, id) in self.viewers.iter().zip(&viewers) {
                subjects.push(subject(id.clone(), n));
            }
            if !viewers.is_empty() {
                policies.push(
                    json!({ "rules": ["state_in", "state_out", "telemetry_in", "telemetry_out"],
                                      "subjects": viewers }),
                );
            }
        } else {
            // No identity can be proven: every peer is a forecaster (on any forecast key) and a
            // viewer; states and torques still never come in.
            subjects.push(json!({ "id": "anyone" }));
            rules.push(rule(
                "forecast_put_any",
                &["put"],
                "ingress",
                vec![k("forecast"), k("forecast/**")],
            ));
            policies.push(json!({ "rules": ["forecast_put_any", "forecast_subscriber_out",
                                             "state_in", "state_out", "telemetry_in", "telemetry_out"],
                                  "subjects": ["anyone"] }));
        }
        json!({ "enabled": true, "default_permission": "deny",
                "rules": rules, "subjects": subjects, "policies": policies })
    }
}

/// `tcp/127.0.0.1:7447`, `tcp/[::1]:7447`, `tcp/localhost:7447`: reachable from this host only.
fn is_loopback(endpoint: &str) -> bool {
    let Some((_, addr)) = endpoint.split_once('/') else {
        return false;
    };
    // Zenoh's endpoint metadata and configuration follow `?` and `#`.
    let addr = addr.split(['?', '#']).next().unwrap_or(addr);
    let host = addr.rsplit_once(':').map_or(addr, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost" || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

fn plain_chunk(n: &str) -> bool {
    !n.is_empty() && !n.contains(['/', '*', '$', '?', '#'])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plain() -> SecurityConfig {
        SecurityConfig {
            tls: false,
            ca: String::new(),
            certificate: String::new(),
            private_key: String::new(),
            users: String::new(),
            forecasters: vec![],
            viewers: vec![],
            insecure: false,
        }
    }

    #[test]
    fn loopback_endpoints() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tcp/127.0.0.2:1",
            "tcp/[::1]:7447",
            "tcp/localhost:7447",
        ] {
            assert!(is_loopback(e), "{e}");
        }
        for e in [
            "tcp/0.0.0.0:7447",
            "tcp/10.0.0.2:7447",
            "tcp/[::]:7447",
            "tcp/robot.lab:7447",
            "nonsense",
        ] {
            assert!(!is_loopback(e), "{e}");
        }
    }

    #[test]
    fn plain_beyond_loopback_needs_insecure_and_names_need_identities() {
        let s = plain();
        let lo = ["tcp/127.0.0.1:7447".to_string()];
        let lan = ["tcp/0.0.0.0:7447".to_string()];
        assert_eq!(s.posture(&lo, &[]), Ok(Posture::PlainLoopback));
        let e = s.posture(&lan, &[]).unwrap_err();
        assert!(
            e.contains("--insecure") && e.contains("tcp/0.0.0.0:7447"),
            "{e}"
        );
        let e = s.posture(&[], &lan).unwrap_err();
        assert!(e.contains("--insecure"), "{e}");
        let insecure = SecurityConfig {
            insecure: true,
            ..plain()
        };
        assert_eq!(insecure.posture(&lan, &[]), Ok(Posture::Insecure));
        let named = SecurityConfig {
            forecasters: vec!["fc".into()],
            ..plain()
        };
        assert!(named.posture(&lo, &[]).unwrap_err().contains("prove"));
        let tls = SecurityConfig {
            tls: true,
            ..plain()
        };
        assert!(tls.posture(&lo, &[]).unwrap_err().contains("tls/HOST:PORT"));
        let tls_ep = ["tls/127.0.0.1:7447".to_string()];
        assert!(
            tls.posture(&tls_ep, &[])
                .unwrap_err()
                .contains("bridge.security.ca")
        );
    }

    #[test]
    fn a_forecasts_key_names_its_source() {
        let k = Keys { prefix: "lab/upc" };
        assert_eq!(k.source("lab/upc/forecast"), "");
        assert_eq!(k.source("lab/upc/forecast/fc1"), "fc1");
        assert_eq!(k.forecasts(), "lab/upc/forecast/**");
    }

    #[test]
    fn identified_acl_binds_each_forecaster_to_its_own_key() {
        let s = SecurityConfig {
            tls: true,
            forecasters: vec!["fc1".into(), "fc2".into()],
            viewers: vec!["v".into()],
            ..plain()
        };
        let acl = s.access_control(Posture::MutualTls, "upc");
        assert_eq!(acl["default_permission"], "deny");
        let rule = |id: &str| {
            acl["rules"]
                .as_array()
                .unwrap()
                .iter()
                .find(|r| r["id"] == id)
                .cloned()
                .unwrap()
        };
        assert_eq!(
            rule("forecast_put_fc1")["key_exprs"],
            json!(["upc/forecast/fc1"])
        );
        assert_eq!(rule("forecast_put_fc2")["flows"], json!(["ingress"]));
        let subjects = acl["subjects"].as_array().unwrap();
        assert!(
            subjects
                .iter()
                .all(|s| s.get("cert_common_names").is_some())
        );
        // No rule lets anything but a forecast in.
        for r in acl["rules"].as_array().unwrap() {
            if r["flows"] == json!(["ingress"]) && r["messages"] == json!(["put"]) {
                assert!(
                    r["id"].as_str().unwrap().starts_with("forecast_put_"),
                    "{r}"
                );
            }
        }
        let mut c = zenoh::Config::default();
        let dir = std::env::temp_dir();
        let f = dir.to_string_lossy().to_string();
        let s = SecurityConfig {
            ca: f.clone(),
            certificate: f.clone(),
            private_key: f,
            ..s
        };
        s.apply(Posture::MutualTls, "upc", &mut c)
            .expect("Zenoh takes the settings");
    }
}
