//! Storvik's algorithm with Gaussian sufficient statistics (SPEC §5.3; Storvik 2002, with the
//! paper's update, §3.3.2), on run-time dimensions.
//!
//! Same partition as the MLN-RBPF: each particle carries `u` and the sufficient statistics
//! `s = (μ, C)` of the static block `z`. Per particle and step ([`StorvikStep::advance`]):
//! - (i) draw a realisation `z0 ~ N(μ, C)` (semidefinite factor: fixed parameters and directions
//!   the data pin down have zero spread, which is not a repair);
//! - (ii) `u_k ~ N(f + F z0, Q_u)`, stage by stage; weight `N(y_k; H(u_k) z0 + h(u_k), R)`;
//! - (iii) update `(μ, C)` with the stacked measurement `[u_{k,L}; y_k]`, noise
//!   `blockdiag(Q_L, R)`, as sequential updates (one per stage's linked rows, then `y_k`; with
//!   block-diagonal noise and measurements linear at a fixed point, sequential updates equal the
//!   stacked one). For `y_k`:
//!   - [`StorvikUpdate::Linearised`] (the paper's, default): `y_k` written through `u_{k−1}`,
//!     `g(z) = H(u_k(z)) z + h(u_k(z))`, linearised at `z0`: `G = H(u_k) + J_u ∂u_k/∂z`,
//!     `ŷ = g(z0) + G (μ − z0)`;
//!   - [`StorvikUpdate::Exact`]: given `u_k`, `y_k` is linear in `z`: the KF update with
//!     `(H(u_k), h(u_k))`, exactly as MLN-RBPF (d).
//!
//! Failure policy as the MLN-RBPF: a particle whose factorisation or update fails gets a NaN
//! log-weight; `R` is factorised once, and if it cannot be every step fails.

#![allow(non_snake_case)]

use serde::{Deserialize, Serialize};

use crate::error::FilterError;
use crate::health::Health;
use crate::linalg::gauss::{factorise, lower_mul, psd_cholesky};
use crate::linalg::{FactoredNoise, Sparse};
use crate::real::Real;

use super::batch::{Ancestry, Marginalized, ParticleStep, Slots};
use super::linear_plan::{LinearPlan, LinearScratch};
use super::model::{ConditionallyLinear, LinearDims};
use super::store::Shape;

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

/// The per-particle step of Storvik's algorithm (SPEC §5.3).
pub struct StorvikStep<M> {
    model: M,
    plan: LinearPlan,
    update: StorvikUpdate,
    ju_pattern: Sparse<f64>,
    s_pattern: Sparse<f64>,
    /// The terms of `G += J_u S` in the order they are summed (set-up, from the two patterns).
    g_terms: Vec<GTerm>,
    noise: Result<FactoredNoise, FilterError>,
    draws: usize,
}

/// Scratch of one [`StorvikStep`] for one number type.
pub struct StorvikScratch<T> {
    lin: LinearScratch<T>,
    L: Vec<T>,
    z0: Vec<T>,
    /// `f` of every stage (kept for the updates of step (iii)).
    f: Vec<Vec<T>>,
    fz: Vec<T>,
    resid_l: Vec<T>,
    Ju: Sparse<T>,
    S: Sparse<T>,
    G: Sparse<T>,
    yhat: Vec<T>,
    white: Vec<T>,
}

/// One term `G[g] += J_u[ju] · S[s]` of the product of the observation's Jacobian in `u` and the
/// transition's sensitivity (indices into `G`'s column-major values and the two patterns' entries).
#[derive(Debug, Clone, Copy)]
struct GTerm {
    g: u32,
    ju: u32,
    s: u32,
}

/// The terms of `J_u S` (`ny × nu` times `nu × nz`): for every entry `(i, c)` of `J_u` in its
/// order, every entry `(c, j)` of `S` in its order. Listed once at set-up, so that the step's
/// product is one pass over three indices instead of a walk through both patterns.
fn g_terms(ju: &Sparse<f64>, sens: &Sparse<f64>, ny: usize) -> Vec<GTerm> {
    let mut s_rows = vec![Vec::new(); sens.nrows()];
    for e in 0..sens.nnz() {
        s_rows[sens.entry(e).0].push(e);
    }
    let mut terms = Vec::new();
    for e in 0..ju.nnz() {
        let (i, c, _) = ju.entry(e);
        for &se in &s_rows[c] {
            let j = sens.entry(se).1;
            let index = |v: usize| u32::try_from(v).expect("a Jacobian of fewer than 2^32 entries");
            terms.push(GTerm {
                g: index(i + j * ny),
                ju: index(e),
                s: index(se),
            });
        }
    }
    terms
}

impl<M: ConditionallyLinear> StorvikStep<M> {
    /// Reads the model, records the Jacobian patterns and factorises `R` once.
    #[track_caller]
    pub fn new(model: M, update: StorvikUpdate) -> Self {
        let plan = LinearPlan::new(&model);
        let LinearDims { nu, nz, ny } = plan.dims;
        // z0 takes nz draws; every row with noise one more.
        let draws = nz
            + plan
                .stages
                .iter()
                .map(|st| st.sd.iter().filter(|s| **s != 0.0).count())
                .sum::<usize>();
        let zu = vec![0.0; nu];
        let zz = vec![0.0; nz];
        let mut ju_pattern = Sparse::recording(ny, nu);
        ju_pattern.evaluate(|j| model.observation_jacobian_u(1, &zu, &zz, j));
        let mut s_pattern = Sparse::recording(nu, nz);
        s_pattern.evaluate(|j| model.transition_sensitivity(1, &zu, &zu, &zz, j));
        let g_terms = g_terms(&ju_pattern, &s_pattern, ny);
        let mut setup = Health::default();
        let noise = FactoredNoise::new(&plan.r, ny, "measurement covariance R", &mut setup);
        Self {
            model,
            plan,
            update,
            ju_pattern,
            s_pattern,
            g_terms,
            noise,
            draws,
        }
    }
}

impl<M: ConditionallyLinear> ParticleStep for StorvikStep<M> {
    type Scratch<T: Real> = StorvikScratch<T>;

    fn name(&self) -> &'static str {
        "storvik"
    }

    type Model = M;

    fn model(&self) -> &M {
        &self.model
    }

    /// None: Storvik's algorithm draws θ from the Gaussian of its sufficient statistics at every
    /// step, so truncating the moments would not keep its draws ≥ 0 (and changes its statistics
    /// non-conjugately: with it the default regression's c1 spread rose from its bound 0.132 to
    /// 0.139). Its impossible answers stay flagged instead.
    fn lower_bounds(&self) -> Vec<crate::linalg::LowerBound> {
        Vec::new()
    }

    /// `R` is factorised once; if it could not be, every step fails with that error.
    fn check(&self, k: usize) -> Result<(), FilterError> {
        FactoredNoise::at_step(&self.noise, k).map(|_| ())
    }

    fn broken_pattern<T: Real>(s: &StorvikScratch<T>) -> Option<&'static str> {
        if let Some(which) = s.lin.broken_pattern() {
            Some(which)
        } else if s.Ju.pattern_broken() {
            Some("measurement Jacobian J_u")
        } else if s.S.pattern_broken() {
            Some("transition sensitivity S")
        } else {
            None
        }
    }

    fn scratch<T: Real>(&self) -> StorvikScratch<T> {
        let LinearDims { nu, nz, ny } = self.plan.dims;
        let z = T::splat(0.0);
        StorvikScratch {
            lin: self.plan.scratch(),
            L: vec![z; nz * nz],
            z0: vec![z; nz],
            f: self.plan.stages.iter().map(|_| vec![z; nu]).collect(),
            fz: vec![z; nu],
            resid_l: vec![z; nu],
            Ju: Sparse::with_pattern_of(&self.ju_pattern),
            S: Sparse::with_pattern_of(&self.s_pattern),
            G: Sparse::dense(ny, nz),
            yhat: vec![z; ny],
            white: vec![z; ny],
        }
    }

    fn shape(&self) -> Shape {
        self.plan.shape()
    }

    fn draws(&self) -> usize {
        self.draws
    }

    /// SPEC §5.3 (i)–(iii) for one particle (or a pack).
    fn advance<T: Real>(
        &self,
        from: Ancestry<'_, T>,
        p: Slots<'_, T>,
        s: &mut StorvikScratch<T>,
        health: &mut Health,
    ) -> (T, T::Mask) {
        let Ancestry {
            k,
            y,
            prev: u_prev,
            xi,
        } = from;
        let (u, mu, C) = (p.sampled, p.mean, p.cov);
        let LinearDims { nz, ny, .. } = self.plan.dims;
        let noise = match &self.noise {
            Ok(n) => n,
            Err(_) => return (T::splat(f64::NAN), T::not(T::all_true())),
        };
        // (i) z0 = μ + L ξ with L the semidefinite factor of C.
        let mut ok = psd_cholesky(C, nz, &mut s.L);
        lower_mul(&s.L, nz, &xi[..nz], &mut s.z0);
        for (z, m) in s.z0.iter_mut().zip(mu.iter()) {
            *z += *m;
        }
        let mut next_draw = nz;
        // (ii) u_k ~ N(f + F z0, Q_u), stage by stage.
        for (st, plan) in self.plan.stages.iter().enumerate() {
            let (F, f) = (&mut s.lin.F[st], &mut s.f[st]);
            F.evaluate(|j| self.model.transition(st, k, u_prev, u, f, j));
            let l = plan.stage.linked.len();
            s.fz[..l].fill(T::splat(0.0));
            F.mul_add(&s.z0, &mut s.fz[..l]);
            for (pos, &row) in plan.stage.rows.iter().enumerate() {
                let mut v = f[pos];
                if let Some(li) = plan.linked_index[pos] {
                    v += s.fz[li];
                }
                if plan.sd[pos] != 0.0 {
                    v += T::splat(plan.sd[pos]) * xi[next_draw];
                    next_draw += 1;
                }
                u[row] = v;
            }
        }
        // Weight N(y_k; H(u_k) z0 + h(u_k), R).
        let lin = &mut s.lin;
        lin.H
            .evaluate(|j| self.model.observation(k, u, &mut lin.h, j));
        s.yhat.copy_from_slice(&lin.h);
        lin.H.mul_add(&s.z0, &mut s.yhat);
        for j in 0..ny {
            lin.resid[j] = T::splat(y[j]) - s.yhat[j];
        }
        let loglik = noise.log_density(&lin.resid, &mut s.white);
        // (iii) the linked rows of every stage: linear in z along the sampled path.
        for (st, plan) in self.plan.stages.iter().enumerate() {
            let l = plan.stage.linked.len();
            if l == 0 {
                continue;
            }
            let F = &lin.F[st];
            for (i, &pos) in plan.linked_pos.iter().enumerate() {
                s.resid_l[i] = u[plan.stage.rows[pos]] - s.f[st][pos];
            }
            for e in 0..F.nnz() {
                let (r, c, v) = F.entry(e);
                s.resid_l[r] -= v * mu[c];
            }
            let factor = &mut lin.factors[st];
            ok = ok & factorise(factor, C, F, &lin.q_l[st], health);
            let (_, upd) = factor.update(mu, C, &s.resid_l[..l]);
            ok = ok & upd;
        }
        // … then y_k.
        match self.update {
            StorvikUpdate::Exact => {
                lin.innovation(y, mu);
                ok = ok & factorise(&mut lin.y_factor, C, &lin.H, &lin.r, health);
            }
            StorvikUpdate::Linearised => {
                // G = H(u_k) + J_u ∂u_k/∂z at z0, dense (ny × nz, column-major values).
                s.Ju.evaluate(|j| self.model.observation_jacobian_u(k, u, &s.z0, j));
                s.S.evaluate(|j| self.model.transition_sensitivity(k, u_prev, u, &s.z0, j));
                let g = s.G.values_mut();
                g.fill(T::splat(0.0));
                for e in 0..lin.H.nnz() {
                    let (r, c, v) = lin.H.entry(e);
                    g[r + c * ny] += v;
                }
                let (ju, sens) = (s.Ju.values(), s.S.values());
                for t in &self.g_terms {
                    g[t.g as usize] += ju[t.ju as usize] * sens[t.s as usize];
                }
                // ŷ = g(z0) + G (μ − z0), g(z0) = h + H z0 (= s.yhat).
                for j in 0..ny {
                    lin.resid[j] = T::splat(y[j]) - s.yhat[j];
                }
                for c in 0..nz {
                    let d = mu[c] - s.z0[c];
                    for r in 0..ny {
                        lin.resid[r] -= g[r + c * ny] * d;
                    }
                }
                ok = ok & factorise(&mut lin.y_factor, C, &s.G, &lin.r, health);
            }
        }
        let (_, upd) = lin.y_factor.update(mu, C, &lin.resid);
        debug_assert_eq!(next_draw, self.draws);
        (loglik, ok & upd)
    }
}

/// Storvik's algorithm (SPEC §5.3) as a [`super::Filter`]: its per-particle step run by the batch
/// layer.
pub type Storvik<M> = Marginalized<StorvikStep<M>>;

impl<M: ConditionallyLinear> Storvik<M> {
    pub fn new(model: M, update: StorvikUpdate) -> Self {
        Self::with_lanes(model, update, true)
    }

    /// `lanes = false` runs every particle through the `f64` step (the reference).
    pub fn with_lanes(model: M, update: StorvikUpdate, lanes: bool) -> Self {
        Marginalized::from_step(StorvikStep::new(model, update), lanes)
    }

    pub fn model(&self) -> &M {
        self.particle_step().model()
    }
}
