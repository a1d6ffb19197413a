//! The reference posterior of one data set as `sysid reference` computes it: a request, the
//! chain, and the record it writes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{bail, Context, Result};
use core_filters::pmmh::{PmmhChain, PmmhConfig};
use core_filters::rng::{stream, StreamRng};
use models::dataset::{load_dir, LoadedDataset};

use super::{chain_warnings, run_chain, summarise, FilterLikelihood, ReferenceRecord, ThetaMap};
use identify::pipeline::{chain_spec, Algorithm, FilterSettings};

/// What `sysid reference` asks for (every flag but `--out`).
#[derive(Debug, Clone)]
pub(crate) struct ReferenceRequest {
    /// Data-set directory.
    pub data: PathBuf,
    /// Likelihood estimator: the MPF-EKF2 or the bootstrap PF.
    pub estimator: Algorithm,
    /// Particles of the likelihood estimator.
    pub particles: usize,
    /// Kept iterations.
    pub iterations: usize,
    /// Burn-in iterations.
    pub burn_in: usize,
    /// Repeated likelihood estimates at the start point.
    pub probe: usize,
    /// Start at the true θ.
    pub start_at_truth: bool,
    /// Start at the θ_val of this run record.
    pub start_from: Option<PathBuf>,
    pub seed: u64,
    /// TOML file of filter settings.
    pub config: Option<PathBuf>,
}

/// Runs the chain of a request: checks the counts, resolves the building (simulated data carry
/// theirs; field data need the config's `[structure]` table), estimates the likelihood's s.d. at
/// the start point, runs the chain and summarises it. `note` hears the progress lines, in order.
pub(crate) fn reference_posterior(
    args: &ReferenceRequest,
    note: &mut dyn FnMut(String),
) -> Result<ReferenceRecord> {
    identify::limits::check_count(args.particles, 1, identify::limits::MAX_PARTICLES)
        .context("--particles")?;
    identify::limits::check_chain(args.iterations, args.burn_in, args.probe)
        .map_err(|(flag, e)| crate::error::invalid!("{flag}: {e}"))?;
    let data = load_dir(&args.data)
        .with_context(|| format!("loading data set {}", args.data.display()))?;
    let chain = data
        .true_chain()
        .context("rebuilding the data set's structure")?;
    let settings = structure_settings(args, &data)?;
    let mut spec = chain_spec(&data, chain.as_ref(), &settings)?;
    // `substeps = "auto"` in a config is resolved as in `sysid filter`, not silently one.
    let scaled = identify::pipeline::prior_from_data(&data, chain.as_ref(), &settings)?;
    identify::pipeline::resolve_substeps(args.estimator, &mut spec, &settings, scaled.as_ref());
    let names = spec.prior.names();
    let map = ThetaMap::new(&spec.prior)?;
    let truth = data.meta.as_ref().map(|m| m.theta_true.clone());
    let start = start_point(args, truth.as_deref(), &names, &map)?;
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
    let (pm, psd, probes) = likelihood_at_start(&mut target, &start, args.probe, &mut rng);
    note(format!(
        "reference: {} steps, {} free parameters, estimator {} × {} particles; log-likelihood \
         at the start {pm:.2} ± {psd:.2} (s.d. of {} estimates)",
        steps,
        map.dim(),
        args.estimator.name(),
        args.particles,
        probes
    ));
    let config = PmmhConfig {
        iterations: args.iterations,
        burn_in: args.burn_in,
        initial_sd: initial_step_sd(&map, &start, &names),
        adapt_every: 100,
    };
    let started = Instant::now();
    let chain_out = chain_with_progress(&mut target, &start, &config, &mut rng, started, note);
    let params = summarise(&chain_out, &map, &names, truth.as_deref());
    let warnings = chain_warnings(
        chain_out.acceptance,
        &params,
        target.failures,
        target.evaluations,
    );
    let record = ReferenceRecord {
        data: args.data.display().to_string(),
        data_sha256: identify::record::fingerprint::data_identity(&data)
            .get("sha256")
            .and_then(|v| v.as_str())
            .map(str::to_string),
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
    Ok(record)
}

/// The filter settings of a request (its `--config`, or the defaults) with the building
/// resolved: simulated data carry their structure, which a stated key must agree with; field
/// data need the config's `[structure]` table.
fn structure_settings(args: &ReferenceRequest, data: &LoadedDataset) -> Result<FilterSettings> {
    let mut settings = match &args.config {
        Some(path) => identify::limits::load_filter_settings(path)?,
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
        identify::field::resolve(data, None, &settings.structure, &measured, &table_name)?;
        settings.structure = identify::field::StructureSettings::default();
    } else {
        identify::field::resolve(data, None, &settings.structure, &measured, &table_name).context(
            "field data: give the building with --config FILE and its [structure] table",
        )?;
    }
    Ok(settings)
}

/// Where the chain starts: the true θ (`--start-at-truth`), the θ_val of a run record of the
/// same parameters (`--start-from`), or the prior medians.
fn start_point(
    args: &ReferenceRequest,
    truth: Option<&[f64]>,
    names: &[String],
    map: &ThetaMap,
) -> Result<Vec<f64>> {
    Ok(match (truth, args.start_at_truth, &args.start_from) {
        (Some(t), true, _) => t.to_vec(),
        (None, true, _) => bail!("--start-at-truth: {} has no true θ", args.data.display()),
        (_, false, Some(path)) => {
            let r: identify::record::RunRecord = crate::sweep::read_record(path)?;
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
    })
}

/// The mean and s.d. of `probe` estimates of the log-likelihood at the start point (how noisy
/// the estimator is there), and their number.
fn likelihood_at_start(
    target: &mut FilterLikelihood,
    start: &[f64],
    probe: usize,
    rng: &mut StreamRng,
) -> (f64, f64, usize) {
    let probes: Vec<f64> = (0..probe).map(|_| target.estimate(start, rng)).collect();
    let pm = probes.iter().sum::<f64>() / probes.len().max(1) as f64;
    let psd = (probes.iter().map(|v| (v - pm).powi(2)).sum::<f64>()
        / (probes.len().max(2) - 1) as f64)
        .sqrt();
    (pm, psd, probes.len())
}

/// Initial random walk: 2% in the log coordinates, 0.2 in the logistic ones; adapted in the
/// burn-in.
fn initial_step_sd(map: &ThetaMap, start: &[f64], names: &[String]) -> Vec<f64> {
    let u0 = map.unconstrained(start);
    let mut sd = vec![0.2; u0.len()];
    for (i, idx) in map.free_indices().into_iter().enumerate() {
        if names[idx].starts_with('k') || names[idx].starts_with('c') {
            sd[i] = 0.02;
        }
    }
    sd
}

/// Runs the chain, telling `note` where it is every 30 s and at its last iteration, with the
/// time elapsed since `started` and an estimate of the time left.
fn chain_with_progress(
    target: &mut FilterLikelihood,
    start: &[f64],
    config: &PmmhConfig,
    rng: &mut StreamRng,
    started: Instant,
    note: &mut dyn FnMut(String),
) -> PmmhChain {
    let total = config.burn_in + config.iterations;
    let mut last_print = Instant::now();
    run_chain(target, start, config, rng, &mut |i, n| {
        if last_print.elapsed().as_secs() >= 30 || i == n {
            last_print = Instant::now();
            let el = started.elapsed().as_secs_f64();
            note(format!(
                "reference: iteration {i}/{total} ({:.0} s elapsed, ~{:.0} s left)",
                el,
                el / i as f64 * (n - i) as f64
            ));
        }
    })
}

/// Writes a reference record to `out`; an error (after writing) when its chain did not move
/// after the burn-in.
pub fn write_reference(out: &Path, record: &ReferenceRecord) -> Result<()> {
    identify::record::read::write(out, record)
        .with_context(|| format!("writing {}", out.display()))?;
    if record.acceptance == 0.0 {
        bail!(
            "the chain did not move after the burn-in: not a reference posterior (record with its \
             warnings written to {})",
            out.display()
        );
    }
    Ok(())
}
