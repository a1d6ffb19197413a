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
//!   at the start of the next step; `(μ, C)` are read from the ancestor where they are and the
//!   updated ones written to the other buffer).
//!
//! Speed, with results unchanged to the bit: the particles go through the step four at a time.
//! The factors of their proposal covariances are computed side by side in SIMD lanes, the draws
//! are taken particle by particle in order, then (b)–(d) run for the four in lanes
//! ([`crate::kalman::lanes`]), each lane doing the scalar update's operations in its order. A
//! particle the lanes cannot take (its scalar update would need the documented repair, or fail)
//! takes the scalar code, which counts and reports it. [`MlnRbpf::without_lanes`] runs every
//! particle through the scalar code; the tests check that it gives the same bits.
//!
//! Failure policy: a particle whose proposal covariance cannot be factorised even after the
//! documented repair (counted in `health.cholesky_failures`) or whose Kalman update fails
//! (non-finite innovation or result) gets a NaN log-weight, which the weight routine maps to −∞
//! and counts in `health.nan_weights`; the step fails with [`FilterError::AllWeightsZero`] only
//! if no particle survives (e.g. a NaN measurement).

use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::lane_group::LaneMoments;
use super::{MarginalParticles, ParticleConfig, ParticleFilter, Posterior, StepInfo, WeightedSet};
use crate::error::FilterError;
use crate::health::Health;
use crate::kalman::kf::{all_finite, whitened_loglik};
use crate::kalman::lanes::{
    gather_mat, gather_vec, gaussian_update, get_lane_mat, get_lane_vec, lane, mul_vec, LaneFactor,
    LaneMat, LaneVec, LANES,
};
use crate::kalman::{kf_update, UpdateFactor};
use crate::model::{ConditionallyLinear, Layout};
use wide::f64x4;

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
    /// Scratch of the four particles processed together.
    group: Box<MlnGroup<NU, NZ, NL, NY>>,
    /// Which particle's moments each particle starts the step from (see
    /// [`MarginalParticles::resample_sampled_only`]).
    source: Vec<usize>,
    /// Whether (b)–(d) run in lanes: `Q_L` and `R` must be exactly symmetric (the scalar update
    /// symmetrises them otherwise), and [`MlnRbpf::without_lanes`] was not asked for.
    use_lanes: bool,
}

/// Scratch of one lane group of the MLN-RBPF.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
struct MlnGroup<const NU: usize, const NZ: usize, const NL: usize, const NY: usize> {
    moments: LaneMoments<NZ>,
    F_L: LaneMat<NL, NZ>,
    xi: LaneVec<NL>,
    H: LaneMat<NY, NZ>,
    h: LaneVec<NY>,
    /// Whether each lane's particle was drawn for (b)–(d) in lanes (otherwise it failed, or the
    /// scalar code has updated it already).
    in_lanes: [bool; LANES],
    /// Per particle: `f` and `F_L` of the transition, the proposal mean, the draw and the
    /// observation `(h, H)`, kept for the scalar update should the lanes decline the particle.
    f: [SVector<f64, NU>; LANES],
    F_L_of: [SMatrix<f64, NL, NZ>; LANES],
    mean_l: [SVector<f64, NL>; LANES],
    /// `u_k` before the draw of its linked rows is written into it.
    u_drawless: [SVector<f64, NU>; LANES],
    xi_of: [SVector<f64, NL>; LANES],
    h_of: [SVector<f64, NY>; LANES],
    H_of: [SMatrix<f64, NY, NZ>; LANES],
}

impl<const NU: usize, const NZ: usize, const NL: usize, const NY: usize> Default
    for MlnGroup<NU, NZ, NL, NY>
{
    fn default() -> Self {
        Self {
            moments: LaneMoments::default(),
            F_L: [[f64x4::ZERO; NL]; NZ],
            xi: [f64x4::ZERO; NL],
            H: [[f64x4::ZERO; NY]; NZ],
            h: [f64x4::ZERO; NY],
            in_lanes: [false; LANES],
            f: [SVector::zeros(); LANES],
            F_L_of: [SMatrix::zeros(); LANES],
            mean_l: [SVector::zeros(); LANES],
            u_drawless: [SVector::zeros(); LANES],
            xi_of: [SVector::zeros(); LANES],
            h_of: [SVector::zeros(); LANES],
            H_of: [SMatrix::zeros(); LANES],
        }
    }
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
        let linked = LinkedRows::new(model.linked_rows(), &noise_sd);
        let r = model.measurement_cov();
        Self {
            layout: model.layout(),
            use_lanes: r == r.transpose() && linked.q_l == linked.q_l.transpose(),
            linked,
            r,
            noise_sd,
            p: MarginalParticles::new(np),
            set: WeightedSet::new(&config),
            health: Health::default(),
            group: Box::default(),
            source: vec![0; np],
            config,
            model,
        }
    }

    /// Every particle's steps (a)–(d) by the scalar updates, one particle at a time. The lanes
    /// give the same results to the bit; this is the reference they are tested against.
    pub fn without_lanes(mut self) -> Self {
        self.use_lanes = false;
        self
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

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
    MlnRbpf<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    /// SPEC §5.2 (a)–(d) for the `count ≤ 4` particles from `first` on, with the results of
    /// (a)–(d) particle by particle to the bit: the factors of the proposal covariances in
    /// lanes, the draws particle by particle in order, then (b)–(d) in lanes. A particle the
    /// lanes cannot take (its scalar update would need the documented repair, or fail) takes
    /// the scalar code, which counts and reports it.
    #[allow(non_snake_case)]
    fn step_group<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
        first: usize,
        count: usize,
    ) {
        let linked = &self.linked;
        let g = &mut self.group;
        let source = &self.source;
        let (sampled, src_mu, src_cov, dst_mu, dst_cov) = self.p.moments_split();
        // Lanes past the last particle repeat the group's first one and are discarded.
        let member = |b: usize| if b < count { b } else { 0 };
        for b in 0..count {
            (g.f[b], g.F_L_of[b]) = self.model.transition(k, &sampled[first + b]);
        }
        g.moments
            .gather(src_mu, src_cov, &source[first..first + count]);
        gather_mat(&mut g.F_L, std::array::from_fn(|b| &g.F_L_of[member(b)]));
        // (a)+(b): the innovation covariance of (b) is the proposal covariance of (a).
        let (proposal, straight) = if self.use_lanes {
            LaneFactor::new(&g.moments.cov, &g.F_L, &linked.q_l)
        } else {
            (LaneFactor::default(), f64x4::ZERO)
        };
        for b in 0..count {
            let i = first + b;
            let (mu, cov, health) = (&src_mu[source[i]], &src_cov[source[i]], &mut self.health);
            let F_L = &g.F_L_of[b];
            let mut u_new = g.f[b];
            linked.add_unlinked_noise(&mut u_new, &self.noise_sd, rng);
            // (a) the linked rows with z marginalised: N(f_L + F_L μ, S), S = F_L C F_Lᵀ + Q_L.
            let mean_l = linked.pick(&g.f[b]) + F_L * *mu;
            g.in_lanes[b] = false;
            if !lane(straight, b) {
                // The scalar path, in place on the particle's new moments.
                let (mu, cov) = (&mut dst_mu[i], &mut dst_cov[i]);
                (*mu, *cov) = (src_mu[source[i]], src_cov[source[i]]);
                let scalar = Scalar {
                    model: &self.model,
                    linked,
                    r: &self.r,
                    k,
                    y,
                };
                let draw = || standard_normal::<NL, G>(rng);
                let (u, loglik) = scalar.particle(mu, cov, u_new, &mean_l, F_L, health, draw);
                sampled[i] = u;
                self.set.log_w[i] = loglik.map_or(f64::NAN, |l| self.set.log_w[i] + l);
                continue;
            }
            let xi = standard_normal::<NL, G>(rng);
            let drawn = mean_l + proposal.chol(b) * xi;
            if !all_finite(&drawn) {
                // As `UpdateFactor::condition_on_draw`: the moments stay as they were.
                sampled[i] = u_new;
                (dst_mu[i], dst_cov[i]) = (*mu, *cov);
                self.set.log_w[i] = f64::NAN;
                continue;
            }
            g.u_drawless[b] = u_new;
            linked.scatter(&mut u_new, &drawn);
            sampled[i] = u_new;
            (g.h_of[b], g.H_of[b]) = self.model.observation(k, &u_new);
            (g.mean_l[b], g.xi_of[b]) = (mean_l, xi);
            g.in_lanes[b] = true;
        }
        let lanes_taken: [bool; LANES] = std::array::from_fn(|b| b < count && g.in_lanes[b]);
        if !lanes_taken.contains(&true) {
            return;
        }
        // (b) with the whitened innovation ξ, then (c)+(d), in lanes.
        gather_vec(&mut g.xi, std::array::from_fn(|b| &g.xi_of[member(b)]));
        gather_mat(&mut g.H, std::array::from_fn(|b| &g.H_of[member(b)]));
        gather_vec(&mut g.h, std::array::from_fn(|b| &g.h_of[member(b)]));
        let m = &mut g.moments;
        let conditioned = proposal.apply_whitened(&mut m.mu, &mut m.cov, &g.xi);
        let h_mu = mul_vec(&g.H, &m.mu);
        let residual: LaneVec<NY> =
            std::array::from_fn(|r| f64x4::splat(y[r]) - (h_mu[r] + g.h[r]));
        let (updated, chol, e) = gaussian_update(&mut m.mu, &mut m.cov, &residual, &g.H, &self.r);
        let ok = straight & conditioned & updated;
        let take: [bool; LANES] = std::array::from_fn(|b| lanes_taken[b] && lane(ok, b));
        let group = first..first + count;
        m.write_back(take, &mut dst_mu[group.clone()], &mut dst_cov[group]);
        for b in 0..count {
            let i = first + b;
            if take[b] {
                let (e, chol) = (get_lane_vec(&e, b), get_lane_mat(&chol, b));
                self.set.log_w[i] += whitened_loglik(&e, &chol);
            } else if lanes_taken[b] {
                // The scalar (b)–(d) from the particle's moments and its draw (no repair: the
                // lanes' factor took the straight path, and the scalar one is the same).
                let (mu, cov) = (&mut dst_mu[i], &mut dst_cov[i]);
                (*mu, *cov) = (src_mu[source[i]], src_cov[source[i]]);
                let scalar = Scalar {
                    model: &self.model,
                    linked,
                    r: &self.r,
                    k,
                    y,
                };
                let (u_drawless, mean_l, F_L) = (g.u_drawless[b], &g.mean_l[b], &g.F_L_of[b]);
                let draw = || g.xi_of[b];
                let (u, loglik) =
                    scalar.particle(mu, cov, u_drawless, mean_l, F_L, &mut self.health, draw);
                sampled[i] = u;
                self.set.log_w[i] = loglik.map_or(f64::NAN, |l| self.set.log_w[i] + l);
            }
        }
    }
}

/// What the scalar path of one MLN-RBPF particle needs besides the particle.
struct Scalar<'a, M, const NU: usize, const NL: usize, const NY: usize> {
    model: &'a M,
    linked: &'a LinkedRows<NU, NL>,
    r: &'a SMatrix<f64, NY, NY>,
    k: usize,
    y: &'a SVector<f64, NY>,
}

impl<M, const NU: usize, const NL: usize, const NY: usize> Scalar<'_, M, NU, NL, NY> {
    /// SPEC §5.2 (a)–(d) of one particle by the scalar code, in place on `(μ, C)`: the proposal
    /// factor (with the documented repair), `ξ` from `draw` (the generator on the particle's
    /// turn, its stored draw when the lanes declined it), (b), then (c)+(d). Returns `u_k` (its
    /// linked rows are the draw only if (b) succeeded) and the log-likelihood, `None` on failure.
    #[allow(clippy::too_many_arguments, non_snake_case)]
    fn particle<const NZ: usize>(
        &self,
        mu: &mut SVector<f64, NZ>,
        cov: &mut SMatrix<f64, NZ, NZ>,
        mut u_new: SVector<f64, NU>,
        mean_l: &SVector<f64, NL>,
        F_L: &SMatrix<f64, NL, NZ>,
        health: &mut Health,
        draw: impl FnOnce() -> SVector<f64, NL>,
    ) -> (SVector<f64, NU>, Option<f64>)
    where
        M: ConditionallyLinear<NU, NZ, NL, NY>,
    {
        let (k, linked) = (self.k, self.linked);
        let drawn = UpdateFactor::new(cov, F_L, &linked.q_l, k, "MLN proposal covariance", health)
            .and_then(|factor| factor.condition_on_draw(mu, cov, mean_l, &draw(), k));
        let Ok(u_l) = drawn else {
            return (u_new, None);
        };
        linked.scatter(&mut u_new, &u_l);
        // (c) + (d): the KF update's log-likelihood is log N(y; H μ + h, H C Hᵀ + R).
        let (h, H) = self.model.observation(k, &u_new);
        let loglik = kf_update(mu, cov, self.y, &H, &h, self.r, k, health).map(|inn| inn.loglik);
        (u_new, loglik.ok())
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
            .resample_sampled_only(&mut self.set, rng, &mut self.health, &mut self.source);
        let np = self.config.particles;
        for first in (0..np).step_by(LANES) {
            self.step_group(k, y, rng, first, (np - first).min(LANES));
        }
        self.p.swap_moments();
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
