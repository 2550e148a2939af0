//! The URDF as the draft reads it: its link tree (from its joints) and its zero posture.

use std::collections::HashMap;

use super::FINGER_NAMES;
use crate::dynamics::{Data, Model, SE3, forward_kinematics};
use crate::robot::RobotError;

/// The URDF's link tree (from its joints).
pub(super) struct Tree {
    pub(super) root: String,
    /// Link → (parent link, joint is moving).
    pub(super) parent: HashMap<String, (String, bool)>,
    /// Link → (child link, joint is moving).
    pub(super) children: HashMap<String, Vec<(String, bool)>>,
}

impl Tree {
    pub(super) fn new(urdf: &urdf_rs::Robot) -> Result<Self, String> {
        use urdf_rs::JointType as T;
        let mut parent = HashMap::new();
        let mut children: HashMap<String, Vec<(String, bool)>> = HashMap::new();
        for j in &urdf.joints {
            let moving = !matches!(j.joint_type, T::Fixed);
            parent.insert(j.child.link.clone(), (j.parent.link.clone(), moving));
            children
                .entry(j.parent.link.clone())
                .or_default()
                .push((j.child.link.clone(), moving));
        }
        let root = urdf
            .links
            .iter()
            .find(|l| !parent.contains_key(&l.name))
            .map(|l| l.name.clone())
            .ok_or("the URDF's links form no tree (no root link)")?;
        Ok(Self {
            root,
            parent,
            children,
        })
    }

    /// `link`, its parent, … the root.
    pub(super) fn ancestors<'a>(&'a self, link: &'a str) -> Vec<&'a str> {
        let mut out = vec![link];
        let mut cur = link;
        while let Some((p, _)) = self.parent.get(cur) {
            out.push(p);
            cur = p;
        }
        out
    }

    /// Moving joints between the root and `link`.
    pub(super) fn depth(&self, link: &str) -> usize {
        let mut n = 0;
        let mut cur = link;
        while let Some((p, moving)) = self.parent.get(cur) {
            n += usize::from(*moving);
            cur = p;
        }
        n
    }

    /// The deepest link both `a` and `b` descend from.
    pub(super) fn common<'a>(&'a self, a: &'a str, b: &'a str) -> &'a str {
        let up = self.ancestors(b);
        self.ancestors(a)
            .into_iter()
            .find(|l| up.contains(l))
            .unwrap_or(&self.root)
    }

    /// `link` and every link below it.
    pub(super) fn subtree(&self, link: &str) -> Vec<String> {
        let mut out = vec![link.to_owned()];
        let mut k = 0;
        while k < out.len() {
            if let Some(c) = self.children.get(&out[k]) {
                out.extend(c.iter().map(|(l, _)| l.clone()));
            }
            k += 1;
        }
        out
    }

    /// `a` and `b` share no moving joint on their paths from the root (two legs).
    pub(super) fn apart(&self, a: &str, b: &str) -> bool {
        let moved = |l: &str| -> Vec<String> {
            self.ancestors(l)
                .into_iter()
                .filter(|x| self.parent.get(*x).is_some_and(|p| p.1))
                .map(str::to_owned)
                .collect()
        };
        let (ma, mb) = (moved(a), moved(b));
        !ma.is_empty() && !mb.is_empty() && ma.iter().all(|x| !mb.contains(x))
    }

    /// A moving joint below `link`, or into it when `moving`.
    pub(super) fn moves_below(&self, link: &str) -> bool {
        self.children
            .get(link)
            .is_some_and(|c| c.iter().any(|(l, m)| *m || self.moves_below(l)))
    }

    /// Branches below `link` that move (fingers).
    pub(super) fn moving_branches(&self, link: &str) -> usize {
        self.children.get(link).map_or(0, |c| {
            c.iter().filter(|(l, m)| *m || self.moves_below(l)).count()
        })
    }

    /// A moving joint into a child of `link` that a gripper's or a hand's name says it is
    /// (a one-joint gripper: no branching tells it from the arm).
    pub(super) fn grips(&self, link: &str) -> bool {
        self.children.get(link).is_some_and(|c| {
            c.iter().any(|(l, m)| {
                let n = l.to_ascii_lowercase();
                *m && FINGER_NAMES.iter().any(|f| n.contains(f))
            })
        })
    }

    /// The link's body: itself, or the first ancestor a moving joint carries.
    pub(super) fn body<'a>(&'a self, link: &'a str) -> &'a str {
        let mut cur = link;
        while let Some((p, moving)) = self.parent.get(cur) {
            if *moving {
                break;
            }
            cur = p;
        }
        cur
    }
}

/// The zero posture's kinematics.
pub(super) struct Pose<'a> {
    pub(super) model: &'a Model,
    pub(super) data: Data,
}

impl<'a> Pose<'a> {
    /// The zero posture, the base at the identity.
    pub(super) fn zero(model: &'a Model) -> Result<Self, RobotError> {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &model.neutral())?;
        Ok(Pose { model, data })
    }

    pub(super) fn link(&self, name: &str) -> Result<SE3, RobotError> {
        Ok(self.data.o_m_f[self.model.frame_id(name)?])
    }
}
