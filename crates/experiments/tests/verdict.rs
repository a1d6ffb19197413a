//! The report's verdicts on constructed Fig. 7 sweeps where each verdict is known by
//! construction: clear differences (holds), reversed ones (does not hold) and differences
//! smaller than their standard error (not resolved). The statements are the ones
//! `experiments/fig7.toml` declares.

mod common;

use common::{record, wiggle};
use experiments::record::RunRecord;
use experiments::study::Study;
use experiments::verdict::{paper_findings, Declared, Finding, Verdict};

const RUNS: u64 = 20;

/// The statements of the Fig. 7 study file.
fn statements() -> Vec<Declared> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../experiments/fig7.toml");
    Study::load(std::path::Path::new(path)).unwrap().verdicts
}

fn findings(records: &[RunRecord]) -> Vec<Finding> {
    paper_findings(&statements(), &[], records)
}

/// Ratios θ_val/θ_true of one run: stiffnesses `k`, dampings `c1, c2, c3`, then β, γ, n.
fn ratios(k: f64, c: [f64; 3], beta: f64) -> [f64; 9] {
    [k, k, k, c[0], c[1], c[2], beta, 1.0, 1.0]
}

fn find<'a>(findings: &'a [Finding], needle: &str) -> &'a Finding {
    findings
        .iter()
        .find(|f| f.statement.contains(needle))
        .unwrap_or_else(|| panic!("no statement containing `{needle}` in {findings:#?}"))
}

fn assert_verdict(findings: &[Finding], needle: &str, expected: Verdict) {
    let f = find(findings, needle);
    assert_eq!(
        f.verdict, expected,
        "`{}`: test `{}`, evidence `{}`",
        f.statement, f.test, f.evidence
    );
}

/// A bootstrap run whose sampled parameters kept `distinct` values each.
fn bootstrap(run: u64, distinct: usize) -> RunRecord {
    let mut r = record("bootstrap", run, ratios(1.1, [1.3, 1.3, 1.3], 1.5), 0.2);
    for n in common::NAMES {
        r.distinct_sampled.insert(n.to_string(), distinct);
    }
    r
}

/// Scenario with clear differences, in the paper's direction.
fn clear() -> Vec<RunRecord> {
    let mut out = Vec::new();
    for run in 0..RUNS {
        let w = |s| wiggle(run, s);
        out.push(record(
            "mln-rbpf",
            run,
            ratios(
                1.02 + 0.01 * w(1),
                [1.0 + 0.02 * w(2), 1.3 + 0.02 * w(3), 1.0 + 0.02 * w(4)],
                1.9,
            ),
            0.09 + 0.005 * w(5),
        ));
        out.push(record(
            "storvik",
            run,
            ratios(
                1.04 + 0.01 * w(6),
                [1.0 + 0.02 * w(7), 1.3 + 0.02 * w(8), 1.0 + 0.02 * w(9)],
                1.9,
            ),
            0.09 + 0.005 * w(10),
        ));
        out.push(record(
            "mpf-ekf2",
            run,
            ratios(
                1.005 + 0.002 * w(11),
                [
                    1.0 + 0.004 * w(12),
                    1.6 + 0.004 * w(13),
                    1.0 + 0.004 * w(14),
                ],
                1.8,
            ),
            0.05 + 0.005 * w(15),
        ));
        out.push(bootstrap(run, 1));
    }
    out
}

#[test]
fn clear_differences_hold() {
    let f = findings(&clear());
    use Verdict::Holds;
    assert_verdict(&f, "bootstrap PF collapses", Holds);
    assert_verdict(&f, "MLN-RBPF better than Storvik on stiffness", Holds);
    assert_verdict(&f, "lower online state NRMSE", Holds);
    assert_verdict(&f, "MPF-EKF2 as good as MLN-RBPF on stiffness", Holds);
    assert_verdict(&f, "much lower run-to-run s.d.", Holds);
    assert_verdict(&f, "stiffness accurate", Holds);
    assert_verdict(&f, "c1, c3 good", Holds);
    assert_verdict(&f, "c2 over-estimated", Holds);
    assert_verdict(&f, "≈ 20% mean error on dampings", Holds);
    assert_verdict(&f, "γ, n fair", Holds);
    assert_verdict(&f, "β over-estimated", Holds);
    assert_verdict(&f, "β poor", Holds);
    assert_verdict(&f, "validation run matches", Holds);
    assert_verdict(&f, "no run of a marginalized filter fails", Holds);
    assert_verdict(&f, "validation loop misses", Holds);
    // MPF-EKF2's damping error (20%) exceeds MLN-RBPF's (10%) by more than the 5-point margin.
    assert_verdict(&f, "as good as MLN-RBPF on damping", Verdict::DoesNotHold);
    // Every statement says what decides it.
    for x in &f {
        assert!(!x.test.is_empty() && !x.evidence.is_empty(), "{x:?}");
    }
}

#[test]
fn reversed_differences_do_not_hold() {
    let mut recs = Vec::new();
    for run in 0..RUNS {
        let w = |s| wiggle(run, s);
        // Storvik better than the MLN-RBPF; c1 and c3 off by 25%; c2 under-estimated; MPF-EKF2
        // with the higher state error and the larger spread; β slightly under-estimated (fair,
        // not poor).
        recs.push(record(
            "mln-rbpf",
            run,
            ratios(
                1.04 + 0.002 * w(1),
                [1.25 + 0.01 * w(2), 0.8 + 0.01 * w(3), 1.25 + 0.01 * w(4)],
                0.9 + 0.01 * w(16),
            ),
            0.05 + 0.005 * w(5),
        ));
        recs.push(record(
            "storvik",
            run,
            ratios(
                1.02 + 0.002 * w(6),
                [1.25 + 0.01 * w(7), 0.8 + 0.01 * w(8), 1.25 + 0.01 * w(9)],
                0.9 + 0.01 * w(16),
            ),
            0.05 + 0.005 * w(10),
        ));
        recs.push(record(
            "mpf-ekf2",
            run,
            ratios(
                1.10 + 0.05 * w(11),
                [1.25 + 0.1 * w(12), 0.8 + 0.1 * w(13), 1.25 + 0.1 * w(14)],
                0.9 + 0.01 * w(16),
            ),
            0.09 + 0.005 * w(15),
        ));
        recs.push(bootstrap(run, 50));
    }
    // One failed MLN-RBPF run.
    recs[0].failure = Some("all weights zero at step 12".into());
    let f = findings(&recs);
    use Verdict::DoesNotHold;
    assert_verdict(&f, "bootstrap PF collapses", DoesNotHold);
    assert_verdict(&f, "MLN-RBPF better than Storvik on stiffness", DoesNotHold);
    assert_verdict(&f, "lower online state NRMSE", DoesNotHold);
    assert_verdict(&f, "much lower run-to-run s.d.", DoesNotHold);
    assert_verdict(&f, "stiffness accurate", DoesNotHold);
    assert_verdict(&f, "c1, c3 good", DoesNotHold);
    assert_verdict(&f, "c2 over-estimated", DoesNotHold);
    assert_verdict(&f, "β over-estimated", DoesNotHold);
    assert_verdict(&f, "β poor", DoesNotHold);
    assert_verdict(&f, "no run of a marginalized filter fails", DoesNotHold);
    // The failed run is left out of the pairs.
    let pairs = find(&f, "MLN-RBPF better than Storvik on stiffness");
    assert!(pairs.evidence.contains("n = 19"), "{}", pairs.evidence);
}

#[test]
fn differences_within_two_standard_errors_are_not_resolved() {
    let mut recs = Vec::new();
    for run in 0..RUNS {
        // ±: equal means, a run-to-run difference that averages to exactly zero.
        let alt = if run % 2 == 0 { 1.0 } else { -1.0 };
        let w = |s| wiggle(run, s);
        let base_k = 1.03 + 0.005 * w(1);
        let c = [1.1 + 0.05 * alt, 1.3, 1.1 - 0.05 * alt];
        recs.push(record(
            "mln-rbpf",
            run,
            ratios(base_k, c, 1.3 + 0.2 * alt),
            0.07 + 0.01 * w(2),
        ));
        recs.push(record(
            "storvik",
            run,
            ratios(base_k + 0.01 * alt, c, 1.3 + 0.2 * alt),
            0.07 + 0.01 * w(3),
        ));
        recs.push(record(
            "mpf-ekf2",
            run,
            ratios(base_k, c, 1.3 + 0.2 * alt),
            0.07 + 0.01 * w(2) + 0.01 * alt,
        ));
    }
    let f = findings(&recs);
    use Verdict::NotResolved;
    assert_verdict(&f, "MLN-RBPF better than Storvik on stiffness", NotResolved);
    assert_verdict(&f, "lower online state NRMSE", NotResolved);
    assert_verdict(&f, "c1, c3 good", NotResolved);
    assert_verdict(&f, "β poor", NotResolved);
    // No bootstrap runs: the collapse statement is left out, not guessed.
    assert!(f
        .iter()
        .all(|x| !x.statement.contains("bootstrap PF collapses")));
}

#[test]
fn every_declared_statement_is_decided() {
    let f = findings(&clear());
    let declared = statements();
    assert_eq!(f.len(), declared.len(), "{f:#?}");
    for (x, d) in f.iter().zip(&declared) {
        assert_eq!(x.statement, d.statement);
    }
}

/// A statement declared in a study file alone, with no code of its own, is decided by its
/// test; both directions, by construction (online NRMSE: MPF-EKF2 0.05, Storvik 0.09).
#[test]
fn a_new_statement_needs_only_its_declaration() {
    let text = r#"
name = "declared"
description = "statements declared in the file"
[data]
preset = "paper-3dof"
[sweep]
algorithms = ["storvik", "mpf-ekf2"]
runs = 2
master_seed = 1
[[verdicts]]
statement = "MPF-EKF2 tracks the states within 0.07"
test = "below"
metric = "online-nrmse"
algorithms = ["mpf-ekf2"]
threshold = 0.07
[[verdicts]]
statement = "Storvik tracks the states within 0.07"
test = "below"
metric = "online-nrmse"
algorithms = ["storvik"]
threshold = 0.07
"#;
    let dir = std::env::temp_dir().join(format!("sysid-verdict-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("declared.toml");
    std::fs::write(&path, text).unwrap();
    let study = Study::load(&path).unwrap();
    let f = paper_findings(&study.verdicts, &[], &clear());
    assert_verdict(&f, "MPF-EKF2 tracks", Verdict::Holds);
    assert_verdict(&f, "Storvik tracks", Verdict::DoesNotHold);
    assert!(find(&f, "MPF-EKF2 tracks").test.contains("< 0.07"));
    // A declaration the sweep cannot decide is refused when the file is read, naming it.
    std::fs::write(&path, text.replace("[\"storvik\"]", "[\"mln-rbpf\"]")).unwrap();
    let e = format!("{:#}", Study::load(&path).unwrap_err());
    assert!(
        e.contains("Storvik tracks") && e.contains("`mln-rbpf` is not one of the sweep's"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
