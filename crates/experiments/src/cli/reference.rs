//! `sysid reference`: the reference posterior of θ for one data set by particle marginal
//! Metropolis–Hastings ([`crate::reference`]), written as JSON.

use std::path::PathBuf;

use crate::error::{Context, Result};

use crate::reference::posterior::{reference_posterior, write_reference, ReferenceRequest};
use identify::pipeline::Algorithm;

/// Arguments of `sysid reference`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Data-set directory (a short record: every iteration runs one particle filter over it).
    #[arg(long)]
    pub data: PathBuf,
    /// Likelihood estimator: mpf-ekf2 (exact Rao–Blackwellised filter when θ is fixed) or
    /// bootstrap.
    #[arg(long, default_value = "mpf-ekf2", value_parser = parse_estimator)]
    pub estimator: Algorithm,
    /// Particles of the likelihood estimator.
    #[arg(long, default_value_t = 200)]
    pub particles: usize,
    /// Kept iterations.
    #[arg(long, default_value_t = 5000)]
    pub iterations: usize,
    /// Burn-in iterations (proposal adaptation; discarded).
    #[arg(long, default_value_t = 1000)]
    pub burn_in: usize,
    /// Repeated likelihood estimates at the start point, to report the estimator's s.d.
    #[arg(long, default_value_t = 20)]
    pub probe: usize,
    /// Start the chain at the true θ (when the data set knows it) instead of the prior medians.
    #[arg(long, conflicts_with = "start_from")]
    pub start_at_truth: bool,
    /// Start the chain at the θ_val of a run record (e.g. an online filter's answer on the same
    /// data).
    #[arg(long)]
    pub start_from: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// TOML file of filter settings (as `sysid filter --config`): its `[structure]` table gives
    /// the building of field data (no dataset.json); its priors, fixed values and noise
    /// fraction define the posterior.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output file (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

/// The estimators `--estimator` takes. With θ fixed, the Storvik filter and the MLN-RBPF have no
/// static parameter left to sample or marginalise: they would be a bootstrap filter under another
/// name, so they are refused rather than run.
fn parse_estimator(s: &str) -> Result<Algorithm, String> {
    match s.parse::<Algorithm>()? {
        a @ (Algorithm::MpfEkf2 | Algorithm::Bootstrap) => Ok(a),
        a => Err(format!(
            "`{}` is not a likelihood estimator of `sysid reference` (with θ fixed it has no \
             parameter to sample); use mpf-ekf2 or bootstrap",
            a.name()
        )),
    }
}

pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    // Checked before the chain runs: a refused --out costs no filter run, and the record never
    // replaces a file the chain reads.
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("--data", &args.data)];
    for (flag, p) in [
        ("--config", &args.config),
        ("--start-from", &args.start_from),
    ] {
        if let Some(p) = p {
            inputs.push((flag, p));
        }
    }
    identify::record::atomic::check_output(&args.out, "--out", &inputs)?;
    let request = ReferenceRequest {
        data: args.data,
        estimator: args.estimator,
        particles: args.particles,
        iterations: args.iterations,
        burn_in: args.burn_in,
        probe: args.probe,
        start_at_truth: args.start_at_truth,
        start_from: args.start_from,
        seed: args.seed,
        config: args.config,
    };
    let record = reference_posterior(&request, &mut |line| {
        let _ = writeln!(con.err(), "{line}");
    })?;
    // Written before the table is printed: a reader of standard output that has gone ends the
    // process at the print (SIGPIPE), and the record asked for is there by then.
    write_reference(&args.out, &record)?;
    writeln!(
        con.out(),
        "{:<8} {:>12} {:>10} {:>24} {:>8} {:>10}",
        "param",
        "mean",
        "s.d.",
        "95% interval",
        "ESS",
        "truth"
    )?;
    for p in &record.params {
        writeln!(
            con.out(),
            "{:<8} {:>12.5} {:>10.5} {:>24} {:>8.0} {:>10}",
            p.name,
            p.mean,
            p.sd,
            format!("[{:.4}, {:.4}]", p.quantiles[0], p.quantiles[4]),
            p.ess,
            p.truth
                .map(|t| format!("{t:.4}"))
                .unwrap_or_else(|| "-".into())
        )?;
    }
    writeln!(
        con.out(),
        "acceptance {:.3} (burn-in {:.3}), {} failed estimates of {}",
        record.acceptance,
        record.acceptance_burn_in,
        record.failed_estimates,
        record.evaluations
    )?;
    for w in &record.warnings {
        writeln!(con.err(), "warning: {w}")?;
    }
    Ok(())
}

/// Arguments of `sysid compare-reference`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The reference posterior written by `sysid reference`; several chains on the same data are
    /// pooled as an equal-weight mixture (give it once per chain). Chains of several data sets
    /// (each record names its data set) give one table per data set and one across them.
    #[arg(long, required = true)]
    pub reference: Vec<PathBuf>,
    /// Run records of online filters on the reference's data set(s).
    #[arg(required = true)]
    pub records: Vec<PathBuf>,
    /// Write the markdown table here (default: stdout only).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// `sysid compare-reference`.
pub fn compare(args: CompareArgs, con: &mut crate::console::Console) -> Result<()> {
    if let Some(out) = &args.out {
        let mut inputs: Vec<(&str, &std::path::Path)> = Vec::new();
        inputs.extend(args.reference.iter().map(|p| ("--reference", p.as_path())));
        inputs.extend(args.records.iter().map(|p| ("a record", p.as_path())));
        identify::record::atomic::check_output(out, "--out", &inputs)?;
    }
    let md = crate::reference::compare_files(&args.reference, &args.records, &mut |w| {
        let _ = writeln!(con.err(), "warning: {w}");
    })?;
    // Written before it is printed (a closed standard output ends the process at the print),
    // and only as a new or regular file ([`crate::sweep::write_bytes_atomic`]).
    if let Some(out) = &args.out {
        crate::sweep::write_bytes_atomic(out, md.as_bytes()).context("--out")?;
    }
    write!(con.out(), "{md}")?;
    Ok(())
}
