//! Storvik's algorithm with Gaussian sufficient statistics (SPEC §5.3; Storvik 2002, with the
//! paper's update, §3.3.2).
//!
//! Same partition as the MLN-RBPF: each particle carries `u` and the sufficient statistics
//! `s = (μ, C)` of the static block `z`. Per particle and step, with
//! `(f, F_L) = transition(k, u_{k−1})`:
//! - (i) draw a realisation `z0 ~ N(μ, C)`;
//! - (ii) `u_k ~ N(f + F z0, Q_u)` (only the linked rows depend on `z`), weight
//!   `N(y_k; H(u_k) z0 + h(u_k), R)`;
//! - (iii) update `(μ, C)` with the stacked measurement `[u_{k,L}; y_k]`, noise
//!   `blockdiag(Q_L, R)`. The linked rows are linear in `z` (Jacobian `F_L`). For `y_k`:
//!   - [`StorvikUpdate::Linearised`] (the paper's update, default): `y_k` written through
//!     `u_{k−1}`, `g(z) = H(u_k(z)) z + h(u_k(z))`, linearised at `z0`:
//!     `G_z = H(u_k) + J_u F`, `ŷ = g(z0) + G_z (μ − z0)`;
//!   - [`StorvikUpdate::Exact`]: given `u_k`, `y_k` is linear in `z`: a KF update with
//!     `(H(u_k), h(u_k))`, exactly as MLN-RBPF (d).
//!
//!   The stacked update is done as two sequential updates (linked rows, then `y_k`) at the same
//!   linearisation point `z0`: with block-diagonal noise, sequential updates with linear (or
//!   fixed-point linearised) measurements equal the stacked one.
//!
//! Then normalise, summarise the weighted mixture, resample `(u, μ, C)` jointly (at the start of
//! the next step; `(μ, C)` are read from the ancestor where they are, and the updated ones are
//! written to the other buffer, so they are not copied twice).
//!
//! Speed, with results unchanged to the bit: the particles go through the step four at a time.
//! The factors of their `C` are computed side by side in SIMD lanes ([`PsdLaneFactors`]); steps (i)
//! and (ii), which take the random draws, run particle by particle in order; then both updates
//! of step (iii) run for the four in lanes ([`crate::kalman::lanes`]), each lane doing the scalar
//! update's operations in its order. A particle the lanes cannot take (its scalar update would
//! need the documented repair, or fail) is redone by the scalar update, which counts and reports
//! it. [`Storvik::without_lanes`] runs every particle through the scalar updates; the tests
//! check that it gives the same bits.
//!
//! Sampling from a singular `C`: static parameters held fixed (zero prior variance) or directions
//! the data pin down make `C` positive *semi*-definite. Step (i) uses a semidefinite Cholesky
//! factor (see [`psd_cholesky`]): a pivot that is zero up to round-off gives a zero column, so the
//! draw has exactly zero spread in that direction, as the Gaussian does. This is not a repair and
//! is not counted; a clearly negative pivot (an indefinite `C`) is a failure of that particle.
//!
//! Failure policy (as MLN-RBPF): a particle whose factorisation or Kalman update fails gets a NaN
//! log-weight, mapped to −∞ and counted by the weight routine (Cholesky failures are counted in
//! `health.cholesky_failures`); the step fails with [`FilterError::AllWeightsZero`] only if no
//! particle survives. `R` is factorised once in [`Storvik::new`]; if it is not positive definite
//! every step returns that error.

use nalgebra::{SMatrix, SVector};
use rand::Rng;
use serde::{Deserialize, Serialize};
use wide::{f64x4, CmpGt, CmpLe, CmpLt};

use super::lane_group::LaneMoments;
use super::mlnrbpf::{standard_normal, LinkedRows};
use super::{MarginalParticles, ParticleConfig, ParticleFilter, Posterior, StepInfo, WeightedSet};
use crate::error::FilterError;
use crate::health::Health;
use crate::kalman::kf::{all_finite, cholesky_with, update_from_residual, Pivot};
use crate::kalman::lanes::{
    finite_lanes, gather_mat, gather_vec, gaussian_update, lane, mul_vec, LaneMat, LaneVec, Mask,
    LANES,
};
use crate::kalman::FactoredCov;
use crate::model::{ConditionallyLinear, Layout};

/// How Storvik's step (iii) treats the measurement `y_k` (SPEC §5.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StorvikUpdate {
    /// The paper's update: `y_k` through `u_{k−1}`, linearised at the realisation `z0`.
    #[default]
    Linearised,
    /// Given `u_k`, `y_k` is linear in `z`: an exact KF update (no linearisation).
    Exact,
}

impl StorvikUpdate {
    pub fn name(self) -> &'static str {
        match self {
            StorvikUpdate::Linearised => "linearised",
            StorvikUpdate::Exact => "exact",
        }
    }
}

/// A pivot below this fraction of the largest diagonal entry of `C` is round-off (a direction of
/// zero variance); below minus this fraction, `C` is indefinite.
const PSD_PIVOT_REL_TOL: f64 = 1e-12;

/// Lower factor `L` with `L Lᵀ = A` for a symmetric positive *semi*-definite `A`: Cholesky in
/// which a pivot within `±1e-12 · max_j a_jj` of zero yields a zero column (that direction has
/// no variance). `None` for a non-finite entry or a clearly negative pivot (indefinite `A`).
pub fn psd_cholesky<const N: usize>(a: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    if !all_finite(a) {
        return None;
    }
    let mut max_diag = 0.0_f64;
    for j in 0..N {
        if a[(j, j)] > max_diag {
            max_diag = a[(j, j)];
        }
    }
    let tol = PSD_PIVOT_REL_TOL * max_diag;
    cholesky_with(a, |_, d| {
        if d < -tol {
            Pivot::Fail
        } else if d <= tol {
            Pivot::ZeroColumn
        } else {
            Pivot::Accept
        }
    })
}

/// The semidefinite factors ([`psd_cholesky`]) of [`LANES`] matrices, computed side by side and
/// kept in lane layout: `l[j][i]` holds entry `(i, j)` of the four factors.
///
/// Why: one factorisation is a chain of dependent square roots, divisions and dot products that
/// leaves most of the processor idle; four independent chains run side by side in about the
/// time of one. The factors stay in lane layout because their one use, `L ξ` for the draw, reads
/// them entry by entry anyway.
#[derive(Debug, Clone, Copy)]
pub struct PsdLaneFactors<const N: usize> {
    l: LaneMat<N, N>,
    ok: [bool; LANES],
}

impl<const N: usize> Default for PsdLaneFactors<N> {
    fn default() -> Self {
        Self {
            l: [[f64x4::ZERO; N]; N],
            ok: [false; LANES],
        }
    }
}

impl<const N: usize> PsdLaneFactors<N> {
    /// Factorises `a[b]` into lane `b` with the same operations in the same order as
    /// [`psd_cholesky`], so each factor is bit for bit the one it returns. A lane whose pivot is
    /// a zero column keeps that column exactly zero (a select, not a multiplication by zero,
    /// which could give `−0`); a lane that fails goes on computing with meaningless values,
    /// which [`PsdLaneFactors::ok`] disowns.
    #[inline]
    #[allow(clippy::needless_range_loop, clippy::assign_op_pattern)] // the scalar order, spelled out
    pub fn factorise(&mut self, a: &LaneMat<N, N>) {
        let entry = |i: usize, j: usize| a[j][i];
        let finite = finite_lanes(a);
        let mut max_diag = f64x4::ZERO;
        for j in 0..N {
            max_diag = a[j][j].cmp_gt(max_diag).blend(a[j][j], max_diag);
        }
        let tol = f64x4::splat(PSD_PIVOT_REL_TOL) * max_diag;
        let neg_tol = -tol;
        // All bits set in the lanes whose pivot was clearly negative.
        let mut failed = f64x4::ZERO;
        let l = &mut self.l;
        for j in 0..N {
            let mut d = entry(j, j);
            for k in 0..j {
                d = d - l[k][j] * l[k][j];
            }
            failed = failed | d.cmp_lt(neg_tol);
            let zero = d.cmp_le(tol);
            let ljj = d.sqrt();
            // Above the diagonal the factor is zero.
            for i in 0..j {
                l[j][i] = f64x4::ZERO;
            }
            l[j][j] = zero.blend(f64x4::ZERO, ljj);
            let inv = ljj * (f64x4::ONE / d);
            for i in (j + 1)..N {
                let mut s = entry(i, j);
                for k in 0..j {
                    s = s - l[k][i] * l[k][j];
                }
                l[j][i] = zero.blend(f64x4::ZERO, s * inv);
            }
        }
        let ok = finite & !failed;
        self.ok = std::array::from_fn(|b| lane(ok, b));
    }

    /// Whether lane `b` has a factor (its matrix was finite and not indefinite).
    pub fn ok(&self, b: usize) -> bool {
        self.ok[b]
    }

    /// `L_b x` for lane `b`, summed over the columns in order as nalgebra's matrix–vector
    /// product sums (`Σ_j L[:, j] x_j`, zeros included), so it equals `psd_cholesky(a) * x` to
    /// the bit.
    #[inline]
    pub fn mul_vec(&self, b: usize, x: &SVector<f64, N>) -> SVector<f64, N> {
        let col = |j: usize| SVector::<f64, N>::from_fn(|i, _| self.l[j][i].as_array_ref()[b]);
        let mut out = col(0) * x[0];
        for j in 1..N {
            out += col(j) * x[j];
        }
        out
    }

    /// Lane `b`'s factor as a matrix, if it has one.
    pub fn factor(&self, b: usize) -> Option<SMatrix<f64, N, N>> {
        self.ok[b].then(|| SMatrix::from_fn(|i, j| self.l[j][i].as_array_ref()[b]))
    }
}

/// Storvik's filter (SPEC §5.3) for `u ∈ R^NU`, `z ∈ R^NZ`, `NL` linked rows and `NY`
/// measurements. All buffers are allocated in [`Storvik::new`]; `step` allocates nothing.
pub struct Storvik<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    model: M,
    config: ParticleConfig,
    update: StorvikUpdate,
    layout: Layout,
    /// Sampled blocks and Gaussians of the marginalised block, double-buffered.
    p: MarginalParticles<NU, NZ>,
    /// Weights and the resampling bookkeeping.
    set: WeightedSet,
    noise_sd: SVector<f64, NU>,
    linked: LinkedRows<NU, NL>,
    r: SMatrix<f64, NY, NY>,
    /// The constant `R` factorised once (weights of step (ii)), or why it failed.
    r_noise: Result<FactoredCov<NY>, FilterError>,
    /// Scratch of the four particles processed together.
    group: Box<LaneGroup<NZ, NL, NY>>,
    /// Whether step (iii) runs in lanes: `Q_L` and `R` must be exactly symmetric, as the lane
    /// updates require (the scalar update symmetrises them otherwise, so every particle takes
    /// it), and [`Storvik::without_lanes`] was not asked for.
    use_lanes: bool,
    /// Which particle's moments each particle starts the step from (see
    /// [`MarginalParticles::resample_sampled_only`]).
    source: Vec<usize>,
    setup_health: Health,
    health: Health,
}

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
    Storvik<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    /// Storvik's filter with the paper's linearised update ([`StorvikUpdate::Linearised`]).
    #[track_caller]
    pub fn new(model: M, config: ParticleConfig) -> Self {
        Self::with_update(model, config, StorvikUpdate::default())
    }

    /// Storvik's filter with the chosen treatment of `y_k` in step (iii).
    ///
    /// # Panics
    /// If `config.particles == 0` or the model's linked rows are out of range or repeated.
    #[track_caller]
    pub fn with_update(model: M, config: ParticleConfig, update: StorvikUpdate) -> Self {
        let np = config.particles;
        assert!(np > 0, "a particle filter needs at least one particle");
        let noise_sd = model.process_noise_sd();
        let r = model.measurement_cov();
        let mut health = Health::default();
        let r_noise = FactoredCov::new(&r, "measurement covariance R", &mut health);
        let linked = LinkedRows::new(model.linked_rows(), &noise_sd);
        Self {
            layout: model.layout(),
            r,
            r_noise,
            noise_sd,
            update,
            group: Box::default(),
            source: vec![0; np],
            use_lanes: r == r.transpose() && linked.q_l == linked.q_l.transpose(),
            linked,
            p: MarginalParticles::new(np),
            set: WeightedSet::new(&config),
            setup_health: health,
            health,
            config,
            model,
        }
    }

    /// Every particle's step (iii) by the scalar updates, one particle at a time. The lanes give
    /// the same results to the bit; this is the reference they are tested against.
    pub fn without_lanes(mut self) -> Self {
        self.use_lanes = false;
        self
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    pub fn update(&self) -> StorvikUpdate {
        self.update
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

/// What step (iii) needs of one particle of a lane group, found in steps (i)–(ii): the
/// residual and Jacobian of the linked rows, and the Jacobian and offset of `y_k` (`H(u_k)` and
/// `h(u_k)` for [`StorvikUpdate::Exact`]; `G_z` and `g(z0)` for the linearised update, with the
/// realisation `z0`).
#[derive(Debug, Clone, Copy)]
#[allow(non_snake_case)]
struct Pending<const NZ: usize, const NL: usize, const NY: usize> {
    residual_l: SVector<f64, NL>,
    F_L: SMatrix<f64, NL, NZ>,
    jac_y: SMatrix<f64, NY, NZ>,
    offset_y: SVector<f64, NY>,
    z0: SVector<f64, NZ>,
}

impl<const NZ: usize, const NL: usize, const NY: usize> Default for Pending<NZ, NL, NY> {
    fn default() -> Self {
        Self {
            residual_l: SVector::zeros(),
            F_L: SMatrix::zeros(),
            jac_y: SMatrix::zeros(),
            offset_y: SVector::zeros(),
            z0: SVector::zeros(),
        }
    }
}

impl<const NZ: usize, const NL: usize, const NY: usize> Pending<NZ, NL, NY> {
    /// `ŷ` of `y_k` given the moments after the linked rows: `H μ + h` (exact) or
    /// `g(z0) + G_z (μ − z0)` (linearised).
    fn y_hat(&self, update: StorvikUpdate, mu: &SVector<f64, NZ>) -> SVector<f64, NY> {
        match update {
            StorvikUpdate::Exact => self.jac_y * mu + self.offset_y,
            StorvikUpdate::Linearised => self.offset_y + self.jac_y * (mu - self.z0),
        }
    }

    /// Step (iii) of one particle with the scalar updates; the reference the lanes reproduce,
    /// and the path of every particle they cannot take.
    #[allow(clippy::too_many_arguments)]
    fn update_scalar(
        &self,
        update: StorvikUpdate,
        mu: &mut SVector<f64, NZ>,
        cov: &mut SMatrix<f64, NZ, NZ>,
        y: &SVector<f64, NY>,
        q_l: &SMatrix<f64, NL, NL>,
        r: &SMatrix<f64, NY, NY>,
        k: usize,
        health: &mut Health,
    ) -> Result<(), FilterError> {
        update_from_residual(mu, cov, &self.residual_l, &self.F_L, q_l, k, health)?;
        let residual_y = y - self.y_hat(update, mu);
        update_from_residual(mu, cov, &residual_y, &self.jac_y, r, k, health).map(|_| ())
    }
}

/// Scratch of one lane group: the moments and step (iii) inputs of four particles in lanes.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
struct LaneGroup<const NZ: usize, const NL: usize, const NY: usize> {
    moments: LaneMoments<NZ>,
    factors: PsdLaneFactors<NZ>,
    pending: [Pending<NZ, NL, NY>; LANES],
    /// Whether each lane's particle reached step (iii).
    ready: [bool; LANES],
    residual_l: LaneVec<NL>,
    F_L: LaneMat<NL, NZ>,
    jac_y: LaneMat<NY, NZ>,
    offset_y: LaneVec<NY>,
    z0: LaneVec<NZ>,
}

impl<const NZ: usize, const NL: usize, const NY: usize> Default for LaneGroup<NZ, NL, NY> {
    fn default() -> Self {
        Self {
            moments: LaneMoments::default(),
            factors: PsdLaneFactors::default(),
            pending: [Pending::default(); LANES],
            ready: [false; LANES],
            residual_l: [f64x4::ZERO; NL],
            F_L: [[f64x4::ZERO; NL]; NZ],
            jac_y: [[f64x4::ZERO; NY]; NZ],
            offset_y: [f64x4::ZERO; NY],
            z0: [f64x4::ZERO; NZ],
        }
    }
}

impl<const NZ: usize, const NL: usize, const NY: usize> LaneGroup<NZ, NL, NY> {
    /// Both updates of step (iii) in the lanes; returns the lanes that took the scalar
    /// updates' straight path (see [`crate::kalman::lanes`]).
    fn update(
        &mut self,
        update: StorvikUpdate,
        y: &SVector<f64, NY>,
        q_l: &SMatrix<f64, NL, NL>,
        r: &SMatrix<f64, NY, NY>,
    ) -> Mask {
        let p = &self.pending;
        gather_vec(
            &mut self.residual_l,
            std::array::from_fn(|b| &p[b].residual_l),
        );
        gather_mat(&mut self.F_L, std::array::from_fn(|b| &p[b].F_L));
        gather_mat(&mut self.jac_y, std::array::from_fn(|b| &p[b].jac_y));
        gather_vec(&mut self.offset_y, std::array::from_fn(|b| &p[b].offset_y));
        let (ok_l, ..) = gaussian_update(
            &mut self.moments.mu,
            &mut self.moments.cov,
            &self.residual_l,
            &self.F_L,
            q_l,
        );
        // ŷ as `Pending::y_hat` computes it, lane by lane.
        let y_hat: LaneVec<NY> = match update {
            StorvikUpdate::Exact => {
                let h_mu = mul_vec(&self.jac_y, &self.moments.mu);
                std::array::from_fn(|r| h_mu[r] + self.offset_y[r])
            }
            StorvikUpdate::Linearised => {
                gather_vec(&mut self.z0, std::array::from_fn(|b| &p[b].z0));
                let d: LaneVec<NZ> = std::array::from_fn(|j| self.moments.mu[j] - self.z0[j]);
                let g_d = mul_vec(&self.jac_y, &d);
                std::array::from_fn(|r| self.offset_y[r] + g_d[r])
            }
        };
        let residual_y: LaneVec<NY> = std::array::from_fn(|r| f64x4::splat(y[r]) - y_hat[r]);
        let (ok_y, ..) = gaussian_update(
            &mut self.moments.mu,
            &mut self.moments.cov,
            &residual_y,
            &self.jac_y,
            r,
        );
        ok_l & ok_y
    }
}

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
    Storvik<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    /// SPEC §5.3 (i)–(iii) for the `count ≤ 4` particles from `first` on: (i) and (ii) particle
    /// by particle in order (they take the draws), then (iii) for all of them in SIMD lanes,
    /// with the scalar update for any particle the lanes cannot take. Results are bit for bit
    /// those of (i)–(iii) particle by particle.
    #[allow(non_snake_case)]
    fn step_group<G: Rng + ?Sized>(
        &mut self,
        k: usize,
        y: &SVector<f64, NY>,
        rng: &mut G,
        r_noise: &FactoredCov<NY>,
        first: usize,
        count: usize,
    ) {
        let linked = &self.linked;
        let g = &mut self.group;
        let source = &self.source;
        // Particle i starts from the moments of particle source[i] (its ancestor) and its new
        // ones go to the back buffers.
        let (sampled, src_mu, src_cov, dst_mu, dst_cov) = self.p.moments_split();
        g.moments
            .gather(src_mu, src_cov, &source[first..first + count]);
        g.factors.factorise(&g.moments.cov);
        for b in 0..count {
            let i = first + b;
            g.ready[b] = false;
            // (i) z0 ~ N(μ, C) with a semidefinite factor of C.
            if !g.factors.ok(b) {
                self.health.cholesky_failures += 1;
                self.set.log_w[i] = f64::NAN;
                (dst_mu[i], dst_cov[i]) = (src_mu[source[i]], src_cov[source[i]]);
                continue;
            }
            let mu = &src_mu[source[i]];
            let z0 = *mu + g.factors.mul_vec(b, &standard_normal::<NZ, G>(rng));
            // (ii) u_k ~ N(f + F z0, Q_u): linked rows f_L + F_L z0 + noise, others f + noise.
            let (f, F_L) = self.model.transition(k, &sampled[i]);
            let f_l = linked.pick(&f);
            let mut u_new = f;
            linked.add_unlinked_noise(&mut u_new, &self.noise_sd, rng);
            let mut u_l = f_l + F_L * z0;
            for l in 0..NL {
                let sd = self.noise_sd[linked.rows[l]];
                if sd != 0.0 {
                    u_l[l] += sd * standard_normal::<1, G>(rng)[0];
                }
            }
            linked.scatter(&mut u_new, &u_l);
            sampled[i] = u_new;
            let (h, H) = self.model.observation(k, &u_new);
            let y_z0 = H * z0 + h;
            self.set.log_w[i] += r_noise.log_density(&(y - y_z0));
            // (iii), prepared: the linked rows are linear in z with Jacobian F_L, noise Q_L; y_k
            // follows them sequentially (block-diagonal noise).
            let pending = &mut g.pending[b];
            pending.residual_l = u_l - (f_l + F_L * *mu);
            pending.F_L = F_L;
            match self.update {
                StorvikUpdate::Exact => {
                    pending.jac_y = H;
                    pending.offset_y = h;
                }
                StorvikUpdate::Linearised => {
                    // G_z = H(u_k) + J_u F, F zero outside the linked rows.
                    let J_u = self.model.observation_jacobian_u(k, &u_new, &z0);
                    let mut G_z = H;
                    for (l, &r) in linked.rows.iter().enumerate() {
                        G_z += J_u.column(r) * F_L.row(l);
                    }
                    pending.jac_y = G_z;
                    pending.offset_y = y_z0;
                    pending.z0 = z0;
                }
            }
            g.ready[b] = true;
        }
        // (iii) in lanes, if any particle got there and the noises allow it.
        let ok = if self.use_lanes && g.ready[..count].contains(&true) {
            g.update(self.update, y, &linked.q_l, &self.r)
        } else {
            f64x4::ZERO
        };
        let take: [bool; LANES] = std::array::from_fn(|b| b < count && g.ready[b] && lane(ok, b));
        let group = first..first + count;
        g.moments
            .write_back(take, &mut dst_mu[group.clone()], &mut dst_cov[group]);
        for b in 0..count {
            if !g.ready[b] || take[b] {
                continue;
            }
            let i = first + b;
            (dst_mu[i], dst_cov[i]) = (src_mu[source[i]], src_cov[source[i]]);
            let (mu, cov) = (&mut dst_mu[i], &mut dst_cov[i]);
            if g.pending[b]
                .update_scalar(
                    self.update,
                    mu,
                    cov,
                    y,
                    &linked.q_l,
                    &self.r,
                    k,
                    &mut self.health,
                )
                .is_err()
            {
                self.set.log_w[i] = f64::NAN;
            }
        }
    }
}

impl<M, const NU: usize, const NZ: usize, const NL: usize, const NY: usize> ParticleFilter<NY>
    for Storvik<M, NU, NZ, NL, NY>
where
    M: ConditionallyLinear<NU, NZ, NL, NY>,
{
    fn name(&self) -> &'static str {
        "storvik"
    }

    fn particles(&self) -> usize {
        self.config.particles
    }

    /// Draws `u_0^i` and `(μ_0^i, C_0^i)` from the model's priors, uniform weights, counters
    /// reset to the repairs made in `new` (factorising `R`).
    fn initialise<G: Rng + ?Sized>(&mut self, rng: &mut G) {
        let model = &self.model;
        self.p.initialise(rng, |rng| {
            let u = model.sample_initial(rng);
            let (mu, cov) = model.sample_marginal_prior(rng);
            (u, mu, cov)
        });
        self.set.reset();
        self.health = self.setup_health;
    }

    /// SPEC §5.3 (i)–(iii) for every particle; see the module documentation.
    #[allow(non_snake_case)]
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
        self.p
            .resample_sampled_only(&mut self.set, rng, &mut self.health, &mut self.source);
        let np = self.config.particles;
        for first in (0..np).step_by(LANES) {
            self.step_group(k, y, rng, &r_noise, first, (np - first).min(LANES));
        }
        self.p.swap_moments();
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
    use nalgebra::Matrix3;

    #[test]
    fn psd_cholesky_handles_zero_variance_directions() {
        // Entry 1 fixed (zero variance), entries 0 and 2 correlated.
        let a = Matrix3::new(4.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0);
        let l = psd_cholesky(&a).unwrap();
        assert!((l * l.transpose() - a).abs().max() < 1e-15);
        assert_eq!(l.column(1).abs().max(), 0.0);
        // A rank-one matrix in a non-coordinate direction.
        let v = nalgebra::Vector3::new(1.0, -2.0, 0.5);
        let b = v * v.transpose();
        let l = psd_cholesky(&b).unwrap();
        assert!((l * l.transpose() - b).abs().max() < 1e-12);
    }

    /// A random symmetric 8 × 8 matrix of one of the kinds Storvik meets: definite (badly
    /// scaled), semidefinite with fixed parameters (zero rows and columns) or a rank deficit,
    /// indefinite, or with a non-finite entry.
    fn random_case(rng: &mut rand_xoshiro::Xoshiro256PlusPlus, kind: u32) -> SMatrix<f64, 8, 8> {
        use rand::Rng;
        let scale = SVector::<f64, 8>::from_fn(|_, _| 10f64.powf(rng.random_range(-4.0..3.0)));
        let rank = if kind == 1 {
            rng.random_range(1..8)
        } else {
            8 + 2
        };
        let b = SMatrix::<f64, 8, 10>::from_fn(|_, c| {
            if c < rank {
                rng.random_range(-1.0..1.0)
            } else {
                0.0
            }
        });
        let mut a = SMatrix::<f64, 8, 8>::from_diagonal(&scale)
            * (b * b.transpose())
            * SMatrix::<f64, 8, 8>::from_diagonal(&scale);
        match kind {
            // Fixed parameters: zero rows and columns.
            2 => {
                for _ in 0..rng.random_range(1..4) {
                    let r = rng.random_range(0..8);
                    a.row_mut(r).fill(0.0);
                    a.column_mut(r).fill(0.0);
                }
            }
            3 => {
                let r = rng.random_range(0..8);
                a[(r, r)] = -a[(r, r)] - 1.0;
            }
            4 => a[(rng.random_range(0..8), rng.random_range(0..8))] = f64::NAN,
            5 => a[(rng.random_range(0..8), rng.random_range(0..8))] = f64::INFINITY,
            _ => {}
        }
        a
    }

    #[test]
    fn lanes_factor_bit_for_bit_as_one_at_a_time() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(20261123);
        let (mut some, mut none, mut zero_cols) = (0, 0, 0);
        // One set of lanes reused throughout, as in the filter.
        let mut lanes = PsdLaneFactors::<8>::default();
        for _ in 0..500 {
            let cases: [SMatrix<f64, 8, 8>; LANES] = std::array::from_fn(|_| {
                let kind = rng.random_range(0..6);
                random_case(&mut rng, kind)
            });
            let mut gathered = [[f64x4::ZERO; 8]; 8];
            gather_mat(&mut gathered, std::array::from_fn(|b| &cases[b]));
            lanes.factorise(&gathered);
            for (b, case) in cases.iter().enumerate() {
                let want = psd_cholesky(case);
                match (want, lanes.factor(b)) {
                    (Some(w), Some(g)) => {
                        some += 1;
                        zero_cols += (0..8).filter(|&j| w[(j, j)] == 0.0).count();
                        for (x, y) in w.iter().zip(g.iter()) {
                            assert_eq!(x.to_bits(), y.to_bits(), "{case}");
                        }
                        let x = SVector::<f64, 8>::from_fn(|_, _| rng.random_range(-3.0..3.0));
                        let (want_lx, got_lx) = (w * x, lanes.mul_vec(b, &x));
                        for (p, q) in want_lx.iter().zip(got_lx.iter()) {
                            assert_eq!(p.to_bits(), q.to_bits(), "{case}");
                        }
                    }
                    (None, None) => none += 1,
                    _ => panic!("lanes and one-at-a-time disagree on {case}"),
                }
            }
        }
        // Every kind of case occurred: factors, zero columns and failures.
        assert!(
            some > 800 && none > 500 && zero_cols > 300,
            "{some} {none} {zero_cols}"
        );
    }

    #[test]
    fn psd_cholesky_rejects_indefinite_and_nan() {
        let a = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(psd_cholesky(&a).is_none());
        let mut b = Matrix3::identity();
        b[(2, 2)] = f64::NAN;
        assert!(psd_cholesky(&b).is_none());
    }
}
