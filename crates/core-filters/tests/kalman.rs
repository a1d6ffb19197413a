//! Gaussian filters (SPEC §4) against independent computations: a hand-written scalar recursion,
//! batch conditioning of the joint Gaussian of all states and measurements, exact and
//! Monte-Carlo moments of quadratic maps, dense Hessian traces, Table I, and the documented
//! behaviour on ill-conditioned, indefinite and non-finite input.

use core_filters::kalman::{
    ekf2_moments, ekf2_propagate, ekf2_update, gaussian_update, kalman_filter, kf_propagate,
    kf_update, second_order_terms, table1, table1_rows, Expansion, LinearGaussian, StepLog,
    UtParams,
};
use core_filters::linalg::gauss::cholesky_repaired;
use core_filters::model::SparseHessians;
use core_filters::rng::stream;
use core_filters::{FilterError, Health};
use nalgebra::{DMatrix, DVector, Matrix1, SMatrix, SVector, Vector1};
use rand::Rng;
use rand_distr::StandardNormal;

fn normal<R: Rng>(rng: &mut R) -> f64 {
    rng.sample(StandardNormal)
}

fn random_matrix<const R: usize, const C: usize, G: Rng>(
    rng: &mut G,
    scale: f64,
) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|_, _| scale * normal(rng))
}

/// A random SPD matrix `A Aᵀ + δ I`.
fn random_spd<const N: usize, G: Rng>(rng: &mut G, delta: f64) -> SMatrix<f64, N, N> {
    let a: SMatrix<f64, N, N> = random_matrix(rng, 1.0);
    a * a.transpose() + SMatrix::identity() * delta
}

fn simulate<const N: usize, const NY: usize, G: Rng>(
    model: &LinearGaussian<N, NY>,
    steps: usize,
    rng: &mut G,
) -> Vec<SVector<f64, NY>> {
    let chol_q = model.q.cholesky().unwrap().l();
    let chol_r = model.r.cholesky().unwrap().l();
    let chol_p0 = model.p0.cholesky().unwrap().l();
    let mut z = model.m0 + chol_p0 * SVector::<f64, N>::from_fn(|_, _| normal(rng));
    (0..steps)
        .map(|_| {
            z = model.g_mat * z
                + model.g_off
                + chol_q * SVector::<f64, N>::from_fn(|_, _| normal(rng));
            model.h_mat * z + model.h_off + chol_r * SVector::<f64, NY>::from_fn(|_, _| normal(rng))
        })
        .collect()
}

/// SPEC §4 KF on a scalar model against the textbook scalar recursion written out by hand.
#[test]
fn kf_matches_hand_written_scalar_recursion() {
    let (a, b, q, c, d, r) = (0.9, 0.3, 0.2, 1.5, -0.4, 0.5);
    let (m0, p0) = (1.0, 2.0);
    let model = LinearGaussian::<1, 1> {
        g_mat: Matrix1::new(a),
        g_off: Vector1::new(b),
        h_mat: Matrix1::new(c),
        h_off: Vector1::new(d),
        q: Matrix1::new(q),
        r: Matrix1::new(r),
        m0: Vector1::new(m0),
        p0: Matrix1::new(p0),
    };
    let ys: Vec<f64> = vec![0.7, 1.9, -0.3, 2.2, 1.1, 0.0, 3.0];
    let ysv: Vec<_> = ys.iter().map(|&y| Vector1::new(y)).collect();
    let run = kalman_filter(&model, &ysv).unwrap();

    let (mut m, mut p, mut ll) = (m0, p0, 0.0);
    for (k, &y) in ys.iter().enumerate() {
        m = a * m + b;
        p = a * a * p + q;
        let s = c * c * p + r;
        let innov = y - (c * m + d);
        ll += -0.5 * (2.0 * std::f64::consts::PI * s).ln() - 0.5 * innov * innov / s;
        let gain = p * c / s;
        m += gain * innov;
        p -= gain * s * gain;
        assert!((run.means[k][0] - m).abs() < 1e-10, "mean at k={}", k + 1);
        assert!(
            (run.covs[k][(0, 0)] - p).abs() < 1e-10,
            "cov at k={}",
            k + 1
        );
    }
    assert!((run.loglik - ll).abs() < 1e-10, "{} vs {}", run.loglik, ll);
    assert_eq!(run.health, Health::default());
}

/// Independent reference: every state and measurement is an affine map of the base Gaussian
/// ξ = (z_0, v_1..v_T, η_1..η_T); filtered moments are conditionals of the joint Gaussian and
/// the log-likelihood is the joint density of y_1:T.
#[test]
fn kf_matches_batch_conditioning_of_the_joint_gaussian() {
    const N: usize = 3;
    const NY: usize = 2;
    const T: usize = 6;
    let mut rng = stream(11, 0, "kalman-test/batch");
    let model = LinearGaussian::<N, NY> {
        g_mat: random_matrix(&mut rng, 0.5),
        g_off: random_matrix(&mut rng, 1.0),
        h_mat: random_matrix(&mut rng, 1.0),
        h_off: random_matrix(&mut rng, 1.0),
        q: random_spd(&mut rng, 0.1) * 0.2,
        r: random_spd(&mut rng, 0.1) * 0.3,
        m0: random_matrix(&mut rng, 1.0),
        p0: random_spd(&mut rng, 0.5),
    };
    let ys = simulate(&model, T, &mut rng);
    let run = kalman_filter(&model, &ys).unwrap();

    let dim = N + T * N + T * NY;
    let mut cov_xi = DMatrix::<f64>::zeros(dim, dim);
    let mut mean_xi = DVector::<f64>::zeros(dim);
    let put = |c: &mut DMatrix<f64>, at: usize, b: &DMatrix<f64>| {
        c.view_mut((at, at), (b.nrows(), b.ncols())).copy_from(b)
    };
    let dyn_m = |m: &dyn Fn(usize, usize) -> f64, r: usize, c: usize| DMatrix::from_fn(r, c, m);
    put(&mut cov_xi, 0, &dyn_m(&|i, j| model.p0[(i, j)], N, N));
    mean_xi.rows_mut(0, N).copy_from_slice(model.m0.as_slice());
    for k in 0..T {
        put(
            &mut cov_xi,
            N + k * N,
            &dyn_m(&|i, j| model.q[(i, j)], N, N),
        );
        put(
            &mut cov_xi,
            N + T * N + k * NY,
            &dyn_m(&|i, j| model.r[(i, j)], NY, NY),
        );
    }
    // z_k = A_k ξ + c_k, y_k = B_k ξ + e_k.
    let g = dyn_m(&|i, j| model.g_mat[(i, j)], N, N);
    let h = dyn_m(&|i, j| model.h_mat[(i, j)], NY, N);
    let mut a_k = DMatrix::<f64>::zeros(N, dim);
    a_k.view_mut((0, 0), (N, N)).fill_with_identity();
    let mut c_k = DVector::<f64>::zeros(N);
    let mut b_rows = DMatrix::<f64>::zeros(T * NY, dim);
    let mut e_rows = DVector::<f64>::zeros(T * NY);
    let y_all = DVector::from_iterator(T * NY, ys.iter().flat_map(|y| y.iter().copied()));
    for k in 0..T {
        a_k = &g * &a_k;
        c_k = &g * &c_k + DVector::from_column_slice(model.g_off.as_slice());
        for i in 0..N {
            a_k[(i, N + k * N + i)] += 1.0;
        }
        let mut b_k = &h * &a_k;
        for i in 0..NY {
            b_k[(i, N + T * N + k * NY + i)] += 1.0;
        }
        let e_k = &h * &c_k + DVector::from_column_slice(model.h_off.as_slice());
        b_rows.view_mut((k * NY, 0), (NY, dim)).copy_from(&b_k);
        e_rows.rows_mut(k * NY, NY).copy_from(&e_k);

        // Condition z_k on y_1..y_k.
        let ny = (k + 1) * NY;
        let b = b_rows.rows(0, ny).into_owned();
        let mu_y = &b * &mean_xi + e_rows.rows(0, ny);
        let s_yy = &b * &cov_xi * b.transpose();
        let s_zy = &a_k * &cov_xi * b.transpose();
        let mu_z = &a_k * &mean_xi + &c_k;
        let s_zz = &a_k * &cov_xi * a_k.transpose();
        let chol = s_yy.clone().cholesky().unwrap();
        let innov = y_all.rows(0, ny) - &mu_y;
        let cond_mean = &mu_z + &s_zy * chol.solve(&innov);
        let cond_cov = &s_zz - &s_zy * chol.solve(&s_zy.transpose());
        for i in 0..N {
            assert!(
                (run.means[k][i] - cond_mean[i]).abs() < 1e-10,
                "mean k={} i={i}",
                k + 1
            );
            for j in 0..N {
                assert!((run.covs[k][(i, j)] - cond_cov[(i, j)]).abs() < 1e-10);
            }
        }
        if k == T - 1 {
            let l = chol.l();
            let white = l.solve_lower_triangular(&innov).unwrap();
            let log_det: f64 = 2.0 * l.diagonal().iter().map(|v| v.ln()).sum::<f64>();
            let ll = -0.5 * white.norm_squared()
                - 0.5 * log_det
                - 0.5 * (ny as f64) * (2.0 * std::f64::consts::PI).ln();
            assert!((run.loglik - ll).abs() < 1e-10, "{} vs {ll}", run.loglik);
        }
    }
}

/// EKF1 (empty Hessians) and EKF2 (explicit zero Hessians) on a linear model reproduce the KF.
#[test]
fn ekf_and_ekf2_equal_kf_on_a_linear_model() {
    const N: usize = 4;
    const NY: usize = 2;
    let mut rng = stream(12, 0, "kalman-test/ekf-linear");
    let model = LinearGaussian::<N, NY> {
        g_mat: random_matrix(&mut rng, 0.5),
        g_off: random_matrix(&mut rng, 1.0),
        h_mat: random_matrix(&mut rng, 1.0),
        h_off: random_matrix(&mut rng, 1.0),
        q: random_spd(&mut rng, 0.1) * 0.2,
        r: random_spd(&mut rng, 0.1) * 0.3,
        m0: random_matrix(&mut rng, 1.0),
        p0: random_spd(&mut rng, 0.5),
    };
    let ys = simulate(&model, 20, &mut rng);
    let run = kalman_filter(&model, &ys).unwrap();
    let mut zero_dyn = SparseHessians::new();
    let mut zero_obs = SparseHessians::new();
    for i in 0..N {
        zero_dyn.push(i, i, (i + 1) % N, 0.0);
        zero_dyn.push(i, i, i, 0.0);
    }
    for i in 0..NY {
        zero_obs.push(i, 0, i + 1, 0.0);
    }
    let empty = SparseHessians::new();
    for (hd, ho) in [(&empty, &empty), (&zero_dyn, &zero_obs)] {
        let (mut m, mut p) = (model.m0, model.p0);
        let mut health = Health::default();
        let mut ll = 0.0;
        for (idx, y) in ys.iter().enumerate() {
            let phi = Expansion {
                value: model.g_mat * m + model.g_off,
                jac: model.g_mat,
                hess: hd,
            };
            ekf2_propagate(&mut m, &mut p, &phi, &model.q);
            let psi = Expansion {
                value: model.h_mat * m + model.h_off,
                jac: model.h_mat,
                hess: ho,
            };
            let log = StepLog {
                step: idx + 1,
                health: &mut health,
            };
            let inn = ekf2_update(&mut m, &mut p, y, &psi, &model.r, log).unwrap();
            ll += inn.loglik;
            assert!((m - run.means[idx]).abs().max() < 1e-12);
            assert!((p - run.covs[idx]).abs().max() < 1e-12);
        }
        assert!((ll - run.loglik).abs() < 1e-12);
        assert_eq!(health, Health::default());
    }
}

/// The quadratic test map y = c + B x + ½ [xᵀA₀x, xᵀA₁x] on R³:
/// y0 = 0.5 + x0 − x2 + x0 x1 + 0.75 x2², y1 = −1 + 2 x1 + x1 x2 − 0.5 x0² + 0.3 x0 x2.
fn quad_map(x: &SVector<f64, 3>) -> SVector<f64, 2> {
    SVector::<f64, 2>::new(
        0.5 + x[0] - x[2] + x[0] * x[1] + 0.75 * x[2] * x[2],
        -1.0 + 2.0 * x[1] + x[1] * x[2] - 0.5 * x[0] * x[0] + 0.3 * x[0] * x[2],
    )
}

fn quad_hessians() -> SparseHessians {
    let mut h = SparseHessians::new();
    h.push(0, 0, 1, 1.0);
    h.push(0, 2, 2, 1.5);
    h.push(1, 1, 2, 1.0);
    h.push(1, 0, 0, -1.0);
    h.push(1, 2, 0, 0.3);
    h
}

fn quad_jacobian(x: &SVector<f64, 3>) -> SMatrix<f64, 2, 3> {
    SMatrix::<f64, 2, 3>::new(
        1.0 + x[1],
        x[0],
        -1.0 + 1.5 * x[2],
        -x[0] + 0.3 * x[2],
        2.0 + x[2],
        x[1] + 0.3 * x[0],
    )
}

/// SPEC §4: for a quadratic map of a Gaussian the EKF2 moments are exact. Checked against the
/// closed form (Isserlis, with dense Hessians) and against a seeded Monte-Carlo estimate within
/// 4 standard errors.
#[test]
fn ekf2_moments_of_a_quadratic_map_are_exact() {
    let mu = SVector::<f64, 3>::new(0.4, -0.8, 1.1);
    let p = SMatrix::<f64, 3, 3>::new(0.5, 0.1, -0.2, 0.1, 0.3, 0.05, -0.2, 0.05, 0.4);
    let hess = quad_hessians();
    let psi = Expansion {
        value: quad_map(&mu),
        jac: quad_jacobian(&mu),
        hess: &hess,
    };
    let (mean, cov) = ekf2_moments(&p, &psi, &SMatrix::zeros());

    // Closed form: y_i = f_i(μ) + g_iᵀ δ + ½ δᵀ A_i δ with δ ~ N(0, P), g_i the gradient at μ:
    // E y_i = f_i(μ) + ½ tr(A_i P), Cov = g_iᵀ P g_j + ½ tr(A_i P A_j P).
    let pd = DMatrix::from_fn(3, 3, |i, j| p[(i, j)]);
    let a = [hess.dense(0, 3), hess.dense(1, 3)];
    let jac = quad_jacobian(&mu);
    let f_mu = quad_map(&mu);
    for i in 0..2 {
        let exact_mean = f_mu[i] + 0.5 * (&a[i] * &pd).trace();
        assert!((mean[i] - exact_mean).abs() < 1e-12);
        for j in 0..2 {
            let gi = jac.row(i).transpose();
            let gj = jac.row(j).transpose();
            let exact =
                (gi.transpose() * p * gj)[(0, 0)] + 0.5 * (&a[i] * &pd * &a[j] * &pd).trace();
            assert!((cov[(i, j)] - exact).abs() < 1e-12);
        }
    }

    // Monte Carlo with a fixed seed.
    let n = 200_000;
    let l = p.cholesky().unwrap().l();
    let mut rng = stream(13, 0, "kalman-test/ekf2-mc");
    let samples: Vec<SVector<f64, 2>> = (0..n)
        .map(|_| quad_map(&(mu + l * SVector::<f64, 3>::from_fn(|_, _| normal(&mut rng)))))
        .collect();
    let nf = n as f64;
    let mc_mean: SVector<f64, 2> = samples.iter().sum::<SVector<f64, 2>>() / nf;
    for i in 0..2 {
        let se_mean = (cov[(i, i)] / nf).sqrt();
        assert!(
            (mc_mean[i] - mean[i]).abs() < 4.0 * se_mean,
            "mean {i}: MC {} EKF2 {} se {se_mean}",
            mc_mean[i],
            mean[i]
        );
        for j in i..2 {
            // Sample covariance and the standard error of its terms (d_i d_j).
            let prods: Vec<f64> = samples
                .iter()
                .map(|s| (s[i] - mc_mean[i]) * (s[j] - mc_mean[j]))
                .collect();
            let c_hat = prods.iter().sum::<f64>() / (nf - 1.0);
            let var_prod = prods.iter().map(|v| (v - c_hat).powi(2)).sum::<f64>() / (nf - 1.0);
            let se = (var_prod / nf).sqrt();
            assert!(
                (c_hat - cov[(i, j)]).abs() < 4.0 * se,
                "cov ({i},{j}): MC {c_hat} EKF2 {} se {se}",
                cov[(i, j)]
            );
        }
    }
}

/// SPEC Table I: T2 (nx, 2nx), UT with β = 2, κ = 0 (nx, 2nx²), T1 (0, 0), exact (nx, 2nx).
#[test]
fn table1_values_are_exact() {
    let rows = table1().unwrap();
    assert_eq!(rows.len(), 40);
    for row in &rows {
        let nx = row.nx as f64;
        let (mean, var) = match row.method {
            "exact" | "T2" => (nx, 2.0 * nx),
            "T1" => (0.0, 0.0),
            "UT" => (nx, 2.0 * nx * nx),
            other => panic!("unexpected method {other}"),
        };
        assert!((row.mean - mean).abs() < 1e-9, "{row:?}");
        assert!((row.variance - var).abs() < 1e-9, "{row:?}");
    }
    for nx in 1..=10 {
        assert_eq!(rows.iter().filter(|r| r.nx == nx).count(), 4);
    }
    // Table I holds for any α: check a small one.
    let small = UtParams {
        alpha: 1e-3,
        beta: 2.0,
        kappa: 0.0,
    };
    let ut7 = table1_rows::<7>(&small).unwrap()[3];
    assert_eq!(ut7.method, "UT");
    assert!(
        (ut7.mean - 7.0).abs() < 1e-9 && (ut7.variance - 98.0).abs() < 1e-9,
        "{ut7:?}"
    );
}

/// Sparse second-order terms equal the explicit dense traces on random sparse Hessians.
#[test]
fn second_order_terms_equal_dense_traces() {
    const N: usize = 7;
    const NO: usize = 4;
    let mut rng = stream(14, 0, "kalman-test/second-order");
    for _trial in 0..20 {
        let mut hess = SparseHessians::new();
        let nnz = rng.random_range(1..15);
        for _ in 0..nnz {
            let out = rng.random_range(0..NO);
            let a = rng.random_range(0..N);
            // Diagonal entries a quarter of the time; duplicates allowed (they add).
            let b = if rng.random_bool(0.25) {
                a
            } else {
                rng.random_range(0..N)
            };
            hess.push(out, a, b, normal(&mut rng));
        }
        let p: SMatrix<f64, N, N> = random_spd(&mut rng, 0.1);
        let (mean, cov): (SVector<f64, NO>, SMatrix<f64, NO, NO>) = second_order_terms(&hess, &p);
        // The same entries grouped by output (the order models use) give the same terms.
        let mut by_output = hess.entries().to_vec();
        by_output.sort_by_key(|e| e.output);
        let mut sorted = SparseHessians::new();
        for e in &by_output {
            sorted.push(e.output, e.a, e.b, e.value);
        }
        let (mean_s, cov_s): (SVector<f64, NO>, SMatrix<f64, NO, NO>) =
            second_order_terms(&sorted, &p);
        assert!((mean_s - mean).abs().max() < 1e-12 * (1.0 + mean.abs().max()));
        assert!((cov_s - cov).abs().max() < 1e-12 * (1.0 + cov.abs().max()));
        let pd = DMatrix::from_fn(N, N, |i, j| p[(i, j)]);
        let dense: Vec<DMatrix<f64>> = (0..NO).map(|i| hess.dense(i, N)).collect();
        for i in 0..NO {
            let m_ref = 0.5 * (&dense[i] * &pd).trace();
            assert!((mean[i] - m_ref).abs() < 1e-12 * (1.0 + m_ref.abs()));
            for j in 0..NO {
                let c_ref = 0.5 * (&dense[i] * &pd * &dense[j] * &pd).trace();
                assert!(
                    (cov[(i, j)] - c_ref).abs() < 1e-12 * (1.0 + c_ref.abs()),
                    "({i},{j}) {} vs {c_ref}",
                    cov[(i, j)]
                );
            }
        }
    }
}

/// A nearly singular innovation covariance (two perfectly correlated predicted outputs and a
/// vanishing measurement noise) is repaired by counted jitter; the result is finite.
#[test]
fn nearly_singular_innovation_covariance_is_repaired_and_counted() {
    let mut m = SVector::<f64, 2>::new(1.0, -1.0);
    let mut p = SMatrix::<f64, 2, 2>::new(2.0, 0.5, 0.5, 1.0);
    // Both outputs observe x0: J P Jᵀ has rank one.
    let jac = SMatrix::<f64, 2, 2>::new(1.0, 0.0, 1.0, 0.0);
    let r = SMatrix::<f64, 2, 2>::identity() * 1e-300;
    let y = SVector::<f64, 2>::new(1.5, 1.5);
    let mut health = Health::default();
    let inn = kf_update(
        &mut m,
        &mut p,
        &y,
        &jac,
        &SVector::zeros(),
        &r,
        StepLog {
            step: 5,
            health: &mut health,
        },
    )
    .unwrap();
    assert_eq!(health.jitter_added, 1);
    assert_eq!(health.cholesky_failures, 0);
    assert!(inn.loglik.is_finite());
    assert!(m.iter().chain(p.iter()).all(|v| v.is_finite()));
    // The repaired update is (to the jitter) the exact single-observation update of x0 = 1.5.
    assert!((m[0] - 1.5).abs() < 1e-6, "{m}");
    assert!(p[(0, 0)].abs() < 1e-6, "{p}");
}

/// A covariance perturbed to be slightly indefinite is repaired by jitter; a clearly indefinite
/// one is a typed error and leaves the filter state untouched.
#[test]
fn slightly_indefinite_covariance_is_repaired_clearly_indefinite_is_an_error() {
    // Eigenvalues 2 and −1e-10 (relative to the diagonal scale 1).
    let (c, s) = (0.6_f64, 0.8_f64);
    let rot = SMatrix::<f64, 2, 2>::new(c, -s, s, c);
    let slightly = rot
        * SMatrix::<f64, 2, 2>::from_diagonal(&SVector::<f64, 2>::new(2.0, -1e-10))
        * rot.transpose();
    let mut health = Health::default();
    let l = cholesky_repaired(slightly.as_slice(), 2, 3, "test covariance", &mut health).unwrap();
    let l = SMatrix::<f64, 2, 2>::from_column_slice(&l);
    assert_eq!(health.jitter_added, 1);
    assert!((l * l.transpose() - slightly).abs().max() < 1e-7);

    // The same through an update (S = 0 so L = J P Jᵀ is the indefinite matrix).
    let mut m = SVector::<f64, 2>::zeros();
    let mut p = slightly;
    let mut health = Health::default();
    let y = SVector::<f64, 2>::new(0.1, 0.2);
    let res = gaussian_update(
        &mut m,
        &mut p,
        &y,
        &SVector::zeros(),
        &SMatrix::identity(),
        &SMatrix::zeros(),
        StepLog {
            step: 9,
            health: &mut health,
        },
    );
    assert!(res.is_ok());
    assert_eq!(health.jitter_added, 1);
    assert!(m.iter().chain(p.iter()).all(|v| v.is_finite()));

    let clearly = rot
        * SMatrix::<f64, 2, 2>::from_diagonal(&SVector::<f64, 2>::new(2.0, -0.1))
        * rot.transpose();
    let mut m = SVector::<f64, 2>::new(0.3, 0.4);
    let mut p = clearly;
    let mut health = Health::default();
    let err = gaussian_update(
        &mut m,
        &mut p,
        &y,
        &SVector::zeros(),
        &SMatrix::identity(),
        &SMatrix::zeros(),
        StepLog {
            step: 9,
            health: &mut health,
        },
    )
    .unwrap_err();
    assert_eq!(
        err,
        FilterError::NotPositiveDefinite {
            step: 9,
            which: "innovation covariance"
        }
    );
    assert_eq!(health.cholesky_failures, 1);
    assert_eq!(m, SVector::<f64, 2>::new(0.3, 0.4));
    assert_eq!(p, clearly);
}

/// NaN in the measurement, the mean or the covariance is a typed `NonFinite` error, never a panic
/// and never a NaN written into the filter state.
#[test]
fn non_finite_input_is_a_typed_error() {
    let m0 = SVector::<f64, 2>::new(0.3, 0.4);
    let p0 = SMatrix::<f64, 2, 2>::new(1.0, 0.2, 0.2, 0.5);
    let hm = SMatrix::<f64, 1, 2>::new(1.0, 1.0);
    let r = Matrix1::new(0.1);
    let cases: [(SVector<f64, 2>, SMatrix<f64, 2, 2>, Vector1<f64>); 4] = [
        (m0, p0, Vector1::new(f64::NAN)),
        (m0, p0, Vector1::new(f64::INFINITY)),
        (SVector::<f64, 2>::new(f64::NAN, 0.0), p0, Vector1::new(1.0)),
        (
            m0,
            SMatrix::<f64, 2, 2>::new(1.0, f64::NAN, f64::NAN, 0.5),
            Vector1::new(1.0),
        ),
    ];
    for (m_in, p_in, y) in cases {
        let (mut m, mut p) = (m_in, p_in);
        let mut health = Health::default();
        let err = kf_update(
            &mut m,
            &mut p,
            &y,
            &hm,
            &Vector1::zeros(),
            &r,
            StepLog {
                step: 2,
                health: &mut health,
            },
        )
        .unwrap_err();
        assert_eq!(err.kind(), "non_finite", "{err}");
        assert_eq!(err.step(), 2);
        // Unchanged (compare bitwise so NaN inputs compare equal to themselves).
        assert!(m
            .iter()
            .zip(m_in.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(p
            .iter()
            .zip(p_in.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }
    // EKF2 with a NaN covariance: the Hessian terms are NaN too, still a typed error.
    let mut m = m0;
    let mut p = SMatrix::<f64, 2, 2>::new(f64::NAN, 0.0, 0.0, 1.0);
    let mut hess = SparseHessians::new();
    hess.push(0, 0, 1, 1.0);
    let mut health = Health::default();
    let psi = Expansion {
        value: Vector1::new(0.12),
        jac: hm,
        hess: &hess,
    };
    let log = StepLog {
        step: 3,
        health: &mut health,
    };
    let err = ekf2_update(&mut m, &mut p, &Vector1::new(1.0), &psi, &r, log).unwrap_err();
    assert_eq!(err.kind(), "non_finite");
    assert_eq!(m, m0);
}

/// KF propagate keeps the covariance exactly symmetric.
#[test]
fn kf_propagate_output_is_symmetric() {
    let mut rng = stream(15, 0, "kalman-test/propagate");
    let g: SMatrix<f64, 5, 5> = random_matrix(&mut rng, 1.0);
    let q: SMatrix<f64, 5, 5> = random_spd(&mut rng, 0.1);
    let mut m = SVector::<f64, 5>::zeros();
    let mut p: SMatrix<f64, 5, 5> = random_spd(&mut rng, 0.1);
    for _ in 0..10 {
        kf_propagate(&mut m, &mut p, &g, &SVector::repeat(0.1), &q);
    }
    assert_eq!(p, p.transpose());
}
