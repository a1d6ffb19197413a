//! How well a record supports fixed parameter values, without the truth: the log-likelihood
//! `log p(y | θ)` of a data set at each of several answers (run records of different algorithms,
//! settings or seeds, or the data set's true θ), and which of them lie outside the record's 95 %
//! likelihood region.
//!
//! The estimate is the one the reference posterior uses (docs/reference-posterior.md): the
//! MPF-EKF2 with every parameter fixed at θ is an exact Rao–Blackwellised particle filter of the
//! filters' own model, so its log-likelihood is the log of an unbiased estimate of `p(y | θ)`.
//! Every θ is evaluated under one model, the one `sysid filter --algorithm mpf-ekf2` builds for
//! these data (its discretisation, sub-steps, noise levels and building; a config file's when
//! one is given), by one filter of `particles` particles resampling when ESS < Np/2, with
//! `seeds` independent estimates whose spread is reported.
//!
//! The test of a verdict: the record's 95 % likelihood region of the p free parameters holds the
//! θ within χ²_p(0.95)/2 nats of the maximum, and the maximum is at least the best candidate's.
//! A candidate whose mean estimate is below the best one's by more than that, plus twice the
//! standard error of the difference, lies outside the region: the record itself says that answer
//! is wrong, whatever the algorithm's intervals claim.

use std::path::{Path, PathBuf};

use crate::error::{bail, Context, Result};
use identify::field::StructureSettings;
use identify::identification::{settle, Target};
use identify::pipeline::{identify_stoppable, Algorithm, RunInput};
use identify::record::RunRecord;
use identify::settings::FilterSettings;
use models::dataset::{load_dir, LoadedDataset, MEASURED};
use models::structure::ShearChain;

/// One θ to score: a label (the record's path, or `truth`) and its values by name.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub label: String,
    pub names: Vec<String>,
    pub theta: Vec<f64>,
}

impl Candidate {
    /// The answer (θ_val) of a run record.
    pub fn from_record(path: &Path) -> Result<Self> {
        let r: RunRecord = crate::sweep::read_record(path)?;
        Self::of(path.display().to_string(), &r)
    }

    /// The answer (θ_val) of a record in memory, under `label`.
    pub fn of(label: String, r: &RunRecord) -> Result<Self> {
        if r.theta_val.iter().any(|v| !v.is_finite()) {
            bail!(
                "{label}: the run gives no finite θ_val (it failed before its averaging window?)"
            );
        }
        Ok(Self {
            label,
            names: r.param_names.clone(),
            theta: r.theta_val.clone(),
        })
    }
}

/// Most independent estimates per candidate: each is one full filter run, so more would run
/// for days, and the count sizes an allocation (a value near `u64::MAX` would overflow it).
pub const MAX_SEEDS: u64 = 10_000;

/// What to score and how.
#[derive(Debug, Clone)]
pub struct LikelihoodRequest {
    /// Data-set directory.
    pub data: PathBuf,
    /// Filter settings (as `sysid filter --config`); `None`: `sysid filter`'s recommended ones.
    pub config: Option<PathBuf>,
    /// Particles of the one filter of each estimate.
    pub particles: usize,
    /// Independent estimates per candidate (filter master seeds 1..=seeds).
    pub seeds: u64,
    /// Also score the data set's true θ (simulated data only).
    pub truth: bool,
}

/// How each candidate is scored: the part of a [`LikelihoodRequest`] that is not where the data
/// and the settings come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scoring {
    /// Particles of the one filter of each estimate.
    pub particles: usize,
    /// Independent estimates per candidate (filter master seeds 1..=seeds).
    pub seeds: u64,
    /// Also score the data set's true θ (simulated data only).
    pub truth: bool,
}

impl LikelihoodRequest {
    /// How each candidate is scored.
    pub(crate) fn scoring(&self) -> Scoring {
        Scoring {
            particles: self.particles,
            seeds: self.seeds,
            truth: self.truth,
        }
    }
}

/// The estimates of one candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    pub label: String,
    /// `log p̂(y | θ)`, one per seed (−∞ for a failed estimate).
    pub estimates: Vec<f64>,
}

impl Scored {
    /// Mean of the estimates.
    pub fn mean(&self) -> f64 {
        self.estimates.iter().sum::<f64>() / self.estimates.len() as f64
    }

    /// Standard error of the mean (NaN with one estimate).
    pub fn se(&self) -> f64 {
        let n = self.estimates.len() as f64;
        let m = self.mean();
        let var = self.estimates.iter().map(|e| (e - m).powi(2)).sum::<f64>() / (n - 1.0);
        (var / n).sqrt()
    }
}

/// The scores of every candidate and the half-width of the record's 95 % likelihood region.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    pub scored: Vec<Scored>,
    /// Free parameters (the candidates' θ length).
    pub params: usize,
    /// χ²_p(0.95)/2 in nats.
    pub region_nats: f64,
}

/// The verdict on one candidate against the best.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// The best mean estimate.
    Best,
    /// Below the best by less than the region's half-width plus two standard errors: not shown
    /// outside. Not shown inside either — the maximum may lie above every answer scored.
    NotShownOutside,
    /// Below the best by more: outside the record's 95 % likelihood region.
    Outside,
    /// Not resolved: a single estimate per candidate gives no standard error.
    Unresolved,
}

impl Verdict {
    /// Short name of the verdict (what the Python package returns).
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Best => "best",
            Verdict::NotShownOutside => "not shown outside",
            Verdict::Outside => "outside",
            Verdict::Unresolved => "not resolved",
        }
    }
}

impl Comparison {
    /// Index of the best (largest mean) candidate.
    pub fn best(&self) -> usize {
        (0..self.scored.len())
            .max_by(|&a, &b| self.scored[a].mean().total_cmp(&self.scored[b].mean()))
            .expect("at least one candidate")
    }

    /// Each candidate's verdict (see the module documentation for the test).
    pub fn verdicts(&self) -> Vec<Verdict> {
        let b = self.best();
        let best = &self.scored[b];
        self.scored
            .iter()
            .enumerate()
            .map(|(i, s)| {
                if i == b {
                    return Verdict::Best;
                }
                let gap = best.mean() - s.mean();
                let se = (best.se().powi(2) + s.se().powi(2)).sqrt();
                if !gap.is_finite() && gap > 0.0 {
                    // A candidate whose every estimate failed: the record gives it no support.
                    Verdict::Outside
                } else if !se.is_finite() {
                    Verdict::Unresolved
                } else if gap > self.region_nats + 2.0 * se {
                    Verdict::Outside
                } else {
                    Verdict::NotShownOutside
                }
            })
            .collect()
    }
}

/// The settings of every estimate: the base settings (a config's or the recommended ones) as
/// `sysid filter` settles them for the MPF-EKF2 on these data, then one filter of `particles`
/// without traces, validation or moves, every parameter fixed at `c`.
fn fixed_at(base: &FilterSettings, c: &Candidate, particles: usize) -> FilterSettings {
    let mut s = base.clone();
    s.particles = particles;
    s.pool = 1;
    s.ess_threshold = Some(0.5);
    s.trace_every = 0;
    s.loop_every = 0;
    s.validate = false;
    s.rejuvenation = None;
    s.fix = c
        .names
        .iter()
        .cloned()
        .zip(c.theta.iter().copied())
        .collect();
    s
}

/// Scores every candidate (and the truth when asked) on the request's data-set directory;
/// `progress` hears one line per finished estimate.
pub fn score(
    req: &LikelihoodRequest,
    candidates: &[Candidate],
    progress: &mut dyn FnMut(&str),
) -> Result<Comparison> {
    let dir = DataDir::load(&req.data, req.config.as_deref())?;
    score_on(&dir.scored(), req.scoring(), candidates, progress, &|| {
        false
    })
}

/// A data-set directory loaded with the settings of its model (a config file's, or `None` for
/// `sysid filter`'s recommended ones): what [`ScoredData`] borrows from.
pub(crate) struct DataDir {
    pub data: LoadedDataset,
    pub chain: Option<ShearChain>,
    measured: PathBuf,
    name: String,
    flags: StructureSettings,
    settings: Option<FilterSettings>,
    config: Option<String>,
}

impl DataDir {
    /// Loads `dir` (its true structure when it has one) and `config`.
    pub fn load(dir: &Path, config: Option<&Path>) -> Result<Self> {
        let data = load_dir(dir).with_context(|| format!("loading data set {}", dir.display()))?;
        let chain = data
            .true_chain()
            .context("rebuilding the data set's structure")?;
        let settings = config
            .map(identify::limits::load_filter_settings)
            .transpose()?;
        Ok(Self {
            data,
            chain,
            measured: dir.join(MEASURED),
            name: dir.display().to_string(),
            flags: StructureSettings::default(),
            settings,
            config: config.map(|p| p.display().to_string()),
        })
    }

    /// The data and model to score.
    pub fn scored(&self) -> ScoredData<'_> {
        ScoredData {
            data: &self.data,
            chain: self.chain.as_ref(),
            measured: &self.measured,
            name: &self.name,
            flags: &self.flags,
            settings: self.settings.clone(),
            config: self.config.as_deref(),
        }
    }
}

/// A data set already in memory and the model to score it under (what [`score`] builds from a
/// directory; the Python package builds it from its `Dataset`).
pub struct ScoredData<'a> {
    pub data: &'a LoadedDataset,
    /// The true structure (simulated data).
    pub chain: Option<&'a ShearChain>,
    /// The measured file, for messages.
    pub measured: &'a Path,
    /// How messages name the data set.
    pub name: &'a str,
    /// Structure given beside the data (as `sysid filter`'s flags).
    pub flags: &'a StructureSettings,
    /// Filter settings of the model; `None`: `sysid filter`'s recommended ones.
    pub settings: Option<FilterSettings>,
    /// How messages name the settings' source.
    pub config: Option<&'a str>,
}

/// The model every θ is scored under on one data set: the base settings as `sysid filter`
/// settles them for the MPF-EKF2 on these data, and the names of the model's parameters (every
/// θ must give exactly these). Built once, then asked for `log p̂(y | θ)` at any θ.
pub struct LikelihoodModel<'a> {
    on: &'a ScoredData<'a>,
    base: FilterSettings,
    /// The parameters of the model on these data, in θ's order.
    pub names: Vec<String>,
}

impl<'a> LikelihoodModel<'a> {
    /// Settles the model of `on` (errors: field data without a building, settings the data
    /// refuse).
    pub fn settle(on: &'a ScoredData<'a>) -> Result<Self> {
        let data = on.data;
        if data.meta.is_none()
            && on.chain.is_none()
            && on.settings.is_none()
            && on.flags.storeys.is_none()
        {
            bail!(
                "{}: field data (no dataset.json): state the building the answers were \
                 identified on (--config with its [structure] table; in Python, a config or \
                 building=)",
                on.name
            );
        }
        let base = on
            .settings
            .clone()
            .unwrap_or_else(FilterSettings::recommended);
        let target = Target {
            algorithm: Algorithm::MpfEkf2,
            data,
            chain: on.chain,
            measured: on.measured,
            flags: on.flags,
            config: on.config,
            // Every score sets its own particle count (`fixed_at`).
            particles_asked: true,
        };
        let base = settle(&target, base, &mut |_| {})?;
        let names = identify::pipeline::chain_spec(data, on.chain, &base)?
            .prior
            .names();
        Ok(Self { on, base, names })
    }

    /// The settled settings (before θ is fixed).
    pub fn settings(&self) -> &FilterSettings {
        &self.base
    }

    /// Whether the model samples nothing once θ is fixed — a building without hysteretic
    /// storeys — so that `log p̂(y | θ)` is the Kalman filter's exact log-likelihood, the same
    /// for every seed and particle count.
    pub(crate) fn is_exact(&self) -> Result<bool> {
        let spec = identify::pipeline::chain_spec(self.on.data, self.on.chain, &self.base)?;
        Ok(spec.building.hysteretic().is_empty())
    }

    /// Parameters that the base settings already fix: the same in every candidate, not free.
    pub(crate) fn fixed_by_settings(&self) -> usize {
        self.names
            .iter()
            .filter(|n| self.base.fix.contains_key(*n))
            .count()
    }

    /// Errors unless `c` gives exactly the model's parameters.
    pub fn check(&self, c: &Candidate) -> Result<()> {
        if c.names != self.names || c.theta.len() != self.names.len() {
            bail!(
                "{}: its parameters ({}) are not those of the building of {} ({}): every answer \
                 must be of that building",
                c.label,
                c.names.join(", "),
                self.on.name,
                self.names.join(", ")
            );
        }
        Ok(())
    }

    /// One estimate of `log p(y | θ)` at `c` (checked with [`Self::check`] first): one filter
    /// of `particles` with filter master seed `seed`; −∞ when the filter fails. `stop` is asked
    /// before every filter step whether to stop.
    pub fn loglik(
        &self,
        c: &Candidate,
        particles: usize,
        seed: u64,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> Result<f64> {
        let settings = fixed_at(&self.base, c, particles);
        let input = RunInput {
            data: self.on.data,
            chain: self.on.chain,
            experiment: "loglik",
            seed,
            run: 0,
            progress: None,
            residuals: false,
        };
        let r = identify_stoppable(&input, Algorithm::MpfEkf2, &settings, stop)
            .with_context(|| format!("{}: the likelihood at its θ", c.label))?;
        Ok(if r.failure.is_some() || !r.loglik.is_finite() {
            f64::NEG_INFINITY
        } else {
            r.loglik
        })
    }
}

/// Scores every candidate (and the truth when asked) on `on` as `req` says. `stop` is asked
/// before every filter step whether to stop (an interactive caller's Ctrl-C); a stop ends the
/// scoring with [`crate::error::Error::interrupted`].
pub fn score_on(
    on: &ScoredData<'_>,
    req: Scoring,
    candidates: &[Candidate],
    progress: &mut dyn FnMut(&str),
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Comparison> {
    if req.seeds == 0 {
        bail!("--seeds: at least one estimate per candidate");
    }
    if req.seeds > MAX_SEEDS {
        bail!(
            "--seeds {}: at most {MAX_SEEDS} estimates per candidate",
            req.seeds
        );
    }
    if req.particles == 0 {
        bail!("--particles: at least one particle per estimate");
    }
    identify::limits::check_particle_cloud(req.particles, 1).context("--particles")?;
    let model = LikelihoodModel::settle(on)?;
    let mut all = candidates.to_vec();
    if req.truth {
        let Some(meta) = &on.data.meta else {
            bail!(
                "--truth: {} has no dataset.json, so its true θ is unknown",
                on.name
            );
        };
        all.push(Candidate {
            label: "truth".into(),
            names: model.names.clone(),
            theta: meta.theta_true.clone(),
        });
    }
    if all.is_empty() {
        bail!("no record to score (give run records, or --truth)");
    }
    for c in &all {
        model.check(c)?;
    }
    let mut scored = Vec::with_capacity(all.len());
    for c in &all {
        let mut estimates = Vec::with_capacity(req.seeds as usize);
        for seed in 1..=req.seeds {
            let l = model.loglik(c, req.particles, seed, stop)?;
            progress(&format!("{}: seed {seed}: log p̂(y | θ) = {l:.2}", c.label));
            estimates.push(l);
        }
        scored.push(Scored {
            label: c.label.clone(),
            estimates,
        });
    }
    let params = model.names.len() - model.fixed_by_settings();
    Ok(Comparison {
        scored,
        params,
        region_nats: identify::residuals::chi2_95(params.max(1)) / 2.0,
    })
}

/// The comparison as a table, best first, with each verdict.
pub fn table(c: &Comparison) -> String {
    use std::fmt::Write as _;
    let b = c.best();
    let best_mean = c.scored[b].mean();
    let verdicts = c.verdicts();
    let mut order: Vec<usize> = (0..c.scored.len()).collect();
    order.sort_by(|&x, &y| c.scored[y].mean().total_cmp(&c.scored[x].mean()));
    let mut o = String::new();
    let w = c
        .scored
        .iter()
        .map(|s| s.label.chars().count())
        .max()
        .unwrap_or(0)
        .max("answer".len());
    let _ = writeln!(
        o,
        "{:<w$}  {:>16}  {:>8}  {:>12}  verdict",
        "answer", "log p̂(y | θ)", "s.e.", "below best"
    );
    for i in order {
        let s = &c.scored[i];
        let verdict = match verdicts[i] {
            Verdict::Best => "best".to_string(),
            Verdict::NotShownOutside => {
                "not shown outside (within the region's width of the best)".to_string()
            }
            Verdict::Outside => "OUTSIDE the 95 % likelihood region".to_string(),
            Verdict::Unresolved => {
                "not resolved (one estimate: no s.e.; use --seeds 2 or more)".to_string()
            }
        };
        let _ = writeln!(
            o,
            "{:<w$}  {:>16.2}  {:>8.2}  {:>12.2}  {verdict}",
            s.label,
            s.mean(),
            s.se(),
            best_mean - s.mean()
        );
    }
    let _ = writeln!(
        o,
        "95 % likelihood region of {} free parameters: within χ²_{}(0.95)/2 = {:.1} nats of the \
         maximum (at least the best answer's); outside means below the best by more than that \
         plus 2 s.e. of the difference.",
        c.params, c.params, c.region_nats
    );
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    fn comparison(estimates: &[&[f64]], params: usize) -> Comparison {
        Comparison {
            scored: estimates
                .iter()
                .enumerate()
                .map(|(i, e)| Scored {
                    label: format!("r{i}"),
                    estimates: e.to_vec(),
                })
                .collect(),
            params,
            region_nats: identify::residuals::chi2_95(params) / 2.0,
        }
    }

    #[test]
    fn the_verdicts_follow_the_region_and_the_standard_error() {
        // 9 parameters: region 8.46 nats. r1 is 5 below (not shown outside), r2 30 below (outside), r3 10
        // below with s.e.s of 2 (10 < 8.46 + 2·2.83: not shown outside), r4 every estimate failed.
        let c = comparison(
            &[
                &[-100.0, -100.0],
                &[-105.0, -105.0],
                &[-130.0, -130.0],
                &[-108.0, -112.0],
                &[f64::NEG_INFINITY, f64::NEG_INFINITY],
            ],
            9,
        );
        assert!((c.region_nats - 8.46).abs() < 0.05, "{}", c.region_nats);
        assert_eq!(c.best(), 0);
        assert_eq!(
            c.verdicts(),
            vec![
                Verdict::Best,
                Verdict::NotShownOutside,
                Verdict::Outside,
                Verdict::NotShownOutside,
                Verdict::Outside
            ]
        );
        let t = table(&c);
        assert!(t.lines().nth(1).unwrap().starts_with("r0"), "{t}");
        assert!(t.contains("OUTSIDE"), "{t}");
        // One estimate each: no standard error, no verdict.
        let c = comparison(&[&[-100.0], &[-130.0]], 9);
        assert_eq!(c.verdicts(), vec![Verdict::Best, Verdict::Unresolved]);
    }
}
