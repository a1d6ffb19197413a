//! Cost of one MPF-EKF2 particle's Gaussian work (SPEC §5.4 (b), (c), (e)) at 13 marginalised
//! states with the sparse Hessians of SPEC §6, on the kernels the particle filters run
//! ([`core_filters::linalg`]): the pseudo-measurement factorisation and conditioning on a draw,
//! the near-identity EKF2 propagate, and the measurement update. Inputs are seeded; set-up is
//! outside the timed closure.

use core_filters::linalg::gauss::{factorise, Factor};
use core_filters::linalg::{
    ekf2_propagate_near_identity, PropagateScratch, Propagation, SecondOrder, Sparse, SymEntries,
};
use core_filters::model::SparseHessians;
use core_filters::rng::stream;
use core_filters::Health;
use criterion::{black_box, criterion_group, criterion_main, BatchSize, Criterion};
use rand::Rng;
use rand_distr::StandardNormal;

fn random<G: Rng>(rng: &mut G, len: usize, scale: f64) -> Vec<f64> {
    (0..len)
        .map(|_| scale * rng.sample::<f64, _>(StandardNormal))
        .collect()
}

/// `A Aᵀ + I` (`n × n`, column-major).
fn spd<G: Rng>(rng: &mut G, n: usize, scale: f64) -> Vec<f64> {
    let a = random(rng, n * n, 1.0);
    let mut p = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let v: f64 = (0..n).map(|k| a[i + k * n] * a[j + k * n]).sum();
            p[i + j * n] = scale * (v + if i == j { 1.0 } else { 0.0 });
        }
    }
    p
}

/// A dense `rows × cols` Jacobian as entries.
fn dense_jacobian<G: Rng>(rng: &mut G, rows: usize, cols: usize, scale: f64) -> Sparse<f64> {
    Sparse::nonzeros_of(&random(rng, rows * cols, scale), rows, cols)
}

/// The constant Hessians of SPEC §6 (the paper's chain partitioned for the MPF-EKF2; x^bl index
/// 0 x1, 1 x2, 2 x3, 3 ẋ2, 4 ẋ3, 5 k1, 6 k2, 7 k3, 8 c1, 9 c2, 10 c3, 11 β, 12 γ): of ψ_ẋ1, of
/// φ_bl and of the three measured accelerations.
fn spec6_hessians(dt: f64) -> (SparseHessians, SparseHessians, SparseHessians) {
    let mut sampled = SparseHessians::new();
    for (a, b, v) in [(6, 1, dt), (6, 0, -dt), (9, 3, dt)] {
        sampled.push(0, a, b, v);
    }
    let mut marginal = SparseHessians::new();
    let phi3 = [
        (6, 0, 1.0),
        (6, 1, -1.0),
        (7, 2, 1.0),
        (7, 1, -1.0),
        (9, 3, -1.0),
        (10, 4, 1.0),
        (10, 3, -1.0),
    ];
    let phi4 = [(7, 1, 1.0), (7, 2, -1.0), (10, 3, 1.0), (10, 4, -1.0)];
    for (a, b, v) in phi3 {
        marginal.push(3, a, b, dt * v);
    }
    for (a, b, v) in phi4 {
        marginal.push(4, a, b, dt * v);
    }
    let mut obs = SparseHessians::new();
    for (a, b, v) in [(6, 1, 1.0), (6, 0, -1.0), (9, 3, 1.0)] {
        obs.push(0, a, b, v);
    }
    for (a, b, v) in phi3 {
        obs.push(1, a, b, v);
    }
    for (a, b, v) in phi4 {
        obs.push(2, a, b, v);
    }
    (sampled, marginal, obs)
}

fn ekf2_mpf_step(c: &mut Criterion) {
    const N: usize = 13;
    let dt = 0.005;
    let (sampled, marginal, obs) = spec6_hessians(dt);
    let (sampled, marginal, obs) = (
        SecondOrder::new(&sampled, N, 2),
        SecondOrder::new(&marginal, N, N),
        SecondOrder::new(&obs, N, 3),
    );
    let mut rng = stream(2, 0, "bench/ekf2");
    let m = random(&mut rng, N, 1.0);
    let p = spd(&mut rng, N, 0.1);
    // Pseudo-measurement (ẋ1, r1): prediction, Jacobian, noise Qₙ, draw ξ.
    let psi_n = random(&mut rng, 2, 1.0);
    let jac_n = dense_jacobian(&mut rng, 2, N, dt);
    let q_n = [1e-4, 0.0, 0.0, 1e-6];
    let xi = random(&mut rng, 2, 1.0);
    // Marginal transition: Euler map, Jacobian I + D with D = O(dt).
    let phi = random(&mut rng, N, 1.0);
    let d = dense_jacobian(&mut rng, N, N, dt);
    let marginal = Propagation {
        hess: marginal,
        q: SymEntries::diagonal(&[1e-8, 1e-8, 1e-8, 1e-8, 1e-8]),
    };
    // Measurement of three accelerations.
    let y_res = random(&mut rng, 3, 1.0);
    let jac_y = dense_jacobian(&mut rng, 3, N, 1.0);
    let r = [0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.3];

    let mut scratch = PropagateScratch::new(N, &marginal.hess);
    let mut pseudo = Factor::<f64>::new(N, 2);
    let mut update = Factor::<f64>::new(N, 3);
    let (mut s_n, mut s_y) = (vec![0.0; 4], vec![0.0; 9]);
    let (mut mean2, mut cov2) = (vec![0.0; 3], vec![0.0; 9]);
    let mut drawn = vec![0.0; 2];
    c.bench_function(
        "ekf2 13 states: pseudo-update 2 + propagate + update 3",
        |b| {
            b.iter_batched(
                || (m.clone(), p.clone(), Health::default()),
                |(mut m, mut p, mut health)| {
                    // (b) proposal = pseudo-measurement: L = J P Jᵀ + ½ tr(…) + Qₙ.
                    sampled.terms(&p, N, &mut mean2[..1], &mut cov2[..1]);
                    s_n.copy_from_slice(&q_n);
                    s_n[0] += cov2[0];
                    factorise(&mut pseudo, &p, &jac_n, &s_n, &mut health);
                    pseudo.condition_on_draw(&mut m, &mut p, &psi_n, &xi, &mut drawn);
                    // (c) propagate.
                    ekf2_propagate_near_identity(
                        &mut m,
                        &mut p,
                        N,
                        &phi,
                        &d,
                        &marginal,
                        &mut scratch,
                    );
                    // (e) measurement update.
                    obs.terms(&p, N, &mut mean2, &mut cov2);
                    s_y.copy_from_slice(&r);
                    for (s, v) in s_y.iter_mut().zip(&cov2) {
                        *s += v;
                    }
                    factorise(&mut update, &p, &jac_y, &s_y, &mut health);
                    let (loglik, _) = update.update(&mut m, &mut p, &y_res);
                    black_box((m, p, loglik))
                },
                BatchSize::SmallInput,
            )
        },
    );

    c.bench_function("second_order terms 13 states, 2 outputs of phi_bl", |b| {
        b.iter(|| {
            marginal
                .hess
                .terms(black_box(&p), N, &mut mean2[..2], &mut cov2[..4]);
            black_box((&mean2, &cov2));
        })
    });
}

criterion_group!(benches, ekf2_mpf_step);
criterion_main!(benches);
