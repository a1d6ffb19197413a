//! The reference posterior's likelihood estimator (`experiments::reference`): with θ fixed, the
//! MPF-EKF2 is an exact Rao–Blackwellised particle filter, so its likelihood estimate and the
//! bootstrap PF's (the textbook unbiased estimator) estimate the same p(y | θ).

use crate::common;

use core_filters::rng::stream;
use experiments::reference::{
    compare, goal_rows, information_limit, pool_chains, reference_covers, FilterLikelihood,
    ParamSummary, ThetaMap, GOAL_MARGIN,
};
use experiments::verdict::Verdict;
use identify::pipeline::{chain_spec, Algorithm, FilterSettings};
use models::dataset::{generate, DatasetConfig};

/// `log mean exp` of independent log-likelihood estimates (an estimate of log p(y | θ) whose
/// exponential is unbiased) and the delta-method standard error of it.
fn log_mean_exp(ll: &[f64]) -> (f64, f64) {
    let m = ll.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = ll.iter().map(|v| (v - m).exp()).collect();
    let n = w.len() as f64;
    let mean = w.iter().sum::<f64>() / n;
    let var = w.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (m + mean.ln(), (var / n).sqrt() / mean)
}

#[test]
fn mpf_and_bootstrap_estimate_the_same_likelihood_at_fixed_theta() {
    let mut config = DatasetConfig::from_preset("paper-3dof", 7).unwrap();
    config.duration = Some(0.5);
    let set = generate(&config).unwrap();
    let data = set.to_loaded();
    let spec = chain_spec(&data, Some(&set.chain), &FilterSettings::default()).unwrap();
    let map = ThetaMap::new(&spec.prior).unwrap();
    let theta = set.chain.theta();
    let steps = data.len() - 1;
    let ys: Vec<f64> = (1..=steps).flat_map(|k| data.y(k).to_vec()).collect();
    let estimates = |algorithm: Algorithm, particles: usize, seeds: u64| -> Vec<f64> {
        let mut target = FilterLikelihood {
            spec: spec.clone(),
            map: map.clone(),
            algorithm,
            particles,
            ys: ys.clone(),
            ny: data.channels,
            failures: 0,
            evaluations: 0,
        };
        (0..seeds)
            .map(|s| target.estimate(&theta, &mut stream(11, s, "test/reference")))
            .collect()
    };
    let mpf = estimates(Algorithm::MpfEkf2, 100, 12);
    let boot = estimates(Algorithm::Bootstrap, 1000, 12);
    let (lm, sm) = log_mean_exp(&mpf);
    let (lb, sb) = log_mean_exp(&boot);
    let se = (sm * sm + sb * sb).sqrt();
    // 4 standard errors, plus the O(σ²/n) bias of log(mean) itself (σ² ≤ the sample variance).
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0)
    };
    let bias = (var(&mpf) + var(&boot)) / 12.0;
    assert!(
        (lm - lb).abs() < 4.0 * se + bias,
        "MPF-EKF2 {lm:.3} ± {sm:.3} vs bootstrap {lb:.3} ± {sb:.3}"
    );
}

/// The comparison with the reference on constructed records whose answer is known: k1's online
/// means are 8.1 and 8.3 against a reference 8.0 ± 0.1 (shifts +1 and +3 reference s.d., mean
/// +2, spread √2), online s.d. 0.05 × 8 = 0.4 (ratio 4); a failed run is left out.
#[test]
fn comparison_against_the_reference_on_constructed_records() {
    let reference = vec![ParamSummary {
        name: "k1".into(),
        mean: 8.0,
        sd: 0.1,
        quantiles: [7.8, 7.93, 8.0, 8.07, 8.2],
        ess: 500.0,
        truth: Some(8.0),
    }];
    let mut ratios = [1.0; 9];
    ratios[0] = 8.1 / 8.0;
    let a = common::record("mpf-ekf2", 0, ratios, 0.1);
    ratios[0] = 8.3 / 8.0;
    let b = common::record("mpf-ekf2", 1, ratios, 0.1);
    let mut failed = common::record("mpf-ekf2", 2, [2.0; 9], 0.1);
    failed.failure = Some("constructed".into());
    let c = compare(&reference, &[a, b, failed]);
    assert_eq!(c.len(), 1);
    assert_eq!(c[0].runs, 2);
    assert!((c[0].mean_shift_in_ref_sd - 2.0).abs() < 1e-9);
    assert!((c[0].spread_in_ref_sd - 2f64.sqrt()).abs() < 1e-9);
    assert!((c[0].sd_ratio - 4.0).abs() < 1e-9);
}

/// Two chains pooled as an equal mixture: means 1 and 3 with s.d. 1 give mean 2 and variance
/// 1 + 1 = 2.
#[test]
fn chains_pool_as_an_equal_mixture() {
    let chain = |mean: f64| {
        vec![ParamSummary {
            name: "k1".into(),
            mean,
            sd: 1.0,
            quantiles: [0.0; 5],
            ess: 10.0,
            truth: None,
        }]
    };
    let p = pool_chains(&[chain(1.0), chain(3.0)]).unwrap();
    assert_eq!(p[0].mean, 2.0);
    assert!((p[0].sd - 2f64.sqrt()).abs() < 1e-12);
    assert_eq!(p[0].ess, 20.0);
    assert!(pool_chains(&[]).is_err());
}

/// A chain that did not move, a nearly stuck one and one with few effective samples are named;
/// a healthy chain gets no warning.
#[test]
fn untrustworthy_chains_are_flagged() {
    use experiments::reference::chain_warnings;
    let p = |ess: f64| {
        vec![ParamSummary {
            name: "k1".into(),
            mean: 8.0,
            sd: 0.1,
            quantiles: [0.0; 5],
            ess,
            truth: None,
        }]
    };
    assert!(chain_warnings(0.2, &p(500.0), 0, 100).is_empty());
    let stuck = chain_warnings(0.0, &p(500.0), 0, 100);
    assert!(stuck[0].contains("did not move"), "{stuck:?}");
    assert!(chain_warnings(0.01, &p(500.0), 0, 100)[0].contains("nearly stuck"));
    let few = chain_warnings(0.2, &p(25.0), 3, 100);
    assert!(few[0].starts_with("k1: chain ESS 25"), "{few:?}");
    assert!(few[0].contains("0.020"), "{few:?}");
    assert!(few[1].contains("3 of 100"), "{few:?}");
}

/// The information limit over two constructed data sets whose answer is known. k1 = 8:
/// references 8.0 ± 0.1 (error 0) and 8.16 ± 0.05 (error 2 %, its 95 % interval 8.062–8.258
/// misses the truth), so the reference's mean error is 1 %, its mean relative s.d. 0.9375 %, and
/// one of two intervals holds the truth. Online: θ_val 8.08 on the first data set, 7.84 on the
/// second (errors 1 % and 2 %, mean 1.5 %, ratio 1.5 to the reference), s.d. 0.4 (ratios 4 and
/// 8, mean 6), 95 % intervals θ_val ± 0.1 (the first holds 8, the second does not); a failed run
/// on the first data set is left out.
#[test]
fn information_limit_on_constructed_records() {
    use core_filters::credible::CredibleInterval;
    use identify::observe::{ParamIntervals, PosteriorShape};
    let summary = |mean: f64, sd: f64| ParamSummary {
        name: "k1".into(),
        mean,
        sd,
        quantiles: [f64::NAN; 5],
        ess: 500.0,
        truth: Some(8.0),
    };
    let online = |run: u64, k1: f64| {
        let mut ratios = [1.0; 9];
        ratios[0] = k1 / 8.0;
        let mut r = common::record("storvik", run, ratios, 0.1);
        r.credible = vec![ParamIntervals {
            parameter: "k1".into(),
            shape: PosteriorShape::GaussianMixture,
            intervals: vec![CredibleInterval {
                level: 0.95,
                lo: k1 - 0.1,
                hi: k1 + 0.1,
            }],
            error: None,
            mc_se: None,
        }];
        r
    };
    let mut failed = online(2, 9.0);
    failed.failure = Some("constructed".into());
    assert_eq!(reference_covers(&summary(8.0, 0.1)), Some(true));
    assert_eq!(reference_covers(&summary(8.16, 0.05)), Some(false));
    let rows = information_limit(&[
        (vec![summary(8.0, 0.1)], vec![online(0, 8.08), failed]),
        (vec![summary(8.16, 0.05)], vec![online(1, 7.84)]),
    ]);
    assert_eq!(rows.len(), 1);
    let r = &rows[0];
    assert_eq!((r.param.as_str(), r.algorithm.as_str()), ("k1", "storvik"));
    assert_eq!((r.data_sets, r.ref_covered, r.runs), (2, 1, 2));
    assert!((r.ref_rel_error - 0.01).abs() < 1e-12);
    assert!((r.ref_rel_sd - 0.009375).abs() < 1e-12);
    assert!((r.online_rel_error - 0.015).abs() < 1e-12);
    assert_eq!((r.online_covered, r.intervals), (1, 2));
    assert!((r.sd_ratio - 6.0).abs() < 1e-9);
}

/// The goal "online within 10 % of the reference's error" is decided by its stated test: the
/// paired difference over (data set, parameter) below the margin with its ±2 s.e. interval
/// holds, above it does not, across it is not resolved; only the parameters the reference has
/// (here the stiffnesses) get a row, and failed runs are left out.
#[test]
fn the_goal_against_the_limit_is_decided_by_its_stated_test() {
    // Two data sets whose reference means of k1..k3 are 10 % off their truth (8): error 0.10.
    let summaries = || -> Vec<ParamSummary> {
        ["k1", "k2", "k3"]
            .iter()
            .map(|n| ParamSummary {
                name: n.to_string(),
                mean: 8.8,
                sd: 0.2,
                quantiles: [f64::NAN; 5],
                ess: 500.0,
                truth: Some(8.0),
            })
            .collect()
    };
    // One online run per data set with the given stiffness ratios (dampings exact).
    let online = |run: u64, k: [f64; 3]| {
        let mut ratios = [1.0; 9];
        ratios[..3].copy_from_slice(&k);
        common::record("mpf-ekf2", run, ratios, 0.1)
    };
    let verdict = |a: [f64; 3], b: [f64; 3]| {
        let mut failed = online(9, [3.0; 3]);
        failed.failure = Some("constructed".into());
        let rows = goal_rows(&[
            (summaries(), vec![online(0, a), failed]),
            (summaries(), vec![online(1, b)]),
        ]);
        assert_eq!(rows.len(), 1, "no damping row without a damping reference");
        let r = &rows[0];
        assert_eq!((r.group, r.difference.n), ('k', 6));
        assert!((r.reference - 0.10).abs() < 1e-12);
        r.verdict
    };
    // As far from the truth as the reference: a difference of 0 ± 0.
    assert_eq!(verdict([1.1; 3], [0.9; 3]), Verdict::Holds);
    // Twice as far: 0.10 ± 0, above the margin of 0.01.
    assert_eq!(verdict([1.2; 3], [0.8; 3]), Verdict::DoesNotHold);
    // Differences −0.05, +0.07, … : mean 0.01 (the margin) with a non-zero s.e.
    assert_eq!(
        verdict([1.05, 1.17, 1.05], [1.17, 1.05, 1.17]),
        Verdict::NotResolved
    );
    assert!((GOAL_MARGIN - 0.10).abs() < 1e-15);
}
