//! `upc preview`: the reduced-model closed loop.

#[derive(clap::Args)]
pub struct PreviewArgs {}

pub fn run(_args: PreviewArgs) -> super::CliResult {
    Err("upc preview: not built yet".into())
}
