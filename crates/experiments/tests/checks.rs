//! Plausibility warnings and the exit decision of `sysid filter` (`identification::finish` and
//! `Finished::verdict`, what the binary calls after a run) on constructed records.

use crate::common;

use common::record;
use core_filters::credible::CredibleInterval;
use identify::checks::{check, summary_table, WarningKind};
use identify::identification::{finish, Rejected};
use identify::observe::{ParamIntervals, PosteriorShape};
use identify::record::RunRecord;

/// The exit decision on a finished run: its record written, then accepted or rejected.
fn finish_run(r: RunRecord, path: &std::path::Path) -> Result<(), Rejected> {
    finish(r, path).expect("the record is written").verdict()
}

/// `run.json` in a fresh directory under the system temp dir, and the guard that removes the
/// directory when dropped (also when the test panics).
fn out_path(test: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("checks-test-{test}-"))
        .tempdir()
        .unwrap();
    let path = tmp.path().join("run.json");
    (tmp, path)
}

fn healthy() -> RunRecord {
    record("mln-rbpf", 0, [1.0; 9], 0.05)
}

fn written(path: &std::path::Path) -> RunRecord {
    serde_json::from_str(&std::fs::read_to_string(path).expect("record written"))
        .expect("a run record")
}

#[test]
fn a_healthy_run_has_no_warnings_and_succeeds() {
    let r = healthy();
    assert!(check(&r).is_empty(), "{:?}", check(&r));
    let (_tmp, path) = out_path("healthy");
    finish_run(r, &path).expect("a healthy run exits successfully");
    assert!(written(&path).warnings.is_empty());
}

#[test]
fn a_negative_stiffness_is_impossible_and_exits_non_zero() {
    let mut r = healthy();
    // k3 = −4.43 (the field case of a stiff structure with the paper's priors).
    r.theta_val[2] = -4.43;
    let w = check(&r);
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(w[0].kind, WarningKind::NonPositive);
    assert_eq!(w[0].parameter.as_deref(), Some("k3"));
    assert!(
        w[0].message.contains("physically impossible"),
        "{}",
        w[0].message
    );
    let (_tmp, path) = out_path("negative");
    let err = finish_run(r, &path).expect_err("an impossible result must not exit successfully");
    assert!(err.to_string().contains("physically impossible"), "{err}");
    assert!(err.to_string().contains("k3"), "{err}");
    // The record is still written, with its warning.
    let back = written(&path);
    assert_eq!(back.warnings, w);
    assert_eq!(back.theta_val[2], -4.43);
}

#[test]
fn a_zero_damping_and_a_nan_are_impossible() {
    let mut r = healthy();
    r.theta_val[4] = 0.0;
    r.theta_val[7] = f64::NAN;
    let kinds: Vec<_> = check(&r).iter().map(|w| w.kind).collect();
    assert_eq!(
        kinds,
        vec![WarningKind::NonPositive, WarningKind::NonFinite]
    );
    assert!(finish_run(r, &out_path("zero").1).is_err());
}

#[test]
fn negative_hysteresis_parameters_are_not_flagged() {
    // γ may be negative in the Bouc–Wen model (SPEC §1); only k and c must be positive.
    let mut r = healthy();
    r.theta_val[7] = -0.5;
    assert!(check(&r).is_empty());
}

#[test]
fn few_distinct_values_and_tiny_ess_warn_without_failing() {
    let mut r = healthy();
    r.distinct_sampled.insert("n".into(), 1);
    r.distinct_sampled.insert("beta".into(), 250);
    r.ess_min = 3.0;
    let w = check(&r);
    let kinds: Vec<_> = w.iter().map(|w| w.kind).collect();
    assert_eq!(kinds, vec![WarningKind::FewDistinct, WarningKind::TinyEss]);
    assert_eq!(w[0].parameter.as_deref(), Some("n"));
    let table = summary_table(&r);
    assert!(table.contains("RESTS ON FEW PARTICLES"), "{table}");
    assert!(table.contains("250 distinct values"), "{table}");
    assert!(table.contains("(TINY)"), "{table}");
    let (_tmp, path) = out_path("few");
    finish_run(r, &path).expect("unreliable but possible: warn, exit 0");
    assert_eq!(written(&path).warnings, w);
}

#[test]
fn a_fixed_parameter_is_shown_as_fixed_not_as_a_collapse() {
    // `--fix n=2`: one particle value of n is the user's choice, not a filter that lost it.
    let mut r = healthy();
    r.distinct_sampled.insert("n".into(), 1);
    r.config = serde_json::json!({ "filter": { "fix": { "n": 2.0, "beta": 2.0 } } });
    assert!(check(&r).is_empty(), "{:?}", check(&r));
    let table = summary_table(&r);
    assert!(!table.contains("RESTS ON FEW PARTICLES"), "{table}");
    let fixed: Vec<&str> = table
        .lines()
        .filter(|l| l.ends_with("fixed (point-mass prior)"))
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(fixed, ["beta", "n"], "{table}");
}

#[test]
fn a_failed_run_warns_and_exits_non_zero() {
    let mut r = healthy();
    r.failure = Some("all weights zero at step 412".into());
    r.steps_completed = 411;
    let w = check(&r);
    assert_eq!(w[0].kind, WarningKind::Failed);
    let err = finish_run(r, &out_path("failed").1).unwrap_err();
    assert!(matches!(err, Rejected::Failed { step: 412, .. }), "{err:?}");
    assert!(err.to_string().contains("failed at step 412"), "{err}");
}

#[test]
fn the_summary_table_gives_the_interval_of_every_parameter() {
    let mut r = healthy();
    let table = summary_table(&r);
    // No recorded intervals: k1 θ_val 8, final s.d. 0.4 → *[8 − 0.784, 8 + 0.784], marked.
    assert!(table.contains("*[7.2160, 8.7840]"), "{table}");
    for name in common::NAMES {
        assert!(
            table.lines().any(|l| l.starts_with(name)),
            "{name}: {table}"
        );
    }
    assert!(
        table.contains("θ_val ± 1.96 s.d. where the record"),
        "{table}"
    );
    // With the record's intervals, the 95 % one is shown (not the 50 or 90 %), unmarked.
    r.credible = vec![ParamIntervals {
        parameter: "k1".into(),
        shape: PosteriorShape::GaussianMixture,
        intervals: [(0.5, 7.9, 8.1), (0.9, 7.5, 8.6), (0.95, 7.25, 8.75)]
            .iter()
            .map(|&(level, lo, hi)| CredibleInterval { level, lo, hi })
            .collect(),
        error: None,
        mc_se: None,
    }];
    let table = summary_table(&r);
    let k1 = table.lines().find(|l| l.starts_with("k1")).unwrap();
    assert!(k1.contains(" [7.2500, 8.7500]"), "{table}");
    // The other parameters still have no interval in the record.
    assert!(table.contains("*["), "{table}");
}

#[test]
fn records_without_warnings_still_load() {
    let mut v = serde_json::to_value(healthy()).unwrap();
    v.as_object_mut().unwrap().remove("warnings");
    let r: RunRecord = serde_json::from_value(v).expect("warnings default to none");
    assert!(r.warnings.is_empty());
}

#[test]
fn a_filter_left_out_of_its_pool_is_a_warning_written_into_the_record_and_not_fatal() {
    use identify::record::diagnostics::{LeftOutFilter, LeftOutReason};
    let r = healthy();
    // Eight pooled filters: the settings and their fingerprint.
    let filter = serde_json::json!({ "particles": r.particles, "window": r.window, "pool": 8 });
    let mut r = common::sealed_with(r, filter);
    r.pool_left_out = vec![LeftOutFilter {
        filter: 3,
        reason: LeftOutReason::Lost,
        failure_kind: None,
        tail_loglik: Some(-1.0e5),
        median_tail_loglik: Some(-3.0),
        message: "it predicted the measurements far worse".into(),
    }];
    let w = check(&r);
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(w[0].kind, WarningKind::LeftOut);
    assert!(
        w[0].message.contains("filter 3 of the pool's 8")
            && w[0].message.contains("lost track of the record")
            && w[0].message.contains("rests on 7 filters"),
        "{}",
        w[0].message
    );
    let (_tmp, path) = out_path("left-out");
    finish_run(r, &path).expect("a pool that kept a majority answers");
    let back = written(&path);
    assert_eq!(back.pool_left_out.len(), 1);
    assert_eq!(back.pool_left_out[0].reason, LeftOutReason::Lost);
    assert_eq!(back.warnings[0].kind, WarningKind::LeftOut);
}

#[test]
fn a_parameter_held_at_its_physical_bound_is_flagged_but_not_rejected() {
    let mut r = healthy();
    let prior = models::filtering::ChainPrior::paper(3, &[0]);
    let means = prior.moments().0;
    r.config = serde_json::json!({ "spec": { "prior": prior } });
    // c2 (θ index 4) at 0.1 % of its prior mean, after truncations.
    r.theta_val[4] = 1e-3 * means[4];
    r.health.truncated = 7;
    let w = check(&r);
    let at: Vec<_> = w
        .iter()
        .filter(|w| w.kind == WarningKind::AtBound)
        .collect();
    assert_eq!(at.len(), 1, "{w:?}");
    assert_eq!(at[0].parameter.as_deref(), Some("c2"));
    assert!(!WarningKind::AtBound.is_fatal());
    // Without a truncation the same value is a small damping, not one held at the bound.
    r.health.truncated = 0;
    assert!(check(&r).iter().all(|w| w.kind != WarningKind::AtBound));
}

#[test]
fn the_real_time_factor_is_seconds_of_record_per_second_of_computation() {
    let mut r = healthy();
    r.config = serde_json::json!({ "spec": { "dt": 0.01 } });
    r.steps_completed = 1000;
    r.timing.wall_s = 2.0;
    assert_eq!(identify::identification::realtime_factor(&r), Some(5.0));
    r.timing.wall_s = 0.0;
    assert_eq!(identify::identification::realtime_factor(&r), None);
    r.config = serde_json::json!({});
    r.timing.wall_s = 2.0;
    assert_eq!(identify::identification::realtime_factor(&r), None);
}
