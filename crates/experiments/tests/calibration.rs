//! Calibration metrics (SPEC §9 "Calibration"): coverage and z-scores against hand-made runs
//! whose answers are known, the report table, the JSON form and the figure, and a statistical
//! check on a conjugate Gaussian model whose exact posterior is known.

use std::path::PathBuf;

use core_filters::credible::{CredibleInterval, GaussianMixture, STANDARD_LEVELS};
use core_filters::rng::stream;
use experiments::calibration::{
    calibrate_algorithm, calibrate_parameter, coverage_figure, markdown, CalibrationError,
    LevelCoverage, RunPosterior, SweepCalibration, Verdict, ZQuantile,
};
use identify::figures::validate_svg;
use rand::Rng;

fn ci(level: f64, lo: f64, hi: f64) -> CredibleInterval {
    CredibleInterval { level, lo, hi }
}

/// Ten runs of a parameter with truth 8: the 90 % interval contains it in runs 0–6 (run 6 with
/// the truth exactly on its lower end), the 50 % interval in runs 0–2, the 95 % in runs 0–8.
fn ten_runs() -> Vec<RunPosterior> {
    (0..10)
        .map(|i| {
            let contains = |k: usize| i < k;
            let around = |k: usize, half: f64| {
                if contains(k) {
                    (8.0 - half, 8.0 + half)
                } else {
                    (8.5, 8.5 + half)
                }
            };
            let (lo50, hi50) = around(3, 0.1);
            let (mut lo90, hi90) = around(7, 0.3);
            if i == 6 {
                lo90 = 8.0;
            }
            let (lo95, hi95) = around(9, 0.4);
            RunPosterior {
                truth: 8.0,
                estimate: 8.0 + 0.1 * i as f64,
                sd: 0.2,
                intervals: vec![
                    ci(0.95, lo95, hi95),
                    ci(0.5, lo50, hi50),
                    ci(0.9, lo90, hi90),
                ],
            }
        })
        .collect()
}

#[test]
fn coverage_of_hand_made_runs() {
    let p = calibrate_parameter("k1", &ten_runs(), &STANDARD_LEVELS).unwrap();
    assert_eq!(p.parameter, "k1");
    assert_eq!(p.runs, 10);
    let at = |q: f64| p.coverage.iter().find(|c| c.level == q).unwrap();

    // 90 %: 7 of 10 → 0.7 ± √(0.7·0.3/10); the test uses √(0.9·0.1/10) ≈ 0.095 and
    // |0.7 − 0.9| = 0.2 > 2 × 0.095: over-confident.
    let c90 = at(0.9);
    assert_eq!((c90.runs, c90.covered), (10, 7));
    assert!((c90.coverage.unwrap() - 0.7).abs() < 1e-15);
    assert!((c90.se.unwrap() - (0.21f64 / 10.0).sqrt()).abs() < 1e-15);
    assert!((c90.se_nominal.unwrap() - (0.09f64 / 10.0).sqrt()).abs() < 1e-15);
    assert_eq!(c90.verdict, Verdict::OverConfident);

    // 50 %: 3 of 10; |0.3 − 0.5| = 0.2 < 2 √(0.025) ≈ 0.32: consistent.
    let c50 = at(0.5);
    assert_eq!(c50.covered, 3);
    assert!((c50.se.unwrap() - (0.21f64 / 10.0).sqrt()).abs() < 1e-15);
    assert_eq!(c50.verdict, Verdict::Consistent);

    // 95 %: 9 of 10; |0.9 − 0.95| = 0.05 < 2 √(0.00475) ≈ 0.14: consistent.
    let c95 = at(0.95);
    assert_eq!(c95.covered, 9);
    assert_eq!(c95.verdict, Verdict::Consistent);

    // Every 50 % interval containing the truth: 1.0 against 0.5 is under-confident.
    let wide: Vec<RunPosterior> = (0..10)
        .map(|_| RunPosterior {
            truth: 1.0,
            estimate: 1.0,
            sd: 1.0,
            intervals: vec![ci(0.5, -5.0, 5.0)],
        })
        .collect();
    let p = calibrate_parameter("c1", &wide, &[0.5]).unwrap();
    assert_eq!(p.coverage[0].covered, 10);
    assert_eq!(p.coverage[0].se, Some(0.0));
    assert_eq!(p.coverage[0].verdict, Verdict::UnderConfident);
    assert_eq!(p.coverage[0].verdict.label(), "under-confident");

    // Fewer than 10 runs: coverage is reported, no verdict.
    let p = calibrate_parameter("k1", &ten_runs()[..9], &STANDARD_LEVELS).unwrap();
    assert!(p.coverage.iter().all(|c| c.verdict == Verdict::TooFewRuns));
    assert_eq!(p.coverage[1].covered, 7);
}

#[test]
fn z_scores_and_spread_by_hand() {
    // Errors θ_val − θ_true = 1, −1, 2, 0, 3, 0.5, 0 with s.d.s 1, 1, 1, 2, 0.5, 0, 0:
    // finite z = 1, −1, 2, 0, 6; one infinite (s.d. 0, error 0.5); one undefined (0/0).
    let runs: Vec<RunPosterior> = [
        (1.0, 1.0),
        (-1.0, 1.0),
        (2.0, 1.0),
        (0.0, 2.0),
        (3.0, 0.5),
        (0.5, 0.0),
        (0.0, 0.0),
    ]
    .iter()
    .map(|&(err, sd)| RunPosterior {
        truth: 2.0,
        estimate: 2.0 + err,
        sd,
        intervals: vec![ci(0.9, 2.0 + err - 1.645 * sd, 2.0 + err + 1.645 * sd)],
    })
    .collect();
    let p = calibrate_parameter("n", &runs, &[0.9]).unwrap();
    let z = &p.z;
    assert_eq!((z.finite, z.infinite, z.undefined), (5, 1, 1));
    // Mean 8/5; squared deviations 0.36 + 6.76 + 0.16 + 2.56 + 19.36 = 29.2 over 4.
    assert!((z.mean.unwrap() - 1.6).abs() < 1e-15);
    assert!((z.sd.unwrap() - 7.3f64.sqrt()).abs() < 1e-14);
    // |z| > 2: z = 6 and the infinite one, of 6 defined (z = 2 is not above 2).
    assert!((z.frac_abs_above_2.unwrap() - 2.0 / 6.0).abs() < 1e-15);
    // Inverse empirical CDF of (−1, 0, 1, 2, 6), each of weight 1/5.
    let want = [
        (0.05, -1.0),
        (0.25, 0.0),
        (0.5, 1.0),
        (0.75, 2.0),
        (0.95, 6.0),
    ];
    let got: Vec<(f64, f64)> = z.quantiles.iter().map(|q| (q.p, q.z)).collect();
    assert_eq!(got, want);

    // Mean s.d. 5.5/7; error mean 11/14 and Σe² = 15.25, so the sample variance is
    // (15.25 − 7·(11/14)²)/6 = (15.25 − 121/28)/6; RMSE √(15.25/7).
    let s = &p.spread;
    let error_sd = ((15.25 - 121.0 / 28.0) / 6.0f64).sqrt();
    assert!((s.mean_posterior_sd.unwrap() - 5.5 / 7.0).abs() < 1e-15);
    assert!((s.error_sd.unwrap() - error_sd).abs() < 1e-14);
    assert!((s.sd_ratio.unwrap() - 5.5 / 7.0 / error_sd).abs() < 1e-14);
    assert!((s.rmse.unwrap() - (15.25f64 / 7.0).sqrt()).abs() < 1e-15);
    // Intervals θ_val ± 1.645 s.d. contain the truth for errors 1, −1 and 0 (s.d. 2), not for
    // 2 and 3; of the zero-s.d. runs the degenerate interval contains it only with error 0.
    assert_eq!(p.coverage[0].covered, 4);
}

#[test]
fn no_runs_give_nulls_not_nans() {
    let p = calibrate_parameter("k1", &[], &STANDARD_LEVELS).unwrap();
    assert_eq!(p.runs, 0);
    assert!(p
        .coverage
        .iter()
        .all(|c| c.coverage.is_none() && c.verdict == Verdict::TooFewRuns));
    assert_eq!(p.z.mean, None);
    assert!(p.z.quantiles.is_empty());
    assert_eq!(p.spread.sd_ratio, None);
    let json = serde_json::to_string(&p).unwrap();
    assert!(!json.contains("NaN"));
    assert!(json.contains("\"coverage\":null"));
    assert!(json.contains("\"verdict\":\"too_few_runs\""));
}

#[test]
fn bad_inputs_are_typed_errors() {
    let mut runs = ten_runs();
    runs[3].estimate = f64::NAN;
    let e = calibrate_parameter("k2", &runs, &STANDARD_LEVELS).unwrap_err();
    assert!(matches!(
        &e,
        CalibrationError::NonFinite { parameter, run: 3, field: "estimate", .. } if parameter == "k2"
    ));
    assert_eq!(
        e.to_string(),
        "parameter k2, run 3: estimate = NaN is not finite"
    );

    let mut runs = ten_runs();
    runs[5].intervals.retain(|c| c.level != 0.95);
    assert!(matches!(
        calibrate_parameter("k1", &runs, &STANDARD_LEVELS),
        Err(CalibrationError::MissingLevel { run: 5, level, .. }) if level == 0.95
    ));

    let mut runs = ten_runs();
    runs[0].intervals[0] = ci(0.95, 9.0, 7.0);
    assert!(matches!(
        calibrate_parameter("k1", &runs, &STANDARD_LEVELS),
        Err(CalibrationError::InvertedInterval { run: 0, .. })
    ));

    let mut runs = ten_runs();
    runs[2].intervals[1].hi = f64::INFINITY;
    assert!(matches!(
        calibrate_parameter("k1", &runs, &STANDARD_LEVELS),
        Err(CalibrationError::NonFinite {
            run: 2,
            field: "interval hi",
            ..
        })
    ));

    let mut runs = ten_runs();
    runs[9].sd = -0.1;
    assert!(matches!(
        calibrate_parameter("k1", &runs, &STANDARD_LEVELS),
        Err(CalibrationError::NegativeSd { run: 9, .. })
    ));

    assert_eq!(
        calibrate_parameter("k1", &ten_runs(), &[]),
        Err(CalibrationError::NoLevels)
    );
    assert!(matches!(
        calibrate_parameter("k1", &ten_runs(), &[0.9, 1.0]),
        Err(CalibrationError::InvalidLevel { level }) if level == 1.0
    ));
}

/// A sweep of two algorithms and two parameters built from the hand-made runs.
fn sweep() -> SweepCalibration {
    let shifted: Vec<RunPosterior> = ten_runs()
        .into_iter()
        .map(|mut r| {
            // Every interval widened to contain the truth: coverage 1 at every level.
            for c in &mut r.intervals {
                c.lo = c.lo.min(7.5);
                c.hi = c.hi.max(8.5);
            }
            r
        })
        .collect();
    let a = calibrate_algorithm(
        "mln-rbpf",
        &[("k1", ten_runs()), ("c1", shifted.clone())],
        &STANDARD_LEVELS,
    )
    .unwrap();
    let b = calibrate_algorithm(
        "mpf-ekf2",
        &[("k1", shifted), ("c1", ten_runs())],
        &STANDARD_LEVELS,
    )
    .unwrap();
    SweepCalibration {
        sweep: "fig7".into(),
        levels: STANDARD_LEVELS.to_vec(),
        algorithms: vec![a, b],
    }
}

#[test]
fn markdown_table_has_one_row_per_algorithm_and_parameter() {
    let text = markdown(&sweep());
    let rows: Vec<&str> = text.lines().filter(|l| l.starts_with('|')).collect();
    assert_eq!(rows.len(), 2 + 4, "{text}");
    assert_eq!(
        rows[0],
        r"| algorithm | parameter | n | 50 % | 90 % | 95 % | mean z | s.d. z | \|z\| > 2 | s.d. ratio |"
    );
    // Every row has as many cells as the header (pipes inside cells are escaped).
    let cells = |r: &str| r.replace(r"\|", "").matches('|').count();
    assert!(rows.iter().all(|r| cells(r) == cells(rows[0])), "{text}");
    // mln-rbpf k1: the hand-made runs (z = 0.5 i for i = 0..9: mean 2.25, s.d. √(55/6)·0.5).
    assert!(rows[2].starts_with(
        "| mln-rbpf | k1 | 10 | 0.30 ± 0.14 | 0.70 ± 0.14 **over** | 0.90 ± 0.09 | 2.25 |"
    ));
    assert!(rows[3].contains("| 1.00 ± 0.00 *under* |"), "{}", rows[3]);
    assert!(text.contains("sweep `fig7`"));
}

#[test]
fn summary_json_round_trips() {
    let s = sweep();
    let json = serde_json::to_string_pretty(&s).unwrap();
    assert!(json.contains("\"verdict\": \"over_confident\""));
    let back: SweepCalibration = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s);
}

/// An output directory for `test`, not yet created, in a fresh directory under the system temp
/// dir, and the guard that removes them when dropped (also when the test panics).
fn out_dir(test: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix("calibration-test-")
        .tempdir()
        .unwrap();
    let dir = tmp.path().join(test);
    (tmp, dir)
}

#[test]
fn coverage_figure_is_well_formed() {
    let (_tmp, dir) = out_dir("figure");
    let path = dir.join("coverage.svg");
    coverage_figure(&sweep(), &path, "Coverage — fig7 sweep").unwrap();
    validate_svg(&path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    for text in [
        "k1",
        "c1",
        "mln-rbpf",
        "mpf-ekf2",
        "nominal level",
        "coverage",
    ] {
        assert!(svg.contains(text), "figure lacks '{text}'");
    }
    // A sweep without algorithms is refused with the path in the message.
    let empty = SweepCalibration {
        sweep: "x".into(),
        levels: STANDARD_LEVELS.to_vec(),
        algorithms: vec![],
    };
    let e = coverage_figure(&empty, &path, "t").unwrap_err().to_string();
    assert!(e.contains("coverage.svg"), "{e}");
    // A parameter without runs is drawn without points and without panicking.
    let mut s = sweep();
    s.algorithms[0].params[0] = calibrate_parameter("k1", &[], &STANDARD_LEVELS).unwrap();
    let path = dir.join("no-runs.svg");
    coverage_figure(&s, &path, "no runs").unwrap();
    validate_svg(&path).unwrap();
}

/// A standard normal draw (Box–Muller; the test needs no distribution crate).
fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Conjugate model: θ ~ N(0, 1), y | θ ~ N(θ, 1), so θ | y ~ N(y/2, 1/2) exactly. Over R
/// replications the number of q-intervals that contain θ is Binomial(R, q) when the posterior
/// is exact; `sd_scale` shrinks the reported s.d. (and so the intervals) to make it
/// over-confident.
fn conjugate_runs(reps: usize, sd_scale: f64) -> Vec<RunPosterior> {
    let mut rng = stream(2024, 0, "calibration/conjugate");
    (0..reps)
        .map(|_| {
            let theta = normal(&mut rng);
            let y = theta + normal(&mut rng);
            let var = 0.5 * sd_scale * sd_scale;
            let (w, mu, v) = ([1.0], [0.5 * y], [var]);
            let posterior = GaussianMixture::new(&w, &mu, &v).unwrap();
            let mut intervals = vec![ci(0.0, 0.0, 0.0); STANDARD_LEVELS.len()];
            posterior
                .central_intervals(&STANDARD_LEVELS, &mut intervals)
                .unwrap();
            RunPosterior {
                truth: theta,
                estimate: posterior.mean(),
                sd: posterior.sd(),
                intervals,
            }
        })
        .collect()
}

#[test]
fn exact_posterior_covers_at_the_nominal_rate() {
    let reps = 2000;
    let p = calibrate_parameter("theta", &conjugate_runs(reps, 1.0), &STANDARD_LEVELS).unwrap();
    for c in &p.coverage {
        let LevelCoverage {
            level,
            coverage: Some(cov),
            se_nominal: Some(se),
            ..
        } = *c
        else {
            panic!("no coverage at {}", c.level)
        };
        // Within 3 binomial s.e. of nominal (a false alarm has probability 0.003 per level;
        // the seed is fixed).
        assert!(
            (cov - level).abs() < 3.0 * se,
            "coverage {cov} at {level}, s.e. {se}"
        );
        assert_ne!(c.verdict, Verdict::OverConfident);
    }
    // z ~ N(0, 1): mean within 3/√R, s.d. within 3/√(2(R − 1)) of 1.
    let n = reps as f64;
    assert!(p.z.mean.unwrap().abs() < 3.0 / n.sqrt(), "{:?}", p.z);
    assert!((p.z.sd.unwrap() - 1.0).abs() < 3.0 / (2.0 * (n - 1.0)).sqrt());
    // P(|z| > 2) = 0.0455, s.e. √(0.0455·0.9545/R) ≈ 0.0047.
    assert!((p.z.frac_abs_above_2.unwrap() - 0.0455).abs() < 3.0 * 0.0047);
    // The posterior s.d. √½ equals the s.d. of θ_val − θ = y/2 − θ (variance ¼ + ¼): ratio 1
    // up to the relative s.e. of a sample s.d., 1/√(2(R − 1)).
    let ratio = p.spread.sd_ratio.unwrap();
    assert!(
        (ratio - 1.0).abs() < 3.0 / (2.0 * (n - 1.0)).sqrt(),
        "{ratio}"
    );
    let median = p.z.quantiles.iter().find(|q| q.p == 0.5).copied();
    assert!(matches!(median, Some(ZQuantile { z, .. }) if z.abs() < 0.1));
}

#[test]
fn halved_posterior_sd_is_flagged_over_confident() {
    let p = calibrate_parameter("theta", &conjugate_runs(2000, 0.5), &STANDARD_LEVELS).unwrap();
    // With the s.d. halved the 90 % interval is ±0.82 true s.d.s: coverage 2Φ(0.822) − 1 ≈ 0.59.
    let c90 = p.coverage.iter().find(|c| c.level == 0.9).unwrap();
    assert!((c90.coverage.unwrap() - 0.589).abs() < 3.0 * (0.589f64 * 0.411 / 2000.0).sqrt());
    assert!(p
        .coverage
        .iter()
        .all(|c| c.verdict == Verdict::OverConfident));
    assert!((p.spread.sd_ratio.unwrap() - 0.5).abs() < 0.05);
    assert!((p.z.sd.unwrap() - 2.0).abs() < 0.15);
}
