//! The marginalised (Rao–Blackwellised) particle filter for mixed linear/nonlinear models,
//! MLN-RBPF (SPEC §5.2; Schön, Gustafsson & Nordlund 2005 with `G = I`, `g = 0`), on run-time
//! dimensions.
//!
//! Each particle carries the sampled block `u` and a Gaussian `N(μ, C)` over the static block `z`.
//! Per particle and step ([`MlnStep::advance`]), for each stage of the transition (forward Euler
//! has one; a semi-implicit scheme has two, see [`super::model`]):
//! - (a) proposal with `z` marginalised: linked rows `u_L ~ N(f_L + F μ, F C Fᵀ + Q_L)`; the other
//!   rows of the stage are `f + noise` (they do not depend on `z`);
//! - (b) pseudo-measurement update of `(μ, C)` with `u_L` (Jacobian `F`, noise `Q_L`): its
//!   innovation covariance is the proposal covariance of (a), factorised once, and the whitened
//!   innovation is the draw `ξ` itself ([`Factor::condition_on_draw`]);
//!
//! then
//! - (c) weight `N(y_k; H μ + h, H C Hᵀ + R)` with `(h, H) = observation(k, u_k)`, which is the
//!   log-likelihood of the measurement update (d), so (c) and (d) are one update;
//! - (d) measurement update of `(μ, C)` with `y_k`;
//! - (e) normalise, summarise, resample `(u, μ, C)` jointly: the runner ([`super::runner`]).
//!
//! Failure policy: a particle whose proposal or innovation covariance cannot be factorised even
//! after the documented repair (counted in `health`) or whose update gives a non-finite result
//! gets a NaN log-weight, which the weight routine maps to −∞ and counts; the run fails only if
//! no particle survives.

#![allow(non_snake_case)] // F, H, C as in the SPEC

use crate::health::Health;
use crate::linalg::gauss::factorise;
use crate::linalg::{Factor, Sparse};
use crate::model::Layout;
use crate::real::Real;
use crate::rng::StreamRng;

use super::batch::{Ancestry, Marginalized, ParticleStep, Slots};
use super::model::{linear_patterns, ConditionallyLinear, LinearDims, Stage};
use super::store::Shape;

/// The per-particle step of the MLN-RBPF (SPEC §5.2) and what it needs from the model, read once.
pub struct MlnStep<M> {
    model: M,
    dims: LinearDims,
    stages: Vec<StagePlan>,
    /// Recorded patterns of `F` per stage and of `H`.
    f_patterns: Vec<Sparse<f64>>,
    h_pattern: Sparse<f64>,
    r: Vec<f64>,
    draws: usize,
}

/// One stage with its noise levels split into linked and unlinked rows.
struct StagePlan {
    stage: Stage,
    /// Position in `stage.rows` of each linked row.
    linked_pos: Vec<usize>,
    /// Unlinked rows with non-zero noise: (position in `stage.rows`, row of `u`, s.d.).
    noisy_unlinked: Vec<(usize, usize, f64)>,
    /// Unlinked rows without noise: (position in `stage.rows`, row of `u`).
    quiet_unlinked: Vec<(usize, usize)>,
    /// `Q_L` (dense, `l × l`).
    q_l: Vec<f64>,
}

/// Scratch of one [`MlnStep`] for one number type.
pub struct MlnScratch<T> {
    f: Vec<T>,
    F: Vec<Sparse<T>>,
    pred: Vec<T>,
    drawn: Vec<T>,
    q_l: Vec<Vec<T>>,
    factors: Vec<Factor<T>>,
    h: Vec<T>,
    H: Sparse<T>,
    r: Vec<T>,
    resid: Vec<T>,
    y_factor: Factor<T>,
}

impl<M: ConditionallyLinear> MlnStep<M> {
    /// Reads the model's dimensions, stages, noise and `R`, and records the Jacobian patterns.
    #[track_caller]
    pub fn new(model: M) -> Self {
        let dims = model.dims();
        let sd = model.process_noise_sd().to_vec();
        assert_eq!(sd.len(), dims.nu, "process noise s.d. of every row of u");
        let mut stages = Vec::new();
        let mut draws = 0;
        for st in model.stages() {
            let linked_pos = st.linked_positions();
            let mut noisy_unlinked = Vec::new();
            let mut quiet_unlinked = Vec::new();
            for (p, &r) in st.rows.iter().enumerate() {
                if st.linked.contains(&r) {
                    continue;
                }
                if sd[r] != 0.0 {
                    noisy_unlinked.push((p, r, sd[r]));
                } else {
                    quiet_unlinked.push((p, r));
                }
            }
            draws += st.linked.len() + noisy_unlinked.len();
            stages.push(StagePlan {
                stage: st.clone(),
                linked_pos,
                noisy_unlinked,
                quiet_unlinked,
                q_l: st.linked_noise_cov(&sd),
            });
        }
        let (f_patterns, h_pattern, r) = linear_patterns(&model);
        Self {
            model,
            dims,
            stages,
            f_patterns,
            h_pattern,
            r,
            draws,
        }
    }

    pub fn model(&self) -> &M {
        &self.model
    }
}

impl<M: ConditionallyLinear> ParticleStep for MlnStep<M> {
    type Scratch<T: Real> = MlnScratch<T>;

    fn name(&self) -> &'static str {
        "mln-rbpf"
    }

    fn layout(&self) -> Layout {
        self.model.layout()
    }

    fn initialise(&self, rng: &mut StreamRng, u: &mut [f64], mu: &mut [f64], cov: &mut [f64]) {
        self.model.sample_initial(rng, u);
        self.model.marginal_prior(rng, mu, cov);
    }

    fn broken_pattern<T: Real>(s: &MlnScratch<T>) -> Option<&'static str> {
        if s.F.iter().any(Sparse::pattern_broken) {
            Some("transition matrix F")
        } else if s.H.pattern_broken() {
            Some("measurement matrix H")
        } else {
            None
        }
    }

    fn scratch<T: Real>(&self) -> MlnScratch<T> {
        let LinearDims { nu, nz, ny } = self.dims;
        let splat = |v: &[f64]| v.iter().map(|x| T::splat(*x)).collect::<Vec<T>>();
        MlnScratch {
            f: vec![T::splat(0.0); nu],
            F: self
                .f_patterns
                .iter()
                .map(Sparse::with_pattern_of)
                .collect(),
            pred: vec![T::splat(0.0); nu],
            drawn: vec![T::splat(0.0); nu],
            q_l: self.stages.iter().map(|p| splat(&p.q_l)).collect(),
            factors: self
                .stages
                .iter()
                .map(|p| Factor::new(nz, p.stage.linked.len()))
                .collect(),
            h: vec![T::splat(0.0); ny],
            H: Sparse::with_pattern_of(&self.h_pattern),
            r: splat(&self.r),
            resid: vec![T::splat(0.0); ny],
            y_factor: Factor::new(nz, ny),
        }
    }

    fn shape(&self) -> Shape {
        Shape {
            sampled: self.dims.nu,
            marginal: self.dims.nz,
        }
    }

    fn draws(&self) -> usize {
        self.draws
    }

    /// SPEC §5.2 (a)–(d) for one particle (or a pack).
    fn advance<T: Real>(
        &self,
        from: Ancestry<'_, T>,
        p: Slots<'_, T>,
        s: &mut MlnScratch<T>,
        health: &mut Health,
    ) -> (T, T::Mask) {
        let Ancestry {
            k,
            y,
            prev: u_prev,
            xi,
        } = from;
        let (u, mu, C) = (p.sampled, p.mean, p.cov);
        let mut ok = T::all_true();
        let mut next_draw = 0;
        for (st, plan) in self.stages.iter().enumerate() {
            let F = &mut s.F[st];
            F.evaluate(|j| self.model.transition(st, k, u_prev, u, &mut s.f, j));
            // Rows that do not depend on z: f plus their own noise (or copied exactly).
            for &(pos, row, sd) in &plan.noisy_unlinked {
                u[row] = s.f[pos] + T::splat(sd) * xi[next_draw];
                next_draw += 1;
            }
            for &(pos, row) in &plan.quiet_unlinked {
                u[row] = s.f[pos];
            }
            let l = plan.stage.linked.len();
            if l == 0 {
                continue;
            }
            // (a) proposal mean f_L + F μ; covariance S = F C Fᵀ + Q_L, factorised once.
            for (i, &pos) in plan.linked_pos.iter().enumerate() {
                s.pred[i] = s.f[pos];
            }
            F.mul_add(mu, &mut s.pred[..l]);
            let factor = &mut s.factors[st];
            ok = ok & factorise(factor, C, F, &s.q_l[st], health);
            // (a) u_L = mean + chol(S) ξ and (b) the update of (μ, C) with it: whitened by ξ.
            let xi_l = &xi[next_draw..next_draw + l];
            next_draw += l;
            ok = ok & factor.condition_on_draw(mu, C, &s.pred[..l], xi_l, &mut s.drawn[..l]);
            for (i, &row) in plan.stage.linked.iter().enumerate() {
                u[row] = s.drawn[i];
            }
        }
        debug_assert_eq!(next_draw, self.draws);
        // (c)+(d): y_k = h(u_k) + H(u_k) z + η: weight and update in one.
        s.H.evaluate(|j| self.model.observation(k, u, &mut s.h, j));
        for (j, r) in s.resid.iter_mut().enumerate() {
            *r = T::splat(y[j]) - s.h[j];
        }
        for e in 0..s.H.nnz() {
            let (r, c, v) = s.H.entry(e);
            s.resid[r] -= v * mu[c];
        }
        ok = ok & factorise(&mut s.y_factor, C, &s.H, &s.r, health);
        let (loglik, upd) = s.y_factor.update(mu, C, &s.resid);
        (loglik, ok & upd)
    }
}

/// MLN-RBPF (SPEC §5.2) as a [`super::Filter`]: its per-particle step run by the batch layer.
pub type MlnRbpf<M> = Marginalized<MlnStep<M>>;

impl<M: ConditionallyLinear> MlnRbpf<M> {
    /// The filter with the batch layer's lanes where they pay ([`crate::smc::batch::Batch::new`]).
    pub fn new(model: M) -> Self {
        Self::with_lanes(model, true)
    }

    /// `lanes = false` runs every particle through the `f64` step (the reference).
    pub fn with_lanes(model: M, lanes: bool) -> Self {
        Marginalized::from_step(MlnStep::new(model), lanes)
    }

    pub fn model(&self) -> &M {
        self.particle_step().model()
    }
}
