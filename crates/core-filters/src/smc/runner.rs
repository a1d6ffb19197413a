//! The one generic runner (STYLE: particles' `SMC.__next__`, argmin's `Executor`): it owns the
//! particle storage, the weights, the resampling decision and the ancestors, the time loop and the
//! observers; a filter is a small adapter ([`Filter`]) that advances and weights particles.
//!
//! One step `k`:
//! 1. if the previous step decided to resample, draw ancestors (from the filter's stream) and
//!    reset the weights to uniform; otherwise every particle is its own ancestor. With a
//!    rejuvenation move ([`SmcConfig::rejuvenation`]) the resampled particles are then copied into
//!    place, their static parameters moved by the Liu–West kernel ([`super::rejuvenation`], draws
//!    from the same stream) and every particle becomes its own ancestor;
//! 2. the filter advances particle `i` from its ancestor's slot of the current store into slot `i`
//!    of the other store and adds its log-likelihood increment to `log w_i` (NaN for a numerical
//!    failure of that particle);
//! 3. the stores are swapped; the weights are normalised with the one weight routine (SPEC §3:
//!    log domain, NaN → −∞, all −∞ is a typed failure); the resampling decision is taken;
//! 4. the posterior summary of the weighted set is handed to the observers (SPEC §5 (e):
//!    estimate, then resample — the resampling itself happens at the start of the next step).
//!
//! A failure ends the run and is returned in the [`RunSummary`], never a panic.

use serde::Serialize;

use crate::credible::{CredibleError, CredibleInterval, GaussianMixture, WeightedSample};
use crate::error::FilterError;
use crate::health::Health;
use crate::linalg::LowerBound;
use crate::model::{Layout, Slot};
use crate::resampling::{ResamplePolicy, Resampler};
use crate::rng::StreamRng;
use crate::weights::{normalise_log_weights, reset_uniform};

use super::rejuvenation::{LiuWest, Rejuvenation, StaticParam};
use super::store::{Particles, Shape};

/// Settings shared by every particle filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct SmcConfig {
    /// Number of particles `Np`.
    pub particles: usize,
    /// Resampling scheme and ESS threshold.
    pub resampling: ResamplePolicy,
    /// The Liu–West move of the filter's static parameters after every resampling
    /// ([`super::rejuvenation`]); `None`: no move, no copy, no extra draw.
    #[serde(skip)]
    pub rejuvenation: Option<LiuWest>,
}

impl Default for SmcConfig {
    fn default() -> Self {
        Self {
            particles: 500,
            resampling: ResamplePolicy::default(),
            rejuvenation: None,
        }
    }
}

/// A particle filter as the runner sees it: an adapter that initialises and advances particles.
/// Object safe, so that a run can hold any filter as `Box<dyn Filter>`.
pub trait Filter: Send {
    /// Short algorithm name (`bootstrap`, `mln-rbpf`, `storvik`, `mpf-ekf2`).
    fn name(&self) -> &'static str;
    /// Where θ and the physical states live in a particle.
    fn layout(&self) -> &Layout;
    /// The static entries of the sampled block that a rejuvenation move may change, with their
    /// supports; none by default (the bootstrap PF declares none: its β and γ share a triangle,
    /// not an interval each).
    fn static_params(&self) -> &[StaticParam] {
        &[]
    }
    /// Sizes of a particle's blocks.
    fn shape(&self) -> Shape;
    /// Draws every particle from the prior and resets the filter's counters.
    fn initialise(&mut self, rng: &mut StreamRng, particles: &mut Particles);
    /// Advances every particle `i` from slot `ancestors[i]` of `src` to slot `i` of `out.dst`
    /// with the measurement `y = y_k` ([`StepInput`]), adding its log-likelihood increment to
    /// `out.log_w[i]` (NaN when a numerical failure leaves the particle without a result). A
    /// particle whose `log_w` is −∞ is copied unchanged. Random draws are taken particle by
    /// particle, in order.
    fn step(
        &mut self,
        input: &StepInput<'_>,
        out: &mut StepOutput<'_>,
        rng: &mut StreamRng,
    ) -> Result<(), FilterError>;
    /// Repairs counted so far.
    fn health(&self) -> Health;
    /// Entries of the marginalised block held to their physical support
    /// ([`crate::linalg::support`]); none by default.
    fn lower_bounds(&self) -> &[LowerBound] {
        &[]
    }
}

/// What step `k` starts from: the measurement `y_k` and the particles of step `k − 1`, particle
/// `i` descending from `src`'s slot `ancestors[i]`.
#[derive(Clone, Copy)]
pub struct StepInput<'a> {
    pub k: usize,
    pub y: &'a [f64],
    pub src: &'a Particles,
    pub ancestors: &'a [usize],
}

/// What step `k` writes: the particles of step `k` and their log-weights (incremented).
pub struct StepOutput<'a> {
    pub dst: &'a mut Particles,
    pub log_w: &'a mut [f64],
}

/// What one step reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// Time step `k` (1-based: the first measurement is `y_1`).
    pub k: usize,
    /// `log p̂(y_k | y_{1:k−1})`.
    pub loglik_increment: f64,
    /// Effective sample size after the update, before resampling.
    pub ess: f64,
    /// Whether the particles will be resampled before the next step.
    pub resampled: bool,
}

/// Posterior means and s.d.s of θ and of the physical states, in the order of the [`Layout`].
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

/// The weighted particle set of the last completed step, as observers see it at the end.
pub struct WeightedParticles<'a> {
    pub layout: &'a Layout,
    /// Normalised weights.
    pub w: &'a [f64],
    pub particles: &'a Particles,
    /// The filter's physical support ([`Filter::lower_bounds`]): the credible intervals of a
    /// bounded entry are those of its posterior truncated to the bound.
    pub bounds: &'a [LowerBound],
}

impl WeightedParticles<'_> {
    /// Posterior mean and s.d. of one slot (SPEC §7).
    pub fn moments(&self, slot: Slot) -> (f64, f64) {
        slot_moments(slot, self.w, self.particles)
    }

    /// Number of distinct values of sampled entry `j` (degeneracy; sorts, not for hot loops).
    pub fn distinct(&self, j: usize) -> usize {
        let mut v: Vec<f64> = (0..self.particles.len())
            .map(|i| self.particles.sampled(i)[j])
            .collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v.len()
    }

    /// Central credible intervals of one slot at each of `levels` (SPEC §9 "Calibration"): the
    /// weighted sample `Σ w_i δ(x − x_i)` of a sampled entry, the Gaussian mixture
    /// `Σ w_i N(μ_i, C_i)` of a marginalised one (see [`crate::credible`]), truncated to its
    /// bound when the entry is held to a physical support. Allocates two
    /// vectors of `Np`; meant for the end of a run, not for every step.
    pub fn central_intervals(
        &self,
        slot: Slot,
        levels: &[f64],
    ) -> Result<Vec<CredibleInterval>, CredibleError> {
        let np = self.particles.len();
        let mut out = vec![
            CredibleInterval {
                level: f64::NAN,
                lo: f64::NAN,
                hi: f64::NAN,
            };
            levels.len()
        ];
        match slot {
            Slot::Sampled(j) => {
                let values: Vec<f64> = (0..np).map(|i| self.particles.sampled(i)[j]).collect();
                WeightedSample::new(&values, self.w)?.central_intervals(levels, &mut out)?;
            }
            Slot::Marginal(j) => {
                let n = self.particles.shape().marginal;
                let means: Vec<f64> = (0..np).map(|i| self.particles.mean(i)[j]).collect();
                // Round-off in a covariance update can leave a variance a hair below zero.
                let vars: Vec<f64> = (0..np)
                    .map(|i| self.particles.cov(i)[j + j * n].max(0.0))
                    .collect();
                let mixture = GaussianMixture::new(self.w, &means, &vars)?;
                match self.bounds.iter().find(|b| b.index == j) {
                    Some(b) => mixture.central_intervals_above(b.bound, levels, &mut out)?,
                    None => mixture.central_intervals(levels, &mut out)?,
                }
            }
        }
        Ok(out)
    }

    /// The posterior correlation matrix of the parameters θ (the layout's order, row-major
    /// `n × n`): the covariance of the sampled entries over the weighted particles, of the
    /// marginalised ones the Gaussian mixture's `Σ w (C + μμᵀ) − m mᵀ`, of a sampled and a
    /// marginalised entry `Σ w x μ − m_x m_μ`, each scaled by the two s.d.s. A parameter of zero
    /// variance is uncorrelated with every other (its row and column are the identity's). Meant
    /// for the end of a run.
    pub fn param_correlation(&self) -> Vec<f64> {
        slot_correlation(&self.layout.params, self.w, self.particles)
    }

    /// Distinct-value counts of every parameter held in the sampled block.
    pub fn distinct_sampled_params(&self) -> Vec<(String, usize)> {
        self.layout
            .param_names
            .iter()
            .zip(&self.layout.params)
            .filter_map(|(name, slot)| match slot {
                Slot::Sampled(j) => Some((name.clone(), self.distinct(*j))),
                Slot::Marginal(_) => None,
            })
            .collect()
    }
}

/// Receives what happens during a run. All methods have no-op defaults.
pub trait Observer {
    /// Called once before the first step.
    fn on_start(&mut self, _layout: &Layout, _particles: usize) {}
    /// Whether the posterior summary is needed at step `k` (skip the cost when decimating).
    fn wants_posterior(&self, _k: usize) -> bool {
        true
    }
    /// Called after every successful step with the posterior summary of that step.
    fn on_step(&mut self, _info: &StepInfo, _posterior: &Posterior) {}
    /// Called once at the end of a run that completed every step, with the weighted particles of
    /// the last step (for credible intervals and degeneracy counts).
    fn on_finish(&mut self, _last: &WeightedParticles<'_>) {}
    /// Whether the run should stop before step `k` (an interruption by the user, e.g. Ctrl-C in
    /// an interactive session). Asked once per step, before the step; `true` ends the run with
    /// [`FilterError::Interrupted`] and the steps before `k` completed.
    fn should_stop(&mut self, _k: usize) -> bool {
        false
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
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// Steps completed successfully.
    pub steps_completed: usize,
    /// Log-likelihood estimate over the completed steps.
    pub loglik: f64,
    /// Smallest and mean ESS over the completed steps (`None` when no step completed).
    pub ess_min: Option<f64>,
    pub ess_mean: Option<f64>,
    /// The failure that ended the run early, if any.
    pub failure: Option<FilterError>,
    /// Repairs counted by the filter, and resampling events.
    pub health: Health,
}

/// Posterior mean and s.d. of one named quantity (SPEC §7): a sampled entry is averaged over the
/// weighted particles; a marginalised entry is the moment of the Gaussian mixture
/// `Σ_i w_i N(μ_i, C_i)`: mean `Σ w μ`, variance `Σ w (C + μ²) − mean²`.
pub fn slot_moments(slot: Slot, w: &[f64], p: &Particles) -> (f64, f64) {
    let (mut m1, mut m2) = (0.0, 0.0);
    match slot {
        Slot::Sampled(j) => {
            for (i, wi) in w.iter().enumerate() {
                let v = p.sampled(i)[j];
                m1 += wi * v;
                m2 += wi * v * v;
            }
        }
        Slot::Marginal(j) => {
            let n = p.shape().marginal;
            for (i, wi) in w.iter().enumerate() {
                let mu = p.mean(i)[j];
                m1 += wi * mu;
                m2 += wi * (p.cov(i)[j + j * n] + mu * mu);
            }
        }
    }
    // Round-off can make a zero variance slightly negative.
    (m1, (m2 - m1 * m1).max(0.0).sqrt())
}

/// The correlation matrix of `slots` over the weighted particles (row-major; see
/// [`WeightedParticles::param_correlation`]).
pub(crate) fn slot_correlation(slots: &[Slot], w: &[f64], p: &Particles) -> Vec<f64> {
    let n = slots.len();
    let nm = p.shape().marginal;
    let value = |i: usize, slot: Slot| match slot {
        Slot::Sampled(j) => p.sampled(i)[j],
        Slot::Marginal(j) => p.mean(i)[j],
    };
    let mean: Vec<f64> = slots.iter().map(|&s| slot_moments(s, w, p).0).collect();
    let mut cov = vec![0.0; n * n];
    for a in 0..n {
        for b in a..n {
            let mut s = 0.0;
            for (i, wi) in w.iter().enumerate() {
                let within = match (slots[a], slots[b]) {
                    (Slot::Marginal(ja), Slot::Marginal(jb)) => p.cov(i)[ja + jb * nm],
                    _ => 0.0,
                };
                s +=
                    wi * ((value(i, slots[a]) - mean[a]) * (value(i, slots[b]) - mean[b]) + within);
            }
            cov[a * n + b] = s;
            cov[b * n + a] = s;
        }
    }
    let sd: Vec<f64> = (0..n).map(|a| cov[a * n + a].max(0.0).sqrt()).collect();
    let mut r = vec![0.0; n * n];
    for a in 0..n {
        for b in 0..n {
            r[a * n + b] = if a == b {
                1.0
            } else if sd[a] > 0.0 && sd[b] > 0.0 && cov[a * n + b].is_finite() {
                (cov[a * n + b] / (sd[a] * sd[b])).clamp(-1.0, 1.0)
            } else {
                0.0
            };
        }
    }
    r
}

/// Fills `out` from the layout with [`slot_moments`].
pub(crate) fn fill_posterior(layout: &Layout, w: &[f64], p: &Particles, out: &mut Posterior) {
    for (j, slot) in layout.params.iter().enumerate() {
        (out.param_mean[j], out.param_sd[j]) = slot_moments(*slot, w, p);
    }
    for (j, slot) in layout.states.iter().enumerate() {
        (out.state_mean[j], out.state_sd[j]) = slot_moments(*slot, w, p);
    }
}

/// Runs `filter` on `ys` (row `k−1` holds `y_k`, `ny` values per row): initialises, then steps
/// through every measurement. A step failure ends the run and is returned; the runner never
/// panics on numerical failure. With [`SmcConfig::rejuvenation`] the filter's static parameters
/// ([`Filter::static_params`]) are moved after every resampling (module docs, step 1); without
/// one, with a kernel that does not move (`δ = 1`) or with a filter that declares no static
/// parameter, nothing is copied and no extra draw taken.
pub fn run(
    filter: &mut dyn Filter,
    config: &SmcConfig,
    ys: &[f64],
    ny: usize,
    rng: &mut StreamRng,
    observer: &mut dyn Observer,
) -> RunSummary {
    let np = config.particles;
    assert!(np > 0, "a particle filter needs at least one particle");
    assert!(
        ny > 0 && ys.len().is_multiple_of(ny),
        "measurements are rows of {ny}"
    );
    let layout = filter.layout().clone();
    let shape = filter.shape();
    let mut front = Particles::new(np, shape);
    let mut back = Particles::new(np, shape);
    let mut log_w = vec![0.0; np];
    let mut w = vec![0.0; np];
    let mut ancestors: Vec<usize> = (0..np).collect();
    let mut resampler = Resampler::new(config.resampling.scheme, np);
    let mut post = Posterior::for_layout(&layout);
    let mut rejuvenation = config
        .rejuvenation
        .and_then(|k| Rejuvenation::new(k, filter.static_params(), np));
    filter.initialise(rng, &mut front);
    reset_uniform(&mut log_w, &mut w);
    observer.on_start(&layout, np);

    let mut health_extra = Health::default();
    let (mut loglik, mut ess_min, mut ess_sum) = (0.0, f64::INFINITY, 0.0);
    let mut failure = None;
    let mut done = 0;
    let mut pending = false;
    for (idx, y) in ys.chunks_exact(ny).enumerate() {
        let k = idx + 1;
        if observer.should_stop(k) {
            failure = Some(FilterError::Interrupted { step: k });
            break;
        }
        if y.iter().any(|v| !v.is_finite()) {
            failure = Some(FilterError::NonFinite {
                step: k,
                which: "measurement",
            });
            break;
        }
        if pending {
            resampler.resample(&w, &mut ancestors, rng);
            reset_uniform(&mut log_w, &mut w);
            health_extra.resamples += 1;
            if let Some(move_) = &mut rejuvenation {
                // The resampled set in place (equally weighted), its static parameters moved.
                for (i, &a) in ancestors.iter().enumerate() {
                    back.copy_from(i, &front, a);
                }
                std::mem::swap(&mut front, &mut back);
                move_.apply(&mut front, rng);
                for (i, a) in ancestors.iter_mut().enumerate() {
                    *a = i;
                }
            }
        } else {
            for (i, a) in ancestors.iter_mut().enumerate() {
                *a = i;
            }
        }
        let input = StepInput {
            k,
            y,
            src: &front,
            ancestors: &ancestors,
        };
        let mut out = StepOutput {
            dst: &mut back,
            log_w: &mut log_w,
        };
        if let Err(e) = filter.step(&input, &mut out, rng) {
            failure = Some(e);
            break;
        }
        std::mem::swap(&mut front, &mut back);
        let s = match normalise_log_weights(&mut log_w, &mut w, k, &mut health_extra) {
            Ok(s) => s,
            Err(e) => {
                failure = Some(e);
                break;
            }
        };
        pending = config.resampling.should_resample(s.ess, np);
        loglik += s.loglik_increment;
        ess_min = ess_min.min(s.ess);
        ess_sum += s.ess;
        done = k;
        let info = StepInfo {
            k,
            loglik_increment: s.loglik_increment,
            ess: s.ess,
            resampled: pending,
        };
        if observer.wants_posterior(k) {
            fill_posterior(&layout, &w, &front, &mut post);
        }
        observer.on_step(&info, &post);
    }
    // The weighted set of the last step, when the run completed (after a failure the weights of
    // the failing step are not a posterior).
    if done > 0 && failure.is_none() {
        observer.on_finish(&WeightedParticles {
            layout: &layout,
            w: &w,
            particles: &front,
            bounds: filter.lower_bounds(),
        });
    }
    let mut health = filter.health();
    health.absorb(&health_extra);
    RunSummary {
        steps_completed: done,
        loglik,
        ess_min: (done > 0).then_some(ess_min),
        ess_mean: (done > 0).then(|| ess_sum / done as f64),
        failure,
        health,
    }
}

#[cfg(test)]
mod correlation_tests {
    use super::*;
    use crate::smc::store::{Particles, Shape};

    /// Two particles, one sampled entry and a two-dimensional marginal Gaussian each: the
    /// correlation is the mixture's, written out by hand.
    #[test]
    fn the_correlation_is_the_weighted_mixtures() {
        let mut p = Particles::new(
            2,
            Shape {
                sampled: 1,
                marginal: 2,
            },
        );
        let blocks = [
            (1.0, [0.0, 1.0], [1.0, 0.5, 0.5, 2.0]),
            (3.0, [2.0, -1.0], [0.5, -0.2, -0.2, 1.0]),
        ];
        for (i, (s, m, c)) in blocks.iter().enumerate() {
            let q = p.particle_mut(i);
            q.sampled[0] = *s;
            q.mean.copy_from_slice(m);
            q.cov.copy_from_slice(c);
        }
        let w = [0.25, 0.75];
        let slots = [Slot::Sampled(0), Slot::Marginal(0), Slot::Marginal(1)];
        let r = slot_correlation(&slots, &w, &p);
        // Means: s 2.5, a 1.5, b −0.5.
        let (ms, ma, mb): (f64, f64, f64) = (2.5, 1.5, -0.5);
        let var_s = 0.25 * (1.0 - ms).powi(2) + 0.75 * (3.0 - ms).powi(2);
        let var_a = 0.25 * (1.0 + (0.0 - ma).powi(2)) + 0.75 * (0.5 + (2.0 - ma).powi(2));
        let var_b = 0.25 * (2.0 + (1.0 - mb).powi(2)) + 0.75 * (1.0 + (-1.0 - mb).powi(2));
        let cov_sa = 0.25 * (1.0 - ms) * (0.0 - ma) + 0.75 * (3.0 - ms) * (2.0 - ma);
        let cov_sb = 0.25 * (1.0 - ms) * (1.0 - mb) + 0.75 * (3.0 - ms) * (-1.0 - mb);
        let cov_ab =
            0.25 * (0.5 + (0.0 - ma) * (1.0 - mb)) + 0.75 * (-0.2 + (2.0 - ma) * (-1.0 - mb));
        let (r_sa, r_sb, r_ab) = (
            cov_sa / (var_s * var_a).sqrt(),
            cov_sb / (var_s * var_b).sqrt(),
            cov_ab / (var_a * var_b).sqrt(),
        );
        let want = [1.0, r_sa, r_sb, r_sa, 1.0, r_ab, r_sb, r_ab, 1.0];
        for (k, (got, want)) in r.iter().zip(want).enumerate() {
            assert!((got - want).abs() < 1e-12, "entry {k}: {got} vs {want}");
        }
        // A parameter of no variance is uncorrelated with the others.
        let one = Particles::new(
            1,
            Shape {
                sampled: 1,
                marginal: 0,
            },
        );
        assert_eq!(
            slot_correlation(&[Slot::Sampled(0)], &[1.0], &one),
            vec![1.0]
        );
        let r0 = slot_correlation(&[Slot::Sampled(0), Slot::Marginal(0)], &w, &{
            let mut q = Particles::new(
                2,
                Shape {
                    sampled: 1,
                    marginal: 1,
                },
            );
            for i in 0..2 {
                let b = q.particle_mut(i);
                b.sampled[0] = 7.0;
                b.mean[0] = i as f64;
                b.cov[0] = 1.0;
            }
            q
        });
        assert_eq!(r0, vec![1.0, 0.0, 0.0, 1.0]);
    }
}
