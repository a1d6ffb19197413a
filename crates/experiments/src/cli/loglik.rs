//! `sysid loglik`: which answers a record supports — the log-likelihood of a data set at the
//! θ_val of run records (and its true θ), and whether each lies outside the record's 95 %
//! likelihood region ([`crate::likelihood`]).

use std::path::PathBuf;

use crate::error::Result;
use crate::likelihood::{score, table, Candidate, LikelihoodRequest, MAX_SEEDS};

/// Arguments of `sysid loglik`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Data-set directory the answers were identified on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run records whose θ_val to score (any algorithms, settings or seeds on these data).
    pub records: Vec<PathBuf>,
    /// Also score the data set's true θ (simulated data with dataset.json).
    #[arg(long)]
    pub truth: bool,
    /// Filter settings of the model (as `sysid filter --config`; field data: its `[structure]`
    /// table). Default: the model `sysid filter --algorithm mpf-ekf2` builds for these data.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Particles of the one filter of each estimate.
    #[arg(long, default_value_t = 250)]
    pub particles: usize,
    /// Independent estimates per answer (their spread gives the standard error); 1 to 10000.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=MAX_SEEDS))]
    pub seeds: u64,
    /// Also write the table to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    // Checked before the scoring, not only when written: a refused --out costs no filter run.
    if let Some(out) = &args.out {
        let mut inputs: Vec<(&str, &std::path::Path)> = vec![("--data", &args.data)];
        if let Some(c) = &args.config {
            inputs.push(("--config", c));
        }
        inputs.extend(args.records.iter().map(|r| ("a record", r.as_path())));
        identify::record::atomic::check_output(out, "--out", &inputs)?;
    }
    let candidates = args
        .records
        .iter()
        .map(|p| Candidate::from_record(p))
        .collect::<Result<Vec<_>>>()?;
    let req = LikelihoodRequest {
        data: args.data,
        config: args.config,
        particles: args.particles,
        seeds: args.seeds,
        truth: args.truth,
    };
    let c = score(&req, &candidates, &mut |line| {
        let _ = writeln!(con.err(), "{line}");
    })?;
    let t = table(&c);
    // Written before it is printed: a reader of standard output that has gone ends the process
    // at the print.
    if let Some(out) = &args.out {
        crate::sweep::write_bytes_atomic(out, t.as_bytes())?;
    }
    write!(con.out(), "{t}")?;
    Ok(())
}
