//! The one weight routine every particle filter uses (STYLE lesson 5, SPEC §3).
//!
//! Weights live in the log domain. After a filter has added each particle's log-likelihood
//! increment to its (normalised) log-weight, `normalise_log_weights` normalises them with the
//! log-sum-exp trick, maps NaN to −∞ (counted), and returns the log-likelihood increment
//! `log Σ_i w_{k-1}^i p(y_k | particle i)` and the effective sample size. All weights zero is a typed
//! error carrying the time step, never a panic.

use crate::error::FilterError;
use crate::health::Health;

/// What normalising the weights of one step produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WeightSummary {
    /// `log Σ_i exp(log_w_i)` of the un-normalised log-weights: the log-likelihood increment
    /// `log p̂(y_k | y_{1:k-1})` when the incoming log-weights were normalised.
    pub loglik_increment: f64,
    /// Effective sample size `1 / Σ_i w_i²` of the normalised weights.
    pub ess: f64,
}

/// Normalises `log_w` in place (so that `Σ exp(log_w) = 1`) and writes the linear weights into
/// `w`. NaN log-weights count as −∞ (and are counted in `health.nan_weights`); +∞ is treated as
/// non-finite too (a density cannot be infinite for a non-degenerate covariance).
///
/// Returns [`FilterError::AllWeightsZero`] when no weight is finite.
pub(crate) fn normalise_log_weights(
    log_w: &mut [f64],
    w: &mut [f64],
    step: usize,
    health: &mut Health,
) -> Result<WeightSummary, FilterError> {
    assert_eq!(log_w.len(), w.len(), "weight buffers differ in length");
    let mut max = f64::NEG_INFINITY;
    for lw in log_w.iter_mut() {
        if lw.is_nan() || *lw == f64::INFINITY {
            health.nan_weights += 1;
            *lw = f64::NEG_INFINITY;
        }
        if *lw > max {
            max = *lw;
        }
    }
    if max == f64::NEG_INFINITY {
        return Err(FilterError::AllWeightsZero { step });
    }
    let mut sum = 0.0;
    for (wi, lw) in w.iter_mut().zip(log_w.iter()) {
        *wi = (lw - max).exp();
        sum += *wi;
    }
    // sum ≥ 1 because the maximal term is exp(0).
    let log_sum = max + sum.ln();
    let mut sum_sq = 0.0;
    for (wi, lw) in w.iter_mut().zip(log_w.iter_mut()) {
        *wi /= sum;
        *lw -= log_sum;
        sum_sq += *wi * *wi;
    }
    Ok(WeightSummary {
        loglik_increment: log_sum,
        ess: 1.0 / sum_sq,
    })
}

/// Sets uniform normalised weights (after resampling or at initialisation).
pub(crate) fn reset_uniform(log_w: &mut [f64], w: &mut [f64]) {
    let n = log_w.len();
    let lw = -(n as f64).ln();
    let wi = 1.0 / n as f64;
    log_w.iter_mut().for_each(|x| *x = lw);
    w.iter_mut().for_each(|x| *x = wi);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(log_w: &mut [f64]) -> (Vec<f64>, Result<WeightSummary, FilterError>, Health) {
        let mut w = vec![0.0; log_w.len()];
        let mut h = Health::default();
        let r = normalise_log_weights(log_w, &mut w, 7, &mut h);
        (w, r, h)
    }

    #[test]
    fn equal_weights_give_full_ess_and_mean_likelihood() {
        // Normalised incoming weights 1/4 each, each particle likelihood 0.5: p̂ = 0.5.
        let mut lw = [(0.25f64 * 0.5).ln(); 4];
        let (w, r, _) = run(&mut lw);
        let s = r.unwrap();
        assert!((s.loglik_increment - 0.5f64.ln()).abs() < 1e-15);
        assert!((s.ess - 4.0).abs() < 1e-12);
        assert!(w.iter().all(|x| (x - 0.25).abs() < 1e-15));
        assert!(lw.iter().all(|x| (x - 0.25f64.ln()).abs() < 1e-15));
    }

    #[test]
    fn extreme_magnitudes_do_not_overflow() {
        // exp(1e5) overflows: only the log-sum-exp shift keeps this finite.
        let mut lw = [1e5, 1e5 - 1.0, -1e300];
        let (w, r, _) = run(&mut lw);
        let s = r.unwrap();
        let e = (-1.0f64).exp();
        assert!((w[0] - 1.0 / (1.0 + e)).abs() < 1e-15);
        assert!((w[1] - e / (1.0 + e)).abs() < 1e-15);
        assert_eq!(w[2], 0.0);
        assert!((s.loglik_increment - (1e5 + (1.0 + e).ln())).abs() < 1e-9);
        let mut lw = [1e300, -1e300];
        let (w, r, _) = run(&mut lw);
        assert_eq!((w[0], w[1], r.unwrap().loglik_increment), (1.0, 0.0, 1e300));
        let mut lw = [-1e300, -1e300];
        let s = run(&mut lw).1.unwrap();
        assert!((s.ess - 2.0).abs() < 1e-12);
    }

    #[test]
    fn one_finite_weight_takes_all_mass() {
        let mut lw = [f64::NEG_INFINITY, -1234.5, f64::NAN, f64::NEG_INFINITY];
        let (w, r, h) = run(&mut lw);
        let s = r.unwrap();
        assert_eq!(w, vec![0.0, 1.0, 0.0, 0.0]);
        assert_eq!(s.ess, 1.0);
        assert_eq!(s.loglik_increment, -1234.5);
        assert_eq!(h.nan_weights, 1);
        assert_eq!(lw[2], f64::NEG_INFINITY);
    }

    #[test]
    fn all_zero_weights_are_a_typed_error() {
        let mut lw = [f64::NEG_INFINITY, f64::NAN, f64::INFINITY];
        let (_, r, h) = run(&mut lw);
        assert_eq!(r, Err(FilterError::AllWeightsZero { step: 7 }));
        assert_eq!(h.nan_weights, 2);
    }
}
