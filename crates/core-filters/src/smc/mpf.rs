//! MPF-EKF2: the marginalised particle filter with second-order EKF blocks (SPEC §5.4, with the
//! exact derivatives of §6), on run-time dimensions.
//!
//! The state splits into a small sampled block `xⁿ` (particles) and a marginalised block `x^bl`
//! carried per particle as a Gaussian `N(m, P)`. Given `xⁿ`, every map is at most quadratic in
//! `x^bl`, so the EKF2 moments (SPEC §4) are exact moments of the maps of the Gaussian.
//!
//! One step `k` of one particle `(xⁿ_{k−1}, m, P)` ([`MpfStep::advance`]); for each stage of the
//! sampled dynamics (forward Euler has one; a semi-implicit scheme samples the velocities first,
//! then the hysteretic variables with the new velocities):
//! - (a) proposal: `xⁿ_k[stage] ~ N(ψ(m) + ½tr(𝓗ⁱP), J P Jᵀ + ½tr(𝓗ⁱP𝓗^{i'}P) + Qₙ)`;
//! - (b) EKF2 update of `x^bl_{k−1}` with that pseudo-measurement: same moments, one factor, and
//!   the whitened innovation is the draw itself;
//!
//! then
//! - (c) EKF2 propagate of `x^bl` through `φ_bl(xⁿ_{k−1}, xⁿ_k, ·)` at the updated mean, with the
//!   near-identity kernel (`J = I + D`, [`ekf2_propagate_near_identity`]);
//! - (d)+(e) EKF2 update with `y_k` at `xⁿ_k`; its innovation log-density is the particle's
//!   weight factor. Normalising and resampling are the runner's.
//!
//! Entries of `xⁿ` in no stage (the Bouc–Wen exponents) are static and copied; the runner may
//! move them after resampling ([`super::rejuvenation`], off by default).
//!
//! A model with `M = substeps() > 1` transitions per measurement (a time grid `M` times finer
//! than the data) gets (a)–(c) `M` times, each with its own draws, before (d)+(e) — the same
//! filter on a grid whose intermediate points have no measurement.
//!
//! Failure policy: a particle whose Gaussian computations fail even after the documented repair
//! gets a NaN log-weight (mapped to −∞ and counted by the weight routine); the run fails only if
//! every particle fails.

use crate::health::Health;
use crate::linalg::gauss::factorise;
use crate::linalg::{
    ekf2_propagate_near_identity, Factor, PropagateScratch, Propagation, SecondOrder, Sparse,
};
use crate::real::Real;

use super::batch::{Ancestry, Marginalized, ParticleStep, Slots};
use super::model::{ConditionallyQuadratic, QuadraticDims, SampledAt};
use super::store::Shape;

/// What one sampled stage needs, read once from the model.
struct StagePlan {
    rows: Vec<usize>,
    hess: SecondOrder,
    /// `Qₙ` of the stage (diagonal variances).
    q: Vec<f64>,
    jac: Sparse<f64>,
}

/// The per-particle step of the MPF-EKF2 (SPEC §5.4).
pub struct MpfStep<M> {
    model: M,
    dims: QuadraticDims,
    stages: Vec<StagePlan>,
    d_pattern: Sparse<f64>,
    /// `φ_bl`'s Hessians and `Q_bl`.
    marginal: Propagation,
    y_pattern: Sparse<f64>,
    y_hess: SecondOrder,
    r: Vec<f64>,
    /// Transitions per measurement ([`ConditionallyQuadratic::substeps`]).
    substeps: usize,
    /// Standard normal draws of one transition (the batch layer supplies `substeps` times as many).
    draws: usize,
}

/// Scratch of one stage.
pub(crate) struct StageScratch<T> {
    value: Vec<T>,
    jac: Sparse<T>,
    mean2: Vec<T>,
    cov2: Vec<T>,
    pred: Vec<T>,
    s_add: Vec<T>,
    drawn: Vec<T>,
    factor: Factor<T>,
}

/// Scratch of one [`MpfStep`] for one number type.
pub struct MpfScratch<T> {
    stages: Vec<StageScratch<T>>,
    phi: Vec<T>,
    d: Sparse<T>,
    propagate: PropagateScratch<T>,
    h: Vec<T>,
    jy: Sparse<T>,
    mean2: Vec<T>,
    cov2: Vec<T>,
    s_add: Vec<T>,
    resid: Vec<T>,
    y_factor: Factor<T>,
    /// `xⁿ` after the previous sub-step (sub-steps after the first).
    xn_sub: Vec<T>,
}

/// Writes the additive covariance `Q (diagonal) + cov2 at the Hessian outputs` (`q × q`).
#[inline]
fn additive_cov<T: Real>(s_add: &mut [T], q: usize, diag: &[T], hess: &SecondOrder, cov2: &[T]) {
    s_add[..q * q].fill(T::splat(0.0));
    for i in 0..q {
        s_add[i + i * q] = diag[i];
    }
    let k = hess.len();
    for g in 0..k {
        for h in 0..k {
            s_add[hess.output(g) + hess.output(h) * q] += cov2[g + h * k];
        }
    }
}

impl<M: ConditionallyQuadratic> MpfStep<M> {
    /// Reads the model's dimensions, stages, Hessians and noise, and records the Jacobian
    /// patterns with one evaluation at zero.
    #[track_caller]
    pub fn new(model: M) -> Self {
        let dims = model.dims();
        let (nn, nbl, ny) = (dims.nn, dims.nbl, dims.ny);
        let zn = vec![0.0; nn];
        let zbl = vec![0.0; nbl];
        let mut draws = 0;
        let stages: Vec<StagePlan> = model
            .sampled_stages()
            .iter()
            .enumerate()
            .map(|(s, rows)| {
                let q: Vec<f64> = model.sampled_noise_sd(s).iter().map(|v| v * v).collect();
                assert_eq!(
                    q.len(),
                    rows.len(),
                    "noise s.d. of every entry of stage {s}"
                );
                let mut jac = Sparse::recording(rows.len(), nbl);
                let mut value = vec![0.0; rows.len()];
                jac.evaluate(|j| {
                    let at = SampledAt {
                        stage: s,
                        k: 1,
                        prev: &zn,
                        new: &zn,
                        m: &zbl,
                    };
                    model.sampled_dynamics(at, &mut value, j)
                });
                draws += rows.len();
                StagePlan {
                    rows: rows.clone(),
                    hess: SecondOrder::new(model.sampled_hessians(s), nbl, rows.len()),
                    q,
                    jac,
                }
            })
            .collect();
        let mut d_pattern = Sparse::recording(nbl, nbl);
        let mut phi = vec![0.0; nbl];
        d_pattern.evaluate(|j| model.marginal_dynamics(1, &zn, &zn, &zbl, &mut phi, j));
        let mut y_pattern = Sparse::recording(ny, nbl);
        let mut h = vec![0.0; ny];
        y_pattern.evaluate(|j| model.observation(1, &zn, &zbl, &mut h, j));
        let r = model.measurement_cov();
        assert_eq!(r.len(), ny * ny, "R is ny × ny");
        let substeps = model.substeps();
        assert!(substeps >= 1, "at least one transition per measurement");
        Self {
            substeps,
            marginal: Propagation {
                hess: SecondOrder::new(model.marginal_hessians(), nbl, nbl),
                q: model.marginal_noise().clone(),
            },
            y_hess: SecondOrder::new(model.observation_hessians(), nbl, ny),
            model,
            dims,
            stages,
            d_pattern,
            y_pattern,
            r,
            draws,
        }
    }

    /// SPEC §5.4 (a) on its own, for tests and diagnostics: the mean and covariance (`q × q`,
    /// column-major) of the proposal of stage `stage` for a particle at `(xⁿ_{k−1}, N(m, P))`,
    /// computed by the same kernels as the step.
    pub fn proposal_moments(
        &self,
        stage: usize,
        k: usize,
        xn_prev: &[f64],
        m: &[f64],
        p: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let nbl = self.dims.nbl;
        let plan = &self.stages[stage];
        let q = plan.rows.len();
        let mut s = self.scratch::<f64>();
        let ss = &mut s.stages[stage];
        ss.jac.evaluate(|j| {
            let at = SampledAt {
                stage,
                k,
                prev: xn_prev,
                new: xn_prev,
                m,
            };
            self.model.sampled_dynamics(at, &mut ss.value, j)
        });
        let mut mean = ss.value.clone();
        if !plan.hess.is_empty() {
            plan.hess.terms(p, nbl, &mut ss.mean2, &mut ss.cov2);
            for g in 0..plan.hess.len() {
                mean[plan.hess.output(g)] += ss.mean2[g];
            }
        }
        additive_cov(&mut ss.s_add, q, &plan.q, &plan.hess, &ss.cov2);
        ss.factor.compute(p, &ss.jac, &ss.s_add);
        (mean, ss.factor.cov.clone())
    }

    /// SPEC §5.4 (a)–(c) for the transition to index `k` of the model's grid: every sampled stage
    /// drawn from its EKF2 proposal (with the next of the particle's `draws`) with the update of
    /// `x^bl` by the draw, then the EKF2 propagate of `x^bl`.
    #[inline]
    fn transition<T: Real>(
        &self,
        k: usize,
        xn_prev: &[T],
        p: &mut Slots<'_, T>,
        draws: &mut Draws<'_, T>,
        s: &mut MpfScratch<T>,
        health: &mut Health,
    ) -> T::Mask {
        let (xn, m, cov) = (&mut *p.sampled, &mut *p.mean, &mut *p.cov);
        let nbl = self.dims.nbl;
        let mut ok = T::all_true();
        for (st, plan) in self.stages.iter().enumerate() {
            let ss = &mut s.stages[st];
            let q = plan.rows.len();
            // (a) the EKF2 moments of ψ: mean ψ(m) + ½tr(𝓗ⁱP), covariance J P Jᵀ + cov2 + Qₙ.
            ss.jac.evaluate(|j| {
                let at = SampledAt {
                    stage: st,
                    k,
                    prev: xn_prev,
                    new: xn,
                    m,
                };
                self.model.sampled_dynamics(at, &mut ss.value, j)
            });
            ss.pred.copy_from_slice(&ss.value);
            if !plan.hess.is_empty() {
                plan.hess.terms(cov, nbl, &mut ss.mean2, &mut ss.cov2);
                for g in 0..plan.hess.len() {
                    ss.pred[plan.hess.output(g)] += ss.mean2[g];
                }
            }
            let q_diag: &mut [T] = &mut ss.drawn;
            for (d, v) in q_diag.iter_mut().zip(&plan.q) {
                *d = T::splat(*v);
            }
            additive_cov(&mut ss.s_add, q, q_diag, &plan.hess, &ss.cov2);
            ok = ok & factorise(&mut ss.factor, cov, &ss.jac, &ss.s_add, health);
            // (a) the draw and (b) the update of x^bl_{k−1} with it (whitened innovation ξ).
            let xi_s = draws.take(q);
            ok = ok
                & ss.factor
                    .condition_on_draw(m, cov, &ss.pred, xi_s, &mut ss.drawn);
            for (i, &row) in plan.rows.iter().enumerate() {
                xn[row] = ss.drawn[i];
            }
        }
        // (c) propagate x^bl through φ_bl(xⁿ_{k−1}, xⁿ_k, ·) at the updated mean.
        s.d.evaluate(|j| {
            self.model
                .marginal_dynamics(k, xn_prev, xn, m, &mut s.phi, j)
        });
        ekf2_propagate_near_identity(m, cov, nbl, &s.phi, &s.d, &self.marginal, &mut s.propagate);
        ok
    }
}

impl<M: ConditionallyQuadratic> ParticleStep for MpfStep<M> {
    type Scratch<T: Real> = MpfScratch<T>;

    fn name(&self) -> &'static str {
        "mpf-ekf2"
    }

    type Model = M;

    fn model(&self) -> &M {
        &self.model
    }

    fn broken_pattern<T: Real>(s: &MpfScratch<T>) -> Option<&'static str> {
        if s.stages.iter().any(|ss| ss.jac.pattern_broken()) {
            Some("sampled dynamics Jacobian")
        } else if s.d.pattern_broken() {
            Some("marginal dynamics Jacobian")
        } else if s.jy.pattern_broken() {
            Some("measurement Jacobian")
        } else {
            None
        }
    }

    fn scratch<T: Real>(&self) -> MpfScratch<T> {
        let QuadraticDims { nbl, ny, .. } = self.dims;
        let z = T::splat(0.0);
        let stages = self
            .stages
            .iter()
            .map(|p| {
                let q = p.rows.len();
                let k = p.hess.len();
                StageScratch {
                    value: vec![z; q],
                    jac: Sparse::with_pattern_of(&p.jac),
                    mean2: vec![z; k],
                    cov2: vec![z; k * k],
                    pred: vec![z; q],
                    s_add: vec![z; q * q],
                    drawn: vec![z; q],
                    factor: Factor::new(nbl, q),
                }
            })
            .collect();
        let ky = self.y_hess.len();
        MpfScratch {
            stages,
            phi: vec![z; nbl],
            d: Sparse::with_pattern_of(&self.d_pattern),
            propagate: PropagateScratch::new(nbl, &self.marginal.hess),
            h: vec![z; ny],
            jy: Sparse::with_pattern_of(&self.y_pattern),
            mean2: vec![z; ky],
            cov2: vec![z; ky * ky],
            s_add: vec![z; ny * ny],
            resid: vec![z; ny],
            y_factor: Factor::new(nbl, ny),
            xn_sub: vec![z; self.dims.nn],
        }
    }

    fn shape(&self) -> Shape {
        Shape {
            sampled: self.dims.nn,
            marginal: self.dims.nbl,
        }
    }

    fn draws(&self) -> usize {
        self.draws * self.substeps
    }

    /// SPEC §5.4 (a)–(e) for one particle (or a pack).
    fn advance<T: Real>(
        &self,
        from: Ancestry<'_, T>,
        p: Slots<'_, T>,
        s: &mut MpfScratch<T>,
        health: &mut Health,
    ) -> (T, T::Mask) {
        let Ancestry {
            k,
            y,
            prev: xn_prev,
            xi,
        } = from;
        let mut p = p;
        let nbl = self.dims.nbl;
        let mut ok = T::all_true();
        let mut draws = Draws { xi, next: 0 };
        // (a)–(c) once per transition of the model's grid between y_{k−1} and y_k (grid indices
        // (k−1)M+1 ..= kM, M = substeps); the first starts at the ancestor's xⁿ.
        let last = k * self.substeps;
        let first = last + 1 - self.substeps;
        ok = ok & self.transition(first, xn_prev, &mut p, &mut draws, s, health);
        if self.substeps > 1 {
            // Moved out of the scratch while the scratch is lent (no allocation).
            let mut xn_sub = std::mem::take(&mut s.xn_sub);
            for kf in first + 1..=last {
                xn_sub.copy_from_slice(p.sampled);
                ok = ok & self.transition(kf, &xn_sub, &mut p, &mut draws, s, health);
            }
            s.xn_sub = xn_sub;
        }
        let (xn, m, cov) = (p.sampled, p.mean, p.cov);
        // (d)+(e) the EKF2 update with y_k at grid index kM; its innovation log-density is the
        // weight factor.
        let k = last;
        s.jy.evaluate(|j| self.model.observation(k, xn, m, &mut s.h, j));
        let ny = self.dims.ny;
        for j in 0..ny {
            s.resid[j] = T::splat(y[j]) - s.h[j];
        }
        if !self.y_hess.is_empty() {
            self.y_hess.terms(cov, nbl, &mut s.mean2, &mut s.cov2);
            for g in 0..self.y_hess.len() {
                s.resid[self.y_hess.output(g)] -= s.mean2[g];
            }
        }
        for v in s.s_add.iter_mut() {
            *v = T::splat(0.0);
        }
        let k2 = self.y_hess.len();
        for c in 0..ny {
            for r in 0..ny {
                s.s_add[r + c * ny] = T::splat(self.r[r + c * ny]);
            }
        }
        for g in 0..k2 {
            for h in 0..k2 {
                s.s_add[self.y_hess.output(g) + self.y_hess.output(h) * ny] += s.cov2[g + h * k2];
            }
        }
        ok = ok & factorise(&mut s.y_factor, cov, &s.jy, &s.s_add, health);
        let (loglik, upd) = s.y_factor.update(m, cov, &s.resid);
        debug_assert_eq!(draws.next, self.draws * self.substeps);
        (loglik, ok & upd)
    }
}

/// A particle's standard normal draws of one step, taken in order by the transitions.
struct Draws<'a, T> {
    xi: &'a [T],
    next: usize,
}

impl<'a, T> Draws<'a, T> {
    /// The next `q` draws.
    #[inline]
    fn take(&mut self, q: usize) -> &'a [T] {
        let d = &self.xi[self.next..self.next + q];
        self.next += q;
        d
    }
}

/// MPF-EKF2 (SPEC §5.4) as a [`super::Filter`]: its per-particle step run by the batch layer.
pub type MpfEkf2<M> = Marginalized<MpfStep<M>>;

impl<M: ConditionallyQuadratic> MpfEkf2<M> {
    /// The filter with the batch layer's lanes where they pay.
    pub fn new(model: M) -> Self {
        Self::with_lanes(model, true)
    }

    /// `lanes = false` runs every particle through the `f64` step (the reference).
    pub fn with_lanes(model: M, lanes: bool) -> Self {
        Marginalized::from_step(MpfStep::new(model), lanes)
    }

    pub fn model(&self) -> &M {
        self.particle_step().model()
    }
}
