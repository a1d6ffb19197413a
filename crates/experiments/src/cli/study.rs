//! `sysid study`: run a study file (`experiments/*.toml` format) — typically one whose `[data]`
//! names a data directory (`dir = "..."`) — and write its records, `summary.json` and
//! `REPORT.md` (per algorithm and parameter: θ_val mean over runs, run-to-run spread, posterior
//! s.d.).

use std::path::PathBuf;

use crate::error::Result;

use crate::sweep::Shard;

/// Arguments of `sysid study`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The study file.
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (records/, summary.json, REPORT.md).
    #[arg(long)]
    pub out: PathBuf,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Reuse the records whose fingerprint matches instead of recomputing them.
    #[arg(long)]
    pub resume: bool,
    /// The study's `[quick]` form.
    #[arg(long)]
    pub quick: bool,
    /// Run only part i of n of the sweep (e.g. one task of a Slurm job array, see `sysid
    /// cluster`); merge the shards' records with `sysid merge`, then run without `--shard` and
    /// with `--resume` to write the report.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
}

/// Runs `sysid study`.
pub fn run(args: Args) -> Result<()> {
    crate::user_study::run(&crate::user_study::Options {
        config: args.config,
        out: args.out,
        threads: args.threads,
        resume: args.resume,
        quick: args.quick,
        shard: args.shard,
    })
}
