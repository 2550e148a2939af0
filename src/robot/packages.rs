//! Where the registry packages with robot models are: `scripts/setup.sh` installs
//! `example-robot-data` and `icub-models` (PyPI) into a virtual environment outside the clone,
//! `$UPC_ROBOT_VENV` or `~/.cache/upc/robot-venv`.

use std::path::{Path, PathBuf};

/// The packages a robot description may name, and where each puts its files inside the
/// environment (`{site}`: the environment's `site-packages`).
const LAYOUT: [(&str, &str); 2] = [
    (
        "example-robot-data",
        "{site}/cmeel.prefix/share/example-robot-data",
    ),
    ("icub-models", "share/iCub"),
];

/// The robot-model environment (it may not exist).
pub fn robot_venv() -> Option<PathBuf> {
    std::env::var_os("UPC_ROBOT_VENV")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache/upc/robot-venv"))
        })
}

fn site_packages(venv: &std::path::Path) -> Option<PathBuf> {
    let lib = std::fs::read_dir(venv.join("lib")).ok()?;
    let mut found: Vec<PathBuf> = lib
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("site-packages"))
        .filter(|p| p.is_dir())
        .collect();
    found.sort();
    found.pop()
}

/// The root directory of `package`'s files, or why there is none.
pub fn package_root(package: &str) -> Result<PathBuf, String> {
    let Some((_, layout)) = LAYOUT.iter().find(|(p, _)| *p == package) else {
        let known: Vec<&str> = LAYOUT.iter().map(|(p, _)| *p).collect();
        return Err(format!(
            "unknown robot package `{package}` (known: {})",
            known.join(", ")
        ));
    };
    let venv = robot_venv().ok_or("neither UPC_ROBOT_VENV nor HOME is set")?;
    let root = if let Some(rest) = layout.strip_prefix("{site}/") {
        site_packages(&venv).map(|s| s.join(rest))
    } else {
        Some(venv.join(layout))
    };
    match root {
        Some(r) if r.is_dir() => Ok(r),
        _ => Err(format!(
            "the package `{package}` is not installed in {} (scripts/setup.sh installs it; \
             UPC_ROBOT_VENV points elsewhere)",
            venv.display()
        )),
    }
}

/// The file a URDF mesh `filename` names: `package://<pkg>/<rest>` looked up in the robot-model
/// environment (`share/<pkg>` of the environment or of its cmeel prefix), `file://` or a plain
/// path (relative to `urdf_dir`). `None` when there is no such file.
pub fn resolve_mesh(filename: &str, urdf_dir: Option<&Path>) -> Option<PathBuf> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (pkg, rel) = rest.split_once('/')?;
        let venv = robot_venv()?;
        let mut roots = vec![venv.join("share").join(pkg)];
        if let Some(site) = site_packages(&venv) {
            roots.push(site.join("cmeel.prefix/share").join(pkg));
        }
        return roots.into_iter().map(|r| r.join(rel)).find(|p| p.is_file());
    }
    let path = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
    let full = match urdf_dir {
        Some(d) if path.is_relative() => d.join(path),
        _ => path.to_path_buf(),
    };
    full.is_file().then_some(full)
}
