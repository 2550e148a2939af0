//! The four contact points under each sole, as frames of the model named `<sole>_fl`, `_fr`,
//! `_rl`, `_rr` (front/rear, left/right in the sole frame: [`CORNERS`], which the whole-body
//! controller and the simulator look up). Given as frames of the URDF, as points, or derived
//! from the foot's collision geometry (boxes, spheres, or a mesh: [`super::sole_mesh`]).

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::RobotError;
use super::description::{ContactSpec, FootSpec, SoleOrigin};
use crate::dynamics::{Model, SE3};

/// Corner frame suffixes, front/rear and left/right in the sole frame: the order of each foot's
/// four contact forces in the channel contract and in the whole-body controller's output.
pub const CORNERS: [&str; 4] = ["fl", "fr", "rl", "rr"];

/// The contact points of a biped: each foot's corners (the whole-body QP's contact count, the
/// base estimator's; the channel contract carries as many, checked in `control::contract`).
pub const N_CONTACTS: usize = 2 * CORNERS.len();

/// Placement of link or frame `name` in its carrying body, and the body's joint.
fn on_body(model: &Model, name: &str) -> Option<(Option<usize>, SE3)> {
    let f = &model.frames[model.frame_id(name).ok()?];
    Some((f.parent, f.placement))
}

/// Candidate points (link frame) from a link's collision geometry: a box's eight corners,
/// spheres' centres with their radii, a mesh's vertices.
pub(super) struct Collision {
    pub(super) points: Vec<Vector3<f64>>,
    pub(super) radii: Vec<f64>,
    /// A mesh among them: the contacts are its lowest face's corners, not the four lowest
    /// points.
    mesh: bool,
}

pub(super) fn collision_points(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    link: &str,
) -> Result<Collision, RobotError> {
    geometry_points(urdf, urdf_dir, link, false)
}

/// As [`collision_points`], from the link's visual geometry (`visual`) or its collision
/// geometry.
pub(super) fn geometry_points(
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    link: &str,
    visual: bool,
) -> Result<Collision, RobotError> {
    let l = urdf
        .links
        .iter()
        .find(|l| l.name == link)
        .ok_or_else(|| RobotError::Feet(format!("no link `{link}` in the URDF")))?;
    let (mut pts, mut radii, mut mesh) = (Vec::new(), Vec::new(), false);
    let shapes: Vec<(&urdf_rs::Pose, &urdf_rs::Geometry)> = if visual {
        l.visual.iter().map(|v| (&v.origin, &v.geometry)).collect()
    } else {
        l.collision
            .iter()
            .map(|c| (&c.origin, &c.geometry))
            .collect()
    };
    for (origin, geometry) in shapes {
        let o = SE3::from_xyz_rpy(origin.xyz.0, origin.rpy.0);
        match geometry {
            urdf_rs::Geometry::Box { size } => {
                let h = Vector3::from(size.0) * 0.5;
                for k in 0..8 {
                    let s = |b: usize| if k & b == 0 { -1.0 } else { 1.0 };
                    pts.push(o.act_point(&Vector3::new(s(1) * h.x, s(2) * h.y, s(4) * h.z)));
                    radii.push(0.0);
                }
            }
            urdf_rs::Geometry::Sphere { radius } => {
                pts.push(o.trans);
                radii.push(*radius);
            }
            urdf_rs::Geometry::Mesh { filename, scale } => {
                let list = "or list the contact points (contacts = [[x, y, z], …] in the sole \
                            frame)";
                let path = super::packages::resolve_mesh(filename, urdf_dir).ok_or_else(|| {
                    RobotError::Feet(format!(
                        "link `{link}`: collision mesh `{filename}` not found (looked next to \
                         the URDF{} and in {}): install its package, {list}",
                        urdf_dir.map_or(String::new(), |d| format!(", {}", d.display())),
                        super::packages::package_search_dirs()
                            .iter()
                            .map(|d| d.display().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
                let vertices = super::sole_mesh::vertices(&path)
                    .map_err(|e| RobotError::Feet(format!("link `{link}`: {e}; {list}")))?;
                let k = scale.map_or(Vector3::repeat(1.0), |s| Vector3::from(s.0));
                for v in vertices {
                    pts.push(o.act_point(&v.component_mul(&k)));
                    radii.push(0.0);
                }
                mesh = true;
            }
            other => {
                return Err(RobotError::Feet(format!(
                    "link `{link}`: a collision {} cannot give contact points: list them \
                     (contacts = [[x, y, z], …] in the sole frame)",
                    match other {
                        urdf_rs::Geometry::Cylinder { .. } => "cylinder",
                        _ => "capsule",
                    }
                )));
            }
        }
    }
    if pts.is_empty() {
        return Err(RobotError::Feet(format!(
            "link `{link}` has no collision geometry: list the contact points"
        )));
    }
    Ok(Collision {
        points: pts,
        radii,
        mesh,
    })
}

/// The four contact points in `frame` (placement `to_frame` from the link): a mesh's lowest
/// face's corners, else the four lowest points along `-z`, each sphere lowered by its radius:
/// the face that rests on the ground.
pub(super) fn lowest_four(
    c: &Collision,
    to_frame: &SE3,
    link: &str,
) -> Result<Vec<Vector3<f64>>, RobotError> {
    let mut p: Vec<Vector3<f64>> = c
        .points
        .iter()
        .zip(&c.radii)
        .map(|(x, r)| to_frame.act_point(x) - Vector3::z() * *r)
        .collect();
    if c.mesh {
        return super::sole_mesh::lowest_face_corners(&p)
            .map(Vec::from)
            .map_err(|e| {
                RobotError::Feet(format!(
                    "link `{link}`: collision mesh: {e}; turn the sole frame (`origin` rpy) or \
                     list the contact points"
                ))
            });
    }
    p.sort_by(|a, b| a.z.total_cmp(&b.z));
    if p.len() < 4 {
        return Err(RobotError::Feet(format!(
            "link `{link}`: {} collision points, four are needed",
            p.len()
        )));
    }
    let flat = p[3].z - p[0].z;
    if flat > 1e-3 {
        return Err(RobotError::Feet(format!(
            "link `{link}`: the four lowest collision points are not in the sole plane \
             ({:.1} mm apart along its normal): list the contact points",
            flat * 1e3
        )));
    }
    p.truncate(4);
    Ok(p)
}

/// Front-left, front-right, rear-left, rear-right.
fn ordered(mut p: Vec<Vector3<f64>>) -> [Vector3<f64>; 4] {
    p.sort_by(|a, b| b.x.total_cmp(&a.x));
    let (mut front, mut rear) = ([p[0], p[1]], [p[2], p[3]]);
    front.sort_by(|a, b| b.y.total_cmp(&a.y));
    rear.sort_by(|a, b| b.y.total_cmp(&a.y));
    [front[0], front[1], rear[0], rear[1]]
}

/// A frame's body (its joint) and its placement in that body.
type OnBody = (Option<usize>, SE3);

/// Adds the foot's sole frame (if new) and contact frames to `model`; returns the contact
/// frames' names in [`CORNERS`] order.
///
/// `urdf_dir`: the URDF's directory, where a collision mesh's relative path starts.
pub fn attach(
    model: &mut Model,
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    spec: &FootSpec,
) -> Result<[String; 4], RobotError> {
    let names = CORNERS.map(|c| format!("{}_{c}", spec.frame));
    let sole = on_body(model, &spec.frame);
    let origin = spec.origin.unwrap_or_default();
    if spec.origin.is_some() && sole.is_some() {
        return Err(RobotError::Feet(format!(
            "`origin` places a sole frame upc makes, but the URDF has `{}`: drop `origin`, or \
             name a new frame",
            spec.frame
        )));
    }
    if !origin.xyz.iter().chain(&origin.rpy).all(|x| x.is_finite()) {
        return Err(RobotError::Feet(format!(
            "sole `{}`: origin is not finite",
            spec.frame
        )));
    }
    let points: Vec<Vector3<f64>> = match &spec.contacts {
        ContactSpec::Keyword(k) if k == "frames" => {
            return corner_frames(model, spec, sole, names);
        }
        ContactSpec::Keyword(k) if k == "collision" => {
            collision_contacts(model, urdf, urdf_dir, spec, sole, &origin)?
        }
        ContactSpec::Keyword(k) => {
            return Err(RobotError::Feet(format!(
                "contacts = \"{k}\": expected \"frames\", \"collision\" or four [x, y, z] points"
            )));
        }
        ContactSpec::Points(p) => listed_contacts(model, spec, sole, &origin, p)?,
    };
    let (joint, sole_in_body) = on_body(model, &spec.frame)
        .ok_or_else(|| RobotError::Feet(format!("no sole frame `{}`", spec.frame)))?;
    for (name, p) in names.iter().zip(ordered(points)) {
        let at = sole_in_body.compose(&SE3::new(Matrix3::identity(), p));
        model.add_frame(name.clone(), joint, at).map_err(|_| {
            RobotError::Feet(format!(
                "the URDF already has a frame `{name}`: use contacts = \"frames\""
            ))
        })?;
    }
    Ok(names)
}

/// The made sole frame in its link's frame.
fn made_sole(origin: &SoleOrigin) -> SE3 {
    SE3::from_xyz_rpy(origin.xyz, origin.rpy)
}

/// `contacts = "frames"`: the URDF's sole frame (`sole`) and its corner frames `names`.
fn corner_frames(
    model: &Model,
    spec: &FootSpec,
    sole: Option<OnBody>,
    names: [String; 4],
) -> Result<[String; 4], RobotError> {
    if sole.is_none() {
        return Err(RobotError::Feet(format!(
            "contacts = \"frames\" but the URDF has no sole frame `{}`",
            spec.frame
        )));
    }
    for n in &names {
        model.frame_id(n).map_err(|_| {
            RobotError::Feet(format!(
                "contacts = \"frames\" but the URDF has no frame `{n}`"
            ))
        })?;
    }
    Ok(names)
}

/// `contacts = "collision"`: the four lowest points of the link's collision geometry, in the
/// sole frame: the URDF's (`sole`), or one made at their centroid (added to `model`), its
/// axes the link's turned by `origin.rpy`.
fn collision_contacts(
    model: &mut Model,
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    spec: &FootSpec,
    sole: Option<OnBody>,
    origin: &SoleOrigin,
) -> Result<Vec<Vector3<f64>>, RobotError> {
    let link = spec.link.as_deref().unwrap_or(&spec.frame);
    let (body_joint, link_in_body) = on_body(model, link)
        .ok_or_else(|| RobotError::Feet(format!("no link `{link}` in the model")))?;
    let collision = collision_points(urdf, urdf_dir, link)?;
    match sole {
        Some((joint, sole_in_body)) => {
            if joint != body_joint {
                return Err(RobotError::Feet(format!(
                    "sole `{}` and link `{link}` are on different bodies",
                    spec.frame
                )));
            }
            let to_sole = sole_in_body.inverse().compose(&link_in_body);
            lowest_four(&collision, &to_sole, link)
        }
        None => {
            // A new sole frame at the contact points' centroid, axes of the link turned by
            // `origin.rpy`.
            if origin.xyz != [0.0; 3] {
                return Err(RobotError::Feet(format!(
                    "sole `{}`: a sole made from collision geometry sits at its contact \
                     points' centroid: give `origin` an rpy only",
                    spec.frame
                )));
            }
            let made = made_sole(origin);
            let p = lowest_four(&collision, &made.inverse(), link)?;
            let c = p.iter().sum::<Vector3<f64>>() / 4.0;
            let sole_in_body = link_in_body
                .compose(&made)
                .compose(&SE3::new(Matrix3::identity(), c));
            model.add_frame(spec.frame.clone(), body_joint, sole_in_body)?;
            Ok(p.iter().map(|x| x - c).collect())
        }
    }
}

/// Four contact points listed in the sole frame: the URDF's (`sole`), or one made on the
/// foot's `link` at `origin` (added to `model`).
fn listed_contacts(
    model: &mut Model,
    spec: &FootSpec,
    sole: Option<OnBody>,
    origin: &SoleOrigin,
    p: &[[f64; 3]],
) -> Result<Vec<Vector3<f64>>, RobotError> {
    if p.len() != 4 || p.iter().flatten().any(|x| !x.is_finite()) {
        return Err(RobotError::Feet(format!(
            "sole `{}`: four finite [x, y, z] contact points are needed, got {}",
            spec.frame,
            p.len()
        )));
    }
    if sole.is_none() {
        let link = spec.link.as_deref().ok_or_else(|| {
            RobotError::Feet(format!(
                "no sole frame `{}` in the URDF: name its `link`",
                spec.frame
            ))
        })?;
        let (joint, at) = on_body(model, link)
            .ok_or_else(|| RobotError::Feet(format!("no link `{link}` in the model")))?;
        model.add_frame(spec.frame.clone(), joint, at.compose(&made_sole(origin)))?;
    }
    Ok(p.iter().map(|x| Vector3::from(*x)).collect())
}
