//! `sysid field-study`: a study of one real structure from its recordings
//! (`experiments/real/study.toml`; [`crate::field_study`]).

use std::path::PathBuf;

use crate::console::Console;
use crate::error::Result;

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
    /// instead of recomputing them — each only where this build computed it from the inputs it
    /// has now (the digest of the program, the command and the files it reads, kept beside its
    /// log); the others, and everything computed from them, are computed again.
    #[arg(long)]
    pub resume: bool,
}

/// Runs `sysid field-study`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
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
        writeln!(con.err(), "report {}", path.display())?;
        return Ok(());
    }
    run_study(
        &study,
        &RunOptions {
            run_step,
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

/// The subcommands a study's step runs, parsed as `sysid` parses them.
#[derive(clap::Parser)]
#[command(no_binary_name = true, allow_negative_numbers = true)]
enum Step {
    Import(super::import::Args),
    Filter(Box<super::filter::Args>),
    Validate(super::validate::Args),
}

/// Runs one step of a study in this process (`crate::field_study::StepRunner`): `args` are what
/// a user types after `sysid`, parsed and run by the same code as `sysid`'s.
pub(crate) fn run_step(args: &[String], con: &mut Console) -> Result<()> {
    let step = <Step as clap::Parser>::try_parse_from(args)
        .map_err(|e| crate::error::invalid!("`sysid {}`: {e}", args.join(" ")))?;
    match step {
        Step::Import(a) => super::import::run(a, con),
        Step::Filter(a) => super::filter::run(*a, con),
        Step::Validate(a) => super::validate::run(a, con),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log() -> Console {
        Console::log_file(tempfile::tempfile().unwrap()).unwrap()
    }

    #[test]
    fn a_step_is_parsed_as_sysid_parses_it() {
        // An unknown flag or subcommand is refused with clap's message before anything runs.
        let e = run_step(&["filter".into(), "--no-such-flag".into()], &mut log()).unwrap_err();
        assert!(format!("{e}").contains("--no-such-flag"), "{e}");
        let e = run_step(&["simulate".into()], &mut log()).unwrap_err();
        assert!(format!("{e}").contains("simulate"), "{e}");
        // A real command runs: `filter --print-config` writes the commented defaults.
        let file = tempfile::NamedTempFile::new().unwrap();
        let mut con = Console::log_file(file.reopen().unwrap()).unwrap();
        run_step(&["filter".into(), "--print-config".into()], &mut con).unwrap();
        drop(con);
        let text = std::fs::read_to_string(file.path()).unwrap();
        assert!(text.contains("particles"), "{text}");
    }
}
