//! The bootstrap particle filter on an augmented state (SPEC §5.1, the paper's Algorithm 1).
//!
//! Each particle is a full augmented state `x = [states; θ]`. Per step: propagate every particle
//! with the model's deterministic map plus diagonal Gaussian process noise (entries with s.d.
//! zero, such as static parameters, are copied exactly), weight by `N(y_k; measure(k, x_k), R)`,
//! normalise, and decide whether to resample. The resampling decided at step `k` is carried out
//! at the start of step `k + 1`, so that the weighted set of step `k` is what
//! [`ParticleFilter::posterior`] summarises.
//!
//! Failure policy: `R` is factorised once, in [`BootstrapPf::new`]; if it is not positive
//! definite (even after the documented repair of [`cholesky_repaired`]) every `step` returns that
//! typed error. A non-finite particle log-likelihood is mapped to −∞ (and counted) by the weight
//! routine; if no weight is left, `step` returns [`FilterError::AllWeightsZero`].

use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::{
    distinct_sampled, fill_posterior, gather, ParticleConfig, ParticleFilter, Posterior, StepInfo,
    WeightedSet,
};
use crate::error::FilterError;
use crate::health::Health;
use crate::kalman::FactoredCov;
use crate::model::{Layout, StateSpace};

/// Bootstrap PF (SPEC §5.1) for a model with an `NX`-dimensional augmented state and `NY`
/// measurements. All buffers are allocated in [`BootstrapPf::new`]; `step` allocates nothing.
pub struct BootstrapPf<M, const NX: usize, const NY: usize>
where
    M: StateSpace<NX, NY>,
{
    model: M,
    config: ParticleConfig,
    layout: Layout,
    /// Particles `x_k^i` (current buffer) and the gather target of resampling.
    x: Vec<SVector<f64, NX>>,
    x_next: Vec<SVector<f64, NX>>,
    /// Weights and the resampling bookkeeping.
    set: WeightedSet,
    /// Process-noise standard deviations (diagonal `Q`), read once from the model.
    noise_sd: SVector<f64, NX>,
    /// The constant `R` factorised once, or the error that prevented it.
    r_noise: Result<FactoredCov<NY>, FilterError>,
    /// Repairs made while factorising `R` in `new`; a re-initialisation starts from these.
    setup_health: Health,
    health: Health,
}

impl<M, const NX: usize, const NY: usize> BootstrapPf<M, NX, NY>
where
    M: StateSpace<NX, NY>,
{
    /// Allocates every buffer for `config.particles` particles and factorises `R` once.
    ///
    /// # Panics
    /// If `config.particles == 0` (a programmer error).
    #[track_caller]
    pub fn new(model: M, config: ParticleConfig) -> Self {
        let np = config.particles;
        let set = WeightedSet::new(&config);
        let mut health = Health::default();
        let r_noise = FactoredCov::new(
            &model.measurement_cov(),
            "measurement covariance R",
            &mut health,
        );
        Self {
            layout: model.layout(),
            noise_sd: model.process_noise_sd(),
            r_noise,
            x: vec![SVector::zeros(); np],
            x_next: vec![SVector::zeros(); np],
            set,
            setup_health: health,
            health,
            config,
            model,
        }
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    /// The particles of the current step (weighted by [`Self::weights`]).
    pub fn particles_state(&self) -> &[SVector<f64, NX>] {
        &self.x
    }

    /// The normalised weights of the current step.
    pub fn weights(&self) -> &[f64] {
        &self.set.w
    }
}

impl<M, const NX: usize, const NY: usize> ParticleFilter<NY> for BootstrapPf<M, NX, NY>
where
    M: StateSpace<NX, NY>,
{
    fn name(&self) -> &'static str {
        "bootstrap"
    }

    fn particles(&self) -> usize {
        self.config.particles
    }

    /// Draws `x_0^i` from the model's prior, sets uniform weights and resets the counters to
    /// the repairs made in `new` (factorising `R`).
    fn initialise<G: Rng + ?Sized>(&mut self, rng: &mut G) {
        for xi in self.x.iter_mut() {
            *xi = self.model.sample_initial(rng);
        }
        self.set.reset();
        self.health = self.setup_health;
    }

    /// SPEC §5.1: resample (if decided at `k − 1`), propagate with noise, weight, normalise.
    fn step<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
    ) -> Result<StepInfo, FilterError> {
        let r_noise = match &self.r_noise {
            Ok(r) => *r,
            Err(e) => return Err(e.clone()),
        };
        if let Some(ancestors) = self.set.take_pending(rng, &mut self.health) {
            gather(&self.x, ancestors, &mut self.x_next);
            std::mem::swap(&mut self.x, &mut self.x_next);
        }
        for (xi, lw) in self.x.iter_mut().zip(self.set.log_w.iter_mut()) {
            let mut xn = self.model.propagate(k, xi);
            for j in 0..NX {
                let sd = self.noise_sd[j];
                // Zero s.d. means an exactly copied entry (static parameter): draw nothing.
                if sd != 0.0 {
                    let e: f64 = StandardNormal.sample(rng);
                    xn[j] += sd * e;
                }
            }
            *xi = xn;
            let residual = y - self.model.measure(k, xi);
            *lw += r_noise.log_density(&residual);
        }
        self.set.conclude(k, &mut self.health)
    }

    fn posterior(&self, out: &mut Posterior) {
        let none_mu: &[SVector<f64, 0>] = &[];
        let none_cov: &[SMatrix<f64, 0, 0>] = &[];
        fill_posterior(&self.layout, &self.set.w, &self.x, none_mu, none_cov, out);
    }

    fn layout(&self) -> &Layout {
        &self.layout
    }

    fn health(&self) -> Health {
        self.health
    }

    fn distinct_sampled_params(&self) -> Vec<(String, usize)> {
        distinct_sampled(&self.layout, &self.x)
    }
}
