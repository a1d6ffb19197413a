//! Coverage of a sweep from its run records (SPEC §9 "Calibration"): hand-made records whose
//! answers are known, read back from JSON like the records of a sweep, through the one
//! record → posterior extraction that `summary.json` and `REPORT.md` use.

use crate::common;

use common::{record, NAMES, THETA_TRUE};
use core_filters::credible::{CredibleInterval, STANDARD_LEVELS};
use experiments::calibration::Verdict;
use experiments::coverage::{report_section, run_posterior, sweep_coverage, Missing};
use identify::observe::{ParamIntervals, PosteriorShape};
use identify::record::RunRecord;

/// Half-widths of the 50, 90 and 95 % intervals for a parameter whose truth is 8 (scaled with
/// the truth for the others).
const HALF: [f64; 3] = [0.2, 0.45, 0.6];

/// Run `i`: k1's θ_val is 8 + 0.08 i, every other parameter's is the truth; each interval is
/// θ_val ± HALF. So k1's truth lies in the 50 % interval for i ≤ 2, in the 90 % one for i ≤ 5,
/// in the 95 % one for i ≤ 7; every other parameter's in all of them.
fn run(i: u64) -> RunRecord {
    let mut ratios = [1.0; 9];
    ratios[0] = 1.0 + 0.01 * i as f64;
    let mut r = record("mpf-ekf2", i, ratios, 0.05);
    r.credible = NAMES
        .iter()
        .enumerate()
        .map(|(j, name)| ParamIntervals {
            parameter: name.to_string(),
            shape: if *name == "n" {
                PosteriorShape::WeightedSample
            } else {
                PosteriorShape::GaussianMixture
            },
            intervals: STANDARD_LEVELS
                .iter()
                .zip(HALF)
                .map(|(&level, h)| {
                    let h = h * THETA_TRUE[j] / 8.0;
                    CredibleInterval {
                        level,
                        lo: r.theta_val[j] - h,
                        hi: r.theta_val[j] + h,
                    }
                })
                .collect(),
            error: None,
            mc_se: None,
        })
        .collect();
    // Through JSON, as a sweep reads its records.
    serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap()
}

#[test]
fn coverage_of_hand_made_records() {
    let mut records: Vec<RunRecord> = (0..12).map(run).collect();
    // A failed run and a run without intervals (an older record) are left out and counted.
    let mut failed = run(12);
    failed.failure = Some("all weights zero at step 7".into());
    failed.steps_completed = 6;
    records.push(failed);
    let mut old = run(13);
    old.credible.clear();
    records.push(old);
    let group: Vec<&RunRecord> = records.iter().collect();
    let c = sweep_coverage("hand", &[("mpf-ekf2", group)])
        .unwrap()
        .expect("the records know the truth");

    assert_eq!(c.param_names, NAMES);
    assert_eq!(c.theta_true, THETA_TRUE);
    let e = &c.excluded[0];
    assert_eq!((e.records, e.failed, e.without_intervals), (14, 1, 1));
    let a = &c.calibration.algorithms[0];
    assert_eq!(a.algorithm, "mpf-ekf2");
    let k1 = &a.params[0];
    assert_eq!(k1.parameter, "k1");
    assert_eq!(k1.runs, 12);
    let covered: Vec<usize> = k1.coverage.iter().map(|l| l.covered).collect();
    assert_eq!(covered, vec![3, 6, 8]);
    // 90 %: 6 of 12 = 0.5 against 0.9 ± 2·√(0.09/12) = 0.9 ± 0.17: over-confident.
    assert_eq!(k1.coverage[1].coverage, Some(0.5));
    assert_eq!(k1.coverage[1].verdict, Verdict::OverConfident);
    // z for run i: 0.08 i / 0.4 = 0.2 i (the common records' s.d. is 5 % of the truth).
    let z_mean = k1.z.mean.unwrap();
    assert!((z_mean - 0.2 * 5.5).abs() < 1e-12, "{z_mean}");
    for p in &a.params[1..] {
        let covered: Vec<usize> = p.coverage.iter().map(|l| l.covered).collect();
        assert_eq!(covered, vec![12, 12, 12], "{}", p.parameter);
        // 12 of 12 at 50 %: wider than they should be.
        assert_eq!(p.coverage[0].verdict, Verdict::UnderConfident);
    }

    let mut md = String::new();
    report_section(&mut md, "hand-made", &c);
    assert!(md.contains("k1 = 8"), "{md}");
    assert!(md.contains("| mpf-ekf2 | k1 | 12 | 0.25 ± 0.12"), "{md}");
    assert!(md.contains("1 failed, 1 without intervals (of 14)"), "{md}");
    // summary.json form: serialisable, numbers not NaN.
    let json = serde_json::to_string(&c).unwrap();
    assert!(!json.contains("NaN"), "{json}");
}

#[test]
fn what_a_record_cannot_say_is_named() {
    let mut r = run(0);
    assert!(run_posterior(&r, 0).is_ok());
    r.credible[3].error = Some("the posterior has no particles".into());
    r.credible[3].intervals.clear();
    assert_eq!(run_posterior(&r, 3), Err(Missing::NoInterval));
    r.theta_true = None;
    assert_eq!(run_posterior(&r, 0), Err(Missing::NoTruth));
    r.failure = Some("failed".into());
    assert_eq!(run_posterior(&r, 0), Err(Missing::Failed));
    // Field data: no coverage at all.
    let mut field = run(1);
    field.theta_true = None;
    assert!(sweep_coverage("field", &[("mpf-ekf2", vec![&field])])
        .unwrap()
        .is_none());
    // Records of one sweep with other parameters: an error naming the record.
    let mut other = run(2);
    other.param_names[0] = "k9".into();
    let a = run(3);
    let err = sweep_coverage("mixed", &[("mpf-ekf2", vec![&a, &other])]).unwrap_err();
    assert!(err.to_string().contains("mpf-ekf2 run 2"), "{err}");
}

#[test]
fn records_without_intervals_still_load() {
    let mut v = serde_json::to_value(record("storvik", 0, [1.0; 9], 0.1)).unwrap();
    v.as_object_mut().unwrap().remove("credible");
    let r: RunRecord = serde_json::from_value(v).unwrap();
    assert!(r.credible.is_empty());
    assert_eq!(run_posterior(&r, 0), Err(Missing::NoInterval));
}

#[test]
fn pooled_stiffness_and_damping_coverage() {
    // 10 runs × 6 storey parameters; k1's truth leaves the 95 % interval from run 8 on, every
    // other parameter is covered: 60 pairs, 58 covered. A failed run counts no pair.
    let mut records: Vec<RunRecord> = (0..10).map(run).collect();
    let mut failed = run(11);
    failed.failure = Some("all weights zero".into());
    records.push(failed);
    let refs: Vec<&RunRecord> = records.iter().collect();
    let (fraction, pairs) = experiments::coverage::stiffness_damping_coverage(&refs, 0.95);
    assert_eq!(pairs, 60);
    assert!((fraction - 58.0 / 60.0).abs() < 1e-12, "{fraction}");
    // At 50 %: k1 covered for runs 0–2 only.
    let (f50, _) = experiments::coverage::stiffness_damping_coverage(&refs, 0.5);
    assert!((f50 - 53.0 / 60.0).abs() < 1e-12, "{f50}");
}
