//! The data a run's observer hands to its record: decimated traces of the posterior and the
//! central credible intervals of θ at the end ([`crate::observe`] computes them).

use core_filters::credible::CredibleInterval;
use serde::{Deserialize, Serialize};

/// Decimated per-step traces (step `k` is kept when `k % every == 0` or `k` is the last step).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Trace {
    /// Keep one step in `every` (0: no trace).
    pub every: usize,
    /// Time of each kept step (s).
    pub t: Vec<f64>,
    /// Posterior means of θ at each kept step (one row per kept step).
    pub param_mean: Vec<Vec<f64>>,
    /// Posterior s.d.s of θ at each kept step.
    pub param_sd: Vec<Vec<f64>>,
    /// ESS at each kept step.
    pub ess: Vec<f64>,
}

/// Which shape of posterior an interval comes from (SPEC §9 "Calibration").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PosteriorShape {
    /// A sampled parameter: the weighted sample of the particles' values.
    WeightedSample,
    /// A marginalised parameter: the mixture of the particles' Gaussians.
    GaussianMixture,
}

/// The central credible intervals of one parameter (at [`STANDARD_LEVELS`](core_filters::credible::STANDARD_LEVELS): 50, 90, 95 %).
///
/// They are those of the posterior of the **last step**, `p(θ | y_1:T)`, the filter's answer
/// after all the data — not of θ_val, which averages the posterior mean over the last `window`
/// steps (SPEC eq. 26). For a static parameter the two differ by the drift of the mean over the
/// window (0.4 s at the paper's settings), small against the posterior width once the filter
/// has converged; the last step is the one posterior the filter actually holds, so coverage
/// tests the filter's own claim. θ_sd_final is the s.d. of the same posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamIntervals {
    pub parameter: String,
    pub shape: PosteriorShape,
    /// One interval per level, in the order of [`STANDARD_LEVELS`](core_filters::credible::STANDARD_LEVELS) (empty when `error` is set).
    #[serde(with = "intervals_repr")]
    pub intervals: Vec<CredibleInterval>,
    /// Why the intervals could not be computed (a non-finite particle value, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Monte-Carlo standard error of θ_val, from the spread of the θ_vals of independent
    /// filters pooled into this run (s.d. over filters / √filters); absent for a single filter,
    /// whose posterior does not know its own Monte-Carlo error.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "crate::record::number::opt_scalar"
    )]
    pub mc_se: Option<f64>,
}

/// [`CredibleInterval`] with the record's number encoding (its type lives with the filters,
/// which write no records).
mod intervals_repr {
    use super::*;
    use crate::record::number::scalar;
    use serde::{Deserializer, Serializer};

    #[derive(Serialize, Deserialize)]
    struct Repr {
        #[serde(with = "scalar")]
        level: f64,
        #[serde(with = "scalar")]
        lo: f64,
        #[serde(with = "scalar")]
        hi: f64,
    }

    pub(crate) fn serialize<S: Serializer>(
        x: &[CredibleInterval],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(x.iter().map(|c| Repr {
            level: c.level,
            lo: c.lo,
            hi: c.hi,
        }))
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Vec<CredibleInterval>, D::Error> {
        Ok(Vec::<Repr>::deserialize(d)?
            .into_iter()
            .map(|r| CredibleInterval {
                level: r.level,
                lo: r.lo,
                hi: r.hi,
            })
            .collect())
    }
}

impl ParamIntervals {
    /// The interval at nominal level `level`, if recorded.
    pub fn at(&self, level: f64) -> Option<&CredibleInterval> {
        self.intervals
            .iter()
            .find(|c| (c.level - level).abs() <= 1e-9)
    }
}
