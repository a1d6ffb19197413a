//! `sysid study`: run a study file (`experiments/*.toml` format) — typically one whose `[data]`
//! names a data directory (`dir = "..."`) — and write its records, `summary.json` and
//! `REPORT.md` (per algorithm and parameter: θ_val mean over runs, run-to-run spread, posterior
//! s.d.).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};

use crate::study::Study;
use crate::sweep::lock::DirLock;
use crate::sweep::{run_sweep, write_bytes_atomic, Shard, SweepOptions};

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

pub fn run(args: Args) -> Result<()> {
    let start = Instant::now();
    let mut study = Study::load(&args.config)?;
    if args.quick {
        study = study.quick();
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let _lock = DirLock::acquire(&args.out)?;
    let sweep = SweepOptions {
        threads: args.threads,
        shard: args.shard,
        progress: true,
        label: study.name.clone(),
        resume: args.resume,
    };
    let outcome = run_sweep(
        &study.jobs(),
        |job| study.record_id(job),
        |job| study.job_fingerprint(job),
        &args.out.join("records"),
        &sweep,
        |job| study.run_job(job),
    )?;
    if args.shard != Shard::default() {
        eprintln!(
            "shard {}/{}: {}; merge the shards' records (`sysid merge`) and run `sysid study \
             --resume` to write the report",
            args.shard.index,
            args.shard.count,
            outcome.summary()
        );
        return Ok(());
    }
    let spreads = crate::user_study::spreads(&outcome.records);
    let data = match &study.data.dir {
        Some(d) => d.display().to_string(),
        None => format!("preset {} (one data set per run)", study.data.preset),
    };
    write_bytes_atomic(
        &args.out.join("summary.json"),
        (serde_json::to_string_pretty(&serde_json::json!({
            "study": study.name,
            "data": data,
            "runs": { "executed": outcome.executed, "reused": outcome.reused, "failed": outcome.failed },
            "wall_s": start.elapsed().as_secs_f64(),
            "algorithms": spreads,
        }))? + "\n")
            .as_bytes(),
    )?;
    crate::user_study::figures(&spreads, &args.out)?;
    let report = crate::user_study::markdown(&study.name, &study.description, &data, &spreads);
    write_bytes_atomic(&args.out.join("REPORT.md"), report.as_bytes())?;
    print!("{report}");
    eprintln!(
        "study {}: {} runs ({} executed, {} reused, {} failed) in {:.1} s; wrote {}",
        study.name,
        outcome.records.len(),
        outcome.executed,
        outcome.reused,
        outcome.failed,
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}
