//! A study on a user's own record (`[data] dir = ...` in a study file; `sysid study`): N filter
//! seeds × algorithms on the same data, aggregated into what a user needs to trust one run —
//! the mean of θ_val over the runs, its run-to-run spread (the Monte-Carlo error of one run) and
//! the posterior s.d. a run reports beside it. With a known truth (`dataset.json`) the relative
//! error is added.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use std::path::PathBuf;
use std::time::Instant;

use crate::error::{Context, Result};

use crate::engine::{load, write_json, RunMode};
use crate::markdown::compact_header;
use crate::run_dir::open;
use crate::stats::{completed, truth};
use crate::study::Study;
use crate::sweep::write_bytes_atomic;
use crate::verdict::{findings_table, Finding};
use identify::metrics::mean_spread;
use identify::record::RunRecord;

/// One algorithm's statistics of one parameter over the runs of a study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamSpread {
    pub algorithm: String,
    pub param: String,
    /// Completed runs (failed runs are left out and counted in [`AlgorithmSpread::failed`]).
    pub runs: usize,
    /// Mean of θ_val over the runs.
    pub mean: f64,
    /// s.d. of θ_val over the runs: the Monte-Carlo spread of one run's answer (NaN below 2 runs).
    pub spread: f64,
    /// Mean over the runs of the posterior s.d. a run reports.
    pub posterior_sd: f64,
    /// `posterior_sd / spread`: below 1, a single run's interval is narrower than the scatter of
    /// its own answer.
    pub sd_over_spread: f64,
    pub truth: Option<f64>,
}

/// One algorithm's runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlgorithmSpread {
    pub algorithm: String,
    pub runs: usize,
    pub failed: usize,
    /// Runs whose record carries at least one warning (`checks`).
    pub with_warnings: usize,
    pub params: Vec<ParamSpread>,
}

/// The statistics per algorithm (in name order) and parameter.
pub(crate) fn spreads(records: &[RunRecord]) -> Vec<AlgorithmSpread> {
    let mut by: BTreeMap<&str, Vec<&RunRecord>> = BTreeMap::new();
    for r in records {
        by.entry(r.algorithm.as_str()).or_default().push(r);
    }
    by.into_iter()
        .map(|(alg, rs)| {
            let (ok, names) = completed(&rs);
            let params = names
                .iter()
                .enumerate()
                .map(|(j, name)| {
                    let vals: Vec<f64> = ok
                        .iter()
                        .filter_map(|r| r.theta_val.get(j).copied())
                        .collect();
                    let sds: Vec<f64> = ok
                        .iter()
                        .filter_map(|r| r.theta_sd_final.get(j).copied())
                        .collect();
                    let (mean, spread) = mean_spread(&vals);
                    let posterior_sd = identify::metrics::mean_sd(&sds).0;
                    ParamSpread {
                        algorithm: alg.to_string(),
                        param: name.clone(),
                        runs: vals.len(),
                        mean,
                        spread,
                        posterior_sd,
                        sd_over_spread: posterior_sd / spread,
                        truth: truth(&ok, j),
                    }
                })
                .collect();
            AlgorithmSpread {
                algorithm: alg.to_string(),
                runs: rs.len(),
                failed: rs.len() - ok.len(),
                with_warnings: rs.iter().filter(|r| !r.warnings.is_empty()).count(),
                params,
            }
        })
        .collect()
}

/// The report of a study: on a user's record (`one_record`: every run filters the same data) or
/// on a preset (every run generates its own data set).
pub fn markdown(
    name: &str,
    description: &str,
    data: &str,
    one_record: bool,
    spreads: &[AlgorithmSpread],
) -> String {
    let mut o = String::new();
    let spread = if one_record {
        "Every run filters this record with its own filter streams (seed, run), so the spread over runs is the Monte-Carlo error of one run's answer."
    } else {
        "Every run generates its own data set from (master seed, run) and filters it with its own filter streams, so the spread over runs is that of the data and of the Monte-Carlo error together."
    };
    let _ = writeln!(
        o,
        "# Study `{name}`\n\n{description}\n\nData: `{data}`. {spread}\n"
    );
    compact_header(
        &mut o,
        &[
            "algorithm",
            "runs (failed, with warnings)",
            "parameter",
            "θ_val mean over runs",
            "run-to-run s.d.",
            "mean posterior s.d.",
            "posterior s.d. / spread",
            "truth",
        ],
        "llllllll",
    );
    for a in spreads {
        for p in &a.params {
            let _ = writeln!(
                o,
                "| {} | {} ({}, {}) | {} | {:.5} | {:.5} | {:.5} | {:.2} | {} |",
                a.algorithm,
                a.runs,
                a.failed,
                a.with_warnings,
                p.param,
                p.mean,
                p.spread,
                p.posterior_sd,
                p.sd_over_spread,
                p.truth
                    .map_or_else(|| "–".to_string(), |t| format!("{t:.5}"))
            );
        }
    }
    let _ = writeln!(
        o,
        "\n![θ_val](theta_val.svg)\n\n![s.d. over spread](sd_over_spread.svg)"
    );
    let _ = writeln!(o, "\nA posterior s.d. / spread well below 1 means a single run's interval is narrower than the scatter of its own answer: pool runs (`pool` in the filter settings) or use more particles before acting on one run.");
    o
}

/// The figures of a study on a user's record, written into `out`:
///
/// - `theta_val.svg`: per parameter and algorithm, the mean of θ_val over the runs with ± 2
///   run-to-run s.d., divided by the truth when `dataset.json` knows it (the truth is then 1),
///   otherwise by the mean over every algorithm's runs (so parameters of different scales share
///   one axis);
/// - `sd_over_spread.svg`: per parameter and algorithm, the mean posterior s.d. a run reports
///   over the run-to-run s.d. of its answer (1: a run's interval is as wide as the scatter of
///   its answer; below 1: over-confident).
///
/// Returns the files written.
pub fn figures(
    spreads: &[AlgorithmSpread],
    out: &std::path::Path,
) -> crate::error::Result<Vec<std::path::PathBuf>> {
    use identify::figures::{category_panels, CategoryGroup, CategoryPanel};
    let Some(first) = spreads.iter().find(|a| !a.params.is_empty()) else {
        return Ok(Vec::new());
    };
    let params: Vec<String> = first.params.iter().map(|p| p.param.clone()).collect();
    let with_truth = first.params.iter().all(|p| p.truth.is_some());
    // The reference of each parameter: its truth, or the mean of the algorithms' means.
    let reference: Vec<f64> = params
        .iter()
        .map(|name| {
            let ps = spreads
                .iter()
                .filter_map(|a| a.params.iter().find(|p| &p.param == name));
            if with_truth {
                ps.filter_map(|p| p.truth).next().unwrap_or(f64::NAN)
            } else {
                let means: Vec<f64> = ps.map(|p| p.mean).collect();
                identify::metrics::mean_sd(&means).0
            }
        })
        .collect();
    let group = |a: &AlgorithmSpread, value: &dyn Fn(&ParamSpread, f64) -> (f64, f64)| {
        let (mean, half_width) = params
            .iter()
            .zip(&reference)
            .map(|(name, &r)| {
                a.params
                    .iter()
                    .find(|p| &p.param == name)
                    .map_or((f64::NAN, f64::NAN), |p| value(p, r))
            })
            .unzip();
        CategoryGroup {
            label: format!("{} ({} runs)", a.algorithm, a.runs),
            mean,
            half_width,
        }
    };
    let theta = CategoryPanel {
        caption: if with_truth {
            "θ_val / truth: mean over runs ± 2 run-to-run s.d.".to_string()
        } else {
            "θ_val / mean over all runs: mean over runs ± 2 run-to-run s.d.".to_string()
        },
        y_desc: if with_truth {
            "θ_val / truth"
        } else {
            "θ_val / overall mean"
        }
        .to_string(),
        groups: spreads
            .iter()
            .map(|a| group(a, &|p, r| (p.mean / r, 2.0 * p.spread / r.abs())))
            .collect(),
    };
    let ratio = CategoryPanel {
        caption: "mean posterior s.d. / run-to-run s.d. (1: honest; below 1: over-confident)"
            .to_string(),
        y_desc: "s.d. / spread".to_string(),
        groups: spreads
            .iter()
            .map(|a| group(a, &|p, _| (p.sd_over_spread, f64::NAN)))
            .collect(),
    };
    let files = [
        (
            out.join("theta_val.svg"),
            theta,
            "θ_val over the runs of the study",
        ),
        (
            out.join("sd_over_spread.svg"),
            ratio,
            "Reported uncertainty against the Monte-Carlo scatter",
        ),
    ];
    let mut written = Vec::new();
    for (path, panel, title) in files {
        category_panels(&params, &[panel], &path, title)?;
        written.push(path);
    }
    Ok(written)
}

/// What `sysid study` is asked to do: the study file, where its results go, and how.
#[derive(Debug, Clone)]
pub struct Options {
    /// The study file.
    pub config: PathBuf,
    /// Output directory (records/, summary.json, REPORT.md).
    pub out: PathBuf,
    /// How it runs.
    pub mode: RunMode,
}

/// Runs a study file and writes its records, `summary.json` and `REPORT.md` (per algorithm and
/// parameter: θ_val mean over runs, run-to-run spread, posterior s.d.); a shard writes only its
/// records.
pub fn run(args: &Options) -> Result<Option<String>> {
    let start = Instant::now();
    let study = load(&args.config, args.mode.quick)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let (_lock, engine) = open(&args.out, args.mode)?;
    let outcome = engine.sweep(
        &study,
        &study.jobs(),
        &args.out.join("records"),
        |job| study.record_id(job),
        |job| study.run_job(job),
    )?;
    if engine.sharded() {
        engine.shard_note(&outcome.summary());
        return Ok(None);
    }
    let spreads = spreads(&outcome.records);
    let data = match &study.data.dir {
        Some(d) => d.display().to_string(),
        None => format!("preset {} (one data set per run)", study.data.preset),
    };
    engine.last_run(serde_json::json!({
        "runs": { "executed": outcome.executed, "reused": outcome.reused, "failed": outcome.failed },
        "wall_s": start.elapsed().as_secs_f64(),
    }))?;
    identify::plot::figures_in_place(&args.out, |dir| figures(&spreads, dir).map(|_| ()))?;
    let mut report = markdown(
        &study.name,
        &study.description,
        &data,
        study.data.dir.is_some(),
        &spreads,
    );
    // Per structure of the structure axis (their parameters differ), else over the whole sweep:
    // the declared verdicts and, with a known truth (a preset), how often the intervals hold it.
    let jobs = study.jobs();
    let mut all_findings = Vec::new();
    for (suffix, structure) in structure_groups(&study) {
        let records: Vec<&RunRecord> = outcome
            .records
            .iter()
            .zip(&jobs)
            .filter(|(_, j)| j.structure == structure)
            .map(|(r, _)| r)
            .collect();
        if let Some(f) = verdicts_section(&mut report, &study, &records, &suffix, structure) {
            all_findings.push(f);
        }
        coverage_section(&mut report, &study, &records, &suffix)?;
    }
    let mut summary = serde_json::json!({
        "study": study.name,
        "data": data,
        "algorithms": spreads,
    });
    if !all_findings.is_empty() {
        summary["verdicts"] = serde_json::Value::Array(all_findings);
    }
    write_json(&args.out.join("summary.json"), &summary)?;
    write_bytes_atomic(&args.out.join("REPORT.md"), report.as_bytes())?;
    log::info!(
        "study {}: {} runs ({} executed, {} reused, {} failed) in {:.1} s; wrote {}",
        study.name,
        outcome.records.len(),
        outcome.executed,
        outcome.reused,
        outcome.failed,
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(Some(report))
}

/// The groups the report's verdicts and coverage are given for: one per structure of the
/// structure axis (a heading suffix naming it, and its index), else the whole sweep.
fn structure_groups(study: &Study) -> Vec<(String, Option<usize>)> {
    if study.sweep.structures.is_empty() {
        vec![(String::new(), None)]
    } else {
        study
            .sweep
            .structures
            .iter()
            .enumerate()
            .map(|(i, s)| (format!(", structure `{}`", s.label), Some(i)))
            .collect()
    }
}

/// The statements the study declares, decided on one group's records: their section of the
/// report, and their entry of `summary.json` (none when no statement is decided).
fn verdicts_section(
    report: &mut String,
    study: &Study,
    records: &[&RunRecord],
    suffix: &str,
    structure: Option<usize>,
) -> Option<serde_json::Value> {
    let findings: Vec<Finding> = study
        .verdicts
        .iter()
        .filter_map(|d| d.decide(records, &[]))
        .collect();
    if findings.is_empty() {
        return None;
    }
    let _ = writeln!(report, "\n### Verdicts{suffix}\n");
    findings_table(
        report,
        ["statement", "verdict", "test", "evidence"],
        &findings,
    );
    let _ = writeln!(report, "\nA statement holds when its ±2 s.e. interval lies on the stated side of the threshold (inside the band), does not hold when it lies entirely on the other side, and is not resolved otherwise; comparisons of two algorithms use the paired difference over the runs both completed.");
    Some(serde_json::json!({
        "structure": structure.map(|i| study.sweep.structures[i].label.clone()),
        "findings": findings,
    }))
}

/// With a known truth, the coverage of one group's credible intervals per algorithm, and the
/// share of the 95 % intervals of the stiffnesses and dampings that hold it.
fn coverage_section(
    report: &mut String,
    study: &Study,
    records: &[&RunRecord],
    suffix: &str,
) -> Result<()> {
    let by_algorithm: Vec<(&str, Vec<&RunRecord>)> = study
        .sweep
        .algorithms
        .iter()
        .map(|a| {
            let recs = records.iter().copied().filter(|r| r.algorithm == a.name());
            (a.name(), recs.collect())
        })
        .collect();
    let Some(c) = crate::coverage::sweep_coverage(&study.name, &by_algorithm)? else {
        return Ok(());
    };
    let _ = writeln!(report);
    let title = format!("Coverage of the credible intervals{suffix}");
    crate::coverage::report_section(report, &title, &c);
    for (name, recs) in &by_algorithm {
        let (fraction, pairs) = crate::coverage::stiffness_damping_coverage(recs, 0.95);
        if pairs > 0 {
            let _ = writeln!(
                report,
                "{name}: the 95 % intervals of the stiffnesses and dampings hold the truth in {} of {} (run, parameter) pairs ({fraction:.2}).",
                (fraction * pairs as f64).round() as usize,
                pairs
            );
        }
    }
    Ok(())
}
