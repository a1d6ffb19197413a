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

use serde::Serialize;

use crate::markdown::{cell, header, row};
use crate::metrics::mean_sd;
use crate::record::RunRecord;

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
pub fn normal_quantile(p: f64) -> f64 {
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
pub fn bonferroni_z(m: usize) -> f64 {
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
pub fn per_run(records: &[&RunRecord], metric: impl Fn(&RunRecord) -> f64) -> BTreeMap<u64, f64> {
    records
        .iter()
        .filter(|r| !r.is_failure())
        .map(|r| (r.run, metric(r)))
        .filter(|(_, v)| v.is_finite())
        .collect()
}

/// Paired difference a − b over the run indices present in both.
pub fn paired_difference(a: &BTreeMap<u64, f64>, b: &BTreeMap<u64, f64>) -> Estimate {
    let d: Vec<f64> = a
        .iter()
        .filter_map(|(run, va)| b.get(run).map(|vb| va - vb))
        .collect();
    Estimate::of(&d)
}

/// Whether `name` is a parameter of the group `prefix` followed by digits (`k1`, `c12`).
pub fn in_group(name: &str, prefix: char) -> bool {
    name.strip_prefix(prefix)
        .is_some_and(|rest| !rest.is_empty() && rest.chars().all(|c| c.is_ascii_digit()))
}

/// Mean relative error of one run over a group of parameters (`k` stiffnesses, `c` dampings);
/// `None` without truth or without such parameters.
pub fn group_mean_error(r: &RunRecord, prefix: char) -> Option<f64> {
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
pub fn group_error(r: &RunRecord, prefix: char) -> f64 {
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
pub fn online_nrmse(r: &RunRecord) -> f64 {
    r.online_states
        .as_ref()
        .map_or(f64::NAN, |s| s.mean_nrmse())
}

/// Mean validation-run NRMSE of one run (NaN without a successful validation).
pub fn validation_nrmse(r: &RunRecord) -> f64 {
    r.validation
        .as_ref()
        .filter(|v| v.error.is_none())
        .map_or(f64::NAN, |v| v.states.mean_nrmse())
}

/// Largest number of distinct values of a sampled static parameter at the end of one run.
pub fn max_distinct(r: &RunRecord) -> f64 {
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
}

/// Writes findings as a Markdown table under the column names `columns` (statement, verdict,
/// test, evidence).
pub fn findings_table(out: &mut String, columns: [&str; 4], findings: &[Finding]) {
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

/// Records of one algorithm.
fn of<'a>(records: &'a [RunRecord], algorithm: &str) -> Vec<&'a RunRecord> {
    records
        .iter()
        .filter(|r| r.algorithm == algorithm)
        .collect()
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

/// "`a` has a lower `metric` than `b`": paired difference b − a above 0.
fn lower_paired(
    statement: &str,
    records: &[RunRecord],
    a: &str,
    b: &str,
    metric: impl Fn(&RunRecord) -> f64 + Copy,
    (what, scale, unit): (&str, f64, &str),
) -> Option<Finding> {
    let (ra, rb) = (of(records, a), of(records, b));
    if ra.is_empty() || rb.is_empty() {
        return None;
    }
    let (va, vb) = (per_run(&ra, metric), per_run(&rb, metric));
    let d = paired_difference(&vb, &va);
    let (ma, mb) = (
        Estimate::of(&va.values().copied().collect::<Vec<_>>()),
        Estimate::of(&vb.values().copied().collect::<Vec<_>>()),
    );
    let better = va
        .iter()
        .filter(|(run, v)| vb.get(run).is_some_and(|w| *v < w))
        .count();
    Some(Finding {
        statement: statement.into(),
        test: format!(
            "paired difference {} − {} of the per-run {what} over the common runs: holds if > 2 s.e., does not hold if < −2 s.e.",
            label(b),
            label(a)
        ),
        verdict: above(&d, 0.0),
        evidence: format!(
            "{} {:.2}{unit}, {} {:.2}{unit}; difference {}; {} lower in {better} of {} runs",
            label(a),
            scale * ma.mean,
            label(b),
            scale * mb.mean,
            d.show(scale, 2, unit),
            label(a),
            d.n
        ),
    })
}

/// The marginalized filters of the Fig. 7 sweep present in `records`, in the paper's order.
fn marginalized(records: &[RunRecord]) -> Vec<&'static str> {
    ["mln-rbpf", "storvik", "mpf-ekf2"]
        .into_iter()
        .filter(|a| records.iter().any(|r| r.algorithm == *a))
        .collect()
}

/// "θ_val / θ_true of each named parameter lies in [lo, hi] for every marginalized filter".
fn ratio_band(
    statement: &str,
    records: &[RunRecord],
    params: &[&str],
    (lo, hi): (f64, f64),
    band_words: &str,
) -> Option<Finding> {
    let algs = marginalized(records);
    if algs.is_empty() {
        return None;
    }
    let mut verdicts = Vec::new();
    let mut evidence = Vec::new();
    for a in &algs {
        let ra = of(records, a);
        for p in params {
            let v: Vec<f64> = per_run(&ra, |r| ratio(r, p)).into_values().collect();
            let e = Estimate::of(&v);
            verdicts.push(within(&e, lo, hi));
            evidence.push(format!("{} {p} {:.3} ± {:.3}", label(a), e.mean, e.se));
        }
    }
    Some(Finding {
        statement: statement.into(),
        test: format!(
            "mean over runs of θ_val/θ_true ± 2 s.e. inside [{lo}, {hi}] ({band_words}) for every marginalized filter and parameter; does not hold if any lies entirely outside"
        ),
        verdict: Verdict::all(verdicts),
        evidence: evidence.join("; "),
    })
}

/// "Each named parameter is over-estimated (θ_val/θ_true > 1) by every marginalized filter".
fn over_estimated(statement: &str, records: &[RunRecord], param: &str) -> Option<Finding> {
    let algs = marginalized(records);
    if algs.is_empty() {
        return None;
    }
    let mut verdicts = Vec::new();
    let mut evidence = Vec::new();
    for a in &algs {
        let v: Vec<f64> = per_run(&of(records, a), |r| ratio(r, param))
            .into_values()
            .collect();
        let e = Estimate::of(&v);
        verdicts.push(above(&e, 1.0));
        evidence.push(format!("{} {:.3} ± {:.3}", label(a), e.mean, e.se));
    }
    Some(Finding {
        statement: statement.into(),
        test: format!("mean over runs of {param}_val/{param}_true − 2 s.e. > 1 for every marginalized filter; does not hold if + 2 s.e. < 1 for any"),
        verdict: Verdict::all(verdicts),
        evidence: evidence.join("; "),
    })
}

/// Parameter names of a group in the records (`k1`, `k2`, … for `k`).
fn group_names(records: &[RunRecord], prefix: char) -> Vec<String> {
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

/// The paper's statements (SPEC §8) decided on the records of the Fig. 4 study (bootstrap
/// collapse, one run or more) and the Fig. 7 sweep (50 runs per algorithm; every other
/// statement). Statements whose records are missing are left out.
pub fn paper_findings(fig4: &[RunRecord], fig7: &[RunRecord]) -> Vec<Finding> {
    let mut out: Vec<Finding> = Vec::new();

    // Fig. 4: bootstrap collapse, over every bootstrap run available.
    let boot: Vec<&RunRecord> = fig4
        .iter()
        .chain(fig7)
        .filter(|r| r.algorithm == "bootstrap")
        .collect();
    if !boot.is_empty() {
        // Every bootstrap run counts (the Fig. 4 run and the sweep's share run indices).
        let v: Vec<f64> = boot
            .iter()
            .filter(|r| !r.is_failure())
            .map(|r| max_distinct(r))
            .collect();
        let e = Estimate::of(&v);
        out.push(Finding {
            statement: "Fig. 4: the bootstrap PF collapses (parameter particles degenerate)".into(),
            test: "per run, the largest number of distinct particle values of a static parameter at the end; mean over runs + 2 s.e. < 5 holds, − 2 s.e. > 5 does not hold".into(),
            verdict: below(&e, 5.0),
            evidence: format!("{} distinct values", e.show(1.0, 1, "")),
        });
    }
    if let Some(f) = lower_paired(
        "Fig. 4(b): the bootstrap PF's validation loop misses the true loop (worse than MPF-EKF2's)",
        fig7,
        "mpf-ekf2",
        "bootstrap",
        validation_nrmse,
        ("mean validation-run state NRMSE", 1.0, ""),
    ) {
        out.push(f);
    }

    // Fig. 5.
    for (prefix, what) in [('k', "stiffness"), ('c', "damping")] {
        if let Some(f) = lower_paired(
            &format!("Fig. 5: MLN-RBPF better than Storvik on {what} ({prefix})"),
            fig7,
            "mln-rbpf",
            "storvik",
            move |r| group_error(r, prefix),
            (&format!("mean relative {what} error"), 100.0, "%"),
        ) {
            out.push(f);
        }
    }

    // Fig. 6.
    for (prefix, what, margin) in [('k', "stiffness", 0.01), ('c', "damping", 0.05)] {
        let (m, p) = (of(fig7, "mln-rbpf"), of(fig7, "mpf-ekf2"));
        if m.is_empty() || p.is_empty() {
            continue;
        }
        let d = paired_difference(
            &per_run(&p, |r| group_error(r, prefix)),
            &per_run(&m, |r| group_error(r, prefix)),
        );
        out.push(Finding {
            statement: format!("Fig. 6: MPF-EKF2 as good as MLN-RBPF on {what} ({prefix})"),
            test: format!("paired difference MPF-EKF2 − MLN-RBPF of the per-run mean relative {what} error below a margin of {:.0} percentage point(s): holds if + 2 s.e. < margin, does not hold if − 2 s.e. > margin", 100.0 * margin),
            verdict: below(&d, margin),
            evidence: format!("difference {}", d.show(100.0, 2, "%")),
        });
    }
    if let Some(f) = lower_paired(
        "Fig. 6: MPF-EKF2 has a lower online state NRMSE than MLN-RBPF",
        fig7,
        "mpf-ekf2",
        "mln-rbpf",
        online_nrmse,
        ("online state NRMSE (mean over states)", 1.0, ""),
    ) {
        out.push(f);
    }

    // Fig. 7: run-to-run spread.
    if !of(fig7, "mpf-ekf2").is_empty() {
        let mut verdicts = Vec::new();
        let mut worst: Option<(f64, String)> = None;
        let mut names = group_names(fig7, 'k');
        names.extend(group_names(fig7, 'c'));
        for other in ["mln-rbpf", "storvik"] {
            if of(fig7, other).is_empty() {
                continue;
            }
            for p in &names {
                let spread = |a: &str| {
                    let v: Vec<f64> = per_run(&of(fig7, a), |r| ratio(r, p))
                        .into_values()
                        .collect();
                    let (_, sd, n) = mean_sd(&v);
                    (sd, n)
                };
                let ((s_mpf, n_mpf), (s_o, n_o)) = (spread("mpf-ekf2"), spread(other));
                // log(s.d.) has s.e. ≈ 1/√(2(n − 1)) for normal data.
                let e = Estimate {
                    mean: (s_o / s_mpf).ln(),
                    se: (1.0 / (2.0 * (n_mpf as f64 - 1.0)) + 1.0 / (2.0 * (n_o as f64 - 1.0)))
                        .sqrt(),
                    n: n_mpf.min(n_o),
                };
                verdicts.push(above(&e, 0.0));
                let ratio_sd = s_o / s_mpf;
                if worst.as_ref().is_none_or(|(w, _)| ratio_sd < *w) {
                    worst = Some((ratio_sd, format!("{p} vs {}", label(other))));
                }
            }
        }
        if let Some((w, at)) = worst {
            out.push(Finding {
                statement: "Fig. 7: MPF-EKF2 has a much lower run-to-run s.d. of θ_val on k and c".into(),
                test: "for every k, c and each of MLN-RBPF and Storvik: log(s.d._other / s.d._MPF-EKF2) over runs > 2 s.e. (s.e. of a log s.d. ≈ 1/√(2(n−1))); does not hold if < −2 s.e. for any".into(),
                verdict: Verdict::all(verdicts),
                evidence: format!("smallest s.d. ratio other / MPF-EKF2: {w:.2} ({at})"),
            });
        }
    }

    // Fig. 7: accuracy statements, per marginalized filter.
    let algs = marginalized(fig7);
    if !algs.is_empty() {
        let mut verdicts = Vec::new();
        let mut ev = Vec::new();
        for a in &algs {
            let v: Vec<f64> = per_run(&of(fig7, a), |r| group_error(r, 'k'))
                .into_values()
                .collect();
            let e = Estimate::of(&v);
            verdicts.push(below(&e, 0.05));
            ev.push(format!("{} {}", label(a), e.show(100.0, 2, "%")));
        }
        out.push(Finding {
            statement: "Fig. 7: stiffness accurate (every marginalized filter)".into(),
            test: "mean over runs of the per-run mean relative k error + 2 s.e. < 5% for every marginalized filter; does not hold if − 2 s.e. > 5% for any".into(),
            verdict: Verdict::all(verdicts),
            evidence: ev.join("; "),
        });
    }
    let c_names = group_names(fig7, 'c');
    let (c_first, c_mid, c_last) = (
        c_names.first().cloned(),
        c_names.get(1).cloned(),
        c_names.last().cloned(),
    );
    if let (Some(c1), Some(c3)) = (&c_first, &c_last) {
        if c1 != c3 {
            if let Some(f) = ratio_band(
                &format!("Fig. 7: {c1}, {c3} good"),
                fig7,
                &[c1, c3],
                (0.9, 1.1),
                "good: |ratio − 1| < 0.1",
            ) {
                out.push(f);
            }
        }
    }
    if let Some(c2) = &c_mid {
        if let Some(f) = over_estimated(
            &format!("Fig. 7: {c2} over-estimated by all marginalized filters"),
            fig7,
            c2,
        ) {
            out.push(f);
        }
    }
    let p = of(fig7, "mpf-ekf2");
    if !p.is_empty() {
        let v: Vec<f64> = per_run(&p, |r| group_error(r, 'c')).into_values().collect();
        let e = Estimate::of(&v);
        out.push(Finding {
            statement: "Fig. 7: MPF-EKF2 ≈ 20% mean error on dampings".into(),
            test: "mean over runs of the per-run mean relative c error ± 2 s.e. inside [10%, 30%] (≈ 20%: within 10 percentage points)".into(),
            verdict: within(&e, 0.10, 0.30),
            evidence: e.show(100.0, 1, "%"),
        });
    }
    let present = |p: &str| {
        fig7.first()
            .is_some_and(|r| r.param_names.iter().any(|n| n == p))
    };
    let fair: Vec<&str> = ["gamma", "n"].into_iter().filter(|p| present(p)).collect();
    if !fair.is_empty() {
        if let Some(f) = ratio_band(
            "Fig. 7: γ, n fair on average",
            fig7,
            &fair,
            (0.7, 1.3),
            "fair: |ratio − 1| < 0.3",
        ) {
            out.push(f);
        }
    }
    if present("beta") {
        if let Some(f) = over_estimated("Fig. 7: β over-estimated", fig7, "beta") {
            out.push(f);
        }
        let algs = marginalized(fig7);
        let mut verdicts = Vec::new();
        let mut ev = Vec::new();
        for a in &algs {
            let v: Vec<f64> = per_run(&of(fig7, a), |r| ratio(r, "beta"))
                .into_values()
                .collect();
            let e = Estimate::of(&v);
            // Poor: outside the "fair" band |ratio − 1| < 0.3, decided on the whole interval.
            verdicts.push(match within(&e, 0.7, 1.3) {
                Verdict::Holds => Verdict::DoesNotHold,
                Verdict::DoesNotHold => Verdict::Holds,
                Verdict::NotResolved => Verdict::NotResolved,
            });
            ev.push(format!("{} {:.3} ± {:.3}", label(a), e.mean, e.se));
        }
        if !algs.is_empty() {
            out.push(Finding {
                statement: "Fig. 7: β poor".into(),
                test: "mean over runs of β_val/β_true ± 2 s.e. entirely outside [0.7, 1.3] (poor: |ratio − 1| > 0.3, i.e. not fair) for every marginalized filter".into(),
                verdict: Verdict::all(verdicts),
                evidence: ev.join("; "),
            });
        }
    }

    // Fig. 8: the validation loop "matches very well", over the MPF-EKF2 runs of the sweep.
    if !p.is_empty() {
        let v: Vec<f64> = per_run(&p, validation_nrmse).into_values().collect();
        let e = Estimate::of(&v);
        out.push(Finding {
            statement: "Fig. 8: MPF-EKF2's validation run matches the truth very well".into(),
            test: "mean over the MPF-EKF2 runs of the validation-run state NRMSE (mean over states) + 2 s.e. < 0.10 (very well: NRMSE < 0.1)".into(),
            verdict: below(&e, 0.10),
            evidence: e.show(1.0, 4, ""),
        });
    }

    // Not a statement of the paper: no marginalized filter failed.
    if !algs.is_empty() {
        let failed: Vec<String> = algs
            .iter()
            .map(|a| {
                let r = of(fig7, a);
                format!(
                    "{} {} of {}",
                    label(a),
                    r.iter().filter(|r| r.is_failure()).count(),
                    r.len()
                )
            })
            .collect();
        let any = fig7
            .iter()
            .any(|r| algs.contains(&r.algorithm.as_str()) && r.is_failure());
        out.push(Finding {
            statement: "(ours) no run of a marginalized filter fails".into(),
            test: "count of failed runs = 0 (a count, no sampling error to weigh)".into(),
            verdict: if any {
                Verdict::DoesNotHold
            } else {
                Verdict::Holds
            },
            evidence: format!("failed runs: {}", failed.join(", ")),
        });
    }
    out
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
