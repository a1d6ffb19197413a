//! The set-up the MLN-RBPF and Storvik share (SPEC §5.2–5.3): what each reads once from a
//! [`ConditionallyLinear`] model — its dimensions, per stage the linked rows with their noise, the
//! Jacobian patterns of `F` and `H`, `R` — and the scratch both fill per particle.

#![allow(non_snake_case)] // F, H as in the SPEC

use crate::linalg::{Factor, Sparse};
use crate::real::Real;

use super::model::{ConditionallyLinear, LinearDims, Stage};
use super::store::Shape;

/// One stage of the transition with what both filters need of its rows.
pub(crate) struct StagePlan {
    pub stage: Stage,
    /// Per row of the stage: its index among the stage's linked rows, if linked.
    pub linked_index: Vec<Option<usize>>,
    /// Per linked row: its position among the stage's rows.
    pub linked_pos: Vec<usize>,
    /// Per row of the stage: the process-noise s.d.
    pub sd: Vec<f64>,
    /// `Q_L`, the noise of the linked rows (dense, `l × l`): the noise of the stage's
    /// pseudo-measurement of `z`.
    pub q_l: Vec<f64>,
}

/// What the MLN-RBPF and Storvik read once from the model.
pub(crate) struct LinearPlan {
    pub dims: LinearDims,
    pub stages: Vec<StagePlan>,
    /// Recorded pattern of `F` per stage (over its linked rows).
    pub f_patterns: Vec<Sparse<f64>>,
    /// Recorded pattern of `H`.
    pub h_pattern: Sparse<f64>,
    /// `R` (column-major `ny × ny`).
    pub r: Vec<f64>,
}

impl LinearPlan {
    /// Reads the model's dimensions, stages, noise and `R`, and records the patterns of `F`
    /// and `H` with one evaluation at `u = 0` (the values are irrelevant, the pattern is the
    /// structure's).
    #[track_caller]
    pub fn new<M: ConditionallyLinear>(model: &M) -> Self {
        let dims = model.dims();
        let LinearDims { nu, nz, ny } = dims;
        let sd = model.process_noise_sd();
        assert_eq!(sd.len(), nu, "process noise s.d. of every row of u");
        let stages = model
            .stages()
            .iter()
            .map(|st| StagePlan {
                stage: st.clone(),
                linked_index: st
                    .rows
                    .iter()
                    .map(|r| st.linked.iter().position(|l| l == r))
                    .collect(),
                linked_pos: st.linked_positions(),
                sd: st.rows.iter().map(|&r| sd[r]).collect(),
                q_l: st.linked_noise_cov(sd),
            })
            .collect();
        let zeros = vec![0.0; nu];
        let mut f = vec![0.0; nu];
        let f_patterns = model
            .stages()
            .iter()
            .enumerate()
            .map(|(s, stage)| {
                let mut F = Sparse::recording(stage.linked.len(), nz);
                F.evaluate(|j| model.transition(s, 1, &zeros, &zeros, &mut f, j));
                F
            })
            .collect();
        let mut h_pattern = Sparse::recording(ny, nz);
        let mut h = vec![0.0; ny];
        h_pattern.evaluate(|j| model.observation(1, &zeros, &mut h, j));
        let r = model.measurement_cov();
        assert_eq!(r.len(), ny * ny, "R is ny × ny");
        Self {
            dims,
            stages,
            f_patterns,
            h_pattern,
            r,
        }
    }

    /// The particle store's shape: `u` sampled, `z` marginalised.
    pub fn shape(&self) -> Shape {
        Shape {
            sampled: self.dims.nu,
            marginal: self.dims.nz,
        }
    }

    /// The scratch both filters fill per particle, for one number type.
    pub fn scratch<T: Real>(&self) -> LinearScratch<T> {
        let LinearDims { nz, ny, .. } = self.dims;
        let splat = |v: &[f64]| v.iter().map(|x| T::splat(*x)).collect::<Vec<T>>();
        LinearScratch {
            F: self
                .f_patterns
                .iter()
                .map(Sparse::with_pattern_of)
                .collect(),
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
}

/// Per-particle scratch both filters use: `F` and the factor of each stage's pseudo-measurement,
/// `h`, `H`, the measurement residual and its factor.
pub(crate) struct LinearScratch<T> {
    pub F: Vec<Sparse<T>>,
    pub q_l: Vec<Vec<T>>,
    pub factors: Vec<Factor<T>>,
    pub h: Vec<T>,
    pub H: Sparse<T>,
    pub r: Vec<T>,
    pub resid: Vec<T>,
    pub y_factor: Factor<T>,
}

impl<T: Real> LinearScratch<T> {
    /// Which Jacobian, if any, was written with another pattern than the recorded one.
    pub(crate) fn broken_pattern(&self) -> Option<&'static str> {
        if self.F.iter().any(Sparse::pattern_broken) {
            Some("transition matrix F")
        } else if self.H.pattern_broken() {
            Some("measurement matrix H")
        } else {
            None
        }
    }

    /// `resid = y − h − H μ`: the innovation of `y_k` given `(h, H) = observation(k, u_k)`.
    // Always inlined into the MLN-RBPF's and Storvik's steps (docs/performance.md, "Speed
    // across builds").
    #[inline(always)]
    pub fn innovation(&mut self, y: &[f64], mu: &[T]) {
        for (j, r) in self.resid.iter_mut().enumerate() {
            *r = T::splat(y[j]) - self.h[j];
        }
        for e in 0..self.H.nnz() {
            let (r, c, v) = self.H.entry(e);
            self.resid[r] -= v * mu[c];
        }
    }
}
