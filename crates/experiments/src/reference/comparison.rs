//! The online filters against a reference posterior: per data set ([`compare`]), the
//! information limit across data sets ([`information_limit`]) and the accuracy goal against it,
//! decided by a stated test ([`goal_rows`]); `compare_files` is `sysid compare-reference`.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{chain_warnings, pool_chains, ParamSummary, ReferenceRecord};
use crate::error::{bail, Result};

/// One algorithm's final posteriors against the reference, per parameter, over its runs
/// (several filter seeds on the reference's data set).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    pub algorithm: String,
    pub param: String,
    pub runs: usize,
    /// Mean over runs of (online final mean − reference mean) / reference s.d.
    pub mean_shift_in_ref_sd: f64,
    /// Run-to-run s.d. of the online final mean, in reference s.d.
    pub spread_in_ref_sd: f64,
    /// Mean over runs of online s.d. / reference s.d.
    pub sd_ratio: f64,
}

/// The comparisons of every algorithm and parameter present in both (records of failed runs
/// are left out). The online posterior is the last step's (`theta_sd_final` and the mean of the
/// last step's posterior are what a user reads at the end of the record; θ_val averages the
/// last window, which on a short record is close to it).
pub fn compare(
    reference: &[ParamSummary],
    records: &[identify::record::RunRecord],
) -> Vec<Comparison> {
    let mut algorithms: Vec<&str> = records.iter().map(|r| r.algorithm.as_str()).collect();
    algorithms.sort();
    algorithms.dedup();
    let mut out = Vec::new();
    for alg in algorithms {
        for p in reference {
            let mut shifts = Vec::new();
            let mut ratios = Vec::new();
            for r in records
                .iter()
                .filter(|r| r.algorithm == alg && r.failure.is_none())
            {
                let Some(i) = r.param_names.iter().position(|n| *n == p.name) else {
                    continue;
                };
                let (Some(m), Some(sd)) = (r.theta_val.get(i), r.theta_sd_final.get(i)) else {
                    continue;
                };
                shifts.push((m - p.mean) / p.sd);
                ratios.push(sd / p.sd);
            }
            if shifts.is_empty() {
                continue;
            }
            let (mean, spread, n) = identify::metrics::mean_sd(&shifts);
            out.push(Comparison {
                algorithm: alg.to_string(),
                param: p.name.clone(),
                runs: n,
                mean_shift_in_ref_sd: mean,
                spread_in_ref_sd: if n > 1 { spread } else { f64::NAN },
                sd_ratio: identify::metrics::mean_sd(&ratios).0,
            });
        }
    }
    out
}

/// The comparison as a markdown table, with the reference beside it.
pub(crate) fn compare_markdown(
    reference: &[ParamSummary],
    records: &[identify::record::RunRecord],
) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(o, "| parameter | reference mean ± s.d. (truth) | algorithm | runs | shift of the online mean (ref. s.d.) | run-to-run spread (ref. s.d.) | online s.d. / ref. s.d. |");
    let _ = writeln!(o, "|---|---|---|---|---|---|---|");
    for c in compare(reference, records) {
        let p = reference
            .iter()
            .find(|p| p.name == c.param)
            .expect("from the reference");
        let truth = p.truth.map(|t| format!(" ({t:.4})")).unwrap_or_default();
        let _ = writeln!(
            o,
            "| {} | {:.4} ± {:.4}{} | {} | {} | {:+.2} | {:.2} | {:.3} |",
            c.param,
            p.mean,
            p.sd,
            truth,
            c.algorithm,
            c.runs,
            c.mean_shift_in_ref_sd,
            c.spread_in_ref_sd,
            c.sd_ratio
        );
    }
    o
}

/// Whether the reference's central 95 % interval of `p` holds its truth: the chain's 2.5 and
/// 97.5 % quantiles for one chain, mean ± 1.96 s.d. for pooled chains (whose quantiles are not
/// pooled). `None` without a truth.
pub fn reference_covers(p: &ParamSummary) -> Option<bool> {
    let t = p.truth?;
    let [lo, .., hi] = p.quantiles;
    Some(if lo.is_finite() && hi.is_finite() {
        lo <= t && t <= hi
    } else {
        (p.mean - t).abs() <= 1.96 * p.sd
    })
}

/// One parameter and algorithm over several data sets: what the reference posterior of each
/// record reaches (the information in the data) beside what the online filter reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LimitRow {
    pub param: String,
    pub algorithm: String,
    /// Data sets with a reference and a truth for this parameter.
    pub data_sets: usize,
    /// Mean over data sets of |reference mean / truth − 1|.
    pub ref_rel_error: f64,
    /// Mean over data sets of reference s.d. / |truth|.
    pub ref_rel_sd: f64,
    /// Data sets whose reference 95 % interval holds the truth ([`reference_covers`]).
    pub ref_covered: usize,
    /// Completed online runs over all data sets.
    pub runs: usize,
    /// Mean over runs of |θ_val / truth − 1|.
    pub online_rel_error: f64,
    /// Runs whose recorded 95 % credible interval holds the truth, of `intervals` runs with one.
    pub online_covered: usize,
    pub intervals: usize,
    /// Mean over runs of online s.d. / the reference s.d. of the run's data set.
    pub sd_ratio: f64,
}

/// One data set: its (pooled) reference and the online records computed on it.
pub type DataSetRuns = (Vec<ParamSummary>, Vec<identify::record::RunRecord>);

/// The algorithms of the online records of `groups`, sorted, once each.
fn algorithms_of(groups: &[DataSetRuns]) -> Vec<&str> {
    let mut algorithms: Vec<&str> = groups
        .iter()
        .flat_map(|(_, rs)| rs.iter().map(|r| r.algorithm.as_str()))
        .collect();
    algorithms.sort();
    algorithms.dedup();
    algorithms
}

/// The information limit over several data sets: `groups` holds, per data set, the (pooled)
/// reference and the online records of that data set. Rows per algorithm and parameter (in the
/// reference's order); failed runs are left out, as in [`compare`].
pub fn information_limit(groups: &[DataSetRuns]) -> Vec<LimitRow> {
    let algorithms = algorithms_of(groups);
    let Some((first, _)) = groups.first() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for alg in algorithms {
        for name in first.iter().map(|p| p.name.as_str()) {
            let (mut ref_err, mut ref_sd, mut ref_cov) = (Vec::new(), Vec::new(), 0usize);
            let (mut err, mut ratio, mut covered, mut intervals) = (Vec::new(), Vec::new(), 0, 0);
            for (reference, records) in groups {
                let Some(p) = reference.iter().find(|p| p.name == name) else {
                    continue;
                };
                let Some(t) = p.truth.filter(|t| *t != 0.0) else {
                    continue;
                };
                ref_err.push((p.mean / t - 1.0).abs());
                ref_sd.push(p.sd / t.abs());
                ref_cov += usize::from(reference_covers(p) == Some(true));
                for r in records
                    .iter()
                    .filter(|r| r.algorithm == alg && !r.is_failure())
                {
                    let Some(j) = r.param_names.iter().position(|n| n == name) else {
                        continue;
                    };
                    let (Some(m), Some(sd)) = (r.theta_val.get(j), r.theta_sd_final.get(j)) else {
                        continue;
                    };
                    err.push((m / t - 1.0).abs());
                    ratio.push(sd / p.sd);
                    let interval = r
                        .credible
                        .iter()
                        .find(|c| c.parameter == name && c.error.is_none())
                        .and_then(|c| c.at(0.95));
                    if let Some(ci) = interval {
                        intervals += 1;
                        covered += usize::from(ci.contains(t));
                    }
                }
            }
            if err.is_empty() {
                continue;
            }
            let mean = |x: &[f64]| identify::metrics::mean_sd(x).0;
            out.push(LimitRow {
                param: name.to_string(),
                algorithm: alg.to_string(),
                data_sets: ref_err.len(),
                ref_rel_error: mean(&ref_err),
                ref_rel_sd: mean(&ref_sd),
                ref_covered: ref_cov,
                runs: err.len(),
                online_rel_error: mean(&err),
                online_covered: covered,
                intervals,
                sd_ratio: mean(&ratio),
            });
        }
    }
    out
}

/// The margin of the accuracy goal against the information limit: the online filter's mean
/// |error| of the storeys' stiffnesses (or dampings) at most 10 % above the reference
/// posterior's own.
pub const GOAL_MARGIN: f64 = 0.10;

/// The goal "the online mean |error| of a group of parameters is within [`GOAL_MARGIN`] of the
/// reference's", for one algorithm, decided by a stated test ([`crate::verdict::below`]): the
/// difference online − reference, paired over (data set, parameter) — per pair the online
/// |error| is the mean over that data set's completed runs — must lie below
/// `GOAL_MARGIN × reference` with its ±2 s.e. interval (holds), above it (does not hold), or the
/// goal is not resolved. The s.e. is over the pairs, which treats the parameters of one data set
/// as independent; the margin takes the reference's measured error as exact.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GoalRow {
    pub algorithm: String,
    /// `k` (the storeys' stiffnesses) or `c` (their dampings).
    pub group: char,
    /// Mean over the pairs of the reference's |mean / truth − 1|.
    pub reference: f64,
    /// Mean over the pairs of the online |θ_val / truth − 1|.
    pub online: f64,
    /// Online − reference, paired.
    pub difference: crate::verdict::Estimate,
    pub verdict: crate::verdict::Verdict,
}

/// [`GoalRow`]s of every algorithm of `groups` (as [`information_limit`]) for the stiffnesses and
/// the dampings.
pub fn goal_rows(groups: &[DataSetRuns]) -> Vec<GoalRow> {
    use crate::verdict::{below, in_group, Estimate};
    let algorithms = algorithms_of(groups);
    let mut out = Vec::new();
    for alg in algorithms {
        for group in ['k', 'c'] {
            let (mut reference, mut online) = (Vec::new(), Vec::new());
            for (summaries, records) in groups {
                for p in summaries.iter().filter(|p| in_group(&p.name, group)) {
                    let Some(t) = p.truth.filter(|t| *t != 0.0) else {
                        continue;
                    };
                    let errors: Vec<f64> = records
                        .iter()
                        .filter(|r| r.algorithm == alg && !r.is_failure())
                        .filter_map(|r| {
                            let j = r.param_names.iter().position(|n| *n == p.name)?;
                            Some((r.theta_val.get(j)? / t - 1.0).abs())
                        })
                        .collect();
                    if !errors.is_empty() {
                        reference.push((p.mean / t - 1.0).abs());
                        online.push(identify::metrics::mean_sd(&errors).0);
                    }
                }
            }
            if reference.is_empty() {
                continue;
            }
            let mean = |x: &[f64]| identify::metrics::mean_sd(x).0;
            let difference = Estimate::of(
                &online
                    .iter()
                    .zip(&reference)
                    .map(|(o, r)| o - r)
                    .collect::<Vec<_>>(),
            );
            out.push(GoalRow {
                algorithm: alg.to_string(),
                group,
                reference: mean(&reference),
                online: mean(&online),
                verdict: below(&difference, GOAL_MARGIN * mean(&reference)),
                difference,
            });
        }
    }
    out
}

/// The goal rows as a markdown table.
pub(crate) fn goal_markdown(rows: &[GoalRow]) -> String {
    use crate::markdown::{compact_header, num, row};
    let mut o = String::new();
    compact_header(
        &mut o,
        &[
            "algorithm",
            "parameters",
            "pairs (data set, parameter)",
            "reference: mean \\|error\\|",
            "online: mean \\|error\\|",
            "online − reference (± s.e.)",
            "margin: 10 % of the reference's",
            "online within the margin",
        ],
        "llrrrrrl",
    );
    for r in rows {
        let pct = |v: f64| format!("{} %", num(100.0 * v, 2));
        row(
            &mut o,
            &[
                r.algorithm.clone(),
                format!("all {}", r.group),
                r.difference.n.to_string(),
                pct(r.reference),
                pct(r.online),
                format!(
                    "{} ± {} points",
                    num(100.0 * r.difference.mean, 2),
                    num(100.0 * r.difference.se, 2)
                ),
                format!("{} points", num(100.0 * GOAL_MARGIN * r.reference, 2)),
                r.verdict.label().to_string(),
            ],
        );
    }
    o
}

/// The information limit as a markdown table ("–" where a ratio has no finite value, e.g. a
/// reference error of exactly zero).
pub(crate) fn limit_markdown(rows: &[LimitRow]) -> String {
    use crate::markdown::{compact_header, num, row};
    let mut o = String::new();
    compact_header(
        &mut o,
        &[
            "parameter",
            "algorithm",
            "data sets",
            "reference: mean \\|error\\|",
            "reference: mean s.d. / truth",
            "reference 95 % intervals holding the truth",
            "online runs",
            "online: mean \\|error\\|",
            "online error / reference error",
            "online 95 % intervals holding the truth",
            "online s.d. / ref. s.d.",
        ],
        "llrrrrrrrrr",
    );
    for r in rows {
        row(
            &mut o,
            &[
                r.param.clone(),
                r.algorithm.clone(),
                r.data_sets.to_string(),
                format!("{} %", num(100.0 * r.ref_rel_error, 2)),
                format!("{} %", num(100.0 * r.ref_rel_sd, 2)),
                format!("{} of {}", r.ref_covered, r.data_sets),
                r.runs.to_string(),
                format!("{} %", num(100.0 * r.online_rel_error, 2)),
                num(r.online_rel_error / r.ref_rel_error, 2),
                format!(
                    "{} of {} ({})",
                    r.online_covered,
                    r.intervals,
                    num(r.online_covered as f64 / r.intervals as f64, 2)
                ),
                num(r.sd_ratio, 2),
            ],
        );
    }
    o
}

/// The data set a run record was computed on (`data.sha256` of its fingerprint).
pub(crate) fn record_data_sha(r: &identify::record::RunRecord) -> Option<&str> {
    r.fingerprint
        .as_ref()?
        .inputs
        .get("data")?
        .get("sha256")?
        .as_str()
}

/// The chains of one data set and the online records computed on it.
struct DataSetGroup {
    data: String,
    sha: Option<String>,
    chains: Vec<Vec<crate::reference::ParamSummary>>,
    records: Vec<identify::record::RunRecord>,
}

/// `sysid compare-reference`: the online filters' final posteriors against the reference; with
/// references of several data sets, each online record against the reference of its own data
/// set, and the information limit across them.
/// `sysid compare-reference`: the online filters' final posteriors against the reference; with
/// references of several data sets, each online record against the reference of its own data
/// set, the information limit across them and the goal against it. Returns the markdown; `warn`
/// hears each reference chain's warnings (which the markdown lists too).
pub(crate) fn compare_files(
    references: &[PathBuf],
    records: &[PathBuf],
    warn: &mut dyn FnMut(String),
) -> Result<String> {
    // The chains' warnings go into the table's file as well, so that a reference resting on few
    // effective samples is not read as exact.
    let (mut groups, chain_notes) = reference_groups(references, warn)?;
    assign_records(&mut groups, records)?;
    let several = groups.len() > 1;
    let mut md = String::new();
    let mut compared = Vec::new();
    for g in groups {
        let pooled = pool_chains(&g.chains)?;
        if several {
            md.push_str(&format!(
                "## Data set {} (sha256 {})\n\n",
                g.data,
                g.sha.as_deref().map_or("?", |s| &s[..s.len().min(12)])
            ));
        }
        md.push_str(&compare_markdown(&pooled, &g.records));
        if several {
            md.push('\n');
        }
        compared.push((pooled, g.records));
    }
    if several {
        limit_and_goal(&mut md, &compared);
    }
    if !chain_notes.is_empty() {
        md.push_str(&format!(
            "\nWarnings on the reference chains:\n\n{}\n",
            chain_notes.join("\n")
        ));
    }
    Ok(md)
}

/// The reference records read and grouped by data set (several chains of one data set are
/// pooled later), with the notes of their chains' warnings, each also told to `warn`. An error
/// for a chain that did not move, or when references of several data sets include one that does
/// not name its data set.
fn reference_groups(
    references: &[PathBuf],
    warn: &mut dyn FnMut(String),
) -> Result<(Vec<DataSetGroup>, Vec<String>)> {
    let mut groups: Vec<DataSetGroup> = Vec::new();
    let mut chain_notes = Vec::new();
    for path in references {
        let r: ReferenceRecord = identify::record::read::read(path)?;
        // Older records carry no warnings: recompute them from what they hold.
        let warnings = chain_warnings(r.acceptance, &r.params, r.failed_estimates, r.evaluations);
        if r.acceptance == 0.0 {
            bail!(
                "{}: the chain did not move after the burn-in; it is not a posterior to compare with",
                path.display()
            );
        }
        for w in &warnings {
            warn(format!("{}: {w}", path.display()));
            chain_notes.push(format!("- {}: {w}", path.display()));
        }
        match groups.iter_mut().find(|g| g.sha == r.data_sha256) {
            Some(g) => g.chains.push(r.params),
            None => groups.push(DataSetGroup {
                data: r.data,
                sha: r.data_sha256,
                chains: vec![r.params],
                records: Vec::new(),
            }),
        }
    }
    if groups.len() > 1 && groups.iter().any(|g| g.sha.is_none()) {
        bail!(
            "the references name different data sets, and some were written before references \
             recorded their data set: compare those one data set at a time"
        );
    }
    Ok((groups, chain_notes))
}

/// Each online run record read and put with the reference of its data set; an error for a
/// record whose data set has no reference.
fn assign_records(groups: &mut [DataSetGroup], records: &[PathBuf]) -> Result<()> {
    for p in records {
        let r: identify::record::RunRecord = crate::sweep::read_record(p)?;
        let sha = record_data_sha(&r);
        let group = match &mut *groups {
            // A reference that does not name its data set is compared with every record, as
            // before references recorded it.
            [g] if g.sha.is_none() => g,
            gs => gs
                .iter_mut()
                .find(|g| g.sha.as_deref() == sha)
                .ok_or_else(|| {
                    crate::error::invalid!(
                        "{}: its data set (sha256 {}) is not that of any reference given",
                        p.display(),
                        sha.unwrap_or("unknown")
                    )
                })?,
        };
        group.records.push(r);
    }
    Ok(())
}

/// Across several data sets: the information limit, and the goal "online error within the
/// margin of the reference's" decided against it.
fn limit_and_goal(md: &mut String, compared: &[DataSetRuns]) {
    md.push_str(&format!(
        "## Across the {} data sets: the information limit\n\n",
        compared.len()
    ));
    md.push_str(&limit_markdown(&information_limit(compared)));
    md.push_str(&format!(
        "\n## The goal against the limit\n\nThe online mean |error| of the storeys' \
         stiffnesses and dampings within {:.0} % of the reference posterior's: the paired \
         difference online − reference over (data set, parameter) must lie below the margin \
         with its ±2 s.e. interval (holds), above it (does not hold), or the goal is not \
         resolved.\n\n",
        100.0 * GOAL_MARGIN
    ));
    md.push_str(&goal_markdown(&goal_rows(compared)));
}
