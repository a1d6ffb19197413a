//! One-step-ahead prediction errors of a run: the evidence, without the truth, that the model
//! fits the record (issue "a user's own records": measured against predicted accelerations,
//! normalised prediction errors and their whiteness).
//!
//! At every step k ≥ 2 the [`Predictor`] takes the posterior means of the states and of θ after
//! step k − 1, advances them one step with the filter's own equations of motion and
//! discretisation without noise (the augmented model of SPEC §5.1, the one source of the
//! physics) and measures: ŷ_k. The prediction error y_k − ŷ_k is divided by the measurement
//! noise s.d. √R_ii. This is the plug-in prediction at the posterior mean, not the filter's
//! exact predictive distribution: its variance is at least R_ii, so the normalised errors have
//! a variance of at least 1 when the model and its noise levels are right — a variance far
//! above 1, or errors correlated in time (Ljung–Box, `whiteness`), say that the
//! model or its noise levels do not fit the record.

use crate::error::Result;
use core_filters::model::Layout;
use core_filters::smc::model::{Partition, StateSpace};
use core_filters::smc::Posterior;
use models::filtering::{AugmentedChain, ChainSpec};
use serde::Serialize;

pub use crate::record::diagnostics::{ChannelCheck, Residuals};

/// Lags of the whiteness check.
pub(crate) const MAX_LAG: usize = 20;

/// Share of the record's first steps the whiteness check leaves out: the learning transient,
/// where the estimates still move and the errors of a right model are correlated by
/// construction. Measured on 150 channels of records of the model's own class (paper-3dof,
/// seeds 1–50, 500 particles): with every step tested the check flagged 15 (10 %), without the
/// first quarter 11 (7.3 %; 7.5 expected of a 5 % test); validated on seeds 51–100
/// (docs/residuals.md).
pub(crate) const LEARNING_SHARE: f64 = 0.25;

/// The one-step-ahead predictor of one run (see the module documentation).
pub struct Predictor {
    model: AugmentedChain,
    /// `y_k` for k = 1..=K, row-major, `ny` per row.
    ys: Vec<f64>,
    ny: usize,
    dt: f64,
    noise_sd: Vec<f64>,
    /// For each entry of the augmented state: where it is in the filter's posterior (state or
    /// parameter index), filled at the first step.
    map: Option<Vec<Source>>,
    prev: Vec<f64>,
    have_prev: bool,
    next: Vec<f64>,
    zeros: Vec<f64>,
    yhat: Vec<f64>,
    out: Residuals,
}

#[derive(Debug, Clone, Copy)]
enum Source {
    State(usize),
    Param(usize),
}

impl Predictor {
    /// A predictor with the run's filter specification (noise levels, discretisation, sensors)
    /// for the measurements `ys` (`y_k` for k = 1..=K, `ny` per row) named `channels`.
    pub fn new(mut spec: ChainSpec, ys: Vec<f64>, channels: Vec<String>) -> Result<Self> {
        // The prediction errors are the model's, scaled by the whole measurement noise: a
        // coloured part of it is a state of the filter, not of the structure's prediction.
        spec.coloured_noise = None;
        spec.regressors = None;
        let ny = channels.len();
        let noise_sd = spec.r_diag.iter().map(|r| r.sqrt()).collect();
        let dt = spec.dt;
        let model = AugmentedChain::new(spec)?;
        let dim = model.dim();
        let noise = model.noise_dim();
        Ok(Self {
            model,
            ys,
            ny,
            dt,
            noise_sd,
            map: None,
            prev: vec![0.0; dim],
            have_prev: false,
            next: vec![0.0; dim],
            zeros: vec![0.0; noise],
            yhat: vec![0.0; ny],
            out: Residuals {
                channels,
                ..Residuals::default()
            },
        })
    }

    fn mapping(&self, layout_states: &[String], layout_params: &[String]) -> Option<Vec<Source>> {
        let l = self.model.layout();
        let mut map = vec![Source::State(0); self.model.dim()];
        for (name, slot) in l.state_names.iter().zip(&l.states) {
            let i = layout_states.iter().position(|n| n == name)?;
            map[slot_index(*slot)] = Source::State(i);
        }
        for (name, slot) in l.param_names.iter().zip(&l.params) {
            let i = layout_params.iter().position(|n| n == name)?;
            map[slot_index(*slot)] = Source::Param(i);
        }
        Some(map)
    }

    /// Called at the start of a run with the filter's layout. A filter whose layout does not
    /// name every state and parameter of the chain gets no prediction errors.
    pub fn start(&mut self, layout: &Layout) {
        self.map = self.mapping(&layout.state_names, &layout.param_names);
        self.have_prev = false;
    }

    /// Called after step `k` with its posterior summary.
    pub fn step(&mut self, k: usize, post: &Posterior) {
        let Some(map) = &self.map else { return };
        if self.have_prev && k >= 1 && k * self.ny <= self.ys.len() {
            self.model
                .propagate(k, &self.prev, &self.zeros, &mut self.next);
            self.model.measure(k, &self.next, &mut self.yhat);
            let y = &self.ys[(k - 1) * self.ny..k * self.ny];
            self.out.t.push(k as f64 * self.dt);
            self.out.measured.push(y.to_vec());
            self.out.predicted.push(self.yhat.clone());
            self.out.normalised_innovation.push(
                y.iter()
                    .zip(&self.yhat)
                    .zip(&self.noise_sd)
                    .map(|((a, b), s)| (a - b) / s)
                    .collect(),
            );
        }
        for (v, src) in self.prev.iter_mut().zip(map) {
            *v = match *src {
                Source::State(i) => post.state_mean[i],
                Source::Param(i) => post.param_mean[i],
            };
        }
        self.have_prev = true;
    }

    /// The prediction errors of the run (empty when the layout did not map).
    pub fn finish(mut self) -> Residuals {
        if !self.out.t.is_empty() {
            self.out.noise_sd = self.noise_sd;
        }
        self.out
    }
}

fn slot_index(slot: core_filters::model::Slot) -> usize {
    match slot {
        core_filters::model::Slot::Sampled(i) | core_filters::model::Slot::Marginal(i) => i,
    }
}

/// The check of every channel over the steps after the learning transient
/// (`LEARNING_SHARE`; channels with too few finite values are left out).
pub fn channel_checks(r: &Residuals) -> Vec<ChannelCheck> {
    let from = (r.normalised_innovation.len() as f64 * LEARNING_SHARE).round() as usize;
    r.channels
        .iter()
        .enumerate()
        .filter_map(|(i, name)| {
            let x: Vec<f64> = r.normalised_innovation[from..]
                .iter()
                .map(|row| row[i])
                .collect();
            let w: Whiteness = whiteness(&x, MAX_LAG)?;
            Some(ChannelCheck {
                channel: name.clone(),
                n: w.n,
                mean: w.mean,
                variance: w.variance,
                white: w.is_white(),
                ljung_box: w.ljung_box,
                critical: w.critical,
            })
        })
        .collect()
}

/// One line per channel for the terminal summary.
pub fn describe(checks: &[ChannelCheck]) -> Vec<String> {
    checks
        .iter()
        .map(|c| {
            format!(
                "{}: one-step prediction errors / noise s.d. (after the first quarter, the learning transient): mean {:+.2}, variance {:.2}; {}",
                c.channel,
                c.mean,
                c.variance,
                if c.white {
                    format!(
                        "consistent with white noise (Ljung–Box Q = {:.1} < {:.1})",
                        c.ljung_box, c.critical
                    )
                } else {
                    format!(
                        "correlated in time (Ljung–Box Q = {:.1}, {:.1}× its 95 % critical \
                         value): the model, its noise levels or this run's estimates do not \
                         fully explain the record (docs/residuals.md)",
                        c.ljung_box,
                        c.ljung_box / c.critical
                    )
                }
            )
        })
        .collect()
}

/// Whiteness check of one channel's normalised innovations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Whiteness {
    pub n: usize,
    pub mean: f64,
    pub variance: f64,
    /// Sample autocorrelation at lags 1..=L.
    pub autocorrelation: Vec<f64>,
    /// 1.96/√n: the 95% band of one autocorrelation of a white sequence.
    pub bound: f64,
    /// Ljung–Box statistic Q = n(n+2) Σ ρ_k²/(n−k) over lags 1..=L, and its 95% critical value
    /// (χ²_L quantile, Wilson–Hilferty approximation).
    pub ljung_box: f64,
    pub critical: f64,
}

impl Whiteness {
    /// Whether the sequence passes: Q below its 95% critical value.
    pub(crate) fn is_white(&self) -> bool {
        self.ljung_box < self.critical
    }
}

/// 95% quantile of χ² with `dof` degrees of freedom: exact for 1 and 2 (1.96² and −2 ln 0.05),
/// Wilson–Hilferty from 3 up (relative error below 1%; 2.4 % at 1 degree, where the likelihood
/// region of one free parameter needs it).
pub fn chi2_95(dof: usize) -> f64 {
    match dof {
        1 => return 3.841_458_820_694_124,
        2 => return -2.0 * 0.05_f64.ln(),
        _ => {}
    }
    let k = dof as f64;
    let z = 1.644_853_626_951_472_2;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

/// Whiteness check of a sequence (finite values only) up to `max_lag` lags (fewer when the
/// sequence is short: at most n/4). `None` with fewer than 8 finite values.
pub(crate) fn whiteness(x: &[f64], max_lag: usize) -> Option<Whiteness> {
    let v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    let n = v.len();
    if n < 8 {
        return None;
    }
    let lags = max_lag.min(n / 4).max(1);
    let mean = v.iter().sum::<f64>() / n as f64;
    let c0 = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n as f64;
    let rho: Vec<f64> = (1..=lags)
        .map(|k| {
            let ck = (0..n - k)
                .map(|i| (v[i] - mean) * (v[i + k] - mean))
                .sum::<f64>()
                / n as f64;
            if c0 > 0.0 {
                ck / c0
            } else {
                0.0
            }
        })
        .collect();
    let nf = n as f64;
    let q = nf
        * (nf + 2.0)
        * rho
            .iter()
            .enumerate()
            .map(|(k, r)| r * r / (nf - (k + 1) as f64))
            .sum::<f64>();
    Some(Whiteness {
        n,
        mean,
        variance: c0 * nf / (nf - 1.0),
        autocorrelation: rho,
        bound: 1.96 / nf.sqrt(),
        ljung_box: q,
        critical: chi2_95(lags),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi_square_quantiles() {
        // Tables: χ²_0.95 with 10 and 20 degrees of freedom.
        assert!((chi2_95(1) - 3.8415).abs() < 1e-4, "{}", chi2_95(1));
        assert!((chi2_95(2) - 5.9915).abs() < 1e-4, "{}", chi2_95(2));
        assert!((chi2_95(3) - 7.8147).abs() < 0.08, "{}", chi2_95(3));
        assert!((chi2_95(10) - 18.307).abs() < 0.05, "{}", chi2_95(10));
        assert!((chi2_95(20) - 31.410).abs() < 0.05, "{}", chi2_95(20));
    }

    #[test]
    fn white_noise_passes_and_a_random_walk_fails() {
        // SplitMix64 uniforms (fixed seed); sums of 12 give mean 0, variance 1, independent.
        let mut state = 7u64;
        let mut uniform = || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let white: Vec<f64> = (0..2000)
            .map(|_| (0..12).map(|_| uniform()).sum::<f64>() - 6.0)
            .collect();
        let w = whiteness(&white, 20).unwrap();
        assert!(w.is_white(), "Q = {} ≥ {}", w.ljung_box, w.critical);
        assert!(w.mean.abs() < 4.0 / 2000f64.sqrt() && (w.variance - 1.0).abs() < 0.15);
        let mut acc = 0.0;
        let walk: Vec<f64> = white
            .iter()
            .map(|e| {
                acc = 0.9 * acc + e;
                acc
            })
            .collect();
        let w = whiteness(&walk, 20).unwrap();
        assert!(!w.is_white());
        assert!(w.autocorrelation[0] > 0.8);
        assert!(whiteness(&[1.0; 5], 20).is_none());
    }
}
