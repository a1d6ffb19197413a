//! The identification-accuracy regression check (`sysid regression`).
//!
//! Runs the study of a regression file (`experiments/regression.toml`: a `[study]` table in the
//! format of the other study configs plus a `[thresholds]` table), computes the per-algorithm
//! statistics of θ_val over the runs (SPEC §7, eq. 26) and compares them with the bounds:
//!
//! - per algorithm and parameter, the mean over runs of the relative error |θ_val − θ_true|/θ_true
//!   and the run-to-run s.d. of θ_val/θ_true (the Fig. 7 cross of SPEC §8);
//! - per algorithm, the number of failed runs (SPEC §3: a failure is reported, never hidden);
//! - optionally, a degeneracy bound: the mean over runs of the number of distinct values of each
//!   sampled static parameter (SPEC §5.1: the bootstrap PF is expected to collapse);
//! - optionally, a lower bound on the pooled coverage of the central 95 % credible intervals of
//!   the stiffnesses and dampings (SPEC §9; counted by
//!   [`crate::coverage::stiffness_damping_coverage`]).
//!
//! Every run draws from streams seeded by (master seed, run), so on unchanged code the measured
//! values are reproduced exactly; the margins in the file allow a change that is statistically
//! equivalent (other random draws, other operation order) and flag one that is not.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use crate::error::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::engine::RunMode;
use crate::reproduce::{algorithm_stats, AlgorithmStats};
use crate::study::Study;
use crate::sweep::lock::DirLock;
use crate::sweep::Shard;
use identify::metrics::mean_sd;
use identify::record::RunRecord;

/// Bounds for one algorithm.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlgorithmThresholds {
    /// Largest allowed number of failed runs.
    pub max_failed: usize,
    /// Parameter name → bound on the mean over runs of |θ_val − θ_true| / θ_true.
    pub rel_error_mean: BTreeMap<String, f64>,
    /// Parameter name → bound on the s.d. over runs of θ_val / θ_true.
    pub ratio_sd: BTreeMap<String, f64>,
    /// Bound on the mean over runs of the number of distinct values of every sampled static
    /// parameter at the end of the run (degeneracy, SPEC §5.1, §7).
    pub max_distinct_sampled_mean: Option<f64>,
    /// Lower bound on the pooled coverage of the central 95 % credible intervals of every k_j
    /// and c_j over the completed runs ([`KcCoverage`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_coverage95_kc: Option<f64>,
}

/// A regression file: the study to run and the bounds its statistics must meet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegressionFile {
    pub study: Study,
    /// Algorithm name (`mln-rbpf`, …) → bounds.
    pub thresholds: BTreeMap<String, AlgorithmThresholds>,
}

impl RegressionFile {
    /// Parses a regression file from TOML text and checks that every algorithm of the sweep has
    /// bounds for every parameter of `param_names`.
    pub fn parse(text: &str, param_names: &[&str]) -> Result<Self> {
        let file: RegressionFile = toml::from_str(text)?;
        file.check(param_names)?;
        Ok(file)
    }

    /// Reads and checks a regression file against the parameters of its study's structure
    /// ([`Study::param_names`]: the paper's [`PAPER_PARAMS`] for `paper-3dof`, `k1..kN`,
    /// `c1..cN` and the elements' for one structure of a building preset); errors name the file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = identify::limits::read_text_file(path, "regression file")?;
        let parse = || -> Result<Self> {
            let file: RegressionFile =
                identify::limits::parse_toml(&text, path, "regression file")?;
            let names = file.study.param_names()?;
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            file.check(&names)?;
            Ok(file)
        };
        parse().with_context(|| format!("regression file {}", path.display()))
    }

    /// Every algorithm of the sweep has a bound on both statistics of every parameter, every
    /// bound is a finite non-negative number, and no bound names an unknown parameter.
    pub fn check(&self, param_names: &[&str]) -> Result<()> {
        if self.study.sweep.runs < 2 {
            bail!("a run-to-run s.d. needs at least 2 runs");
        }
        for a in &self.study.sweep.algorithms {
            let Some(t) = self.thresholds.get(a.name()) else {
                bail!("no [thresholds.{}] for an algorithm of the sweep", a.name());
            };
            for (what, map) in [
                ("rel_error_mean", &t.rel_error_mean),
                ("ratio_sd", &t.ratio_sd),
            ] {
                for p in param_names {
                    if !map.contains_key(*p) {
                        bail!("[thresholds.{}.{what}] has no bound for `{p}`", a.name());
                    }
                }
                for (p, v) in map {
                    if !param_names.contains(&p.as_str()) {
                        bail!(
                            "[thresholds.{}.{what}] names unknown parameter `{p}`",
                            a.name()
                        );
                    }
                    if !(v.is_finite() && *v >= 0.0) {
                        bail!("[thresholds.{}.{what}] {p} = {v} is not a bound", a.name());
                    }
                }
            }
            if let Some(c) = t.min_coverage95_kc {
                if !(0.0..=1.0).contains(&c) {
                    bail!(
                        "[thresholds.{}] min_coverage95_kc = {c} is not a proportion in [0, 1]",
                        a.name()
                    );
                }
            }
            if let Some(d) = t.max_distinct_sampled_mean {
                if !(d.is_finite() && d >= 1.0) {
                    bail!(
                        "[thresholds.{}] max_distinct_sampled_mean = {d} is below 1",
                        a.name()
                    );
                }
            }
        }
        for name in self.thresholds.keys() {
            if !self.study.sweep.algorithms.iter().any(|a| a.name() == name) {
                bail!("[thresholds.{name}] names an algorithm that is not in the sweep");
            }
        }
        Ok(())
    }
}

/// Parameter names of the `paper-3dof` preset (SPEC §1).
pub const PAPER_PARAMS: [&str; 9] = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];

/// One comparison of a measured statistic with its bound (`measured ≤ bound` passes, or
/// `measured ≥ bound` for a lower bound; NaN fails).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub algorithm: String,
    /// `rel_error_mean`, `ratio_sd`, `failed`, `distinct_sampled_mean` or `coverage95_kc`.
    pub quantity: String,
    /// Parameter name (empty for `failed`; `k,c` for the pooled coverage).
    pub parameter: String,
    pub measured: f64,
    pub bound: f64,
    /// The bound is a lower bound (coverage) instead of an upper one.
    pub at_least: bool,
    /// Standard error of the measured value over the runs, when defined (for recalibration).
    pub std_error: Option<f64>,
}

impl Check {
    /// Whether the measured value meets its bound (a NaN never does).
    pub fn ok(&self) -> bool {
        if self.at_least {
            self.measured >= self.bound
        } else {
            self.measured <= self.bound
        }
    }
}

/// Pooled coverage of the central 95 % credible intervals of the stiffnesses and dampings of one
/// algorithm's records: over the completed runs with a known truth, the fraction of (run, k_j or
/// c_j) pairs whose interval contains the true value
/// ([`crate::coverage::stiffness_damping_coverage`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct KcCoverage {
    /// Covered pairs / pairs (NaN without a pair).
    pub fraction: f64,
    /// (run, parameter) pairs counted.
    pub pairs: usize,
    /// Runs contributing pairs.
    pub runs: usize,
    /// Standard error of `fraction`: the larger of the binomial s.e. √(p(1 − p)/pairs) and the
    /// s.e. over runs (s.d. of the per-run fractions / √runs), since the intervals of one run are
    /// not independent. NaN with fewer than 2 runs.
    pub std_error: f64,
}

/// The pooled 95 % coverage of the k_j and c_j of `records` (one algorithm's runs), counted by
/// [`crate::coverage::stiffness_damping_coverage`] over all of them and per run for the s.e.
pub fn kc_coverage95(records: &[&RunRecord]) -> KcCoverage {
    let (fraction, pairs) = crate::coverage::stiffness_damping_coverage(records, 0.95);
    let per_run: Vec<f64> = records
        .iter()
        .filter_map(
            |r| match crate::coverage::stiffness_damping_coverage(&[*r], 0.95) {
                (f, n) if n > 0 => Some(f),
                _ => None,
            },
        )
        .collect();
    let (_, sd, runs) = mean_sd(&per_run);
    let std_error = if runs > 1 && pairs > 0 {
        let binomial = (fraction * (1.0 - fraction) / pairs as f64).sqrt();
        binomial.max(sd / (runs as f64).sqrt())
    } else {
        f64::NAN
    };
    KcCoverage {
        fraction,
        pairs,
        runs,
        std_error,
    }
}

/// Compares the pooled 95 % coverage of every algorithm with a `min_coverage95_kc` bound with
/// that bound. An algorithm without a measured coverage (no record, or no interval) yields a
/// failing check (NaN).
pub fn evaluate_coverage(
    thresholds: &BTreeMap<String, AlgorithmThresholds>,
    coverage: &BTreeMap<String, KcCoverage>,
) -> Vec<Check> {
    thresholds
        .iter()
        .filter_map(|(alg, t)| {
            let bound = t.min_coverage95_kc?;
            let c = coverage.get(alg);
            Some(Check {
                algorithm: alg.clone(),
                quantity: "coverage95_kc".into(),
                parameter: "k,c".into(),
                measured: c.map_or(f64::NAN, |c| c.fraction),
                bound,
                at_least: true,
                std_error: c.map(|c| c.std_error).filter(|s| s.is_finite()),
            })
        })
        .collect()
}

/// Compares statistics with bounds. An algorithm with bounds but without statistics, or a
/// parameter with a bound but missing from the statistics, yields a failing check (NaN).
/// `std_errors` (algorithm → parameter → s.e. of the mean relative error) is optional context.
pub fn evaluate(
    thresholds: &BTreeMap<String, AlgorithmThresholds>,
    stats: &[AlgorithmStats],
    std_errors: &BTreeMap<String, BTreeMap<String, f64>>,
) -> Vec<Check> {
    let mut out = Vec::new();
    for (alg, t) in thresholds {
        let s = stats.iter().find(|s| &s.algorithm == alg);
        let check = |quantity: &str, parameter: &str, measured: f64, bound: f64| Check {
            algorithm: alg.clone(),
            quantity: quantity.into(),
            parameter: parameter.into(),
            measured,
            bound,
            at_least: false,
            std_error: None,
        };
        out.push(check(
            "failed",
            "",
            s.map_or(f64::NAN, |s| s.failed as f64),
            t.max_failed as f64,
        ));
        // Parameters in the model's order (k1 … n), unknown names last.
        let order = |map: &BTreeMap<String, f64>| {
            let mut v: Vec<(String, f64)> = map.iter().map(|(k, b)| (k.clone(), *b)).collect();
            v.sort_by_key(|(k, _)| {
                s.and_then(|s| s.params.iter().position(|q| &q.name == k))
                    .unwrap_or(usize::MAX)
            });
            v
        };
        for (p, bound) in order(&t.rel_error_mean) {
            let p = &p;
            let ps = s.and_then(|s| s.params.iter().find(|q| &q.name == p));
            let mut c = check(
                "rel_error_mean",
                p,
                ps.map_or(f64::NAN, |q| q.rel_error_mean),
                bound,
            );
            c.std_error = std_errors.get(alg).and_then(|m| m.get(p)).copied();
            out.push(c);
        }
        for (p, bound) in order(&t.ratio_sd) {
            let p = &p;
            let ps = s.and_then(|s| s.params.iter().find(|q| &q.name == p));
            let mut c = check("ratio_sd", p, ps.map_or(f64::NAN, |q| q.ratio_sd), bound);
            // s.e. of a sample s.d. over n Gaussian values: s.d. / √(2(n−1)).
            c.std_error = match (ps, s) {
                (Some(q), Some(s)) if s.runs > s.failed + 1 => {
                    Some(q.ratio_sd / (2.0 * (s.runs - s.failed - 1) as f64).sqrt())
                }
                _ => None,
            };
            out.push(c);
        }
        if let Some(bound) = t.max_distinct_sampled_mean {
            match s.map(|s| &s.distinct_sampled_mean) {
                Some(d) if !d.is_empty() => {
                    for (p, &v) in d {
                        out.push(check("distinct_sampled_mean", p, v, bound));
                    }
                }
                // A degeneracy bound on a filter that reports no sampled parameter is a breach:
                // the statistic the bound is about is missing.
                _ => out.push(check("distinct_sampled_mean", "", f64::NAN, bound)),
            }
        }
    }
    out
}

/// Algorithm → parameter → standard error over the successful runs of the mean relative error
/// (s.d. / √n), for the table and for recalibrating the bounds.
pub(crate) fn rel_error_std_errors(
    records: &[RunRecord],
) -> BTreeMap<String, BTreeMap<String, f64>> {
    let mut out: BTreeMap<String, BTreeMap<String, f64>> = BTreeMap::new();
    let mut algs: Vec<&str> = records.iter().map(|r| r.algorithm.as_str()).collect();
    algs.sort_unstable();
    algs.dedup();
    for alg in algs {
        let ok: Vec<&RunRecord> = records
            .iter()
            .filter(|r| r.algorithm == alg && !r.is_failure())
            .collect();
        let Some(first) = ok.first() else { continue };
        for (j, name) in first.param_names.iter().enumerate() {
            let errs: Vec<f64> = ok
                .iter()
                .filter_map(|r| r.rel_error.as_ref().map(|e| e[j]))
                .collect();
            let (_, sd, n) = mean_sd(&errs);
            if n > 1 {
                out.entry(alg.to_string())
                    .or_default()
                    .insert(name.clone(), sd / (n as f64).sqrt());
            }
        }
    }
    out
}

/// The table printed by `sysid regression`.
pub fn format_table(checks: &[Check]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<10} {:<22} {:<6} {:>10} {:>10} {:>10}  status",
        "algorithm", "quantity", "param", "measured", "s.e.", "bound"
    );
    for c in checks {
        let se = c.std_error.map_or("-".into(), |v| format!("{v:.4}"));
        // A lower bound is marked `≥`.
        let bound = format!("{}{:.4}", if c.at_least { "≥" } else { "" }, c.bound);
        let _ = writeln!(
            s,
            "{:<10} {:<22} {:<6} {:>10.4} {:>10} {:>10}  {}",
            c.algorithm,
            c.quantity,
            c.parameter,
            c.measured,
            se,
            bound,
            if c.ok() { "ok" } else { "BREACH" }
        );
    }
    s
}

/// How to run a regression check: where its records go and how the sweep runs.
#[derive(Debug, Clone)]
pub(crate) struct RegressionOptions<'a> {
    /// Output directory: `records/` (one JSON per run) and the summary.
    pub out: &'a Path,
    /// Worker threads (0: one per core).
    pub threads: usize,
    /// Reuse the records of an earlier check whose fingerprint matches.
    pub resume: bool,
    /// Delete the records directory of an earlier check first.
    pub fresh: bool,
}

/// A finished regression sweep: its records, per-algorithm statistics and checks. Holds the
/// lock of the output directory until dropped.
#[derive(Debug)]
pub(crate) struct RegressionRun {
    pub records: Vec<RunRecord>,
    /// Runs computed by this check.
    pub executed: usize,
    /// Records reused (`resume`).
    pub reused: usize,
    pub stats: Vec<AlgorithmStats>,
    /// Algorithm → pooled 95 % coverage of its k_j and c_j.
    pub coverage: BTreeMap<String, KcCoverage>,
    pub checks: Vec<Check>,
    _lock: DirLock,
}

/// The bounds a regression check breached, one line each (`algorithm quantity parameter:
/// measured > bound`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{} regression bound(s) breached:\n  {}", .0.len(), .0.join("\n  "))]
pub(crate) struct Breaches(pub Vec<String>);

crate::error::domain_error!(Breaches);

/// Runs the study of `file` into `options.out` (locked for the lifetime of the result) and
/// compares its statistics with the bounds.
pub(crate) fn run(file: &RegressionFile, options: &RegressionOptions) -> Result<RegressionRun> {
    let study = &file.study;
    // Through the engine every study runs by: the output directory locked for the whole check,
    // records written as runs finish, resumable by fingerprint.
    let mode = RunMode {
        quick: false,
        threads: options.threads,
        shard: Shard::default(),
        progress: true,
        resume: options.resume,
    };
    let (lock, engine) = crate::run_dir::open(options.out, mode)?;
    let dir = options.out.join("records");
    if options.fresh && dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    let jobs = study.jobs();
    let outcome = engine.sweep(study, &jobs, &dir, Study::job_id, |job| study.run_job(job))?;
    let records = outcome.records;
    // Each algorithm's records, in the sweep's order.
    let groups: Vec<(&str, Vec<&RunRecord>)> = study
        .sweep
        .algorithms
        .iter()
        .map(|a| {
            let recs = records.iter().filter(|r| r.algorithm == a.name()).collect();
            (a.name(), recs)
        })
        .collect();
    let stats: Vec<AlgorithmStats> = groups
        .iter()
        .map(|(name, recs)| algorithm_stats(name, recs))
        .collect();
    let coverage: BTreeMap<String, KcCoverage> = groups
        .iter()
        .map(|(name, recs)| (name.to_string(), kc_coverage95(recs)))
        .collect();
    let mut checks = evaluate(&file.thresholds, &stats, &rel_error_std_errors(&records));
    checks.extend(evaluate_coverage(&file.thresholds, &coverage));
    Ok(RegressionRun {
        records,
        executed: outcome.executed,
        reused: outcome.reused,
        stats,
        coverage,
        checks,
        _lock: lock,
    })
}

impl RegressionRun {
    /// Writes the summary (`regression.json`): the regression file's path, the wall time, the run
    /// counts, the statistics and every check with its outcome.
    pub(crate) fn write_summary(&self, path: &Path, config: &Path, wall_s: f64) -> Result<()> {
        let text = serde_json::to_string_pretty(&serde_json::json!({
            "config": config,
            "wall_s": wall_s,
            "runs": { "executed": self.executed, "reused": self.reused, "total": self.records.len() },
            "stats": self.stats,
            "coverage95_kc": self.coverage,
            "checks": self.checks.iter().map(|c| serde_json::json!({
                "check": c, "ok": c.ok()
            })).collect::<Vec<_>>(),
        }))? + "\n";
        // Through the writer of every output: atomic, and only a new or regular file replaced.
        crate::sweep::write_bytes_atomic(path, text.as_bytes())
    }

    /// Every bound met, or the breached ones.
    pub fn verdict(&self) -> Result<(), Breaches> {
        let breaches: Vec<String> = self
            .checks
            .iter()
            .filter(|c| !c.ok())
            .map(|c| {
                format!(
                    "{} {} {}: {} {} {}",
                    c.algorithm,
                    c.quantity,
                    c.parameter,
                    c.measured,
                    if c.at_least { "<" } else { ">" },
                    c.bound
                )
            })
            .collect();
        if breaches.is_empty() {
            Ok(())
        } else {
            Err(Breaches(breaches))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::ParamStats;

    fn stats(alg: &str, err: f64, sd: f64, failed: usize) -> AlgorithmStats {
        AlgorithmStats {
            algorithm: alg.into(),
            runs: 8,
            failed,
            params: vec![ParamStats {
                name: "k1".into(),
                truth: 8.0,
                ratio_mean: 1.0,
                ratio_sd: sd,
                rel_error_mean: err,
            }],
            online_nrmse_mean: 0.0,
            validation_nrmse_mean: 0.0,
            distinct_sampled_mean: BTreeMap::new(),
            ess_mean: 0.0,
            loglik_mean: 0.0,
            wall_s_mean: 0.0,
            particle_steps_per_s_mean: 0.0,
        }
    }

    fn bounds() -> BTreeMap<String, AlgorithmThresholds> {
        let t = AlgorithmThresholds {
            max_failed: 0,
            rel_error_mean: [("k1".to_string(), 0.05)].into(),
            ratio_sd: [("k1".to_string(), 0.02)].into(),
            max_distinct_sampled_mean: None,
            min_coverage95_kc: None,
        };
        [("mln-rbpf".to_string(), t)].into()
    }

    #[test]
    fn bound_is_inclusive_and_nan_fails() {
        let none = BTreeMap::new();
        let at = evaluate(&bounds(), &[stats("mln-rbpf", 0.05, 0.02, 0)], &none);
        assert_eq!(at.len(), 3);
        assert!(at.iter().all(Check::ok));
        let nan = evaluate(&bounds(), &[stats("mln-rbpf", f64::NAN, 0.02, 0)], &none);
        assert_eq!(nan.iter().filter(|c| !c.ok()).count(), 1);
    }

    #[test]
    fn missing_algorithm_is_a_breach() {
        let c = evaluate(
            &bounds(),
            &[stats("storvik", 0.0, 0.0, 0)],
            &BTreeMap::new(),
        );
        assert!(c.iter().all(|c| !c.ok()));
    }

    #[test]
    fn coverage_below_its_lower_bound_is_a_breach() {
        let mut t = bounds();
        t.get_mut("mln-rbpf").unwrap().min_coverage95_kc = Some(0.7);
        let cov = |fraction: f64| -> BTreeMap<String, KcCoverage> {
            [(
                "mln-rbpf".to_string(),
                KcCoverage {
                    fraction,
                    pairs: 144,
                    runs: 24,
                    std_error: 0.03,
                },
            )]
            .into()
        };
        // At the bound and above: met (the bound is inclusive).
        for f in [0.7, 0.9, 1.0] {
            let c = evaluate_coverage(&t, &cov(f));
            assert_eq!(c.len(), 1);
            assert!(c[0].ok() && c[0].at_least, "{f}");
            assert_eq!(c[0].std_error, Some(0.03));
        }
        // Below it, NaN (no interval) or no records of the algorithm: breached.
        for f in [0.7 - 1e-9, 0.5, 0.0, f64::NAN] {
            assert!(!evaluate_coverage(&t, &cov(f))[0].ok(), "{f}");
        }
        assert!(!evaluate_coverage(&t, &BTreeMap::new())[0].ok());
        // An algorithm without a coverage bound gets no coverage check.
        assert!(evaluate_coverage(&bounds(), &cov(0.0)).is_empty());
        // The table marks the lower bound and the breach.
        let c = evaluate_coverage(&t, &cov(0.5));
        let table = format_table(&c);
        assert!(
            table.contains("≥0.7000") && table.contains("BREACH"),
            "{table}"
        );
    }

    #[test]
    fn a_coverage_bound_must_be_a_proportion() {
        let text = |c: f64| {
            format!(
                "[study]\nname = \"r\"\ndescription = \"d\"\n[study.data]\npreset = \"paper-3dof\"\n\
                 [study.sweep]\nalgorithms = [\"mln-rbpf\"]\nruns = 2\nmaster_seed = 1\n\
                 particles = [10]\n[thresholds.mln-rbpf]\nmax_failed = 0\n\
                 min_coverage95_kc = {c}\n[thresholds.mln-rbpf.rel_error_mean]\nk1 = 0.1\n\
                 [thresholds.mln-rbpf.ratio_sd]\nk1 = 0.1\n"
            )
        };
        let f = RegressionFile::parse(&text(0.7), &["k1"]).unwrap();
        assert_eq!(f.thresholds["mln-rbpf"].min_coverage95_kc, Some(0.7));
        for bad in [1.5, -0.1] {
            let err = RegressionFile::parse(&text(bad), &["k1"]).unwrap_err();
            assert!(err.to_string().contains("min_coverage95_kc"), "{err}");
        }
    }

    #[test]
    fn table_marks_breaches() {
        let c = evaluate(
            &bounds(),
            &[stats("mln-rbpf", 0.06, 0.01, 0)],
            &BTreeMap::new(),
        );
        let t = format_table(&c);
        assert_eq!(t.matches("BREACH").count(), 1);
        assert_eq!(t.lines().count(), 4);
    }
}
