//! Tests of the priors of `models::priors` through the chain's prior [`ChainPrior`]: they live
//! here, beside `ChainPrior`, so that `priors` imports nothing of `filtering`.

use crate::filtering::prior::ChainPrior;
use crate::priors::*;
use core_filters::rng::stream;
use rand::Rng;

/// SPEC §3's θ for `n` storeys with the one Bouc–Wen element at storey 1.
fn paper(n: usize) -> ChainPrior {
    ChainPrior::paper(n, &[0])
}

fn sample<G: Rng + ?Sized>(prior: &ChainPrior, rng: &mut G) -> Vec<f64> {
    let mut out = vec![0.0; prior.len()];
    prior.sample_into(rng, &mut out);
    out
}

/// Monte-Carlo check of mean, variance and the β–γ covariance of a prior.
///
/// Tolerances are 5 Monte-Carlo standard errors: for the mean √(var/M); for the variance
/// √((μ4 − σ⁴)/M) with μ4 estimated from the same sample; for the covariance √(E[(βγ)²]/M).
/// With ~40 checks at 5 s.e. a false failure has probability < 1e-4 (and the seed is fixed).
fn check_moments_by_monte_carlo(prior: &ChainPrior, draws: usize, seed: u64) {
    let d = prior.len();
    let (mean, var) = prior.moments();
    let mut rng = stream(seed, 0, "priors-test");
    let samples: Vec<Vec<f64>> = (0..draws).map(|_| sample(prior, &mut rng)).collect();
    let m = draws as f64;
    for i in 0..d {
        let mc_mean = samples.iter().map(|s| s[i]).sum::<f64>() / m;
        let mc_var = samples
            .iter()
            .map(|s| (s[i] - mc_mean).powi(2))
            .sum::<f64>()
            / (m - 1.0);
        let mu4 = samples
            .iter()
            .map(|s| (s[i] - mc_mean).powi(4))
            .sum::<f64>()
            / m;
        let se_mean = (var[i] / m).sqrt();
        let se_var = ((mu4 - mc_var * mc_var).max(0.0) / m).sqrt();
        assert!(
            (mc_mean - mean[i]).abs() <= 5.0 * se_mean + 1e-12,
            "param {i}: MC mean {mc_mean} vs {} (se {se_mean})",
            mean[i]
        );
        assert!(
            (mc_var - var[i]).abs() <= 5.0 * se_var + 1e-12,
            "param {i}: MC var {mc_var} vs {} (se {se_var})",
            var[i]
        );
    }
    let n = prior.n_storeys();
    let (b, g) = (2 * n, 2 * n + 1);
    let (mb, mg) = (mean[b], mean[g]);
    let cov = samples
        .iter()
        .map(|s| (s[b] - mb) * (s[g] - mg))
        .sum::<f64>()
        / m;
    let e2 = samples
        .iter()
        .map(|s| ((s[b] - mb) * (s[g] - mg)).powi(2))
        .sum::<f64>()
        / m;
    assert!(
        cov.abs() <= 5.0 * (e2 / m).sqrt() + 1e-12,
        "beta-gamma covariance {cov} not zero"
    );
}

#[test]
fn paper_moments_match_spec_numbers() {
    let prior = paper(3);
    prior.validate().unwrap();
    let (mean, var) = prior.moments();
    // SPEC §3: k: 10.46 ± 3.21; c: 0.453 ± 0.242; β: 10/3, 25/18; γ: 0, 25/6; n: 3, 16/12.
    for j in 0..3 {
        assert!((mean[j] - 10.46).abs() < 5e-3, "k mean {}", mean[j]);
        assert!(
            (var[j].sqrt() - 3.21).abs() < 5e-3,
            "k sd {}",
            var[j].sqrt()
        );
        assert!((mean[3 + j] - 0.453).abs() < 5e-4, "c mean {}", mean[3 + j]);
        assert!((var[3 + j].sqrt() - 0.242).abs() < 5e-4);
    }
    assert!((mean[6] - 10.0 / 3.0).abs() < 1e-12);
    assert!((var[6] - 25.0 / 18.0).abs() < 1e-12);
    assert_eq!(mean[7], 0.0);
    assert!((var[7] - 25.0 / 6.0).abs() < 1e-12);
    assert!((mean[8] - 3.0).abs() < 1e-12);
    assert!((var[8] - 16.0 / 12.0).abs() < 1e-12);
}

#[test]
fn paper_moments_match_monte_carlo() {
    check_moments_by_monte_carlo(&paper(3), 200_000, 11);
}

#[test]
fn conditional_triangle_moments_match_monte_carlo() {
    let mut p = paper(2);
    p.fix("gamma", -1.5).unwrap();
    assert_eq!(
        p.elements[0].beta_gamma,
        BetaGammaPrior::FixedGamma {
            gamma: -1.5,
            beta_max: 5.0
        }
    );
    check_moments_by_monte_carlo(&p, 100_000, 12);
    let mut q = paper(2);
    q.fix("beta", 2.0).unwrap();
    check_moments_by_monte_carlo(&q, 100_000, 13);
    // Conditional samples stay in the triangle.
    let mut rng = stream(5, 0, "priors-test");
    for _ in 0..1000 {
        let s = sample(&p, &mut rng);
        assert!(s[4] >= 1.5 && s[4] <= 5.0 && s[5] == -1.5);
        let s = sample(&q, &mut rng);
        assert!(s[4] == 2.0 && s[5].abs() <= 2.0);
    }
}

#[test]
fn triangle_samples_stay_in_triangle() {
    let prior = paper(3);
    let mut rng = stream(3, 0, "priors-test");
    for _ in 0..10_000 {
        let s = sample(&prior, &mut rng);
        assert!((0.0..=5.0).contains(&s[6]) && s[7].abs() <= s[6]);
        assert!((1.0..5.0).contains(&s[8]));
        assert!(s[..6].iter().all(|&v| v > 0.0));
    }
}

#[test]
fn fix_makes_point_masses_and_rejects_unknown_names() {
    let mut p = paper(3);
    p.fix("k2", 8.0).unwrap();
    p.fix("c3", 0.25).unwrap();
    p.fix("n", 2.0).unwrap();
    p.fix("beta", 2.0).unwrap();
    p.fix("gamma", 1.0).unwrap();
    assert_eq!(
        p.elements[0].beta_gamma,
        BetaGammaPrior::Fixed {
            beta: 2.0,
            gamma: 1.0
        }
    );
    let (mean, var) = p.moments();
    assert_eq!((mean[1], var[1]), (8.0, 0.0));
    assert_eq!((mean[5], var[5]), (0.25, 0.0));
    assert_eq!((mean[6], mean[7], mean[8]), (2.0, 1.0, 2.0));
    assert_eq!((var[6], var[7], var[8]), (0.0, 0.0, 0.0));
    let mut rng = stream(4, 0, "priors-test");
    let s = sample(&p, &mut rng);
    assert_eq!((s[1], s[5], s[6], s[7], s[8]), (8.0, 0.25, 2.0, 1.0, 2.0));

    let before = p.clone();
    for bad in ["k0", "k4", "c", "x1", "k01", "", "betaa", "K1"] {
        assert_eq!(
            p.fix(bad, 1.0),
            Err(PriorError::UnknownParameter {
                name: bad.to_string()
            }),
            "{bad}"
        );
    }
    assert!(matches!(
        p.fix("k1", -1.0),
        Err(PriorError::NegativeSupport { .. })
    ));
    assert!(matches!(
        p.fix("n", f64::NAN),
        Err(PriorError::NonFinite { .. })
    ));
    assert_eq!(p, before, "a rejected fix leaves the prior unchanged");
    let mut t = paper(1);
    assert!(matches!(
        t.fix("gamma", 6.0),
        Err(PriorError::GammaOutsideTriangle { .. })
    ));
}

#[test]
fn validation_rejects_bad_hyper_parameters() {
    let mut p = paper(2);
    p.k[0] = Prior::LogNormal {
        median: 0.0,
        log_sd: 0.3,
    };
    assert!(matches!(
        p.validate(),
        Err(PriorError::NonPositiveMedian { .. })
    ));
    p.k[0] = Prior::LogNormal {
        median: 1.0,
        log_sd: -0.3,
    };
    assert!(matches!(p.validate(), Err(PriorError::BadLogSd { .. })));
    p.k[0] = Prior::Uniform { lo: 2.0, hi: 2.0 };
    assert!(matches!(
        p.validate(),
        Err(PriorError::EmptyInterval { .. })
    ));
    p.k[0] = Prior::Uniform { lo: -1.0, hi: 2.0 };
    assert!(matches!(
        p.validate(),
        Err(PriorError::NegativeSupport { .. })
    ));
    p.k[0] = Prior::Uniform { lo: 1.0, hi: 2.0 };
    p.validate().unwrap();
    p.c.pop();
    assert!(matches!(p.validate(), Err(PriorError::WrongLength { .. })));
    let mut q = paper(2);
    q.elements[0].beta_gamma = BetaGammaPrior::Triangle { beta_max: 0.0 };
    assert!(matches!(
        q.validate(),
        Err(PriorError::NonPositiveBetaMax { .. })
    ));
}

#[test]
fn serde_form_is_readable_and_round_trips() {
    let p = paper(2);
    let json = serde_json::to_string(&p).unwrap();
    assert!(json.contains(r#""kind":"log_normal""#), "{json}");
    assert!(json.contains(r#""kind":"triangle""#), "{json}");
    let back: ChainPrior = serde_json::from_str(&json).unwrap();
    assert_eq!(back, p);
    let one: Prior = serde_json::from_str(r#"{"kind":"fixed","value":2.0}"#).unwrap();
    assert_eq!(one, Prior::Fixed { value: 2.0 });
}

#[test]
fn parameter_names_follow_theta_order() {
    assert_eq!(
        paper(2).names(),
        ["k1", "k2", "c1", "c2", "beta", "gamma", "n"]
    );
}
