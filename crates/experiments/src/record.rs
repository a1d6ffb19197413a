//! The run record: one flat, self-describing JSON document per run (STYLE lesson 10). Figures and
//! reports are drawn from records only.
//!
//! Everything in a record is a deterministic function of (data, configuration, seed) except the
//! `timing` object, so two runs with the same seed give identical records once `timing` is
//! removed, whatever the number of threads.

use std::collections::BTreeMap;

use core_filters::Health;
use serde::{Deserialize, Serialize};

use crate::metrics::StateErrors;
use crate::observe::Trace;
use crate::sweep::SweepRecord;

/// Versions and provenance written into every record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Versions {
    /// Version of this toolkit.
    pub toolkit: String,
    /// Schema version of the record.
    pub record_schema: u32,
}

impl Versions {
    pub fn current() -> Self {
        Self {
            toolkit: env!("CARGO_PKG_VERSION").to_string(),
            record_schema: 1,
        }
    }
}

/// Wall-clock measurements (excluded from determinism comparisons).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Wall time of the filter run (s), excluding data loading and validation.
    pub wall_s: f64,
    /// Particles × steps / wall_s.
    pub particle_steps_per_s: f64,
    /// Wall time of the validation integration (s).
    pub validation_s: f64,
}

/// A hysteresis loop: restoring force of element 1 (k1·r1) against its drift x1, decimated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Loop {
    pub x: Vec<f64>,
    pub force: Vec<f64>,
}

/// The validation run (SPEC §7): the equations of motion integrated with θ_val, zero initial
/// conditions and the clean excitation by adaptive Dormand–Prince 5(4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// Errors of the validation states against the true states.
    pub states: StateErrors,
    /// Validation loop and true loop (decimated), when the record keeps loops.
    pub loop_validation: Option<Loop>,
    pub loop_true: Option<Loop>,
    /// Why the validation could not be run, if it could not (e.g. θ_val outside the model's
    /// valid range).
    pub error: Option<String>,
}

/// One run of one algorithm on one data set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Name of the experiment (config) the run belongs to.
    pub experiment: String,
    pub algorithm: String,
    /// Master seed and run index: the data come from (seed, run, data purposes), the filter from
    /// (seed, run, `filter/<algorithm>`).
    pub seed: u64,
    pub run: u64,
    pub particles: usize,
    pub param_names: Vec<String>,
    /// True θ (null for field data).
    pub theta_true: Option<Vec<f64>>,
    /// θ_val: posterior mean averaged over the last `window` steps (SPEC eq. 26).
    pub theta_val: Vec<f64>,
    pub window: usize,
    /// Posterior s.d. of θ at the last completed step.
    pub theta_sd_final: Vec<f64>,
    /// |θ_val − θ_true| / θ_true (null for field data).
    pub rel_error: Option<Vec<f64>>,
    /// Log-likelihood estimate over the completed steps.
    pub loglik: f64,
    pub steps_total: usize,
    pub steps_completed: usize,
    pub ess_min: f64,
    pub ess_mean: f64,
    /// Distinct values of each sampled static parameter at the end (degeneracy).
    pub distinct_sampled: BTreeMap<String, usize>,
    /// Failures by kind (`all_weights_zero`, `not_positive_definite`, `non_finite`).
    pub failures: BTreeMap<String, u64>,
    /// The failure message, when the run ended early.
    pub failure: Option<String>,
    /// Numerical repairs counted by the filter.
    pub health: Health,
    /// Online state-estimate errors against the truth (null for field data).
    pub online_states: Option<StateErrors>,
    pub validation: Option<Validation>,
    /// The full configuration of the run (data and filter).
    pub config: serde_json::Value,
    pub versions: Versions,
    /// Decimated traces of posterior means and s.d.s (decimation stated inside).
    pub trace: Trace,
    pub timing: Timing,
    /// Plausibility warnings with their reasons (`checks::check`): an impossible answer, a
    /// posterior resting on few particles, a failure. Absent in records written before checks.
    #[serde(default)]
    pub warnings: Vec<crate::checks::Warning>,
}

impl RunRecord {
    /// Whether the run ended early with a failure.
    pub fn is_failure(&self) -> bool {
        self.failure.is_some()
    }

    /// θ_val / θ_true (null for field data).
    pub fn normalised_theta_val(&self) -> Option<Vec<f64>> {
        self.theta_true
            .as_ref()
            .map(|t| self.theta_val.iter().zip(t).map(|(a, b)| a / b).collect())
    }

    /// The record without its timings, as canonical JSON (for determinism checks).
    pub fn deterministic_json(&self) -> String {
        let mut v = serde_json::to_value(self).expect("a record serialises");
        v.as_object_mut().expect("object").remove("timing");
        serde_json::to_string(&v).expect("serialises")
    }
}

impl SweepRecord for RunRecord {
    fn failed(&self) -> bool {
        self.is_failure()
    }
}
