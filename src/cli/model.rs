//! `upc model`: inspect a URDF.

#[derive(clap::Args)]
pub struct ModelArgs {
    /// URDF file.
    pub urdf: std::path::PathBuf,
}

pub fn run(_args: ModelArgs) -> super::CliResult {
    Err("upc model: not built yet".into())
}
