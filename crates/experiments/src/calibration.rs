//! Calibration of the posterior over a sweep with known truth (SPEC §9 "Calibration").
//!
//! A user reads a posterior as "the truth is probably in here"; over many runs with a known
//! truth we can check whether it is. Per algorithm and parameter:
//!
//! - **coverage** at each nominal level q: the fraction of runs whose central q-credible interval
//!   contains θ_true (intervals from [`core_filters::credible`]), with its binomial standard
//!   error, and a verdict — see [`LevelCoverage`] for the test;
//! - **z-scores** `z = (θ_val − θ_true) / s.d.` ([`ZSummary`]): a calibrated Gaussian posterior
//!   gives z ≈ N(0, 1), so mean ≈ 0, s.d. ≈ 1 and |z| > 2 in about 5 % of runs;
//! - **spread** ([`SpreadSummary`]): the mean posterior s.d. against the run-to-run s.d. of the
//!   error θ_val − θ_true (with a fixed truth, the s.d. of θ_val over runs). A ratio below 1
//!   means the posterior is narrower than the Monte-Carlo and data scatter of its own estimate.
//!
//! The results serialise for `summary.json` (undefined numbers are `null`, never NaN);
//! [`markdown`] writes the report's table and [`coverage_figure`] the figure of coverage against
//! nominal level. Nothing here reads records: the caller extracts one [`RunPosterior`] per run
//! and parameter, leaving out failed runs (and counting them itself).

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{bail, Result};
use core_filters::credible::{CredibleInterval, WeightedSample};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::markdown::{header, row};

/// Runs below which no verdict is given: with fewer than 10 runs the normal approximation to the
/// binomial behind the test is poor and, at q = 0.5, not even 0 of n covered would be flagged.
pub(crate) const MIN_RUNS_FOR_VERDICT: usize = 10;

/// Width of the calibration test in nominal standard errors (two-sided, ≈ 5 % false alarms
/// per level under the normal approximation).
pub(crate) const VERDICT_SE: f64 = 2.0;

/// Probabilities at which the z-score distribution is summarised.
pub(crate) const Z_PROBABILITIES: [f64; 5] = [0.05, 0.25, 0.5, 0.75, 0.95];

/// Two interval levels closer than this are the same nominal level.
const LEVEL_MATCH: f64 = 1e-9;

/// One run's posterior of one parameter: the inputs of calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunPosterior {
    /// The true value θ_true.
    pub truth: f64,
    /// The point estimate reported to the user (θ_val, SPEC eq. 26).
    pub estimate: f64,
    /// The posterior s.d. reported with it (SPEC §7).
    pub sd: f64,
    /// Central credible intervals, at least one at every level the calibration asks for.
    pub intervals: Vec<CredibleInterval>,
}

/// Why the calibration of a parameter could not be computed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CalibrationError {
    #[error("no nominal levels were given")]
    NoLevels,
    #[error("nominal level {level} is not in (0, 1)")]
    InvalidLevel { level: f64 },
    #[error("parameter {parameter}, run {run}: {field} = {value} is not finite")]
    NonFinite {
        parameter: String,
        run: usize,
        field: &'static str,
        value: f64,
    },
    #[error("parameter {parameter}, run {run}: the posterior s.d. {value} is negative")]
    NegativeSd {
        parameter: String,
        run: usize,
        value: f64,
    },
    #[error("parameter {parameter}, run {run}: no credible interval at level {level}")]
    MissingLevel {
        parameter: String,
        run: usize,
        level: f64,
    },
    #[error("parameter {parameter}, run {run}: interval at level {level} has lo {lo} > hi {hi}")]
    InvertedInterval {
        parameter: String,
        run: usize,
        level: f64,
        lo: f64,
        hi: f64,
    },
}

crate::error::domain_error!(CalibrationError);

/// Outcome of the calibration test at one level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// |coverage − q| ≤ 2 nominal s.e.
    Consistent,
    /// Coverage below q by more than 2 nominal s.e.: intervals too narrow (or off-centre).
    OverConfident,
    /// Coverage above q by more than 2 nominal s.e.: intervals too wide.
    UnderConfident,
    /// Fewer than `MIN_RUNS_FOR_VERDICT` runs.
    TooFewRuns,
}

impl Verdict {
    /// The words used in reports.
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Consistent => "consistent with nominal",
            Verdict::OverConfident => "over-confident",
            Verdict::UnderConfident => "under-confident",
            Verdict::TooFewRuns => "too few runs",
        }
    }
}

/// Coverage at one nominal level.
///
/// `coverage = covered / runs`. Two standard errors are given: `se = sqrt(c(1 − c)/n)` at the
/// observed coverage c, the one to display beside it, and `se_nominal = sqrt(q(1 − q)/n)` at the
/// nominal level q, the one the test uses (the s.e. under the hypothesis of calibration; it does
/// not vanish when 0 or all of n runs are covered). Verdict: with n ≥ `MIN_RUNS_FOR_VERDICT`,
/// over-confident if `q − c > 2 se_nominal`, under-confident if `c − q > 2 se_nominal`, else
/// consistent with nominal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelCoverage {
    /// Nominal level q.
    pub level: f64,
    /// Runs n.
    pub runs: usize,
    /// Runs whose interval contains θ_true.
    pub covered: usize,
    /// covered / runs (null without runs).
    pub coverage: Option<f64>,
    /// Binomial s.e. at the observed coverage (null without runs).
    pub se: Option<f64>,
    /// Binomial s.e. at the nominal level (null without runs).
    pub se_nominal: Option<f64>,
    pub verdict: Verdict,
}

impl LevelCoverage {
    /// Coverage of `covered` out of `runs` at nominal level `level`.
    pub fn new(level: f64, runs: usize, covered: usize) -> Self {
        let n = runs as f64;
        let coverage = (runs > 0).then(|| covered as f64 / n);
        let se = coverage.map(|c| (c * (1.0 - c) / n).sqrt());
        let se_nominal = (runs > 0).then(|| (level * (1.0 - level) / n).sqrt());
        let verdict = match (coverage, se_nominal) {
            (Some(c), Some(s)) if runs >= MIN_RUNS_FOR_VERDICT => {
                if level - c > VERDICT_SE * s {
                    Verdict::OverConfident
                } else if c - level > VERDICT_SE * s {
                    Verdict::UnderConfident
                } else {
                    Verdict::Consistent
                }
            }
            _ => Verdict::TooFewRuns,
        };
        Self {
            level,
            runs,
            covered,
            coverage,
            se,
            se_nominal,
            verdict,
        }
    }
}

/// One quantile of the z-score distribution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ZQuantile {
    pub p: f64,
    pub z: f64,
}

/// Distribution of `z = (θ_val − θ_true) / s.d.` over runs.
///
/// A run whose posterior s.d. is zero claims certainty: its z is infinite when θ_val ≠ θ_true
/// (counted in `infinite` and as |z| > 2) and undefined when θ_val = θ_true (counted in
/// `undefined` only). Mean, s.d. (n − 1) and quantiles (inverse empirical CDF, as in
/// [`core_filters::credible`]) are over the finite z-scores.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ZSummary {
    /// Runs with a finite z.
    pub finite: usize,
    /// Runs with s.d. 0 and θ_val ≠ θ_true.
    pub infinite: usize,
    /// Runs with s.d. 0 and θ_val = θ_true.
    pub undefined: usize,
    pub mean: Option<f64>,
    pub sd: Option<f64>,
    /// Fraction of runs with |z| > 2 among the finite and infinite ones (≈ 0.046 when
    /// calibrated).
    pub frac_abs_above_2: Option<f64>,
    pub quantiles: Vec<ZQuantile>,
}

/// The posterior's width against the run-to-run scatter of its estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpreadSummary {
    /// Mean over runs of the posterior s.d.
    pub mean_posterior_sd: Option<f64>,
    /// Sample s.d. (n − 1) over runs of θ_val − θ_true; with one θ_true for all runs it is the
    /// run-to-run s.d. of θ_val.
    pub error_sd: Option<f64>,
    /// `mean_posterior_sd / error_sd`: below 1, the posterior is narrower than the scatter of
    /// its own estimate (null with fewer than 2 runs or no scatter).
    pub sd_ratio: Option<f64>,
    /// Root mean square of θ_val − θ_true (scatter and bias together).
    pub rmse: Option<f64>,
}

/// Calibration of one parameter of one algorithm over a sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamCalibration {
    pub parameter: String,
    pub runs: usize,
    pub coverage: Vec<LevelCoverage>,
    pub z: ZSummary,
    pub spread: SpreadSummary,
}

/// Calibration of every parameter of one algorithm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlgorithmCalibration {
    pub algorithm: String,
    pub params: Vec<ParamCalibration>,
}

/// Calibration of a sweep: one entry per algorithm, all at the same nominal levels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepCalibration {
    pub sweep: String,
    pub levels: Vec<f64>,
    pub algorithms: Vec<AlgorithmCalibration>,
}

fn check_levels(levels: &[f64]) -> Result<(), CalibrationError> {
    if levels.is_empty() {
        return Err(CalibrationError::NoLevels);
    }
    match levels.iter().find(|&&q| !(q > 0.0 && q < 1.0)) {
        Some(&level) => Err(CalibrationError::InvalidLevel { level }),
        None => Ok(()),
    }
}

/// Checks one run's inputs and returns its interval at each level, in the order of `levels`.
fn run_intervals<'r>(
    parameter: &str,
    run: usize,
    r: &'r RunPosterior,
    levels: &[f64],
) -> Result<Vec<&'r CredibleInterval>, CalibrationError> {
    let non_finite = |field, value| CalibrationError::NonFinite {
        parameter: parameter.to_string(),
        run,
        field,
        value,
    };
    for (field, value) in [("truth", r.truth), ("estimate", r.estimate), ("sd", r.sd)] {
        if !value.is_finite() {
            return Err(non_finite(field, value));
        }
    }
    if r.sd < 0.0 {
        return Err(CalibrationError::NegativeSd {
            parameter: parameter.to_string(),
            run,
            value: r.sd,
        });
    }
    levels
        .iter()
        .map(|&level| {
            let ci = r
                .intervals
                .iter()
                .find(|ci| (ci.level - level).abs() <= LEVEL_MATCH)
                .ok_or_else(|| CalibrationError::MissingLevel {
                    parameter: parameter.to_string(),
                    run,
                    level,
                })?;
            if !ci.lo.is_finite() {
                return Err(non_finite("interval lo", ci.lo));
            }
            if !ci.hi.is_finite() {
                return Err(non_finite("interval hi", ci.hi));
            }
            if ci.lo > ci.hi {
                return Err(CalibrationError::InvertedInterval {
                    parameter: parameter.to_string(),
                    run,
                    level,
                    lo: ci.lo,
                    hi: ci.hi,
                });
            }
            Ok(ci)
        })
        .collect()
}

/// Mean and sample s.d. (n − 1) of `v`; `None` where undefined.
fn mean_sd(v: &[f64]) -> (Option<f64>, Option<f64>) {
    let n = v.len();
    if n == 0 {
        return (None, None);
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    let sd = (n > 1)
        .then(|| (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1) as f64).sqrt());
    (Some(mean), sd)
}

fn z_summary(runs: &[RunPosterior]) -> ZSummary {
    let (mut finite, mut infinite, mut undefined) = (Vec::new(), 0, 0);
    for r in runs {
        let err = r.estimate - r.truth;
        if r.sd > 0.0 {
            finite.push(err / r.sd);
        } else if err != 0.0 {
            infinite += 1;
        } else {
            undefined += 1;
        }
    }
    let (mean, sd) = mean_sd(&finite);
    let defined = finite.len() + infinite;
    let above = finite.iter().filter(|z| z.abs() > 2.0).count() + infinite;
    let frac_abs_above_2 = (defined > 0).then(|| above as f64 / defined as f64);
    let quantiles = if finite.is_empty() {
        Vec::new()
    } else {
        let ones = vec![1.0; finite.len()];
        // Finite values and unit weights: the sample always builds.
        WeightedSample::new(&finite, &ones)
            .map(|s| {
                Z_PROBABILITIES
                    .iter()
                    .filter_map(|&p| s.quantile(p).ok().map(|z| ZQuantile { p, z }))
                    .collect()
            })
            .unwrap_or_default()
    };
    ZSummary {
        finite: finite.len(),
        infinite,
        undefined,
        mean,
        sd,
        frac_abs_above_2,
        quantiles,
    }
}

fn spread_summary(runs: &[RunPosterior]) -> SpreadSummary {
    let sds: Vec<f64> = runs.iter().map(|r| r.sd).collect();
    let errors: Vec<f64> = runs.iter().map(|r| r.estimate - r.truth).collect();
    let (mean_posterior_sd, _) = mean_sd(&sds);
    let (_, error_sd) = mean_sd(&errors);
    let sd_ratio = match (mean_posterior_sd, error_sd) {
        (Some(m), Some(s)) if s > 0.0 => Some(m / s),
        _ => None,
    };
    let rmse = (!errors.is_empty())
        .then(|| (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt());
    SpreadSummary {
        mean_posterior_sd,
        error_sd,
        sd_ratio,
        rmse,
    }
}

/// Calibration of one parameter over `runs` at the nominal `levels` (e.g.
/// [`core_filters::credible::STANDARD_LEVELS`]). Every run must carry an interval at every
/// level; non-finite inputs are errors naming the parameter, the run (its index in `runs`) and
/// the field.
pub fn calibrate_parameter(
    parameter: &str,
    runs: &[RunPosterior],
    levels: &[f64],
) -> Result<ParamCalibration, CalibrationError> {
    check_levels(levels)?;
    let mut covered = vec![0usize; levels.len()];
    for (i, r) in runs.iter().enumerate() {
        for (c, ci) in covered
            .iter_mut()
            .zip(run_intervals(parameter, i, r, levels)?)
        {
            if ci.contains(r.truth) {
                *c += 1;
            }
        }
    }
    Ok(ParamCalibration {
        parameter: parameter.to_string(),
        runs: runs.len(),
        coverage: levels
            .iter()
            .zip(&covered)
            .map(|(&q, &c)| LevelCoverage::new(q, runs.len(), c))
            .collect(),
        z: z_summary(runs),
        spread: spread_summary(runs),
    })
}

/// Calibration of every parameter of one algorithm: `params` holds, per parameter name, its
/// posteriors over the runs.
pub fn calibrate_algorithm(
    algorithm: &str,
    params: &[(&str, Vec<RunPosterior>)],
    levels: &[f64],
) -> Result<AlgorithmCalibration, CalibrationError> {
    Ok(AlgorithmCalibration {
        algorithm: algorithm.to_string(),
        params: params
            .iter()
            .map(|(name, runs)| calibrate_parameter(name, runs, levels))
            .collect::<Result<_, _>>()?,
    })
}

// ---------------------------------------------------------------------------------------------
// Markdown
// ---------------------------------------------------------------------------------------------

fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(|| "–".to_string(), |x| format!("{x:.decimals$}"))
}

/// `0.95` → "95 %", `0.975` → "97.5 %".
fn percent(level: f64) -> String {
    let s = format!("{:.1}", 100.0 * level);
    format!("{} %", s.strip_suffix(".0").unwrap_or(&s))
}

fn coverage_cell(c: &LevelCoverage) -> String {
    let (Some(cov), Some(se)) = (c.coverage, c.se) else {
        return "–".to_string();
    };
    let mark = match c.verdict {
        Verdict::Consistent => "",
        Verdict::OverConfident => " **over**",
        Verdict::UnderConfident => " *under*",
        Verdict::TooFewRuns => " (n < 10)",
    };
    format!("{cov:.2} ± {se:.2}{mark}")
}

/// The report section of a sweep: a sentence stating the definitions and the test, then one
/// table with a row per algorithm × parameter and columns n, coverage ± s.e. at each nominal
/// level, mean z, s.d. of z, the fraction of |z| > 2 and the s.d. ratio.
pub fn markdown(sweep: &SweepCalibration) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "Coverage of sweep `{}`: the fraction of n runs whose central credible interval contains \
         θ_true, ± its binomial s.e. √(c(1 − c)/n) at the observed coverage c. **over** \
         (over-confident) / *under* (under-confident): c below / above the nominal q by more than \
         {VERDICT_SE} √(q(1 − q)/n); no verdict with n < {MIN_RUNS_FOR_VERDICT}. \
         z = (θ_val − θ_true)/s.d. (mean and s.d. over finite z; ∞: runs with s.d. 0); a \
         calibrated posterior has mean z ≈ 0, s.d. z ≈ 1, |z| > 2 in ≈ 5 % of runs. s.d. ratio = \
         mean posterior s.d. / run-to-run s.d. of θ_val − θ_true (below 1: narrower than the \
         scatter of its own estimate).\n",
        sweep.sweep
    );
    let mut head = vec!["algorithm".to_string(), "parameter".into(), "n".into()];
    head.extend(sweep.levels.iter().map(|&q| percent(q)));
    head.extend(
        // A pipe inside a cell must be escaped in a Markdown table.
        ["mean z", "s.d. z", r"\|z\| > 2", "s.d. ratio"]
            .iter()
            .map(|s| s.to_string()),
    );
    header(&mut o, &head);
    for a in &sweep.algorithms {
        for p in &a.params {
            let mut cells = vec![a.algorithm.clone(), p.parameter.clone(), p.runs.to_string()];
            for &q in &sweep.levels {
                cells.push(
                    p.coverage
                        .iter()
                        .find(|c| (c.level - q).abs() <= LEVEL_MATCH)
                        .map_or_else(|| "–".to_string(), coverage_cell),
                );
            }
            let mut mean_z = opt(p.z.mean, 2);
            if p.z.infinite > 0 {
                let _ = write!(mean_z, " (+{} ∞)", p.z.infinite);
            }
            cells.push(mean_z);
            cells.push(opt(p.z.sd, 2));
            cells.push(opt(p.z.frac_abs_above_2, 2));
            cells.push(opt(p.spread.sd_ratio, 2));
            row(&mut o, &cells);
        }
    }
    o
}

// ---------------------------------------------------------------------------------------------
// Figure
// ---------------------------------------------------------------------------------------------

// Fonts, sizes and palette of every figure of the project.
use identify::figures::{
    draw_mesh, grid_dims, marker, open_figure, present, style, CAPTION_SIZE, DESC_SIZE, FONT,
};

const LEGEND_ROW: i32 = 34;

/// A chart of one panel of the coverage figure: nominal level against coverage, both in [0, 1].
type CoverageChart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Coverage figure of a sweep: one panel per parameter, coverage (y) against nominal level (x),
/// one colour and marker per algorithm with ± 2 s.e. bars (s.e. at the observed coverage), the
/// diagonal of perfect calibration dashed, and a grey band where the test of [`LevelCoverage`]
/// calls coverage consistent with nominal (drawn for the smallest n of the panel, so the widest
/// band). Parameters are those of the first algorithm, in its order.
pub fn coverage_figure(sweep: &SweepCalibration, path: &Path, title: &str) -> Result<()> {
    let Some(first) = sweep.algorithms.first() else {
        bail!("coverage figure {}: no algorithms to draw", path.display());
    };
    let names: Vec<&str> = first.params.iter().map(|p| p.parameter.as_str()).collect();
    if names.is_empty() {
        bail!("coverage figure {}: no parameters to draw", path.display());
    }
    let g = sweep.algorithms.len();
    let legend_rows = (g + 2).div_ceil(2) as i32;
    let legend_h = (legend_rows * LEGEND_ROW + 16) as u32;
    let (rows, cols) = grid_dims(names.len());
    let height = 60 + legend_h + 330 * rows as u32;
    let (root, grid, legend) = open_figure(path, height, title, legend_h)?;
    let panels = grid.split_evenly((rows, cols));
    for (name, area) in names.iter().zip(&panels) {
        coverage_panel(sweep, name, area, &root)?;
    }
    coverage_legend(sweep, &legend)?;
    present(&root, path)
}

/// Where algorithm `i` of `g` is drawn beside a nominal level: the algorithms side by side
/// around it, so that their bars do not hide one another.
fn level_offset(i: usize, g: usize) -> f64 {
    (i as f64 - (g as f64 - 1.0) / 2.0) * 0.012
}

/// The panel of one parameter: axes, the band of coverage consistent with nominal, the
/// diagonal, and each algorithm's coverage with its bars (markers drawn on `root`).
fn coverage_panel(
    sweep: &SweepCalibration,
    name: &str,
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
) -> Result<()> {
    let per_alg: Vec<Option<&ParamCalibration>> = sweep
        .algorithms
        .iter()
        .map(|a| a.params.iter().find(|p| p.parameter == name))
        .collect();
    let mut chart = ChartBuilder::on(area)
        .caption(name, (FONT, CAPTION_SIZE))
        .margin(10)
        .x_label_area_size(48)
        .y_label_area_size(62)
        .build_cartesian_2d(0.0..1.0, 0.0..1.0)?;
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("nominal level")
            .y_desc("coverage")
            .x_labels(6)
            .y_labels(6)
            .x_label_formatter(&|v| format!("{v:.1}"))
            .y_label_formatter(&|v| format!("{v:.1}")),
    )?;
    let n_min = per_alg
        .iter()
        .flatten()
        .map(|p| p.runs)
        .filter(|&n| n > 0)
        .min();
    if let Some(n) = n_min {
        consistency_band(&mut chart, n)?;
    }
    chart.draw_series(DashedLineSeries::new(
        vec![(0.0, 0.0), (1.0, 1.0)],
        10,
        6,
        BLACK.stroke_width(2),
    ))?;
    for (i, p) in per_alg.iter().enumerate() {
        let Some(p) = p else { continue };
        algorithm_coverage(sweep, i, p, &mut chart, root)?;
    }
    Ok(())
}

/// The grey band of coverages the test of [`LevelCoverage`] calls consistent with nominal,
/// for `n` runs: nominal ± [`VERDICT_SE`] s.e., clipped to [0, 1].
fn consistency_band(chart: &mut CoverageChart<'_, '_>, n: usize) -> Result<()> {
    let half = |q: f64| VERDICT_SE * (q * (1.0 - q) / n as f64).sqrt();
    let qs: Vec<f64> = (1..100).map(|k| k as f64 / 100.0).collect();
    let upper = qs.iter().map(|&q| (q, (q + half(q)).min(1.0)));
    let lower = qs.iter().rev().map(|&q| (q, (q - half(q)).max(0.0)));
    chart.draw_series(std::iter::once(Polygon::new(
        upper.chain(lower).collect::<Vec<_>>(),
        BLACK.mix(0.10).filled(),
    )))?;
    Ok(())
}

/// Algorithm `i`'s coverage at each level of one parameter: a line, ± 2 s.e. bars and a
/// marker per level (drawn on `root`, in pixels).
fn algorithm_coverage(
    sweep: &SweepCalibration,
    i: usize,
    p: &ParamCalibration,
    chart: &mut CoverageChart<'_, '_>,
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
) -> Result<()> {
    let g = sweep.algorithms.len();
    let st = style::for_label(sweep.algorithms[i].algorithm.as_str(), i);
    let c = st.colour;
    let points: Vec<(f64, f64, f64)> = p
        .coverage
        .iter()
        .filter_map(|lc| Some((lc.level + level_offset(i, g), lc.coverage?, lc.se?)))
        .collect();
    chart.draw_series(LineSeries::new(
        points.iter().map(|&(x, y, _)| (x, y)),
        c.stroke_width(2),
    ))?;
    for &(x, y, se) in &points {
        let (lo, hi) = ((y - 2.0 * se).max(0.0), (y + 2.0 * se).min(1.0));
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(x, lo), (x, hi)],
            c.stroke_width(2),
        )))?;
        let px = chart.backend_coord(&(x, y));
        root.draw(&marker(st, px))?;
    }
    Ok(())
}

/// The legend's entries: each algorithm (by its index), then the diagonal and the band, whose
/// words say the number of runs it was drawn for.
fn legend_entries(sweep: &SweepCalibration) -> Vec<(Option<usize>, String)> {
    let ns = || {
        sweep
            .algorithms
            .iter()
            .flat_map(|a| &a.params)
            .map(|p| p.runs)
            .filter(|&n| n > 0)
    };
    let (n_min, n_max) = (ns().min(), ns().max());
    let mut entries: Vec<(Option<usize>, String)> = sweep
        .algorithms
        .iter()
        .enumerate()
        .map(|(i, a)| {
            (
                Some(i),
                format!("{}: coverage ± 2 s.e.", a.algorithm.as_str()),
            )
        })
        .collect();
    entries.push((None, "perfect calibration".to_string()));
    entries.push((
        None,
        match (n_min, n_max) {
            (Some(lo), Some(hi)) if lo == hi => {
                format!("grey: nominal ± {VERDICT_SE} s.e. (n = {lo})")
            }
            (Some(lo), _) => {
                format!("grey: nominal ± {VERDICT_SE} s.e. at each panel's smallest n (≥ {lo})")
            }
            _ => "grey: no runs".to_string(),
        },
    ));
    entries
}

/// Legend: algorithms, then the diagonal and the band, two per row.
fn coverage_legend(
    sweep: &SweepCalibration,
    legend: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
) -> Result<()> {
    let entries = legend_entries(sweep);
    let (w, _) = legend.dim_in_pixel();
    let slot = (w as i32 - 40) / 2;
    let text =
        TextStyle::from((FONT, DESC_SIZE).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for (k, (alg, label)) in entries.iter().enumerate() {
        let x = 20 + (k % 2) as i32 * slot;
        let y = 8 + (k / 2) as i32 * LEGEND_ROW + LEGEND_ROW / 2;
        match alg {
            Some(i) => {
                let st = style::for_label(sweep.algorithms[*i].algorithm.as_str(), *i);
                let c = st.colour;
                legend.draw(&PathElement::new(
                    vec![(x, y), (x + 40, y)],
                    c.stroke_width(2),
                ))?;
                legend.draw(&marker(st, (x + 20, y)))?;
            }
            None if k == entries.len() - 2 => {
                for dx in [0, 16, 32] {
                    legend.draw(&PathElement::new(
                        vec![(x + dx, y), (x + dx + 9, y)],
                        BLACK.stroke_width(2),
                    ))?;
                }
            }
            None => {
                legend.draw(&Rectangle::new(
                    [(x, y - 8), (x + 40, y + 8)],
                    BLACK.mix(0.10).filled(),
                ))?;
            }
        }
        legend.draw(&Text::new(label.clone(), (x + 48, y), text.clone()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_follow_the_stated_test() {
        // n = 100, q = 0.9: nominal s.e. 0.03, so the band is [0.84, 0.96].
        assert_eq!(
            LevelCoverage::new(0.9, 100, 90).verdict,
            Verdict::Consistent
        );
        assert_eq!(
            LevelCoverage::new(0.9, 100, 85).verdict,
            Verdict::Consistent
        );
        assert_eq!(
            LevelCoverage::new(0.9, 100, 83).verdict,
            Verdict::OverConfident
        );
        assert_eq!(
            LevelCoverage::new(0.9, 100, 97).verdict,
            Verdict::UnderConfident
        );
        assert_eq!(LevelCoverage::new(0.9, 9, 0).verdict, Verdict::TooFewRuns);
        let none = LevelCoverage::new(0.5, 0, 0);
        assert_eq!(
            (none.coverage, none.se, none.verdict),
            (None, None, Verdict::TooFewRuns)
        );
    }

    #[test]
    fn percent_labels() {
        assert_eq!(percent(0.5), "50 %");
        assert_eq!(percent(0.95), "95 %");
        assert_eq!(percent(0.975), "97.5 %");
    }
}
