//! `sysid reproduce`: run every study of the paper reproduction, draw the figures, write the
//! report (what `cargo xtask reproduce-paper` runs).

use std::path::PathBuf;

use crate::reproduce::{reproduce, Options};

/// Arguments of `sysid reproduce`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory of the study configs.
    #[arg(long, default_value = "experiments")]
    pub experiments: PathBuf,
    /// Output directory (records, figures, summary.json, REPORT.md).
    #[arg(long, default_value = "results/paper")]
    pub out: PathBuf,
    #[command(flatten)]
    pub run: super::RunArgs,
}

/// Runs `sysid reproduce`.
pub fn run(args: Args) -> crate::error::Result<()> {
    reproduce(&Options {
        experiments: crate::project::locate(&args.experiments, "study directory")?,
        out: args.out,
        mode: args.run.mode(),
    })?;
    Ok(())
}
