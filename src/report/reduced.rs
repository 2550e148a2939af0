//! The reduced-model section: C0, C1 and C2 on the cart-table and hand impedance models
//! (`upc preview`'s loop), in-process, with the run's scenario and config layers.

use std::path::PathBuf;

use super::ReportError;
use super::series::ReducedRun;
use crate::config::{Config, ControllerKind};
use crate::robot::{ReducedModel, Robot};
use crate::scenario::Scenario;

/// Config layers as `upc` builds them: defaults ← the robot's ← files ← the scenario's
/// `[config]` ← sets.
#[derive(Debug, Clone, Default)]
pub struct ConfigLayers {
    pub files: Vec<PathBuf>,
    pub sets: Vec<String>,
}

impl ConfigLayers {
    pub fn load(&self, robot: &Robot, scenario: &Scenario) -> Result<Config, ReportError> {
        let mut layers = Config::layers_for(robot)?;
        for path in &self.files {
            layers.push_file(path)?;
        }
        if let Some(table) = &scenario.config {
            layers.push_table(&format!("{} [config]", scenario.origin), table.clone());
        }
        for s in &self.sets {
            layers.push_override(s)?;
        }
        let config = layers.build()?;
        crate::control::parts::check(&config, &layers)?;
        Ok(config)
    }
}

/// C0, C1 and C2 on `robot`'s reduced models, in that order.
pub fn run_reduced(
    config: &Config,
    robot: ReducedModel,
    scenario: &Scenario,
) -> Result<Vec<ReducedRun>, ReportError> {
    [ControllerKind::C0, ControllerKind::C1, ControllerKind::C2]
        .into_iter()
        .map(|kind| {
            crate::offline::ReducedLoop::new(config, robot, scenario, kind)
                .run()
                .map(|r| ReducedRun::new(r, robot.support))
                .map_err(|source| ReportError::Preview {
                    scenario: scenario.name.clone(),
                    controller: kind.name().to_uppercase(),
                    source,
                })
        })
        .collect()
}

/// Smallest signed distance of the ZMP to the edge of the support rectangle over the samples
/// (m; negative when it is outside), or `None` without samples.
pub fn min_support_margin(x: &[f64], y: &[f64], support: [[f64; 2]; 2]) -> Option<f64> {
    x.iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(&px, &py)| {
            (px - support[0][0])
                .min(support[0][1] - px)
                .min(py - support[1][0])
                .min(support[1][1] - py)
        })
        .reduce(f64::min)
}
