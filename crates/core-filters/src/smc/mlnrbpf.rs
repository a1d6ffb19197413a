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
//!   innovation is the draw `ξ` itself ([`crate::linalg::Factor::condition_on_draw`]);
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
use crate::real::Real;

use super::batch::{Ancestry, Marginalized, ParticleStep, Slots};
use super::linear_plan::{LinearPlan, LinearScratch};
use super::model::{ConditionallyLinear, LinearDims};
use super::store::Shape;

/// The per-particle step of the MLN-RBPF (SPEC §5.2) and what it needs from the model, read once.
pub struct MlnStep<M> {
    model: M,
    plan: LinearPlan,
    /// Per stage, the rows that do not depend on `z`.
    unlinked: Vec<Unlinked>,
    draws: usize,
}

/// The rows of a stage that do not depend on `z`, split by their noise.
struct Unlinked {
    /// With non-zero noise: (position in `stage.rows`, row of `u`, s.d.).
    noisy: Vec<(usize, usize, f64)>,
    /// Without noise: (position in `stage.rows`, row of `u`).
    quiet: Vec<(usize, usize)>,
}

/// Scratch of one [`MlnStep`] for one number type.
pub struct MlnScratch<T> {
    lin: LinearScratch<T>,
    f: Vec<T>,
    pred: Vec<T>,
    drawn: Vec<T>,
}

impl<M: ConditionallyLinear> MlnStep<M> {
    /// Reads the model's dimensions, stages, noise and `R`, and records the Jacobian patterns.
    #[track_caller]
    pub fn new(model: M) -> Self {
        let plan = LinearPlan::new(&model);
        let mut draws = 0;
        let unlinked: Vec<Unlinked> = plan
            .stages
            .iter()
            .map(|st| {
                let mut u = Unlinked {
                    noisy: Vec::new(),
                    quiet: Vec::new(),
                };
                for (p, &r) in st.stage.rows.iter().enumerate() {
                    match (st.linked_index[p], st.sd[p]) {
                        (Some(_), _) => {}
                        (None, 0.0) => u.quiet.push((p, r)),
                        (None, sd) => u.noisy.push((p, r, sd)),
                    }
                }
                draws += st.stage.linked.len() + u.noisy.len();
                u
            })
            .collect();
        Self {
            model,
            plan,
            unlinked,
            draws,
        }
    }
}

impl<M: ConditionallyLinear> ParticleStep for MlnStep<M> {
    type Scratch<T: Real> = MlnScratch<T>;

    fn name(&self) -> &'static str {
        "mln-rbpf"
    }

    type Model = M;

    fn model(&self) -> &M {
        &self.model
    }

    fn broken_pattern<T: Real>(s: &MlnScratch<T>) -> Option<&'static str> {
        s.lin.broken_pattern()
    }

    fn scratch<T: Real>(&self) -> MlnScratch<T> {
        let LinearDims { nu, .. } = self.plan.dims;
        MlnScratch {
            lin: self.plan.scratch(),
            f: vec![T::splat(0.0); nu],
            pred: vec![T::splat(0.0); nu],
            drawn: vec![T::splat(0.0); nu],
        }
    }

    fn shape(&self) -> Shape {
        self.plan.shape()
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
        for (st, (plan, unlinked)) in self.plan.stages.iter().zip(&self.unlinked).enumerate() {
            let F = &mut s.lin.F[st];
            F.evaluate(|j| self.model.transition(st, k, u_prev, u, &mut s.f, j));
            // Rows that do not depend on z: f plus their own noise (or copied exactly).
            for &(pos, row, sd) in &unlinked.noisy {
                u[row] = s.f[pos] + T::splat(sd) * xi[next_draw];
                next_draw += 1;
            }
            for &(pos, row) in &unlinked.quiet {
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
            let factor = &mut s.lin.factors[st];
            ok = ok & factorise(factor, C, F, &s.lin.q_l[st], health);
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
        let lin = &mut s.lin;
        lin.H
            .evaluate(|j| self.model.observation(k, u, &mut lin.h, j));
        lin.innovation(y, mu);
        ok = ok & factorise(&mut lin.y_factor, C, &lin.H, &lin.r, health);
        let (loglik, upd) = lin.y_factor.update(mu, C, &lin.resid);
        (loglik, ok & upd)
    }
}

/// MLN-RBPF (SPEC §5.2) as a [`super::Filter`]: its per-particle step run by the batch layer.
pub type MlnRbpf<M> = Marginalized<MlnStep<M>>;

impl<M: ConditionallyLinear> MlnRbpf<M> {
    /// The filter with the batch layer's lanes where they pay (up to `batch::MAX_LANE_DIM`).
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
