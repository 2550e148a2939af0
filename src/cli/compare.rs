//! `upc compare`: report.md with figures and metrics tables for run directories of `upc run`,
//! and the same controllers on the reduced models.

use std::path::PathBuf;

use upc::report::{CompareOptions, ConfigLayers};

use super::CliResult;
use super::common::ConfigArgs;

#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Run directories written by `upc run` (e.g. runs/multiple_impacts-…).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Output directory for report.md and figures/ (default: the run directory for one run,
    /// <parent>/compare for several).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Leave out the reduced-model section.
    #[arg(long)]
    pub no_reduced: bool,
    /// SVG figures only.
    #[arg(long)]
    pub no_png: bool,
    /// Overlay every run's controllers in one section besides each run's own (conditions of
    /// one experiment; runs on different plants are overlaid anyway).
    #[arg(long)]
    pub overlay: bool,
    /// Config layered over each run's own for the reduced models (files, then --set).
    #[command(flatten)]
    pub config: ConfigArgs,
}

pub fn run(args: CompareArgs) -> CliResult {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| upc::report::default_out(&args.runs));
    let written = compare(
        &args.runs,
        out,
        &args.config,
        !args.no_reduced,
        !args.no_png,
        args.overlay,
    )?;
    println!("wrote {}", written.display());
    Ok(())
}

/// Write the report; returns the path of report.md. Used by `upc run` on its own directory.
pub fn compare(
    runs: &[PathBuf],
    out: PathBuf,
    config: &ConfigArgs,
    reduced: bool,
    png: bool,
    overlay: bool,
) -> Result<PathBuf, upc::report::ReportError> {
    let opts = CompareOptions {
        out,
        config: ConfigLayers {
            files: config.configs.clone(),
            sets: config.sets.clone(),
        },
        reduced,
        png,
        overlay,
    };
    Ok(upc::report::compare(runs, &opts)?.report)
}
