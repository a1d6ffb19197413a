//! `sysid validate --record RUN.json --data OTHER [--out validation.json]`: cross-validation —
//! the model identified on one record predicts another record of the same building from its
//! ground motion alone (free run, fit and NRMSE per channel, a band from the first record's
//! posterior shifted by the spread between its parts), and its modes are set beside the other record's transfer-function peaks
//! (docs/validation.md).

use std::path::PathBuf;

use crate::console::Console;
use crate::error::Result;

use identify::validation::cross::cross_validate;
use identify::validation::{self, BAND_DRAWS};

/// Arguments of `sysid validate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run record of the identification (written by `sysid filter`).
    #[arg(long)]
    pub record: PathBuf,
    /// Another record of the same building (a data-set directory with `measured.csv`).
    #[arg(long)]
    pub data: PathBuf,
    /// Where to write the result (JSON).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also draw `free_run.svg`, `transfer.svg` and, where mode shapes were compared (two
    /// measured floors or more), `shapes.svg` into this directory.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Posterior draws for the band (0: no band).
    #[arg(long, default_value_t = BAND_DRAWS)]
    pub draws: usize,
}

/// Runs `sysid validate`, its text to `con`.
pub fn run(args: Args, con: &mut Console) -> Result<()> {
    // Checked before the work, not only when written: a refused --out costs no run.
    if let Some(out) = &args.out {
        identify::record::atomic::check_output(
            out,
            "--out",
            &[("--record", &args.record), ("--data", &args.data)],
        )?;
    }
    // The record goes through the one reader of records first, with every check `plot` and
    // `merge` make: a regular file within the size limit (a named pipe or `/dev/zero` is
    // refused before a byte is read), complete, its fingerprint and the digest of its `config`
    // verified (an edited sensor kind would model another building).
    let _: identify::record::RunRecord = identify::record::read::read(&args.record)?;
    let mut notes = Vec::new();
    let validated = cross_validate(&args.record, &args.data, args.draws, &mut |n| {
        notes.push(n.to_string())
    });
    // Said before an error too: a note may tell why the validation failed.
    for n in notes {
        writeln!(con.err(), "note: {n}")?;
    }
    let validated = validated?;
    let (record, result) = (&validated.record, &validated.result);
    // The files first, the summary after: a reader of standard output that has gone (`| head`)
    // ends the process at its next print, and must not cost the files asked for.
    if let Some(out) = &args.out {
        crate::sweep::write_atomic(out, result)?;
        writeln!(con.err(), "result written to {}", out.display())?;
    }
    let mut drawn = identify::plot::Plotted::default();
    if let Some(dir) = &args.plot {
        let who = format!("{} on {}", record.algorithm, args.data.display());
        // Each figure put in place whole (drawn aside, checked, renamed), as `sysid plot` does.
        drawn = identify::plot::draw_in_place(dir, |staging| {
            let mut p = identify::plot::Plotted::default();
            validation::figures::draw(
                Some(&result.free_run),
                Some(&result.modal),
                staging,
                &who,
                &mut p.written,
                &mut p.skipped,
            )?;
            Ok(p)
        })?;
    }
    writeln!(
        con.out(),
        "cross-validation: {} ({}, seed {}) identified on {}, predicting {}",
        record.algorithm,
        record.experiment,
        record.seed,
        args.record.display(),
        args.data.display()
    )?;
    write!(
        con.out(),
        "{}",
        validation::summary(Some(&result.free_run), Some(&result.modal))
    )?;
    for s in drawn.skipped {
        writeln!(con.err(), "note: {s}")?;
    }
    for w in drawn.written {
        writeln!(con.out(), "{}", w.display())?;
    }
    Ok(())
}
