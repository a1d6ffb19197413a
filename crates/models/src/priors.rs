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
