//! `sysid plot RUN.json --out DIR`: the SVG figures of one run, drawn from its record only.
//!
//! - `convergence.svg`: posterior mean of every parameter against time with its ±2 s.d. band
//!   (and the true value when the record knows it), from the record's trace;
//! - `ess.svg`: the effective sample size against time, from the trace;
//! - `hysteresis.svg`: the validation hysteresis loop, with the true loop when known;
//! - `accelerations.svg`, `innovations.svg`, `innovation_acf.svg`: measured against predicted
//!   accelerations, the normalised innovations and their autocorrelation with a whiteness check
//!   (Ljung–Box), when the record carries `residuals` ([`identify::checks::Residuals`]).
//!
//! A figure whose data the record lacks is skipped with a note saying what is missing.

use std::path::PathBuf;

use crate::error::Result;

use identify::plot::plot;

/// Arguments of `sysid plot`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run record written by `sysid filter` (JSON).
    pub record: PathBuf,
    /// Directory for the SVG files (created if needed).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `sysid plot`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    let p = plot(&args.record, &args.out)?;
    for note in &p.skipped {
        writeln!(con.err(), "note: {note}")?;
    }
    for f in &p.written {
        writeln!(con.out(), "{}", f.display())?;
    }
    if p.written.is_empty() {
        writeln!(
            con.err(),
            "note: nothing drawn: {} holds none of the data above",
            args.record.display()
        )?;
    }
    Ok(())
}
