//! The run record: one flat, self-describing JSON document per run (STYLE lesson 10). Figures and
//! reports are drawn from records only.
//!
//! Everything in a record is a deterministic function of (data, configuration, seed) except the
//! `timing` object, so two runs with the same seed give identical records once `timing` is
//! removed, whatever the number of threads.
//!
//! A record is always readable by the tool that wrote it: a number that is not finite (an ESS
//! minimum over no completed step, a relative error against a true value of 0, …) is written as
//! one of the strings `"NaN"`, `"inf"`, `"-inf"` ([`number`]), never as `null`. Reading a record
//! checks it ([`RunRecord::check`]): its schema, its fingerprint ([`fingerprint`]) and the
//! consistency of its fields.
//!
//! Schema history: 1 — non-finite numbers written as `null`, no fingerprint; 2 — non-finite
//! numbers as named strings, `fingerprint` and `versions.numerics` added. Records of schema 1
//! are still read (they have no fingerprint, so a resumed sweep computes them again).

pub mod atomic;
pub mod diagnostics;
pub mod fingerprint;
pub mod number;
pub mod read;
pub(crate) mod signal_errors;
pub mod trace;
pub mod validation;

use std::collections::BTreeMap;

use core_filters::Health;
use serde::{Deserialize, Serialize};

use read::SweepRecord;
use signal_errors::{SignalError, StateErrors};
use trace::Trace;

pub use fingerprint::Fingerprint;

/// The record schema this build writes (see the schema history above).
pub const RECORD_SCHEMA: u32 = 2;

/// Version of the numerics: **bump it whenever a change of the code changes results** (a filter,
/// a Kalman step, the data generation, a metric, the order of floating-point operations). It is
/// part of every record's fingerprint, so that a resumed sweep never reuses a record computed by
/// code that gives other numbers.
///
/// History: 2 — the run-time filters' draws (2026-11-23); 3 — `substeps = "auto"` sub-steps the
/// MPF-EKF2 with one shared prior Gaussian against the velocity lag below 10 storeys
/// ([`crate::pipeline::LAG_SUBSTEPS`], 2026-11-27; every other run gives the numbers of 2); 4 —
/// particles with a marginalised dimension of 49 to 200 are processed in SIMD lanes
/// (`core_filters::smc::batch::MAX_LANE_DIM`, 2026-11-29): from 64 on their downdates round
/// otherwise (relative 1e-13 to 3e-11 on θ_val at 20 and 40 storeys); every smaller run gives the
/// numbers of 3.
pub const NUMERICS_VERSION: u32 = 4;

/// Version of what the record of a **field-data** run carries beyond the filter's numbers — the
/// free run, its band and the discrepancy term ([`crate::validation`]): bump it whenever a change
/// of the code changes them. It is part of the fingerprint of field-data runs only (a data set
/// without `dataset.json`), so a resumed field study never reuses a record whose validation was
/// computed otherwise, while the studies' simulated runs, which carry none of it, keep their
/// fingerprints.
///
/// History: 1 — the discrepancy term beside the building, chosen by the held-out part of the
/// record (`crate::validation::discrepancy`, 2026-11-30); field-data records without this key
/// were computed before it. 2 — θ identified with the discrepancy modes inside the filter where
/// that predicts the held-out part at least as well (`crate::choice`, `evidence.joint_discrepancy`).
/// 3 — the intervals' model-error term is Paule–Mandel's τ with Student's t (`crate::spread`,
/// 2026-12-01); the sub-step check reads its s.d.s off those intervals, so θ_val can move too.
pub const FIELD_VALIDATION_VERSION: u32 = 3;

/// Versions and provenance written into every record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Versions {
    /// Version of this toolkit.
    pub toolkit: String,
    /// Schema version of the record.
    pub record_schema: u32,
    /// [`NUMERICS_VERSION`] of the code that computed the record (absent in schema 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub numerics: Option<u32>,
}

impl Versions {
    pub fn current() -> Self {
        Self {
            toolkit: env!("CARGO_PKG_VERSION").to_string(),
            record_schema: RECORD_SCHEMA,
            numerics: Some(NUMERICS_VERSION),
        }
    }
}

/// Wall-clock measurements (excluded from determinism comparisons).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Wall time of the filter run (s), excluding data loading and validation.
    #[serde(with = "number::scalar")]
    pub wall_s: f64,
    /// Particles × steps / wall_s.
    #[serde(with = "number::scalar")]
    pub particle_steps_per_s: f64,
    /// Wall time of the validation (s): against the truth on simulated data; on field data the
    /// free run, its band, the transfer functions and the modal intervals.
    #[serde(with = "number::scalar")]
    pub validation_s: f64,
    /// Wall time of settling the run's plan before it (s): its rules, the sub-step checks and
    /// the held-out choice of noise, damping form and discrepancy term, each an identification
    /// of its own — on field data most of a run's time. Absent where the plan was given
    /// (`--plan`) and in older records.
    #[serde(
        default,
        with = "number::opt_scalar",
        skip_serializing_if = "Option::is_none"
    )]
    pub plan_s: Option<f64>,
    /// Seconds of record filtered per second of computation (steps × dt / wall_s): above 1 the
    /// filter keeps up with the structure in real time. Absent in older records.
    #[serde(
        default,
        with = "number::opt_scalar",
        skip_serializing_if = "Option::is_none"
    )]
    pub realtime_factor: Option<f64>,
    /// Worker threads of the run: its pooled filters side by side and, with
    /// `particle_blocks`, each filter's particles in blocks. Absent in older records.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// Each filter advanced its particles in blocks on those threads (a marginalised dimension
    /// of at least `core_filters::smc::batch::PARALLEL_MIN_DIM`); the particles are the same on
    /// any number of threads.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub particle_blocks: bool,
}

/// A hysteresis loop: restoring force of element 1 (k1·r1) against its drift x1, decimated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Loop {
    #[serde(with = "number::vec")]
    pub x: Vec<f64>,
    #[serde(with = "number::vec")]
    pub force: Vec<f64>,
}

/// The validation run (SPEC §7): the equations of motion integrated with θ_val, zero initial
/// conditions and the clean excitation by adaptive Dormand–Prince 5(4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// Errors of the validation states against the true states.
    #[serde(with = "state_errors")]
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
    #[serde(with = "number::opt_vec")]
    pub theta_true: Option<Vec<f64>>,
    /// θ_val: posterior mean averaged over the last `window` steps (SPEC eq. 26).
    #[serde(with = "number::vec")]
    pub theta_val: Vec<f64>,
    pub window: usize,
    /// Posterior s.d. of θ at the last completed step (empty when no step completed).
    #[serde(with = "number::vec")]
    pub theta_sd_final: Vec<f64>,
    /// |θ_val − θ_true| / θ_true (null for field data; `"inf"` or `"NaN"` where θ_true = 0).
    #[serde(with = "number::opt_vec")]
    pub rel_error: Option<Vec<f64>>,
    /// Log-likelihood estimate over the completed steps.
    #[serde(with = "number::scalar")]
    pub loglik: f64,
    pub steps_total: usize,
    pub steps_completed: usize,
    /// Smallest and mean ESS over the completed steps (`"inf"` and `"NaN"` when none completed).
    #[serde(with = "number::scalar")]
    pub ess_min: f64,
    #[serde(with = "number::scalar")]
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
    #[serde(with = "opt_state_errors")]
    pub online_states: Option<StateErrors>,
    pub validation: Option<Validation>,
    /// The full configuration of the run (data and filter).
    pub config: serde_json::Value,
    pub versions: Versions,
    /// What determined the result (absent in schema 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fingerprint: Option<Fingerprint>,
    /// Decimated traces of posterior means and s.d.s (decimation stated inside).
    #[serde(with = "trace_repr")]
    pub trace: Trace,
    pub timing: Timing,
    /// Plausibility warnings with their reasons (`checks::check`): an impossible answer, a
    /// posterior resting on few particles, a failure. Absent in records written before checks.
    #[serde(default)]
    pub warnings: Vec<diagnostics::Warning>,
    /// Central 50/90/95 % credible intervals of every parameter from the last step's particle
    /// posterior ([`trace::ParamIntervals`]); empty for a failed run and in records
    /// written before intervals were recorded.
    #[serde(default)]
    pub credible: Vec<trace::ParamIntervals>,
    /// The last step's posterior correlation matrix of θ, one row per parameter in
    /// `param_names`' order (the weighted particles' for sampled entries, the Gaussian
    /// mixture's for marginalised ones); the free-run band draws θ with it. Kept in records of
    /// field data (no `dataset.json`); empty for a failed run, for generated data sets and in
    /// records written before it was recorded (their draws are independent).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub theta_correlation: Vec<Vec<f64>>,
    /// Field records: the spread of θ between the record's parts that widened `credible`
    /// (model error, `crate::spread`), with the filter's own intervals.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment_spread: Option<diagnostics::SegmentSpread>,
    /// Whiteness check of each channel's one-step-ahead prediction errors
    /// ([`crate::residuals`]); empty in sweep records (no traces) and older records.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub innovation_checks: Vec<diagnostics::ChannelCheck>,
    /// The prediction errors at every step (records of `sysid filter`), drawn by `sysid plot`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residuals: Option<diagnostics::Residuals>,
    /// Free run of the identified model on the measured record: fit and NRMSE per channel, a
    /// band from posterior draws ([`crate::validation`]); field-data runs of `sysid filter`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub free_run: Option<validation::FreeRun>,
    /// Modes of the identified linearised model beside the peaks of the measured transfer
    /// functions ([`crate::validation`]); field-data runs of `sysid filter`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modal: Option<validation::ModalComparison>,
    /// Filters of a pool left out of its answer because they failed or lost track of the record
    /// (module `pool`); absent when every filter was kept, and in unpooled runs.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pool_left_out: Vec<diagnostics::LeftOutFilter>,
    /// Nothing was sampled: the run is one Gaussian filter (the MPF-EKF2 on a building without
    /// hysteretic element, one shared prior Gaussian: `rules::samples_nothing`), so it has no
    /// particle diagnostics (ESS, distinct values, Monte-Carlo error). Absent when false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub one_gaussian_filter: bool,
    /// The plan the run executed (`plan::RunPlan`, read with `RunPlan::of_record`): written by
    /// `sysid filter` and the Python `identify`; absent in a study's records, whose plan is
    /// their study description and fingerprint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<serde_json::Value>,
}

impl RunRecord {
    /// Whether the run ended early with a failure.
    pub fn is_failure(&self) -> bool {
        self.failure.is_some()
    }

    /// θ_val / θ_true (null for field data).
    pub(crate) fn normalised_theta_val(&self) -> Option<Vec<f64>> {
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

    /// Checks a record just read: a schema this build knows, a fingerprint that is the hash of
    /// its inputs and agrees with the record's own algorithm, seed, run, numerics version and
    /// filter settings (schema 2 on), and consistent sizes and step counts.
    pub fn check(&self) -> Result<(), String> {
        let schema = self.versions.record_schema;
        if schema == 0 || schema > RECORD_SCHEMA {
            return Err(format!(
                "record schema {schema} is not one this sysid reads (1 to {RECORD_SCHEMA}); \
                 it was written by another version of the tool"
            ));
        }
        if schema >= 2 {
            let f = self
                .fingerprint
                .as_ref()
                .ok_or("a record of schema 2 has no fingerprint")?;
            f.verify()?;
            f.verify_config(&self.config)?;
            let inputs = &f.inputs;
            let agree = |key: &str, value: serde_json::Value| -> Result<(), String> {
                if inputs.get(key) == Some(&value) {
                    Ok(())
                } else {
                    Err(format!(
                        "the fingerprint's `{key}` ({}) disagrees with the record ({value})",
                        inputs.get(key).unwrap_or(&serde_json::Value::Null)
                    ))
                }
            };
            agree("algorithm", self.algorithm.clone().into())?;
            agree("seed", self.seed.into())?;
            agree("run", self.run.into())?;
            agree(
                "numerics",
                self.versions
                    .numerics
                    .ok_or("a record of schema 2 has no numerics version")?
                    .into(),
            )?;
            agree(
                "filter",
                self.config
                    .get("filter")
                    .cloned()
                    .unwrap_or(serde_json::Value::Null),
            )?;
            // The record's own copies of filter settings are those the fingerprint covers (an
            // edited `particles` under an unchanged fingerprint is refused).
            let setting = |key: &str, value: usize| -> Result<(), String> {
                match inputs.get("filter").and_then(|f| f.get(key)) {
                    Some(v) if v.as_u64() == Some(value as u64) => Ok(()),
                    other => Err(format!(
                        "`{key}` {value} disagrees with the fingerprint's filter `{key}` ({})",
                        other.unwrap_or(&serde_json::Value::Null)
                    )),
                }
            };
            setting("particles", self.particles)?;
            setting("window", self.window)?;
        }
        let n = self.param_names.len();
        let sized = |what: &str, len: usize| -> Result<(), String> {
            if len == n {
                Ok(())
            } else {
                Err(format!("{what} has {len} entries for {n} parameters"))
            }
        };
        sized("theta_val", self.theta_val.len())?;
        if !self.theta_sd_final.is_empty() {
            sized("theta_sd_final", self.theta_sd_final.len())?;
        }
        if !self.theta_correlation.is_empty() {
            sized("theta_correlation", self.theta_correlation.len())?;
            for (j, row) in self.theta_correlation.iter().enumerate() {
                sized(&format!("theta_correlation row {}", j + 1), row.len())?;
                if row.iter().any(|r| !(-1.0..=1.0).contains(r)) {
                    return Err(format!(
                        "theta_correlation row {} holds a value outside [-1, 1]",
                        j + 1
                    ));
                }
            }
        }
        if let Some(t) = &self.theta_true {
            sized("theta_true", t.len())?;
        }
        if let Some(e) = &self.rel_error {
            sized("rel_error", e.len())?;
        }
        self.check_lengths()?;
        if self.steps_completed > self.steps_total {
            return Err(format!(
                "steps_completed {} exceeds steps_total {}",
                self.steps_completed, self.steps_total
            ));
        }
        if self.failure.is_none() && self.steps_completed != self.steps_total {
            return Err(format!(
                "the run completed {} of {} steps but records no failure",
                self.steps_completed, self.steps_total
            ));
        }
        Ok(())
    }
}

impl RunRecord {
    /// The per-step and per-channel blocks have the sizes their readers index by: one trace row
    /// per kept time with one entry per parameter, one residual row per kept time with one entry
    /// per channel, intervals of known parameters.
    fn check_lengths(&self) -> Result<(), String> {
        let n = self.param_names.len();
        let tr = &self.trace;
        let kept = tr.t.len();
        for (what, len) in [
            ("trace.param_mean", tr.param_mean.len()),
            ("trace.param_sd", tr.param_sd.len()),
            ("trace.ess", tr.ess.len()),
        ] {
            if len != kept {
                return Err(format!("{what} has {len} rows for {kept} times in trace.t"));
            }
        }
        for (what, rows) in [
            ("trace.param_mean", &tr.param_mean),
            ("trace.param_sd", &tr.param_sd),
        ] {
            if let Some((k, row)) = rows.iter().enumerate().find(|(_, r)| r.len() != n) {
                return Err(format!(
                    "{what} row {k} has {} entries for {n} parameters",
                    row.len()
                ));
            }
        }
        if let Some(r) = &self.residuals {
            let (kept, ny) = (r.t.len(), r.channels.len());
            for (what, rows) in [
                ("residuals.measured", &r.measured),
                ("residuals.predicted", &r.predicted),
                ("residuals.normalised_innovation", &r.normalised_innovation),
            ] {
                if rows.len() != kept {
                    return Err(format!(
                        "{what} has {} rows for {kept} times in residuals.t",
                        rows.len()
                    ));
                }
                if let Some((k, row)) = rows.iter().enumerate().find(|(_, x)| x.len() != ny) {
                    return Err(format!(
                        "{what} row {k} has {} entries for {ny} channels",
                        row.len()
                    ));
                }
            }
        }
        if let Some(p) = self
            .credible
            .iter()
            .find(|p| !self.param_names.contains(&p.parameter))
        {
            return Err(format!(
                "credible intervals of `{}`, which is not a parameter of the record",
                p.parameter
            ));
        }
        if let Some(v) = &self.validation {
            for (what, l) in [
                ("validation.loop_validation", &v.loop_validation),
                ("validation.loop_true", &v.loop_true),
            ] {
                if let Some(l) = l.as_ref().filter(|l| l.x.len() != l.force.len()) {
                    return Err(format!(
                        "{what} has {} drifts for {} forces",
                        l.x.len(),
                        l.force.len()
                    ));
                }
            }
        }
        Ok(())
    }
}

impl SweepRecord for RunRecord {
    fn failed(&self) -> bool {
        self.is_failure()
    }
    fn fingerprint(&self) -> Option<&str> {
        self.fingerprint.as_ref().map(|f| f.sha256.as_str())
    }
    fn same_result(&self, other: &Self) -> bool {
        self.deterministic_json() == other.deterministic_json()
    }
}

impl read::Checked for RunRecord {
    const KIND: &'static str = "run record";
    fn check(&self) -> Result<(), String> {
        RunRecord::check(self)
    }
}

/// [`SignalError`] with the record's number encoding (its type lives with the metrics).
#[derive(Serialize, Deserialize)]
struct SignalErrorRepr {
    #[serde(with = "number::scalar")]
    rmse: f64,
    #[serde(with = "number::scalar")]
    cv_rmse: f64,
    #[serde(with = "number::scalar")]
    nrmse: f64,
}

#[derive(Serialize, Deserialize)]
struct StateErrorsRepr {
    names: Vec<String>,
    errors: Vec<SignalErrorRepr>,
}

impl From<&StateErrors> for StateErrorsRepr {
    fn from(s: &StateErrors) -> Self {
        Self {
            names: s.names.clone(),
            errors: s
                .errors
                .iter()
                .map(|e| SignalErrorRepr {
                    rmse: e.rmse,
                    cv_rmse: e.cv_rmse,
                    nrmse: e.nrmse,
                })
                .collect(),
        }
    }
}

impl From<StateErrorsRepr> for StateErrors {
    fn from(s: StateErrorsRepr) -> Self {
        Self {
            names: s.names,
            errors: s
                .errors
                .into_iter()
                .map(|e| SignalError {
                    rmse: e.rmse,
                    cv_rmse: e.cv_rmse,
                    nrmse: e.nrmse,
                })
                .collect(),
        }
    }
}

mod state_errors {
    use super::*;
    use serde::{Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(x: &StateErrors, s: S) -> Result<S::Ok, S::Error> {
        StateErrorsRepr::from(x).serialize(s)
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<StateErrors, D::Error> {
        StateErrorsRepr::deserialize(d).map(Into::into)
    }
}

mod opt_state_errors {
    use super::*;
    use serde::{Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(
        x: &Option<StateErrors>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        x.as_ref().map(StateErrorsRepr::from).serialize(s)
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<StateErrors>, D::Error> {
        Ok(Option::<StateErrorsRepr>::deserialize(d)?.map(Into::into))
    }
}

/// [`Trace`] with the record's number encoding (its type lives with the observer).
#[derive(Serialize, Deserialize)]
struct TraceRepr {
    every: usize,
    #[serde(with = "number::vec")]
    t: Vec<f64>,
    #[serde(with = "number::vec_vec")]
    param_mean: Vec<Vec<f64>>,
    #[serde(with = "number::vec_vec")]
    param_sd: Vec<Vec<f64>>,
    #[serde(with = "number::vec")]
    ess: Vec<f64>,
}

mod trace_repr {
    use super::*;
    use serde::{Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(x: &Trace, s: S) -> Result<S::Ok, S::Error> {
        let Trace {
            every,
            t,
            param_mean,
            param_sd,
            ess,
        } = x.clone();
        TraceRepr {
            every,
            t,
            param_mean,
            param_sd,
            ess,
        }
        .serialize(s)
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Trace, D::Error> {
        let r = TraceRepr::deserialize(d)?;
        Ok(Trace {
            every: r.every,
            t: r.t,
            param_mean: r.param_mean,
            param_sd: r.param_sd,
            ess: r.ess,
        })
    }
}
