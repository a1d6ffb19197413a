//! Counters of numerical repairs. A repair keeps a run going; it is never silent: every filter
//! owns a [`Health`] the caller can read, and run records report it.

use serde::{Deserialize, Serialize};

/// Counts of numerical repairs made during a run (all start at zero).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Health {
    /// A covariance was symmetrised where its asymmetry exceeded round-off.
    pub symmetrised: u64,
    /// Diagonal jitter was added so that a Cholesky factorisation could succeed.
    pub jitter_added: u64,
    /// A Cholesky factorisation failed even after jitter (the step then returned an error).
    pub cholesky_failures: u64,
    /// Particle log-weights that were NaN and were mapped to -inf.
    pub nan_weights: u64,
    /// Resampling events.
    pub resamples: u64,
    /// Marginalised Gaussians truncated to their physical support where a mean had left it (one
    /// per bound and particle and step; `linalg::support`). Not a repair: the model's support,
    /// enforced.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub truncated: u64,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

impl Health {
    /// Adds the counts of `other` to `self` (used to combine per-particle counters).
    pub fn absorb(&mut self, other: &Health) {
        self.symmetrised += other.symmetrised;
        self.jitter_added += other.jitter_added;
        self.cholesky_failures += other.cholesky_failures;
        self.nan_weights += other.nan_weights;
        self.resamples += other.resamples;
        self.truncated += other.truncated;
    }

    /// Total number of repairs (excluding resampling, which is not a repair).
    pub fn repairs(&self) -> u64 {
        self.symmetrised + self.jitter_added + self.cholesky_failures + self.nan_weights
    }
}
