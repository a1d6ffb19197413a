//! `sysid reference`: the reference posterior of θ for one data set by particle marginal
//! Metropolis–Hastings ([`crate::reference`]), written as JSON.

use std::path::PathBuf;

use crate::error::{bail, Context, Result};

use crate::pipeline::Algorithm;
use crate::reference::posterior::{reference_posterior, write_reference, ReferenceRequest};
use crate::reference::{chain_warnings, ReferenceRecord};

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

pub fn run(args: Args) -> Result<()> {
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
    let record = reference_posterior(&request, &mut |line| eprintln!("{line}"))?;
    println!(
        "{:<8} {:>12} {:>10} {:>24} {:>8} {:>10}",
        "param", "mean", "s.d.", "95% interval", "ESS", "truth"
    );
    for p in &record.params {
        println!(
            "{:<8} {:>12.5} {:>10.5} {:>24} {:>8.0} {:>10}",
            p.name,
            p.mean,
            p.sd,
            format!("[{:.4}, {:.4}]", p.quantiles[0], p.quantiles[4]),
            p.ess,
            p.truth
                .map(|t| format!("{t:.4}"))
                .unwrap_or_else(|| "-".into())
        );
    }
    println!(
        "acceptance {:.3} (burn-in {:.3}), {} failed estimates of {}",
        record.acceptance, record.acceptance_burn_in, record.failed_estimates, record.evaluations
    );
    for w in &record.warnings {
        eprintln!("warning: {w}");
    }
    write_reference(&args.out, &record)
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

/// The data set a run record was computed on (`data.sha256` of its fingerprint).
fn record_data_sha(r: &crate::record::RunRecord) -> Option<&str> {
    r.fingerprint
        .as_ref()?
        .inputs
        .get("data")?
        .get("sha256")?
        .as_str()
}

/// The chains of one data set and the online records computed on it.
struct DataSetGroup {
    data: String,
    sha: Option<String>,
    chains: Vec<Vec<crate::reference::ParamSummary>>,
    records: Vec<crate::record::RunRecord>,
}

/// `sysid compare-reference`: the online filters' final posteriors against the reference; with
/// references of several data sets, each online record against the reference of its own data
/// set, and the information limit across them.
pub fn compare(args: CompareArgs) -> Result<()> {
    let mut groups: Vec<DataSetGroup> = Vec::new();
    // The chains' warnings go into the table's file as well, so that a reference resting on few
    // effective samples is not read as exact.
    let mut chain_notes = Vec::new();
    for path in &args.reference {
        let r: ReferenceRecord = crate::record::read::read(path)?;
        // Older records carry no warnings: recompute them from what they hold.
        let warnings = chain_warnings(r.acceptance, &r.params, r.failed_estimates, r.evaluations);
        if r.acceptance == 0.0 {
            bail!(
                "{}: the chain did not move after the burn-in; it is not a posterior to compare with",
                path.display()
            );
        }
        for w in &warnings {
            eprintln!("warning: {}: {w}", path.display());
            chain_notes.push(format!("- {}: {w}", path.display()));
        }
        match groups.iter_mut().find(|g| g.sha == r.data_sha256) {
            Some(g) => g.chains.push(r.params),
            None => groups.push(DataSetGroup {
                data: r.data,
                sha: r.data_sha256,
                chains: vec![r.params],
                records: Vec::new(),
            }),
        }
    }
    if groups.len() > 1 && groups.iter().any(|g| g.sha.is_none()) {
        bail!(
            "the references name different data sets, and some were written before references \
             recorded their data set: compare those one data set at a time"
        );
    }
    for p in &args.records {
        let r: crate::record::RunRecord = crate::sweep::read_record(p)?;
        let sha = record_data_sha(&r);
        let group = match groups.as_mut_slice() {
            // A reference that does not name its data set is compared with every record, as
            // before references recorded it.
            [g] if g.sha.is_none() => g,
            gs => gs
                .iter_mut()
                .find(|g| g.sha.as_deref() == sha)
                .ok_or_else(|| {
                    crate::error::invalid!(
                        "{}: its data set (sha256 {}) is not that of any reference given",
                        p.display(),
                        sha.unwrap_or("unknown")
                    )
                })?,
        };
        group.records.push(r);
    }
    let several = groups.len() > 1;
    let mut md = String::new();
    let mut compared = Vec::new();
    for g in groups {
        let pooled = crate::reference::pool_chains(&g.chains)?;
        if several {
            md.push_str(&format!(
                "## Data set {} (sha256 {})\n\n",
                g.data,
                g.sha.as_deref().map_or("?", |s| &s[..s.len().min(12)])
            ));
        }
        md.push_str(&crate::reference::compare_markdown(&pooled, &g.records));
        if several {
            md.push('\n');
        }
        compared.push((pooled, g.records));
    }
    if several {
        md.push_str(&format!(
            "## Across the {} data sets: the information limit\n\n",
            compared.len()
        ));
        md.push_str(&crate::reference::limit_markdown(
            &crate::reference::information_limit(&compared),
        ));
        md.push_str(&format!(
            "\n## The goal against the limit\n\nThe online mean |error| of the storeys' \
             stiffnesses and dampings within {:.0} % of the reference posterior's: the paired \
             difference online − reference over (data set, parameter) must lie below the margin \
             with its ±2 s.e. interval (holds), above it (does not hold), or the goal is not \
             resolved.\n\n",
            100.0 * crate::reference::GOAL_MARGIN
        ));
        md.push_str(&crate::reference::goal_markdown(
            &crate::reference::goal_rows(&compared),
        ));
    }
    if !chain_notes.is_empty() {
        md.push_str(&format!(
            "\nWarnings on the reference chains:\n\n{}\n",
            chain_notes.join("\n")
        ));
    }
    print!("{md}");
    if let Some(out) = &args.out {
        std::fs::write(out, &md).with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
