//! The simulator's configuration (`config/sim.toml`, embedded), layered like the rest of upc:
//! embedded defaults ← `--config` files ← `--set key=value`. Errors name the key and its layer.

use std::path::PathBuf;

use serde::Deserialize;

use crate::config::{ConfigError, Layers};

/// The defaults shipped inside the binary.
pub const SIM_TOML: &str = include_str!("../../config/sim.toml");

/// Stepping mode of the process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Wait for the torques answering each published state (deterministic).
    Lockstep,
    /// Step at wall-clock rate with the latest torques.
    Realtime,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimFile {
    pub sim: SimConfig,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    pub dt: f64,
    pub mode: Mode,
    pub duration: f64,
    pub friction: f64,
    pub joint_damping: f64,
    pub door_damping: f64,
    pub joint_limits: bool,
    pub effort_limits: bool,
    pub door: bool,
    pub push: Push,
    pub scenario: String,
    pub record_period: f64,
    pub solver: SolverConfig,
    pub process: ProcessConfig,
    pub hold: HoldConfig,
    pub mujoco: MujocoConfig,
    /// What the robot's sensors make of the plant's state (docs/sensing.md).
    pub sensors: super::sensors::SensorsConfig,
}

/// How the scenario's force reaches the hand (`sim.push`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Push {
    /// Through the door: its hinge torque, so only the component along the tangent of the
    /// hinge's circle (x at the handle) pushes the hand.
    Door,
    /// No door: the force applied at the hand frame as it is, in any direction.
    Hand,
    /// The door held at the hand, and no push at all: the scenario's force is only what a
    /// forecaster announces (a phantom push, for tests of forecasts the hand contradicts).
    None,
}

/// MuJoCo's friction cone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Cone {
    Pyramidal,
    Elliptic,
}

/// The MuJoCo plant's solver settings (`[sim.mujoco]`; the rest of the scene follows the
/// simulator's own keys).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MujocoConfig {
    pub cone: Cone,
    pub impratio: f64,
    /// Iterations of MuJoCo's no-slip solver after the main one (0: off): it removes the slow
    /// creep that soft friction allows under a sustained tangential load.
    pub noslip_iterations: u32,
    /// The contact spheres' constraint time constant (s; MuJoCo's `solref` with damping ratio
    /// 1). With MuJoCo's default, 0.02 s, the feet creep sideways during the pushes, which the
    /// no-slip solver does not remove; 0.002 s halves that. MuJoCo integrates down to twice
    /// the step.
    pub contact_timeconst: f64,
}

/// What holds the robot when no controller does (`[sim.hold]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldKind {
    /// A stiff joint-space PD at the posture to hold (as a robot's start-up controller).
    PosturePd,
    /// Joint damping only: the robot is not held (the behaviour before holds existed).
    Damping,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HoldConfig {
    pub kind: HoldKind,
    pub frequency: f64,
    pub damping_ratio: f64,
    pub leg_kp: f64,
    pub leg_kd: f64,
    pub handover: f64,
    pub feedforward_fade: f64,
    pub lost_timeout: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverConfig {
    pub max_iterations: usize,
    pub tolerance: f64,
    pub regularisation: f64,
    pub contact_stabilisation: f64,
    pub loop_stabilisation: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessConfig {
    pub prefix: String,
    pub lockstep_timeout: f64,
    pub command_timeout: f64,
    pub safe_damping: f64,
    pub first_command_timeout: f64,
    /// Lockstep: poll for the answering torques this long (µs) before sleeping on their event.
    pub ipc_spin_us: f64,
}

impl SimConfig {
    /// The embedded defaults.
    pub fn embedded() -> Result<SimConfig, ConfigError> {
        Self::load(&[], &[])
    }

    /// Embedded defaults, then `files` in order, then `sets` (`sim.key=value`).
    pub fn load(files: &[PathBuf], sets: &[String]) -> Result<SimConfig, ConfigError> {
        let layers = Layers::stack("<embedded config/sim.toml>", SIM_TOML, files, sets)?;
        let file: SimFile = layers.typed()?;
        file.sim.validate(&layers)?;
        Ok(file.sim)
    }

    fn validate(&self, l: &Layers) -> Result<(), ConfigError> {
        let pos = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(l.range_error(key, format!("must be finite and > 0, got {v}")))
            }
        };
        let nonneg = |key: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(l.range_error(key, format!("must be finite and ≥ 0, got {v}")))
            }
        };
        let unit = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= 1.0 {
                Ok(())
            } else {
                Err(l.range_error(key, format!("must be in (0, 1], got {v}")))
            }
        };
        pos("sim.dt", self.dt)?;
        if self.dt > 0.02 {
            return Err(l.range_error("sim.dt", format!("must be ≤ 0.02 s, got {}", self.dt)));
        }
        nonneg("sim.duration", self.duration)?;
        nonneg("sim.friction", self.friction)?;
        nonneg("sim.joint_damping", self.joint_damping)?;
        nonneg("sim.door_damping", self.door_damping)?;
        pos("sim.record_period", self.record_period)?;
        if self.solver.max_iterations == 0 {
            return Err(l.range_error("sim.solver.max_iterations", "must be ≥ 1"));
        }
        nonneg("sim.solver.tolerance", self.solver.tolerance)?;
        nonneg("sim.solver.regularisation", self.solver.regularisation)?;
        unit(
            "sim.solver.contact_stabilisation",
            self.solver.contact_stabilisation,
        )?;
        unit(
            "sim.solver.loop_stabilisation",
            self.solver.loop_stabilisation,
        )?;
        if self.process.prefix.is_empty() {
            return Err(l.range_error("sim.process.prefix", "must not be empty"));
        }
        pos(
            "sim.process.lockstep_timeout",
            self.process.lockstep_timeout,
        )?;
        pos("sim.process.command_timeout", self.process.command_timeout)?;
        nonneg("sim.process.safe_damping", self.process.safe_damping)?;
        nonneg("sim.process.ipc_spin_us", self.process.ipc_spin_us)?;
        pos(
            "sim.process.first_command_timeout",
            self.process.first_command_timeout,
        )?;
        pos("sim.hold.frequency", self.hold.frequency)?;
        pos("sim.hold.damping_ratio", self.hold.damping_ratio)?;
        nonneg("sim.hold.leg_kp", self.hold.leg_kp)?;
        nonneg("sim.hold.leg_kd", self.hold.leg_kd)?;
        nonneg("sim.hold.handover", self.hold.handover)?;
        nonneg("sim.hold.feedforward_fade", self.hold.feedforward_fade)?;
        nonneg("sim.hold.lost_timeout", self.hold.lost_timeout)?;
        if let Some((key, msg)) = self.sensors.invalid() {
            return Err(l.range_error(&format!("sim.sensors.{key}"), msg));
        }
        let tc = self.mujoco.contact_timeconst;
        if !(tc.is_finite() && tc >= 2.0 * self.dt) {
            return Err(l.range_error(
                "sim.mujoco.contact_timeconst",
                format!(
                    "must be finite and ≥ 2 × sim.dt = {} s (MuJoCo cannot integrate a stiffer contact), got {tc}",
                    2.0 * self.dt
                ),
            ));
        }
        if !(self.mujoco.impratio.is_finite() && self.mujoco.impratio >= 1.0) {
            return Err(l.range_error(
                "sim.mujoco.impratio",
                format!("must be finite and ≥ 1, got {}", self.mujoco.impratio),
            ));
        }
        Ok(())
    }
}
