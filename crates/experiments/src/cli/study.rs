//! `sysid study`: run a study file (`experiments/*.toml` format) — typically one whose `[data]`
//! names a data directory (`dir = "..."`) — and write its records, `summary.json` and
//! `REPORT.md` (per algorithm and parameter: θ_val mean over runs, run-to-run spread, posterior
//! s.d.).

use std::path::PathBuf;

use crate::error::Result;

/// Arguments of `sysid study`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The study file.
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (records/, summary.json, REPORT.md).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub run: super::RunArgs,
}

/// Runs `sysid study`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    let report = crate::user_study::run(&crate::user_study::Options {
        config: crate::project::locate(&args.config, "study")?,
        out: args.out,
        mode: args.run.mode(),
    })?;
    if let Some(report) = report {
        write!(con.out(), "{report}")?;
    }
    Ok(())
}
