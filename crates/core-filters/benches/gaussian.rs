//! Gaussian filter step costs (SPEC §4): one KF update (8 states, 3 measurements) and one
//! MPF-EKF2 particle's Gaussian work (SPEC §5.4 (b), (c), (e)) at 13 marginalised states with the
//! sparse Hessians of SPEC §6. Inputs are seeded; set-up is outside the timed closure.

use core_filters::kalman::{ekf2_propagate, ekf2_update, kf_update, second_order_terms};
use core_filters::model::SparseHessians;
use core_filters::rng::stream;
use core_filters::Health;
use criterion::{black_box, criterion_group, criterion_main, BatchSize, Criterion};
use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::StandardNormal;

fn random<const R: usize, const C: usize, G: Rng>(rng: &mut G, scale: f64) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|_, _| scale * rng.sample::<f64, _>(StandardNormal))
}

fn spd<const N: usize, G: Rng>(rng: &mut G) -> SMatrix<f64, N, N> {
    let a: SMatrix<f64, N, N> = random(rng, 1.0);
    a * a.transpose() + SMatrix::identity()
}

fn kf_update_8x3(c: &mut Criterion) {
    let mut rng = stream(1, 0, "bench/kf");
    let m: SVector<f64, 8> = random(&mut rng, 1.0);
    let p: SMatrix<f64, 8, 8> = spd(&mut rng);
    let h: SMatrix<f64, 3, 8> = random(&mut rng, 1.0);
    let h_off: SVector<f64, 3> = random(&mut rng, 1.0);
    let r: SMatrix<f64, 3, 3> = spd(&mut rng);
    let y: SVector<f64, 3> = random(&mut rng, 1.0);
    c.bench_function("kf_update 8 states 3 measurements", |b| {
        b.iter_batched(
            || (m, p, Health::default()),
            |(mut m, mut p, mut health)| {
                let inn = kf_update(&mut m, &mut p, &y, &h, &h_off, &r, 1, &mut health).unwrap();
                black_box((m, p, inn))
            },
            BatchSize::SmallInput,
        )
    });
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
    let dt = 0.005;
    let (sampled, marginal, obs) = spec6_hessians(dt);
    let mut rng = stream(2, 0, "bench/ekf2");
    let m: SVector<f64, 13> = random(&mut rng, 1.0);
    let p: SMatrix<f64, 13, 13> = spd(&mut rng) * 0.1;
    // Pseudo-measurement (ẋ1, r1): value, Jacobian, noise Qₙ.
    let xn: SVector<f64, 2> = random(&mut rng, 1.0);
    let psi_n: SVector<f64, 2> = random(&mut rng, 1.0);
    let jac_n: SMatrix<f64, 2, 13> = random(&mut rng, dt);
    let q_n = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::<f64, 2>::new(1e-4, 1e-6));
    // Marginal transition: Euler map, Jacobian I + O(dt).
    let phi: SVector<f64, 13> = random(&mut rng, 1.0);
    let jac_phi = SMatrix::<f64, 13, 13>::identity() + random::<13, 13, _>(&mut rng, dt);
    let mut q_bl = SMatrix::<f64, 13, 13>::zeros();
    for i in 0..5 {
        q_bl[(i, i)] = 1e-8;
    }
    // Measurement of three accelerations.
    let y: SVector<f64, 3> = random(&mut rng, 1.0);
    let psi_y: SVector<f64, 3> = random(&mut rng, 1.0);
    let jac_y: SMatrix<f64, 3, 13> = random(&mut rng, 1.0);
    let r: SMatrix<f64, 3, 3> = SMatrix::from_diagonal(&SVector::<f64, 3>::new(0.1, 0.2, 0.3));

    c.bench_function(
        "ekf2 13 states: pseudo-update 2 + propagate + update 3",
        |b| {
            b.iter_batched(
                || (m, p, Health::default()),
                |(mut m, mut p, mut health)| {
                    let a = ekf2_update(
                        &mut m,
                        &mut p,
                        &xn,
                        &psi_n,
                        &jac_n,
                        &sampled,
                        &q_n,
                        1,
                        &mut health,
                    )
                    .unwrap();
                    ekf2_propagate(&mut m, &mut p, &phi, &jac_phi, &marginal, &q_bl);
                    let e =
                        ekf2_update(&mut m, &mut p, &y, &psi_y, &jac_y, &obs, &r, 1, &mut health)
                            .unwrap();
                    black_box((m, p, a.loglik, e.loglik))
                },
                BatchSize::SmallInput,
            )
        },
    );

    c.bench_function("ekf2_propagate 13 states", |b| {
        b.iter_batched(
            || (m, p),
            |(mut m, mut p)| {
                ekf2_propagate(&mut m, &mut p, &phi, &jac_phi, &marginal, &q_bl);
                black_box((m, p))
            },
            BatchSize::SmallInput,
        )
    });

    c.bench_function("ekf2_update 13 states 3 measurements", |b| {
        b.iter_batched(
            || (m, p, Health::default()),
            |(mut m, mut p, mut health)| {
                let e = ekf2_update(&mut m, &mut p, &y, &psi_y, &jac_y, &obs, &r, 1, &mut health)
                    .unwrap();
                black_box((m, p, e.loglik))
            },
            BatchSize::SmallInput,
        )
    });

    c.bench_function("second_order_terms 13 states, 5 outputs of phi_bl", |b| {
        b.iter_batched(
            || (SVector::<f64, 13>::zeros(), SMatrix::<f64, 13, 13>::zeros()),
            |(mut mean, mut cov)| {
                second_order_terms(&marginal, &p, &mut mean, &mut cov);
                black_box((mean, cov))
            },
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, kf_update_8x3, ekf2_mpf_step);
criterion_main!(benches);
