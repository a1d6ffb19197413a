//! Subcommands of `sysid`, one module each. Each module exposes `Args` (clap) and `run`.

pub mod cluster;
pub mod field_study;
pub mod filter;
pub mod import;
pub mod information;
pub mod loglik;
pub mod merge;
pub mod plot;
pub mod reference;
pub mod regression;
pub mod reproduce;
pub mod scaling;
pub mod simulate;
pub mod study;
pub mod table1;
pub mod validate;

use crate::engine::RunMode;
use crate::sweep::Shard;

/// How a study command runs: the options `sysid reproduce`, `scaling`, `excitations` and
/// `study` share ([`RunMode`]).
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The study's `[quick]` form: fewer runs and particles, a shorter record.
    #[arg(long)]
    pub quick: bool,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Run only part i of n of every sweep (e.g. one task of a Slurm job array, see `sysid
    /// cluster`); merge the shards' records with `sysid merge`, then run the same command
    /// without `--shard` and with `--resume` to write the report.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
    /// Reuse the records of the output directory whose fingerprint (configuration, data, seed,
    /// numerics version) matches the run's; without it, every run is computed.
    #[arg(long)]
    pub resume: bool,
}

impl RunArgs {
    /// The run mode, with progress on stderr.
    pub fn mode(&self) -> RunMode {
        RunMode {
            quick: self.quick,
            threads: self.threads,
            shard: self.shard,
            progress: true,
            resume: self.resume,
        }
    }
}
