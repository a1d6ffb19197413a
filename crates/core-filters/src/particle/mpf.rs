//! MPF-EKF2: the marginalised particle filter with second-order EKF blocks (SPEC §5.4, with the
//! exact derivatives of §6).
//!
//! The state splits into a small sampled block `xⁿ` (particles; its first `ND` entries evolve,
//! the others are static and copied) and a marginalised block `x^bl` carried per particle as a
//! Gaussian `N(m, P)`. Given `xⁿ`, every map is at most quadratic in `x^bl`, so the EKF2 moments
//! (SPEC §4) are exact moments of the maps of the Gaussian.
//!
//! One step `k` processes each particle `(xⁿ_{k−1}, m, P)` as follows (SPEC §5.4):
//! - (a) proposal: `xⁿ_k[0..ND] ~ N(ψₙ(m) + ½tr(𝓗ⁱP), Jₙ P Jₙᵀ + ½tr(𝓗ⁱP𝓗^{i'}P) + Qₙ)`;
//!   static entries copied;
//! - (b) EKF2 update of `x^bl_{k−1}` with the pseudo-measurement `xⁿ_k[0..ND]` (same moments);
//! - (c) EKF2 propagate of `x^bl` through `φ_bl(xⁿ_{k−1}, ·)` (evaluated at the updated `m`);
//! - (d)+(e) EKF2 update with `y_k` at `xⁿ_k`; its log-likelihood `log N(y_k; ŷ, L)` is added to
//!   the particle's log-weight.
//!
//! Then the weights are normalised with the one weight routine and resampling is decided. The
//! resampling decided at step `k` is carried out at the start of step `k + 1`, so the weighted
//! set of step `k` is what [`ParticleFilter::posterior`] sees (SPEC §5 (e): estimate, then
//! resample).
//!
//! Failure policy: a non-finite measurement ends the step with
//! [`FilterError::NonFinite`] (`which = "measurement"`). A numerical failure inside one particle's
//! Gaussian computations (a covariance that cannot be factorised even after the repair of
//! [`cholesky_repaired`], or a non-finite result) gives that particle a NaN log-weight, which the
//! weight routine maps to −∞ and counts in [`Health::nan_weights`]; the particle then has weight
//! zero and is never chosen as an ancestor. If every particle fails the step returns
//! [`FilterError::AllWeightsZero`]. A particle whose weight is already zero (possible with an ESS
//! threshold) is not advanced: its weight stays zero whatever it would compute.
//!
//! Performance (SPEC §4, §6): the Jacobian of `φ_bl` is the identity plus a few entries for the
//! Bouc–Wen chain and the other Jacobians are sparse. The default [`MpfKernel::Sparse`] therefore
//! (i) propagates `P` with `J P Jᵀ = (I + D) P (I + D)ᵀ` visiting only the non-zero entries of
//! `D = J − I` ([`ekf2_propagate_near_identity`]); (ii) fuses the proposal draw (a) with the
//! pseudo-measurement update (b), whose innovation covariance is the proposal covariance, so
//! `Jₙ P`, its Cholesky factor and the whitened innovation (the standard normal draw itself) are
//! computed once ([`UpdateFactor`]). The measurement update (d) is [`ekf2_update`] on both paths
//! (the shared Gaussian update already visits only the non-zeros of `J`). [`MpfKernel::Dense`]
//! forms the proposal covariance with dense products, samples, then calls [`gaussian_update`],
//! and propagates with the dense [`ekf2_propagate`]; it is the reference the sparse kernel is
//! tested against (same random draws, results equal to round-off).

use nalgebra::{SMatrix, SVector};
use rand::Rng;

use super::mlnrbpf::standard_normal;
use super::{MarginalParticles, Posterior, StepInfo, WeightedSet};
use super::{ParticleConfig, ParticleFilter};
use crate::error::FilterError;
use crate::health::Health;
use crate::kalman::kf::symmetrise;
use crate::kalman::second_order_terms;
use crate::kalman::{
    cholesky_repaired, ekf2_propagate, ekf2_update, gaussian_update, UpdateFactor,
};
use crate::model::{ConditionallyQuadratic, Layout, SparseHessians};

/// Which implementation of the Gaussian steps the filter uses (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MpfKernel {
    /// Sparse, fused steps: cost proportional to the non-zeros of the Jacobians.
    #[default]
    Sparse,
    /// The generic dense Kalman steps of [`crate::kalman`] (reference implementation).
    Dense,
}

/// The moments of the proposal of SPEC §5.4 (a), kept so that the pseudo-measurement update (b)
/// reuses them instead of recomputing the Hessian terms.
#[derive(Debug, Clone, Copy)]
struct Proposal<const ND: usize, const NBL: usize> {
    /// `ψₙ(m) + ½ tr(𝓗ⁱ P)`.
    mean: SVector<f64, ND>,
    /// `∂ψₙ/∂x^bl` at `m`.
    jac: SMatrix<f64, ND, NBL>,
    /// `½ tr(𝓗ⁱ P 𝓗^{i'} P) + Qₙ`: the part of the covariance added to `Jₙ P Jₙᵀ`.
    cov_add: SMatrix<f64, ND, ND>,
}

/// The MPF-EKF2 particle filter (SPEC §5.4). All particle storage is allocated in [`Self::new`];
/// [`ParticleFilter::step`] allocates nothing.
pub struct MpfEkf2<M, const NN: usize, const ND: usize, const NBL: usize, const NY: usize> {
    model: M,
    config: ParticleConfig,
    kernel: MpfKernel,
    layout: Layout,
    /// Weights and the resampling bookkeeping.
    set: WeightedSet,
    /// Sampled blocks and Gaussians of the marginalised block, double-buffered.
    p: MarginalParticles<NN, NBL>,
    /// `Qₙ` (ND×ND, diagonal).
    q_n: SMatrix<f64, ND, ND>,
    /// Diagonal of `Q_bl`.
    q_bl_diag: SVector<f64, NBL>,
    /// `Q_bl` as a matrix, for the dense reference kernel.
    q_bl: SMatrix<f64, NBL, NBL>,
    /// `R`.
    r: SMatrix<f64, NY, NY>,
    health: Health,
}

impl<M, const NN: usize, const ND: usize, const NBL: usize, const NY: usize>
    MpfEkf2<M, NN, ND, NBL, NY>
where
    M: ConditionallyQuadratic<NN, ND, NBL, NY>,
{
    /// Builds the filter and allocates every buffer once. `config.particles` must be positive
    /// (a configuration layer validates user input before this point).
    #[track_caller]
    pub fn new(model: M, config: ParticleConfig) -> Self {
        assert!(config.particles > 0, "MPF-EKF2 needs at least one particle");
        assert!(
            ND <= NN,
            "the dynamic sampled entries are a prefix of xⁿ (ND ≤ NN)"
        );
        let np = config.particles;
        let q_n = SMatrix::<f64, ND, ND>::from_diagonal(&model.sampled_noise_sd().map(|s| s * s));
        let q_bl_diag = model.marginal_noise_sd().map(|s| s * s);
        let q_bl = SMatrix::<f64, NBL, NBL>::from_diagonal(&q_bl_diag);
        let r = model.measurement_cov();
        let layout = model.layout();
        Self {
            set: WeightedSet::new(&config),
            p: MarginalParticles::new(np),
            q_n,
            q_bl_diag,
            q_bl,
            r,
            health: Health::default(),
            kernel: MpfKernel::default(),
            layout,
            config,
            model,
        }
    }

    /// Chooses the implementation of the Gaussian steps (default [`MpfKernel::Sparse`]).
    pub fn with_kernel(mut self, kernel: MpfKernel) -> Self {
        self.kernel = kernel;
        self
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    /// Normalised weights of the current step.
    pub fn weights(&self) -> &[f64] {
        &self.set.w
    }

    /// Sampled block `xⁿ` of every particle.
    pub fn sampled(&self) -> &[SVector<f64, NN>] {
        &self.p.sampled
    }

    /// Means `m` of the marginalised block of every particle.
    pub fn marginal_means(&self) -> &[SVector<f64, NBL>] {
        &self.p.mu
    }

    /// Covariances `P` of the marginalised block of every particle.
    pub fn marginal_covs(&self) -> &[SMatrix<f64, NBL, NBL>] {
        &self.p.cov
    }

    /// SPEC §5.4 (a): mean and covariance of the proposal of the dynamic sampled entries
    /// `xⁿ_k[0..ND]` for a particle at `(xⁿ_{k−1}, N(m, P))`:
    /// `ψₙ(m) + ½ tr(𝓗ⁱ P)` and `Jₙ P Jₙᵀ + ½ tr(𝓗ⁱ P 𝓗^{i'} P) + Qₙ`.
    pub fn proposal_moments(
        &self,
        k: usize,
        x_n: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
        p: &SMatrix<f64, NBL, NBL>,
    ) -> (SVector<f64, ND>, SMatrix<f64, ND, ND>) {
        let prop = proposal(&self.model, &self.q_n, k, x_n, m, p);
        let mut cov = prop.jac * p * prop.jac.transpose() + prop.cov_add;
        symmetrise(&mut cov);
        (prop.mean, cov)
    }
}

/// SPEC §5.4 (a): the proposal moments, with the Hessian terms computed once.
fn proposal<M, const NN: usize, const ND: usize, const NBL: usize, const NY: usize>(
    model: &M,
    q_n: &SMatrix<f64, ND, ND>,
    k: usize,
    x_n: &SVector<f64, NN>,
    m: &SVector<f64, NBL>,
    p: &SMatrix<f64, NBL, NBL>,
) -> Proposal<ND, NBL>
where
    M: ConditionallyQuadratic<NN, ND, NBL, NY>,
{
    let (value, jac) = model.sampled_dynamics(k, x_n, m);
    let hess = model.sampled_hessians();
    let mut mean = value;
    let mut cov_add = *q_n;
    if !hess.is_empty() {
        let mut mean2 = SVector::<f64, ND>::zeros();
        let mut cov2 = SMatrix::<f64, ND, ND>::zeros();
        second_order_terms(hess, p, &mut mean2, &mut cov2);
        mean += mean2;
        cov_add += cov2;
    }
    Proposal { mean, jac, cov_add }
}

/// EKF2 propagate (SPEC §4), `m ← φ(m) + ½ tr(𝓗ⁱ P)`, `P ← J P Jᵀ + ½ tr(𝓗ⁱ P 𝓗^{i'} P) + Q`
/// with diagonal `Q`, specialised for a Jacobian close to the identity: with `D = J − I`,
/// `J P Jᵀ = A + A Dᵀ` where `A = P + D P`, and only the non-zero entries of `D` are visited, so
/// the cost is `2 N nnz(D)` instead of `2 N³` (SPEC §6: `φ_bl` is the identity on the parameters
/// and near-identity on the states). Exactly the same result as [`ekf2_propagate`] up to
/// round-off, for any `J`.
pub fn ekf2_propagate_near_identity<const N: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    value: &SVector<f64, N>,
    jac: &SMatrix<f64, N, N>,
    hess: &SparseHessians,
    q_diag: &SVector<f64, N>,
) {
    // A = (I + D) P: row r of A gains D[r, j] · (row j of P).
    let mut a = *p;
    for j in 0..N {
        for r in 0..N {
            let d = if r == j {
                jac[(r, j)] - 1.0
            } else {
                jac[(r, j)]
            };
            if d != 0.0 {
                for c in 0..N {
                    a[(r, c)] += d * p[(j, c)];
                }
            }
        }
    }
    // B = A (I + D)ᵀ: column r of B gains D[r, j] · (column j of A).
    let mut b = a;
    for j in 0..N {
        for r in 0..N {
            let d = if r == j {
                jac[(r, j)] - 1.0
            } else {
                jac[(r, j)]
            };
            if d != 0.0 {
                for c in 0..N {
                    b[(c, r)] += d * a[(c, j)];
                }
            }
        }
    }
    for i in 0..N {
        b[(i, i)] += q_diag[i];
    }
    if hess.is_empty() {
        *m = *value;
    } else {
        // The Hessian terms use the covariance before propagation.
        let mut mean2 = SVector::<f64, N>::zeros();
        let mut cov2 = SMatrix::<f64, N, N>::zeros();
        second_order_terms(hess, p, &mut mean2, &mut cov2);
        *m = value + mean2;
        b += cov2;
    }
    symmetrise(&mut b);
    *p = b;
}

/// SPEC §5.4 (a) and (b) fused, for the [`MpfKernel::Sparse`] path: with `S = Jₙ P Jₙᵀ + cov_add
/// = C Cᵀ` (the proposal covariance, which is also the innovation covariance of the
/// pseudo-measurement), the draw is `xⁿ = mean + C ξ`, so the whitened innovation
/// `C⁻¹ (xⁿ − mean)` is `ξ` itself ([`UpdateFactor::condition_on_draw`]). Same
/// result as the dense path (sample, then [`gaussian_update`]) up to round-off, with the same
/// random draws; same repair and failure policy.
fn sample_and_update_fused<G: Rng + ?Sized, const ND: usize, const NBL: usize>(
    prop: &Proposal<ND, NBL>,
    m: &mut SVector<f64, NBL>,
    p: &mut SMatrix<f64, NBL, NBL>,
    k: usize,
    rng: &mut G,
    health: &mut Health,
) -> Result<SVector<f64, ND>, FilterError> {
    let factor = UpdateFactor::new(
        p,
        &prop.jac,
        &prop.cov_add,
        k,
        "proposal covariance",
        health,
    )?;
    let xi = standard_normal::<ND, G>(rng);
    factor.condition_on_draw(m, p, &prop.mean, &xi, k)
}

/// Advances one particle through SPEC §5.4 (a)–(e) and returns `log N(y_k; ŷ, L)`.
/// `x_n` is overwritten with `xⁿ_k`; `m`, `p` with the filtered moments of `x^bl_k`.
#[allow(clippy::too_many_arguments)]
fn advance_particle<M, G, const NN: usize, const ND: usize, const NBL: usize, const NY: usize>(
    model: &M,
    kernel: MpfKernel,
    q_n: &SMatrix<f64, ND, ND>,
    q_bl_diag: &SVector<f64, NBL>,
    q_bl: &SMatrix<f64, NBL, NBL>,
    r: &SMatrix<f64, NY, NY>,
    k: usize,
    y: &SVector<f64, NY>,
    x_n: &mut SVector<f64, NN>,
    m: &mut SVector<f64, NBL>,
    p: &mut SMatrix<f64, NBL, NBL>,
    rng: &mut G,
    health: &mut Health,
) -> Result<f64, FilterError>
where
    M: ConditionallyQuadratic<NN, ND, NBL, NY>,
    G: Rng + ?Sized,
{
    // φ_bl and ψₙ take xⁿ_{k−1}: keep it until (c) is done.
    let x_prev = *x_n;

    // (a) Proposal: sample the dynamic entries from the EKF2 moments; static entries copied.
    // (b) Pseudo-measurement update of x^bl_{k−1} with xⁿ_k[0..ND]: the predicted moments are
    // those of (a), so ŷ = prop.mean and the additive covariance is the Hessian term plus Qₙ.
    let prop = proposal(model, q_n, k, &x_prev, m, p);
    let x_dyn = match kernel {
        MpfKernel::Sparse => sample_and_update_fused(&prop, m, p, k, rng, health)?,
        MpfKernel::Dense => {
            let s = prop.jac * *p * prop.jac.transpose() + prop.cov_add;
            let chol = cholesky_repaired(&s, k, "proposal covariance", health)?;
            let x_dyn = prop.mean + chol * standard_normal::<ND, G>(rng);
            gaussian_update(
                m,
                p,
                &x_dyn,
                &prop.mean,
                &prop.jac,
                &prop.cov_add,
                k,
                health,
            )?;
            x_dyn
        }
    };
    let mut x_new = x_prev;
    for d in 0..ND {
        x_new[d] = x_dyn[d];
    }

    // (c) Propagate x^bl through φ_bl(xⁿ_{k−1}, ·) at the updated mean.
    let (phi, jac_bl) = model.marginal_dynamics(k, &x_prev, m);
    match kernel {
        MpfKernel::Sparse => {
            ekf2_propagate_near_identity(m, p, &phi, &jac_bl, model.marginal_hessians(), q_bl_diag)
        }
        MpfKernel::Dense => ekf2_propagate(m, p, &phi, &jac_bl, model.marginal_hessians(), q_bl),
    }
    *x_n = x_new;

    // (d)+(e) EKF2 update with y_k at xⁿ_k; its innovation log-density is the weight factor.
    let (h, jac_y) = model.observation(k, x_n, m);
    let hess_y = model.observation_hessians();
    Ok(ekf2_update(m, p, y, &h, &jac_y, hess_y, r, k, health)?.loglik)
}

impl<M, const NN: usize, const ND: usize, const NBL: usize, const NY: usize> ParticleFilter<NY>
    for MpfEkf2<M, NN, ND, NBL, NY>
where
    M: ConditionallyQuadratic<NN, ND, NBL, NY>,
{
    fn name(&self) -> &'static str {
        "mpf-ekf2"
    }

    fn particles(&self) -> usize {
        self.config.particles
    }

    fn initialise<G: Rng + ?Sized>(&mut self, rng: &mut G) {
        let model = &self.model;
        self.p.initialise(rng, |rng| {
            let x_n = model.sample_initial(rng);
            let (m0, p0) = model.sample_marginal_prior(rng);
            (x_n, m0, p0)
        });
        self.set.reset();
        self.health = Health::default();
    }

    /// SPEC §5.4: resample (as decided at `k − 1`), then (a)–(e) per particle, normalise, decide
    /// resampling. See the module documentation for the failure policy.
    fn step<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
    ) -> Result<StepInfo, FilterError> {
        if y.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::NonFinite {
                step: k,
                which: "measurement",
            });
        }
        self.p
            .resample_pending(&mut self.set, rng, &mut self.health);
        for i in 0..self.config.particles {
            if self.set.log_w[i] == f64::NEG_INFINITY {
                continue;
            }
            let res = advance_particle(
                &self.model,
                self.kernel,
                &self.q_n,
                &self.q_bl_diag,
                &self.q_bl,
                &self.r,
                k,
                y,
                &mut self.p.sampled[i],
                &mut self.p.mu[i],
                &mut self.p.cov[i],
                rng,
                &mut self.health,
            );
            match res {
                Ok(loglik) => self.set.log_w[i] += loglik,
                // Counted as a NaN weight by the weight routine (module docs).
                Err(_) => self.set.log_w[i] = f64::NAN,
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream;
    use rand::Rng;

    fn random_spd<const N: usize>(rng: &mut impl Rng) -> SMatrix<f64, N, N> {
        let a = SMatrix::<f64, N, N>::from_fn(|_, _| rng.random::<f64>() - 0.5);
        a * a.transpose() + SMatrix::<f64, N, N>::identity() * 0.1
    }

    fn compare_kernels<const N: usize>(jac: SMatrix<f64, N, N>, hess: &SparseHessians, seed: u64) {
        let mut rng = stream(seed, 0, "test");
        let p0 = random_spd::<N>(&mut rng);
        let m0 = SVector::<f64, N>::from_fn(|_, _| rng.random::<f64>());
        let value = SVector::<f64, N>::from_fn(|_, _| rng.random::<f64>());
        let q_diag = SVector::<f64, N>::from_fn(|i, _| 0.01 * (i as f64 + 1.0));
        let q = SMatrix::<f64, N, N>::from_diagonal(&q_diag);
        let (mut m1, mut p1) = (m0, p0);
        let (mut m2, mut p2) = (m0, p0);
        ekf2_propagate(&mut m1, &mut p1, &value, &jac, hess, &q);
        ekf2_propagate_near_identity(&mut m2, &mut p2, &value, &jac, hess, &q_diag);
        let scale = p1.abs().max();
        assert!((m1 - m2).abs().max() < 1e-13 * (1.0 + m1.abs().max()));
        assert!((p1 - p2).abs().max() < 1e-13 * scale, "{p1} vs {p2}");
    }

    #[test]
    fn near_identity_kernel_matches_dense_on_sparse_jacobian() {
        let mut jac = SMatrix::<f64, 6, 6>::identity();
        jac[(0, 3)] = 0.005;
        jac[(3, 4)] = -0.02;
        jac[(3, 3)] = 0.97;
        jac[(5, 1)] = 0.3;
        let mut hess = SparseHessians::new();
        hess.push(3, 1, 4, 0.005);
        hess.push(3, 2, 2, -0.01);
        hess.push(4, 4, 5, 0.2);
        compare_kernels(jac, &hess, 1);
        compare_kernels(jac, &SparseHessians::new(), 2);
    }

    #[test]
    fn near_identity_kernel_matches_dense_on_dense_jacobian() {
        let mut rng = stream(3, 0, "test");
        let jac = SMatrix::<f64, 5, 5>::from_fn(|_, _| rng.random::<f64>() - 0.5);
        compare_kernels(jac, &SparseHessians::new(), 4);
        compare_kernels(SMatrix::<f64, 5, 5>::zeros(), &SparseHessians::new(), 5);
    }
}
