//! `sysid regression`: identification-accuracy regression check.
//!
//! Runs the study of a regression file (`experiments/regression.toml`: a `[study]` table in the
//! format of the other study configs plus a `[thresholds]` table), computes the per-algorithm
//! statistics of θ_val over the runs (SPEC §7, eq. 26) and compares them with the bounds:
//!
//! - per algorithm and parameter, the mean over runs of the relative error |θ_val − θ_true|/θ_true
//!   and the run-to-run s.d. of θ_val/θ_true (the Fig. 7 cross of SPEC §8);
//! - per algorithm, the number of failed runs (SPEC §3: a failure is reported, never hidden);
//! - optionally, a degeneracy bound: the mean over runs of the number of distinct values of each
//!   sampled static parameter (SPEC §5.1: the bootstrap PF is expected to collapse);
//! - optionally, a lower bound on the pooled coverage of the 95 % credible intervals of the
//!   stiffnesses and dampings (`experiments/regression-defaults.toml`).
//!
//! Every run draws from streams seeded by (master seed, run), so on unchanged code the measured
//! values are reproduced exactly; the margins in the file allow a change that is statistically
//! equivalent (other random draws, other operation order) and flag one that is not.

use std::path::PathBuf;
use std::time::Instant;

use crate::error::Result;

use crate::regression::{format_table, RegressionFile, RegressionOptions};

/// Arguments of `sysid regression`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Regression file: a `[study]` and a `[thresholds]` table.
    #[arg(long, default_value = "experiments/regression.toml")]
    pub config: PathBuf,
    /// Output directory: `records/` (one JSON per run, resumable) and `regression.json`.
    #[arg(long, default_value = "results/regression")]
    pub out: PathBuf,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Reuse the records of an earlier check whose fingerprint (configuration, data, seed,
    /// numerics version) matches the run's, e.g. after an interruption; without it, every run is
    /// computed by the code being checked.
    #[arg(long, conflicts_with = "fresh")]
    pub resume: bool,
    /// Delete the records directory of an earlier check first (every run is computed anyway
    /// without `--resume`; this also removes records of runs no longer in the study).
    #[arg(long)]
    pub fresh: bool,
}

/// Runs `sysid regression`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    let start = Instant::now();
    let config = crate::project::locate(&args.config, "regression file")?;
    let file = RegressionFile::load(&config)?;
    let options = RegressionOptions {
        out: &args.out,
        threads: args.threads,
        resume: args.resume,
        fresh: args.fresh,
    };
    let outcome = crate::regression::run(&file, &options)?;
    let wall_s = start.elapsed().as_secs_f64();
    write!(con.out(), "{}", format_table(&outcome.checks))?;
    writeln!(
        con.out(),
        "{} runs of {} ({} executed, {} reused) in {wall_s:.1} s ({})",
        outcome.records.len(),
        file.study.name,
        outcome.executed,
        outcome.reused,
        args.config.display()
    )?;
    outcome.write_summary(&args.out.join("regression.json"), &args.config, wall_s)?;
    outcome.verdict()?;
    writeln!(
        con.out(),
        "all {} regression bounds met",
        outcome.checks.len()
    )?;
    Ok(())
}
