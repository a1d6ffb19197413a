//! Central credible intervals of weighted samples and Gaussian mixtures (SPEC §9 "Calibration"):
//! hand cases (one component gives μ ± z σ with the normal quantile; point masses; equal
//! weights), brute force (a naive weighted quantile; numerical integration of the mixture
//! density; a large sample drawn from the mixture) and the typed errors.

use core_filters::credible::{
    central_probabilities, CredibleError, CredibleInterval, GaussianMixture, WeightedSample,
    STANDARD_LEVELS,
};
use core_filters::rng::stream;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// Standard normal quantiles Φ⁻¹(0.75), Φ⁻¹(0.95), Φ⁻¹(0.975) (mpmath, 20 digits): the upper
/// ends of the central 50 %, 90 % and 95 % intervals of N(0, 1).
const Z: [(f64, f64); 3] = [
    (0.5, 0.674_489_750_196_081_7),
    (0.9, 1.644_853_626_951_472_7),
    (0.95, 1.959_963_984_540_054_2),
];

fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got}, want {want} (|diff| = {:e} > {tol:e})",
        (got - want).abs()
    );
}

fn intervals(m: &GaussianMixture, levels: &[f64]) -> Vec<CredibleInterval> {
    let mut out = vec![
        CredibleInterval {
            level: 0.0,
            lo: f64::NAN,
            hi: f64::NAN
        };
        levels.len()
    ];
    m.central_intervals(levels, &mut out).unwrap();
    out
}

#[test]
fn one_component_gives_mean_plus_minus_z_sd() {
    for (mu, var) in [
        (8.0, 0.02f64 * 0.02),
        (0.0, 1.0),
        (-3.0, 25.0),
        (0.25, 1e-8),
    ] {
        let sd = var.sqrt();
        let (mu_s, var_s) = ([mu], [var]);
        let m = GaussianMixture::new(&[1.0], &mu_s, &var_s).unwrap();
        assert_eq!(m.mean(), mu);
        assert_close(m.sd(), sd, 1e-15 * sd, "s.d.");
        for (level, z) in Z {
            let ci = m.central_interval(level).unwrap();
            // Located to 1e−12 σ; the normal CDF adds ≈ 1e−15 relative.
            let tol = 2e-12 * sd + 8.0 * f64::EPSILON * mu.abs();
            assert_eq!(ci.level, level);
            assert_close(ci.lo, mu - z * sd, tol, "lower end");
            assert_close(ci.hi, mu + z * sd, tol, "upper end");
        }
    }
}

#[test]
fn far_tails_keep_their_relative_accuracy() {
    // Φ⁻¹(5e−11) and −Φ⁻¹(1 − p_u) for the double p_u nearest 1 − 5e−11, whose exact complement
    // is 5.000000413701855e−11 (mpmath, 20 digits). The upper quantile is solved on the survival
    // function, so it is as accurate as the lower one.
    let m = GaussianMixture::new(&[1.0], &[0.0], &[1.0]).unwrap();
    let lower = m.quantile(5e-11).unwrap();
    assert_close(lower, -6.466_951_087_240_516, 1e-12, "lower tail");
    let pu = 1.0 - 5e-11;
    assert_eq!(1.0 - pu, 5.000_000_413_701_855e-11);
    let upper = m.quantile(pu).unwrap();
    assert_close(upper, 6.466_951_074_732_419, 1e-12, "upper tail");
}

#[test]
fn equal_weight_copies_of_one_component_are_that_component() {
    let n = 50;
    let (w, mu, var) = (vec![0.02; n], vec![8.0; n], vec![0.04; n]);
    let m = GaussianMixture::new(&w, &mu, &var).unwrap();
    for ((level, z), ci) in Z.iter().zip(intervals(&m, &STANDARD_LEVELS)) {
        assert_eq!(ci.level, *level);
        assert_close(ci.lo, 8.0 - z * 0.2, 1e-12, "lower end");
        assert_close(ci.hi, 8.0 + z * 0.2, 1e-12, "upper end");
    }
}

#[test]
fn symmetric_equal_weight_mixture_has_symmetric_intervals() {
    // ½ N(−2, 1) + ½ N(2, 1): median 0, every central interval symmetric about it.
    let m = GaussianMixture::new(&[0.5, 0.5], &[-2.0, 2.0], &[1.0, 1.0]).unwrap();
    assert_close(m.quantile(0.5).unwrap(), 0.0, 1e-12, "median");
    for ci in intervals(&m, &STANDARD_LEVELS) {
        assert_close(ci.lo, -ci.hi, 1e-12, "symmetry");
        let (pl, pu) = central_probabilities(ci.level).unwrap();
        assert_close(m.cdf(ci.lo), pl, 1e-14, "F(lo)");
        assert_close(m.sf(ci.hi), 1.0 - pu, 1e-14, "S(hi)");
    }
    assert_close(m.sd(), 5.0f64.sqrt(), 1e-15, "s.d. = √(1 + 4)");
}

#[test]
fn single_particle_and_point_masses() {
    // One particle: a degenerate interval at its value, for both shapes.
    let s = WeightedSample::new(&[2.5], &[0.3]).unwrap();
    let m = GaussianMixture::new(&[0.3], &[2.5], &[0.0]).unwrap();
    for level in STANDARD_LEVELS {
        for ci in [
            s.central_interval(level).unwrap(),
            m.central_interval(level).unwrap(),
        ] {
            assert_eq!((ci.lo, ci.hi), (2.5, 2.5));
            assert!(ci.contains(2.5) && !ci.contains(2.5000001));
            assert_eq!(ci.width(), 0.0);
        }
    }
    // Point masses 1, 2, 3, 4 with weights ⅛, ½, ¼, ⅛ (cumulative ⅛, ⅝, ⅞, 1), given unsorted.
    let values = [4.0, 2.0, 1.0, 3.0];
    let weights = [0.125, 0.5, 0.125, 0.25];
    let s = WeightedSample::new(&values, &weights).unwrap();
    let m = GaussianMixture::new(&weights, &values, &[0.0; 4]).unwrap();
    // Q(p) = inf {x : F(x) ≥ p}: at a cumulative weight exactly, the lower value.
    for (p, q) in [
        (0.1, 1.0),
        (0.125, 1.0),
        (0.13, 2.0),
        (0.625, 2.0),
        (0.7, 3.0),
        (0.875, 3.0),
        (0.9, 4.0),
    ] {
        assert_eq!(s.quantile(p).unwrap(), q, "sample Q({p})");
        assert_eq!(m.quantile(p).unwrap(), q, "mixture Q({p})");
    }
    assert_eq!(s.central_interval(0.5).unwrap().lo, 2.0);
    assert_eq!(s.central_interval(0.5).unwrap().hi, 3.0);
    assert_eq!(m.central_interval(0.9).unwrap().lo, 1.0);
    assert_eq!(m.central_interval(0.9).unwrap().hi, 4.0);
}

#[test]
fn point_mass_beside_a_continuous_part() {
    // ½ δ(0) + ½ N(10, 1): F jumps from ≈ 0 to ½ at 0, then follows ½ + ½ Φ(x − 10).
    let m = GaussianMixture::new(&[0.5, 0.5], &[0.0, 10.0], &[0.0, 1.0]).unwrap();
    assert_eq!(m.quantile(0.25).unwrap(), 0.0);
    assert_eq!(m.quantile(0.5).unwrap(), 0.0);
    // F(x) = 0.6 ⟺ Φ(x − 10) = 0.2.
    assert_close(
        m.quantile(0.6).unwrap(),
        10.0 - 0.841_621_233_572_914_2,
        1e-11,
        "Q(0.6)",
    );
    // ½ N(0, 1) + ½ δ(5): Q(0.3) = Φ⁻¹(0.6) lies in the continuous part although the point
    // mass is inside the root finder's first bracket.
    let m = GaussianMixture::new(&[0.5, 0.5], &[0.0, 5.0], &[1.0, 0.0]).unwrap();
    assert_close(
        m.quantile(0.3).unwrap(),
        0.253_347_103_135_799_8,
        1e-11,
        "Q(0.3)",
    );
    assert_eq!(m.quantile(0.7).unwrap(), 5.0);
}

#[test]
fn zero_weight_components_change_nothing() {
    let w = [0.2, 0.0, 0.5, 0.3];
    let mu = [7.9, 1e6, 8.1, 8.0];
    let var = [0.01, 1e4, 0.02, 0.0];
    let with = GaussianMixture::new(&w, &mu, &var).unwrap();
    let keep = [0, 2, 3];
    let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let (w2, mu2, var2) = (pick(&w), pick(&mu), pick(&var));
    let without = GaussianMixture::new(&w2, &mu2, &var2).unwrap();
    assert_eq!(
        intervals(&with, &STANDARD_LEVELS),
        intervals(&without, &STANDARD_LEVELS)
    );
    let s = WeightedSample::new(&mu, &w).unwrap();
    assert_eq!(s.distinct(), 3);
    assert!(s.central_interval(0.95).unwrap().hi < 9.0);
}

/// Naive weighted quantile, O(N²): the smallest particle value v with Σ_{θ_i ≤ v} w_i ≥ p Σ w.
fn naive_quantile(values: &[f64], weights: &[f64], p: f64) -> f64 {
    let total: f64 = weights.iter().sum();
    values
        .iter()
        .zip(weights)
        .filter(|(_, &w)| w > 0.0)
        .map(|(&v, _)| v)
        .filter(|&v| {
            let cum: f64 = values
                .iter()
                .zip(weights)
                .filter(|(&u, _)| u <= v)
                .map(|(_, &w)| w)
                .sum();
            cum >= p * total
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn weighted_sample_matches_the_naive_quantile_and_the_point_mass_mixture() {
    let mut rng = stream(3, 0, "credible/weighted-sample");
    let mut sample = WeightedSample::with_capacity(64);
    for trial in 0..200 {
        let n = rng.random_range(1..60);
        // Values on a coarse grid (many ties); integer weights (exact sums), some zero.
        let values: Vec<f64> = (0..n)
            .map(|_| f64::from(rng.random_range(0..15u8)) * 0.5 - 3.0)
            .collect();
        let mut weights: Vec<f64> = (0..n)
            .map(|_| f64::from(rng.random_range(0..5u8)))
            .collect();
        if weights.iter().all(|&w| w == 0.0) {
            weights[0] = 1.0;
        }
        sample.set(&values, &weights).unwrap();
        let zeros = vec![0.0; n];
        let mixture = GaussianMixture::new(&weights, &values, &zeros).unwrap();
        for _ in 0..20 {
            let p: f64 = rng.random_range(0.001..0.999);
            let want = naive_quantile(&values, &weights, p);
            assert_eq!(sample.quantile(p).unwrap(), want, "trial {trial}, p = {p}");
            assert_eq!(mixture.quantile(p).unwrap(), want, "trial {trial}, p = {p}");
        }
        for level in STANDARD_LEVELS {
            let (pl, pu) = central_probabilities(level).unwrap();
            let ci = sample.central_interval(level).unwrap();
            assert_eq!(ci.lo, naive_quantile(&values, &weights, pl));
            assert_eq!(ci.hi, naive_quantile(&values, &weights, pu));
        }
    }
}

/// A random mixture of `n` components: weights uniform on (0, 1), means N(8, 0.3²), s.d.s
/// uniform on (0.05, 0.3), every `point_every`-th component a point mass.
fn random_mixture(seed: u64, n: usize, point_every: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = stream(seed, 0, "credible/mixture");
    let normal = Normal::new(8.0, 0.3).unwrap();
    let w = (0..n).map(|_| rng.random_range(0.01..1.0)).collect();
    let mu = (0..n).map(|_| normal.sample(&mut rng)).collect();
    let var = (0..n)
        .map(|i| {
            let s: f64 = rng.random_range(0.05..0.3);
            if point_every > 0 && i % point_every == 0 {
                0.0
            } else {
                s * s
            }
        })
        .collect();
    (w, mu, var)
}

/// F(x) of the mixture by composite Simpson integration of the continuous density from
/// min μ − 12 max σ (plus the point masses ≤ x): independent of the erfc used by the crate.
fn cdf_by_integration(w: &[f64], mu: &[f64], var: &[f64], x: f64) -> f64 {
    let total: f64 = w.iter().sum();
    let start = mu.iter().fold(f64::INFINITY, |a, &m| a.min(m))
        - 12.0 * var.iter().fold(0.0f64, |a, &v| a.max(v.sqrt()));
    let density = |t: f64| -> f64 {
        w.iter()
            .zip(mu)
            .zip(var)
            .filter(|(_, &v)| v > 0.0)
            .map(|((&wi, &m), &v)| {
                let s = v.sqrt();
                let z = (t - m) / s;
                wi * (-0.5 * z * z).exp() / (s * (2.0 * std::f64::consts::PI).sqrt())
            })
            .sum()
    };
    let steps = 40_000; // even; h ≤ 2.5e−4, h/σ_min ≤ 5e−3: Simpson's error ≈ 1e−11.
    let h = (x - start) / steps as f64;
    let mut acc = density(start) + density(x);
    for k in 1..steps {
        let t = start + k as f64 * h;
        acc += if k % 2 == 1 { 4.0 } else { 2.0 } * density(t);
    }
    let masses: f64 = w
        .iter()
        .zip(mu)
        .zip(var)
        .filter(|((_, &m), &v)| v == 0.0 && m <= x)
        .map(|((&wi, _), _)| wi)
        .sum();
    (acc * h / 3.0 + masses) / total
}

#[test]
fn mixture_quantiles_agree_with_numerical_integration() {
    for (seed, point_every) in [(1, 0), (2, 7)] {
        let (w, mu, var) = random_mixture(seed, 40, point_every);
        let m = GaussianMixture::new(&w, &mu, &var).unwrap();
        for ci in intervals(&m, &STANDARD_LEVELS) {
            let (pl, pu) = central_probabilities(ci.level).unwrap();
            for (x, p) in [(ci.lo, pl), (ci.hi, pu)] {
                let f = cdf_by_integration(&w, &mu, &var, x);
                // With point masses, F may jump across p at x: then F(x⁻) < p ≤ F(x).
                let is_mass = mu.iter().zip(&var).any(|(&m, &v)| v == 0.0 && m == x);
                if is_mass {
                    assert!(f >= p - 1e-9, "seed {seed}: F({x}) = {f} < {p}");
                } else {
                    assert_close(f, p, 1e-9, "F(Q(p)) by integration");
                }
            }
        }
    }
}

#[test]
fn mixture_quantiles_agree_with_a_large_sample() {
    // One million draws from a 200-component mixture. The sample p-quantile has standard error
    // √(p(1 − p)/n) / f(Q(p)); we require each end within 5 standard errors.
    let (w, mu, var) = random_mixture(4, 200, 0);
    let m = GaussianMixture::new(&w, &mu, &var).unwrap();
    let total: f64 = w.iter().sum();
    let mut cum = Vec::with_capacity(w.len());
    let mut acc = 0.0;
    for &wi in &w {
        acc += wi / total;
        cum.push(acc);
    }
    let n = 1_000_000;
    let mut rng = stream(4, 1, "credible/mixture-draws");
    let mut draws: Vec<f64> = (0..n)
        .map(|_| {
            let u: f64 = rng.random::<f64>() * acc;
            let i = cum.partition_point(|&c| c < u).min(w.len() - 1);
            Normal::new(mu[i], var[i].sqrt()).unwrap().sample(&mut rng)
        })
        .collect();
    draws.sort_unstable_by(f64::total_cmp);
    let density = |x: f64| -> f64 {
        w.iter()
            .zip(&mu)
            .zip(&var)
            .map(|((&wi, &mm), &v)| {
                let s = v.sqrt();
                let z = (x - mm) / s;
                wi / total * (-0.5 * z * z).exp() / (s * (2.0 * std::f64::consts::PI).sqrt())
            })
            .sum()
    };
    for ci in intervals(&m, &STANDARD_LEVELS) {
        let (pl, pu) = central_probabilities(ci.level).unwrap();
        for (x, p) in [(ci.lo, pl), (ci.hi, pu)] {
            let k = ((p * n as f64).ceil() as usize).clamp(1, n) - 1;
            let se = (p * (1.0 - p) / n as f64).sqrt() / density(x);
            assert_close(draws[k], x, 5.0 * se, "sample quantile");
        }
    }
}

#[test]
fn several_levels_at_once_equal_one_at_a_time_and_nest() {
    let (w, mu, var) = random_mixture(5, 100, 9);
    let m = GaussianMixture::new(&w, &mu, &var).unwrap();
    let levels = [0.95, 0.5, 0.9, 0.99, 0.2];
    let together = intervals(&m, &levels);
    for (ci, &level) in together.iter().zip(&levels) {
        let alone = m.central_interval(level).unwrap();
        assert_close(ci.lo, alone.lo, 4e-12, "lower end");
        assert_close(ci.hi, alone.hi, 4e-12, "upper end");
    }
    let mut sorted = together.clone();
    sorted.sort_by(|a, b| a.level.total_cmp(&b.level));
    for pair in sorted.windows(2) {
        assert!(pair[1].lo <= pair[0].lo && pair[0].hi <= pair[1].hi);
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let ok = [1.0, 1.0];
    assert_eq!(
        GaussianMixture::new(&[], &[], &[]).unwrap_err(),
        CredibleError::Empty
    );
    assert!(matches!(
        GaussianMixture::new(&ok, &[1.0, f64::NAN], &ok),
        Err(CredibleError::NonFinite {
            what: "means",
            index: 1,
            ..
        })
    ));
    assert!(matches!(
        GaussianMixture::new(&ok, &ok, &[f64::INFINITY, 1.0]),
        Err(CredibleError::NonFinite {
            what: "variances",
            index: 0,
            ..
        })
    ));
    assert!(matches!(
        GaussianMixture::new(&[1.0, f64::NAN], &ok, &ok),
        Err(CredibleError::NonFinite {
            what: "weights",
            index: 1,
            ..
        })
    ));
    assert!(matches!(
        GaussianMixture::new(&[1.0, -0.5], &ok, &ok),
        Err(CredibleError::NegativeWeight { index: 1, .. })
    ));
    assert!(matches!(
        GaussianMixture::new(&ok, &ok, &[1.0, -1e-30]),
        Err(CredibleError::NegativeVariance { index: 1, .. })
    ));
    assert!(matches!(
        GaussianMixture::new(&[0.0, 0.0], &ok, &ok),
        Err(CredibleError::ZeroTotalWeight { .. })
    ));
    assert!(matches!(
        GaussianMixture::new(&ok, &[1.0], &ok),
        Err(CredibleError::LengthMismatch {
            what: "means",
            expected: 2,
            got: 1
        })
    ));
    let m = GaussianMixture::new(&ok, &ok, &ok).unwrap();
    for bad in [0.0, 1.0, f64::NAN, 2.0] {
        assert!(matches!(
            m.central_interval(bad),
            Err(CredibleError::InvalidLevel { .. })
        ));
        assert!(matches!(
            m.quantile(bad),
            Err(CredibleError::InvalidProbability { .. })
        ));
    }
    let mut out = [CredibleInterval {
        level: 0.5,
        lo: 0.0,
        hi: 0.0,
    }];
    assert!(matches!(
        m.central_intervals(&STANDARD_LEVELS, &mut out),
        Err(CredibleError::OutputLength { levels: 3, out: 1 })
    ));
    assert!(matches!(
        WeightedSample::new(&[f64::INFINITY, 1.0], &ok),
        Err(CredibleError::NonFinite {
            what: "values",
            index: 0,
            ..
        })
    ));
    assert!(matches!(
        WeightedSample::new(&ok, &[0.0, 0.0]),
        Err(CredibleError::ZeroTotalWeight { .. })
    ));
    assert_eq!(
        WeightedSample::with_capacity(4).quantile(0.5),
        Err(CredibleError::Empty)
    );
    let message = GaussianMixture::new(&ok, &[1.0, f64::NAN], &ok)
        .unwrap_err()
        .to_string();
    assert_eq!(message, "means[1] = NaN is not finite");
}

#[test]
fn ill_scaled_mixtures_give_certified_quantiles() {
    // Component s.d.s log-uniform over nine decades, every fifth a point mass, some weights
    // tiny: every quantile must come back, with F(Q − δ) < p ≤ F(Q + δ) for δ a few
    // tolerances (1e−12 of the smallest s.d. plus 4 ε |Q|).
    let mut rng = stream(6, 0, "credible/ill-scaled");
    let normal = Normal::new(8.0, 1.0).unwrap();
    for trial in 0..50 {
        let n = rng.random_range(2..80);
        let w: Vec<f64> = (0..n)
            .map(|_| 10f64.powf(rng.random_range(-12.0..0.0)))
            .collect();
        let mu: Vec<f64> = (0..n).map(|_| normal.sample(&mut rng)).collect();
        let var: Vec<f64> = (0..n)
            .map(|i| {
                if i % 5 == 0 {
                    0.0
                } else {
                    10f64.powf(rng.random_range(-18.0..0.0))
                }
            })
            .collect();
        let m = GaussianMixture::new(&w, &mu, &var).unwrap();
        let sd_min = var
            .iter()
            .filter(|&&v| v > 0.0)
            .fold(f64::INFINITY, |a, &v| a.min(v.sqrt()));
        for ci in intervals(&m, &[0.5, 0.9, 0.95, 0.999]) {
            let (pl, pu) = central_probabilities(ci.level).unwrap();
            for (x, p) in [(ci.lo, pl), (ci.hi, pu)] {
                let delta = 4.0 * (1e-12 * sd_min + 4.0 * f64::EPSILON * x.abs());
                // Upper quantiles are certified on S = 1 − F (F near 1 is rounded to 1e−16).
                let ok = if p <= 0.5 {
                    m.cdf(x + delta) >= p && m.cdf(x - delta) < p
                } else {
                    m.sf(x + delta) <= 1.0 - p && m.sf(x - delta) > 1.0 - p
                };
                assert!(
                    ok,
                    "trial {trial}: Q({p}) = {x}, F(Q ± δ) = {}, {}",
                    m.cdf(x - delta),
                    m.cdf(x + delta)
                );
            }
        }
    }
}

/// The intervals of a particle set read each slot from the right block: a marginalised slot is
/// the mixture of the particles' means and covariance diagonals (entry `j + j·n`), a sampled slot
/// the weighted sample of that entry — checked against the two shapes built by hand.
#[test]
fn weighted_particles_read_the_right_block_of_each_slot() {
    use core_filters::model::{Layout, Slot};
    use core_filters::smc::runner::WeightedParticles;
    use core_filters::smc::{Particles, Shape};

    let np = 5;
    let shape = Shape {
        sampled: 2,
        marginal: 2,
    };
    let mut p = Particles::new(np, shape);
    for i in 0..np {
        let x = i as f64;
        let b = p.particle_mut(i);
        b.sampled.copy_from_slice(&[10.0 + x, -x * x]);
        b.mean.copy_from_slice(&[1.0 + 0.1 * x, 5.0 - x]);
        // Covariance [[v0, c], [c, v1]] in column-major order; the off-diagonal must be ignored.
        b.cov
            .copy_from_slice(&[0.01 * (1.0 + x), 0.3, 0.3, 0.25 + 0.5 * x]);
    }
    let w = [0.1, 0.3, 0.2, 0.25, 0.15];
    let layout = Layout {
        param_names: vec!["a".into(), "b".into(), "c".into()],
        params: vec![Slot::Marginal(1), Slot::Sampled(0), Slot::Marginal(0)],
        state_names: vec![],
        states: vec![],
    };
    let wp = WeightedParticles {
        bounds: &[],
        layout: &layout,
        w: &w,
        particles: &p,
    };
    let levels = STANDARD_LEVELS;
    for j in 0..2 {
        let means: Vec<f64> = (0..np).map(|i| p.mean(i)[j]).collect();
        let vars: Vec<f64> = (0..np).map(|i| p.cov(i)[j + 2 * j]).collect();
        let want = intervals(&GaussianMixture::new(&w, &means, &vars).unwrap(), &levels);
        assert_eq!(
            wp.central_intervals(Slot::Marginal(j), &levels).unwrap(),
            want
        );
        let values: Vec<f64> = (0..np).map(|i| p.sampled(i)[j]).collect();
        let mut want = want.clone();
        WeightedSample::new(&values, &w)
            .unwrap()
            .central_intervals(&levels, &mut want)
            .unwrap();
        assert_eq!(
            wp.central_intervals(Slot::Sampled(j), &levels).unwrap(),
            want
        );
    }
    // One particle with all the weight: the marginal slot is N(μ, v), μ ± z √v.
    let w1 = [0.0, 0.0, 1.0, 0.0, 0.0];
    let wp1 = WeightedParticles {
        bounds: &[],
        layout: &layout,
        w: &w1,
        particles: &p,
    };
    let ci = wp1.central_intervals(Slot::Marginal(1), &[0.95]).unwrap()[0];
    let (mu, sd) = (3.0, 1.25f64.sqrt());
    assert_close(ci.lo, mu - Z[2].1 * sd, 1e-9, "lo");
    assert_close(ci.hi, mu + Z[2].1 * sd, 1e-9, "hi");
    // The sampled slot of one particle is a point mass.
    let ci = wp1.central_intervals(Slot::Sampled(1), &[0.5]).unwrap()[0];
    assert_eq!((ci.lo, ci.hi), (-4.0, -4.0));
    // Bad levels are typed errors, not panics.
    assert_eq!(
        wp.central_intervals(Slot::Sampled(0), &[1.0]),
        Err(CredibleError::InvalidLevel { level: 1.0 })
    );
}
