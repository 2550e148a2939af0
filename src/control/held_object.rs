//! What the hand holds (a door on its hinge: its apparent mass at the hand Λ = m e eᵀ along its
//! free direction e) and what follows from it for the controller: the path the hand previewer
//! keeps the hand on (HP-1), the stiffness's projector (`hand.stiffness = "decoupled"`), the
//! force the held object passes to the hand (HF-1), and where a push along its path is felt at
//! the hand (FC-0b). docs/hand_previewer.md, docs/whole_body_qp.md, docs/forecast_correction.md.

use nalgebra::{Matrix3, Vector3};

use crate::config::HeldPath;

/// The held object as the controller uses it, from its apparent mass at the hand.
#[derive(Debug, Clone, Copy)]
pub struct HeldObject {
    /// Λ (world, kg; zero: nothing held, or a mass with a non-finite entry).
    pub mass: Matrix3<f64>,
    /// Its free direction e, whatever `hand.held_path` (FC-0b).
    pub free_dir: Option<Vector3<f64>>,
    /// HP-1: the path the previewer keeps the hand on and the object's mass along it, per
    /// `hand.held_path` (`None`: free).
    pub path: Option<(Vector3<f64>, f64)>,
    /// `hand.stiffness = "decoupled"`: the projector P = e eᵀ onto the free direction; `None`:
    /// eq. (17) as is.
    pub stiffness_projector: Option<Matrix3<f64>>,
}

impl HeldObject {
    /// Nothing held.
    pub const NONE: HeldObject = HeldObject {
        mass: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        free_dir: None,
        path: None,
        stiffness_projector: None,
    };

    /// From Λ, `hand.held_path` and whether `hand.stiffness = "decoupled"`.
    pub fn new(held_mass: Matrix3<f64>, held_path: HeldPath, decoupled: bool) -> Self {
        // HP-1: the path e and, if asked, the object's mass along it (m e eᵀ's trace).
        let along = match held_path {
            HeldPath::PathInertia => held_mass.trace(),
            HeldPath::Path | HeldPath::Free => 0.0,
        };
        let free_dir = free_direction(&held_mass);
        let path = free_dir
            .filter(|_| held_path != HeldPath::Free)
            .map(|e| (e, along));
        // HF-1 inverts M_e + Λ each tick: a Λ with a non-finite entry is not held at all.
        let mass = if held_mass.iter().all(|x| x.is_finite()) {
            held_mass
        } else {
            Matrix3::zeros()
        };
        // A door's apparent mass is m e eᵀ: its trace is m, and it over m projects onto e.
        let m = held_mass.trace();
        let stiffness_projector = (m.is_finite() && m > 0.0 && decoupled).then(|| held_mass / m);
        Self {
            mass,
            free_dir,
            path,
            stiffness_projector,
        }
    }

    /// Λ as rows (the frame's and the parts' form).
    pub fn rows(&self) -> [[f64; 3]; 3] {
        [0, 1, 2].map(|r| [0, 1, 2].map(|c| self.mass[(r, c)]))
    }
}

/// The force a held object passes to the hand when it is pushed with `push` and the hand
/// follows eq. (23)'s impedance law (its acceleration `law`, arm's inertia `m_e`), the object's
/// apparent mass `held` riding on the hand (HF-1): F = P − Λ ẍ with M_e (ẍ − ẍ_law) = F, i.e.
/// (M_e + Λ) ẍ = P + M_e ẍ_law. The inertia term is the hand's commanded acceleration, not a
/// measured one: no lag and no velocity noise (docs/whole_body_qp.md, "The hand force fed
/// back"). `push` itself when M_e + Λ is singular.
pub fn held_object_force(
    push: &Vector3<f64>,
    m_e: &Matrix3<f64>,
    held: &Matrix3<f64>,
    law: &Vector3<f64>,
) -> Vector3<f64> {
    match (m_e + held).try_inverse() {
        Some(inv) => push - held * (inv * (push + m_e * law)),
        None => *push,
    }
}

/// The held object's free direction e (unit, its sign arbitrary) from its apparent mass at the
/// hand: a door's is m e eᵀ (`crate::sim::scene::PlacedDoor::apparent_mass`), so its largest
/// column is m e_k e. `None` when nothing is held (a zero or non-finite mass).
pub fn free_direction(held_mass: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let m = held_mass.trace();
    if !(m.is_finite() && m > 0.0) {
        return None;
    }
    let c = (0..3)
        .map(|k| held_mass.column(k).into_owned())
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
    Some(c.normalize())
}

/// Where a hand held by a stiffness of shape `k_e` feels a push along a door's path `e` (unit),
/// per newton along e: d = K_e e / (eᵀ K_e e) (FC-0b). Held on the path, the hand's error s e
/// pushes back along K_e e; the push balances its part along e (eᵀd = 1) and the hinge the rest.
/// `None` when eᵀ K_e e is not positive.
pub fn felt_direction(e: &Vector3<f64>, k_e: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let k = k_e * e;
    let s = e.dot(&k);
    (s.is_finite() && s > 0.0).then(|| k / s)
}

/// FC-0b as far as the forecast is believed: e + w (d − e), w the forecast's weight (FC-5).
/// The hinge's share across e is the forecast's claim, wrong whenever the forecast is; a
/// discounted forecast keeps it only in part (w = 0: FC-0's e; a non-finite w counts as 0).
/// eᵀ(e + w (d − e)) = 1 for every w: the push along the path is the forecast's.
pub fn believed_felt_direction(e: &Vector3<f64>, d: &Vector3<f64>, w: f64) -> Vector3<f64> {
    let w = if w.is_finite() {
        w.clamp(0.0, 1.0)
    } else {
        0.0
    };
    e + (d - e) * w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_discounted_forecast_keeps_the_hinges_share_only_as_far_as_it_is_believed() {
        let e = Vector3::new(0.995, 0.1, 0.0).normalize();
        let k_e = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 3.0);
        let d = felt_direction(&e, &k_e).unwrap();
        assert!((d - e).norm() > 0.05, "a share across e to keep: {d}");
        let at = |w| believed_felt_direction(&e, &d, w);
        assert!((at(1.0) - d).norm() < 1e-15);
        assert!((at(0.0) - e).norm() < 1e-15);
        assert!((at(0.25) - (e * 0.75 + d * 0.25)).norm() < 1e-15);
        for w in [-1.0, 0.0, 0.3, 0.7, 1.0, 2.0, f64::NAN, f64::INFINITY] {
            assert!((e.dot(&at(w)) - 1.0).abs() < 1e-12, "w {w}: {}", at(w));
        }
        assert!((at(2.0) - d).norm() < 1e-15);
        assert!((at(-1.0) - e).norm() < 1e-15);
        assert!((at(f64::NAN) - e).norm() < 1e-15);
    }

    #[test]
    fn a_held_doors_force_is_the_push_less_its_inertia_at_the_hands_acceleration() {
        // A door of 5 kg along e = x on an arm of 2 kg: a 14 N push with the law at rest moves
        // both, (2 + 5) ẍ = 14, so the door takes 5 · 2 = 10 N and passes 4 N.
        let m_e = Matrix3::identity() * 2.0;
        let e = Vector3::x();
        let held = e * e.transpose() * 5.0;
        let f = held_object_force(&(e * 14.0), &m_e, &held, &Vector3::zeros());
        assert!((f - e * 4.0).norm() < 1e-12, "{f}");
        // Across e the door takes nothing: the push passes whole.
        let side = Vector3::new(0.0, 3.0, -1.0);
        let f = held_object_force(&side, &m_e, &held, &Vector3::zeros());
        assert!((f - side).norm() < 1e-12, "{f}");
        // Any arm, door and law: the force and the hand's acceleration satisfy both equations.
        let m_e = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 3.0);
        let e = Vector3::new(0.99, 0.1, 0.0).normalize();
        let held = e * e.transpose() * 5.1;
        let (push, law) = (Vector3::new(-60.0, 8.0, 3.0), Vector3::new(0.4, -1.2, 0.7));
        let f = held_object_force(&push, &m_e, &held, &law);
        let acc = law + m_e.try_inverse().unwrap() * f;
        assert!((f - (push - held * acc)).norm() < 1e-9, "{f} {acc}");
        // Nothing held: the push itself.
        let f = held_object_force(&push, &m_e, &Matrix3::zeros(), &law);
        assert!((f - push).norm() < 1e-12, "{f}");
    }
}
