//! `sysid field-study`: a study of one real structure from its recordings
//! (`experiments/real/study.toml`; [`crate::field_study`]).

use std::path::PathBuf;

use crate::error::{Context, Result};

use crate::field_study::{run as run_study, FieldStudy, RunOptions};

/// Arguments of `sysid field-study`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The study file (e.g. experiments/real/study.toml).
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (one directory per part, REPORT.md).
    #[arg(long)]
    pub out: PathBuf,
    /// A Python interpreter with the package `mdof` to recompute the baseline (SRIM); without
    /// it the study's committed baseline file is used and the report says so.
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// The baseline script.
    #[arg(long, default_value = "experiments/real/srim.py")]
    pub baseline_script: PathBuf,
    /// Compute nothing: write REPORT.md from the records already there.
    #[arg(long)]
    pub report_only: bool,
    /// Keep the records, imports and validations already written (an interrupted study)
    /// instead of recomputing them.
    #[arg(long)]
    pub resume: bool,
}

/// Runs `sysid field-study`.
pub fn run(args: Args) -> Result<()> {
    let config = crate::project::locate(&args.config, "field study")?;
    let study = FieldStudy::load(&config)?;
    if args.report_only {
        // The report is drawn from a study's output; without one there is nothing to report
        // (and no directory to write REPORT.md into).
        if !args.out.is_dir() {
            crate::error::bail!(
                "--out {}: no such directory: --report-only writes REPORT.md from the records of \
                 a study run into it (run the study first, without --report-only)",
                args.out.display()
            );
        }
        let text = crate::field_study::report::render(&study, &args.out)?;
        let path = args.out.join("REPORT.md");
        identify::record::atomic::write_bytes_atomic(&path, text.as_bytes())?;
        eprintln!("report {}", path.display());
        return Ok(());
    }
    let sysid = std::env::current_exe().context("locating the sysid binary")?;
    run_study(
        &study,
        &RunOptions {
            sysid,
            out: args.out,
            python: args.python,
            baseline_script: Some(
                crate::project::locate(&args.baseline_script, "baseline script")
                    .unwrap_or(args.baseline_script),
            ),
            resume: args.resume,
        },
    )
}
