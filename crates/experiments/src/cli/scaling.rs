//! `sysid scaling`: run the scaling study (`experiments/scaling.toml`), draw its figures and
//! write its report (what `cargo xtask reproduce-scaling` runs).

use std::path::PathBuf;

use crate::scaling::{run as run_study, Options};
use crate::sweep::Shard;

/// Arguments of `sysid scaling`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The study file.
    #[arg(long, default_value = "experiments/scaling.toml")]
    pub config: PathBuf,
    /// Output directory (records, cells.csv, figures, summary.json, REPORT.md).
    #[arg(long, default_value = "results/scaling")]
    pub out: PathBuf,
    /// The study's `[quick]` form: fewer runs and particles, a shorter record.
    #[arg(long)]
    pub quick: bool,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Run only part i of n of the sweep; merge the shards' records with `sysid merge`, then
    /// run without `--shard` and with `--resume` to write the report.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
    /// Reuse the records of the output directory whose fingerprint matches the run's; without
    /// it, every run is computed.
    #[arg(long)]
    pub resume: bool,
    /// Compute nothing: write the report from the records already in the output directory
    /// whose fingerprint matches (e.g. after stopping a sweep that does not fit the time).
    #[arg(long, conflicts_with_all = ["resume", "shard"])]
    pub report_only: bool,
}

/// Runs `sysid scaling`.
pub fn run(args: Args) -> anyhow::Result<()> {
    run_study(&Options {
        config: args.config,
        out: args.out,
        quick: args.quick,
        threads: args.threads,
        shard: args.shard,
        progress: true,
        resume: args.resume,
        report_only: args.report_only,
    })?;
    Ok(())
}
