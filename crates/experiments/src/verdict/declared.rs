//! Verdicts declared in a study file: each `[[verdicts]]` table names a statement, the per-run
//! metric it is about, the algorithms, the test and its threshold or band; [`Declared::decide`]
//! applies the test of the module [`crate::verdict`] to the study's records and writes the test
//! in words from the same declaration, so the words cannot say something the test does not do.
//!
//! ```toml
//! [[verdicts]]
//! statement = "Fig. 7: stiffness accurate (every marginalized filter)"
//! test = "below"                 # below, above, within, outside, lower, paired-below, no-failures
//! metric = "k-error"             # k-error, c-error, ratio (with `params`), c-ratio, beta-error,
//!                                # online-nrmse, validation-nrmse
//! algorithms = ["mln-rbpf", "storvik", "mpf-ekf2"]
//! threshold = 0.05
//! meaning = "accurate: mean error < 5%"   # optional: what the threshold stands for
//! ```
//!
//! `below`, `above`, `within` and `outside` may test arms of the sweep: `scheme = "symplectic"`
//! keeps one discretisation's runs; `schemes = ["euler", "symplectic"]` tests the paired
//! difference first − second (same run, same data set); `against = "discretisation"` the paired
//! difference of this study's runs minus the same runs of that study (given beside), of the
//! `scheme` if named. Their words are short — the estimate, the threshold in the metric's own
//! units, studies named by data rate — and the table showing them states the ±2 s.e. rule.
//!
//! Three tests are code rather than a declaration because their statistic is their own:
//! `bootstrap-collapse` (the distinct particle values of the sampled parameters, over this study
//! and the runs given beside it), `lower-spread` (run-to-run s.d. of θ_val on k and c, through
//! the s.e. of a log s.d.) and `differs-from-first` (each structure of a structure axis against
//! the first, [`Declared::decide_structures`]). A statement whose algorithms have no records is
//! left out.

use serde::{Deserialize, Serialize};

use models::filtering::Discretisation;

use super::{
    above, below, bonferroni_z, group_error, group_names, in_group, label, max_distinct,
    online_nrmse, paired_difference, per_run, ratio, scheme, validation_nrmse, within, Estimate,
    Finding, Verdict,
};
use crate::error::{bail, Result};
use identify::metrics::mean_sd;
use identify::record::RunRecord;

/// Fewest completed runs on both sides for a difference to count in `differs-from-first`.
pub(crate) const MIN_RUNS: usize = 5;

/// The per-run quantity a statement is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Metric {
    /// Storey-averaged |k̂ − k|/k.
    KError,
    /// Storey-averaged |ĉ − c|/c.
    CError,
    /// θ_val/θ_true of each parameter named in `params`.
    Ratio,
    /// Storey-averaged ĉ/c (θ_val/θ_true of the dampings).
    CRatio,
    /// |β̂/β − 1|.
    BetaError,
    /// Online state NRMSE, mean over the states.
    OnlineNrmse,
    /// Validation-run state NRMSE, mean over the states.
    ValidationNrmse,
}

impl Metric {
    /// The metric of one run (`param` for [`Metric::Ratio`]).
    fn of(self, r: &RunRecord, param: &str) -> f64 {
        match self {
            Metric::KError => group_error(r, 'k'),
            Metric::CError => group_error(r, 'c'),
            Metric::Ratio => ratio(r, param),
            Metric::CRatio => {
                let v: Vec<f64> = r
                    .param_names
                    .iter()
                    .filter(|n| in_group(n, 'c'))
                    .map(|n| ratio(r, n))
                    .collect();
                v.iter().sum::<f64>() / v.len() as f64
            }
            Metric::BetaError => (ratio(r, "beta") - 1.0).abs(),
            Metric::OnlineNrmse => online_nrmse(r),
            Metric::ValidationNrmse => validation_nrmse(r),
        }
    }

    /// The metric in words (`params` for [`Metric::Ratio`]).
    fn words(self, params: &[String]) -> String {
        match self {
            Metric::KError => "the per-run mean relative stiffness error".into(),
            Metric::CError => "the per-run mean relative damping error".into(),
            Metric::Ratio => match params {
                [p] => format!("{p}_val/{p}_true"),
                _ => format!("θ_val/θ_true of {}", params.join(", ")),
            },
            Metric::CRatio | Metric::BetaError => format!("the per-run {}", self.brief(params).1),
            Metric::OnlineNrmse => "the per-run online state NRMSE (mean over states)".into(),
            Metric::ValidationNrmse => {
                "the per-run mean validation-run state NRMSE (mean over states)".into()
            }
        }
    }

    /// The metric in the short form of a test on arms: an article and a noun.
    fn brief(self, params: &[String]) -> (&'static str, String) {
        match self {
            Metric::KError => ("the ", "mean k error".into()),
            Metric::CError => ("the ", "mean c error".into()),
            Metric::Ratio => ("", self.words(params)),
            Metric::CRatio => ("", "mean c θ_val/θ_true".into()),
            Metric::BetaError => ("", "|β θ_val/θ_true − 1|".into()),
            Metric::OnlineNrmse => ("the ", "online state NRMSE".into()),
            Metric::ValidationNrmse => ("the ", "validation-run state NRMSE".into()),
        }
    }

    /// Scale, decimals and unit of its values in the report.
    fn display(self) -> (f64, usize, &'static str) {
        match self {
            Metric::KError => (100.0, 2, "%"),
            Metric::CError => (100.0, 1, "%"),
            Metric::Ratio | Metric::CRatio | Metric::BetaError => (1.0, 3, ""),
            Metric::OnlineNrmse | Metric::ValidationNrmse => (1.0, 4, ""),
        }
    }

    /// A threshold in the report's units; `difference`: a margin on a difference (percentage
    /// points for a percentage).
    fn threshold(self, t: f64, difference: bool) -> String {
        let (scale, _, unit) = self.display();
        let v = trimmed(scale * t);
        match (unit, difference) {
            ("%", true) => format!("{v} percentage point(s)"),
            _ => format!("{v}{unit}"),
        }
    }
}

/// `v` with at most four decimals, no trailing zeros and a typographic minus.
fn trimmed(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.replace('-', "−")
}

/// How a statement is decided (see [`crate::verdict`] for the rule at ±2 s.e.).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Test {
    /// The mean over runs is below `threshold`, for every algorithm (and parameter).
    Below,
    /// The mean over runs is above `threshold`, for every algorithm (and parameter).
    Above,
    /// The mean over runs lies in `band`, for every algorithm (and parameter).
    Within,
    /// The mean over runs lies outside `band`, for every algorithm (and parameter).
    Outside,
    /// Each algorithm has a lower metric than each of `than`: the paired difference is above 0.
    Lower,
    /// Each algorithm's metric exceeds each of `than`'s by less than the margin `threshold`:
    /// the paired difference is below it.
    PairedBelow,
    /// No run of the algorithms failed (a count: no sampling error to weigh).
    NoFailures,
    /// The algorithms' runs, here and beside this study, keep fewer than `threshold` distinct
    /// values of every sampled parameter (the bootstrap PF's collapse, Fig. 4).
    BootstrapCollapse,
    /// The algorithms' run-to-run s.d. of θ_val is lower than each of `than`'s, for every k and
    /// c (Fig. 7).
    LowerSpread,
    /// One algorithm's mean error (`k-error`, `c-error`) under some structure of a structure axis
    /// differs from the first structure's: each difference of independent means (s.e.
    /// √(s.e.₁² + s.e.₂²)) is judged at the Bonferroni z of the comparisons; holds when some ±z
    /// s.e. interval excludes 0, does not hold when every one lies within ±`threshold`
    /// (counting only differences with `MIN_RUNS` completed runs on both sides).
    DiffersFromFirst,
}

impl Test {
    fn name(self) -> &'static str {
        match self {
            Test::Below => "below",
            Test::Above => "above",
            Test::Within => "within",
            Test::Outside => "outside",
            Test::Lower => "lower",
            Test::PairedBelow => "paired-below",
            Test::NoFailures => "no-failures",
            Test::BootstrapCollapse => "bootstrap-collapse",
            Test::LowerSpread => "lower-spread",
            Test::DiffersFromFirst => "differs-from-first",
        }
    }
}

/// One statement of a study file (`[[verdicts]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Declared {
    /// The statement as the report writes it.
    pub statement: String,
    pub test: Test,
    /// The per-run metric (every test but `no-failures`, `bootstrap-collapse`, `lower-spread`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<Metric>,
    /// The algorithms the statement is about (record names: `mln-rbpf`, `mpf-ekf2`, …).
    pub algorithms: Vec<String>,
    /// The algorithms compared against (`lower`, `paired-below`, `lower-spread`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub than: Vec<String>,
    /// Parameters of the `ratio` metric (`c2`, `beta`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub params: Vec<String>,
    /// Threshold of `below`, `above`, `bootstrap-collapse`; margin of `paired-below`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// `[lo, hi]` of `within` and `outside`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band: Option<[f64; 2]>,
    /// What the threshold or band stands for, in words (`good: |ratio − 1| < 0.1`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meaning: Option<String>,
    /// Only the runs computed with this discretisation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheme: Option<Discretisation>,
    /// The paired difference first − second of the runs of these two discretisations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schemes: Option<[Discretisation; 2]>,
    /// The paired difference of this study's runs minus the same runs of the study named here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub against: Option<String>,
}

impl Declared {
    /// Checks the declaration against the study's algorithms (`sweep`, record names) and
    /// discretisations; errors name the statement and the field.
    pub fn check(&self, sweep: &[&str], schemes: &[Discretisation]) -> Result<()> {
        let at = format!("verdict `{}` (test `{}`)", self.statement, self.test.name());
        if self.statement.trim().is_empty() {
            bail!("a verdict has an empty `statement`");
        }
        if self.algorithms.is_empty() {
            bail!("{at}: field `algorithms` is empty");
        }
        for a in self.algorithms.iter().chain(&self.than) {
            if !sweep.contains(&a.as_str()) {
                bail!(
                    "{at}: algorithm `{a}` is not one of the sweep's ({})",
                    sweep.join(", ")
                );
            }
        }
        if let Some(a) = self.than.iter().find(|a| self.algorithms.contains(a)) {
            bail!("{at}: algorithm `{a}` is in both `algorithms` and `than`");
        }
        let (metric, than, threshold, band) = match self.test {
            Test::Below | Test::Above | Test::DiffersFromFirst => (true, false, true, false),
            Test::Within | Test::Outside => (true, false, false, true),
            Test::Lower => (true, true, false, false),
            Test::PairedBelow => (true, true, true, false),
            Test::NoFailures => (false, false, false, false),
            Test::BootstrapCollapse => (false, false, true, false),
            Test::LowerSpread => (false, true, false, false),
        };
        let given = [
            ("metric", self.metric.is_some(), metric),
            ("than", !self.than.is_empty(), than),
            ("threshold", self.threshold.is_some(), threshold),
            ("band", self.band.is_some(), band),
        ];
        for (field, is_given, needed) in given {
            match (is_given, needed) {
                (false, true) => bail!("{at}: needs field `{field}`"),
                (true, false) => bail!("{at}: field `{field}` is not used by this test"),
                _ => {}
            }
        }
        match (self.metric, self.params.is_empty()) {
            (Some(Metric::Ratio), true) => bail!("{at}: metric `ratio` needs field `params`"),
            (Some(Metric::Ratio), false) | (_, true) => {}
            (_, false) => bail!("{at}: field `params` is used by metric `ratio` only"),
        }
        if self.test == Test::DiffersFromFirst
            && (self.algorithms.len() > 1
                || !matches!(self.metric, Some(Metric::KError | Metric::CError)))
        {
            bail!("{at}: the test compares one algorithm's mean errors: one algorithm, metric `k-error` or `c-error`");
        }
        if self.on_arms()
            && !matches!(
                self.test,
                Test::Below | Test::Above | Test::Within | Test::Outside
            )
        {
            bail!("{at}: fields `scheme`, `schemes` and `against` are used by the tests below, above, within and outside only");
        }
        if self.schemes.is_some_and(|[a, b]| a == b)
            || (self.schemes.is_some() && (self.scheme.is_some() || self.against.is_some()))
        {
            bail!("{at}: field `schemes` names two different discretisations, without `scheme` or `against`");
        }
        if schemes.len() > 1 && self.scheme.is_none() && self.schemes.is_none() {
            bail!("{at}: the sweep has several discretisations: name `scheme` or `schemes`");
        }
        let named = self.scheme.iter().chain(self.schemes.iter().flatten());
        if let Some(s) = named.into_iter().find(|s| !schemes.contains(s)) {
            bail!("{at}: discretisation `{s}` is not one of the sweep's");
        }
        if let Some(t) = self.threshold {
            if !t.is_finite() {
                bail!("{at}: field `threshold` must be a finite number, got {t}");
            }
        }
        if let Some([lo, hi]) = self.band {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                bail!("{at}: field `band` must be [lo, hi] with lo < hi, got [{lo}, {hi}]");
            }
        }
        Ok(())
    }

    /// Whether the test is on arms of the sweep (`scheme`, `schemes`, `against`).
    fn on_arms(&self) -> bool {
        self.scheme.is_some() || self.schemes.is_some() || self.against.is_some()
    }

    /// The finding on `records` (the study's); `beside` are runs of other studies, which the
    /// `bootstrap-collapse` test counts too and an `against` test compares with. `None` when the
    /// statement's algorithms have no records (or the study it is `against` none), the records
    /// lack a parameter of `params`, or the test is `differs-from-first`.
    pub fn decide(&self, records: &[&RunRecord], beside: &[&RunRecord]) -> Option<Finding> {
        let present: Vec<&str> = self
            .algorithms
            .iter()
            .map(String::as_str)
            .filter(|a| records.iter().any(|r| r.algorithm == *a))
            .collect();
        if present.is_empty() && self.test != Test::BootstrapCollapse {
            return None;
        }
        if self.params.iter().any(|p| {
            records
                .first()
                .is_none_or(|r| !r.param_names.iter().any(|n| n == p))
        }) {
            return None;
        }
        let (test, verdict, evidence) = match self.test {
            Test::Below | Test::Above | Test::Within | Test::Outside => {
                self.single(records, beside, &present)?
            }
            Test::Lower | Test::PairedBelow => self.paired(records, &present)?,
            Test::NoFailures => no_failures(records, &present),
            Test::BootstrapCollapse => self.collapse(records, beside)?,
            Test::LowerSpread => self.spread(records, &present)?,
            Test::DiffersFromFirst => return None,
        };
        Some(Finding {
            statement: self.statement.clone(),
            test,
            verdict,
            evidence,
            parts: Vec::new(),
        })
    }

    fn meaning(&self) -> String {
        self.meaning
            .as_ref()
            .map(|m| format!(" ({m})"))
            .unwrap_or_default()
    }

    /// `below`, `above`, `within`, `outside`: one estimate per algorithm and parameter — the mean
    /// over runs, or on arms a paired difference.
    fn single<'a>(
        &self,
        records: &[&'a RunRecord],
        beside: &[&'a RunRecord],
        present: &[&str],
    ) -> Option<(String, Verdict, String)> {
        let metric = self.metric.expect("checked: the test has a metric");
        let (this, that) = match (self.schemes, &self.against) {
            (Some([x, y]), _) => (arm(records, Some(x), None), arm(records, Some(y), None)),
            (None, against) => (
                arm(records, self.scheme, None),
                arm(beside, self.scheme, against.as_ref()),
            ),
        };
        if self.against.is_some() && that.is_empty() {
            return None;
        }
        let params: Vec<&str> = if self.params.is_empty() {
            vec![""]
        } else {
            self.params.iter().map(String::as_str).collect()
        };
        let mut verdicts = Vec::new();
        let mut evidence = Vec::new();
        for a in present {
            for p in &params {
                let runs = |recs: &[&RunRecord]| per_run(&of(recs, a), |r| metric.of(r, p));
                let e = match self.schemes.is_some() || self.against.is_some() {
                    true => paired_difference(&runs(&this), &runs(&that)),
                    false => Estimate::of(&runs(&this).into_values().collect::<Vec<_>>()),
                };
                verdicts.push(self.single_verdict(&e));
                evidence.push(self.single_evidence(metric, &e, a, p, params.len()));
            }
        }
        let (verdict, evidence) = (Verdict::all(verdicts), evidence.join("; "));
        let (over, every, any) = self.subjects(params.len());
        if self.on_arms() {
            return Some((
                self.brief(metric, records, &that, &every),
                verdict,
                evidence,
            ));
        }
        let test = self.single_test_words(metric, &over, &every, any);
        Some((test, verdict, evidence))
    }

    /// The verdict of one estimate under the test's threshold or band.
    fn single_verdict(&self, e: &Estimate) -> Verdict {
        match (self.test, self.threshold, self.band) {
            (Test::Below, Some(t), _) => below(e, t),
            (Test::Above, Some(t), _) => above(e, t),
            (Test::Within, _, Some([lo, hi])) => within(e, lo, hi),
            (Test::Outside, _, Some([lo, hi])) => match within(e, lo, hi) {
                Verdict::Holds => Verdict::DoesNotHold,
                Verdict::DoesNotHold => Verdict::Holds,
                Verdict::NotResolved => Verdict::NotResolved,
            },
            _ => unreachable!("checked: the test has its threshold or band"),
        }
    }

    /// The evidence of one estimate: the algorithm and parameter when the statement has several,
    /// then the value (a ratio of one arm as a bare number, otherwise in the metric's unit).
    fn single_evidence(
        &self,
        metric: Metric,
        e: &Estimate,
        algorithm: &str,
        param: &str,
        params: usize,
    ) -> String {
        let (scale, decimals, unit) = metric.display();
        let mut who = Vec::new();
        if self.algorithms.len() > 1 {
            who.push(label(algorithm).to_string());
        }
        if params > 1 {
            who.push(param.to_string());
        }
        let value = if metric == Metric::Ratio && !self.on_arms() {
            format!("{:.3} ± {:.3}", e.mean, e.se)
        } else {
            e.show(scale, decimals, unit)
        };
        who.push(value);
        who.join(" ")
    }

    /// Whose runs a test is over, in words: the runs of the one algorithm, or "runs" with " for
    /// each algorithm (and parameter)" and " for any" to say that every one must pass.
    fn subjects(&self, params: usize) -> (String, String, &'static str) {
        match &self.algorithms[..] {
            [a] => (format!("the {} runs", label(a)), String::new(), ""),
            _ => (
                "runs".to_string(),
                format!(
                    " for {}{}",
                    group(&self.algorithms),
                    if params > 1 { " and parameter" } else { "" }
                ),
                " for any",
            ),
        }
    }

    /// The words of a test on one arm: the rule at ±2 s.e. against the threshold or band, and
    /// when it does not hold.
    fn single_test_words(&self, metric: Metric, over: &str, every: &str, any: &str) -> String {
        let what = metric.words(&self.params);
        let meaning = self.meaning();
        match (self.test, self.threshold, self.band) {
            (Test::Below, Some(t), _) => {
                let t = metric.threshold(t, false);
                format!("mean over {over} of {what} + 2 s.e. < {t}{meaning}{every}; does not hold if − 2 s.e. > {t}{any}")
            }
            (Test::Above, Some(t), _) => {
                let t = metric.threshold(t, false);
                format!("mean over {over} of {what} − 2 s.e. > {t}{meaning}{every}; does not hold if + 2 s.e. < {t}{any}")
            }
            (Test::Within, _, Some([lo, hi])) => {
                let (lo, hi) = (metric.threshold(lo, false), metric.threshold(hi, false));
                format!("mean over {over} of {what} ± 2 s.e. inside [{lo}, {hi}]{meaning}{every}; does not hold if it lies entirely outside{any}")
            }
            (Test::Outside, _, Some([lo, hi])) => {
                let (lo, hi) = (metric.threshold(lo, false), metric.threshold(hi, false));
                format!("mean over {over} of {what} ± 2 s.e. entirely outside [{lo}, {hi}]{meaning}{every}; does not hold if it lies entirely inside{any}")
            }
            _ => unreachable!("checked: the test has its threshold or band"),
        }
    }

    /// The short words of a test on arms (the rule at ±2 s.e. is stated beside the table);
    /// `other`: the runs of the study it is `against`.
    fn brief(
        &self,
        metric: Metric,
        records: &[&RunRecord],
        other: &[&RunRecord],
        every: &str,
    ) -> String {
        let (article, noun) = metric.brief(&self.params);
        let word = |d: Discretisation| d.name().replace("euler", "Euler");
        let of = match self.scheme {
            Some(d) => format!("the {} {noun}", word(d)),
            None => format!("{article}{noun}"),
        };
        let estimate = match (self.schemes, &self.against) {
            (Some([a, b]), _) => format!("paired difference {} − {}", word(a), word(b)),
            (None, Some(study)) => {
                // The studies by their data rate (1/dt of their filter step) or, without, by name.
                let rate = |r: &[&RunRecord], name: &str| {
                    let dt = r[0].config.pointer("/spec/dt").and_then(|v| v.as_f64());
                    dt.map_or(format!("`{name}`"), |dt| format!("{:.0} Hz", 1.0 / dt))
                };
                let (a, b) = (rate(records, &records[0].experiment), rate(other, study));
                format!("paired difference ({a} − {b}, same run)")
            }
            (None, None) => "mean over runs".into(),
        };
        let cmp = match (self.threshold, self.band) {
            (Some(t), _) => trimmed(t),
            (_, Some([lo, hi])) => format!("[{}, {}]", trimmed(lo), trimmed(hi)),
            _ => unreachable!("checked: the test has its threshold or band"),
        };
        let test = self.test.name();
        format!("{estimate} of {of} {test} {cmp}{}{every}", self.meaning())
    }

    /// [`Test::DiffersFromFirst`] on the runs of each structure (label and runs, the first the
    /// control; a structure is a `noun` in words, "ground motion"); `parts` holds the
    /// differences. `None` for another test or without runs of the algorithm.
    pub fn decide_structures(
        &self,
        structures: &[(&str, Vec<&RunRecord>)],
        noun: &str,
    ) -> Option<Finding> {
        let ((_, control), others) = structures.split_first()?;
        let a = self.algorithms.first()?;
        let ran = structures.iter().any(|(_, r)| !of(r, a).is_empty());
        if self.test != Test::DiffersFromFirst || !ran {
            return None;
        }
        let (metric, margin) = (self.metric?, self.threshold?);
        let (scale, decimals, _) = metric.display();
        let mean = |recs: &[&RunRecord]| {
            let done = of(recs, a).into_iter().filter(|r| !r.is_failure());
            Estimate::of(&done.map(|r| metric.of(r, "")).collect::<Vec<_>>())
        };
        // Several structures are compared with the first at once: each difference is judged at
        // the Bonferroni z of the family, so that "some differ" has a 5 % chance of a false
        // alarm when none does. A difference with too few runs decides nothing.
        let z = bonferroni_z(others.len());
        let base = mean(control);
        let (mut differs, mut same, mut parts) = (false, !others.is_empty(), Vec::new());
        for (structure, recs) in others {
            let e = mean(recs);
            let d = Estimate {
                mean: e.mean - base.mean,
                se: (e.se.powi(2) + base.se.powi(2)).sqrt(),
                n: e.n.min(base.n),
            };
            let (lo, hi) = (d.mean - z * d.se, d.mean + z * d.se);
            let counts = d.n >= MIN_RUNS && lo.is_finite() && hi.is_finite();
            differs |= counts && (lo > 0.0 || hi < 0.0);
            same &= counts && lo >= -margin && hi <= margin;
            parts.push((structure.to_string(), d));
        }
        let evidence: Vec<String> = (parts.iter())
            .map(|(s, d)| {
                let (m, se) = (scale * d.mean, scale * d.se);
                format!("`{s}` {m:+.decimals$} ± {se:.decimals$} pp")
            })
            .collect();
        Some(Finding {
            statement: self.statement.clone(),
            test: format!(
                "for each {noun} the difference of the mean errors with its standard error \
                 √(s.e.₁² + s.e.₂²) (independent data sets), judged at the Bonferroni z = {z:.2} \
                 of the {} comparisons (family-wise 5 %); **holds** when some difference's ±z \
                 s.e. interval excludes 0, **does not hold** when every difference's ±z s.e. \
                 interval lies within ±{} percentage point, otherwise **not resolved** (a \
                 difference counts only with at least {MIN_RUNS} completed runs on both sides){}",
                others.len(),
                trimmed(scale * margin),
                self.meaning()
            ),
            verdict: match (differs, same) {
                (true, _) => Verdict::Holds,
                (false, true) => Verdict::DoesNotHold,
                (false, false) => Verdict::NotResolved,
            },
            evidence: evidence.join("; "),
            parts,
        })
    }

    /// `lower` and `paired-below`: paired differences over the runs both algorithms completed.
    fn paired(
        &self,
        records: &[&RunRecord],
        present: &[&str],
    ) -> Option<(String, Verdict, String)> {
        let metric = self.metric.expect("checked: the test has a metric");
        let (scale, _, unit) = metric.display();
        let param = self.params.first().map_or("", String::as_str);
        let values = |a: &str| per_run(&of(records, a), |r| metric.of(r, param));
        let what = metric.words(&self.params);
        let mut verdicts = Vec::new();
        let mut tests = Vec::new();
        let mut evidence = Vec::new();
        for a in present {
            for b in &self.than {
                if of(records, b).is_empty() {
                    continue;
                }
                let (va, vb) = (values(a), values(b));
                let (la, lb) = (label(a), label(b));
                if self.test == Test::Lower {
                    let d = paired_difference(&vb, &va);
                    let mean = |v: &std::collections::BTreeMap<u64, f64>| {
                        mean_sd(&v.values().copied().collect::<Vec<_>>()).0
                    };
                    let better = va
                        .iter()
                        .filter(|(run, v)| vb.get(run).is_some_and(|w| *v < w))
                        .count();
                    verdicts.push(above(&d, 0.0));
                    tests.push(format!(
                        "paired difference {lb} − {la} of {what} over the common runs: holds if > 2 s.e., does not hold if < −2 s.e.{}",
                        self.meaning()
                    ));
                    evidence.push(format!(
                        "{la} {:.2}{unit}, {lb} {:.2}{unit}; difference {}; {la} lower in {better} of {} runs",
                        scale * mean(&va),
                        scale * mean(&vb),
                        d.show(scale, 2, unit),
                        d.n
                    ));
                } else {
                    let margin = self.threshold.expect("checked: the test has a margin");
                    let d = paired_difference(&va, &vb);
                    verdicts.push(below(&d, margin));
                    tests.push(format!(
                        "paired difference {la} − {lb} of {what} below a margin of {}{}: holds if + 2 s.e. < margin, does not hold if − 2 s.e. > margin",
                        metric.threshold(margin, true),
                        self.meaning()
                    ));
                    evidence.push(format!("difference {}", d.show(scale, 2, unit)));
                }
            }
        }
        if verdicts.is_empty() {
            return None;
        }
        Some((
            tests.join("; "),
            Verdict::all(verdicts),
            evidence.join("; "),
        ))
    }

    /// `bootstrap-collapse`: every run of the algorithms here and beside counts (their run
    /// indices may repeat: each is its own data set and filter).
    fn collapse(
        &self,
        records: &[&RunRecord],
        beside: &[&RunRecord],
    ) -> Option<(String, Verdict, String)> {
        let t = self.threshold.expect("checked: the test has a threshold");
        let runs: Vec<&RunRecord> = beside
            .iter()
            .chain(records)
            .filter(|r| self.algorithms.contains(&r.algorithm))
            .copied()
            .collect();
        if runs.is_empty() {
            return None;
        }
        let v: Vec<f64> = runs
            .iter()
            .filter(|r| !r.is_failure())
            .map(|r| max_distinct(r))
            .collect();
        let e = Estimate::of(&v);
        let t_words = trimmed(t);
        Some((
            format!("per run, the largest number of distinct particle values of a static parameter at the end; mean over runs + 2 s.e. < {t_words} holds, − 2 s.e. > {t_words} does not hold{}", self.meaning()),
            below(&e, t),
            format!("{} distinct values", e.show(1.0, 1, "")),
        ))
    }

    /// `lower-spread`: log(s.d._other / s.d._this) of θ_val/θ_true over runs, for every k and c.
    fn spread(
        &self,
        records: &[&RunRecord],
        present: &[&str],
    ) -> Option<(String, Verdict, String)> {
        let mut names = group_names(records, 'k');
        names.extend(group_names(records, 'c'));
        let spread = |a: &str, p: &str| {
            let v: Vec<f64> = per_run(&of(records, a), |r| ratio(r, p))
                .into_values()
                .collect();
            let (_, sd, n) = mean_sd(&v);
            (sd, n)
        };
        let mut verdicts = Vec::new();
        let mut worst: Option<(f64, String)> = None;
        for a in present {
            for other in &self.than {
                if of(records, other).is_empty() {
                    continue;
                }
                for p in &names {
                    let ((s_a, n_a), (s_o, n_o)) = (spread(a, p), spread(other, p));
                    // log(s.d.) has s.e. ≈ 1/√(2(n − 1)) for normal data.
                    let e = Estimate {
                        mean: (s_o / s_a).ln(),
                        se: (1.0 / (2.0 * (n_a as f64 - 1.0)) + 1.0 / (2.0 * (n_o as f64 - 1.0)))
                            .sqrt(),
                        n: n_a.min(n_o),
                    };
                    verdicts.push(above(&e, 0.0));
                    let r = s_o / s_a;
                    if worst.as_ref().is_none_or(|(w, _)| r < *w) {
                        worst = Some((r, format!("{p} vs {}", label(other))));
                    }
                }
            }
        }
        let (w, at) = worst?;
        let this = group(&self.algorithms);
        let others: Vec<&str> = self.than.iter().map(|a| label(a)).collect();
        Some((
            format!(
                "for every k, c and each of {}: log(s.d._other / s.d._{this}) over runs > 2 s.e. (s.e. of a log s.d. ≈ 1/√(2(n−1))); does not hold if < −2 s.e. for any{}",
                others.join(" and "),
                self.meaning()
            ),
            Verdict::all(verdicts),
            format!("smallest s.d. ratio other / {this}: {w:.2} ({at})"),
        ))
    }
}

/// `no-failures`: a count of failed runs.
fn no_failures(records: &[&RunRecord], present: &[&str]) -> (String, Verdict, String) {
    let mut any = false;
    let counts: Vec<String> = present
        .iter()
        .map(|a| {
            let r = of(records, a);
            let failed = r.iter().filter(|r| r.is_failure()).count();
            any |= failed > 0;
            format!("{} {failed} of {}", label(a), r.len())
        })
        .collect();
    (
        "count of failed runs = 0 (a count, no sampling error to weigh)".into(),
        if any {
            Verdict::DoesNotHold
        } else {
            Verdict::Holds
        },
        format!("failed runs: {}", counts.join(", ")),
    )
}

/// The runs of an arm: of one discretisation (any with `None`), of this study or, with `study`,
/// of the study of that name beside it.
fn arm<'a>(
    recs: &[&'a RunRecord],
    d: Option<Discretisation>,
    study: Option<&String>,
) -> Vec<&'a RunRecord> {
    let keep = |r: &&RunRecord| d.is_none_or(|d| scheme(r) == Some(d));
    let keep = |r: &&RunRecord| keep(r) && study.is_none_or(|s| &r.experiment == s);
    recs.iter().copied().filter(keep).collect::<Vec<_>>()
}

/// Records of one algorithm.
fn of<'a>(records: &[&'a RunRecord], algorithm: &str) -> Vec<&'a RunRecord> {
    records
        .iter()
        .copied()
        .filter(|r| r.algorithm == algorithm)
        .collect()
}

/// The algorithms in words: "every marginalized filter" for the three, else their names.
fn group(algorithms: &[String]) -> String {
    let marginalized = ["mln-rbpf", "storvik", "mpf-ekf2"];
    if algorithms.len() == 3
        && marginalized
            .iter()
            .all(|a| algorithms.iter().any(|b| b == a))
    {
        return "every marginalized filter".into();
    }
    let names: Vec<&str> = algorithms.iter().map(|a| label(a)).collect();
    match &names[..] {
        [one] => one.to_string(),
        _ => format!("each of {}", names.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_are_written_in_the_report_units() {
        assert_eq!(Metric::KError.threshold(0.05, false), "5%");
        assert_eq!(
            Metric::CError.threshold(0.05, true),
            "5 percentage point(s)"
        );
        assert_eq!(Metric::ValidationNrmse.threshold(0.10, false), "0.1");
        assert_eq!(Metric::Ratio.threshold(1.3, false), "1.3");
        assert_eq!(trimmed(0.015 * 100.0), "1.5");
        assert_eq!(trimmed(-0.05), "−0.05");
    }
}
