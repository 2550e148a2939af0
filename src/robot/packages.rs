//! Where the registry packages with robot models are: `scripts/setup.sh` installs
//! `example-robot-data` and `icub-models` (PyPI) into a virtual environment outside the clone,
//! `$UPC_ROBOT_VENV` or `~/.cache/upc/robot-venv`.

use std::path::{Path, PathBuf};

/// The registry packages a robot description may name, and the directory under a `share`
/// prefix of the environment where each puts its files (what their URDFs call `package://…`).
const PACKAGES: [(&str, &str); 2] = [
    ("example-robot-data", "example-robot-data"),
    ("icub-models", "iCub"),
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

/// The `share` directories of the environment: its own, and that of its cmeel prefix (where
/// `example-robot-data` installs).
fn share_dirs(venv: &Path) -> Vec<PathBuf> {
    let mut dirs = vec![venv.join("share")];
    if let Some(site) = site_packages(venv) {
        dirs.push(site.join("cmeel.prefix/share"));
    }
    dirs
}

/// The directory `share/<name>` of the environment, if it exists.
fn shared(name: &str) -> Option<PathBuf> {
    let venv = robot_venv()?;
    share_dirs(&venv)
        .into_iter()
        .map(|d| d.join(name))
        .find(|p| p.is_dir())
}

/// The root directory of `package`'s files, or why there is none.
pub fn package_root(package: &str) -> Result<PathBuf, String> {
    let Some((_, dir)) = PACKAGES.iter().find(|(p, _)| *p == package) else {
        let known: Vec<&str> = PACKAGES.iter().map(|(p, _)| *p).collect();
        return Err(format!(
            "unknown robot package `{package}` (known: {})",
            known.join(", ")
        ));
    };
    shared(dir).ok_or_else(|| {
        format!(
            "the package `{package}` is not installed in {} (scripts/setup.sh installs it; \
             UPC_ROBOT_VENV points elsewhere)",
            robot_venv().map_or("<no HOME>".into(), |v| v.display().to_string())
        )
    })
}

/// Where `package://<pkg>/…` is looked up, in order: each directory of `ROS_PACKAGE_PATH` (ROS
/// 1: a package is a directory of its name there), `share/` of each prefix of
/// `AMENT_PREFIX_PATH` (ROS 2), then the `share` directories of the robot-model environment
/// (`UPC_ROBOT_VENV`, else `~/.cache/upc/robot-venv`).
pub fn package_search_dirs() -> Vec<PathBuf> {
    search_dirs(
        std::env::var_os("ROS_PACKAGE_PATH").as_deref(),
        std::env::var_os("AMENT_PREFIX_PATH").as_deref(),
        robot_venv().as_deref(),
    )
}

/// [`package_search_dirs`] from the variables' values and the environment's directory.
pub fn search_dirs(
    ros_package_path: Option<&std::ffi::OsStr>,
    ament_prefix_path: Option<&std::ffi::OsStr>,
    venv: Option<&Path>,
) -> Vec<PathBuf> {
    let split = |v: Option<&std::ffi::OsStr>| -> Vec<PathBuf> {
        v.map(|v| {
            std::env::split_paths(v)
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        })
        .unwrap_or_default()
    };
    let mut dirs = split(ros_package_path);
    dirs.extend(
        split(ament_prefix_path)
            .into_iter()
            .map(|p| p.join("share")),
    );
    if let Some(v) = venv {
        dirs.extend(share_dirs(v));
    }
    dirs
}

/// The file a URDF mesh `filename` names: `package://<pkg>/<rest>` looked up in
/// [`package_search_dirs`], `file://` or a plain path (relative to `urdf_dir`). `None` when
/// there is no such file.
pub fn resolve_mesh(filename: &str, urdf_dir: Option<&Path>) -> Option<PathBuf> {
    resolve_mesh_in(filename, urdf_dir, &package_search_dirs())
}

/// [`resolve_mesh`] with `package://` looked up in `dirs` (`<dir>/<pkg>/<rest>`, the first that
/// is a file).
pub fn resolve_mesh_in(
    filename: &str,
    urdf_dir: Option<&Path>,
    dirs: &[PathBuf],
) -> Option<PathBuf> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (pkg, rel) = rest.split_once('/')?;
        return dirs
            .iter()
            .map(|d| d.join(pkg).join(rel))
            .find(|p| p.is_file());
    }
    let path = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
    let full = match urdf_dir {
        Some(d) if path.is_relative() => d.join(path),
        _ => path.to_path_buf(),
    };
    full.is_file().then_some(full)
}
