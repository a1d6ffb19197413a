//! Coverage of a sweep from its run records (SPEC §9 "Calibration"): the one extraction of a
//! record's posterior of each parameter into a [`RunPosterior`], the calibration of every
//! algorithm × parameter of a sweep ([`crate::calibration`]), and its section of `REPORT.md`.
//!
//! What enters: per record and parameter, θ_true (from the data set), θ_val (the estimate a user
//! reads, SPEC eq. 26), the final posterior s.d. and the record's central credible intervals
//! (`credible`: the last step's particle posterior, see [`identify::observe::ParamIntervals`]).
//! Left out, and counted: failed runs (their last weights are not a posterior) and records
//! without intervals (written before intervals were recorded, or a parameter whose interval
//! could not be computed). A sweep without a known truth (field data) has no coverage.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::error::{Context, Result};
use core_filters::credible::STANDARD_LEVELS;
use serde::{Deserialize, Serialize};

use crate::calibration::{calibrate_algorithm, markdown, RunPosterior, SweepCalibration};
use crate::study::Study;
use identify::record::RunRecord;

/// Runs of one algorithm left out of its coverage, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Excluded {
    pub algorithm: String,
    /// Records of the algorithm in the sweep.
    pub records: usize,
    /// Runs that ended early with a failure.
    pub failed: usize,
    /// Completed runs without an interval for at least one parameter.
    pub without_intervals: usize,
}

/// The coverage of one sweep: the calibration of every algorithm and parameter, θ_true, and the
/// runs left out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepCoverage {
    pub calibration: SweepCalibration,
    /// Parameter names and true values, in the records' order.
    pub param_names: Vec<String>,
    pub theta_true: Vec<f64>,
    pub excluded: Vec<Excluded>,
}

/// Why a record's posterior of a parameter is not usable for coverage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Missing {
    /// The run failed.
    Failed,
    /// The data set has no known truth.
    NoTruth,
    /// The record holds no interval for the parameter.
    NoInterval,
}

/// The posterior of parameter `j` of one record as calibration input: θ_true, θ_val, the final
/// posterior s.d. and the recorded intervals. `Err(Missing)` when the record cannot say.
pub fn run_posterior(r: &RunRecord, j: usize) -> std::result::Result<RunPosterior, Missing> {
    if r.is_failure() {
        return Err(Missing::Failed);
    }
    let truth = r
        .theta_true
        .as_ref()
        .and_then(|t| t.get(j))
        .ok_or(Missing::NoTruth)?;
    let name = r.param_names.get(j).ok_or(Missing::NoInterval)?;
    let p = r
        .credible
        .iter()
        .find(|p| &p.parameter == name && p.error.is_none() && !p.intervals.is_empty())
        .ok_or(Missing::NoInterval)?;
    Ok(RunPosterior {
        truth: *truth,
        estimate: r.theta_val.get(j).copied().unwrap_or(f64::NAN),
        sd: r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN),
        intervals: p.intervals.clone(),
    })
}

/// The coverage of a sweep at the standard levels (50, 90, 95 %): `groups` holds each
/// algorithm's records, in the order to report. `None` when no completed record knows θ_true.
/// Records of one sweep share their parameters; a record whose parameter names differ from the
/// first one's is an error naming it.
pub fn sweep_coverage(
    sweep: &str,
    groups: &[(&str, Vec<&RunRecord>)],
) -> Result<Option<SweepCoverage>> {
    let Some(first) = groups
        .iter()
        .flat_map(|(_, rs)| rs)
        .find(|r| !r.is_failure() && r.theta_true.is_some())
    else {
        return Ok(None);
    };
    let names = first.param_names.clone();
    let mut algorithms = Vec::new();
    let mut excluded = Vec::new();
    for (algorithm, records) in groups {
        let mut params: Vec<(&str, Vec<RunPosterior>)> =
            names.iter().map(|n| (n.as_str(), Vec::new())).collect();
        let (mut failed, mut without) = (0, 0);
        for r in records {
            if r.param_names != names {
                crate::error::bail!(
                    "sweep {sweep}: the record of {} run {} has parameters {:?}, the sweep {:?}",
                    r.algorithm,
                    r.run,
                    r.param_names,
                    names
                );
            }
            let mut complete = true;
            for (j, (_, runs)) in params.iter_mut().enumerate() {
                match run_posterior(r, j) {
                    Ok(p) => runs.push(p),
                    Err(Missing::Failed) => {}
                    Err(Missing::NoTruth | Missing::NoInterval) => complete = false,
                }
            }
            if r.is_failure() {
                failed += 1;
            } else if !complete {
                without += 1;
            }
        }
        algorithms.push(
            calibrate_algorithm(algorithm, &params, &STANDARD_LEVELS)
                .with_context(|| format!("sweep {sweep}, {algorithm}"))?,
        );
        excluded.push(Excluded {
            algorithm: algorithm.to_string(),
            records: records.len(),
            failed,
            without_intervals: without,
        });
    }
    Ok(Some(SweepCoverage {
        calibration: SweepCalibration {
            sweep: sweep.to_string(),
            levels: STANDARD_LEVELS.to_vec(),
            algorithms,
        },
        param_names: names,
        theta_true: first.theta_true.clone().unwrap_or_default(),
        excluded,
    }))
}

/// The report section of one sweep's coverage: what the intervals are, θ_true, the table of
/// [`markdown`] and the runs left out.
pub fn report_section(out: &mut String, title: &str, c: &SweepCoverage) {
    let _ = writeln!(out, "### {title}\n");
    let truth: Vec<String> = c
        .param_names
        .iter()
        .zip(&c.theta_true)
        .map(|(n, t)| format!("{n} = {t}"))
        .collect();
    let _ = writeln!(
        out,
        "θ_true: {}. Intervals: central credible intervals of the last step's particle \
         posterior, p(θ | y_1:T) (Gaussian mixture for marginalised parameters, weighted sample \
         for sampled ones); z uses θ_val and the last step's posterior s.d.\n",
        truth.join(", ")
    );
    out.push_str(&markdown(&c.calibration));
    let left: Vec<String> = c
        .excluded
        .iter()
        .filter(|e| e.failed + e.without_intervals > 0)
        .map(|e| {
            format!(
                "{}: {} failed, {} without intervals (of {})",
                e.algorithm, e.failed, e.without_intervals, e.records
            )
        })
        .collect();
    if !left.is_empty() {
        let _ = writeln!(out, "\nLeft out: {}.", left.join("; "));
    }
    let _ = writeln!(out);
}

/// The coverage of a study's sweep, its records grouped by the study's algorithms in order.
pub(crate) fn study_coverage(
    study: &Study,
    records: &[RunRecord],
) -> Result<Option<SweepCoverage>> {
    let groups: Vec<(&str, Vec<&RunRecord>)> = study
        .sweep
        .algorithms
        .iter()
        .map(|a| {
            (
                a.name(),
                records.iter().filter(|r| r.algorithm == a.name()).collect(),
            )
        })
        .collect();
    sweep_coverage(&study.name, &groups)
}

/// The coverage section of `REPORT.md`: one table per study with a known truth, in `order`.
pub fn report(
    out: &mut String,
    order: &[&str],
    studies: &BTreeMap<&str, Study>,
    records: &BTreeMap<&str, Vec<RunRecord>>,
) -> Result<()> {
    let _ = writeln!(out, "## Coverage of the credible intervals\n");
    let _ = writeln!(
        out,
        "Does the truth lie in the interval a run reports? Per study, algorithm and parameter: \
         the fraction of runs whose central 50, 90 and 95 % credible intervals contain θ_true \
         (SPEC §9). The paper's studies use its settings (resampling at every step, no \
         rejuvenation of n); with one or a few runs per algorithm no verdict is given. \
         Figure: coverage against nominal level over the Fig. 7 sweep.\n"
    );
    let _ = writeln!(out, "![Coverage, Fig. 7 sweep](fig7_coverage.svg)\n");
    for name in order {
        let (Some(study), Some(recs)) = (studies.get(name), records.get(name)) else {
            continue;
        };
        if let Some(c) = study_coverage(study, recs)? {
            report_section(out, &format!("`{name}`: {}", study.description), &c);
        }
    }
    Ok(())
}

/// Pooled coverage of the stiffnesses and dampings: over the completed runs with a known truth,
/// the fraction of (run, k_j or c_j) pairs whose central interval at `level` contains the true
/// value, and the number of pairs (runs without recorded intervals count no pair).
pub fn stiffness_damping_coverage(records: &[&RunRecord], level: f64) -> (f64, usize) {
    let (mut covered, mut pairs) = (0usize, 0usize);
    for r in records.iter().filter(|r| !r.is_failure()) {
        let Some(truth) = &r.theta_true else { continue };
        for (j, name) in r.param_names.iter().enumerate() {
            let storey_param = name.len() > 1
                && (name.starts_with('k') || name.starts_with('c'))
                && name[1..].chars().all(|c| c.is_ascii_digit());
            if !storey_param {
                continue;
            }
            let Some(ci) = r
                .credible
                .iter()
                .find(|p| &p.parameter == name)
                .and_then(|p| p.at(level))
            else {
                continue;
            };
            pairs += 1;
            if ci.lo <= truth[j] && truth[j] <= ci.hi {
                covered += 1;
            }
        }
    }
    let fraction = if pairs > 0 {
        covered as f64 / pairs as f64
    } else {
        f64::NAN
    };
    (fraction, pairs)
}
