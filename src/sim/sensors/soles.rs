//! A force sensor at each sole corner (`feet = "corners"`): each foot's wrench is its corners'
//! sum, the centre of pressure that of the measured corner forces.

use nalgebra::Vector3;
use rand_chacha::ChaCha8Rng;

use super::channel::{ForceChannel, ForceSensorConfig};
use super::model::{SensorModel, Truth};
use crate::channels::{N_CONTACTS, SENSOR_FEET, StateMsg};
use crate::dynamics::{PressureLoad, center_of_pressure};
use crate::plant::feet::fill_foot_wrenches;

/// When the feet are measured at the corners (`feet = "corners"`), writes `contact_forces`
/// (each corner a three-axis force sensor: noise, bias and drift, resolution, latency,
/// dropouts), `foot_wrenches` (the measured corners' sums, in the soles' frames), `zmp` (the
/// measured forces' centre of pressure, as the robot computes it; where they carry no weight
/// the plant's stays) and `stamps[SENSOR_FEET]` (the newest corner's sample); counts
/// `sole_dropouts`. Draws six normals and one uniform per corner a step, three normals per
/// corner at reset however the feet are measured (the IMU's draws after them do not depend on
/// it).
pub(super) struct SoleCorners {
    settings: ForceSensorConfig,
    /// The feet are measured at the corners.
    measured: bool,
    corners: [ForceChannel; N_CONTACTS],
    stamp: f64,
    dropouts: u64,
}

impl SoleCorners {
    /// The corners' sensors with `settings`; `measured`: the feet are measured at them.
    pub(super) fn new(settings: &ForceSensorConfig, measured: bool) -> Self {
        Self {
            settings: *settings,
            measured,
            corners: std::array::from_fn(|_| ForceChannel::new(settings)),
            stamp: 0.0,
            dropouts: 0,
        }
    }
}

impl SensorModel for SoleCorners {
    fn invalid(&self) -> Option<(String, String)> {
        self.settings.invalid("soles")
    }

    fn reset(&mut self, rng: &mut ChaCha8Rng) {
        for corner in &mut self.corners {
            corner.reset(&self.settings, rng);
        }
        self.stamp = 0.0;
        self.dropouts = 0;
    }

    fn apply(&mut self, truth: &Truth, m: &mut StateMsg, rng: &mut ChaCha8Rng) {
        if !self.measured {
            return;
        }
        let s = &self.settings;
        let mut lost = 0;
        for (ch, f) in self.corners.iter_mut().zip(m.contact_forces.iter_mut()) {
            if ch.measure(s, truth.step, truth.dt, rng, f) {
                lost += 1;
            }
        }
        self.dropouts += lost;
        // The feet's stamp is the newest sample's: a corner lost holds its previous one.
        if lost < N_CONTACTS as u64 {
            self.stamp = truth.stamp(s.latency);
        }
        m.stamps[SENSOR_FEET] = self.stamp;
        fill_foot_wrenches(m, truth.contact_points);
        if let Some(cop) = corners_cop(&m.contact_forces, truth.contact_points) {
            m.zmp = cop;
        }
    }

    fn counts(&self, report: &mut dyn FnMut(&'static str, u64)) {
        report("sole_dropouts", self.dropouts);
    }
}

/// The centre of pressure (world x, y; flat ground) of the corner forces at `points`; `None`
/// when no corner is loaded (a force ≤ 0 carries nothing).
fn corners_cop(forces: &[[f64; 3]; N_CONTACTS], points: &[[f64; 3]]) -> Option<[f64; 2]> {
    let loads = (forces.iter().zip(points))
        .filter(|(f, _)| f[2] > 0.0)
        .map(|(f, p)| PressureLoad::point(f[2], Vector3::new(p[0], p[1], 0.0)));
    let p = center_of_pressure(loads);
    (p.loads > 0).then(|| p.point())
}
