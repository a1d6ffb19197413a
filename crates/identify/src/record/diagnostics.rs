//! What the checks of a run write into its record: plausibility warnings ([`crate::checks`]),
//! the one-step prediction errors and their whiteness per channel ([`crate::residuals`]).

use serde::{Deserialize, Serialize};

/// What a warning is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// The run ended early with a numerical failure.
    Failed,
    /// A stiffness or damping with posterior mean ≤ 0.
    NonPositive,
    /// A non-finite θ_val.
    NonFinite,
    /// A sampled static parameter with few distinct values at the end.
    FewDistinct,
    /// A tiny effective sample size.
    TinyEss,
    /// Filters of a pool left out of the pooled answer (they failed or lost track of the record).
    LeftOut,
    /// A stiffness, damping or α held at its physical bound: the data pushed its Gaussian below
    /// zero and the support truncated it there (`linalg::support`).
    AtBound,
}

impl WarningKind {
    /// Whether the answer is unusable: the command must not exit successfully.
    pub fn is_fatal(self) -> bool {
        matches!(
            self,
            WarningKind::Failed | WarningKind::NonPositive | WarningKind::NonFinite
        )
    }
}

/// One warning, with the parameter it concerns (if any) and the reason in words.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warning {
    pub kind: WarningKind,
    pub parameter: Option<String>,
    pub message: String,
}

/// Why a filter of a pool was left out of the pooled answer (module `pool`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LeftOutReason {
    /// It ended early with a numerical failure.
    Failed,
    /// It completed, but over the last steps it predicted the measurements far worse than the
    /// pool's median filter: it lost track of the record.
    Lost,
}

/// One filter of a pool left out of the pooled answer, with the evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeftOutFilter {
    /// Its index in the pool (0: the filter on the unpooled run's stream).
    pub filter: usize,
    pub reason: LeftOutReason,
    /// The failure's kind (the key of the record's `failures` counts) for a failed filter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure_kind: Option<String>,
    /// Its mean log-likelihood increment per step and channel over the record's last steps
    /// (null for a failed filter), and the pool's median of the same.
    pub tail_loglik: Option<f64>,
    pub median_tail_loglik: Option<f64>,
    /// The reason in words (the failure's message for a failed filter).
    pub message: String,
}

/// Measured against predicted accelerations and the normalised one-step prediction errors of a
/// run: the only evidence, without truth, that the model fits the data. Written by
/// [`crate::residuals::Predictor`] into the records of `sysid filter`; `sysid plot` draws it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Residuals {
    /// Time of each kept step (s). Keep every step for the whiteness test: a decimated sequence
    /// tests lags that are multiples of the decimation only.
    #[serde(with = "crate::record::number::vec")]
    pub t: Vec<f64>,
    /// Measured channels, e.g. `a1`, `a2`, `a3`.
    pub channels: Vec<String>,
    /// `measured[k][i]`: measurement of channel i at kept step k.
    #[serde(with = "crate::record::number::vec_vec")]
    pub measured: Vec<Vec<f64>>,
    /// One-step-ahead prediction of the measurement from the posterior means of the previous
    /// step ([`crate::residuals`]).
    #[serde(with = "crate::record::number::vec_vec")]
    pub predicted: Vec<Vec<f64>>,
    /// (y_k − ŷ_k) / √R_ii per channel: uncorrelated in time, with a variance of at least 1
    /// (the predictive variance is at least the noise variance), when the model and its noise
    /// levels are right.
    #[serde(with = "crate::record::number::vec_vec")]
    pub normalised_innovation: Vec<Vec<f64>>,
    /// √R_ii of each channel: the noise s.d. the errors are divided by (absent in older records).
    #[serde(
        default,
        with = "crate::record::number::vec",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub noise_sd: Vec<f64>,
}

/// The whiteness check of one channel's normalised prediction errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelCheck {
    pub channel: String,
    pub n: usize,
    #[serde(with = "crate::record::number::scalar")]
    pub mean: f64,
    /// Variance of the normalised errors: ≥ 1 expected ([`crate::residuals`]).
    #[serde(with = "crate::record::number::scalar")]
    pub variance: f64,
    /// Ljung–Box Q over lags 1..=`MAX_LAG` (20) and its 95 % critical value.
    #[serde(with = "crate::record::number::scalar")]
    pub ljung_box: f64,
    #[serde(with = "crate::record::number::scalar")]
    pub critical: f64,
    pub white: bool,
}

/// What one parameter's parts of the record say of it alone (`crate::spread`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamSpread {
    pub parameter: String,
    /// Mean and s.d. of each part with information, in time order.
    #[serde(with = "super::number::vec")]
    pub part_mean: Vec<f64>,
    #[serde(with = "super::number::vec")]
    pub part_sd: Vec<f64>,
    /// The between-part s.d. τ that widened its intervals (0: the parts agree); absent with too
    /// few parts.
    #[serde(
        default,
        with = "super::number::opt_scalar",
        skip_serializing_if = "Option::is_none"
    )]
    pub tau: Option<f64>,
}

/// The spread of θ between the parts of a field record and the filter's own intervals, before
/// they were widened by it (`crate::spread`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentSpread {
    /// Parts of equal duration the run was cut into.
    pub segments: usize,
    pub parameters: Vec<ParamSpread>,
    /// The credible intervals of the filter's posterior alone.
    pub filter_credible: Vec<super::trace::ParamIntervals>,
}
