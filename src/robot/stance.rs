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
    let tasks = Tasks {
        model,
        guess,
        soles,
        hand,
        root,
        targets: Targets::at_zero(model, &mut data, root, soles, contacts, spec)?,
        off_arm: off_arm(model, hand),
    };
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
        (worst, hand_error) =
            tasks.normal_equations(&mut data, &q, &mut jac, &mut normal, &mut rhs)?;
        if worst < TOLERANCE && tasks.targets.hand.is_none_or(|_| hand_error < TOLERANCE) {
            break;
        }
        let dq = step_within_limits(model, &q, &mut normal, &rhs)?;
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

/// The tasks' targets, from the zero posture: where the soles stand, and the CoM's
/// straight-leg height.
struct Targets {
    /// The soles' rotation: flat, toes along the heading they have at the zero posture.
    sole_rot: nalgebra::Matrix3<f64>,
    /// Each sole's position.
    soles: [Vector3<f64>; 2],
    /// The base's height.
    base_height: f64,
    /// The support's centre on the ground, which the CoM stands over.
    support: Vector3<f64>,
    /// The hand's position, if it has one to reach.
    hand: Option<Vector3<f64>>,
}

impl Targets {
    fn at_zero(
        model: &Model,
        data: &mut Data,
        root: usize,
        soles: [usize; 2],
        contacts: &[usize],
        spec: &StanceSpec,
    ) -> Result<Targets, String> {
        let zero = model.neutral();
        forward_kinematics(model, data, &zero).map_err(|e| e.to_string())?;
        update_frame_placements(model, data);
        let feet = soles.map(|s| data.o_m_f[s].trans);
        let ground = (feet[0].z + feet[1].z) / 2.0;
        let centre = Vector3::new(
            (feet[0].x + feet[1].x) / 2.0,
            (feet[0].y + feet[1].y) / 2.0,
            ground,
        );
        // The soles face where they face at the zero posture (the base's −x on a robot whose
        // root link faces backward): their targets and the hand's are turned by that heading,
        // the base keeps its zero-posture orientation.
        let toes: Vector3<f64> = soles
            .iter()
            .map(|&s| data.o_m_f[s].rot * Vector3::x())
            .sum();
        let heading =
            nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), toes.y.atan2(toes.x));
        let across = heading * Vector3::y();
        // The support's centre: the contact points' centroid, offset from the soles' midpoint
        // when a sole frame is not at its contacts' centre (under the ankle, say); the soles
        // keep that offset as they turn flat.
        let mut support = Vector3::zeros();
        for &c in contacts {
            support += data.o_m_f[c].trans / contacts.len().max(1) as f64;
        }
        let offset = heading.transpose() * (support - centre);
        let support = centre + heading * Vector3::new(offset.x, offset.y, 0.0);
        Ok(Targets {
            sole_rot: *heading.matrix(),
            soles: feet.map(|p| centre + across * across.dot(&(p - centre))),
            base_height: data.o_m_i[root].trans.z - spec.crouch,
            support,
            hand: spec.hand.map(|h| support + heading * Vector3::from(h)),
        })
    }
}

/// The joints' velocity indices off the arm: the arm's dofs are those below the chain root
/// (frame `hand[1]`) and above the hand (frame `hand[0]`).
fn off_arm(model: &Model, hand: [usize; 2]) -> Vec<usize> {
    let (hand_joint, arm_root) = (model.frames[hand[0]].parent, model.frames[hand[1]].parent);
    model
        .joints
        .iter()
        .enumerate()
        .filter(|(i, j)| {
            let below_root = arm_root.is_none_or(|r| r != *i && model.is_ancestor(r, *i));
            let above_hand = hand_joint.is_some_and(|h| model.is_ancestor(*i, h));
            j.nv() == 1 && !(below_root && above_hand)
        })
        .map(|(_, j)| j.idx_v)
        .collect()
}

/// ST-1's tasks on the model.
struct Tasks<'a> {
    model: &'a Model,
    guess: &'a DVector<f64>,
    soles: [usize; 2],
    hand: [usize; 2],
    /// The free-flyer joint.
    root: usize,
    targets: Targets,
    /// See [`off_arm`].
    off_arm: Vec<usize>,
}

impl Tasks<'_> {
    /// ST-1's normal equations at `q` into `normal` and `rhs`; returns the largest error of the
    /// soles, the CoM and the base (m, rad) and the hand's distance to its target (0 without
    /// one).
    fn normal_equations(
        &self,
        data: &mut Data,
        q: &DVector<f64>,
        jac: &mut DMatrix<f64>,
        normal: &mut DMatrix<f64>,
        rhs: &mut DVector<f64>,
    ) -> Result<(f64, f64), String> {
        let (model, targets) = (self.model, &self.targets);
        let jcom = jacobian_center_of_mass(model, data, q)
            .map_err(|e| e.to_string())?
            .clone();
        update_frame_placements(model, data);
        normal.fill(0.0);
        rhs.fill(0.0);
        let mut add = |j: &DMatrix<f64>, e: &[f64], w: f64| {
            normal.gemm_tr(w, j, j, 1.0);
            rhs.gemv_tr(w, j, &DVector::from_column_slice(e), 1.0);
        };
        let mut worst = 0.0f64;
        let lwa = ReferenceFrame::LocalWorldAligned;
        for (s, target) in self.soles.iter().zip(&targets.soles) {
            get_frame_jacobian(model, data, *s, lwa, jac).map_err(|e| e.to_string())?;
            let m = &data.o_m_f[*s];
            let dp = target - m.trans;
            let dr = log3(&(targets.sole_rot * m.rot.transpose())); // toward the heading, world axes
            let e = [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z];
            worst = worst.max(e.iter().fold(0.0, |a, x| a.max(x.abs())));
            add(jac, &e, W_SOLE);
        }
        let support = &targets.support;
        let dc = [support.x - data.com.x, support.y - data.com.y];
        worst = worst.max(dc[0].abs()).max(dc[1].abs());
        add(&jcom.rows(0, 2).into_owned(), &dc, W_COM);
        // The base upright at its height: its velocity in world axes is R v[0..3], its angular
        // velocity R v[3..6].
        let base = &data.o_m_i[self.root];
        let mut jb = DMatrix::zeros(4, model.nv);
        jb.view_mut((0, 3), (3, 3)).copy_from(&base.rot);
        jb.view_mut((3, 0), (1, 3)).copy_from(&base.rot.row(2));
        let dr = log3(&base.rot.transpose());
        let eb = [dr.x, dr.y, dr.z, targets.base_height - base.trans.z];
        worst = worst.max(eb.iter().fold(0.0, |a, x| a.max(x.abs())));
        add(&jb, &eb, W_BASE);
        let mut hand_error = 0.0;
        if let Some(t) = targets.hand {
            get_frame_jacobian(model, data, self.hand[0], lwa, jac).map_err(|e| e.to_string())?;
            for &k in &self.off_arm {
                jac.column_mut(k).fill(0.0);
            }
            for k in 0..6 {
                jac.column_mut(k).fill(0.0); // the base: carried by the legs' tasks
            }
            let dh = t - data.o_m_f[self.hand[0]].trans;
            hand_error = dh.norm();
            add(&jac.rows(0, 3).into_owned(), dh.as_slice(), W_HAND);
        }
        // The guess, on the joints (the base's six excluded).
        for j in model.joints.iter().filter(|j| j.nv() == 1 && j.nq() == 1) {
            let k = j.idx_v;
            normal[(k, k)] += W_GUESS;
            rhs[k] += W_GUESS * (self.guess[j.idx_q] - q[j.idx_q]);
        }
        for k in 0..model.nv {
            normal[(k, k)] += DAMPING;
        }
        Ok((worst, hand_error))
    }
}

/// The step δq of the normal equations. A joint at a limit that the step would push further
/// is held where it is (a weight [`HOLD`] added to `normal`), and the others take over its
/// share (a clamp alone would undo that share every step, and the iteration would stall short
/// of the targets).
fn step_within_limits(
    model: &Model,
    q: &DVector<f64>,
    normal: &mut DMatrix<f64>,
    rhs: &DVector<f64>,
) -> Result<DVector<f64>, String> {
    let mut dq = DVector::zeros(model.nv);
    for _ in 0..model.nv {
        dq = normal
            .clone()
            .cholesky()
            .ok_or("[stance]: the tasks' normal matrix is singular")?
            .solve(rhs);
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
    Ok(dq)
}
