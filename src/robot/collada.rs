//! The vertices of a COLLADA (`.dae`) mesh, placed as URDF consumers place them (Assimp, which
//! ROS's viewers and Pinocchio's collision library load meshes with): each geometry instanced
//! in the visual scene through its nodes' transforms (`matrix`, `translate`, `rotate`,
//! `scale`, outermost first), scaled by the document's `<unit meter>` and turned from `Y_UP` to
//! z up. A document with no scene gives its geometries as written.

use nalgebra::{Matrix4, Rotation3, Unit, Vector3};
use roxmltree::{Document, Node};

/// The vertices of the document `text` (m, z up).
pub fn vertices(text: &str) -> Result<Vec<Vector3<f64>>, String> {
    let doc = Document::parse(text).map_err(|e| format!("not COLLADA XML: {e}"))?;
    let root = doc.root_element();
    let asset = child(root, "asset");
    let unit = asset
        .and_then(|a| child(a, "unit"))
        .and_then(|u| u.attribute("meter"))
        .map_or(Ok(1.0), str::parse::<f64>)
        .map_err(|e| format!("<unit meter>: {e}"))?;
    let up = match asset
        .and_then(|a| child(a, "up_axis"))
        .and_then(|u| u.text())
        .map(str::trim)
    {
        None | Some("Y_UP") => {
            Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2)
        }
        Some("Z_UP") => Rotation3::identity(),
        Some(other) => return Err(format!("<up_axis> {other}: upc reads Y_UP and Z_UP")),
    };
    let top = Matrix4::new_scaling(unit) * up.to_homogeneous();
    let mut out = Vec::new();
    let scene = descendants(root, "visual_scene").next();
    match scene {
        Some(s) => {
            for n in s.children().filter(|n| n.has_tag_name("node")) {
                walk(&doc, n, &top, &mut out)?;
            }
        }
        None => {
            for g in descendants(root, "geometry") {
                geometry(&doc, g, &top, &mut out)?;
            }
        }
    }
    Ok(out)
}

fn child<'a, 'i>(n: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(tag))
}

fn descendants<'a, 'i: 'a>(n: Node<'a, 'i>, tag: &'a str) -> impl Iterator<Item = Node<'a, 'i>> {
    n.descendants().filter(move |c| c.has_tag_name(tag))
}

fn numbers(n: Node) -> Result<Vec<f64>, String> {
    n.text()
        .unwrap_or("")
        .split_whitespace()
        .map(|x| {
            x.parse::<f64>()
                .map_err(|e| format!("<{}> `{x}`: {e}", n.tag_name().name()))
        })
        .collect()
}

/// The element whose `id` a `#id` URL names.
fn by_id<'a, 'i>(doc: &'a Document<'i>, url: &str) -> Result<Node<'a, 'i>, String> {
    let id = url.strip_prefix('#').unwrap_or(url);
    doc.descendants()
        .find(|n| n.attribute("id") == Some(id))
        .ok_or_else(|| format!("no element with id `{id}`"))
}

/// A node: its transforms applied to `parent`, its geometries, its child nodes.
fn walk(
    doc: &Document,
    node: Node,
    parent: &Matrix4<f64>,
    out: &mut Vec<Vector3<f64>>,
) -> Result<(), String> {
    let mut m = *parent;
    for c in node.children().filter(Node::is_element) {
        let v = || numbers(c);
        match c.tag_name().name() {
            "matrix" => {
                let x = v()?;
                if x.len() != 16 {
                    return Err("<matrix> needs 16 numbers".into());
                }
                m *= Matrix4::from_row_slice(&x);
            }
            "translate" => {
                let x = v()?;
                if x.len() != 3 {
                    return Err("<translate> needs 3 numbers".into());
                }
                m *= Matrix4::new_translation(&Vector3::new(x[0], x[1], x[2]));
            }
            "rotate" => {
                let x = v()?;
                if x.len() != 4 {
                    return Err("<rotate> needs 4 numbers".into());
                }
                let axis = Vector3::new(x[0], x[1], x[2]);
                if axis.norm() > 0.0 {
                    m *= Rotation3::from_axis_angle(&Unit::new_normalize(axis), x[3].to_radians())
                        .to_homogeneous();
                }
            }
            "scale" => {
                let x = v()?;
                if x.len() != 3 {
                    return Err("<scale> needs 3 numbers".into());
                }
                m *= Matrix4::new_nonuniform_scaling(&Vector3::new(x[0], x[1], x[2]));
            }
            "instance_geometry" => {
                let url = c
                    .attribute("url")
                    .ok_or("<instance_geometry> without url")?;
                geometry(doc, by_id(doc, url)?, &m, out)?;
            }
            "node" => walk(doc, c, &m, out)?,
            "instance_node" => {
                let url = c.attribute("url").ok_or("<instance_node> without url")?;
                walk(doc, by_id(doc, url)?, &m, out)?;
            }
            _ => {}
        }
    }
    Ok(())
}

/// A `<geometry>`'s mesh positions, transformed by `m`.
fn geometry(
    doc: &Document,
    g: Node,
    m: &Matrix4<f64>,
    out: &mut Vec<Vector3<f64>>,
) -> Result<(), String> {
    for vertices in descendants(g, "vertices") {
        let Some(input) = vertices
            .children()
            .find(|i| i.has_tag_name("input") && i.attribute("semantic") == Some("POSITION"))
        else {
            continue;
        };
        let source = by_id(doc, input.attribute("source").unwrap_or(""))?;
        let array = descendants(source, "float_array")
            .next()
            .ok_or("a POSITION source without <float_array>")?;
        let stride = descendants(source, "accessor")
            .next()
            .and_then(|a| a.attribute("stride"))
            .map_or(Ok(3), str::parse::<usize>)
            .map_err(|e| format!("<accessor stride>: {e}"))?;
        if stride < 3 {
            return Err(format!("POSITION stride {stride} < 3"));
        }
        for p in numbers(array)?.chunks_exact(stride) {
            out.push(
                m.transform_point(&nalgebra::Point3::new(p[0], p[1], p[2]))
                    .coords,
            );
        }
    }
    Ok(())
}
