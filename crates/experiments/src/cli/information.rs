//! `sysid information`: the information limit of a linear record ([`crate::information`]) —
//! the maximum-likelihood θ̂, its error and the Cramér–Rao s.d. of every parameter, beside the
//! answers of run records on the same data; or, with `--summary`, several limits and records
//! side by side.

use std::path::PathBuf;

use crate::error::{bail, Result};
use crate::information::{information_limit, report, table, InformationLimit, REL_STEP};
use crate::likelihood::{Candidate, DataDir};
use identify::record::RunRecord;

/// Arguments of `sysid information`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Data-set directory of a linear building (no hysteretic storeys).
    #[arg(long, required_unless_present = "limit")]
    pub data: Option<PathBuf>,
    /// Run records to put beside the limit (identified on these data).
    pub records: Vec<PathBuf>,
    /// Start Newton's ascent at this run record's θ_val (default: the data set's true θ).
    #[arg(long)]
    pub start: Option<PathBuf>,
    /// Filter settings of the model (as `sysid filter --config`). Default: the model
    /// `sysid filter --algorithm mpf-ekf2` builds for these data.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Central-difference step relative to each parameter's start value.
    #[arg(long, default_value_t = REL_STEP)]
    pub step: f64,
    /// Write the limit (JSON) here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Instead of computing a limit: put this limit file (JSON written by --out; repeat the
    /// option for several data sets) beside the run records given, matched to it by data set —
    /// a summary over the data sets, then each data set's table.
    #[arg(long, conflicts_with_all = ["data", "start", "config"])]
    pub limit: Vec<PathBuf>,
    /// Also write the table to this file.
    #[arg(long)]
    pub table: Option<PathBuf>,
}

fn read_records(paths: &[PathBuf]) -> Result<Vec<RunRecord>> {
    paths.iter().map(|p| crate::sweep::read_record(p)).collect()
}

/// Checks `--out` and `--table` before any work: each may be replaced, and neither is one of
/// the files the command reads.
fn check_outputs(args: &Args) -> Result<()> {
    let mut inputs: Vec<(&str, &std::path::Path)> = Vec::new();
    if let Some(d) = &args.data {
        inputs.push(("--data", d));
    }
    for (flag, p) in [("--start", &args.start), ("--config", &args.config)] {
        if let Some(p) = p {
            inputs.push((flag, p));
        }
    }
    inputs.extend(args.limit.iter().map(|p| ("--limit", p.as_path())));
    inputs.extend(args.records.iter().map(|p| ("a record", p.as_path())));
    for (flag, out) in [("--out", &args.out), ("--table", &args.table)] {
        if let Some(out) = out {
            identify::record::atomic::check_output(out, flag, &inputs)?;
        }
    }
    Ok(())
}

pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    check_outputs(&args)?;
    let records = read_records(&args.records)?;
    let text = if !args.limit.is_empty() {
        let limits = args
            .limit
            .iter()
            .map(|p| InformationLimit::read(p))
            .collect::<Result<Vec<_>>>()?;
        report(&limits, &records)?
    } else {
        let Some(dir) = &args.data else {
            bail!("--data: the data set to compute the limit of");
        };
        let dir = DataDir::load(dir, args.config.as_deref())?;
        let on = dir.scored();
        let start = args
            .start
            .as_ref()
            .map(|p| Candidate::from_record(p))
            .transpose()?;
        let limit = information_limit(&on, start.as_ref(), args.step, &mut |l| {
            let _ = writeln!(con.err(), "{l}");
        })?;
        if let Some(out) = &args.out {
            let json = serde_json::to_string_pretty(&limit)?;
            crate::sweep::write_bytes_atomic(out, json.as_bytes())?;
        }
        table(&limit, &records)?
    };
    // Written before it is printed: a reader of standard output that has gone ends the process
    // at the print (SIGPIPE), and the file asked for is there by then.
    if let Some(out) = &args.table {
        crate::sweep::write_bytes_atomic(out, text.as_bytes())?;
    }
    write!(con.out(), "{text}")?;
    Ok(())
}
