//! Smoke tests of the SVG figures: synthetic run records are drawn, the files must be well-formed
//! SVG and carry the expected text, and damaged records (NaN in a trace, no truth, failed runs,
//! no loops) must be drawn without panicking.

use std::collections::BTreeMap;
use std::path::PathBuf;

use core_filters::Health;
use identify::figures::{
    convergence, convergence_y_range, crosses, hysteresis, state_errors, validate_svg,
};
use identify::metrics::{SignalError, StateErrors};
use identify::observe::Trace;
use identify::record::{Loop, RunRecord, Timing, Validation, Versions};

const NAMES: [&str; 9] = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
const THETA_TRUE: [f64; 9] = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 2.0, 1.0, 2.0];

/// A fresh output directory per test (tests of this file run in parallel), not yet created, in
/// a temporary directory whose guard removes it when dropped (also when the test panics).
fn out_dir(test: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix("figures-test-")
        .tempdir()
        .unwrap();
    let dir = tmp.path().join(test);
    (tmp, dir)
}

/// A synthetic run: posterior means relax from 1.5 × truth towards (1 + bias) × truth with s.d.s
/// shrinking as 1/√(1 + t); a Bouc–Wen-like loop for the truth and a slightly stiffer one for
/// the validation.
fn record(algorithm: &str, run: u64, bias: f64) -> RunRecord {
    let steps = 200;
    let dt = 0.005;
    let every = 4;
    let mut trace = Trace {
        every,
        ..Trace::default()
    };
    for k in (0..=steps).step_by(every) {
        let t = k as f64 * dt;
        let relax = (-3.0 * t).exp();
        trace.t.push(t);
        trace.param_mean.push(
            THETA_TRUE
                .iter()
                .map(|v| v * (1.0 + bias + (0.5 - bias) * relax))
                .collect(),
        );
        trace.param_sd.push(
            THETA_TRUE
                .iter()
                .map(|v| 0.3 * v / (1.0 + t).sqrt())
                .collect(),
        );
        trace.ess.push(250.0);
    }
    let theta_val: Vec<f64> = THETA_TRUE.iter().map(|v| v * (1.0 + bias)).collect();
    let loop_of = |k1: f64| {
        let phase: Vec<f64> = (0..200)
            .map(|i| i as f64 * 4.0 * std::f64::consts::PI / 200.0)
            .collect();
        Loop {
            x: phase.iter().map(|p| 0.05 * p.sin()).collect(),
            force: phase
                .iter()
                .map(|p| k1 * 0.577 * (p.sin() + 0.4 * p.cos()).tanh())
                .collect(),
        }
    };
    let state_names: Vec<String> = ["x1", "x2", "x3", "v1", "v2", "v3", "r1"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let errors = |scale: f64| StateErrors {
        names: state_names.clone(),
        errors: (0..7)
            .map(|j| SignalError {
                rmse: scale * (1.0 + j as f64),
                cv_rmse: scale * (1.2 + j as f64) / 10.0,
                nrmse: scale * (1.0 + j as f64) / 10.0,
            })
            .collect(),
    };
    RunRecord {
        experiment: "figure-smoke".into(),
        algorithm: algorithm.into(),
        seed: 7,
        run,
        particles: 500,
        param_names: NAMES.iter().map(|s| s.to_string()).collect(),
        theta_true: Some(THETA_TRUE.to_vec()),
        rel_error: Some(vec![bias.abs(); 9]),
        theta_val,
        window: 80,
        theta_sd_final: THETA_TRUE.iter().map(|v| 0.1 * v).collect(),
        loglik: -1234.5,
        steps_total: steps,
        steps_completed: steps,
        ess_min: 10.0,
        ess_mean: 250.0,
        distinct_sampled: BTreeMap::new(),
        failures: BTreeMap::new(),
        failure: None,
        health: Health::default(),
        online_states: Some(errors(1.0 + bias)),
        validation: Some(Validation {
            states: errors(2.0),
            loop_validation: Some(loop_of(8.0 * (1.0 + bias))),
            loop_true: Some(loop_of(8.0)),
            error: None,
        }),
        config: serde_json::json!({}),
        versions: Versions::current(),
        fingerprint: None,
        trace,
        timing: Timing {
            wall_s: 1.0,
            particle_steps_per_s: 1.0e5,
            validation_s: 0.1,
            realtime_factor: None,
            plan_s: None,
            threads: None,
            particle_blocks: false,
        },
        warnings: Vec::new(),
        credible: Vec::new(),
        theta_correlation: Vec::new(),
        segment_spread: None,
        innovation_checks: Vec::new(),
        residuals: None,
        free_run: None,
        modal: None,
        pool_left_out: vec![],
        plan: None,
        one_gaussian_filter: false,
    }
}

fn read(path: &std::path::Path) -> String {
    validate_svg(path).expect("a well-formed SVG");
    std::fs::read_to_string(path).unwrap()
}

/// Whether the SVG has a text element whose whole content is `label`.
fn has_label(svg: &str, label: &str) -> bool {
    svg.contains(&format!("\n{label}\n</text>"))
}

#[test]
fn convergence_figure_has_panels_legend_and_truth() {
    let (_tmp, dir) = out_dir("convergence");
    let a = record("MLN-RBPF", 0, 0.02);
    let b = record("Storvik", 0, -0.1);
    let path = dir.join("nested/fig5.svg");
    convergence(
        &[("MLN-RBPF", &a), ("Storvik", &b)],
        &path,
        "Fig. 5 — MLN-RBPF vs Storvik",
    )
    .unwrap();
    let svg = read(&path);
    for name in NAMES {
        assert!(
            svg.contains(&format!("\n{name} [")),
            "panel title of {name}"
        );
    }
    assert!(svg.contains("k1 [1/s²]") && svg.contains("c2 [1/s]"));
    for text in ["MLN-RBPF", "Storvik", "true value", "t [s]", "Fig. 5"] {
        assert!(svg.contains(text), "missing text {text}");
    }
    // Nine dashed truth lines: the dashed series writes many short segments, so instead check
    // that the font sizes are the readable ones (≥ 16 px labels, ≥ 20 px titles).
    assert!(
        svg.contains("font-size=\"16.129"),
        "tick labels at 20/1.24 px"
    );
    assert!(
        svg.contains("font-size=\"25.806"),
        "figure title at 32/1.24 px"
    );
}

#[test]
fn convergence_survives_nan_and_missing_truth() {
    let (_tmp, dir) = out_dir("convergence-nan");
    let mut a = record("Bootstrap", 0, 0.3);
    a.theta_true = None;
    a.rel_error = None;
    // A NaN mean, a NaN s.d., an infinite s.d., a short row and a NaN time.
    a.trace.param_mean[3][0] = f64::NAN;
    a.trace.param_sd[5][1] = f64::NAN;
    a.trace.param_sd[6][2] = f64::INFINITY;
    a.trace.param_mean[7].truncate(4);
    a.trace.t[9] = f64::NAN;
    // One parameter diverges: its axis includes every mean (the bands are clipped).
    for row in a.trace.param_mean.iter_mut().skip(20) {
        row[8] = 1.0e6;
    }
    let path = dir.join("fig4.svg");
    convergence(&[("bootstrap PF", &a)], &path, "Fig. 4").unwrap();
    let svg = read(&path);
    assert!(svg.contains("bootstrap PF"));
    assert!(!svg.contains("true value"), "no truth, no truth legend");
    assert!(!svg.contains("NaN"), "no NaN coordinates written");

    // A trace that is all NaN, and an empty trace.
    let mut b = record("Bootstrap", 1, 0.0);
    for row in b.trace.param_mean.iter_mut() {
        row.iter_mut().for_each(|v| *v = f64::NAN);
    }
    let mut c = record("Bootstrap", 2, 0.0);
    c.trace = Trace::default();
    let path = dir.join("fig4-empty.svg");
    convergence(&[("all NaN", &b), ("empty", &c)], &path, "Fig. 4").unwrap();
    let svg = read(&path);
    assert!(svg.contains("all NaN") && svg.contains("empty"));
}

#[test]
fn convergence_rejects_bad_input_with_errors() {
    let (_tmp, dir) = out_dir("convergence-bad");
    assert!(convergence(&[], &dir.join("none.svg"), "none").is_err());
    let a = record("A", 0, 0.0);
    let mut b = record("B", 0, 0.0);
    b.param_names.pop();
    assert!(convergence(&[("A", &a), ("B", &b)], &dir.join("mixed.svg"), "mixed").is_err());
}

#[test]
fn convergence_grid_adapts_to_parameter_count() {
    let (_tmp, dir) = out_dir("convergence-grid");
    let mut a = record("A", 0, 0.0);
    a.param_names.truncate(2);
    a.theta_true.as_mut().unwrap().truncate(2);
    let path = dir.join("two.svg");
    convergence(&[("A", &a)], &path, "two parameters").unwrap();
    let svg = read(&path);
    assert!(svg.contains("k1 [") && svg.contains("k2 ["));
    assert!(!svg.contains("k3 ["));
    // One row of panels: a shorter figure than the 3×3 one.
    assert!(
        svg.contains("height=\"375\""),
        "1 row: 60 + 50 (legend) + 265 px"
    );
}

#[test]
fn hysteresis_figure_with_and_without_loops() {
    let (_tmp, dir) = out_dir("hysteresis");
    let a = record("MPF-EKF2", 0, 0.05);
    let path = dir.join("fig8b.svg");
    hysteresis(&a, &path, "Fig. 8 — validation loop").unwrap();
    let svg = read(&path);
    for text in ["true loop", "validation loop (MPF-EKF2", "x1 [m]", "k1·r1"] {
        assert!(svg.contains(text), "missing text {text}");
    }

    let mut b = record("Bootstrap", 0, 0.0);
    b.validation.as_mut().unwrap().loop_validation = None;
    b.validation.as_mut().unwrap().loop_true = None;
    b.validation.as_mut().unwrap().error = Some("theta_val outside the valid range".into());
    let path = dir.join("noloop.svg");
    hysteresis(&b, &path, "no loops").unwrap();
    assert!(read(&path).contains("validation failed: theta_val outside the valid range"));

    b.validation = None;
    let path = dir.join("novalidation.svg");
    hysteresis(&b, &path, "no validation").unwrap();
    assert!(read(&path).contains("no validation run in this record"));

    // NaN inside the loops.
    let mut c = record("MPF-EKF2", 1, 0.0);
    let v = c.validation.as_mut().unwrap();
    v.loop_validation.as_mut().unwrap().force[10] = f64::NAN;
    v.loop_true.as_mut().unwrap().x[3] = f64::INFINITY;
    let path = dir.join("nanloop.svg");
    hysteresis(&c, &path, "non-finite loop").unwrap();
    let svg = read(&path);
    assert!(svg.contains("true loop") && !svg.contains("NaN"));
}

#[test]
fn crosses_figure_counts_runs_and_skips_failures() {
    let (_tmp, dir) = out_dir("crosses");
    let mlnrbpf: Vec<RunRecord> = (0..5)
        .map(|i| record("MLN-RBPF", i, 0.02 * i as f64))
        .collect();
    let mut storvik: Vec<RunRecord> = (0..4)
        .map(|i| record("Storvik", i, -0.05 * i as f64))
        .collect();
    storvik[1].failure = Some("all weights zero at step 120".into());
    storvik[2].theta_true = None;
    let mut mpf: Vec<RunRecord> = (0..3).map(|i| record("MPF-EKF2", i, 0.01)).collect();
    mpf[0].theta_val[6] = f64::NAN;
    let groups = vec![
        ("MLN-RBPF", mlnrbpf.iter().collect()),
        ("Storvik", storvik.iter().collect()),
        ("MPF-EKF2", mpf.iter().collect()),
    ];
    let path = dir.join("fig7.svg");
    crosses(&groups, &path, "Fig. 7 — θ_val / θ_true over runs").unwrap();
    let svg = read(&path);
    for name in NAMES {
        assert!(has_label(&svg, name), "x label {name}");
    }
    for text in [
        "MLN-RBPF (n = 5)",
        "Storvik (n = 2, 1 failed run(s) skipped, 1 without truth skipped)",
        "MPF-EKF2 (n = 3)",
        "θ_val / θ_true",
    ] {
        assert!(svg.contains(text), "missing text {text}");
    }
    assert!(!svg.contains("NaN"));

    assert!(crosses(&[], &dir.join("none.svg"), "none").is_err());
    // A group whose runs all failed still draws (legend says so).
    let mut failed = record("Storvik", 0, 0.0);
    failed.failure = Some("diverged".into());
    let path = dir.join("allfailed.svg");
    crosses(&[("Storvik", vec![&failed])], &path, "all failed").unwrap();
    assert!(read(&path).contains("Storvik (n = 0, 1 failed run(s) skipped)"));
}

#[test]
fn state_error_figure_has_states_and_algorithms() {
    let (_tmp, dir) = out_dir("states");
    let a: Vec<RunRecord> = (0..3).map(|i| record("MLN-RBPF", i, 0.1)).collect();
    let mut b: Vec<RunRecord> = (0..3).map(|i| record("MPF-EKF2", i, -0.3)).collect();
    b[2].online_states = None;
    b[1].online_states.as_mut().unwrap().errors[0].nrmse = f64::NAN;
    let groups = vec![
        ("MLN-RBPF", a.iter().collect()),
        ("MPF-EKF2", b.iter().collect()),
    ];
    let path = dir.join("fig6-states.svg");
    state_errors(&groups, &path, "Fig. 6 — online state errors").unwrap();
    let svg = read(&path);
    for text in [
        "NRMSE [-]",
        "MLN-RBPF (n = 3)",
        "MPF-EKF2 (n = 2, 1 skipped)",
    ] {
        assert!(svg.contains(text), "missing text {text}");
    }
    for name in ["x1", "x2", "x3", "v1", "v2", "v3", "r1"] {
        assert!(has_label(&svg, name), "x label {name}");
    }
    assert!(!svg.contains("NaN"));

    let mut c = record("X", 0, 0.0);
    c.online_states = None;
    assert!(state_errors(&[("X", vec![&c])], &dir.join("none.svg"), "none").is_err());
}

#[test]
fn validate_svg_rejects_non_svg() {
    let (_tmp, dir) = out_dir("validate");
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        ("empty.svg", ""),
        ("text.svg", "hello"),
        ("open.svg", "<svg width=\"1\">"),
        ("html.svg", "<html></html>"),
    ];
    for (name, body) in cases {
        let p = dir.join(name);
        std::fs::write(&p, body).unwrap();
        assert!(validate_svg(&p).is_err(), "{name} accepted");
    }
    let p = dir.join("ok.svg");
    std::fs::write(&p, "<?xml version=\"1.0\"?>\n<svg></svg>\n").unwrap();
    validate_svg(&p).unwrap();
    assert!(validate_svg(&dir.join("missing.svg")).is_err());
}

/// Numbers written as text between the first text `start` and the next text `end`.
fn numbers_between(svg: &str, start: &str, end: &str) -> Vec<f64> {
    let a = svg.find(start).unwrap_or_else(|| panic!("no {start}"));
    let b = a + svg[a..].find(end).unwrap_or_else(|| panic!("no {end}"));
    svg[a..b]
        .split("</text>")
        .filter_map(|chunk| chunk.rsplit('>').next())
        .filter_map(|t| t.trim().parse::<f64>().ok())
        .collect()
}

#[test]
fn convergence_axes_include_every_mean() {
    let (_tmp, dir) = out_dir("convergence-negative");
    // γ's posterior mean runs off to −2.6 although the truth (1) is positive (Fig. 4 (a)).
    let mut a = record("Bootstrap", 0, 0.0);
    for row in a.trace.param_mean.iter_mut().skip(5) {
        row[7] = -2.60;
    }
    let path = dir.join("fig4a.svg");
    convergence(&[("bootstrap PF", &a)], &path, "Fig. 4(a)").unwrap();
    let svg = read(&path);
    // Clipped at 0 (the former behaviour) the lowest tick would be 0; the axis reaches −2.6.
    let ticks = numbers_between(&svg, "\ngamma [", "\nn [");
    let lowest = ticks.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(lowest <= -2.0, "γ axis ticks {ticks:?}");
    let ((lo, hi), _) = convergence_y_range(&[("bootstrap PF", &a)], 7, Some(1.0));
    assert!(lo < -2.6 && hi > 1.0, "γ axis {lo}..{hi}");
    // Every mean of every parameter is inside its axis.
    for j in 0..9 {
        let ((lo, hi), _) = convergence_y_range(&[("bootstrap PF", &a)], j, Some(THETA_TRUE[j]));
        for row in &a.trace.param_mean {
            assert!(
                row[j] >= lo && row[j] <= hi,
                "parameter {j}: {} outside {lo}..{hi}",
                row[j]
            );
        }
    }
}

#[test]
fn crosses_panels_have_their_own_scales() {
    let (_tmp, dir) = out_dir("crosses-scales");
    // Stiffness ratios within ±2%, β at 3 × its truth.
    let runs: Vec<RunRecord> = (0..6)
        .map(|i| {
            let mut r = record("MLN-RBPF", i, 0.0);
            for j in 0..3 {
                r.theta_val[j] = 8.0 * (1.0 + 0.004 * (i as f64 - 2.5));
            }
            r.theta_val[6] = 6.0;
            r
        })
        .collect();
    let path = dir.join("fig7.svg");
    crosses(&[("MLN-RBPF", runs.iter().collect())], &path, "Fig. 7").unwrap();
    let svg = read(&path);
    for caption in ["stiffness", "damping", "hysteresis"] {
        assert!(has_label(&svg, caption), "panel {caption}");
    }
    let k_ticks = numbers_between(&svg, "\nstiffness\n", "\ndamping\n");
    let (lo, hi) = k_ticks
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    assert!(
        hi - lo < 0.2,
        "stiffness panel spans {lo}..{hi}: differences of 1% must be visible"
    );
    let h_ticks = numbers_between(&svg, "\nhysteresis\n", "MLN-RBPF (n =");
    assert!(
        h_ticks.iter().any(|v| *v >= 3.0),
        "β at 3 × truth inside its panel: {h_ticks:?}"
    );
}

#[test]
fn state_errors_draw_the_distribution_of_every_run() {
    let (_tmp, dir) = out_dir("states-distribution");
    let a: Vec<RunRecord> = (0..50)
        .map(|i| record("MLN-RBPF", i, 0.01 * i as f64))
        .collect();
    let b: Vec<RunRecord> = (0..50)
        .map(|i| record("MPF-EKF2", i, -0.005 * i as f64))
        .collect();
    let path = dir.join("fig6b.svg");
    state_errors(
        &[
            ("MLN-RBPF", a.iter().collect()),
            ("MPF-EKF2", b.iter().collect()),
        ],
        &path,
        "Fig. 6(b)",
    )
    .unwrap();
    let svg = read(&path);
    // One dot per run, state and algorithm.
    assert_eq!(svg.matches("<circle").count(), 50 * 7 * 2);
    assert!(svg.contains("quartiles"));
    assert!(!svg.contains("NaN"));
}
