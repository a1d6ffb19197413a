//! Priors of the parameters θ = [k1..kN, c1..cN, β, γ, n] of the N-storey chain (SPEC §3).
//!
//! - [`Prior`]: one scalar parameter (lognormal, uniform or a point mass);
//! - [`BetaGammaPrior`]: the joint prior of the Bouc–Wen shape parameters (β, γ), uniform on the
//!   triangle {0 ≤ β ≤ β_max, |γ| ≤ β} of SPEC §3, or a conditional/fixed version of it;
//!
//! The whole θ of a chain, with the paper's defaults, sampling and moment matching, is
//! [`crate::filtering::prior::ChainPrior`]; its Monte-Carlo tests live here with the scalar
//! priors they check.
//!
//! The TOML/JSON form is readable: `{ kind = "log_normal", median = 10.0, log_sd = 0.3 }`.

use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Invalid prior specification or request.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PriorError {
    #[error("prior of {name}: median {median} must be positive and finite")]
    NonPositiveMedian { name: String, median: f64 },
    #[error("prior of {name}: log-s.d. {log_sd} must be non-negative and finite")]
    BadLogSd { name: String, log_sd: f64 },
    #[error("prior of {name}: uniform interval [{lo}, {hi}] is empty or not finite")]
    EmptyInterval { name: String, lo: f64, hi: f64 },
    #[error("prior of {name}: value {value} is not finite")]
    NonFinite { name: String, value: f64 },
    #[error("prior of {name}: support reaches negative values (lowest {lowest})")]
    NegativeSupport { name: String, lowest: f64 },
    #[error("beta/gamma prior: beta_max {beta_max} must be positive and finite")]
    NonPositiveBetaMax { beta_max: f64 },
    #[error("beta/gamma prior: beta {beta} must be non-negative and finite")]
    NegativeBeta { beta: f64 },
    #[error(
        "beta/gamma prior: fixed gamma {gamma} leaves no beta with |gamma| < beta <= {beta_max}"
    )]
    GammaOutsideTriangle { gamma: f64, beta_max: f64 },
    #[error("unknown parameter name {name:?}")]
    UnknownParameter { name: String },
    #[error("{which}: expected {expected} priors (one per storey), got {got}")]
    WrongLength {
        which: &'static str,
        expected: usize,
        got: usize,
    },
}

/// Names of θ in order: `k1..kN, c1..cN, beta, gamma, n` (length 2N+3).
pub fn parameter_names(n_storeys: usize) -> Vec<String> {
    let mut names = Vec::with_capacity(2 * n_storeys + 3);
    names.extend((1..=n_storeys).map(|j| format!("k{j}")));
    names.extend((1..=n_storeys).map(|j| format!("c{j}")));
    names.extend(["beta", "gamma", "n"].map(String::from));
    names
}

/// Prior of one scalar parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Prior {
    /// `ln θ ~ N(ln median, log_sd²)`.
    LogNormal { median: f64, log_sd: f64 },
    /// `θ ~ U(lo, hi)`.
    Uniform { lo: f64, hi: f64 },
    /// Point mass at `value` (the parameter is known).
    Fixed { value: f64 },
}

impl Prior {
    /// Checks the hyper-parameters; `non_negative` additionally requires the support in [0, ∞).
    pub fn validate(&self, name: &str, non_negative: bool) -> Result<(), PriorError> {
        let name = || name.to_string();
        match *self {
            Prior::LogNormal { median, log_sd } => {
                if !(median.is_finite() && median > 0.0) {
                    return Err(PriorError::NonPositiveMedian {
                        name: name(),
                        median,
                    });
                }
                if !(log_sd.is_finite() && log_sd >= 0.0) {
                    return Err(PriorError::BadLogSd {
                        name: name(),
                        log_sd,
                    });
                }
            }
            Prior::Uniform { lo, hi } => {
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(PriorError::EmptyInterval {
                        name: name(),
                        lo,
                        hi,
                    });
                }
                if non_negative && lo < 0.0 {
                    return Err(PriorError::NegativeSupport {
                        name: name(),
                        lowest: lo,
                    });
                }
            }
            Prior::Fixed { value } => {
                if !value.is_finite() {
                    return Err(PriorError::NonFinite {
                        name: name(),
                        value,
                    });
                }
                if non_negative && value < 0.0 {
                    return Err(PriorError::NegativeSupport {
                        name: name(),
                        lowest: value,
                    });
                }
            }
        }
        Ok(())
    }

    /// One draw.
    pub fn sample<G: Rng + ?Sized>(&self, rng: &mut G) -> f64 {
        match *self {
            Prior::LogNormal { median, log_sd } => {
                let z: f64 = rng.sample(StandardNormal);
                median * (log_sd * z).exp()
            }
            Prior::Uniform { lo, hi } => lo + (hi - lo) * rng.random::<f64>(),
            Prior::Fixed { value } => value,
        }
    }

    /// Mean and variance (SPEC §3: lognormal mean m·e^{s²/2}, variance mean²·(e^{s²} − 1)).
    pub fn moments(&self) -> (f64, f64) {
        match *self {
            Prior::LogNormal { median, log_sd } => {
                let s2 = log_sd * log_sd;
                let mean = median * (0.5 * s2).exp();
                (mean, mean * mean * s2.exp_m1())
            }
            Prior::Uniform { lo, hi } => (0.5 * (lo + hi), (hi - lo) * (hi - lo) / 12.0),
            Prior::Fixed { value } => (value, 0.0),
        }
    }
}

/// Joint prior of the Bouc–Wen shape parameters (β, γ).
///
/// The paper's prior is uniform on the triangle T = {0 ≤ β ≤ β_max, |γ| ≤ β} (SPEC §3), drawn as
/// β = β_max·√U, γ ~ U(−β, β). Fixing one of the two keeps the *conditional* of the other in T,
/// which is again uniform and exact:
/// - β fixed at b: γ | β = b ~ U(−b, b) ([`BetaGammaPrior::FixedBeta`]);
/// - γ fixed at g: β | γ = g ~ U(|g|, β_max) ([`BetaGammaPrior::FixedGamma`]), since the joint
///   density of T is constant.
///
/// Fixing both gives [`BetaGammaPrior::Fixed`]. β and γ are uncorrelated in every variant
/// (in T, E\[βγ\] = E\[β·E\[γ|β\]\] = 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum BetaGammaPrior {
    /// Uniform on {0 ≤ β ≤ beta_max, |γ| ≤ β}.
    Triangle { beta_max: f64 },
    /// β known; γ ~ U(−β, β).
    FixedBeta { beta: f64 },
    /// γ known; β ~ U(|γ|, beta_max).
    FixedGamma { gamma: f64, beta_max: f64 },
    /// Both known.
    Fixed { beta: f64, gamma: f64 },
}

impl BetaGammaPrior {
    pub fn validate(&self) -> Result<(), PriorError> {
        let check_beta_max = |beta_max: f64| {
            if beta_max.is_finite() && beta_max > 0.0 {
                Ok(())
            } else {
                Err(PriorError::NonPositiveBetaMax { beta_max })
            }
        };
        match *self {
            BetaGammaPrior::Triangle { beta_max } => check_beta_max(beta_max),
            BetaGammaPrior::FixedBeta { beta } => {
                if beta.is_finite() && beta >= 0.0 {
                    Ok(())
                } else {
                    Err(PriorError::NegativeBeta { beta })
                }
            }
            BetaGammaPrior::FixedGamma { gamma, beta_max } => {
                check_beta_max(beta_max)?;
                if gamma.is_finite() && gamma.abs() < beta_max {
                    Ok(())
                } else {
                    Err(PriorError::GammaOutsideTriangle { gamma, beta_max })
                }
            }
            BetaGammaPrior::Fixed { beta, gamma } => {
                for (name, value) in [("beta", beta), ("gamma", gamma)] {
                    if !value.is_finite() {
                        return Err(PriorError::NonFinite {
                            name: name.to_string(),
                            value,
                        });
                    }
                }
                Ok(())
            }
        }
    }

    /// One draw of (β, γ).
    pub fn sample<G: Rng + ?Sized>(&self, rng: &mut G) -> (f64, f64) {
        match *self {
            BetaGammaPrior::Triangle { beta_max } => {
                let beta = beta_max * rng.random::<f64>().sqrt();
                let gamma = beta * (2.0 * rng.random::<f64>() - 1.0);
                (beta, gamma)
            }
            BetaGammaPrior::FixedBeta { beta } => (beta, beta * (2.0 * rng.random::<f64>() - 1.0)),
            BetaGammaPrior::FixedGamma { gamma, beta_max } => {
                let lo = gamma.abs();
                (lo + (beta_max - lo) * rng.random::<f64>(), gamma)
            }
            BetaGammaPrior::Fixed { beta, gamma } => (beta, gamma),
        }
    }

    /// `(mean β, mean γ, var β, var γ)`; the covariance is zero in every variant.
    ///
    /// Triangle (SPEC §3): β has density 2β/β_max², so E β = 2β_max/3, E β² = β_max²/2,
    /// var β = β_max²/18; γ | β ~ U(−β, β) gives E γ = 0, var γ = E\[β²\]/3 = β_max²/6.
    pub fn moments(&self) -> (f64, f64, f64, f64) {
        match *self {
            BetaGammaPrior::Triangle { beta_max } => (
                2.0 * beta_max / 3.0,
                0.0,
                beta_max * beta_max / 18.0,
                beta_max * beta_max / 6.0,
            ),
            BetaGammaPrior::FixedBeta { beta } => (beta, 0.0, 0.0, beta * beta / 3.0),
            BetaGammaPrior::FixedGamma { gamma, beta_max } => {
                let lo = gamma.abs();
                (
                    0.5 * (lo + beta_max),
                    gamma,
                    (beta_max - lo).powi(2) / 12.0,
                    0.0,
                )
            }
            BetaGammaPrior::Fixed { beta, gamma } => (beta, gamma, 0.0, 0.0),
        }
    }

    /// β fixed at `value`; γ keeps its (conditional) prior or its fixed value.
    pub(crate) fn fix_beta(self, value: f64) -> Self {
        match self {
            BetaGammaPrior::Triangle { .. } | BetaGammaPrior::FixedBeta { .. } => {
                BetaGammaPrior::FixedBeta { beta: value }
            }
            BetaGammaPrior::FixedGamma { gamma, .. } | BetaGammaPrior::Fixed { gamma, .. } => {
                BetaGammaPrior::Fixed { beta: value, gamma }
            }
        }
    }

    /// γ fixed at `value`; β keeps its (conditional) prior or its fixed value.
    pub(crate) fn fix_gamma(self, value: f64) -> Self {
        match self {
            BetaGammaPrior::Triangle { beta_max } | BetaGammaPrior::FixedGamma { beta_max, .. } => {
                BetaGammaPrior::FixedGamma {
                    gamma: value,
                    beta_max,
                }
            }
            BetaGammaPrior::FixedBeta { beta } | BetaGammaPrior::Fixed { beta, .. } => {
                BetaGammaPrior::Fixed { beta, gamma: value }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filtering::prior::ChainPrior;
    use core_filters::rng::stream;

    /// SPEC §3's θ for `n` storeys with the one Bouc–Wen element at storey 1.
    fn paper(n: usize) -> ChainPrior {
        ChainPrior::paper(n, &[0])
    }

    fn sample<G: Rng + ?Sized>(prior: &ChainPrior, rng: &mut G) -> Vec<f64> {
        let mut out = vec![0.0; prior.len()];
        prior.sample_into(rng, &mut out);
        out
    }

    /// Monte-Carlo check of mean, variance and the β–γ covariance of a prior.
    ///
    /// Tolerances are 5 Monte-Carlo standard errors: for the mean √(var/M); for the variance
    /// √((μ4 − σ⁴)/M) with μ4 estimated from the same sample; for the covariance √(E[(βγ)²]/M).
    /// With ~40 checks at 5 s.e. a false failure has probability < 1e-4 (and the seed is fixed).
    fn check_moments_by_monte_carlo(prior: &ChainPrior, draws: usize, seed: u64) {
        let d = prior.len();
        let (mean, var) = prior.moments();
        let mut rng = stream(seed, 0, "priors-test");
        let samples: Vec<Vec<f64>> = (0..draws).map(|_| sample(prior, &mut rng)).collect();
        let m = draws as f64;
        for i in 0..d {
            let mc_mean = samples.iter().map(|s| s[i]).sum::<f64>() / m;
            let mc_var = samples
                .iter()
                .map(|s| (s[i] - mc_mean).powi(2))
                .sum::<f64>()
                / (m - 1.0);
            let mu4 = samples
                .iter()
                .map(|s| (s[i] - mc_mean).powi(4))
                .sum::<f64>()
                / m;
            let se_mean = (var[i] / m).sqrt();
            let se_var = ((mu4 - mc_var * mc_var).max(0.0) / m).sqrt();
            assert!(
                (mc_mean - mean[i]).abs() <= 5.0 * se_mean + 1e-12,
                "param {i}: MC mean {mc_mean} vs {} (se {se_mean})",
                mean[i]
            );
            assert!(
                (mc_var - var[i]).abs() <= 5.0 * se_var + 1e-12,
                "param {i}: MC var {mc_var} vs {} (se {se_var})",
                var[i]
            );
        }
        let n = prior.n_storeys();
        let (b, g) = (2 * n, 2 * n + 1);
        let (mb, mg) = (mean[b], mean[g]);
        let cov = samples
            .iter()
            .map(|s| (s[b] - mb) * (s[g] - mg))
            .sum::<f64>()
            / m;
        let e2 = samples
            .iter()
            .map(|s| ((s[b] - mb) * (s[g] - mg)).powi(2))
            .sum::<f64>()
            / m;
        assert!(
            cov.abs() <= 5.0 * (e2 / m).sqrt() + 1e-12,
            "beta-gamma covariance {cov} not zero"
        );
    }

    #[test]
    fn paper_moments_match_spec_numbers() {
        let prior = paper(3);
        prior.validate().unwrap();
        let (mean, var) = prior.moments();
        // SPEC §3: k: 10.46 ± 3.21; c: 0.453 ± 0.242; β: 10/3, 25/18; γ: 0, 25/6; n: 3, 16/12.
        for j in 0..3 {
            assert!((mean[j] - 10.46).abs() < 5e-3, "k mean {}", mean[j]);
            assert!(
                (var[j].sqrt() - 3.21).abs() < 5e-3,
                "k sd {}",
                var[j].sqrt()
            );
            assert!((mean[3 + j] - 0.453).abs() < 5e-4, "c mean {}", mean[3 + j]);
            assert!((var[3 + j].sqrt() - 0.242).abs() < 5e-4);
        }
        assert!((mean[6] - 10.0 / 3.0).abs() < 1e-12);
        assert!((var[6] - 25.0 / 18.0).abs() < 1e-12);
        assert_eq!(mean[7], 0.0);
        assert!((var[7] - 25.0 / 6.0).abs() < 1e-12);
        assert!((mean[8] - 3.0).abs() < 1e-12);
        assert!((var[8] - 16.0 / 12.0).abs() < 1e-12);
    }

    #[test]
    fn paper_moments_match_monte_carlo() {
        check_moments_by_monte_carlo(&paper(3), 200_000, 11);
    }

    #[test]
    fn conditional_triangle_moments_match_monte_carlo() {
        let mut p = paper(2);
        p.fix("gamma", -1.5).unwrap();
        assert_eq!(
            p.elements[0].beta_gamma,
            BetaGammaPrior::FixedGamma {
                gamma: -1.5,
                beta_max: 5.0
            }
        );
        check_moments_by_monte_carlo(&p, 100_000, 12);
        let mut q = paper(2);
        q.fix("beta", 2.0).unwrap();
        check_moments_by_monte_carlo(&q, 100_000, 13);
        // Conditional samples stay in the triangle.
        let mut rng = stream(5, 0, "priors-test");
        for _ in 0..1000 {
            let s = sample(&p, &mut rng);
            assert!(s[4] >= 1.5 && s[4] <= 5.0 && s[5] == -1.5);
            let s = sample(&q, &mut rng);
            assert!(s[4] == 2.0 && s[5].abs() <= 2.0);
        }
    }

    #[test]
    fn triangle_samples_stay_in_triangle() {
        let prior = paper(3);
        let mut rng = stream(3, 0, "priors-test");
        for _ in 0..10_000 {
            let s = sample(&prior, &mut rng);
            assert!((0.0..=5.0).contains(&s[6]) && s[7].abs() <= s[6]);
            assert!((1.0..5.0).contains(&s[8]));
            assert!(s[..6].iter().all(|&v| v > 0.0));
        }
    }

    #[test]
    fn fix_makes_point_masses_and_rejects_unknown_names() {
        let mut p = paper(3);
        p.fix("k2", 8.0).unwrap();
        p.fix("c3", 0.25).unwrap();
        p.fix("n", 2.0).unwrap();
        p.fix("beta", 2.0).unwrap();
        p.fix("gamma", 1.0).unwrap();
        assert_eq!(
            p.elements[0].beta_gamma,
            BetaGammaPrior::Fixed {
                beta: 2.0,
                gamma: 1.0
            }
        );
        let (mean, var) = p.moments();
        assert_eq!((mean[1], var[1]), (8.0, 0.0));
        assert_eq!((mean[5], var[5]), (0.25, 0.0));
        assert_eq!((mean[6], mean[7], mean[8]), (2.0, 1.0, 2.0));
        assert_eq!((var[6], var[7], var[8]), (0.0, 0.0, 0.0));
        let mut rng = stream(4, 0, "priors-test");
        let s = sample(&p, &mut rng);
        assert_eq!((s[1], s[5], s[6], s[7], s[8]), (8.0, 0.25, 2.0, 1.0, 2.0));

        let before = p.clone();
        for bad in ["k0", "k4", "c", "x1", "k01", "", "betaa", "K1"] {
            assert_eq!(
                p.fix(bad, 1.0),
                Err(PriorError::UnknownParameter {
                    name: bad.to_string()
                }),
                "{bad}"
            );
        }
        assert!(matches!(
            p.fix("k1", -1.0),
            Err(PriorError::NegativeSupport { .. })
        ));
        assert!(matches!(
            p.fix("n", f64::NAN),
            Err(PriorError::NonFinite { .. })
        ));
        assert_eq!(p, before, "a rejected fix leaves the prior unchanged");
        let mut t = paper(1);
        assert!(matches!(
            t.fix("gamma", 6.0),
            Err(PriorError::GammaOutsideTriangle { .. })
        ));
    }

    #[test]
    fn validation_rejects_bad_hyper_parameters() {
        let mut p = paper(2);
        p.k[0] = Prior::LogNormal {
            median: 0.0,
            log_sd: 0.3,
        };
        assert!(matches!(
            p.validate(),
            Err(PriorError::NonPositiveMedian { .. })
        ));
        p.k[0] = Prior::LogNormal {
            median: 1.0,
            log_sd: -0.3,
        };
        assert!(matches!(p.validate(), Err(PriorError::BadLogSd { .. })));
        p.k[0] = Prior::Uniform { lo: 2.0, hi: 2.0 };
        assert!(matches!(
            p.validate(),
            Err(PriorError::EmptyInterval { .. })
        ));
        p.k[0] = Prior::Uniform { lo: -1.0, hi: 2.0 };
        assert!(matches!(
            p.validate(),
            Err(PriorError::NegativeSupport { .. })
        ));
        p.k[0] = Prior::Uniform { lo: 1.0, hi: 2.0 };
        p.validate().unwrap();
        p.c.pop();
        assert!(matches!(p.validate(), Err(PriorError::WrongLength { .. })));
        let mut q = paper(2);
        q.elements[0].beta_gamma = BetaGammaPrior::Triangle { beta_max: 0.0 };
        assert!(matches!(
            q.validate(),
            Err(PriorError::NonPositiveBetaMax { .. })
        ));
    }

    #[test]
    fn serde_form_is_readable_and_round_trips() {
        let p = paper(2);
        let json = serde_json::to_string(&p).unwrap();
        assert!(json.contains(r#""kind":"log_normal""#), "{json}");
        assert!(json.contains(r#""kind":"triangle""#), "{json}");
        let back: ChainPrior = serde_json::from_str(&json).unwrap();
        assert_eq!(back, p);
        let one: Prior = serde_json::from_str(r#"{"kind":"fixed","value":2.0}"#).unwrap();
        assert_eq!(one, Prior::Fixed { value: 2.0 });
    }

    #[test]
    fn parameter_names_follow_theta_order() {
        assert_eq!(
            parameter_names(2),
            ["k1", "k2", "c1", "c2", "beta", "gamma", "n"]
        );
    }
}
