//! The bus's settings (`config/bus.toml`, embedded), layered like the rest of upc: embedded
//! defaults ← `--bus-config` files ← `--bus-set key=value`. Errors name the key and its layer.

use std::net::IpAddr;
use std::path::PathBuf;

use serde::Deserialize;

use super::dds::BusNetwork;
use crate::config::{ConfigError, Layers};

/// The defaults shipped inside the binary.
pub const BUS_TOML: &str = include_str!("../../config/bus.toml");

/// What a state with a CRC that does not match means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BadCrc {
    /// Refused and counted (a robot: the sample is corrupt).
    Refuse,
    /// Counted only (a simulator that leaves the CRC and the tick at zero).
    Count,
}

/// When the simulated robot leaves its harness (`bus.sim.harness`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HarnessRelease {
    /// At the first command that carries torques: a torque controller has the robot (through
    /// `upc bus`, whose hold before a controller is kp, kd and tau = 0).
    Torques,
    /// At the first valid command: a controller that drives the drives with their PD only.
    Command,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct BusFile {
    bus: BusConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusConfig {
    pub domain: u16,
    pub interface: IpAddr,
    pub discovery: f64,
    pub first_state_timeout: f64,
    pub state_timeout: f64,
    pub robot_lost: f64,
    pub command_timeout: f64,
    pub damping: f64,
    pub bad_crc: BadCrc,
    pub late: f64,
    pub hold: BusHold,
    pub sim: BusSim,
    /// Scheduling of `upc bus` (its loop and, created after it, the DDS library's threads).
    pub realtime: crate::config::RealtimeSettings,
}

/// The hand-over to the controller and the brace of its silence. The drives' gains are the
/// robot's (its description's `[bus] hold_kp`, `hold_kd`, per motor slot).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusHold {
    pub handover: f64,
    /// The controller silent (s of robot time) while the drives hold the posture it left the
    /// robot in, with its last torques: its answer meanwhile gives it the robot back at once;
    /// after this, damping, and a later answer gets the hold and a new hand-over.
    pub brace: f64,
}

/// Keys that moved out of the bus's settings, and where to.
const MOVED: [(&str, &str); 5] = [
    (
        "leg_kp",
        "the robot description's `[bus] hold_kp` (one gain per motor slot)",
    ),
    (
        "leg_kd",
        "the robot description's `[bus] hold_kd` (one gain per motor slot)",
    ),
    (
        "arm_kp",
        "the robot description's `[bus] hold_kp` (one gain per motor slot)",
    ),
    (
        "arm_kd",
        "the robot description's `[bus] hold_kd` (one gain per motor slot)",
    ),
    (
        "resume",
        "`bus.hold.brace`: the controller's answer during the brace resumes at once",
    ),
];

/// The simulated robot on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusSim {
    pub rate: f64,
    pub scenario_delay: f64,
    pub lab: bool,
    pub mode_machine: u8,
    pub command_loss: f64,
    /// [start, length] (s of robot time): no state goes out meanwhile, as states lost on the
    /// wire (a test of `upc bus`'s safety); length 0: never.
    pub silence: [f64; 2],
    pub harness: HarnessRelease,
}

impl BusConfig {
    pub fn load(files: &[PathBuf], sets: &[String]) -> Result<Self, ConfigError> {
        let layers = Layers::stack("<embedded config/bus.toml>", BUS_TOML, files, sets)?;
        for (old, new) in MOVED {
            let key = format!("bus.hold.{old}");
            if layers.has(&key) {
                return Err(layers.range_error(&key, format!("moved: {new}")));
            }
        }
        let file: BusFile = layers.typed()?;
        file.bus.validate(&layers)?;
        Ok(file.bus)
    }

    pub fn network(&self) -> BusNetwork {
        BusNetwork {
            domain: self.domain,
            interface: self.interface,
        }
    }

    fn validate(&self, l: &Layers) -> Result<(), ConfigError> {
        let check = |key: &str, v: f64, ok: bool, what: &str| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(l.range_error(key, format!("must be finite and {what}, got {v}")))
            }
        };
        for (key, v) in [
            ("bus.discovery", self.discovery),
            ("bus.hold.handover", self.hold.handover),
            ("bus.hold.brace", self.hold.brace),
            ("bus.sim.scenario_delay", self.sim.scenario_delay),
            ("bus.sim.silence", self.sim.silence[0]),
            ("bus.sim.silence", self.sim.silence[1]),
        ] {
            check(key, v, v >= 0.0, "≥ 0")?;
        }
        for (key, v) in [
            ("bus.first_state_timeout", self.first_state_timeout),
            ("bus.state_timeout", self.state_timeout),
            ("bus.robot_lost", self.robot_lost),
            ("bus.command_timeout", self.command_timeout),
            ("bus.damping", self.damping),
            ("bus.late", self.late),
            ("bus.sim.rate", self.sim.rate),
            ("bus.sim.command_loss", self.sim.command_loss),
        ] {
            check(key, v, v > 0.0, "> 0")?;
        }
        if self.robot_lost < self.state_timeout {
            return Err(l.range_error(
                "bus.robot_lost",
                format!(
                    "must be at least bus.state_timeout ({} s), got {}",
                    self.state_timeout, self.robot_lost
                ),
            ));
        }
        if self.domain > 232 {
            return Err(l.range_error(
                "bus.domain",
                format!("DDS domains are 0–232, got {}", self.domain),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_defaults_load_and_stay_on_the_loopback() {
        let c = BusConfig::load(&[], &[]).unwrap();
        assert!(c.interface.is_loopback());
        assert_eq!(c.bad_crc, BadCrc::Refuse);
        let e = BusConfig::load(&[], &["bus.damping=-1".into()]).unwrap_err();
        assert!(e.to_string().contains("bus.damping"), "{e}");
        // The hold's gains are the robot's now: an old setting is told where they went.
        let e = BusConfig::load(&[], &["bus.hold.leg_kp=100.0".into()]).unwrap_err();
        assert!(e.to_string().contains("hold_kp"), "{e}");
    }

    #[test]
    fn the_simulated_robot_leaves_its_harness_on_torques_unless_told_otherwise() {
        let c = BusConfig::load(&[], &[]).unwrap();
        assert_eq!(c.sim.harness, HarnessRelease::Torques);
        let c = BusConfig::load(&[], &["bus.sim.harness=\"command\"".into()]).unwrap();
        assert_eq!(c.sim.harness, HarnessRelease::Command);
        let e = BusConfig::load(&[], &["bus.sim.harness=\"never\"".into()]).unwrap_err();
        assert!(e.to_string().contains("harness"), "{e}");
    }
}
