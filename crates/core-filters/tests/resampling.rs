//! Offspring counts of every resampling scheme have mean `M w_i` (unbiasedness).

use core_filters::resampling::{Resampler, Scheme};
use core_filters::rng::stream;

/// For each scheme, `R` repetitions with `M = 20` offspring from 8 uneven weights. The count of
/// particle `i` has variance at most `M w_i (1 − w_i)` (multinomial; the other schemes are lower),
/// so its mean over `R` repetitions has standard error at most `√(M w_i (1 − w_i) / R)`; we
/// require every mean within 5 standard errors (a false alarm has probability < 1e-5 per check).
#[test]
fn offspring_counts_have_mean_m_w() {
    let raw = [0.3, 0.01, 2.0, 0.7, 0.0, 1.3, 0.05, 0.64];
    let total: f64 = raw.iter().sum();
    let w: Vec<f64> = raw.iter().map(|x| x / total).collect();
    let m = 20;
    let reps = 20_000;
    for scheme in Scheme::ALL {
        let mut rng = stream(11, 0, scheme.name());
        let mut r = Resampler::new(scheme, m);
        let mut a = vec![0; m];
        let mut counts = vec![0u64; w.len()];
        for _ in 0..reps {
            r.resample(&w, &mut a, &mut rng);
            for &i in &a {
                counts[i] += 1;
            }
        }
        for (i, &wi) in w.iter().enumerate() {
            let mean = counts[i] as f64 / reps as f64;
            let expect = m as f64 * wi;
            let se = (m as f64 * wi * (1.0 - wi) / reps as f64).sqrt();
            if wi == 0.0 {
                assert_eq!(counts[i], 0, "{scheme:?}: zero-weight particle resampled");
            } else {
                assert!(
                    (mean - expect).abs() < 5.0 * se,
                    "{scheme:?} particle {i}: mean offspring {mean}, expected {expect} ± {se}"
                );
            }
        }
    }
}

/// Systematic and residual resampling keep the count of every particle within one of `M w_i`.
#[test]
fn low_variance_schemes_stay_within_one_of_m_w() {
    let w = [0.05, 0.15, 0.3, 0.5];
    let mut rng = stream(3, 0, "low-variance");
    for scheme in [Scheme::Systematic, Scheme::Residual] {
        let mut r = Resampler::new(scheme, 10);
        let mut a = vec![0; 10];
        for _ in 0..1000 {
            r.resample(&w, &mut a, &mut rng);
            for (i, wi) in w.iter().enumerate() {
                let c = a.iter().filter(|&&x| x == i).count() as f64;
                assert!((c - 10.0 * wi).abs() < 1.0 + 1e-12, "{scheme:?}: {a:?}");
            }
        }
    }
}
