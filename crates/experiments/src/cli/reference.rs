//! `sysid reference`: the reference posterior of θ for one data set by particle marginal
//! Metropolis–Hastings ([`crate::reference`]), written as JSON.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use core_filters::pmmh::PmmhConfig;
use core_filters::rng::stream;
use models::dataset::load_dir;
use serde::{Deserialize, Serialize};

use crate::pipeline::{chain_spec, Algorithm, FilterSettings};
use crate::reference::{run_chain, summarise, FilterLikelihood, ParamSummary, ThetaMap};

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

/// What `sysid reference` writes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceRecord {
    pub data: String,
    pub steps: usize,
    #[serde(with = "crate::record::number::scalar")]
    pub dt: f64,
    pub estimator: String,
    pub particles: usize,
    pub iterations: usize,
    pub burn_in: usize,
    pub seed: u64,
    #[serde(with = "crate::record::number::vec")]
    pub start: Vec<f64>,
    /// Mean and s.d. of `probe` likelihood estimates at the start point.
    #[serde(with = "crate::record::number::scalar")]
    pub loglik_at_start_mean: f64,
    #[serde(with = "crate::record::number::scalar")]
    pub loglik_at_start_sd: f64,
    #[serde(with = "crate::record::number::scalar")]
    pub acceptance: f64,
    #[serde(with = "crate::record::number::scalar")]
    pub acceptance_burn_in: f64,
    pub evaluations: u64,
    pub failed_estimates: u64,
    #[serde(with = "crate::record::number::scalar")]
    pub wall_s: f64,
    pub params: Vec<ParamSummary>,
    /// Why this reference should not be trusted as it is ([`chain_warnings`]).
    #[serde(default)]
    pub warnings: Vec<String>,
}

impl crate::record::read::Checked for ReferenceRecord {
    const KIND: &'static str = "reference record";
    /// One summary per free parameter with distinct names, quantiles in order where they are
    /// numbers, and counts that agree (failed estimates within the evaluations).
    fn check(&self) -> Result<(), String> {
        if self.iterations == 0 {
            return Err("`iterations` is 0: a chain of no kept iteration is no posterior".into());
        }
        if self.failed_estimates > self.evaluations {
            return Err(format!(
                "`failed_estimates` {} exceeds `evaluations` {}",
                self.failed_estimates, self.evaluations
            ));
        }
        let mut names: Vec<&str> = self.params.iter().map(|p| p.name.as_str()).collect();
        names.sort_unstable();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("parameter `{}` is summarised twice", w[0]));
        }
        if let Some(p) = self
            .params
            .iter()
            .find(|p| p.quantiles.windows(2).any(|q| q[0] > q[1]))
        {
            return Err(format!("the quantiles of `{}` are not in order", p.name));
        }
        Ok(())
    }
}

/// Chain ESS below which a reference mean is flagged: its Monte-Carlo s.e. is then more than a
/// tenth of the posterior s.d.
pub const MIN_CHAIN_ESS: f64 = 100.0;

/// Acceptance rate below which the chain is flagged as (nearly) stuck.
pub const MIN_ACCEPTANCE: f64 = 0.02;

/// The reasons a chain's summary is not a trustworthy posterior: a chain that did not move
/// after its burn-in (one point, not a distribution), a nearly stuck one, too few effective
/// samples, failed likelihood estimates.
pub fn chain_warnings(
    acceptance: f64,
    params: &[ParamSummary],
    failed: u64,
    evaluations: u64,
) -> Vec<String> {
    let mut w = Vec::new();
    if acceptance == 0.0 {
        w.push(
            "the chain did not move after the burn-in: its summary is one point, not a posterior \
             (start it elsewhere, e.g. --start-from an online run, or use more particles)"
                .to_string(),
        );
    } else if acceptance < MIN_ACCEPTANCE {
        w.push(format!(
            "acceptance {acceptance:.3} < {MIN_ACCEPTANCE}: the chain is nearly stuck"
        ));
    }
    for p in params
        .iter()
        .filter(|p| p.ess.is_nan() || p.ess < MIN_CHAIN_ESS)
    {
        w.push(format!(
            "{}: chain ESS {:.0} < {MIN_CHAIN_ESS}: the mean carries a Monte-Carlo s.e. of about \
             {:.3} (s.d./√ESS)",
            p.name,
            p.ess,
            p.sd / p.ess.max(1.0).sqrt()
        ));
    }
    if failed > 0 {
        w.push(format!(
            "{failed} of {evaluations} likelihood estimates failed (rejected proposals)"
        ));
    }
    w
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
    crate::limits::check_count(args.particles, 1, crate::limits::MAX_PARTICLES)
        .context("--particles")?;
    crate::limits::check_chain(args.iterations, args.burn_in, args.probe)
        .map_err(|(flag, e)| anyhow::anyhow!("{flag}: {e}"))?;
    let data = load_dir(&args.data)
        .with_context(|| format!("loading data set {}", args.data.display()))?;
    let chain = data
        .true_chain()
        .context("rebuilding the data set's structure")?;
    let mut settings = match &args.config {
        Some(path) => crate::limits::load_filter_settings(path)?,
        None => FilterSettings::default(),
    };
    let config_name = args
        .config
        .as_ref()
        .map_or_else(|| "--config".to_string(), |p| p.display().to_string());
    let table_name = |key: &str| format!("[structure] `{key}` in {config_name}");
    let measured = args.data.join(models::dataset::MEASURED);
    if data.meta.is_some() {
        // Simulated data carry their structure: a stated key must agree with it.
        crate::field::resolve(&data, None, &settings.structure, &measured, &table_name)?;
        settings.structure = crate::field::StructureSettings::default();
    } else {
        crate::field::resolve(&data, None, &settings.structure, &measured, &table_name).context(
            "field data: give the building with --config FILE and its [structure] table",
        )?;
    }
    let spec = chain_spec(&data, chain.as_ref(), &settings)?;
    let names = spec.prior.names();
    let map = ThetaMap::new(&spec.prior)?;
    let truth = data.meta.as_ref().map(|m| m.theta_true.clone());
    let start: Vec<f64> = match (&truth, args.start_at_truth, &args.start_from) {
        (Some(t), true, _) => t.clone(),
        (None, true, _) => bail!("--start-at-truth: {} has no true θ", args.data.display()),
        (_, false, Some(path)) => {
            let r: crate::record::RunRecord = crate::sweep::read_record(path)?;
            if r.param_names != names {
                bail!(
                    "--start-from {}: its parameters {:?} are not this data set's {:?}",
                    path.display(),
                    r.param_names,
                    names
                );
            }
            r.theta_val
        }
        _ => {
            // Prior medians (the middle of uniform priors; β, γ at the triangle's centre line).
            map.theta(&vec![0.0; map.dim()])
        }
    };
    let steps = data.len() - 1;
    let ys: Vec<f64> = (1..=steps).flat_map(|k| data.y(k).to_vec()).collect();
    let mut target = FilterLikelihood {
        spec,
        map: map.clone(),
        algorithm: args.estimator,
        particles: args.particles,
        ys,
        ny: data.channels,
        failures: 0,
        evaluations: 0,
    };
    let mut rng = stream(args.seed, 0, "reference/pmmh");
    let probes: Vec<f64> = (0..args.probe)
        .map(|_| target.estimate(&start, &mut rng))
        .collect();
    let pm = probes.iter().sum::<f64>() / probes.len().max(1) as f64;
    let psd = (probes.iter().map(|v| (v - pm).powi(2)).sum::<f64>()
        / (probes.len().max(2) - 1) as f64)
        .sqrt();
    eprintln!(
        "reference: {} steps, {} free parameters, estimator {} × {} particles; log-likelihood \
         at the start {pm:.2} ± {psd:.2} (s.d. of {} estimates)",
        steps,
        map.dim(),
        args.estimator.name(),
        args.particles,
        probes.len()
    );
    // Initial random walk: 2% in the log coordinates, 0.2 in the logistic ones; adapted in the
    // burn-in.
    let initial_sd: Vec<f64> = {
        let u0 = map.unconstrained(&start);
        let mut sd = vec![0.2; u0.len()];
        for (i, idx) in map.free_indices().into_iter().enumerate() {
            if names[idx].starts_with('k') || names[idx].starts_with('c') {
                sd[i] = 0.02;
            }
        }
        sd
    };
    let config = PmmhConfig {
        iterations: args.iterations,
        burn_in: args.burn_in,
        initial_sd,
        adapt_every: 100,
    };
    let started = Instant::now();
    let total = args.burn_in + args.iterations;
    let mut last_print = Instant::now();
    let chain_out = run_chain(&mut target, &start, &config, &mut rng, &mut |i, n| {
        if last_print.elapsed().as_secs() >= 30 || i == n {
            last_print = Instant::now();
            let el = started.elapsed().as_secs_f64();
            eprintln!(
                "reference: iteration {i}/{total} ({:.0} s elapsed, ~{:.0} s left)",
                el,
                el / i as f64 * (n - i) as f64
            );
        }
    });
    let params = summarise(&chain_out, &map, &names, truth.as_deref());
    let warnings = chain_warnings(
        chain_out.acceptance,
        &params,
        target.failures,
        target.evaluations,
    );
    let record = ReferenceRecord {
        data: args.data.display().to_string(),
        steps,
        dt: data.dt,
        estimator: args.estimator.name().to_string(),
        particles: args.particles,
        iterations: args.iterations,
        burn_in: args.burn_in,
        seed: args.seed,
        start,
        loglik_at_start_mean: pm,
        loglik_at_start_sd: psd,
        acceptance: chain_out.acceptance,
        acceptance_burn_in: chain_out.acceptance_burn_in,
        evaluations: target.evaluations,
        failed_estimates: target.failures,
        wall_s: started.elapsed().as_secs_f64(),
        params,
        warnings,
    };
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
    crate::record::read::write(&args.out, &record)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if record.acceptance == 0.0 {
        bail!(
            "the chain did not move after the burn-in: not a reference posterior (record with its \
             warnings written to {})",
            args.out.display()
        );
    }
    Ok(())
}

/// Arguments of `sysid compare-reference`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The reference posterior written by `sysid reference`; several chains on the same data are
    /// pooled as an equal-weight mixture (give it once per chain).
    #[arg(long, required = true)]
    pub reference: Vec<PathBuf>,
    /// Run records of online filters on the same data set.
    #[arg(required = true)]
    pub records: Vec<PathBuf>,
    /// Write the markdown table here (default: stdout only).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// `sysid compare-reference`: the online filters' final posteriors against the reference.
pub fn compare(args: CompareArgs) -> Result<()> {
    let mut chains = Vec::new();
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
        }
        chains.push(r.params);
    }
    let pooled = crate::reference::pool_chains(&chains)?;
    let mut records = Vec::new();
    for p in &args.records {
        let r: crate::record::RunRecord = crate::sweep::read_record(p)?;
        records.push(r);
    }
    let md = crate::reference::compare_markdown(&pooled, &records);
    print!("{md}");
    if let Some(out) = &args.out {
        std::fs::write(out, &md).with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
