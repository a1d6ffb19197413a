//! Particle filters and the one generic runner (STYLE lessons 1, 4, 5).
//!
//! - [`ParticleFilter`]: the verbs every particle filter has (`initialise`, `step`, `posterior`);
//!   the filters are [`bootstrap`] (SPEC §5.1), [`mlnrbpf`] (§5.2), [`storvik`] (§5.3) and
//!   [`mpf`] (MPF-EKF2, §5.4).
//! - [`run`]: the runner owns the time loop, computes the posterior summaries and hands them to an
//!   [`Observer`]; a failure ends the run and is returned in the [`RunSummary`], never a panic.
//! - [`Posterior`] and [`slot_moments`]: posterior means and s.d.s of named quantities, whether
//!   they are sampled (weighted particle average) or marginalised (Gaussian mixture, SPEC §7).

pub mod bootstrap;
pub mod lane_group;
pub mod mlnrbpf;
pub mod mpf;
pub mod storvik;

use nalgebra::{SMatrix, SVector};
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::error::FilterError;
use crate::health::Health;
use crate::model::{Layout, Slot};
use crate::resampling::{ResamplePolicy, Resampler};
use crate::weights::{normalise_log_weights, reset_uniform};

/// Settings shared by every particle filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParticleConfig {
    /// Number of particles `Np`.
    pub particles: usize,
    /// Resampling scheme and ESS threshold.
    pub resampling: ResamplePolicy,
}

impl Default for ParticleConfig {
    fn default() -> Self {
        Self {
            particles: 500,
            resampling: ResamplePolicy::default(),
        }
    }
}

/// The weights of a particle system and its resampling bookkeeping, shared by every particle
/// filter: log-weights and weights, the ancestor buffer, the resampler and the resampling decided
/// at the previous step (carried out at the start of the next one, see
/// [`ParticleFilter::posterior`]). Allocated once; nothing here allocates afterwards.
#[derive(Debug, Clone)]
pub struct WeightedSet {
    /// Normalised log-weights; filters add each particle's log-likelihood increment in `step`.
    pub log_w: Vec<f64>,
    /// Normalised weights.
    pub w: Vec<f64>,
    ancestors: Vec<usize>,
    resampler: Resampler,
    policy: ResamplePolicy,
    pending: bool,
}

impl WeightedSet {
    /// Uniform weights for `config.particles` particles.
    pub fn new(config: &ParticleConfig) -> Self {
        let np = config.particles;
        assert!(np > 0, "a particle filter needs at least one particle");
        let mut set = Self {
            log_w: vec![0.0; np],
            w: vec![0.0; np],
            ancestors: vec![0; np],
            resampler: Resampler::new(config.resampling.scheme, np),
            policy: config.resampling,
            pending: false,
        };
        set.reset();
        set
    }

    /// Uniform weights, nothing pending (initialisation).
    pub fn reset(&mut self) {
        reset_uniform(&mut self.log_w, &mut self.w);
        self.pending = false;
    }

    /// If the previous step decided to resample, draws the ancestors, resets the weights to
    /// uniform, counts the resampling and returns the ancestors; the caller then moves its
    /// particle buffers with [`gather`].
    pub fn take_pending<G: Rng + ?Sized>(
        &mut self,
        rng: &mut G,
        health: &mut Health,
    ) -> Option<&[usize]> {
        if !self.pending {
            return None;
        }
        self.resampler.resample(&self.w, &mut self.ancestors, rng);
        reset_uniform(&mut self.log_w, &mut self.w);
        health.resamples += 1;
        self.pending = false;
        Some(&self.ancestors)
    }

    /// Ends step `k`: normalises the log-weights (SPEC §3, the one weight routine), decides
    /// whether to resample, and reports the step.
    pub fn conclude(&mut self, k: usize, health: &mut Health) -> Result<StepInfo, FilterError> {
        let s = normalise_log_weights(&mut self.log_w, &mut self.w, k, health)?;
        self.pending = self.policy.should_resample(s.ess, self.w.len());
        Ok(StepInfo {
            k,
            loglik_increment: s.loglik_increment,
            ess: s.ess,
            resampled: self.pending,
        })
    }
}

/// The particles of a marginalized filter: per particle the sampled block and the Gaussian
/// `N(μ, C)` of the marginalised block, double-buffered so that resampling moves `(sampled, μ, C)`
/// jointly without allocating (MLN-RBPF, Storvik, MPF-EKF2).
#[derive(Debug, Clone)]
pub struct MarginalParticles<const NS: usize, const NM: usize> {
    pub sampled: Vec<SVector<f64, NS>>,
    pub mu: Vec<SVector<f64, NM>>,
    pub cov: Vec<SMatrix<f64, NM, NM>>,
    sampled_back: Vec<SVector<f64, NS>>,
    mu_back: Vec<SVector<f64, NM>>,
    cov_back: Vec<SMatrix<f64, NM, NM>>,
}

impl<const NS: usize, const NM: usize> MarginalParticles<NS, NM> {
    /// Zeroed storage for `np` particles.
    pub fn new(np: usize) -> Self {
        Self {
            sampled: vec![SVector::zeros(); np],
            mu: vec![SVector::zeros(); np],
            cov: vec![SMatrix::zeros(); np],
            sampled_back: vec![SVector::zeros(); np],
            mu_back: vec![SVector::zeros(); np],
            cov_back: vec![SMatrix::zeros(); np],
        }
    }

    /// Draws every particle: `draw` returns the sampled block and the Gaussian `(μ, C)`.
    pub fn initialise<G: Rng + ?Sized>(
        &mut self,
        rng: &mut G,
        mut draw: impl FnMut(&mut G) -> (SVector<f64, NS>, SVector<f64, NM>, SMatrix<f64, NM, NM>),
    ) {
        for ((s, m), c) in self.sampled.iter_mut().zip(&mut self.mu).zip(&mut self.cov) {
            (*s, *m, *c) = draw(rng);
        }
    }

    /// Carries out the resampling `set` decided at the previous step, if any.
    pub fn resample_pending<G: Rng + ?Sized>(
        &mut self,
        set: &mut WeightedSet,
        rng: &mut G,
        health: &mut Health,
    ) {
        if let Some(ancestors) = set.take_pending(rng, health) {
            self.resample(ancestors);
        }
    }

    /// The resampling of [`MarginalParticles::resample_pending`] for a filter that rewrites
    /// every particle's moments during its step (Storvik): only the sampled block moves now.
    /// `source[i]` is set to the particle whose moments particle `i` starts from (its ancestor,
    /// or itself when nothing was resampled); the step reads them with
    /// [`MarginalParticles::moments_split`], writes particle `i`'s new moments to the back
    /// buffers, and ends with [`MarginalParticles::swap_moments`]. Moving `(μ, C)` twice (once
    /// to the new order, once to the updated values) would copy 576 bytes per particle more.
    pub fn resample_sampled_only<G: Rng + ?Sized>(
        &mut self,
        set: &mut WeightedSet,
        rng: &mut G,
        health: &mut Health,
        source: &mut [usize],
    ) {
        match set.take_pending(rng, health) {
            Some(ancestors) => {
                gather(&self.sampled, ancestors, &mut self.sampled_back);
                std::mem::swap(&mut self.sampled, &mut self.sampled_back);
                source.copy_from_slice(ancestors);
            }
            None => {
                for (i, s) in source.iter_mut().enumerate() {
                    *s = i;
                }
            }
        }
    }

    /// The sampled block, the current moments (to read) and the back buffers (to write); see
    /// [`MarginalParticles::resample_sampled_only`].
    #[allow(clippy::type_complexity)]
    pub fn moments_split(
        &mut self,
    ) -> (
        &mut [SVector<f64, NS>],
        &[SVector<f64, NM>],
        &[SMatrix<f64, NM, NM>],
        &mut [SVector<f64, NM>],
        &mut [SMatrix<f64, NM, NM>],
    ) {
        (
            &mut self.sampled,
            &self.mu,
            &self.cov,
            &mut self.mu_back,
            &mut self.cov_back,
        )
    }

    /// Makes the moments written to the back buffers current.
    pub fn swap_moments(&mut self) {
        std::mem::swap(&mut self.mu, &mut self.mu_back);
        std::mem::swap(&mut self.cov, &mut self.cov_back);
    }

    /// Posterior moments: sampled entries averaged, marginalised ones as a Gaussian mixture.
    pub fn posterior(&self, layout: &Layout, w: &[f64], out: &mut Posterior) {
        fill_posterior(layout, w, &self.sampled, &self.mu, &self.cov, out);
    }

    /// Distinct-value counts of the parameters in the sampled block.
    pub fn distinct_sampled(&self, layout: &Layout) -> Vec<(String, usize)> {
        distinct_sampled(layout, &self.sampled)
    }

    /// Replaces particle `i` by particle `ancestors[i]`, all three blocks jointly.
    pub fn resample(&mut self, ancestors: &[usize]) {
        gather(&self.sampled, ancestors, &mut self.sampled_back);
        gather(&self.mu, ancestors, &mut self.mu_back);
        gather(&self.cov, ancestors, &mut self.cov_back);
        std::mem::swap(&mut self.sampled, &mut self.sampled_back);
        std::mem::swap(&mut self.mu, &mut self.mu_back);
        std::mem::swap(&mut self.cov, &mut self.cov_back);
    }
}

/// What one filter step reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// Time step `k` (1-based: the first measurement is `y_1`).
    pub k: usize,
    /// `log p̂(y_k | y_{1:k-1})`.
    pub loglik_increment: f64,
    /// Effective sample size of the weights after the update, before resampling.
    pub ess: f64,
    /// Whether the particles were resampled at this step.
    pub resampled: bool,
}

/// Posterior means and standard deviations of θ and of the physical states, in the order of
/// the filter's [`Layout`]. Allocated once by [`Posterior::for_layout`], filled in place.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Posterior {
    pub param_mean: Vec<f64>,
    pub param_sd: Vec<f64>,
    pub state_mean: Vec<f64>,
    pub state_sd: Vec<f64>,
}

impl Posterior {
    pub fn for_layout(layout: &Layout) -> Self {
        Self {
            param_mean: vec![0.0; layout.params.len()],
            param_sd: vec![0.0; layout.params.len()],
            state_mean: vec![0.0; layout.states.len()],
            state_sd: vec![0.0; layout.states.len()],
        }
    }
}

/// The verbs of a particle filter. Filters own their buffers (allocated in their constructor)
/// and allocate nothing in `step`.
pub trait ParticleFilter<const NY: usize> {
    /// Short algorithm name (`bootstrap`, `mln-rbpf`, `storvik`, `mpf-ekf2`).
    fn name(&self) -> &'static str;
    /// Number of particles.
    fn particles(&self) -> usize;
    /// Draws the initial particles from the prior and resets weights and counters.
    fn initialise<G: Rng + ?Sized>(&mut self, rng: &mut G);
    /// Processes measurement `y_k` (propagate, weight, update, resample as the algorithm says).
    fn step<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
    ) -> Result<StepInfo, FilterError>;
    /// Posterior moments of θ and the states at the current step, from the *weighted* particle
    /// set of step `k`. Filters carry out the resampling decided at step `k` at the start of step
    /// `k + 1` (an equivalent ordering of SPEC §5 (e): estimate, then resample), so the weighted
    /// set is still there when the runner asks.
    fn posterior(&self, out: &mut Posterior);
    /// Where θ and the states live.
    fn layout(&self) -> &Layout;
    /// Repairs counted so far.
    fn health(&self) -> Health;
    /// For each parameter held in the sampled block, the number of distinct values among the
    /// particles (a degeneracy measure: static sampled parameters collapse onto few values).
    /// Not for hot loops: it sorts.
    fn distinct_sampled_params(&self) -> Vec<(String, usize)>;
}

/// Receives what happens at each step (STYLE: collectors). All methods have no-op defaults.
pub trait Observer {
    /// Called after every successful step with the posterior summary of that step.
    fn on_step(&mut self, _info: &StepInfo, _posterior: &Posterior) {}
    /// Whether the posterior summary is needed at step `k` (skip the cost when decimating).
    fn wants_posterior(&self, _k: usize) -> bool {
        true
    }
}

/// An observer that records nothing.
pub struct NoObserver;
impl Observer for NoObserver {
    fn wants_posterior(&self, _k: usize) -> bool {
        false
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Steps completed successfully.
    pub steps_completed: usize,
    /// Total log-likelihood estimate over the completed steps.
    pub loglik: f64,
    /// Smallest and mean ESS over the completed steps.
    pub ess_min: f64,
    pub ess_mean: f64,
    /// The failure that ended the run early, if any.
    #[serde(skip)]
    pub failure: Option<FilterError>,
    /// Repairs counted by the filter.
    pub health: Health,
}

/// The generic runner: initialises the filter and processes `ys[0] = y_1, …, ys[K-1] = y_K`.
/// A step failure ends the run and is returned; the runner never panics on numerical failure.
pub fn run<const NY: usize, F, G, O>(
    filter: &mut F,
    ys: &[SVector<f64, NY>],
    rng: &mut G,
    observer: &mut O,
) -> RunSummary
where
    F: ParticleFilter<NY>,
    G: Rng + ?Sized,
    O: Observer + ?Sized,
{
    filter.initialise(rng);
    let mut post = Posterior::for_layout(filter.layout());
    let mut loglik = 0.0;
    let mut ess_min = f64::INFINITY;
    let mut ess_sum = 0.0;
    let mut failure = None;
    let mut done = 0;
    for (idx, y) in ys.iter().enumerate() {
        let k = idx + 1;
        match filter.step(k, y, rng) {
            Ok(info) => {
                loglik += info.loglik_increment;
                ess_min = ess_min.min(info.ess);
                ess_sum += info.ess;
                done = k;
                if observer.wants_posterior(k) {
                    filter.posterior(&mut post);
                }
                observer.on_step(&info, &post);
            }
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
    }
    RunSummary {
        steps_completed: done,
        loglik,
        ess_min: if done > 0 { ess_min } else { f64::NAN },
        ess_mean: if done > 0 {
            ess_sum / done as f64
        } else {
            f64::NAN
        },
        failure,
        health: filter.health(),
    }
}

/// Posterior mean and s.d. of one named quantity (SPEC §7): a sampled entry is averaged over the
/// weighted particles; a marginalised entry is the moment of the Gaussian mixture
/// `Σ_i w_i N(μ_i, C_i)`: mean `Σ w μ`, variance `Σ w (C + μ²) − mean²`.
pub fn slot_moments<const NS: usize, const NM: usize>(
    slot: Slot,
    w: &[f64],
    sampled: &[SVector<f64, NS>],
    mu: &[SVector<f64, NM>],
    cov: &[SMatrix<f64, NM, NM>],
) -> (f64, f64) {
    let (mut m1, mut m2) = (0.0, 0.0);
    match slot {
        Slot::Sampled(j) => {
            for (wi, s) in w.iter().zip(sampled) {
                m1 += wi * s[j];
                m2 += wi * s[j] * s[j];
            }
        }
        Slot::Marginal(j) => {
            for ((wi, m), c) in w.iter().zip(mu).zip(cov) {
                m1 += wi * m[j];
                m2 += wi * (c[(j, j)] + m[j] * m[j]);
            }
        }
    }
    // Round-off can make a zero variance slightly negative.
    (m1, (m2 - m1 * m1).max(0.0).sqrt())
}

/// Fills `out` from the layout with [`slot_moments`].
pub fn fill_posterior<const NS: usize, const NM: usize>(
    layout: &Layout,
    w: &[f64],
    sampled: &[SVector<f64, NS>],
    mu: &[SVector<f64, NM>],
    cov: &[SMatrix<f64, NM, NM>],
    out: &mut Posterior,
) {
    for (j, slot) in layout.params.iter().enumerate() {
        (out.param_mean[j], out.param_sd[j]) = slot_moments(*slot, w, sampled, mu, cov);
    }
    for (j, slot) in layout.states.iter().enumerate() {
        (out.state_mean[j], out.state_sd[j]) = slot_moments(*slot, w, sampled, mu, cov);
    }
}

/// Number of distinct values of entry `j` over the particles (degeneracy; sorts, so not for
/// hot loops).
pub fn distinct_values<const NS: usize>(sampled: &[SVector<f64, NS>], j: usize) -> usize {
    let mut v: Vec<f64> = sampled.iter().map(|s| s[j]).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.len()
}

/// Distinct-value counts of every parameter held in the sampled block.
pub fn distinct_sampled<const NS: usize>(
    layout: &Layout,
    sampled: &[SVector<f64, NS>],
) -> Vec<(String, usize)> {
    layout
        .param_names
        .iter()
        .zip(&layout.params)
        .filter_map(|(name, slot)| match slot {
            Slot::Sampled(j) => Some((name.clone(), distinct_values(sampled, *j))),
            Slot::Marginal(_) => None,
        })
        .collect()
}

/// Copies `src[ancestors[i]]` into `dst[i]` (the resampling move on double-buffered storage;
/// the caller swaps the buffers afterwards).
pub fn gather<T: Copy>(src: &[T], ancestors: &[usize], dst: &mut [T]) {
    for (d, &a) in dst.iter_mut().zip(ancestors) {
        *d = src[a];
    }
}
