//! The feet: which way is up, the two feet and the way the robot faces, and each foot's sole
//! frame.

use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::tree::{Pose, Tree};
use super::{DraftFoot, ON_GROUND, round_to};
use crate::dynamics::{BaseJoint, Model, SE3, turn_root};
use crate::robot::{RobotError, feet};

/// A foot found on one side of the base (before knowing which is the robot's left).
pub(super) struct FootFound {
    pub(super) link: String,
    /// The ankle (the foot's last moving joint) and the support's centroid, base frame.
    pub(super) ankle: Vector3<f64>,
    pub(super) centroid: Vector3<f64>,
    pub(super) lowest: f64,
    /// The visual geometry the contacts come from, when the URDF has no collision geometry.
    pub(super) geometry: Option<feet::Collision>,
}

/// The two feet (either side of the base) and the way the robot faces (a horizontal unit
/// vector in the base's frame).
pub(super) fn find_feet(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    tree: &Tree,
    pose: &Pose,
    notes: &mut Vec<String>,
) -> Result<([FootFound; 2], Vector3<f64>), RobotError> {
    let mut search = FootSearch {
        urdf,
        urdf_dir,
        tree,
        pose,
        visual: false,
        found: Vec::new(),
    };
    search.found = search.candidates()?;
    let two_legs = |found: &[(String, f64)]| {
        found
            .iter()
            .any(|a| found.iter().any(|b| tree.apart(&a.0, &b.0)))
    };
    if !two_legs(&search.found) {
        // No collision geometry on the legs (a URDF made for drawing): the visual's.
        search.visual = true;
        search.found = search.candidates()?;
        notes.push(
            "the legs have no collision geometry: the feet and their contacts come from the \
             visual meshes (listed as points below)"
                .into(),
        );
    }
    let a = search.pick(None)?;
    let b = search.pick(Some(&a.link))?;
    if (a.lowest - b.lowest).abs() > 0.02 {
        return Err(RobotError::Feet(format!(
            "the feet found ({}, {}) are {:.0} mm apart in height at the zero posture: not a \
             robot standing straight there; write [feet] by hand",
            a.link,
            b.link,
            (a.lowest - b.lowest).abs() * 1e3
        )));
    }
    let forward = facing(pose, [&a, &b], notes)?;
    Ok(([a, b], forward))
}

/// The search for the feet among the links below the base.
pub(super) struct FootSearch<'a> {
    pub(super) urdf: &'a urdf_rs::Robot,
    pub(super) urdf_dir: Option<&'a Path>,
    pub(super) tree: &'a Tree,
    pub(super) pose: &'a Pose<'a>,
    /// Whether the geometry read is the visual one (the collision one otherwise).
    pub(super) visual: bool,
    /// The candidates: (link, lowest z).
    pub(super) found: Vec<(String, f64)>,
}

impl FootSearch<'_> {
    /// Links below the base with geometry upc reads: (link, lowest z).
    pub(super) fn candidates(&self) -> Result<Vec<(String, f64)>, RobotError> {
        let root = self.pose.link(&self.tree.root)?;
        let mut found = Vec::new();
        for l in &self.urdf.links {
            let at = self.pose.link(&l.name)?;
            if at.trans.z >= root.trans.z {
                continue;
            }
            // A link whose geometry cannot be read is not a foot upc can stand on.
            let Ok(c) = feet::geometry_points(self.urdf, self.urdf_dir, &l.name, self.visual)
            else {
                continue;
            };
            let lowest = c
                .points
                .iter()
                .zip(&c.radii)
                .map(|(p, r)| at.act_point(p).z - r)
                .fold(f64::INFINITY, f64::min);
            found.push((l.name.clone(), lowest));
        }
        Ok(found)
    }

    /// The foot: of the candidates reaching within [`ON_GROUND`] of the lowest (on another
    /// leg than `other`, no moving joint in common, when given), the shallowest in the tree.
    pub(super) fn pick(&self, other: Option<&str>) -> Result<FootFound, RobotError> {
        let (tree, pose) = (self.tree, self.pose);
        let side: Vec<&(String, f64)> = self
            .found
            .iter()
            .filter(|f| other.is_none_or(|o| tree.apart(&f.0, o)))
            .collect();
        let low = side.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
        let link = side
            .iter()
            .filter(|f| f.1 < low + ON_GROUND)
            .min_by(|a, b| {
                tree.depth(&a.0)
                    .cmp(&tree.depth(&b.0))
                    .then(a.1.total_cmp(&b.1))
            })
            .map(|f| f.0.clone())
            .ok_or_else(|| {
                RobotError::Feet(format!(
                    "no {} foot found (no link below the base with collision or visual geometry \
                     upc reads{}): write [feet] by hand",
                    if other.is_some() { "second" } else { "" },
                    other.map_or(String::new(), |o| format!(" on another leg than `{o}`"))
                ))
            })?;
        let root = pose.link(&tree.root)?;
        let base_rot = root.rot;
        let at = pose.link(&link)?;
        let c = feet::geometry_points(self.urdf, self.urdf_dir, &link, self.visual)?;
        // The support in the base's axes about the link's origin.
        let to_base = SE3::new(base_rot.transpose() * at.rot, Vector3::zeros());
        let support = feet::lowest_four(&c, &to_base, &link)?;
        let centroid_rel = support.iter().sum::<Vector3<f64>>() / 4.0;
        let body = tree.body(&link);
        let ankle = base_rot.transpose() * (pose.link(body)?.trans - root.trans);
        let origin = base_rot.transpose() * (at.trans - root.trans);
        Ok(FootFound {
            ankle,
            centroid: origin + centroid_rel,
            lowest: low,
            geometry: self.visual.then_some(c),
            link,
        })
    }
}

/// The way the robot faces (a horizontal unit vector in the base's frame): where the knees
/// bend backward from; failing a knee, the toes: the support reaches further ahead of the
/// ankle than behind it (a note says so).
pub(super) fn facing(
    pose: &Pose,
    [a, b]: [&FootFound; 2],
    notes: &mut Vec<String>,
) -> Result<Vector3<f64>, RobotError> {
    let knees = [knee_forward(pose, &a.link)?, knee_forward(pose, &b.link)?];
    let ahead = (a.centroid.x - a.ankle.x) + (b.centroid.x - b.ankle.x);
    Ok(match knees {
        [Some(x), Some(y)] if x.dot(&y) > 0.9 => (x + y).normalize(),
        _ => {
            let sign = if ahead < 0.0 { -1.0 } else { 1.0 };
            notes.push(format!(
                "no knee bends both legs the same way: the robot is taken to face the base's \
                 {}x, where the soles reach {:.0} mm beyond the ankles; check the feet's x axes \
                 with upc model",
                if sign > 0.0 { "+" } else { "−" },
                ahead.abs() / 2.0 * 1e3,
            ));
            Vector3::x() * sign
        }
    })
}

/// The turns [`upright_turn`] tries: the root link's x, −x, y, −y or z pointing down.
pub(super) const TURNS: [[f64; 3]; 5] = [
    [0.0, FRAC_PI_2, 0.0],
    [0.0, -FRAC_PI_2, 0.0],
    [-FRAC_PI_2, 0.0, 0.0],
    [FRAC_PI_2, 0.0, 0.0],
    [PI, 0.0, 0.0],
];

/// The root link's turn that stands a URDF upright (`[urdf] root_rpy`): none when two feet are
/// found below the base along −z (as URDFs mostly have it); otherwise, of the turns that put
/// one of the root link's other axes down, the one whose two feet reach deepest below the base
/// (the wrong turns find no two feet level, or a shallower pair such as the toes).
pub(super) fn upright_turn(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
) -> Result<Option<[f64; 3]>, RobotError> {
    let depth = |rpy: Option<[f64; 3]>| -> Result<f64, RobotError> {
        let mut turned = urdf.clone();
        if let Some(r) = rpy {
            turn_root(&mut turned, r)?;
        }
        let tree = Tree::new(&turned).map_err(RobotError::Feet)?;
        let model = Model::from_urdf_robot_locked(&turned, BaseJoint::Floating, &HashMap::new())?;
        let pose = Pose::zero(&model)?;
        let ([a, b], _) = find_feet(&turned, urdf_dir, &tree, &pose, &mut Vec::new())?;
        Ok(pose.link(&tree.root)?.trans.z - a.lowest.min(b.lowest))
    };
    let upright = match depth(None) {
        Ok(_) => return Ok(None),
        Err(e) => e,
    };
    TURNS
        .iter()
        .filter_map(|&r| depth(Some(r)).ok().map(|d| (d, r)))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, r)| Some(r))
        .ok_or(upright)
}

/// The way a leg faces (a horizontal unit vector in the base's frame), from its knee: the leg's
/// revolute joint with a horizontal axis nearest midway between hip and ankle, whose larger
/// range (flexion) swings the ankle backward. `None` without such a joint.
pub(super) fn knee_forward(pose: &Pose, foot: &str) -> Result<Option<Vector3<f64>>, RobotError> {
    let model = pose.model;
    let mut chain = Vec::new();
    let mut cur = model.frames[model.frame_id(foot)?].parent;
    while let Some(j) = cur {
        if let crate::dynamics::JointKind::Revolute { axis } = model.joints[j].kind {
            chain.push((j, axis));
        }
        cur = model.joints[j].parent;
    }
    let (Some(ankle), Some(hip)) = (chain.first(), chain.last()) else {
        return Ok(None);
    };
    let at = |j: usize| pose.data.o_m_i[j].trans;
    let (za, zh) = (at(ankle.0).z, at(hip.0).z);
    let knee = chain
        .iter()
        .map(|&(j, axis)| (j, pose.data.o_m_i[j].rot * axis))
        .filter(|(j, w)| w.z.abs() < 0.3 && at(*j).z > za + 0.02 && at(*j).z < zh - 0.02)
        .min_by(|a, b| {
            let mid = (za + zh) / 2.0;
            (at(a.0).z - mid).abs().total_cmp(&(at(b.0).z - mid).abs())
        });
    let Some((k, w)) = knee else {
        return Ok(None);
    };
    let l = &model.joints[k].limits;
    let flexion = if l.upper.abs() >= l.lower.abs() {
        1.0
    } else {
        -1.0
    };
    let swing = flexion * w.cross(&(at(ankle.0) - at(k)));
    let back = pose.data.o_m_i[0].rot.transpose() * swing;
    let back = Vector3::new(back.x, back.y, 0.0);
    Ok((back.norm() > 1e-6).then(|| -back.normalize()))
}

/// The robot's axes in the base's frame (columns): x forward, y its left, z up.
pub(super) fn robot_axes(forward: &Vector3<f64>) -> Matrix3<f64> {
    let z = Vector3::z();
    Matrix3::from_columns(&[*forward, z.cross(forward), z])
}

/// The sole frame of a found foot: the URDF's, when a level frame named `*sole*` on the foot
/// faces the toes; else made on the link, turned to face them with z up.
pub(super) fn sole_for(
    f: &FootFound,
    side: &str,
    tree: &Tree,
    pose: &Pose,
    axes: &Matrix3<f64>,
    notes: &mut Vec<String>,
) -> Result<DraftFoot, RobotError> {
    let model = pose.model;
    let base = pose.link(&tree.root)?.rot;
    let body = model.frames[model.frame_id(&f.link)?].parent;
    let want = base * axes;
    for (k, fr) in model.frames.iter().enumerate() {
        if f.geometry.is_some()
            || fr.parent != body
            || !fr.name.to_ascii_lowercase().contains("sole")
        {
            continue;
        }
        let r = pose.data.o_m_f[k].rot;
        let off = Rotation3::from_matrix_unchecked(want.transpose() * r).angle();
        if off < 1f64.to_radians() {
            // The URDF's own corner frames, when it has them, are the contacts.
            let corners = crate::robot::CORNERS
                .iter()
                .all(|c| model.frame_id(&format!("{}_{c}", fr.name)).is_ok());
            return Ok(DraftFoot {
                link: f.link.clone(),
                frame: fr.name.clone(),
                rpy: None,
                xyz: None,
                contacts: None,
                corner_frames: corners,
                urdf_frame: true,
            });
        }
    }
    let link_rot = pose.link(&f.link)?.rot;
    let turn = Rotation3::from_matrix_unchecked(link_rot.transpose() * want);
    let rpy = (turn.angle() > 1e-9).then(|| {
        let (r, p, y) = turn.euler_angles();
        [r, p, y].map(|x| round_to(x, 1e-6))
    });
    if rpy.is_some() {
        notes.push(format!(
            "the {side} foot link `{}` is not level with its toes along x at the zero posture: \
             its sole frame is turned by `origin.rpy`",
            f.link
        ));
    }
    let mut frame = format!("{side}_sole");
    if model.frame_id(&frame).is_ok() {
        frame = format!("upc_{side}_sole");
    }
    // From visual geometry, the points are listed: the frame at their centroid.
    let (mut xyz, mut contacts) = (None, None);
    if let Some(g) = &f.geometry {
        let p = feet::lowest_four(
            g,
            &SE3::new(turn.matrix().transpose(), Vector3::zeros()),
            &f.link,
        )?;
        let c = p.iter().sum::<Vector3<f64>>() / 4.0;
        let at = turn * c;
        xyz = Some([at.x, at.y, at.z].map(|x| round_to(x, 1e-4)));
        contacts = Some(
            p.iter()
                .map(|x| {
                    let d = x - c;
                    [d.x, d.y, d.z].map(|v| round_to(v, 1e-4))
                })
                .collect(),
        );
    }
    Ok(DraftFoot {
        link: f.link.clone(),
        frame,
        rpy: rpy.or(xyz.map(|_| [0.0; 3])),
        xyz,
        contacts,
        corner_frames: false,
        urdf_frame: false,
    })
}
