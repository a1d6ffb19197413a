//! One identification run, end to end: data set + algorithm + settings + seed → [`RunRecord`],
//! by way of the run's plan: [`identify`] settles it ([`crate::plan::settle`]) and
//! [`execute`] runs it.
//!
//! Configuration errors (an unknown parameter to fix, a storey count that is not compiled in, an
//! invalid prior) are returned as errors before anything runs. Numerical failures *inside* the
//! run are not errors here: they end the run early and are written into the record, so a sweep
//! of 50 runs never aborts because of one.

use std::collections::BTreeMap;
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{bail, invalid, Result};
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::{purpose, stream};
use core_filters::smc::bootstrap::BootstrapPf;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::mpf::MpfEkf2;
use core_filters::smc::storvik::Storvik;
use core_filters::smc::{run, Filter, SmcConfig};
use models::dataset::LoadedDataset;
use models::filtering::{AugmentedChain, ChainSpec, MlnChain, MpfChain};
use models::integrate::{simulate_adaptive, Tolerance};
use models::structure::ShearChain;

use crate::metrics::{relative_errors, ErrorSums, StateErrors};
use crate::observe::{Recorder, TruthStates};
use crate::plan::{PlanRequest, RunPlan};
use crate::pool::Driven;
use crate::record::{Fingerprint, Loop, RunRecord, Timing, Validation, Versions};

pub use crate::algorithm::Algorithm;
pub use crate::plan::{chain_spec, prior_from_data, resolve_substeps, AutoChoice};
pub use crate::rules::{
    per_particle_reason, unmeasured_storeys, LagSubsteps, HYSTERETIC_PARTICLES, LAG_SUBSTEPS,
    MPF_REJUVENATION, PER_PARTICLE_MIN_STOREYS, SPARSE_REL_SD,
};
pub use crate::settings::FilterSettings;

/// What a run is given: the data, and when known the true structure (for the validation run).
pub struct RunInput<'a> {
    pub data: &'a LoadedDataset,
    /// The true structure, with θ_true (for validation); `None` for field data.
    pub chain: Option<&'a ShearChain>,
    pub experiment: &'a str,
    pub seed: u64,
    pub run: u64,
    /// Told how far the run is, `(steps done, steps in all)` counted over every pooled filter
    /// one way from start to end, every 64 steps and at each filter's end (`sysid filter` draws
    /// a bar or reports the pace; the library itself never prints).
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Record the one-step prediction errors at every step ([`crate::residuals`]; `sysid
    /// filter` does, sweeps do not: their records stay small).
    pub residuals: bool,
}

/// The filter of `algorithm` on the partitions of `spec` (no size table: every dimension is the
/// structure's).
pub fn build_filter(
    algorithm: Algorithm,
    spec: ChainSpec,
    s: &FilterSettings,
) -> Result<Box<dyn Filter>> {
    Ok(match algorithm {
        Algorithm::Bootstrap => Box::new(BootstrapPf::new(AugmentedChain::new(spec)?)),
        Algorithm::MlnRbpf => Box::new(MlnRbpf::new(MlnChain::new(spec)?)),
        Algorithm::Storvik => Box::new(Storvik::new(MlnChain::new(spec)?, s.storvik_update)),
        Algorithm::MpfEkf2 => Box::new(MpfEkf2::new(MpfChain::new(spec)?)),
    })
}

pub use crate::error::Interrupted;

/// Which filter of a pool [`drive`] runs, and whether its caller asks it to stop.
#[derive(Clone, Copy)]
struct Member<'a> {
    index: usize,
    stop: &'a (dyn Fn() -> bool + Sync),
}

/// Runs filter `member.index` of a pool (0: the only filter of an unpooled run, on the stream
/// `filter/<algorithm>`; member m > 0 on `filter/<algorithm>/pool<m>`).
fn drive(
    filter: &mut dyn Filter,
    input: &RunInput,
    s: &FilterSettings,
    algorithm: Algorithm,
    pc: &SmcConfig,
    member: Member<'_>,
    predictor: Option<crate::residuals::Predictor>,
) -> Driven {
    let Member {
        index: member,
        stop,
    } = member;
    let data = input.data;
    let layout = filter.layout().clone();
    // Truth rows in the filter's state order, when the truth is known.
    let truth_rows: Option<Vec<Vec<f64>>> = data.truth.as_ref().and_then(|t| {
        let cols: Option<Vec<usize>> = layout
            .state_names
            .iter()
            .map(|n| t.state_names.iter().position(|m| m == n))
            .collect();
        cols.map(|cols| {
            (0..t.states.len())
                .map(|k| cols.iter().map(|&c| t.states.state(k)[c]).collect())
                .collect()
        })
    });
    let steps = data.len() - 1;
    let ny = data.channels;
    let ys: Vec<f64> = (1..=steps)
        .flat_map(|k| data.y(k).iter().copied())
        .collect();
    let mut recorder = Recorder::new(
        steps,
        s.window,
        s.trace_every,
        data.dt,
        layout.params.len(),
        layout.states.len(),
        truth_rows.as_ref().map(|rows| TruthStates { rows }),
    );
    if let Some(progress) = input.progress {
        recorder.progress = Some(crate::observe::Progress {
            tell: progress,
            before: member * steps,
            total: steps * s.pool.max(1),
        });
    }
    recorder.keep_final = s.pool > 1;
    recorder.predictor = predictor;
    recorder.stop = Some(stop);
    let name = match member {
        0 => format!("{}/{}", purpose::FILTER, algorithm.name()),
        m => format!("{}/{}/pool{m}", purpose::FILTER, algorithm.name()),
    };
    let mut rng = stream(input.seed, input.run, &name);
    let start = Instant::now();
    let summary = run(filter, pc, &ys, ny, &mut rng, &mut recorder);
    let wall_s = start.elapsed().as_secs_f64();
    Driven {
        distinct: std::mem::take(&mut recorder.distinct),
        credible: std::mem::take(&mut recorder.credible),
        correlation: std::mem::take(&mut recorder.correlation),
        param_names: layout.param_names.clone(),
        theta_val: recorder.theta_val(),
        theta_sd_final: recorder.last.param_sd.clone(),
        online: truth_rows
            .as_ref()
            .map(|_| StateErrors::from_sums(&layout.state_names, &recorder.state_sums)),
        final_particles: recorder.final_particles.take(),
        residuals: recorder.predictor.take().map(|p| p.finish()),
        tail_loglik: recorder.tail_loglik,
        tail_steps: recorder.tail_steps,
        left_out: Vec::new(),
        trace: recorder.trace,
        summary,
        wall_s,
    }
}

/// Runs one algorithm on one data set and returns its record: the plan of a study's job
/// ([`crate::plan::settle`] with nothing asked: `s` is final but for the prior and
/// `substeps = "auto"`), executed.
pub fn identify(input: &RunInput, algorithm: Algorithm, s: &FilterSettings) -> Result<RunRecord> {
    identify_stoppable(input, algorithm, s, &|| false)
}

/// [`identify`], asking `stop` before every filter step whether to stop (an interactive caller's
/// Ctrl-C): when it answers `true` the run ends and the error is [`Interrupted`]
/// ([`crate::error::Error::interrupted`]); nothing else differs, so a run that is not stopped returns the
/// record [`identify`] returns.
pub fn identify_stoppable(
    input: &RunInput,
    algorithm: Algorithm,
    s: &FilterSettings,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<RunRecord> {
    let plan = crate::plan::settle(PlanRequest {
        algorithm,
        data: input.data,
        chain: input.chain,
        settings: s.clone(),
        seed: input.seed,
        run: input.run,
        experiment: input.experiment,
        asked: None,
    })?;
    execute(&plan, input, stop)
}

/// Runs the plan's filters on `input`: one (`filter`), or a pool of `settings.pool` filters side
/// by side on every core, each with its share of the particles and its own stream, combined in
/// pool order (`pool::combine`), so that the record is the same whatever the thread count.
fn run_pool(
    mut filter: Box<dyn Filter>,
    plan: &RunPlan,
    spec: &ChainSpec,
    input: &RunInput,
    pc: &SmcConfig,
    predictor: &(dyn Fn() -> Result<Option<crate::residuals::Predictor>> + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Driven> {
    let (s, algorithm, data) = (&plan.settings, plan.algorithm, input.data);
    Ok(if s.pool > 1 {
        if s.particles < s.pool {
            bail!(
                "field `pool`: {} particles cannot make {} filters",
                s.particles,
                s.pool
            );
        }
        let pool_started = Instant::now();
        // Np/M particles each, the first Np mod M filters one more.
        let (each, extra) = (s.particles / s.pool, s.particles % s.pool);
        let layout = filter.layout().clone();
        // The filters of a pool run in parallel, each on a filter of its own and its own
        // stream (`drive`), and are combined in pool order: the record is the same whatever
        // the number of threads (tested).
        let mut filters = vec![filter];
        for _ in 1..s.pool {
            filters.push(build_filter(algorithm, spec.clone(), s)?);
        }
        let members: Vec<Driven> = filters
            .into_par_iter()
            .enumerate()
            .map(|(m, mut own)| {
                let member = SmcConfig {
                    particles: each + usize::from(m < extra),
                    ..*pc
                };
                let p = predictor()?;
                let who = Member { index: m, stop };
                interrupted(
                    drive(own.as_mut(), input, s, algorithm, &member, who, p),
                    data.len() - 1,
                )
            })
            .collect::<Result<_>>()?;
        let mut d = crate::pool::combine(&layout, members, data.channels);
        // The filters ran side by side: the run's wall time is the pool's, not their sum.
        d.wall_s = pool_started.elapsed().as_secs_f64();
        d
    } else {
        if s.pool == 0 {
            bail!("field `pool`: 0 filters (1 runs one filter)");
        }
        let who = Member { index: 0, stop };
        interrupted(
            drive(filter.as_mut(), input, s, algorithm, pc, who, predictor()?),
            data.len() - 1,
        )?
    })
}

/// The configuration a record keeps: the algorithm, the filter settings, the data's, the
/// building and noise the filter ran with, and each rule's evidence (sub-steps, the data-scaled
/// prior) where it applied.
fn recorded_config(plan: &RunPlan, spec: &ChainSpec, data: &LoadedDataset) -> serde_json::Value {
    let (s, algorithm) = (&plan.settings, plan.algorithm);
    let mut config = serde_json::json!({
        "algorithm": algorithm.name(),
        "filter": s,
        "data": data.meta.as_ref().map(|m| serde_json::to_value(&m.config).ok()),
        "spec": {
            "dt": spec.dt, "masses": spec.building.masses(),
            "hysteretic": spec.building.hysteretic(),
            "sensors": spec.sensors, "q_disp": spec.q_disp, "q_vel": spec.q_vel,
            "q_r": spec.q_r, "r_diag": spec.r_diag, "prior": spec.prior,
            "discretisation": spec.discretisation,
        },
    });
    if spec.substeps != 1 {
        config["spec"]["substeps"] = spec.substeps.into();
    }
    if !spec.ground_between.is_linear() {
        config["spec"]["ground_between"] =
            serde_json::to_value(spec.ground_between).expect("serialisable");
    }
    if let Some(c) = spec.coloured_noise {
        config["spec"]["coloured_noise"] = serde_json::to_value(c).expect("serialisable");
    }
    if !plan.model.discrepancy_modes.is_empty() {
        config["spec"]["discrepancy_modes"] =
            serde_json::to_value(&plan.model.discrepancy_modes).expect("serialisable");
    }
    let auto = &plan.evidence.substeps;
    if let Some(a) = auto.linear {
        config["substeps_auto"] = serde_json::to_value(a).expect("serialisable");
    }
    if let Some(h) = auto.hysteretic {
        config["substeps_hysteretic"] = serde_json::to_value(h).expect("serialisable");
    }
    if let Some(l) = auto.lag {
        config["substeps_lag"] = serde_json::to_value(l).expect("serialisable");
    }
    if let Some(f) = auto.field {
        config["substeps_field"] = serde_json::to_value(f).expect("serialisable");
    }
    if !spec.building.damping().is_default() {
        config["spec"]["damping"] = spec.building.damping().name().into();
    }
    if let Some(p) = &plan.evidence.prior_from_data {
        config["prior_from_data"] = serde_json::to_value(p).expect("serialisable");
    }
    config
}

/// Runs a settled plan on its data (`input.data`; its seed, run and experiment are the plan's)
/// and returns the run's record, whose configuration is the plan's. `stop` as in
/// [`identify_stoppable`].
pub fn execute(
    plan: &RunPlan,
    input: &RunInput,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<RunRecord> {
    let data = input.data;
    if data.len() < 2 {
        bail!(
            "the data set has {} samples; at least 2 are needed",
            data.len()
        );
    }
    let s = &plan.settings;
    crate::limits::check_filter_settings(s)?;
    let spec = plan.spec(data)?;
    let input = &RunInput {
        seed: plan.seed,
        run: plan.run,
        experiment: &plan.experiment,
        ..*input
    };
    let pc = SmcConfig {
        particles: s.particles,
        resampling: ResamplePolicy {
            scheme: s.resampling,
            ess_threshold: s.ess_threshold,
        },
        rejuvenation: s.liu_west()?,
    };
    let filter = build_filter(plan.algorithm, spec.clone(), s)?;
    // One-step-ahead prediction errors when asked for (`sysid filter`): every filter of a pool
    // computes its own (one noise-free step per time step), and the record keeps those of the
    // first filter the pool keeps (`pool::combine`).
    let predictor = || prediction_errors(input, &spec);
    // The pace of a long run is timed over all its pooled filters (the caller's pace).
    let shape = filter.shape();
    crate::limits::check_particle_cloud(
        s.particles,
        shape.sampled + shape.marginal * (shape.marginal + 1),
    )?;
    let d = run_pool(filter, plan, &spec, input, &pc, &predictor, stop)?;

    let theta_true = data.meta.as_ref().map(|m| m.theta_true.clone());
    if let Some(t) = &theta_true {
        if t.len() != d.param_names.len() {
            return Err(invalid!(
                "the data set's true θ has {} entries, the filter's θ {}",
                t.len(),
                d.param_names.len()
            ));
        }
    }
    let validation_start = Instant::now();
    let validation = match (s.validate, input.chain, &data.truth) {
        (true, Some(chain), Some(truth)) if d.summary.failure.is_none() => {
            Some(validate(chain, &d.theta_val, truth, data.dt, s.loop_every))
        }
        _ => None,
    };
    let validation_s = validation_start.elapsed().as_secs_f64();
    let mut record = run_record(
        plan,
        input,
        &spec,
        d,
        theta_true,
        (validation, validation_s),
    );
    // Each filter shared its steps among the run's threads where it is tall enough and has the
    // particles to fill two blocks (not a one-particle Gaussian filter).
    let per_filter = s.particles.div_ceil(s.pool.max(1));
    record.timing.particle_blocks =
        core_filters::smc::batch::blocks(shape, per_filter, rayon::current_num_threads()) > 1;
    // A result that is physically impossible or rests on few particles says so (issue 16).
    record.warnings = crate::checks::check(&record);
    Ok(record)
}

/// The one-step prediction errors' predictor of a run that records them (`input.residuals`),
/// for each pooled filter to compute its own.
fn prediction_errors(
    input: &RunInput,
    spec: &ChainSpec,
) -> Result<Option<crate::residuals::Predictor>> {
    if !input.residuals {
        return Ok(None);
    }
    let data = input.data;
    let ys = (1..data.len()).flat_map(|k| data.y(k).to_vec()).collect();
    let channels = data.sensors.iter().map(|j| format!("a{j}")).collect();
    Ok(Some(crate::residuals::Predictor::new(
        spec.clone(),
        ys,
        channels,
    )?))
}

/// The failures of a driven pool by kind: the answer's own, or else those of the pooled filters
/// left out (counted even when the pool's answer stands without them).
fn failure_counts(d: &Driven) -> BTreeMap<String, u64> {
    let mut failures = BTreeMap::new();
    if let Some(f) = &d.summary.failure {
        failures.insert(f.kind().to_string(), 1);
    }
    // A pooled filter's failure is counted even when the pool's answer stands without it.
    if d.summary.failure.is_none() {
        for kind in d.left_out.iter().filter_map(|l| l.failure_kind.clone()) {
            *failures.entry(kind).or_insert(0) += 1;
        }
    }
    failures
}

/// The record of a driven pool `d` run by `plan` on `input`: its answer, trace, failures,
/// validation run (with the seconds it took), configuration, fingerprint and timing (no
/// warnings yet).
fn run_record(
    plan: &RunPlan,
    input: &RunInput,
    spec: &ChainSpec,
    d: Driven,
    theta_true: Option<Vec<f64>>,
    (validation, validation_s): (Option<Validation>, f64),
) -> RunRecord {
    let (s, algorithm, data) = (&plan.settings, plan.algorithm, input.data);
    let failures = failure_counts(&d);
    let config = recorded_config(plan, spec, data);
    let fingerprint = Fingerprint::of_run(algorithm.name(), input.seed, input.run, s, data);
    // Kept where the free run's band draws with it, field data; the studies' records of
    // generated data sets (with `dataset.json`) stay what they were, number for number.
    let theta_correlation = match data.meta {
        None => d
            .correlation
            .chunks(d.param_names.len().max(1))
            .map(<[f64]>::to_vec)
            .collect(),
        Some(_) => Vec::new(),
    };
    RunRecord {
        experiment: input.experiment.to_string(),
        algorithm: algorithm.name().to_string(),
        seed: input.seed,
        run: input.run,
        particles: s.particles,
        rel_error: theta_true
            .as_ref()
            .map(|t| relative_errors(&d.theta_val, t)),
        theta_true,
        param_names: d.param_names,
        theta_val: d.theta_val,
        window: s.window,
        theta_sd_final: d.theta_sd_final,
        loglik: d.summary.loglik,
        steps_total: data.len() - 1,
        steps_completed: d.summary.steps_completed,
        ess_min: d.summary.ess_min.unwrap_or(f64::NAN),
        ess_mean: d.summary.ess_mean.unwrap_or(f64::NAN),
        distinct_sampled: d.distinct.into_iter().collect(),
        failures,
        failure: d.summary.failure.as_ref().map(|f| f.to_string()),
        health: d.summary.health,
        online_states: d.online,
        validation,
        config,
        versions: Versions::current(),
        fingerprint: Some(fingerprint),
        trace: d.trace,
        timing: Timing {
            wall_s: d.wall_s,
            particle_steps_per_s: (s.particles * d.summary.steps_completed) as f64
                / d.wall_s.max(1e-12),
            validation_s,
            realtime_factor: (d.wall_s > 0.0)
                .then(|| d.summary.steps_completed as f64 * spec.dt / d.wall_s),
            threads: Some(rayon::current_num_threads()),
            particle_blocks: false,
            plan_s: None,
        },
        warnings: Vec::new(),
        theta_correlation,
        credible: d.credible,
        segment_spread: None,
        innovation_checks: d
            .residuals
            .as_ref()
            .map(crate::residuals::channel_checks)
            .unwrap_or_default(),
        residuals: d.residuals,
        free_run: None,
        modal: None,
        pool_left_out: d.left_out,
        plan: None,
        one_gaussian_filter: crate::rules::samples_nothing(algorithm, spec)
            && (s.particles, s.pool) == (1, 1),
    }
}

/// A driven filter, or [`Interrupted`] when it was stopped.
fn interrupted(d: Driven, steps: usize) -> Result<Driven> {
    if let Some(core_filters::error::FilterError::Interrupted { step }) = d.summary.failure {
        return Err(Interrupted { step, steps }.into());
    }
    Ok(d)
}

/// The validation run (SPEC §7): θ_val, zero initial conditions, clean excitation, adaptive
/// Dormand–Prince 5(4); errors against the true states and the hysteresis loops.
fn validate(
    chain: &ShearChain,
    theta_val: &[f64],
    truth: &models::dataset::LoadedTruth,
    dt: f64,
    loop_every: usize,
) -> Validation {
    let names = truth.state_names.clone();
    let fail = |e: String| Validation {
        states: StateErrors {
            names: names.clone(),
            errors: vec![],
        },
        loop_validation: None,
        loop_true: None,
        error: Some(e),
    };
    let model = match chain.with_theta(theta_val) {
        Ok(m) => m,
        Err(e) => return fail(format!("θ_val is not a valid structure: {e}")),
    };
    let traj = match simulate_adaptive(&model, &truth.ug_clean, dt, Tolerance::default()) {
        Ok(t) => t,
        Err(e) => return fail(format!("validation integration failed: {e}")),
    };
    let mut sums = vec![ErrorSums::default(); names.len()];
    for k in 0..traj.len().min(truth.states.len()) {
        for (j, s) in sums.iter_mut().enumerate() {
            s.add(traj.state(k)[j], truth.states.state(k)[j]);
        }
    }
    let loops = |c: &ShearChain, t: &models::integrate::Trajectory| -> Loop {
        let mut l = Loop::default();
        for k in (0..t.len()).step_by(loop_every.max(1)) {
            l.x.push(c.element_drift(t.state(k), 0));
            l.force.push(c.restoring_force(t.state(k), 0));
        }
        l
    };
    let keep = loop_every > 0 && !chain.bouc_wen().is_empty();
    Validation {
        states: StateErrors::from_sums(&names, &sums),
        loop_validation: keep.then(|| loops(&model, &traj)),
        loop_true: keep.then(|| loops(chain, &truth.states)),
        error: None,
    }
}
