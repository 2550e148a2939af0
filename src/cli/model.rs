//! `upc model`: inspect a URDF (joints, DoF, mass, CoM) or dump M(q), h(q, v), the CoM and a
//! frame Jacobian as JSON for debugging and cross-checking with other tools. With `--robot`, a
//! robot description: its model at home and what upc computes from it.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};
use serde::Deserialize;
use upc::dynamics::{
    BaseJoint, Data, JointKind, Model, ReferenceFrame, center_of_mass_velocity, crba,
    frame_jacobian, nonlinear_effects,
};

use super::CliResult;

#[derive(clap::Args)]
pub struct ModelArgs {
    /// URDF file (or give --robot).
    #[arg(required_unless_present = "robot")]
    pub urdf: Option<PathBuf>,
    /// A robot description (embedded name or TOML path): its model with the sole and contact
    /// frames, at its home configuration by default, and the values computed from it.
    #[arg(long, conflicts_with = "urdf")]
    pub robot: Option<String>,
    /// Add a free-flyer root (default when the URDF root link is not `world`).
    #[arg(long, conflicts_with = "fixed")]
    pub floating: bool,
    /// Weld the URDF root link to the world (default when the root link is `world`).
    #[arg(long)]
    pub fixed: bool,
    /// Print M(q), h(q, v), the CoM and the frame Jacobian as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Configuration, comma-separated (nq values; free-flyer: x,y,z,qx,qy,qz,qw first).
    /// Default: the neutral configuration.
    #[arg(long, allow_hyphen_values = true)]
    pub q: Option<String>,
    /// Velocity, comma-separated (nv values). Default: zero.
    #[arg(long, allow_hyphen_values = true)]
    pub v: Option<String>,
    /// Frame whose Jacobian (LOCAL_WORLD_ALIGNED and LOCAL) is dumped.
    #[arg(long)]
    pub frame: Option<String>,
    /// JSON file {"q": [...], "v": [...], "frame": "..."}; command-line values take precedence.
    #[arg(long)]
    pub input: Option<PathBuf>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct InputFile {
    q: Option<Vec<f64>>,
    v: Option<Vec<f64>>,
    frame: Option<String>,
}

pub fn run(args: ModelArgs) -> CliResult {
    let base = if args.floating {
        BaseJoint::Floating
    } else if args.fixed {
        BaseJoint::Fixed
    } else {
        BaseJoint::Auto
    };
    let robot = args
        .robot
        .as_deref()
        .map(upc::robot::Robot::load)
        .transpose()?;
    let model = match (&robot, &args.urdf) {
        (Some(r), _) => r.model.clone(),
        (None, Some(path)) => Model::from_urdf_file(path, base)?,
        (None, None) => return Err("give a URDF file or --robot".into()),
    };
    let input = match &args.input {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
            serde_json::from_str::<InputFile>(&text)
                .map_err(|e| format!("{}: {e}", path.display()))?
        }
        None => InputFile::default(),
    };
    let q = match (&args.q, input.q) {
        (Some(s), _) => parse_list("--q", s)?,
        (None, Some(v)) => DVector::from_vec(v),
        (None, None) => robot
            .as_ref()
            .map_or_else(|| model.neutral(), |r| r.home.clone()),
    };
    let v = match (&args.v, input.v) {
        (Some(s), _) => parse_list("--v", s)?,
        (None, Some(v)) => DVector::from_vec(v),
        (None, None) => DVector::zeros(model.nv),
    };
    let frame = args.frame.or(input.frame);
    if let (Some(r), false) = (&robot, args.json) {
        print_robot(r)?;
    }
    if args.json {
        print_json(&model, &q, &v, frame.as_deref())
    } else {
        print_table(&model, &q, &v, frame.as_deref())
    }
}

/// What upc computes from a robot description.
fn print_robot(r: &upc::robot::Robot) -> CliResult {
    let d = &r.derived;
    let m = &d.effective_mass;
    println!("robot {} — {}", r.name(), r.description.description);
    println!("  description: {}", r.origin);
    match &r.urdf_path {
        Some(p) => println!("  URDF: {}", p.display()),
        None => println!("  URDF: embedded {}", r.description.urdf.path.display()),
    }
    println!(
        "  nq = {}, nv = {} ({} joints locked{})",
        r.model.nq,
        r.model.nv,
        r.locked.len(),
        if r.locked.is_empty() {
            String::new()
        } else {
            let names: Vec<&str> = r.locked.keys().map(String::as_str).collect();
            format!(": {}", names.join(", "))
        }
    );
    println!(
        "  mass {:.3} kg; CoM at home {:.4} m above the contacts, ({:+.4}, {:+.4}) m from the feet centre",
        d.mass, d.com_height, d.com_offset[0], d.com_offset[1]
    );
    println!(
        "  support x ∈ [{:+.4}, {:+.4}] m, y ∈ [{:+.4}, {:+.4}] m; feet {:.4} m apart; soles tilted ≤ {:.3}°",
        d.support[0][0],
        d.support[0][1],
        d.support[1][0],
        d.support[1][1],
        d.feet_distance,
        d.sole_tilt.to_degrees()
    );
    println!(
        "  hand `{}` at ({:+.4}, {:+.4}, {:.4}) m; M_e ({} → hand, kg) = [[{:.3}, {:.3}, {:.3}], [{:.3}, {:.3}, {:.3}], [{:.3}, {:.3}, {:.3}]]",
        r.description.hand.frame,
        d.hand_position.x,
        d.hand_position.y,
        d.hand_position.z,
        r.description.hand.chain_root,
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 0)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 0)],
        m[(2, 1)],
        m[(2, 2)]
    );
    println!(
        "  the arm holds {:.1} N along x at home (effort limits); scenario forces × {:.4}",
        d.hand_force_capacity,
        r.force_scale()?
    );
    let mut data = Data::new(&r.model);
    upc::dynamics::forward_kinematics(&r.model, &mut data, &r.home)?;
    for c in &r.contacts {
        let p = data.o_m_f[r.model.frame_id(c)?].trans;
        println!(
            "  contact {c:<22} ({:+.4}, {:+.4}, {:+.4}) m",
            p.x, p.y, p.z
        );
    }
    if r.description.stance.is_some() {
        // The solved posture as a [home] table: pasted in place of [stance], the same robot
        // without the solve.
        println!("\n# the posture [stance] solved, as a [home] table (rad):\n[home]");
        for j in r.model.joints.iter().filter(|j| j.nq() == 1) {
            let x = r.home[j.idx_q];
            if x.abs() >= 5e-5 {
                println!("{} = {x:.4}", j.name);
            }
        }
    }
    println!();
    Ok(())
}

fn parse_list(flag: &str, s: &str) -> Result<DVector<f64>, String> {
    let values = s
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .map_err(|e| format!("{flag}: '{t}' is not a number ({e})"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(DVector::from_vec(values))
}

fn fmt_limit(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "-".into()
    }
}

fn print_table(
    model: &Model,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: Option<&str>,
) -> CliResult {
    let mut data = Data::new(model);
    let (com, _) = center_of_mass_velocity(model, &mut data, q, v)?;
    println!("model: {}", model.name);
    println!(
        "base: {}",
        if model.has_floating_base() {
            "floating (free-flyer root_joint: q = [x y z qx qy qz qw], v = [v_body ω_body])"
        } else {
            "fixed"
        }
    );
    println!(
        "nq = {}, nv = {} (DoF), joints = {}, frames = {}",
        model.nq,
        model.nv,
        model.njoints(),
        model.frames.len()
    );
    println!();
    println!(
        "{:>3}  {:<24} {:<10} {:<20} {:>4} {:>4} {:>8} {:>8} {:>8} {:>8}",
        "#", "joint", "type", "parent body", "iq", "iv", "lower", "upper", "vel", "effort"
    );
    for (i, j) in model.joints.iter().enumerate() {
        let parent = j
            .parent
            .map_or("(world)", |p| model.joints[p].body.as_str());
        let l = j.limits;
        println!(
            "{:>3}  {:<24} {:<10} {:<20} {:>4} {:>4} {:>8} {:>8} {:>8} {:>8}",
            i,
            j.name,
            j.kind.label(),
            parent,
            j.idx_q,
            j.idx_v,
            fmt_limit(l.lower),
            fmt_limit(l.upper),
            fmt_limit(l.velocity),
            fmt_limit(l.effort)
        );
    }
    println!();
    println!("total mass: {:.4} kg", model.total_mass());
    let at = if q == &model.neutral() {
        "neutral configuration"
    } else {
        "given configuration"
    };
    println!(
        "CoM ({at}, world): [{:.4}, {:.4}, {:.4}] m",
        com.x, com.y, com.z
    );
    if let Some(name) = frame {
        let id = model.frame_id(name)?;
        let p = data.o_m_f[id].trans;
        println!(
            "frame {name}: origin [{:.4}, {:.4}, {:.4}] m",
            p.x, p.y, p.z
        );
    }
    Ok(())
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|r| m.row(r).iter().copied().collect())
        .collect()
}

fn print_json(model: &Model, q: &DVector<f64>, v: &DVector<f64>, frame: Option<&str>) -> CliResult {
    let mut data = Data::new(model);
    let m = crba(model, &mut data, q)?.clone();
    let h = nonlinear_effects(model, &mut data, q, v)?.clone();
    let (com, vcom) = center_of_mass_velocity(model, &mut data, q, v)?;
    let frame_json = match frame {
        Some(name) => {
            let id = model.frame_id(name)?;
            let lwa =
                frame_jacobian(model, &mut data, q, id, ReferenceFrame::LocalWorldAligned)?.clone();
            let local = frame_jacobian(model, &mut data, q, id, ReferenceFrame::Local)?.clone();
            let pose = data.o_m_f[id];
            serde_json::json!({
                "name": name,
                "translation": pose.trans.as_slice(),
                "rotation": rows(&DMatrix::from_column_slice(3, 3, pose.rot.as_slice())),
                "jacobian_local_world_aligned": rows(&lwa),
                "jacobian_local": rows(&local),
            })
        }
        None => serde_json::Value::Null,
    };
    let dofs: Vec<String> = model
        .joints
        .iter()
        .flat_map(|j| match j.kind {
            JointKind::FreeFlyer => ["vx", "vy", "vz", "wx", "wy", "wz"]
                .iter()
                .map(|c| format!("{}:{c}", j.name))
                .collect::<Vec<_>>(),
            _ => vec![j.name.clone()],
        })
        .collect();
    let out = serde_json::json!({
        "model": model.name,
        "floating_base": model.has_floating_base(),
        "nq": model.nq,
        "nv": model.nv,
        "velocity_names": dofs,
        "conventions": "spatial rows [linear; angular]; free-flyer q = [p_world, quat xyzw], v = [v_body, w_body]; h = RNEA(q, v, 0) including gravity",
        "gravity": model.gravity.as_slice(),
        "q": q.as_slice(),
        "v": v.as_slice(),
        "total_mass": model.total_mass(),
        "M": rows(&m),
        "h": h.as_slice(),
        "com": com.as_slice(),
        "com_velocity": vcom.as_slice(),
        "frame": frame_json,
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
