//! Every number a record holds is written with the one encoding of `record::number` (finite
//! numbers as JSON numbers, NaN and ±∞ as `"NaN"`, `"inf"`, `"-inf"`) and read back by every
//! reader: records with random non-finite values in every numeric field, written as the commands
//! write them, read through `record::read` (a resumed sweep, `merge`, `compare-reference`,
//! `reference --start-from`), `sysid plot`'s reader and drawing, and `merge`; reference records
//! likewise. A structural check makes "every numeric field" hold for fields added later: every
//! non-integer number in a written record is replaced by `"NaN"` in turn, and the record must
//! still parse.

use crate::common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use core_filters::credible::CredibleInterval;
use experiments::reference::ParamSummary;
use experiments::reference::ReferenceRecord;
use identify::checks::{Residuals, Warning, WarningKind};
use identify::metrics::{SignalError, StateErrors};
use identify::observe::{ParamIntervals, PosteriorShape, Trace};
use identify::record::read::{parse, read, write};
use identify::record::{Loop, RunRecord, Validation};
use identify::residuals::ChannelCheck;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-numbers-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// A number of a record: finite (with a fractional part, so that JSON writes it as a float) or
/// one of the three non-finite values, each often enough to meet every field.
fn num() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => (-1e6f64..1e6).prop_map(|x| x.trunc() + 0.25),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
    ]
}

fn nums(n: usize) -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(num(), n)
}

const P: usize = 9;
const STATES: usize = 7;
const KEPT: usize = 6;
const CHANNELS: usize = 3;

fn state_errors(v: Vec<f64>) -> StateErrors {
    StateErrors {
        names: (0..STATES).map(|i| format!("s{i}")).collect(),
        errors: v
            .chunks_exact(3)
            .map(|c| SignalError {
                rmse: c[0],
                cv_rmse: c[1],
                nrmse: c[2],
            })
            .collect(),
    }
}

/// A complete run record of the paper's 9 parameters whose every `f64` comes from `v` (in a
/// fixed order), with every optional block present.
fn record_from(v: &[f64]) -> RunRecord {
    let mut it = v.iter().copied();
    let mut take = |n: usize| -> Vec<f64> { (&mut it).take(n).collect() };
    let mut r = common::record("mpf-ekf2", 0, [1.0; 9], 0.05);
    r.theta_true = Some(take(P));
    r.theta_val = take(P);
    r.theta_sd_final = take(P);
    r.rel_error = Some(take(P));
    r.loglik = take(1)[0];
    r.ess_min = take(1)[0];
    r.ess_mean = take(1)[0];
    r.online_states = Some(state_errors(take(3 * STATES)));
    r.validation = Some(Validation {
        states: state_errors(take(3 * STATES)),
        loop_validation: Some(Loop {
            x: take(KEPT),
            force: take(KEPT),
        }),
        loop_true: Some(Loop {
            x: take(KEPT),
            force: take(KEPT),
        }),
        error: None,
    });
    r.trace = Trace {
        every: 1,
        t: take(KEPT),
        param_mean: (0..KEPT).map(|_| take(P)).collect(),
        param_sd: (0..KEPT).map(|_| take(P)).collect(),
        ess: take(KEPT),
    };
    let t = take(3);
    r.timing.wall_s = t[0];
    r.timing.particle_steps_per_s = t[1];
    r.timing.validation_s = t[2];
    r.credible = r
        .param_names
        .clone()
        .into_iter()
        .map(|name| {
            let c = take(10);
            ParamIntervals {
                parameter: name,
                shape: PosteriorShape::GaussianMixture,
                intervals: c[..9]
                    .chunks_exact(3)
                    .map(|x| CredibleInterval {
                        level: x[0],
                        lo: x[1],
                        hi: x[2],
                    })
                    .collect(),
                error: None,
                mc_se: Some(c[9]),
            }
        })
        .collect();
    r.innovation_checks = (0..CHANNELS)
        .map(|i| {
            let c = take(4);
            ChannelCheck {
                channel: format!("a{}", i + 1),
                n: 100,
                mean: c[0],
                variance: c[1],
                ljung_box: c[2],
                critical: c[3],
                white: false,
            }
        })
        .collect();
    r.residuals = Some(Residuals {
        t: take(KEPT),
        channels: (1..=CHANNELS).map(|i| format!("a{i}")).collect(),
        measured: (0..KEPT).map(|_| take(CHANNELS)).collect(),
        predicted: (0..KEPT).map(|_| take(CHANNELS)).collect(),
        normalised_innovation: (0..KEPT).map(|_| take(CHANNELS)).collect(),
        noise_sd: take(CHANNELS),
    });
    r.warnings = vec![Warning {
        kind: WarningKind::TinyEss,
        parameter: None,
        message: "constructed".into(),
    }];
    r.distinct_sampled = BTreeMap::from([("k1".to_string(), 3)]);
    assert!(
        it.next().is_none(),
        "the record used fewer numbers than drawn"
    );
    common::sealed(r)
}

/// How many numbers [`record_from`] takes.
const RECORD_NUMBERS: usize = 4 * P
    + 3
    + 2 * 3 * STATES
    + 4 * KEPT
    + KEPT * (2 + 2 * P)
    + 3
    + 10 * P
    + 4 * CHANNELS
    + KEPT * (1 + 3 * CHANNELS);

fn reference_from(v: &[f64]) -> ReferenceRecord {
    let mut it = v.iter().copied();
    let mut take = |n: usize| -> Vec<f64> { (&mut it).take(n).collect() };
    let head = take(6);
    let r = ReferenceRecord {
        data: "d".into(),
        data_sha256: None,
        steps: 200,
        dt: head[0],
        estimator: "mpf-ekf2".into(),
        particles: 10,
        iterations: 100,
        burn_in: 10,
        seed: 1,
        start: take(P),
        loglik_at_start_mean: head[1],
        loglik_at_start_sd: head[2],
        acceptance: head[3],
        acceptance_burn_in: head[4],
        evaluations: 110,
        failed_estimates: 0,
        wall_s: head[5],
        params: (0..P)
            .map(|i| {
                let x = take(9);
                ParamSummary {
                    name: format!("p{i}"),
                    mean: x[0],
                    sd: x[1],
                    // Sorted (a reference's quantiles are in order), non-finite values kept.
                    quantiles: {
                        let mut q = [x[2], x[3], x[4], x[5], x[6]];
                        q.sort_by(f64::total_cmp);
                        q
                    },
                    ess: x[7],
                    truth: Some(x[8]),
                }
            })
            .collect(),
        warnings: Vec::new(),
    };
    assert!(it.next().is_none());
    r
}

const REFERENCE_NUMBERS: usize = 6 + P + 9 * P;

/// The written text of a value, for comparisons in which NaN equals NaN (it is `"NaN"`).
fn text<T: serde::Serialize>(x: &T) -> String {
    serde_json::to_string(x).unwrap()
}

#[test]
fn records_with_non_finite_numbers_in_every_field_read_back_through_every_reader() {
    let (_tmp, dir) = temp_dir("run");
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases: 64,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &[28; 32]),
    );
    let case = std::cell::Cell::new(0usize);
    let non_finite = std::cell::Cell::new(0usize);
    runner
        .run(&nums(RECORD_NUMBERS), |v| {
            case.set(case.get() + 1);
            let case = case.get();
            non_finite.set(non_finite.get() + v.iter().filter(|x| !x.is_finite()).count());
            let r = record_from(&v);
            let path = dir.join(format!("run{case}.json"));
            // The writer of every command reads its record back.
            write(&path, &r).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
            // The one reader (resume, merge, compare-reference, --start-from).
            let back: RunRecord = read(&path).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
            prop_assert_eq!(text(&back), text(&r));
            // `sysid plot`: read and draw (every 8th case: drawing is the slow part).
            if case.is_multiple_of(8) {
                identify::plot::plot(&path, &dir.join(format!("figs{case}")))
                    .map_err(|e| TestCaseError::fail(format!("plot: {e:#}")))?;
            }
            Ok(())
        })
        .unwrap();
    let (case, non_finite) = (case.get(), non_finite.get());
    assert!(non_finite > 1000, "{non_finite} non-finite numbers drawn");
    // `sysid merge` reads them all as sources.
    let part = dir.join("part");
    let s = part.join("records/s");
    std::fs::create_dir_all(&s).unwrap();
    for i in 1..=case {
        std::fs::rename(
            dir.join(format!("run{i}.json")),
            s.join(format!("run{i}.json")),
        )
        .unwrap();
    }
    let pairs = experiments::sweep::study_pairs(&[part], &dir.join("into")).unwrap();
    let report = experiments::sweep::merge::<RunRecord>(&pairs).unwrap();
    assert_eq!(report.copied, case);
}

#[test]
fn reference_records_with_non_finite_numbers_read_back() {
    let (_tmp, dir) = temp_dir("reference");
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases: 200,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &[82; 32]),
    );
    runner
        .run(&nums(REFERENCE_NUMBERS), |v| {
            let r = reference_from(&v);
            let path = dir.join("r.json");
            write(&path, &r).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
            let back: ReferenceRecord =
                read(&path).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
            prop_assert_eq!(text(&back), text(&r));
            Ok(())
        })
        .unwrap();
}

/// Every place of `v` that holds a non-integer number (outside `skip`), as JSON pointers.
fn float_leaves(v: &serde_json::Value, at: String, skip: &[&str], out: &mut Vec<String>) {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => out.push(at),
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                float_leaves(x, format!("{at}/{i}"), skip, out);
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                if !(at.is_empty() && skip.contains(&k.as_str())) {
                    float_leaves(x, format!("{at}/{k}"), skip, out);
                }
            }
        }
        _ => {}
    }
}

/// Each float field of a written record, set to `"NaN"` in turn, still parses: no number of a
/// record is read as a plain `f64` (which would refuse the encoding its writer uses).
fn every_float_takes_the_encoding<R: identify::record::read::Checked + serde::Serialize>(
    record: &R,
    skip: &[&str],
    expected_at_least: usize,
) {
    let value = serde_json::to_value(record).unwrap();
    let mut leaves = Vec::new();
    float_leaves(&value, String::new(), skip, &mut leaves);
    assert!(
        leaves.len() >= expected_at_least,
        "{} float fields found",
        leaves.len()
    );
    for at in &leaves {
        let mut v = value.clone();
        *v.pointer_mut(at).unwrap() = "NaN".into();
        let bytes = serde_json::to_vec(&v).unwrap();
        if let Err(e) = parse::<R>(&bytes, Path::new("probe.json")) {
            panic!("{at}: a non-finite number there does not read back: {e}");
        }
    }
}

#[test]
fn every_float_field_of_a_record_takes_the_non_finite_encoding() {
    let finite: Vec<f64> = (0..RECORD_NUMBERS).map(|i| i as f64 + 0.5).collect();
    // `config` and `fingerprint` hold the run's inputs, whose hash the checks verify; no filter
    // setting can be non-finite (the settings checks refuse it).
    every_float_takes_the_encoding(
        &record_from(&finite),
        &["config", "fingerprint"],
        RECORD_NUMBERS,
    );
    let finite: Vec<f64> = (0..REFERENCE_NUMBERS).map(|i| i as f64 + 0.5).collect();
    every_float_takes_the_encoding(&reference_from(&finite), &[], REFERENCE_NUMBERS);
}
