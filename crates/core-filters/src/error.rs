//! Typed failures of a filter step. A failure ends the run it occurs in; the runner records it.

use thiserror::Error;

/// Why a filter step could not produce a result.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FilterError {
    /// A covariance that must be positive definite could not be factorised, even after the
    /// documented repair (symmetrisation and bounded jitter).
    #[error("step {step}: {which} is not positive definite")]
    NotPositiveDefinite { step: usize, which: &'static str },
    /// Every particle weight is zero (all log-weights are -inf or NaN).
    #[error("step {step}: all particle weights are zero")]
    AllWeightsZero { step: usize },
    /// A non-finite value (NaN or infinity) appeared where a finite one is required.
    #[error("step {step}: non-finite value in {which}")]
    NonFinite { step: usize, which: &'static str },
    /// A model wrote a Jacobian with another sparsity pattern than the one it declared at
    /// set-up (`linalg::Sparse`): the step's numbers would be wrong, so the run ends.
    #[error("step {step}: the model's {which} left its declared sparsity pattern")]
    JacobianPattern { step: usize, which: &'static str },
    /// The run was stopped before step `step` at its caller's request ([`crate::smc::Observer::
    /// should_stop`]: an interruption by the user), not by a numerical failure.
    #[error("step {step}: interrupted")]
    Interrupted { step: usize },
}

impl FilterError {
    /// Short machine-readable kind, used as the key of failure counts in run records.
    pub fn kind(&self) -> &'static str {
        match self {
            FilterError::NotPositiveDefinite { .. } => "not_positive_definite",
            FilterError::AllWeightsZero { .. } => "all_weights_zero",
            FilterError::NonFinite { .. } => "non_finite",
            FilterError::JacobianPattern { .. } => "jacobian_pattern",
            FilterError::Interrupted { .. } => "interrupted",
        }
    }

    /// The time step at which the failure occurred.
    pub fn step(&self) -> usize {
        match self {
            FilterError::NotPositiveDefinite { step, .. }
            | FilterError::AllWeightsZero { step }
            | FilterError::NonFinite { step, .. }
            | FilterError::JacobianPattern { step, .. }
            | FilterError::Interrupted { step } => *step,
        }
    }
}
