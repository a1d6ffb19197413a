//! The marginalised (Rao–Blackwellised) particle filter for mixed linear/nonlinear models,
//! MLN-RBPF (SPEC §5.2; Schön, Gustafsson & Nordlund 2005 with `G = I`, `g = 0`).
//!
//! Each particle carries the sampled block `u` and a Gaussian `N(μ, C)` over the static block
//! `z`. Per particle and step, with `(f, F_L) = transition(k, u_{k−1})` and `L` the linked rows:
//! - (a) proposal with `z` marginalised: linked rows `u_L ~ N(f_L + F_L μ, F_L C F_Lᵀ + Q_L)`,
//!   the other rows `f + noise` (they do not depend on `z`);
//! - (b) pseudo-measurement update of `(μ, C)` with `u_L` (Jacobian `F_L`, noise `Q_L`). Its
//!   innovation covariance is the proposal covariance of (a), factorised once; with
//!   `u_L = mean + C ξ` the whitened innovation is the draw `ξ` itself
//!   ([`UpdateFactor::condition_on_draw`]);
//! - (c) weight `N(y_k; H μ + h, H C Hᵀ + R)` with `(h, H) = observation(k, u_k)`, which is the
//!   log-likelihood returned by (d), so (c) and (d) are one [`kf_update`] call;
//! - (d) measurement update of `(μ, C)` with `y_k`;
//! - (e) normalise; posterior from the weighted mixture; resample `(u, μ, C)` jointly (carried out
//!   at the start of the next step).
//!
//! Failure policy: a particle whose proposal covariance cannot be factorised even after the
//! documented repair (counted in `health.cholesky_failures`) or whose Kalman update fails
//! (non-finite innovation or result) gets a NaN log-weight, which the weight routine maps to −∞
//! and counts in `health.nan_weights`; the step fails with [`FilterError::AllWeightsZero`] only
//! if no particle survives (e.g. a NaN measurement).

use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::{MarginalParticles, ParticleConfig, ParticleFilter, Posterior, StepInfo, WeightedSet};
use crate::error::FilterError;
use crate::health::Health;
use crate::kalman::{kf_update, UpdateFactor};
use crate::model::{ConditionallyLinear, Layout};

/// A vector of `N` independent standard normal draws.
pub(crate) fn standard_normal<const N: usize, G: Rng + ?Sized>(rng: &mut G) -> SVector<f64, N> {
    SVector::from_fn(|_, _| StandardNormal.sample(rng))
}

/// The linked-row set of a [`ConditionallyLinear`] model in the forms the filters need: the
/// indices, a membership mask over `u`, and `Q_L = diag(sd_L²)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LinkedRows<const NU: usize, const NL: usize> {
    pub rows: [usize; NL],
    pub is_linked: [bool; NU],
    pub q_l: SMatrix<f64, NL, NL>,
}

impl<const NU: usize, const NL: usize> LinkedRows<NU, NL> {
    #[track_caller]
    pub fn new(rows: [usize; NL], noise_sd: &SVector<f64, NU>) -> Self {
        let mut is_linked = [false; NU];
        let mut q_l = SMatrix::<f64, NL, NL>::zeros();
        for (l, &r) in rows.iter().enumerate() {
            assert!(r < NU, "linked row {r} out of range (NU = {NU})");
            assert!(!is_linked[r], "linked row {r} listed twice");
            is_linked[r] = true;
            q_l[(l, l)] = noise_sd[r] * noise_sd[r];
        }
        Self {
            rows,
            is_linked,
            q_l,
        }
    }

    /// The linked entries of a full `NU` vector.
    #[inline]
    pub fn pick(&self, v: &SVector<f64, NU>) -> SVector<f64, NL> {
        SVector::from_fn(|l, _| v[self.rows[l]])
    }

    /// Adds process noise to the rows of `u` that are not linked (entries with s.d. zero are
    /// copied exactly and consume no draw).
    #[inline]
    pub fn add_unlinked_noise<G: Rng + ?Sized>(
        &self,
        u: &mut SVector<f64, NU>,
        noise_sd: &SVector<f64, NU>,
        rng: &mut G,
    ) {
        for j in 0..NU {
            let sd = noise_sd[j];
            if !self.is_linked[j] && sd != 0.0 {
                let e: f64 = StandardNormal.sample(rng);
                u[j] += sd * e;
            }
        }
    }

    /// Writes the linked entries `v_L` into `u`.
    #[inline]
    pub fn scatter(&self, u: &mut SVector<f64, NU>, v: &SVector<f64, NL>) {
        for (l, &r) in self.rows.iter().enumerate() {
            u[r] = v[l];
        }
    }
}

/// MLN-RBPF (SPEC §5.2) for `u ∈ R^NU`, `z ∈ R^NZ`, `NL` linked rows and `NY` measurements.
/// All buffers are allocated in [`MlnRbpf::new`]; `step` allocates nothing.
pub struct MlnRbpf<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    model: M,
    config: ParticleConfig,
    layout: Layout,
    /// Sampled blocks and Gaussians of the marginalised block, double-buffered.
    p: MarginalParticles<NU, NZ>,
    /// Weights and the resampling bookkeeping.
    set: WeightedSet,
    noise_sd: SVector<f64, NU>,
    linked: LinkedRows<NU, NL>,
    r: SMatrix<f64, NY, NY>,
    health: Health,
}

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
    MlnRbpf<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    /// Allocates every buffer for `config.particles` particles.
    ///
    /// # Panics
    /// If `config.particles == 0` or the model's linked rows are out of range or repeated
    /// (programmer errors).
    #[track_caller]
    pub fn new(model: M, config: ParticleConfig) -> Self {
        let np = config.particles;
        assert!(np > 0, "a particle filter needs at least one particle");
        let noise_sd = model.process_noise_sd();
        Self {
            layout: model.layout(),
            linked: LinkedRows::new(model.linked_rows(), &noise_sd),
            r: model.measurement_cov(),
            noise_sd,
            p: MarginalParticles::new(np),
            set: WeightedSet::new(&config),
            health: Health::default(),
            config,
            model,
        }
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    /// The sampled blocks of the current step.
    pub fn sampled(&self) -> &[SVector<f64, NU>] {
        &self.p.sampled
    }

    /// The per-particle means `μ^i` of `z`.
    pub fn means(&self) -> &[SVector<f64, NZ>] {
        &self.p.mu
    }

    /// The per-particle covariances `C^i` of `z`.
    pub fn covariances(&self) -> &[SMatrix<f64, NZ, NZ>] {
        &self.p.cov
    }

    /// The normalised weights of the current step.
    pub fn weights(&self) -> &[f64] {
        &self.set.w
    }
}

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize> ParticleFilter<NY>
    for MlnRbpf<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    fn name(&self) -> &'static str {
        "mln-rbpf"
    }

    fn particles(&self) -> usize {
        self.config.particles
    }

    /// Draws `u_0^i` and `(μ_0^i, C_0^i)` from the model's priors, uniform weights, counters
    /// reset.
    fn initialise<G: Rng + ?Sized>(&mut self, rng: &mut G) {
        let model = &self.model;
        self.p.initialise(rng, |rng| {
            let u = model.sample_initial(rng);
            let (mu, cov) = model.sample_marginal_prior(rng);
            (u, mu, cov)
        });
        self.set.reset();
        self.health = Health::default();
    }

    /// SPEC §5.2 (a)–(e) for every particle; see the module documentation.
    #[allow(non_snake_case)]
    fn step<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
    ) -> Result<StepInfo, FilterError> {
        self.p
            .resample_pending(&mut self.set, rng, &mut self.health);
        let linked = &self.linked;
        for i in 0..self.config.particles {
            let (mu, cov, health) = (&mut self.p.mu[i], &mut self.p.cov[i], &mut self.health);
            let (f, F_L) = self.model.transition(k, &self.p.sampled[i]);
            let mut u_new = f;
            linked.add_unlinked_noise(&mut u_new, &self.noise_sd, rng);
            // (a) the linked rows with z marginalised: N(f_L + F_L μ, S), S = F_L C F_Lᵀ + Q_L.
            // S is also the innovation covariance of (b): (b) u_L observes z through F_L.
            let mean_l = linked.pick(&f) + F_L * *mu;
            let drawn =
                UpdateFactor::new(cov, &F_L, &linked.q_l, k, "MLN proposal covariance", health)
                    .and_then(|factor| {
                        let xi = standard_normal::<NL, G>(rng);
                        factor.condition_on_draw(mu, cov, &mean_l, &xi, k)
                    });
            if let Ok(u_l) = &drawn {
                linked.scatter(&mut u_new, u_l);
            }
            self.p.sampled[i] = u_new;
            if drawn.is_err() {
                self.set.log_w[i] = f64::NAN;
                continue;
            }
            // (c) + (d): the KF update's log-likelihood is log N(y; H μ + h, H C Hᵀ + R).
            let (h, H) = self.model.observation(k, &u_new);
            match kf_update(mu, cov, y, &H, &h, &self.r, k, health) {
                Ok(inn) => self.set.log_w[i] += inn.loglik,
                Err(_) => self.set.log_w[i] = f64::NAN,
            }
        }
        // (e)
        self.set.conclude(k, &mut self.health)
    }

    fn posterior(&self, out: &mut Posterior) {
        self.p.posterior(&self.layout, &self.set.w, out);
    }

    fn layout(&self) -> &Layout {
        &self.layout
    }

    fn health(&self) -> Health {
        self.health
    }

    fn distinct_sampled_params(&self) -> Vec<(String, usize)> {
        self.p.distinct_sampled(&self.layout)
    }
}
