//! `sysid merge`: gather the record directories of several shards into one.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::sweep::merge;

/// Arguments of `sysid merge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directories of the shards (each holding `records/<study>/`).
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Directory to merge into (its `records/<study>/` receive the records).
    #[arg(long)]
    pub into: PathBuf,
}

/// Runs `sysid merge`.
pub fn run(args: Args) -> Result<()> {
    let mut total = 0;
    for part in &args.parts {
        let records = part.join("records");
        let studies = std::fs::read_dir(&records)
            .with_context(|| format!("reading {}", records.display()))?;
        for entry in studies {
            let dir = entry?.path();
            if dir.is_dir() {
                let name = dir.file_name().expect("directory name").to_owned();
                total += merge(
                    std::slice::from_ref(&dir),
                    &args.into.join("records").join(name),
                )?;
            }
        }
    }
    eprintln!("merged {total} records into {}", args.into.display());
    Ok(())
}
