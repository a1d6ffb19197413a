//! The information limit of a linear record: the answer the record itself supports best and how
//! closely it can pin θ down, computed exactly, beside what the online filters reach on it.
//!
//! For a building without hysteretic storeys the filters' model is linear given θ, so with θ
//! fixed the MPF-EKF2 samples nothing and its log-likelihood is the Kalman filter's, exact and
//! smooth in θ (`crate::likelihood::LikelihoodModel::is_exact`). Its maximum, the
//! maximum-likelihood θ̂, is found by Newton's ascent from the truth (or a given start) with
//! central-difference derivatives ([`core_filters::laplace`]), and `(−H)⁻¹` at θ̂ gives each
//! parameter's standard deviation: the Cramér–Rao bound of an unbiased answer, which is also the
//! width of the posterior when the prior is wide against the data. θ̂'s error against the truth
//! is the error the record allows; an online filter whose error is far above it loses
//! information the record holds, one near it does not.
//!
//! Hysteretic records are refused: their likelihood is a particle estimate, not smooth in θ;
//! their reference posterior is `sysid reference` (particle marginal Metropolis–Hastings).

use std::fmt::Write as _;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{bail, Context, Result};
use crate::likelihood::{Candidate, LikelihoodModel, ScoredData};
use crate::reference::comparison::{
    goal_markdown, goal_rows, information_limit as limit_rows, limit_markdown, record_data_sha,
    DataSetRuns,
};
use crate::reference::ParamSummary;
use crate::verdict::in_group;
use core_filters::laplace::{maximise, NewtonOptions};
use identify::record::{RunRecord, Versions};

/// Default central-difference step, relative to each parameter's start value.
pub const REL_STEP: f64 = 1e-3;

/// Largest move of a parameter in one step of the ascent, relative to its value.
pub(crate) const MAX_REL_STEP: f64 = 0.2;

/// The information limit of one data set (`sysid information` writes it as JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InformationLimit {
    /// The data set, as named on the command line.
    pub data: String,
    /// Its identity (`record::fingerprint::data_identity`'s digest): run records of these data
    /// carry the same one.
    pub data_sha256: String,
    pub names: Vec<String>,
    /// The true θ (simulated data).
    pub truth: Option<Vec<f64>>,
    /// Where Newton's ascent started: `truth` or a run record's path.
    pub start: String,
    /// The maximum-likelihood θ̂.
    pub mle: Vec<f64>,
    /// Cramér–Rao standard deviation of each parameter: √diag((−H)⁻¹) at θ̂.
    pub sd: Vec<f64>,
    /// log p(y | θ) at the start and at θ̂.
    pub loglik_start: f64,
    pub loglik_mle: f64,
    /// Central-difference step relative to the start's values.
    pub rel_step: f64,
    pub newton_steps: usize,
    /// Kalman-filter runs asked for.
    pub evaluations: usize,
    /// Wall time of the computation (s).
    pub seconds: f64,
    pub versions: Versions,
}

impl InformationLimit {
    /// The limit as a reference posterior's summary: mean θ̂, s.d. the Cramér–Rao one, the
    /// Gaussian quantiles; so the comparisons of `sysid compare-reference` apply to it.
    pub fn summaries(&self) -> Vec<ParamSummary> {
        const Z: [f64; 5] = [
            -1.959_963_984_540_054,
            -0.674_489_750_196_081_7,
            0.0,
            0.674_489_750_196_081_7,
            1.959_963_984_540_054,
        ];
        (0..self.names.len())
            .map(|j| ParamSummary {
                name: self.names[j].clone(),
                mean: self.mle[j],
                sd: self.sd[j],
                quantiles: Z.map(|z| self.mle[j] + z * self.sd[j]),
                // Exact, not sampled.
                ess: f64::INFINITY,
                truth: self.truth.as_ref().map(|t| t[j]),
            })
            .collect()
    }

    /// Reads a limit written by `sysid information --out`, with one entry per parameter in each
    /// of its lists (a limit file cut or edited into another shape is refused by file, line and
    /// field, not indexed past its end).
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let text = identify::limits::read_text_file(path, "information limit")?;
        let limit: Self = serde_json::from_str(&text)
            .with_context(|| format!("{}: not an information limit", path.display()))?;
        limit.check_shape(path, &text)?;
        Ok(limit)
    }

    /// `mle`, `sd` and `truth` hold one value per parameter of `names`, of which there is one
    /// at least.
    fn check_shape(&self, path: &std::path::Path, text: &str) -> Result<()> {
        // 1-based line of the first `"field"` in the file (1 when absent).
        let line = |field: &str| {
            text.find(&format!("\"{field}\""))
                .map_or(1, |at| text[..at].matches('\n').count() + 1)
        };
        let n = self.names.len();
        if n == 0 {
            bail!(
                "{}:{}: field `names`: no parameter",
                path.display(),
                line("names")
            );
        }
        let lists = [
            ("mle", Some(self.mle.len())),
            ("sd", Some(self.sd.len())),
            ("truth", self.truth.as_ref().map(Vec::len)),
        ];
        for (field, len) in lists {
            if let Some(len) = len.filter(|&len| len != n) {
                bail!(
                    "{}:{}: field `{field}`: {len} entries, {n} expected (one per parameter of \
                     `names`)",
                    path.display(),
                    line(field)
                );
            }
        }
        Ok(())
    }

    /// θ̂'s error relative to the truth, per parameter (None without a truth).
    pub(crate) fn mle_error(&self) -> Option<Vec<f64>> {
        let t = self.truth.as_ref()?;
        Some(self.mle.iter().zip(t).map(|(m, t)| m / t - 1.0).collect())
    }
}

/// Computes the information limit of the data of `on` (a linear building), starting Newton's
/// ascent at `start` (the truth when `None`; a data set without one needs a start).
/// `progress` hears one line per stencil.
pub fn information_limit(
    on: &ScoredData<'_>,
    start: Option<&Candidate>,
    rel_step: f64,
    progress: &mut dyn FnMut(&str),
) -> Result<InformationLimit> {
    if !(rel_step.is_finite() && rel_step > 0.0 && rel_step < 0.1) {
        bail!("--step: the relative step must be in (0, 0.1), got {rel_step}");
    }
    let clock = std::time::Instant::now();
    let model = LikelihoodModel::settle(on)?;
    if !model.is_exact()? {
        bail!(
            "{}: the building has hysteretic storeys, so its likelihood is a particle estimate, \
             not smooth in θ: the information limit needs a linear building (the reference \
             posterior of hysteretic data is `sysid reference`)",
            on.name
        );
    }
    let truth = on.data.meta.as_ref().map(|m| m.theta_true.clone());
    let start = match (start, &truth) {
        (Some(c), _) => c.clone(),
        (None, Some(t)) => Candidate {
            label: "truth".into(),
            names: model.names.clone(),
            theta: t.clone(),
        },
        (None, None) => bail!(
            "{}: no dataset.json, so no true θ to start from: give --start with a run record",
            on.name
        ),
    };
    model.check(&start)?;
    if let Some(i) = start.theta.iter().position(|v| *v == 0.0) {
        bail!(
            "{}: {} is 0 at the start, so a relative step cannot be taken",
            start.label,
            start.names[i]
        );
    }
    let h: Vec<f64> = start.theta.iter().map(|v| rel_step * v.abs()).collect();
    let names = model.names.clone();
    let eval = |pts: &[Vec<f64>]| -> Result<Vec<f64>> {
        progress(&match pts.len() {
            1 => format!("{}: a trial step", on.name),
            n => format!("{}: a stencil of {n} Kalman-filter runs", on.name),
        });
        pts.par_iter()
            .map(|theta| {
                let c = Candidate {
                    label: "θ".into(),
                    names: names.clone(),
                    theta: theta.clone(),
                };
                // Nothing is sampled: one particle is the exact filter (seed irrelevant).
                model.loglik(&c, 1, 1, &|| false)
            })
            .collect()
    };
    // Stiffnesses and dampings are positive: no step moves one by more than a fifth of itself
    // (far from the mode the start's curvature can point a long way out of the support).
    let opts = NewtonOptions {
        max_rel_step: Some(MAX_REL_STEP),
        ..NewtonOptions::default()
    };
    let l = maximise(&start.theta, &h, opts, eval)
        .with_context(|| format!("{}: the maximum of the likelihood", on.name))?;
    let data_sha256 = identify::record::fingerprint::data_identity(on.data)["sha256"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    Ok(InformationLimit {
        data: on.name.to_string(),
        data_sha256,
        names: model.names.clone(),
        truth,
        start: start.label.clone(),
        sd: l.sd(),
        mle: l.mode,
        loglik_start: l.value_at_start,
        loglik_mle: l.value,
        rel_step,
        newton_steps: l.steps,
        evaluations: l.evaluations,
        seconds: clock.elapsed().as_secs_f64(),
        versions: Versions::current(),
    })
}

/// One run record's answer on the data of a limit: the relative error of θ_val per parameter
/// and whether its 95 % interval holds the truth (None where the record has none).
struct Answer {
    error: Vec<f64>,
    covers: Vec<Option<bool>>,
}

/// Whether run record `r` was identified on the data set of `limit` (its fingerprint names the
/// same data identity).
pub(crate) fn on_data(r: &RunRecord, limit: &InformationLimit) -> bool {
    record_data_sha(r) == Some(limit.data_sha256.as_str())
}

fn mean(x: &[f64]) -> f64 {
    identify::metrics::mean_sd(x).0
}

fn answer(limit: &InformationLimit, truth: &[f64], r: &RunRecord) -> Result<Answer> {
    if r.param_names != limit.names {
        bail!(
            "run {} of {}: its parameters are not those of {}",
            r.run,
            r.algorithm,
            limit.data
        );
    }
    if !on_data(r, limit) {
        bail!(
            "run {} of {} was not identified on {} (another data set, or a record without a \
             fingerprint)",
            r.run,
            r.algorithm,
            limit.data
        );
    }
    let error = r
        .theta_val
        .iter()
        .zip(truth)
        .map(|(v, t)| v / t - 1.0)
        .collect();
    let covers = (0..truth.len())
        .map(|j| {
            let ci = r
                .credible
                .iter()
                .find(|p| p.parameter == limit.names[j])
                .and_then(|p| p.at(0.95))?;
            Some(ci.lo <= truth[j] && truth[j] <= ci.hi)
        })
        .collect();
    Ok(Answer { error, covers })
}

/// The limit of one data set as a table, one row per parameter: the truth, θ̂, θ̂'s error, the
/// Cramér–Rao s.d., and for each record its θ_val's error and whether its 95 % interval holds
/// the truth.
pub fn table(limit: &InformationLimit, records: &[RunRecord]) -> Result<String> {
    let mut o = String::new();
    let Some(truth) = &limit.truth else {
        writeln!(o, "| parameter | θ̂ | s.d. |")?;
        writeln!(o, "|---|---:|---:|")?;
        for (j, n) in limit.names.iter().enumerate() {
            writeln!(o, "| {n} | {:.6} | {:.6} |", limit.mle[j], limit.sd[j])?;
        }
        return Ok(o);
    };
    let answers = records
        .iter()
        .map(|r| answer(limit, truth, r))
        .collect::<Result<Vec<_>>>()?;
    let err = limit.mle_error().unwrap_or_default();
    write!(o, "| parameter | truth | θ̂ | θ̂ error | s.d. |")?;
    for r in records {
        write!(o, " {} run {} error | covers |", r.algorithm, r.run)?;
    }
    writeln!(o)?;
    writeln!(
        o,
        "|---|---:|---:|---:|---:|{}",
        "---:|---|".repeat(records.len())
    )?;
    for (j, n) in limit.names.iter().enumerate() {
        write!(
            o,
            "| {n} | {:.6} | {:.6} | {:+.2} % | {:.2} % |",
            truth[j],
            limit.mle[j],
            100.0 * err[j],
            100.0 * limit.sd[j] / truth[j].abs()
        )?;
        for a in &answers {
            let covers = match a.covers[j] {
                Some(true) => "yes",
                Some(false) => "**no**",
                None => "–",
            };
            write!(o, " {:+.2} % | {covers} |", 100.0 * a.error[j])?;
        }
        writeln!(o)?;
    }
    let gain = limit.loglik_mle - limit.loglik_start;
    let chi2 = identify::residuals::chi2_95(limit.names.len());
    writeln!(
        o,
        "\nθ̂ lies {gain:.2} nats above the start ({}; {} Newton steps, {} Kalman-filter runs, \
         {:.0} s).",
        limit.start, limit.newton_steps, limit.evaluations, limit.seconds,
    )?;
    if limit.start == "truth" {
        // The likelihood-ratio test of the model at the truth: 2 × gain ~ χ²_p when the filters'
        // model is the one that made the data.
        let outside = 2.0 * gain > chi2;
        writeln!(
            o,
            "The truth lies {} the record's 95 % likelihood region under this model (2 × {gain:.2} \
             = {:.1} against χ²_{}(0.95) = {chi2:.1}, a test at the 5 % level){}",
            if outside { "OUTSIDE" } else { "inside" },
            2.0 * gain,
            limit.names.len(),
            if outside {
                ": a sign that the model differs from what made the data (e.g. by its \
                 discretisation), and θ̂'s error then includes that difference."
            } else {
                "."
            }
        )?;
    }
    Ok(o)
}

/// Several data sets' limits beside the online filters' answers on them, one row per data set
/// and a mean: θ̂'s and each algorithm's mean |error| of the stiffnesses and of the dampings,
/// the mean Cramér–Rao s.d.s, and the fraction of the records' 95 % intervals of k and c that
/// hold the truth. Records are matched to limits by the data set's identity; every record must
/// belong to one of the limits.
pub fn summary(limits: &[InformationLimit], records: &[RunRecord]) -> Result<String> {
    let mut algorithms: Vec<String> = records.iter().map(|r| r.algorithm.clone()).collect();
    algorithms.sort();
    algorithms.dedup();
    let mut used = vec![false; records.len()];
    let mut o = String::new();
    summary_header(&mut o, &algorithms)?;
    // Per column: the values of every data set, for the mean row.
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); 4 + 2 * algorithms.len()];
    let mut covered = vec![(0usize, 0usize); algorithms.len()];
    for l in limits {
        let (row, values, counts) = data_set_row(l, &algorithms, records, &mut used)?;
        o.push_str(&row);
        for (c, v) in values.into_iter().enumerate() {
            cols[c].push(v);
        }
        for (ai, (cov, pairs)) in counts.into_iter().enumerate() {
            covered[ai].0 += cov;
            covered[ai].1 += pairs;
        }
    }
    if let Some(i) = used.iter().position(|u| !u) {
        let r = &records[i];
        if !r.is_failure() {
            bail!(
                "run {} of {} belongs to none of the data sets summarised",
                r.run,
                r.algorithm
            );
        }
    }
    mean_row(&mut o, limits.len(), &cols, &covered)?;
    let failed = records.iter().filter(|r| r.is_failure()).count();
    if failed > 0 {
        writeln!(o, "\n{failed} failed runs left out.")?;
    }
    per_parameter_comparison(&mut o, limits, records)?;
    Ok(o)
}

/// The summary table's header: θ̂'s four columns, then three per algorithm.
fn summary_header(o: &mut String, algorithms: &[String]) -> Result<()> {
    write!(
        o,
        "| data set | θ̂ \\|k error\\| | θ̂ \\|c error\\| | s.d. of k | s.d. of c |"
    )?;
    for a in algorithms {
        write!(o, " {a} \\|k\\| | {a} \\|c\\| | {a} k, c covered |")?;
    }
    writeln!(o)?;
    writeln!(
        o,
        "|---|---:|---:|---:|---:|{}",
        "---:|---:|---:|".repeat(algorithms.len())
    )?;
    Ok(())
}

/// The mean |value| of the parameters of `limit` in group `kind` ('k' or 'c'), from one value
/// per parameter.
fn group_mean(limit: &InformationLimit, kind: char, xs: &[f64]) -> f64 {
    let v: Vec<f64> = limit
        .names
        .iter()
        .zip(xs)
        .filter(|(n, _)| in_group(n, kind))
        .map(|(_, x)| x.abs())
        .collect();
    mean(&v)
}

/// A row of [`summary`]: its text, its value in each column, and per algorithm how many of its
/// intervals hold the truth out of how many.
type SummaryRow = (String, Vec<f64>, Vec<(usize, usize)>);

/// One data set's row of the summary: its text, its value in each column (θ̂'s errors and
/// relative s.d.s, then each algorithm's k and c errors) and, per algorithm, how many of its
/// 95 % intervals of k and c hold the truth out of how many. Marks in `used` the records on
/// this data set. An error when the data set has no truth.
fn data_set_row(
    l: &InformationLimit,
    algorithms: &[String],
    records: &[RunRecord],
    used: &mut [bool],
) -> Result<SummaryRow> {
    let Some(truth) = &l.truth else {
        bail!("{}: no truth, so no error to summarise", l.data);
    };
    let err = l.mle_error().unwrap_or_default();
    let rel_sd: Vec<f64> = l.sd.iter().zip(truth).map(|(s, t)| s / t.abs()).collect();
    let mut values = vec![
        group_mean(l, 'k', &err),
        group_mean(l, 'c', &err),
        group_mean(l, 'k', &rel_sd),
        group_mean(l, 'c', &rel_sd),
    ];
    let mut o = String::new();
    write!(o, "| {} |", l.data)?;
    for v in &values {
        write!(o, " {:.2} % |", 100.0 * v)?;
    }
    let mut counts = Vec::new();
    for a in algorithms {
        let (k, c, cov, pairs) = algorithm_on_data(l, truth, a, records, used)?;
        values.push(k);
        values.push(c);
        counts.push((cov, pairs));
        write!(
            o,
            " {:.2} % | {:.2} % | {cov}/{pairs} |",
            100.0 * k,
            100.0 * c
        )?;
    }
    writeln!(o)?;
    Ok((o, values, counts))
}

/// What algorithm `a`'s successful runs on the data set of `l` answer: their mean k and c
/// errors, and how many of their 95 % intervals of k and c hold the truth out of how many.
/// Marks those records in `used`.
fn algorithm_on_data(
    l: &InformationLimit,
    truth: &[f64],
    a: &str,
    records: &[RunRecord],
    used: &mut [bool],
) -> Result<(f64, f64, usize, usize)> {
    let mut errs = (Vec::new(), Vec::new());
    let (mut cov, mut pairs) = (0usize, 0usize);
    for (ri, r) in records.iter().enumerate() {
        if r.algorithm != a || r.is_failure() {
            continue;
        }
        if !on_data(r, l) {
            continue;
        }
        used[ri] = true;
        let ans = answer(l, truth, r)?;
        errs.0.push(group_mean(l, 'k', &ans.error));
        errs.1.push(group_mean(l, 'c', &ans.error));
        for (j, c) in ans.covers.iter().enumerate() {
            if let (Some(c), true) = (c, in_group(&l.names[j], 'k') || in_group(&l.names[j], 'c')) {
                pairs += 1;
                cov += usize::from(*c);
            }
        }
    }
    Ok((mean(&errs.0), mean(&errs.1), cov, pairs))
}

/// The row of means over the data sets, with each algorithm's share of intervals that hold
/// the truth.
fn mean_row(
    o: &mut String,
    data_sets: usize,
    cols: &[Vec<f64>],
    covered: &[(usize, usize)],
) -> Result<()> {
    write!(o, "| mean of {} |", data_sets)?;
    for c in &cols[..4] {
        write!(o, " {:.2} % |", 100.0 * mean(c))?;
    }
    for (ai, &(cov, pairs)) in covered.iter().enumerate() {
        write!(
            o,
            " {:.2} % | {:.2} % | {cov}/{pairs} = {:.3} |",
            100.0 * mean(&cols[4 + 2 * ai]),
            100.0 * mean(&cols[5 + 2 * ai]),
            cov as f64 / pairs as f64
        )?;
    }
    writeln!(o)?;
    Ok(())
}

/// The online answers against the limit, per parameter, and the goal "within 10 % of the
/// limit's error" decided from them.
fn per_parameter_comparison(
    o: &mut String,
    limits: &[InformationLimit],
    records: &[RunRecord],
) -> Result<()> {
    let groups: Vec<DataSetRuns> = limits
        .iter()
        .map(|l| {
            let mine = records.iter().filter(|r| on_data(r, l)).cloned().collect();
            (l.summaries(), mine)
        })
        .collect();
    writeln!(
        o,
        "\nAgainst the limit, per parameter (the limit's s.d. is the Cramér–Rao one; its \
         \"intervals\" are θ̂ ± 1.96 s.d.):\n\n{}",
        limit_markdown(&limit_rows(&groups))
    )?;
    writeln!(
        o,
        "The goal \"online mean |error| within 10 % of the limit's\", paired over (data set, \
         parameter), decided by the difference's ±2 s.e. interval against the margin:\n\n{}",
        goal_markdown(&goal_rows(&groups))
    )?;
    Ok(())
}

/// [`summary`] of several limits and the run records on their data, then each limit's
/// [`table`] with its own records.
pub fn report(limits: &[InformationLimit], records: &[RunRecord]) -> Result<String> {
    let mut text = summary(limits, records)?;
    for l in limits {
        let mine: Vec<RunRecord> = records.iter().filter(|r| on_data(r, l)).cloned().collect();
        write!(text, "\n### {}\n\n{}", l.data, table(l, &mine)?)?;
    }
    Ok(text)
}
