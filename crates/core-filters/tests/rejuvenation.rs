//! The Liu–West kernel of `smc::rejuvenation`: the exact algebra on a constructed cloud, the
//! moments kept over many particles within Monte-Carlo error, values strictly inside their
//! support (also from a bound), only the declared entries moved, and the draws taken from the
//! given stream, one per particle and parameter.

use core_filters::rng::stream;
use core_filters::smc::rejuvenation::{LiuWest, Rejuvenation, StaticParam, Support};
use core_filters::smc::{Particles, Shape};
use rand_distr::{Distribution, StandardNormal};

fn moments(u: &[f64]) -> (f64, f64) {
    let n = u.len() as f64;
    let m = u.iter().sum::<f64>() / n;
    (m, u.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n)
}

/// With draws of mean 0, mean square 1 and orthogonal to the deviations, the move keeps the
/// mean and the variance exactly; and every value is a·u + (1 − a)·ū + h·√V·ε.
#[test]
fn the_kernel_keeps_mean_and_variance_on_a_constructed_cloud() {
    let k = LiuWest::new(0.95).unwrap();
    let (a, h) = (k.shrinkage(), k.spread());
    assert!((a - (3.0 * 0.95 - 1.0) / 1.9).abs() < 1e-15);
    // Deviations (+2, −2, +2, −2) around 0.7; draws (1, 1, −1, −1).
    let u0 = [2.7, -1.3, 2.7, -1.3];
    let eps = [1.0, 1.0, -1.0, -1.0];
    let (m0, v0) = moments(&u0);
    assert_eq!(v0, 4.0);
    let mut u = u0;
    let mut e = eps.iter();
    assert!(k.shrink(&mut u, || *e.next().unwrap()));
    assert!(e.next().is_none(), "one draw per value");
    for i in 0..4 {
        let want = a * u0[i] + (1.0 - a) * m0 + h * v0.sqrt() * eps[i];
        assert!((u[i] - want).abs() < 1e-14, "{i}: {} vs {want}", u[i]);
    }
    let (m1, v1) = moments(&u);
    assert!((m1 - m0).abs() < 1e-14, "mean {m0} → {m1}");
    assert!((v1 - v0).abs() < 1e-13, "variance {v0} → {v1}");
    // The values moved: the kernel is not the identity.
    assert!(u.iter().zip(&u0).all(|(x, y)| (x - y).abs() > 0.1));
    // Nothing to move: empty, or a non-finite value (no draw taken).
    assert!(!k.shrink(&mut [], || unreachable!()));
    let mut bad = [1.0, f64::NAN];
    assert!(!k.shrink(&mut bad, || unreachable!()));
}

/// Over 200 000 values of a skewed cloud with standard normal draws, the new mean and variance
/// are the old ones within 4 Monte-Carlo s.e.: mean error h√V·ε̄ (s.e. h√V/√N), variance error
/// h²V(s²_ε − 1) + 2ah√V·cov(u, ε) (s.e. V√((2h⁴ + 4a²h²)/N)).
#[test]
fn the_kernel_keeps_the_moments_within_monte_carlo_error() {
    let n = 200_000;
    let mut rng = stream(11, 0, "test/rejuvenation-cloud");
    let u0: Vec<f64> = (0..n)
        .map(|_| {
            let z: f64 = StandardNormal.sample(&mut rng);
            (0.8 * z).exp() - 1.0
        })
        .collect();
    let (m0, v0) = moments(&u0);
    for delta in [0.5, 0.95, 0.99] {
        let k = LiuWest::new(delta).unwrap();
        let (a, h) = (k.shrinkage(), k.spread());
        let mut u = u0.clone();
        let mut draws = stream(11, 1, "test/rejuvenation-draws");
        assert!(k.shrink(&mut u, || StandardNormal.sample(&mut draws)));
        let (m1, v1) = moments(&u);
        let nf = n as f64;
        let se_m = h * v0.sqrt() / nf.sqrt();
        let se_v = v0 * ((2.0 * h.powi(4) + 4.0 * a * a * h * h) / nf).sqrt();
        assert!(
            (m1 - m0).abs() < 4.0 * se_m,
            "δ {delta}: mean {m0} → {m1}, s.e. {se_m}"
        );
        assert!(
            (v1 - v0).abs() < 4.0 * se_v,
            "δ {delta}: var {v0} → {v1}, s.e. {se_v}"
        );
        // The values themselves changed by about h√(2V) each.
        let moved = u.iter().zip(&u0).filter(|(x, y)| x != y).count();
        assert_eq!(moved, n);
    }
}

fn store(values: &[f64]) -> Particles {
    // Sampled block [x, n, y] with a marginal Gaussian of dimension 1.
    let shape = Shape {
        sampled: 3,
        marginal: 1,
    };
    let mut p = Particles::new(values.len(), shape);
    for (i, v) in values.iter().enumerate() {
        let q = p.particle_mut(i);
        q.sampled.copy_from_slice(&[i as f64, *v, -(i as f64)]);
        q.mean[0] = 10.0 + i as f64;
        q.cov[0] = 0.5;
    }
    p
}

/// Values on a bound, next to it and far apart, moved 50 times with the widest kernel
/// (δ = 1/3: every value a fresh draw of N(ū, V) in the transformed coordinate): every value
/// stays finite and strictly inside its support; the other entries are not touched.
#[test]
fn moved_values_stay_strictly_inside_the_support() {
    let np = 64;
    let interval = Support::Interval { lo: 1.0, hi: 5.0 };
    let half_line = Support::Above { lo: 0.0 };
    let mut rng = stream(3, 0, "test/rejuvenation-bounds");
    for (support, seeds) in [
        (interval, vec![1.0, 5.0, 1.0 + 1e-15, 5.0 - 1e-15, 3.0, 1.0]),
        (half_line, vec![0.0, 1e-300, 1e300, 1.0, 1e-310, 0.0]),
    ] {
        let values: Vec<f64> = (0..np).map(|i| seeds[i % seeds.len()]).collect();
        let mut p = store(&values);
        let before = p.clone();
        let params = [StaticParam { index: 1, support }];
        let k = LiuWest::new(1.0 / 3.0).unwrap();
        let mut mv = Rejuvenation::new(k, &params, np).unwrap();
        for round in 0..50 {
            mv.apply(&mut p, &mut rng);
            for i in 0..np {
                let v = p.sampled(i)[1];
                assert!(
                    v.is_finite() && support.contains_strictly(v),
                    "{support:?}, round {round}, particle {i}: {v}"
                );
                assert_eq!(p.sampled(i)[0], before.sampled(i)[0]);
                assert_eq!(p.sampled(i)[2], before.sampled(i)[2]);
                assert_eq!(p.mean(i), before.mean(i));
                assert_eq!(p.cov(i), before.cov(i));
            }
        }
        // A move that did nothing would pass the checks above: the values did change.
        assert!((0..np).all(|i| p.sampled(i)[1] != before.sampled(i)[1]));
    }
}

/// The move takes exactly one standard normal per particle and static parameter from the given
/// stream, in order; with nothing to move (δ = 1, or no parameter) there is no move at all.
#[test]
fn the_move_draws_one_normal_per_particle_and_parameter_from_the_stream() {
    let np = 40;
    let values: Vec<f64> = (0..np).map(|i| 1.5 + 0.05 * i as f64).collect();
    let mut p = store(&values);
    let params = [
        StaticParam {
            index: 1,
            support: Support::Interval { lo: 1.0, hi: 5.0 },
        },
        StaticParam {
            index: 0,
            support: Support::Above { lo: -1.0 },
        },
    ];
    let k = LiuWest::new(0.98).unwrap();
    let mut mv = Rejuvenation::new(k, &params, np).unwrap();
    let mut rng = stream(9, 0, "test/rejuvenation-stream");
    let mut twin = rng.clone();
    mv.apply(&mut p, &mut rng);
    // The same values from the twin stream by the kernel itself, parameter after parameter.
    for (q, param) in params.iter().enumerate() {
        let mut u: Vec<f64> = (0..np)
            .map(|i| {
                let theta = if q == 0 { values[i] } else { i as f64 };
                param.support.to_unbounded(theta)
            })
            .collect();
        assert!(k.shrink(&mut u, || StandardNormal.sample(&mut twin)));
        for i in 0..np {
            assert_eq!(
                p.sampled(i)[param.index],
                param.support.from_unbounded(u[i])
            );
        }
    }
    let (x, y): (u64, u64) = (rand::Rng::random(&mut rng), rand::Rng::random(&mut twin));
    assert_eq!(x, y, "the streams are at the same place");
    assert!(Rejuvenation::new(LiuWest::new(1.0).unwrap(), &params, np).is_none());
    assert!(Rejuvenation::new(k, &[], np).is_none());
}
