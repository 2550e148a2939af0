//! Contact points from a foot's collision mesh (STL, binary or ASCII, Wavefront OBJ or COLLADA
//! (`super::collada`), as URDFs ship them): the lowest face's support polygon, and its four corners.
//!
//! The lowest face is every vertex within [`FACE_TOLERANCE`] of the lowest along the sole's
//! normal: a sole of several pads rests on the lowest ones, and a toe a few millimetres higher
//! does not touch the ground while the foot is flat. Its corners are the four vertices furthest
//! toward front-left, front-right, rear-left and rear-right, measured in the face's bounding
//! box halves (a long narrow sole still gets its four corners, not two at each end). They are
//! vertices of the mesh, so the contacts lie on the sole the mesh draws.

use std::path::Path;

use nalgebra::Vector3;

/// How far above the lowest vertex a vertex still belongs to the face that rests on the
/// ground (m): a mesh's flat sole is flat to far better, and a pad raised by more than this is
/// off the ground.
pub const FACE_TOLERANCE: f64 = 1e-3;

/// The smallest extent of the face along x and along y (m): below it the lowest vertices are
/// an edge or a point (a rounded or tilted sole), not a face to stand on.
const MIN_EXTENT: f64 = 5e-3;

/// The vertices of the mesh file at `path` (its own units, before the URDF's scale).
pub fn vertices(path: &Path) -> Result<Vec<Vector3<f64>>, String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let shown = path.display();
    match ext.as_str() {
        "stl" => {
            let mut file = std::fs::File::open(path).map_err(|e| format!("{shown}: {e}"))?;
            let mesh = stl_io::read_stl(&mut file).map_err(|e| format!("{shown}: {e}"))?;
            Ok(mesh
                .vertices
                .iter()
                .map(|v| Vector3::new(v.0[0].into(), v.0[1].into(), v.0[2].into()))
                .collect())
        }
        "obj" => {
            let (models, _) = tobj::load_obj(path, &tobj::LoadOptions::default())
                .map_err(|e| format!("{shown}: {e}"))?;
            Ok(models
                .iter()
                .flat_map(|m| m.mesh.positions.chunks_exact(3))
                .map(|p| Vector3::new(p[0].into(), p[1].into(), p[2].into()))
                .collect())
        }
        "dae" => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{shown}: {e}"))?;
            super::collada::vertices(&text).map_err(|e| format!("{shown}: {e}"))
        }
        _ => Err(format!(
            "{shown}: upc reads contact points from STL, OBJ and COLLADA meshes, not `.{ext}`"
        )),
    }
}

/// The four corners of the lowest face of `points` (the sole's frame: z its normal, x toward
/// the toes), in no particular order.
pub fn lowest_face_corners(points: &[Vector3<f64>]) -> Result<[Vector3<f64>; 4], String> {
    let lowest = points.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
    if !lowest.is_finite() {
        return Err("the mesh has no vertices".into());
    }
    let face: Vec<&Vector3<f64>> = points
        .iter()
        .filter(|p| p.z <= lowest + FACE_TOLERANCE)
        .collect();
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for p in &face {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let (centre, half) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
    if 2.0 * half.x < MIN_EXTENT || 2.0 * half.y < MIN_EXTENT {
        return Err(format!(
            "its lowest vertices (within {:.0} mm) span {:.1} × {:.1} mm: no flat sole along \
             this frame's z (a rounded or tilted sole)",
            FACE_TOLERANCE * 1e3,
            2e3 * half.x,
            2e3 * half.y
        ));
    }
    let corner = |sx: f64, sy: f64| {
        let reach =
            |p: &Vector3<f64>| sx * (p.x - centre.x) / half.x + sy * (p.y - centre.y) / half.y;
        face.iter()
            .copied()
            .max_by(|a, b| reach(a).total_cmp(&reach(b)))
            .copied()
            .unwrap_or(centre)
    };
    Ok([
        corner(1.0, 1.0),
        corner(1.0, -1.0),
        corner(-1.0, 1.0),
        corner(-1.0, -1.0),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sole of two pads, the heel's and the ball's, flat at z = 0, and a toe 3.6 mm higher:
    /// the corners are the pads' outer ones, the toe is off the ground.
    #[test]
    fn the_corners_are_the_lowest_pads_not_a_raised_toe() {
        let mut pts = Vec::new();
        let pad = |pts: &mut Vec<Vector3<f64>>, x0: f64, x1: f64, y: f64, z: f64| {
            for x in [x0, (x0 + x1) / 2.0, x1] {
                for s in [-1.0, 0.0, 1.0] {
                    pts.push(Vector3::new(x, s * y, z));
                    pts.push(Vector3::new(x, s * y, z + 0.02));
                }
            }
        };
        pad(&mut pts, -0.08, -0.02, 0.03, 0.0);
        pad(&mut pts, 0.0, 0.09, 0.04, 0.0);
        pad(&mut pts, 0.10, 0.13, 0.035, 0.0036);
        let c = lowest_face_corners(&pts).expect("corners");
        let want = [[0.09, 0.04], [0.09, -0.04], [-0.08, 0.03], [-0.08, -0.03]];
        for (p, w) in c.iter().zip(want) {
            assert!(
                (p - Vector3::new(w[0], w[1], 0.0)).norm() < 1e-12,
                "{p:?} against {w:?}"
            );
        }
    }

    /// A sole tilted about y has a lowest edge, not a face: refused, saying why.
    #[test]
    fn a_tilted_sole_is_no_face() {
        let pts: Vec<Vector3<f64>> = [[-0.1, -0.04], [-0.1, 0.04], [0.1, -0.04], [0.1, 0.04]]
            .iter()
            .map(|[x, y]| Vector3::new(*x, *y, 0.2 * x))
            .collect();
        let e = lowest_face_corners(&pts).expect_err("tilted");
        assert!(e.contains("no flat sole"), "{e}");
    }
}
