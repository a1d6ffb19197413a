//! The reference posterior's likelihood estimator (`experiments::reference`): with θ fixed, the
//! MPF-EKF2 is an exact Rao–Blackwellised particle filter, so its likelihood estimate and the
//! bootstrap PF's (the textbook unbiased estimator) estimate the same p(y | θ).

use core_filters::rng::stream;
use experiments::pipeline::{chain_spec, Algorithm, FilterSettings};
use experiments::reference::{FilterLikelihood, ThetaMap};
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
