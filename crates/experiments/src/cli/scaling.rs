//! `sysid scaling` and `sysid excitations`: run a study with a structure axis (the scaling
//! study `experiments/scaling.toml`, the excitations study `experiments/excitations.toml`),
//! draw its figures and write its report (what `cargo xtask reproduce-scaling` and
//! `reproduce-excitations` run).

use std::path::PathBuf;

use crate::scaling::{run as run_study, Options};

/// Arguments of `sysid scaling` and `sysid excitations`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The study file [default: experiments/scaling.toml, or experiments/excitations.toml].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory (records, cells.csv, figures, summary.json, REPORT.md) [default:
    /// results/scaling, or results/excitations].
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub run: super::RunArgs,
    /// Compute nothing: write the report from the records already in the output directory
    /// whose fingerprint matches (e.g. after stopping a sweep that does not fit the time).
    #[arg(long, conflicts_with_all = ["resume", "shard"])]
    pub report_only: bool,
}

impl Args {
    fn options(self, study: &str) -> crate::error::Result<Options> {
        let config = self
            .config
            .unwrap_or_else(|| PathBuf::from(format!("experiments/{study}.toml")));
        Ok(Options {
            config: crate::project::locate(&config, "study")?,
            out: self
                .out
                .unwrap_or_else(|| PathBuf::from(format!("results/{study}"))),
            mode: self.run.mode(),
            report_only: self.report_only,
        })
    }
}

/// Runs `sysid scaling`.
pub fn run(args: Args) -> crate::error::Result<()> {
    run_study(&args.options("scaling")?)?;
    Ok(())
}

/// Runs `sysid excitations`.
pub fn run_excitations(args: Args) -> crate::error::Result<()> {
    crate::excitations::run(&args.options("excitations")?)?;
    Ok(())
}
