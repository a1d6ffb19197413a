//! The errors of estimated state signals against the true ones that a record carries (SPEC §7,
//! eq. 27; computed by [`crate::metrics`]).

use serde::{Deserialize, Serialize};

/// Error of one signal (SPEC §7, eq. 27). The paper's printed CV(RMSE) divides by the plain mean
/// of the true signal, which is ≈ 0 for an oscillation; we divide by mean(|x_true|) and also give
/// NRMSE = RMSE / RMS(x_true).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SignalError {
    pub rmse: f64,
    /// RMSE / mean(|x_true|).
    pub cv_rmse: f64,
    /// RMSE / RMS(x_true).
    pub nrmse: f64,
}

/// Errors of named state signals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateErrors {
    pub names: Vec<String>,
    pub errors: Vec<SignalError>,
}
