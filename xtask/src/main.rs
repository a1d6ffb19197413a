//! `cargo xtask <task>`: project tasks written as plain Rust (the cargo-xtask pattern).
//!
//! - `reproduce-paper [--quick] [--threads N] [--shard i/n]`: builds `sysid` in release and runs
//!   `sysid reproduce` from the workspace root into `results/paper/` (or `results/paper-quick/`).
//! - `bench`: runs the criterion benchmarks of `core-filters` in release.

use std::path::PathBuf;
use std::process::Command;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "xtask", about = "Project tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Reproduce the paper: every study, figure, summary.json and REPORT.md under results/paper.
    ReproducePaper {
        /// Few runs, fewer particles (writes results/paper-quick).
        #[arg(long)]
        quick: bool,
        /// Worker threads (0: one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Run part i of n of every sweep (then `sysid merge` and run again without it).
        #[arg(long)]
        shard: Option<String>,
    },
    /// Run the criterion benchmarks (release).
    Bench,
}

/// The workspace root (the parent of this crate's directory).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives inside the workspace")
        .to_path_buf()
}

fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn run(cmd: &mut Command) -> Result<()> {
    let status = cmd.status().with_context(|| format!("starting {cmd:?}"))?;
    if !status.success() {
        bail!("{cmd:?} failed with {status}");
    }
    Ok(())
}

fn main() -> Result<()> {
    let root = root();
    match Cli::parse().task {
        Task::ReproducePaper {
            quick,
            threads,
            shard,
        } => {
            run(Command::new(cargo()).current_dir(&root).args([
                "build",
                "--release",
                "--quiet",
                "-p",
                "experiments",
                "--bin",
                "sysid",
            ]))?;
            let out = if quick {
                "results/paper-quick"
            } else {
                "results/paper"
            };
            let target = std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| root.join("target"));
            let mut cmd = Command::new(target.join("release/sysid"));
            cmd.current_dir(&root).args([
                "reproduce",
                "--experiments",
                "experiments",
                "--out",
                out,
                "--threads",
                &threads.to_string(),
            ]);
            if quick {
                cmd.arg("--quick");
            }
            if let Some(s) = shard {
                cmd.args(["--shard", &s]);
            }
            run(&mut cmd)
        }
        Task::Bench => {
            run(Command::new(cargo())
                .current_dir(&root)
                .args(["bench", "-p", "core-filters"]))
        }
    }
}
