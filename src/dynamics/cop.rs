//! Centre of pressure on flat ground (world x, y) of vertical loads: point forces (a contact
//! point's normal force) or a foot's wrench (its normal force at the sole's centre and its moment
//! on the sole). One function for the plants (the CoP of their true contact forces), the sensor
//! models (the CoP a robot computes from its measured forces) and the base estimator.
//!
//! Each caller chooses which loads count and above which total the CoP means something. The sums
//! run in the loads' order, one load at a time, so a caller's figures are reproducible bit for
//! bit whichever of them computes it.

use nalgebra::Vector3;

/// One vertical load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PressureLoad {
    /// Its normal force (N).
    pub normal: f64,
    /// Where it acts (m, world; x and y are used).
    pub at: Vector3<f64>,
    /// Its first moment about `at`, normal × (its own CoP − `at`) (N m, world): zero for a point
    /// force; for a foot's wrench with moment τ on its sole (sole frame R), R (−τ_y, τ_x, 0).
    pub moment: Vector3<f64>,
}

impl PressureLoad {
    /// A point force of normal component `normal` at `at`.
    pub fn point(normal: f64, at: Vector3<f64>) -> Self {
        Self {
            normal,
            at,
            moment: Vector3::zeros(),
        }
    }
}

/// The sum of the loads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pressure {
    /// Total normal force (N).
    pub total: f64,
    /// Loads summed.
    pub loads: u32,
    /// Σ normal · at + moment (N m, world).
    pub first_moment: Vector3<f64>,
}

impl Pressure {
    /// The centre of pressure (world x, y): the first moment over the total; not finite when
    /// the loads sum to zero.
    pub fn point(&self) -> [f64; 2] {
        [
            self.first_moment.x / self.total,
            self.first_moment.y / self.total,
        ]
    }
}

/// The loads' total and first moment, for their centre of pressure ([`Pressure::point`]).
pub fn center_of_pressure(loads: impl IntoIterator<Item = PressureLoad>) -> Pressure {
    let mut p = Pressure {
        total: 0.0,
        loads: 0,
        first_moment: Vector3::zeros(),
    };
    for l in loads {
        p.total += l.normal;
        // One sum per load (its force's moment and its own moment added first): a point
        // force's zero moment leaves its product unchanged, so point sums are plain Σ f p.
        p.first_moment += l.normal * l.at + l.moment;
        p.loads += 1;
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two point forces: 30 N at (0, 0) and 10 N at (0.4, −0.2) press at their weighted mean
    /// (0.1, −0.05).
    #[test]
    fn point_forces_press_at_their_weighted_mean() {
        let p = center_of_pressure([
            PressureLoad::point(30.0, Vector3::zeros()),
            PressureLoad::point(10.0, Vector3::new(0.4, -0.2, 0.0)),
        ]);
        assert_eq!((p.total, p.loads), (40.0, 2));
        let cop = p.point();
        assert!((cop[0] - 0.1).abs() < 1e-15 && (cop[1] + 0.05).abs() < 1e-15);
    }

    /// A foot of 100 N at (0.2, 0.1) whose sole (turned 90° about z: its x is the world's y)
    /// carries τ_y = −5 N m: on the sole its CoP is 5 cm ahead (x = −τ_y / f_z), in the world
    /// 5 cm along +y. With a second foot of 100 N at (0, −0.1) pressing at its centre, the CoP is
    /// midway: (0.1, 0.025).
    #[test]
    fn a_foot_wrench_presses_at_its_own_centre_of_pressure() {
        let sole = nalgebra::Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let (tau_x, tau_y) = (0.0, -5.0);
        let turned = PressureLoad {
            normal: 100.0,
            at: Vector3::new(0.2, 0.1, 0.0),
            moment: sole * Vector3::new(-tau_y, tau_x, 0.0),
        };
        let alone = center_of_pressure([turned]).point();
        assert!((alone[0] - 0.2).abs() < 1e-15 && (alone[1] - 0.15).abs() < 1e-15);
        let flat = PressureLoad::point(100.0, Vector3::new(0.0, -0.1, 0.0));
        let both = center_of_pressure([turned, flat]).point();
        assert!((both[0] - 0.1).abs() < 1e-15 && (both[1] - 0.025).abs() < 1e-15);
    }

    /// Nothing loaded: zero total, no finite point.
    #[test]
    fn no_load_has_no_centre() {
        let p = center_of_pressure([]);
        assert_eq!((p.total, p.loads), (0.0, 0));
        assert!(p.point().iter().all(|c| c.is_nan()));
    }
}
