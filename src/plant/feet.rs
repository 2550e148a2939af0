//! The feet's soles as the state's sensor block sees them: each foot's four corners (world), its
//! centre and frame, and the wrench of its corner forces. Corner order per foot: front-left,
//! front-right, rear-left, rear-right. The plant's foot sensors (`crate::sim::sensors`) and a
//! robot's bus (`crate::bus`, its lab's sole forces) publish the foot wrenches from here.

use nalgebra::{Matrix3, Vector3};

use crate::channels::StateMsg;

/// Foot `foot`'s sole (its corners' centroid, and its frame: x from the heel's to the toes'
/// midpoint, z the normal) from the corner points (world).
pub fn sole(points: &[[f64; 3]], foot: usize) -> (Vector3<f64>, Matrix3<f64>) {
    let p = |i: usize| Vector3::from(points.get(4 * foot + i).copied().unwrap_or_default());
    let centre = (p(0) + p(1) + p(2) + p(3)) / 4.0;
    (centre, crate::robot::sole_frame(p(0), p(1), p(2), p(3)))
}

/// Each foot's wrench from its four corner forces (`m.contact_forces`, world) at `points`: in
/// the sole frame, about the corners' centroid ([`sole`]). Writes `m.foot_wrenches`.
pub fn fill_foot_wrenches(m: &mut StateMsg, points: &[[f64; 3]]) {
    for foot in 0..2 {
        let k = 4 * foot;
        let p = |i: usize| Vector3::from(points.get(k + i).copied().unwrap_or_default());
        let f = |i: usize| Vector3::from(m.contact_forces[k + i]);
        let (centre, sole) = sole(points, foot);
        let (x, y, z) = (sole.column(0), sole.column(1), sole.column(2));
        let (mut force, mut moment) = (Vector3::zeros(), Vector3::zeros());
        for i in 0..4 {
            force += f(i);
            moment += (p(i) - centre).cross(&f(i));
        }
        let w = [
            x.dot(&force),
            y.dot(&force),
            z.dot(&force),
            x.dot(&moment),
            y.dot(&moment),
            z.dot(&moment),
        ];
        // Forces not measured (NaN): the wrench is not either. A degenerate sole (points not
        // given) publishes zeros rather than NaN.
        let measured = (0..4).all(|i| f(i).iter().all(|c| c.is_finite()));
        m.foot_wrenches[foot] = if !measured {
            [f64::NAN; 6]
        } else if w.iter().all(|c| c.is_finite()) {
            w
        } else {
            [0.0; 6]
        };
    }
}
