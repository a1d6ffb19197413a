//! Verdicts on the paper's statements (SPEC §8), each decided by a stated test on the run records.
//!
//! A statement is reduced to an [`Estimate`] — a mean over runs with its standard error — and a
//! threshold or band. With s.e. the standard error, a statement "estimate above t" **holds** when
//! mean − 2 s.e. > t, **does not hold** when mean + 2 s.e. < t, and is **not resolved**
//! otherwise; a band statement holds when the whole ±2 s.e. interval lies inside the band, does
//! not hold when the interval lies entirely outside, and is not resolved when it straddles an
//! edge. Comparisons of two algorithms use the paired difference over the runs both completed
//! (all algorithms of one run index see the same data set), which removes the data-set-to-data-set
//! spread shared by both. A statement over several algorithms or parameters holds when every part
//! holds and does not hold when any part does not hold.

use std::collections::BTreeMap;

use models::filtering::Discretisation;
use serde::Serialize;

use crate::markdown::{cell, header, row};
use identify::metrics::mean_sd;
use identify::record::RunRecord;

pub mod declared;

pub use declared::Declared;

/// The decision on one statement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Verdict {
    Holds,
    DoesNotHold,
    NotResolved,
}

impl Verdict {
    /// The words written in the report.
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Holds => "holds",
            Verdict::DoesNotHold => "does not hold",
            Verdict::NotResolved => "not resolved",
        }
    }

    /// Verdict of "every part": does not hold if any part does not, holds if all hold, otherwise
    /// not resolved. An empty set of parts is not resolved.
    pub fn all(parts: impl IntoIterator<Item = Verdict>) -> Verdict {
        let mut any = false;
        let mut all_hold = true;
        for v in parts {
            any = true;
            match v {
                Verdict::DoesNotHold => return Verdict::DoesNotHold,
                Verdict::NotResolved => all_hold = false,
                Verdict::Holds => {}
            }
        }
        if any && all_hold {
            Verdict::Holds
        } else {
            Verdict::NotResolved
        }
    }
}

/// A mean over runs and its standard error (s.d. / √n; NaN with fewer than two values).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    pub mean: f64,
    pub se: f64,
    pub n: usize,
}

impl Estimate {
    /// Mean and standard error of the finite values.
    pub fn of(values: &[f64]) -> Self {
        let (mean, sd, n) = mean_sd(values);
        let se = if n >= 2 {
            sd / (n as f64).sqrt()
        } else {
            f64::NAN
        };
        Self { mean, se, n }
    }

    /// The ±2 s.e. interval, `None` when the estimate is not usable.
    fn interval(&self) -> Option<(f64, f64)> {
        (self.mean.is_finite() && self.se.is_finite())
            .then_some((self.mean - 2.0 * self.se, self.mean + 2.0 * self.se))
    }

    /// `mean ± se (n = …)` with `scale` applied (e.g. 100 for percent) and `unit` appended.
    pub fn show(&self, scale: f64, decimals: usize, unit: &str) -> String {
        format!(
            "{:.decimals$}{unit} ± {:.decimals$}{unit} (s.e., n = {})",
            scale * self.mean,
            scale * self.se,
            self.n
        )
    }
}

/// Φ⁻¹(p), the standard normal quantile, by bisection on Φ(z) = erfc(−z/√2)/2 (to 1e-12).
pub(crate) fn normal_quantile(p: f64) -> f64 {
    let cdf = |z: f64| 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2);
    let (mut lo, mut hi) = (-40.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// The two-sided critical z of `m` simultaneous comparisons at a family-wise level of 5 %
/// (Bonferroni): Φ⁻¹(1 − 0.025/m); 1.96 for one comparison, 2.50 for four.
pub(crate) fn bonferroni_z(m: usize) -> f64 {
    normal_quantile(1.0 - 0.025 / m.max(1) as f64)
}

/// "The estimate is above `t`" (see the module documentation).
pub fn above(e: &Estimate, t: f64) -> Verdict {
    match e.interval() {
        Some((lo, _)) if lo > t => Verdict::Holds,
        Some((_, hi)) if hi < t => Verdict::DoesNotHold,
        _ => Verdict::NotResolved,
    }
}

/// "The estimate is below `t`".
pub fn below(e: &Estimate, t: f64) -> Verdict {
    match e.interval() {
        Some((_, hi)) if hi < t => Verdict::Holds,
        Some((lo, _)) if lo > t => Verdict::DoesNotHold,
        _ => Verdict::NotResolved,
    }
}

/// "The estimate lies in [lo, hi]".
pub fn within(e: &Estimate, lo: f64, hi: f64) -> Verdict {
    match e.interval() {
        Some((a, b)) if a >= lo && b <= hi => Verdict::Holds,
        Some((a, b)) if b < lo || a > hi => Verdict::DoesNotHold,
        _ => Verdict::NotResolved,
    }
}

/// Per-run values of a metric, keyed by run index, for the runs that completed and give a
/// finite value.
pub(crate) fn per_run(
    records: &[&RunRecord],
    metric: impl Fn(&RunRecord) -> f64,
) -> BTreeMap<u64, f64> {
    records
        .iter()
        .filter(|r| !r.is_failure())
        .map(|r| (r.run, metric(r)))
        .filter(|(_, v)| v.is_finite())
        .collect()
}

/// Paired difference a − b over the run indices present in both.
pub(crate) fn paired_difference(a: &BTreeMap<u64, f64>, b: &BTreeMap<u64, f64>) -> Estimate {
    let d: Vec<f64> = a
        .iter()
        .filter_map(|(run, va)| b.get(run).map(|vb| va - vb))
        .collect();
    Estimate::of(&d)
}

pub use identify::metrics::in_group;

/// Mean relative error of one run over a group of parameters (`k` stiffnesses, `c` dampings);
/// `None` without truth or without such parameters.
pub(crate) fn group_mean_error(r: &RunRecord, prefix: char) -> Option<f64> {
    let v: Vec<f64> = r
        .param_names
        .iter()
        .zip(r.rel_error.as_ref()?)
        .filter(|(n, _)| in_group(n, prefix))
        .map(|(_, e)| *e)
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// [`group_mean_error`], NaN where it has none.
pub(crate) fn group_error(r: &RunRecord, prefix: char) -> f64 {
    group_mean_error(r, prefix).unwrap_or(f64::NAN)
}

/// θ_val / θ_true of the parameter `name` in one run (NaN when absent).
pub fn ratio(r: &RunRecord, name: &str) -> f64 {
    let j = r.param_names.iter().position(|n| n == name);
    match (j, &r.theta_true) {
        (Some(j), Some(t)) => r.theta_val[j] / t[j],
        _ => f64::NAN,
    }
}

/// Mean online-state NRMSE of one run (NaN without truth).
pub(crate) fn online_nrmse(r: &RunRecord) -> f64 {
    r.online_states
        .as_ref()
        .map_or(f64::NAN, |s| s.mean_nrmse())
}

/// Mean validation-run NRMSE of one run (NaN without a successful validation).
pub(crate) fn validation_nrmse(r: &RunRecord) -> f64 {
    r.validation
        .as_ref()
        .filter(|v| v.error.is_none())
        .map_or(f64::NAN, |v| v.states.mean_nrmse())
}

/// The discretisation a record was computed with (its configuration's `filter.discretisation`).
pub fn scheme(r: &RunRecord) -> Option<Discretisation> {
    serde_json::from_value(r.config.pointer("/filter/discretisation")?.clone()).ok()
}

/// Largest number of distinct values of a sampled static parameter at the end of one run.
pub(crate) fn max_distinct(r: &RunRecord) -> f64 {
    r.distinct_sampled
        .values()
        .copied()
        .max()
        .map_or(f64::NAN, |v| v as f64)
}

/// One statement of the paper, the test that decides it on our records, the verdict and the
/// numbers behind it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    pub statement: String,
    /// The test and its threshold, in words.
    pub test: String,
    pub verdict: Verdict,
    pub evidence: String,
    /// The estimates behind the verdict by label (`differs-from-first`: each difference).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<(String, Estimate)>,
}

/// Writes findings as a Markdown table under the column names `columns` (statement, verdict,
/// test, evidence).
pub(crate) fn findings_table(out: &mut String, columns: [&str; 4], findings: &[Finding]) {
    header(out, &columns);
    for f in findings {
        row(
            out,
            &[
                cell(&f.statement),
                format!("**{}**", f.verdict.label()),
                cell(&f.test),
                cell(&f.evidence),
            ],
        );
    }
}

/// Display name of an algorithm (record name → report label).
fn label(algorithm: &str) -> &str {
    match algorithm {
        "mln-rbpf" => "MLN-RBPF",
        "storvik" => "Storvik",
        "mpf-ekf2" => "MPF-EKF2",
        "bootstrap" => "bootstrap PF",
        other => other,
    }
}

/// Parameter names of a group in the records (`k1`, `k2`, … for `k`).
fn group_names(records: &[&RunRecord], prefix: char) -> Vec<String> {
    records
        .first()
        .map(|r| {
            r.param_names
                .iter()
                .filter(|n| in_group(n, prefix))
                .cloned()
                .collect()
        })
        .unwrap_or_default()
}

/// The paper's statements (SPEC §8), as the Fig. 7 study file declares them (`[[verdicts]]`,
/// see [`declared`]), decided on the records of the Fig. 7 sweep (50 runs per algorithm), with
/// the runs of the Fig. 4 study counted beside them for the bootstrap collapse. Statements whose
/// records are missing are left out.
pub fn paper_findings(
    statements: &[Declared],
    fig4: &[RunRecord],
    fig7: &[RunRecord],
) -> Vec<Finding> {
    let fig4: Vec<&RunRecord> = fig4.iter().collect();
    let fig7: Vec<&RunRecord> = fig7.iter().collect();
    statements
        .iter()
        .filter_map(|d| d.decide(&fig7, &fig4))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantiles() {
        // Tables: Φ⁻¹(0.975) = 1.959964, Φ⁻¹(0.99375) = 2.497705.
        assert!((normal_quantile(0.975) - 1.959_964).abs() < 1e-5);
        assert!((bonferroni_z(4) - 2.497_705).abs() < 1e-5);
        assert!((normal_quantile(0.5)).abs() < 1e-9);
    }

    fn est(mean: f64, se: f64) -> Estimate {
        Estimate { mean, se, n: 50 }
    }

    #[test]
    fn thresholds_decide_at_two_standard_errors() {
        assert_eq!(above(&est(1.0, 0.4), 0.0), Verdict::Holds);
        assert_eq!(above(&est(0.7, 0.4), 0.0), Verdict::NotResolved);
        assert_eq!(above(&est(-1.0, 0.4), 0.0), Verdict::DoesNotHold);
        assert_eq!(below(&est(-1.0, 0.4), 0.0), Verdict::Holds);
        assert_eq!(below(&est(1.0, 0.4), 0.0), Verdict::DoesNotHold);
        assert_eq!(below(&est(0.1, 0.4), 0.0), Verdict::NotResolved);
        assert_eq!(above(&est(1.0, f64::NAN), 0.0), Verdict::NotResolved);
    }

    #[test]
    fn bands_need_the_whole_interval() {
        assert_eq!(within(&est(1.0, 0.02), 0.9, 1.1), Verdict::Holds);
        assert_eq!(within(&est(1.08, 0.02), 0.9, 1.1), Verdict::NotResolved);
        assert_eq!(within(&est(1.2, 0.02), 0.9, 1.1), Verdict::DoesNotHold);
        assert_eq!(within(&est(0.5, 0.02), 0.9, 1.1), Verdict::DoesNotHold);
    }

    #[test]
    fn combined_verdicts() {
        use Verdict::*;
        assert_eq!(Verdict::all([Holds, Holds]), Holds);
        assert_eq!(Verdict::all([Holds, NotResolved]), NotResolved);
        assert_eq!(Verdict::all([NotResolved, DoesNotHold, Holds]), DoesNotHold);
        assert_eq!(Verdict::all([]), NotResolved);
    }

    #[test]
    fn estimates_and_pairs() {
        let e = Estimate::of(&[1.0, 2.0, 3.0, f64::NAN]);
        assert_eq!((e.mean, e.n), (2.0, 3));
        assert!((e.se - 1.0 / 3f64.sqrt()).abs() < 1e-15);
        assert!(Estimate::of(&[1.0]).se.is_nan());
        let a: BTreeMap<u64, f64> = [(0, 1.0), (1, 2.0), (2, 5.0)].into();
        let b: BTreeMap<u64, f64> = [(0, 0.5), (2, 4.0), (3, 9.0)].into();
        let d = paired_difference(&a, &b);
        assert_eq!((d.mean, d.n), (0.75, 2));
    }

    #[test]
    fn group_names_need_digits() {
        assert!(in_group("k1", 'k'));
        assert!(in_group("c12", 'c'));
        assert!(!in_group("c", 'c'));
        assert!(!in_group("cx", 'c'));
    }
}
