//! `sysid reproduce`: run every study of the paper reproduction, draw the figures, write the
//! report (what `cargo xtask reproduce-paper` runs).

use std::path::PathBuf;

use crate::reproduce::{reproduce, Options};
use crate::sweep::Shard;

/// Arguments of `sysid reproduce`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory of the study configs.
    #[arg(long, default_value = "experiments")]
    pub experiments: PathBuf,
    /// Output directory (records, figures, summary.json, REPORT.md).
    #[arg(long, default_value = "results/paper")]
    pub out: PathBuf,
    /// Few runs, fewer particles: a fast look.
    #[arg(long)]
    pub quick: bool,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Run only part i of n of every sweep (e.g. one task of a Slurm job array); merge the
    /// shards' records with `sysid merge`, then run without `--shard` and with `--resume` to
    /// draw and report.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
    /// Reuse the records of the output directory whose fingerprint (configuration, data, seed,
    /// numerics version) matches the run's; without it, every run is computed.
    #[arg(long)]
    pub resume: bool,
}

/// Runs `sysid reproduce`.
pub fn run(args: Args) -> crate::error::Result<()> {
    reproduce(&Options {
        experiments: args.experiments,
        out: args.out,
        quick: args.quick,
        threads: args.threads,
        shard: args.shard,
        progress: true,
        resume: args.resume,
    })?;
    Ok(())
}
