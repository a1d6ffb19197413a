//! `sysid plot` on a record with truth (trace, loops, residuals: every panel) and on a field
//! record without truth (what is there is drawn, the rest skipped with a note).

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{hysteresis_loop, record, trace, THETA_TRUE};
use identify::checks::Residuals;
use identify::figures::validate_svg;
use identify::plot::plot;
use identify::record::Validation;

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn dir(test: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("plot-test-{test}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// Residuals of a model that fits (white innovations) over `n` steps, three channels.
fn residuals(n: usize) -> Residuals {
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.005).collect();
    let wig = |k: usize, i: usize| 2.0 * common::wiggle(k as u64, i as u64 + 40);
    let measured: Vec<Vec<f64>> = (0..n)
        .map(|k| (0..3).map(|i| (t[k] * (2.0 + i as f64)).sin()).collect())
        .collect();
    let innov: Vec<Vec<f64>> = (0..n)
        .map(|k| (0..3).map(|i| 1.7 * wig(k, i)).collect())
        .collect();
    let predicted = measured
        .iter()
        .zip(&innov)
        .map(|(m, e)| m.iter().zip(e).map(|(a, b)| a - 0.1 * b).collect())
        .collect();
    Residuals {
        t,
        channels: vec!["a1".into(), "a2".into(), "a3".into()],
        measured,
        predicted,
        normalised_innovation: innov,
        noise_sd: vec![0.1; 3],
    }
}

fn write_json(path: &Path, v: &serde_json::Value) {
    std::fs::write(path, serde_json::to_string(v).unwrap()).unwrap();
}

fn texts(path: &Path) -> String {
    validate_svg(path).expect("a well-formed SVG");
    std::fs::read_to_string(path).unwrap()
}

#[test]
fn a_record_with_truth_gives_every_panel() {
    let (_tmp, d) = dir("truth");
    let mut r = record("mpf-ekf2", 0, [1.0; 9], 0.05);
    r.trace = trace(&THETA_TRUE, &THETA_TRUE, 60);
    if let Some(v) = r.validation.as_mut() {
        v.loop_true = Some(hysteresis_loop(8.0));
        v.loop_validation = Some(hysteresis_loop(8.1));
    }
    let mut v = serde_json::to_value(&r).unwrap();
    v.as_object_mut().unwrap().insert(
        "residuals".into(),
        serde_json::to_value(residuals(600)).unwrap(),
    );
    let rec = d.join("run.json");
    write_json(&rec, &v);
    let out = d.join("figs");
    let p = plot(&rec, &out).expect("plots");
    assert!(p.skipped.is_empty(), "{:?}", p.skipped);
    let names = [
        "convergence.svg",
        "ess.svg",
        "hysteresis.svg",
        "accelerations.svg",
        "innovations.svg",
        "innovation_acf.svg",
    ];
    assert_eq!(p.written.len(), names.len());
    for n in names {
        assert!(
            p.written.contains(&out.join(n)),
            "{n} missing: {:?}",
            p.written
        );
    }
    let conv = texts(&out.join("convergence.svg"));
    for name in common::NAMES {
        assert!(conv.contains(name), "panel {name}");
    }
    assert!(conv.contains("true value"));
    let hyst = texts(&out.join("hysteresis.svg"));
    assert!(hyst.contains("true loop") && hyst.contains("validation loop"));
    let acc = texts(&out.join("accelerations.svg"));
    assert!(acc.contains("measured") && acc.contains("predicted"));
    for ch in ["a1", "a2", "a3"] {
        assert!(acc.contains(ch));
    }
    let acf = texts(&out.join("innovation_acf.svg"));
    assert_eq!(
        acf.matches("consistent with white").count(),
        3,
        "white innovations"
    );
    texts(&out.join("innovations.svg"));
    texts(&out.join("ess.svg"));
}

#[test]
fn a_field_record_draws_what_it_has_through_the_binary() {
    let (_tmp, d) = dir("field");
    let mut r = record("mln-rbpf", 0, [1.0; 9], 0.05);
    r.theta_true = None;
    r.rel_error = None;
    r.online_states = None;
    r.validation = None;
    r.trace = trace(&THETA_TRUE, &THETA_TRUE, 40);
    let rec = d.join("run.json");
    write_json(&rec, &serde_json::to_value(&r).unwrap());
    let out = d.join("figs");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["plot"])
        .arg(&rec)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("hysteresis.svg: the record has no validation run"),
        "{err}"
    );
    assert!(err.contains("no `residuals`"), "{err}");
    let conv = texts(&out.join("convergence.svg"));
    assert!(!conv.contains("true value"), "no truth to draw");
    texts(&out.join("ess.svg"));
    assert!(!out.join("hysteresis.svg").exists());

    // A failed validation is named.
    r.validation = Some(Validation {
        states: identify::metrics::StateErrors {
            names: vec![],
            errors: vec![],
        },
        loop_validation: None,
        loop_true: None,
        error: Some("θ_val outside the model's valid range".into()),
    });
    write_json(&rec, &serde_json::to_value(&r).unwrap());
    let p = plot(&rec, &out).unwrap();
    assert!(p
        .skipped
        .iter()
        .any(|s| s.contains("validation run failed: θ_val outside")));
}

#[test]
fn bad_records_are_refused_with_the_file_named() {
    let (_tmp, d) = dir("bad");
    let rec = d.join("broken.json");
    std::fs::write(&rec, "{\"algorithm\": 3}").unwrap();
    let err = plot(&rec, &d.join("figs")).unwrap_err();
    assert!(format!("{err:#}").contains("broken.json"), "{err:#}");
    let err = plot(&d.join("absent.json"), &d.join("figs")).unwrap_err();
    assert!(format!("{err:#}").contains("absent.json"), "{err:#}");
}
