//! `sysid merge`: gather the record directories of several shards into one.
//!
//! Every source record is parsed and checked (fingerprint included) before anything is written;
//! a corrupt one is reported by name and the merge exits non-zero without writing. Each record is
//! then written atomically, so the merge can be interrupted and run again. The destination is
//! locked against other writers (`reproduce`, `merge`, `regression`) for the duration.

use std::path::PathBuf;

use crate::error::Result;

use crate::sweep::lock::DirLock;
use crate::sweep::{merge, study_pairs};
use identify::record::RunRecord;

/// Arguments of `sysid merge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directories of the shards (each holding `records/<study>/`, or its records in
    /// `records/` for `scaling`, `excitations` and `study`).
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Directory to merge into (its `records/<study>/` receive the records).
    #[arg(long)]
    pub into: PathBuf,
}

/// Runs `sysid merge`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    let _lock = DirLock::acquire(&args.into)?;
    let pairs = study_pairs(&args.parts, &args.into)?;
    let report = merge::<RunRecord>(&pairs)?;
    for (path, why) in &report.replaced {
        writeln!(con.err(), "replaced {}: {why}", path.display())?;
    }
    if report.cleaned > 0 {
        writeln!(
            con.err(),
            "removed {} temporary file(s) left by interrupted writers",
            report.cleaned
        )?;
    }
    writeln!(
        con.err(),
        "merged into {}: {} copied, {} replaced, {} already present",
        args.into.display(),
        report.copied,
        report.replaced.len(),
        report.present
    )?;
    Ok(())
}
