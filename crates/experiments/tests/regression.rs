//! The regression file parses, covers every algorithm and parameter of its sweep, and its bounds
//! flag a statistic that moved past them.

use crate::common;

use std::collections::BTreeMap;
use std::path::PathBuf;

use core_filters::credible::{CredibleInterval, STANDARD_LEVELS};
use experiments::regression::{
    evaluate, evaluate_coverage, format_table, kc_coverage95, KcCoverage, RegressionFile,
    PAPER_PARAMS,
};
use experiments::reproduce::{AlgorithmStats, ParamStats};
use identify::observe::{ParamIntervals, PosteriorShape};
use identify::record::RunRecord;
use identify::settings::FilterSettings;

fn file() -> RegressionFile {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../experiments/regression.toml");
    RegressionFile::load(&path).expect("experiments/regression.toml")
}

/// Statistics of one algorithm that sit exactly on the bounds of `file` (pass), with θ_val of
/// every parameter moved from the truth by its bound.
fn at_bounds(file: &RegressionFile, alg: &str) -> AlgorithmStats {
    let t = &file.thresholds[alg];
    AlgorithmStats {
        algorithm: alg.into(),
        runs: file.study.sweep.runs as usize,
        failed: t.max_failed,
        params: PAPER_PARAMS
            .iter()
            .map(|p| ParamStats {
                name: p.to_string(),
                truth: 1.0,
                ratio_mean: 1.0 + t.rel_error_mean[*p],
                ratio_sd: t.ratio_sd[*p],
                rel_error_mean: t.rel_error_mean[*p],
            })
            .collect(),
        online_nrmse_mean: 0.1,
        validation_nrmse_mean: f64::NAN,
        distinct_sampled_mean: t
            .max_distinct_sampled_mean
            .map(|d| PAPER_PARAMS.iter().map(|p| (p.to_string(), d)).collect())
            .unwrap_or_default(),
        ess_mean: 100.0,
        loglik_mean: 0.0,
        wall_s_mean: 1.0,
        particle_steps_per_s_mean: 1e6,
    }
}

#[test]
fn regression_file_covers_every_algorithm_and_parameter() {
    let f = file();
    assert_eq!(f.study.data.preset, "paper-3dof");
    assert_ne!(f.study.sweep.master_seed, 2016, "not fig7's data sets");
    assert!(!f.study.filter.validate && f.study.filter.trace_every == 0);
    assert_eq!(f.study.sweep.algorithms.len(), 4);
    for a in &f.study.sweep.algorithms {
        let t = &f.thresholds[a.name()];
        for p in PAPER_PARAMS {
            assert!(t.rel_error_mean[p] > 0.0, "{} {p}", a.name());
            assert!(t.ratio_sd[p] > 0.0, "{} {p}", a.name());
        }
        if a.name() != "bootstrap" {
            assert_eq!(
                t.max_failed,
                0,
                "{}: marginalized filters never fail",
                a.name()
            );
        }
    }
    let boot = &f.thresholds["bootstrap"];
    assert!(boot.max_distinct_sampled_mean.is_some_and(|d| d < 10.0));
}

#[test]
fn a_missing_bound_is_rejected() {
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../experiments/regression.toml"),
    )
    .unwrap();
    assert!(RegressionFile::parse(&text, &PAPER_PARAMS).is_ok());
    // A parameter the file has no bound for.
    let err = RegressionFile::parse(&text, &["k1", "k4"]).unwrap_err();
    assert!(format!("{err:#}").contains("`k4`"), "{err:#}");
    // The bounds of one algorithm of the sweep removed.
    let cut = text.replace("[thresholds.storvik", "[unused.storvik");
    assert!(RegressionFile::parse(&cut, &PAPER_PARAMS).is_err());
}

#[test]
fn statistics_at_the_bounds_pass_and_each_synthetic_breach_is_flagged() {
    let f = file();
    let algs: Vec<&str> = f.study.sweep.algorithms.iter().map(|a| a.name()).collect();
    let base: Vec<AlgorithmStats> = algs.iter().map(|a| at_bounds(&f, a)).collect();
    let none = BTreeMap::new();
    let checks = evaluate(&f.thresholds, &base, &none);
    // failed + 9 + 9 per algorithm, + 9 degeneracy checks for the bootstrap PF.
    assert_eq!(checks.len(), 4 * 19 + 9);
    assert!(checks.iter().all(|c| c.ok()), "{}", format_table(&checks));

    // One statistic a hair above its bound: exactly one breach, on that statistic.
    let mut s = base.clone();
    s[2].params[4].rel_error_mean *= 1.0 + 1e-9;
    let c = evaluate(&f.thresholds, &s, &none);
    let breaches: Vec<_> = c.iter().filter(|c| !c.ok()).collect();
    assert_eq!(breaches.len(), 1);
    assert_eq!(
        (
            breaches[0].algorithm.as_str(),
            breaches[0].quantity.as_str(),
            breaches[0].parameter.as_str()
        ),
        (algs[2], "rel_error_mean", "c2")
    );

    let mut s = base.clone();
    s[0].params[0].ratio_sd += 0.01;
    s[1].failed += 1;
    let b = s.iter().position(|a| a.algorithm == "bootstrap").unwrap();
    s[b].distinct_sampled_mean.insert("k1".into(), 150.0);
    let c = evaluate(&f.thresholds, &s, &none);
    let mut flagged: Vec<(String, String)> = c
        .iter()
        .filter(|c| !c.ok())
        .map(|c| (c.quantity.clone(), c.parameter.clone()))
        .collect();
    flagged.sort();
    assert_eq!(
        flagged,
        [
            ("distinct_sampled_mean".to_string(), "k1".to_string()),
            ("failed".into(), "".into()),
            ("ratio_sd".into(), "k1".into()),
        ]
    );
    assert_eq!(format_table(&c).matches("BREACH").count(), 3);

    // A NaN statistic (e.g. every run failed) and a missing algorithm are breaches.
    let mut s = base.clone();
    s[0].params[8].ratio_sd = f64::NAN;
    s.pop();
    let c = evaluate(&f.thresholds, &s, &none);
    assert!(c
        .iter()
        .any(|c| !c.ok() && c.parameter == "n" && c.quantity == "ratio_sd"));
    assert!(c.iter().filter(|c| c.algorithm == algs[3]).all(|c| !c.ok()));
}

fn defaults_file() -> RegressionFile {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../experiments/regression-defaults.toml");
    RegressionFile::load(&path).expect("experiments/regression-defaults.toml")
}

#[test]
fn the_defaults_regression_file_runs_the_settings_of_sysid_filter() {
    let f = defaults_file();
    assert_eq!(f.study.data.preset, "paper-3dof");
    // Every job runs what `sysid filter` uses without --config on this structure (3 storeys,
    // every storey measured), but keeps no trace, loops or validation.
    for job in f.study.jobs() {
        let mut expected = FilterSettings::recommended_for(job.algorithm, 3, &[]);
        expected.trace_every = 0;
        expected.loop_every = 0;
        expected.validate = false;
        assert_eq!(
            f.study.settings(&job).unwrap(),
            expected,
            "{}",
            job.algorithm.name()
        );
    }
    // The three marginalised filters never fail and have a coverage bound.
    for alg in ["mln-rbpf", "storvik", "mpf-ekf2"] {
        let t = &f.thresholds[alg];
        assert_eq!(t.max_failed, 0, "{alg}");
        assert!(t.min_coverage95_kc.is_some_and(|c| c > 0.5), "{alg}");
    }
}

/// The regression file `experiments/<file>` of the MPF-EKF2 on the `storeys`-storey building:
/// every job runs what `sysid filter` uses there without --config (but keeps no trace, loops or
/// validation), no run may fail, and every parameter of the model has both bounds.
fn building_defaults_file(file: &str, storeys: usize, parameters: usize) -> RegressionFile {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../experiments")
        .join(file);
    let f = RegressionFile::load(&path).expect(file);
    let names = f.study.param_names().unwrap();
    assert_eq!(names.len(), parameters, "{names:?}");
    assert_eq!(f.study.sweep.structures[0].storeys, storeys);
    for job in f.study.jobs() {
        let mut expected = FilterSettings::recommended_for(job.algorithm, storeys, &[]);
        expected.trace_every = 0;
        expected.loop_every = 0;
        expected.validate = false;
        assert_eq!(f.study.settings(&job).unwrap(), expected);
    }
    let t = &f.thresholds["mpf-ekf2"];
    assert_eq!(t.max_failed, 0);
    for p in &names {
        assert!(
            t.rel_error_mean.contains_key(p) && t.ratio_sd.contains_key(p),
            "{p}"
        );
    }
    f
}

/// The 5-storey file runs what `sysid filter` uses without --config there (one shared prior
/// Gaussian, the rejuvenation of n, `substeps = "auto"`, which takes four sub-steps on this
/// building against the velocity lag), and bounds every parameter of the 5-storey model.
#[test]
fn the_five_storey_regression_file_runs_the_settings_of_sysid_filter() {
    let f = building_defaults_file("regression-defaults-n5.toml", 5, 13);
    let t = &f.thresholds["mpf-ekf2"];
    assert!(t.min_coverage95_kc.is_some_and(|c| c > 0.5));
    // The roof, whose bias the sub-steps remove: with one step per sample its mean error was
    // 5.3 % on the same data sets (docs/calibration.md, "Regression bounds of the default
    // settings"), above its bound.
    assert!(t.rel_error_mean["k5"] < 0.05, "{}", t.rel_error_mean["k5"]);
}

/// The 10-storey file runs what `sysid filter` uses without --config there (a prior mean per
/// particle, no rejuvenation, `substeps = "auto"`, which takes one step from ten storeys on),
/// and bounds every parameter of the 10-storey model and the coverage of k and c.
#[test]
fn the_ten_storey_regression_file_runs_the_settings_of_sysid_filter() {
    let f = building_defaults_file("regression-defaults-n10.toml", 10, 23);
    let t = &f.thresholds["mpf-ekf2"];
    // One shared prior Gaussian in its place (what a change that lost the 10-storey rule would
    // run) covered 88/120 = 0.73 of k and c on the same data sets, below the bound, and breached
    // 43 of the file's 47 bounds (docs/calibration.md, "Regression bounds of the default
    // settings").
    assert!(
        t.min_coverage95_kc.is_some_and(|c| c > 0.8),
        "{:?}",
        t.min_coverage95_kc
    );
}

/// Run `i` of one algorithm: every parameter's 95 % interval is θ_true ± 5 %, shifted off the
/// truth for the first `missed` of k1, k2, k3, c1, c2, c3.
fn covering(i: u64, missed: usize) -> RunRecord {
    let mut r = common::record("mpf-ekf2", i, [1.0; 9], 0.05);
    r.credible = common::NAMES
        .iter()
        .enumerate()
        .map(|(j, name)| {
            let t = common::THETA_TRUE[j];
            let centre = if j < missed { 1.2 * t } else { t };
            ParamIntervals {
                parameter: name.to_string(),
                shape: PosteriorShape::GaussianMixture,
                intervals: STANDARD_LEVELS
                    .iter()
                    .map(|&level| CredibleInterval {
                        level,
                        lo: centre - 0.05 * t,
                        hi: centre + 0.05 * t,
                    })
                    .collect(),
                error: None,
                mc_se: None,
            }
        })
        .collect();
    r
}

#[test]
fn coverage_counted_from_records_and_breached_below_the_bound() {
    // 10 runs: runs 0–4 miss one k or c of six, runs 5–9 none: 55 of 60 covered.
    let records: Vec<RunRecord> = (0..10).map(|i| covering(i, usize::from(i < 5))).collect();
    let refs: Vec<&RunRecord> = records.iter().collect();
    let c = kc_coverage95(&refs);
    assert_eq!((c.pairs, c.runs), (60, 10));
    assert!((c.fraction - 55.0 / 60.0).abs() < 1e-12, "{c:?}");
    // s.e.: the larger of the binomial one (0.0357) and the one over runs (per-run fractions
    // 5/6 and 1, s.d. 0.0878, / √10 = 0.0278).
    let binomial = (55.0 / 60.0 * 5.0 / 60.0 / 60.0_f64).sqrt();
    assert!((c.std_error - binomial).abs() < 1e-12, "{c:?}");

    // Against the defaults file's MPF-EKF2 bound: a coverage at the bound passes, the same
    // records with more intervals off the truth breach it.
    let f = defaults_file();
    let bound = f.thresholds["mpf-ekf2"].min_coverage95_kc.unwrap();
    let at: BTreeMap<String, KcCoverage> = [(
        "mpf-ekf2".to_string(),
        KcCoverage {
            fraction: bound,
            ..c
        },
    )]
    .into();
    let checks = evaluate_coverage(&f.thresholds, &at);
    let mpf: Vec<_> = checks
        .iter()
        .filter(|c| c.algorithm == "mpf-ekf2")
        .collect();
    assert_eq!(mpf.len(), 1);
    assert!(mpf[0].ok());
    // Three of six missed in every run: coverage 0.5, below every bound of the file.
    let worse: Vec<RunRecord> = (0..10).map(|i| covering(i, 3)).collect();
    let worse: Vec<&RunRecord> = worse.iter().collect();
    let w = kc_coverage95(&worse);
    assert!((w.fraction - 0.5).abs() < 1e-12);
    let checks = evaluate_coverage(&f.thresholds, &[("mpf-ekf2".to_string(), w)].into());
    let mpf: Vec<_> = checks
        .iter()
        .filter(|c| c.algorithm == "mpf-ekf2")
        .collect();
    assert!(!mpf[0].ok(), "{}", format_table(&checks));
    // Algorithms with a bound but no coverage measured are breaches too.
    assert!(checks
        .iter()
        .filter(|c| c.algorithm != "mpf-ekf2")
        .all(|c| !c.ok()));
}
