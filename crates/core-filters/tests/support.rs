//! Property test of the physical support (`linalg::support`): whatever Gaussian a filter
//! carries — means far below zero, strong correlations — truncating its stiffnesses, dampings
//! and α below at zero leaves every one of their means positive, the covariance symmetric and
//! positive semidefinite, and the chain's damping matrix built from the means positive
//! semidefinite.

use core_filters::linalg::{truncate_below, LowerBound};
use nalgebra::{DMatrix, SymmetricEigen};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The 3-storey shear chain's damping matrix Σ c_j (e_j − e_{j−1})(e_j − e_{j−1})ᵀ + α M (unit
/// masses).
fn damping_matrix(c: &[f64], alpha: f64) -> DMatrix<f64> {
    let n = c.len();
    let mut d = DMatrix::zeros(n, n);
    for j in 0..n {
        d[(j, j)] += c[j] + alpha;
        if j > 0 {
            d[(j - 1, j - 1)] += c[j];
            d[(j, j - 1)] -= c[j];
            d[(j - 1, j)] -= c[j];
        }
    }
    d
}

#[test]
fn no_truncated_gaussian_has_a_negative_damping_or_an_indefinite_damping_matrix() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(49);
    // Block: x1..x3, k1..k3 (3..6), c1..c3 (6..9), alpha (9).
    let n = 10;
    let bounds: Vec<LowerBound> = (3..10)
        .map(|index| LowerBound { index, bound: 0.0 })
        .collect();
    let mut truncated = 0;
    for case in 0..2000 {
        let a = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        let scale: f64 = 10f64.powf(rng.random_range(-3.0..1.0));
        let p = (&a * a.transpose()) * scale + DMatrix::identity(n, n) * 1e-9;
        let mut cov: Vec<f64> = p.as_slice().to_vec();
        let mut mean: Vec<f64> = (0..n).map(|_| rng.random_range(-5.0..5.0)).collect();
        truncated += truncate_below(&mut mean, &mut cov, &bounds);
        for b in &bounds {
            assert!(
                mean[b.index] >= 0.0,
                "case {case}: mean {} = {}",
                b.index,
                mean[b.index]
            );
        }
        let p = DMatrix::from_column_slice(n, n, &cov);
        assert_eq!(p, p.transpose(), "case {case}: symmetric");
        let lowest = SymmetricEigen::new(p.clone()).eigenvalues.min();
        assert!(
            lowest >= -1e-9 * p.amax(),
            "case {case}: covariance eigenvalue {lowest}"
        );
        let d = damping_matrix(&mean[6..9], mean[9]);
        let lowest = SymmetricEigen::new(d.clone()).eigenvalues.min();
        assert!(
            lowest >= -1e-12 * d.amax(),
            "case {case}: damping eigenvalue {lowest}"
        );
    }
    // The cases did reach below zero (the test exercises the truncation).
    assert!(truncated > 2000, "{truncated} bounds applied");
}

/// The central interval of a Gaussian mixture truncated below at a bound, against bisection on
/// the truncated CDF (F(x) − F(a))/(1 − F(a)) computed from the components directly.
#[test]
fn intervals_of_a_bounded_parameter_are_those_of_its_truncated_posterior() {
    use core_filters::credible::{normal_cdf, GaussianMixture};
    let w = [0.5, 0.3, 0.2];
    let m = [0.05, -0.02, 0.3];
    let v = [0.01, 0.04, 0.0025];
    let mix = GaussianMixture::new(&w, &m, &v).unwrap();
    let cdf = |x: f64| -> f64 {
        w.iter()
            .zip(&m)
            .zip(&v)
            .map(|((w, m), v)| w * normal_cdf((x - m) / v.sqrt()))
            .sum()
    };
    let (a, fa) = (0.0, cdf(0.0));
    let quantile = |p: f64| {
        let (mut lo, mut hi) = (a, 5.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if (cdf(mid) - fa) / (1.0 - fa) < p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    let levels = [0.5, 0.9, 0.95];
    let mut out = [core_filters::credible::CredibleInterval {
        level: f64::NAN,
        lo: f64::NAN,
        hi: f64::NAN,
    }; 3];
    mix.central_intervals_above(a, &levels, &mut out).unwrap();
    for (ci, level) in out.iter().zip(levels) {
        let (pl, pu) = ((1.0 - level) / 2.0, (1.0 + level) / 2.0);
        assert!(
            (ci.lo - quantile(pl)).abs() < 1e-9,
            "{level}: {} {}",
            ci.lo,
            quantile(pl)
        );
        assert!(
            (ci.hi - quantile(pu)).abs() < 1e-9,
            "{level}: {} {}",
            ci.hi,
            quantile(pu)
        );
        assert!(ci.lo >= a);
    }
    // No mass below the bound: the plain intervals, bit for bit.
    let far = GaussianMixture::new(&[1.0], &[8.0], &[0.01]).unwrap();
    let (mut x, mut y) = (out, out);
    far.central_intervals_above(0.0, &levels, &mut x).unwrap();
    far.central_intervals(&levels, &mut y).unwrap();
    assert_eq!(x, y);
}
