//! Links MuJoCo's C library for the MuJoCo physics backend of the plant (`upc sim --plant
//! mujoco`, src/sim/mujoco/): the library and headers the `mujoco` wheel carries, which
//! `scripts/setup.sh` installs in `.venv` (or a directory given as `UPC_MUJOCO_DIR`, holding
//! `libmujoco.so.*` and `include/mujoco/`). A small C shim (src/sim/mujoco/shim.c) gives Rust
//! the few fields of `mjModel` / `mjData` the plant reads. Without MuJoCo, upc builds without
//! that backend and `--plant mujoco` says how to get it.

use std::path::{Path, PathBuf};

fn mujoco_dir(root: &Path) -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("UPC_MUJOCO_DIR") {
        return Some(PathBuf::from(d));
    }
    let lib = root.join(".venv/lib");
    let mut found = None;
    for e in std::fs::read_dir(lib).ok()?.flatten() {
        let d = e.path().join("site-packages/mujoco");
        if d.join("include/mujoco/mujoco.h").is_file() {
            found = Some(d);
        }
    }
    found
}

fn library(dir: &Path) -> Option<String> {
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.starts_with("libmujoco.so"))
        .max()
}

fn main() {
    println!("cargo::rustc-check-cfg=cfg(upc_mujoco)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed=src/sim/mujoco/shim.c");
    println!("cargo::rerun-if-env-changed=UPC_MUJOCO_DIR");
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    // Where MuJoCo appears (or changes version) once scripts/setup.sh has run: `.venv/lib` if
    // it exists, else `.venv` (missing: the script runs again on each build until it appears).
    let venv_lib = root.join(".venv/lib");
    let watch = if venv_lib.is_dir() {
        venv_lib
    } else {
        root.join(".venv")
    };
    println!("cargo::rerun-if-changed={}", watch.display());
    let Some(dir) = mujoco_dir(&root) else {
        println!(
            "cargo::warning=MuJoCo not found (.venv of scripts/setup.sh, or UPC_MUJOCO_DIR): \
             building without the MuJoCo plant"
        );
        return;
    };
    let Some(lib) = library(&dir) else {
        println!(
            "cargo::warning=no libmujoco.so* in {}: building without the MuJoCo plant",
            dir.display()
        );
        return;
    };
    println!("cargo::rerun-if-changed={}", dir.join(&lib).display());
    cc::Build::new()
        .file("src/sim/mujoco/shim.c")
        .include(dir.join("include"))
        .flag_if_supported("-std=c11")
        .warnings(true)
        .compile("upc_mujoco_shim");
    println!("cargo::rustc-link-search=native={}", dir.display());
    println!("cargo::rustc-link-lib=dylib:+verbatim={lib}");
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.display());
    println!("cargo::rustc-cfg=upc_mujoco");
    println!(
        "cargo::rustc-env=UPC_MUJOCO_LIBRARY={}",
        dir.join(&lib).display()
    );
}
