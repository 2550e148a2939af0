//! The arms: each side's arm, its palm and the hand's frame, the chain both arms share, and
//! the hand's target in the drafted stance.

use nalgebra::Matrix3;

use super::ground::FootFound;
use super::tree::{Pose, Tree};
use super::{CROUCH, HAND_DOWN, HAND_FORWARD, HAND_NAMES, HAND_OUT, round3};
use crate::robot::RobotError;

/// The arms found on the upper body: the right one's hand and the chain both share.
pub(super) struct Arms {
    /// The link both arms share (the pelvis when there is one arm).
    pub(super) chain_root: String,
    /// Where each arm's chain branches into fingers: the right's, the left's.
    pub(super) right_palm: String,
    pub(super) left_palm: Option<String>,
    /// The right hand's frame.
    pub(super) hand: String,
}

impl Arms {
    /// The arms: the upper body is what the legs (below `feet`) are not; on each side the arm
    /// is the chain that goes deepest.
    pub(super) fn find(
        urdf: &urdf_rs::Robot,
        tree: &Tree,
        pose: &Pose,
        to_robot: &Matrix3<f64>,
        feet: [&FootFound; 2],
        notes: &mut Vec<String>,
    ) -> Result<Arms, RobotError> {
        let [left, right] = feet;
        let pelvis = tree.common(&left.link, &right.link).to_owned();
        let mut legs = Vec::new();
        for f in feet {
            let up = tree.ancestors(&f.link);
            if let Some(k) = up.iter().position(|l| *l == pelvis)
                && k > 0
            {
                legs.extend(tree.subtree(up[k - 1]));
            }
        }
        let arm_tip = |side: f64| arm_tip(urdf, tree, pose, to_robot, &legs, side);
        let right_tip = arm_tip(-1.0)?.ok_or_else(|| {
            RobotError::Feet(
                "no right arm found (no link right of the base above the legs): write [hand] \
                 by hand"
                    .into(),
            )
        })?;
        let left_tip = arm_tip(1.0)?;
        let chain_root = match &left_tip {
            Some(l) => tree.common(&right_tip, l).to_owned(),
            None => {
                notes.push("no left arm found: the arm's chain starts at the pelvis".into());
                pelvis.clone()
            }
        };
        let right_palm = palm(tree, &chain_root, &right_tip);
        let hand = hand_frame(tree, &right_palm);
        let left_palm = left_tip.map(|l| palm(tree, &chain_root, &l));
        Ok(Arms {
            chain_root,
            right_palm,
            left_palm,
            hand,
        })
    }
}

/// The end of the arm on the robot's left (`side` 1) or right (−1): of the links off the
/// `legs` at least 2 cm to that side of the base, the deepest (then the furthest out).
pub(super) fn arm_tip(
    urdf: &urdf_rs::Robot,
    tree: &Tree,
    pose: &Pose,
    to_robot: &Matrix3<f64>,
    legs: &[String],
    side: f64,
) -> Result<Option<String>, RobotError> {
    let root_at = pose.link(&tree.root)?.trans;
    let mut best: Option<(usize, f64, String)> = None;
    for l in &urdf.links {
        if legs.contains(&l.name) {
            continue;
        }
        let y = (to_robot * (pose.link(&l.name)?.trans - root_at)).y * side;
        if y < 0.02 {
            continue;
        }
        let d = tree.depth(&l.name);
        if best
            .as_ref()
            .is_none_or(|(bd, by, _)| d > *bd || (d == *bd && y > *by))
        {
            best = Some((d, y, l.name.clone()));
        }
    }
    Ok(best.map(|b| b.2))
}

/// The stance: the base lower by [`CROUCH`] of its height (the crouch, m), the hand forward
/// and down of its shoulder (its target from the feet's centre on the ground).
pub(super) fn stance(
    tree: &Tree,
    pose: &Pose,
    to_robot: &Matrix3<f64>,
    [left, right]: [&FootFound; 2],
    arms: &Arms,
) -> Result<(f64, [f64; 3]), RobotError> {
    let root_at = pose.link(&tree.root)?.trans;
    let ground = left.lowest.min(right.lowest);
    let base_height = root_at.z - ground;
    let centre = (left.centroid + right.centroid) / 2.0;
    let shoulder = first_moving(tree, &arms.chain_root, &arms.right_palm)
        .map(|l| pose.link(l).map(|p| p.trans))
        .transpose()?
        .unwrap_or(root_at);
    let arm = (pose.link(&arms.hand)?.trans - shoulder).norm();
    let s = to_robot * (shoulder - centre);
    let crouch = round3(CROUCH * base_height);
    let hand_target = [
        round3(s.x + HAND_FORWARD * arm),
        round3(s.y - HAND_OUT * arm),
        round3(shoulder.z - ground - crouch - HAND_DOWN * arm),
    ];
    Ok((crouch, hand_target))
}

/// Where an arm's chain from `root` to `tip` branches into fingers (three moving joints or
/// more below `root`), or the tip's body when it never does.
pub(super) fn palm(tree: &Tree, root: &str, tip: &str) -> String {
    let mut path: Vec<&str> = tree.ancestors(tip);
    let k = path.iter().position(|l| *l == root).unwrap_or(path.len());
    path.truncate(k);
    path.reverse();
    let mut joints = 0;
    for l in &path {
        if tree.parent.get(*l).is_some_and(|p| p.1) {
            joints += 1;
        }
        if joints >= 3 && (tree.moving_branches(l) >= 2 || tree.grips(l)) {
            return (*l).to_owned();
        }
    }
    tree.body(tip).to_owned()
}

/// The hand's frame: the palm, or a link fixed to it whose name says hand, palm, gripper.
pub(super) fn hand_frame(tree: &Tree, palm: &str) -> String {
    let mut fixed = vec![palm.to_owned()];
    let mut k = 0;
    while k < fixed.len() {
        if let Some(c) = tree.children.get(&fixed[k]) {
            fixed.extend(c.iter().filter(|(_, m)| !m).map(|(l, _)| l.clone()));
        }
        k += 1;
    }
    let score = |n: &str| {
        let n = n.to_ascii_lowercase();
        HAND_NAMES
            .iter()
            .position(|h| n.contains(h))
            .map_or(0, |p| HAND_NAMES.len() - p)
    };
    // A name that ends with the word (`r_hand`) names the hand itself, not a part of it
    // (`r_hand_link`, `gripper_right_fingertip_1_link`).
    let ends = |n: &str| {
        let n = n.to_ascii_lowercase();
        HAND_NAMES.iter().any(|h| n.ends_with(h))
    };
    fixed
        .iter()
        .max_by_key(|n| (score(n), ends(n), n.as_str() == palm))
        .cloned()
        .unwrap_or_else(|| palm.to_owned())
}

/// The first link a moving joint carries on the way from `root` to `to` (the shoulder).
pub(super) fn first_moving<'a>(tree: &'a Tree, root: &str, to: &'a str) -> Option<&'a str> {
    let path = tree.ancestors(to);
    let k = path.iter().position(|l| *l == root)?;
    path[..k]
        .iter()
        .rev()
        .find(|l| tree.parent.get(**l).is_some_and(|p| p.1))
        .copied()
}
