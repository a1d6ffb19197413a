//! `cargo xtask fuzz`: the fuzz driver of `experiments::fuzz` on the release `sysid` (and the
//! Python package with `--python`), with its table printed and, on a failure, the directory of
//! the reproducers named and a non-zero exit.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Result};
use experiments::fuzz::{self, Options};

/// Options of `cargo xtask fuzz`.
#[derive(Debug, clap::Args)]
pub struct FuzzArgs {
    /// Master seed: the same seed makes the same probes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Probes in all, spread evenly over the targets.
    #[arg(long, default_value_t = 2200)]
    probes: usize,
    /// Time limit of one probe, in seconds (a probe still running then is a hang).
    #[arg(long, default_value_t = 30.0)]
    timeout: f64,
    /// A Python interpreter with the package `sysid_mpf` installed (e.g.
    /// target/python-ci/bin/python): its API is probed too.
    #[arg(long)]
    python: Option<PathBuf>,
    /// Probes run at once (0: one per core).
    #[arg(long, default_value_t = 0)]
    jobs: usize,
    /// Only the targets whose name starts with this (repeatable): e.g. `filter`, `cluster`,
    /// `py` for the Python ones.
    #[arg(long)]
    only: Vec<String>,
    /// Print the probes the seed makes (target, hostile change, command line); run nothing.
    #[arg(long)]
    list: bool,
}

/// Runs the driver from the workspace `root` with the `sysid` at `sysid`.
pub fn run(
    root: &std::path::Path,
    target: &std::path::Path,
    sysid: PathBuf,
    a: FuzzArgs,
) -> Result<()> {
    if !(a.timeout > 0.0 && a.timeout.is_finite()) {
        bail!("--timeout: a positive number of seconds, not {}", a.timeout);
    }
    let jobs = match a.jobs {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        j => j,
    };
    // Every probe runs in a directory of its own: a relative interpreter path (CI passes
    // `target/python-ci/bin/python`) is made absolute from where the command was started.
    let python = match a.python {
        Some(p) if p.is_relative() => Some(std::env::current_dir()?.join(p)),
        p => p,
    };
    let opts = Options {
        sysid,
        python,
        repository: root.to_path_buf(),
        scratch: target.join("fuzz/scratch"),
        failures: target.join(format!("fuzz/failures-seed{}", a.seed)),
        seed: a.seed,
        probes: a.probes,
        timeout: Duration::from_secs_f64(a.timeout),
        jobs,
        only: a.only,
        unguarded: vec![target.to_path_buf()],
    };
    if a.list {
        for line in fuzz::plan(&opts)? {
            println!("{line}");
        }
        return Ok(());
    }
    let report = fuzz::run(&opts)?;
    print!("{}", report.table());
    if !report.passed() {
        bail!(
            "{} of {} probes failed; reproducers in {}",
            report.failures.len(),
            a.probes,
            opts.failures.display()
        );
    }
    Ok(())
}
