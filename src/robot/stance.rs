//! The standing posture solved by inverse kinematics (`[stance]` of a description): both soles
//! flat on the ground facing x, the CoM over the feet's centre at a chosen height, the base
//! upright, the hand at a target, the joints within their limits and otherwise as close as the
//! tasks allow to the description's `[home]` (its guess). Any hip axes: the solver sees only
//! the kinematics, never a rule such as "hip + knee + ankle pitch = 0".
//!
//! Weighted damped least squares (Gauss–Newton on the tasks' errors, a step toward the guess
//! on the joints the tasks leave free), each step projected onto the joint limits:
//!
//!   min Σ_t w_t ‖J_t δq − e_t‖² + w_g ‖δq_j − (q_g − q)_j‖² + μ ‖δq‖²,   q ← clamp(q ⊕ δq)   (ST-1)
//!
//! Tasks e_t: each sole's position (its zero-posture offset across the feet, the ground's z)
//! and rotation (flat, toes along the heading the soles have at the zero posture); the base's
//! rotation (as at the zero posture: upright) and height (its height at the zero posture, less
//! `crouch`); the CoM's x, y (the feet's centre); the hand's position (feet centre + `hand`,
//! x along the soles' heading), if given. With the soles and the base's height and rotation
//! fixed, each leg's posture follows (the knees bend, the legs do not splay), and the base's
//! x, y carry the CoM over the feet.

use nalgebra::{DMatrix, DVector, Vector3};
use serde::Deserialize;

use crate::dynamics::spatial::log3;

use crate::dynamics::{
    Data, Model, ReferenceFrame, forward_kinematics, get_frame_jacobian, integrate,
    jacobian_center_of_mass, update_frame_placements,
};

/// `[stance]`: what the solved standing posture must do.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StanceSpec {
    /// How far the base sinks below its height at the zero posture (m): the knees' bend.
    pub crouch: f64,
    /// The hand's position relative to the feet's centre on the ground (m; x forward, y left,
    /// z up), if it has one to reach.
    #[serde(default)]
    pub hand: Option<[f64; 3]>,
}

/// Weights of ST-1: the soles, the base and the CoM are what standing needs, six orders above
/// the hand's target (a hand out of reach then moves them by a micrometre, not a millimetre),
/// the guess last.
const W_SOLE: f64 = 1e6;
const W_COM: f64 = 1e6;
const W_BASE: f64 = 1e6;
const W_HAND: f64 = 1.0;
const W_GUESS: f64 = 1e-3;
const DAMPING: f64 = 1e-8;
const ITERATIONS: usize = 500;
/// A joint held at its limit: a weight on its step that no task outweighs.
const HOLD: f64 = 1e14;
/// The soles and the CoM within this (m, rad) make a solved stance.
const TOLERANCE: f64 = 1e-6;

/// The solved posture and how far the hand stayed from its target (m; 0 without one).
#[derive(Debug, Clone)]
pub struct Stance {
    pub q: DVector<f64>,
    pub hand_error: f64,
}

/// Solves ST-1 on `model` (a floating base) from the guess `guess` (its base at the identity,
/// its joints the description's `[home]`) for the sole frames `soles` (the CoM over the centre
/// of their contact frames `contacts`) and the hand frame
/// `hand[0]`, reached by its arm's joints alone (those below the frame `hand[1]`, the arm's
/// chain root: a torso bent to reach would be a posture no one asked for). A guess with straight knees is singular (bending a straight knee does not move the
/// hip at first order, and Gauss–Newton never bends it): if the guess does not converge, it
/// starts again with every joint moved a tenth of the way to the middle of its range, which
/// bends a knee the way its limits allow.
pub fn solve(
    model: &Model,
    guess: &DVector<f64>,
    soles: [usize; 2],
    contacts: &[usize],
    hand: [usize; 2],
    spec: &StanceSpec,
) -> Result<Stance, String> {
    solve_from(model, guess, guess, soles, contacts, hand, spec).or_else(|first| {
        let mut start = guess.clone();
        for j in model.joints.iter().filter(|j| j.nv() == 1 && j.nq() == 1) {
            let (lo, hi) = (j.limits.lower, j.limits.upper);
            if lo.is_finite() && hi.is_finite() && lo < hi {
                start[j.idx_q] += 0.1 * ((lo + hi) / 2.0 - start[j.idx_q]);
            }
        }
        solve_from(model, &start, guess, soles, contacts, hand, spec).map_err(|_| first)
    })
}

/// ST-1 from `start`, drawn toward `guess`.
fn solve_from(
    model: &Model,
    start: &DVector<f64>,
    guess: &DVector<f64>,
    soles: [usize; 2],
    contacts: &[usize],
    hand: [usize; 2],
    spec: &StanceSpec,
) -> Result<Stance, String> {
    if !(spec.crouch.is_finite() && spec.crouch >= 0.0) {
        return Err(format!(
            "[stance] crouch must be ≥ 0 m, got {}",
            spec.crouch
        ));
    }
    let root = model
        .joints
        .iter()
        .position(|j| j.idx_v == 0 && j.nv() == 6)
        .ok_or("[stance] needs a floating base")?;
    let nv = model.nv;
    let mut data = Data::new(model);
    // Targets from the zero posture: where the soles stand, and the CoM's straight-leg height.
    let zero = model.neutral();
    forward_kinematics(model, &mut data, &zero).map_err(|e| e.to_string())?;
    update_frame_placements(model, &mut data);
    let feet = soles.map(|s| data.o_m_f[s].trans);
    let ground = (feet[0].z + feet[1].z) / 2.0;
    let centre = Vector3::new(
        (feet[0].x + feet[1].x) / 2.0,
        (feet[0].y + feet[1].y) / 2.0,
        ground,
    );
    // The soles face where they face at the zero posture (the base's −x on a robot whose root
    // link faces backward): their targets and the hand's are turned by that heading, the base
    // keeps its zero-posture orientation.
    let toes: Vector3<f64> = soles
        .iter()
        .map(|&s| data.o_m_f[s].rot * Vector3::x())
        .sum();
    let heading = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), toes.y.atan2(toes.x));
    let sole_rot = *heading.matrix();
    let across = heading * Vector3::y();
    let sole_targets = feet.map(|p| centre + across * across.dot(&(p - centre)));
    let base_height = data.o_m_i[root].trans.z - spec.crouch;
    // The support's centre: the contact points' centroid, offset from the soles' midpoint
    // when a sole frame is not at its contacts' centre (under the ankle, say); the soles keep
    // that offset as they turn flat.
    let mut support = Vector3::zeros();
    for &c in contacts {
        support += data.o_m_f[c].trans / contacts.len().max(1) as f64;
    }
    let offset = heading.transpose() * (support - centre);
    let support = centre + heading * Vector3::new(offset.x, offset.y, 0.0);
    let hand_target = spec.hand.map(|h| support + heading * Vector3::from(h));
    // The arm's dofs: below the chain root, above the hand.
    let (hand_joint, arm_root) = (model.frames[hand[0]].parent, model.frames[hand[1]].parent);
    let off_arm: Vec<usize> = model
        .joints
        .iter()
        .enumerate()
        .filter(|(i, j)| {
            let below_root = arm_root.is_none_or(|r| r != *i && model.is_ancestor(r, *i));
            let above_hand = hand_joint.is_some_and(|h| model.is_ancestor(*i, h));
            j.nv() == 1 && !(below_root && above_hand)
        })
        .map(|(_, j)| j.idx_v)
        .collect();

    let limits: Vec<(usize, f64, f64)> = model
        .joints
        .iter()
        .filter(|j| j.nv() == 1 && j.nq() == 1)
        .map(|j| (j.idx_q, j.limits.lower, j.limits.upper))
        .collect();
    let mut q = start.clone();
    let mut next = q.clone();
    let mut jac = DMatrix::zeros(6, nv);
    let (mut normal, mut rhs) = (DMatrix::zeros(nv, nv), DVector::zeros(nv));
    let mut worst = f64::INFINITY;
    let mut hand_error = 0.0;
    for _ in 0..ITERATIONS {
        let jcom = jacobian_center_of_mass(model, &mut data, &q)
            .map_err(|e| e.to_string())?
            .clone();
        update_frame_placements(model, &mut data);
        normal.fill(0.0);
        rhs.fill(0.0);
        let mut add = |j: &DMatrix<f64>, e: &[f64], w: f64| {
            normal.gemm_tr(w, j, j, 1.0);
            rhs.gemv_tr(w, j, &DVector::from_column_slice(e), 1.0);
        };
        worst = 0.0f64;
        let lwa = ReferenceFrame::LocalWorldAligned;
        for (s, target) in soles.iter().zip(&sole_targets) {
            get_frame_jacobian(model, &data, *s, lwa, &mut jac).map_err(|e| e.to_string())?;
            let m = &data.o_m_f[*s];
            let dp = target - m.trans;
            let dr = log3(&(sole_rot * m.rot.transpose())); // toward the heading, world axes
            let e = [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z];
            worst = worst.max(e.iter().fold(0.0, |a, x| a.max(x.abs())));
            add(&jac, &e, W_SOLE);
        }
        let dc = [support.x - data.com.x, support.y - data.com.y];
        worst = worst.max(dc[0].abs()).max(dc[1].abs());
        add(&jcom.rows(0, 2).into_owned(), &dc, W_COM);
        // The base upright at its height: its velocity in world axes is R v[0..3], its angular
        // velocity R v[3..6].
        let base = &data.o_m_i[root];
        let mut jb = DMatrix::zeros(4, nv);
        jb.view_mut((0, 3), (3, 3)).copy_from(&base.rot);
        jb.view_mut((3, 0), (1, 3)).copy_from(&base.rot.row(2));
        let dr = log3(&base.rot.transpose());
        let eb = [dr.x, dr.y, dr.z, base_height - base.trans.z];
        worst = worst.max(eb.iter().fold(0.0, |a, x| a.max(x.abs())));
        add(&jb, &eb, W_BASE);
        if let Some(t) = hand_target {
            get_frame_jacobian(model, &data, hand[0], lwa, &mut jac).map_err(|e| e.to_string())?;
            for &k in &off_arm {
                jac.column_mut(k).fill(0.0);
            }
            for k in 0..6 {
                jac.column_mut(k).fill(0.0); // the base: carried by the legs' tasks
            }
            let dh = t - data.o_m_f[hand[0]].trans;
            hand_error = dh.norm();
            add(&jac.rows(0, 3).into_owned(), dh.as_slice(), W_HAND);
        }
        // The guess, on the joints (the base's six excluded).
        for j in model.joints.iter().filter(|j| j.nv() == 1 && j.nq() == 1) {
            let k = j.idx_v;
            normal[(k, k)] += W_GUESS;
            rhs[k] += W_GUESS * (guess[j.idx_q] - q[j.idx_q]);
        }
        for k in 0..nv {
            normal[(k, k)] += DAMPING;
        }
        if worst < TOLERANCE && hand_target.is_none_or(|_| hand_error < TOLERANCE) {
            break;
        }
        // A joint at a limit that the step would push further is held where it is, and the
        // others take over its share (a clamp alone would undo that share every step, and the
        // iteration would stall short of the targets).
        let mut dq = DVector::zeros(nv);
        for _ in 0..nv {
            dq = normal
                .clone()
                .cholesky()
                .ok_or("[stance]: the tasks' normal matrix is singular")?
                .solve(&rhs);
            let mut held = false;
            for j in model.joints.iter().filter(|j| j.nv() == 1 && j.nq() == 1) {
                let (k, x) = (j.idx_v, q[j.idx_q]);
                let (lo, hi) = (j.limits.lower, j.limits.upper);
                let pushed = (x <= lo && dq[k] < 0.0) || (x >= hi && dq[k] > 0.0);
                if lo < hi && pushed && normal[(k, k)] < HOLD {
                    normal[(k, k)] += HOLD;
                    held = true;
                }
            }
            if !held {
                break;
            }
        }
        integrate(model, &q, &dq, 1.0, &mut next).map_err(|e| e.to_string())?;
        std::mem::swap(&mut q, &mut next);
        for &(i, lo, hi) in &limits {
            if lo < hi {
                q[i] = q[i].clamp(lo, hi);
            }
        }
    }
    if worst > 1e-4 {
        return Err(format!(
            "[stance]: no posture stands with flat soles, the base upright and the CoM over the \
             feet within the joint limits (worst error {:.1} mm or mrad); lower `crouch`, or \
             give [home] a closer guess",
            worst * 1e3
        ));
    }
    Ok(Stance { q, hand_error })
}
