//! `upc robot`: bring a robot. `upc robot init [PACKAGE] URDF --out FILE` drafts its
//! description from the URDF alone (`upc::robot::init`), loads it as `upc run` would and writes
//! it.

use std::path::PathBuf;

use super::CliResult;

#[derive(clap::Args)]
pub struct RobotArgs {
    #[command(subcommand)]
    pub command: RobotCommand,
}

#[derive(clap::Subcommand)]
pub enum RobotCommand {
    /// Draft a robot description from a URDF (feet, soles, contacts, hand, IMU, locked fingers,
    /// the solved standing posture), check it as `upc run` would, and write it.
    Init(InitArgs),
}

#[derive(clap::Args)]
pub struct InitArgs {
    /// `[PACKAGE] PATH`: a URDF file, or a registry package installed by scripts/setup.sh
    /// (`example-robot-data`, `icub-models`) and the URDF's path inside it.
    #[arg(num_args = 1..=2, required = true, value_name = "[PACKAGE] PATH")]
    pub source: Vec<String>,
    /// The description to write (TOML).
    #[arg(long, short)]
    pub out: PathBuf,
    /// The robot's name (default: the URDF file's stem).
    #[arg(long)]
    pub name: Option<String>,
    /// Overwrite an existing file.
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: RobotArgs) -> CliResult {
    match args.command {
        RobotCommand::Init(a) => init(a),
    }
}

fn init(a: InitArgs) -> CliResult {
    let (package, path) = match a.source.as_slice() {
        [p] => (None, PathBuf::from(p)),
        [k, p] => (Some(k.as_str()), PathBuf::from(p)),
        _ => return Err("give [PACKAGE] PATH".into()),
    };
    if a.out.exists() && !a.force {
        return Err(format!("{} exists: give --force to overwrite it", a.out.display()).into());
    }
    // The file's stem, or its directory's name when the stem says nothing (`model.urdf`).
    let name = a.name.unwrap_or_else(|| {
        let stem = |p: &std::path::Path| p.file_stem().map(|s| s.to_string_lossy().into_owned());
        let mut n = stem(&path).unwrap_or_else(|| "robot".into());
        if ["model", "robot", "urdf"].contains(&n.as_str())
            && let Some(dir) = path.parent().and_then(stem)
        {
            n = dir;
        }
        n.replace('-', "_")
    });
    let started = std::time::Instant::now();
    let mut draft = upc::robot::init::draft(package, &path, &name)?;
    let write =
        |text: &str| std::fs::write(&a.out, text).map_err(|e| format!("{}: {e}", a.out.display()));
    let (text, robot) = match upc::robot::init::solve(&mut draft) {
        Ok(solved) => solved,
        Err(e) => {
            // The draft as found, for the user to correct: what upc refused, and where.
            write(&draft.to_toml(&Default::default()))?;
            return Err(format!(
                "{e}\n(the draft is written to {}: correct it, then `upc model --robot {0}`)",
                a.out.display()
            )
            .into());
        }
    };
    write(&text)?;
    let d = &robot.derived;
    println!(
        "wrote {} ({:.1} s): {} — {:.1} kg, {} DoF, CoM {:.3} m high",
        a.out.display(),
        started.elapsed().as_secs_f64(),
        robot.name(),
        d.mass,
        robot.model.nv,
        d.com_height
    );
    for (side, f) in ["left", "right"].iter().zip(&draft.feet) {
        println!(
            "  {side} foot: link {}, sole frame {} ({})",
            f.link,
            f.frame,
            if f.urdf_frame {
                "the URDF's"
            } else if f.rpy.is_some() {
                "made, turned by origin.rpy"
            } else {
                "made, the link's axes"
            }
        );
    }
    println!(
        "  hand: {} (arm chain from {}), holds {:.0} N along x",
        draft.hand, draft.chain_root, d.hand_force_capacity
    );
    println!(
        "  IMU: {}; {} joints locked",
        draft.imu.as_deref().unwrap_or("on the base"),
        draft.locked.len()
    );
    for n in &draft.notes {
        println!("  note: {n}");
    }
    println!(
        "next: upc model --robot {0}   then   upc run --robot {0}",
        a.out.display()
    );
    Ok(())
}
