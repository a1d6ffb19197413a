//! MPF-EKF2 on run-time dimensions (SPEC §5.4) against exact answers: a decoupled linear block is
//! the Kalman filter, a coupled linear model has an unbiased likelihood, and the batch layer gives
//! the bits of one particle at a time.

use crate::smc_common;

use core_filters::kalman::{kalman_filter, LinearGaussian};
use core_filters::linalg::{Sparse, SymEntries};
use core_filters::model::{Layout, Slot, SparseHessians};
use core_filters::real::Real;
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::{stream, StreamRng};
use core_filters::smc::model::{
    ConditionallyQuadratic, Marginalised, Partition, QuadraticDims, SampledAt,
};
use core_filters::smc::mpf::MpfEkf2;
use core_filters::smc::runner::NoObserver;
use core_filters::smc::{run, Filter, Observer, Posterior, SmcConfig, StepInfo};
use nalgebra::{Matrix1, Matrix2, Matrix3, SMatrix, SVector, Vector1, Vector2, Vector3};
use rand::Rng;
use smc_common::{normal, ratio_mean_and_se};

fn config(np: usize) -> SmcConfig {
    SmcConfig {
        particles: np,
        resampling: ResamplePolicy::default(),
        rejuvenation: None,
    }
}

#[derive(Default)]
struct Trace(Vec<Vec<f64>>);
impl Observer for Trace {
    fn on_step(&mut self, info: &StepInfo, p: &Posterior) {
        let mut row = p.param_mean.clone();
        row.extend(&p.param_sd);
        row.extend(&p.state_mean);
        row.extend(&p.state_sd);
        row.extend([info.loglik_increment, info.ess]);
        self.0.push(row);
    }
}

/// Simulates `steps` measurements (flat) of a linear-Gaussian model.
fn simulate<const N: usize, const NY: usize>(
    lg: &LinearGaussian<N, NY>,
    steps: usize,
    seed: u64,
) -> Vec<f64> {
    let mut rng = stream(seed, 0, "test-data");
    let chol_p0 = lg.p0.cholesky().expect("p0 SPD").l();
    let mut z = lg.m0 + chol_p0 * SVector::<f64, N>::from_fn(|_, _| normal(&mut rng));
    let chol_r = lg.r.cholesky().expect("R SPD").l();
    let mut out = Vec::new();
    for _ in 0..steps {
        let v = SVector::<f64, N>::from_fn(|i, _| lg.q[(i, i)].sqrt() * normal(&mut rng));
        z = lg.g_mat * z + lg.g_off + v;
        let y =
            lg.h_mat * z + lg.h_off + chol_r * SVector::<f64, NY>::from_fn(|_, _| normal(&mut rng));
        out.extend(y.iter());
    }
    out
}

fn rows<const N: usize>(flat: &[f64]) -> Vec<SVector<f64, N>> {
    flat.chunks_exact(N)
        .map(SVector::<f64, N>::from_column_slice)
        .collect()
}

fn names(n: usize, prefix: &str) -> Vec<String> {
    (0..n).map(|i| format!("{prefix}{i}")).collect()
}

/// Model A: x^bl linear-Gaussian and invisible to xⁿ (ψ does not depend on x^bl, no Hessians,
/// y independent of xⁿ). xⁿ = [dynamic, static].
#[derive(Clone)]
struct Decoupled {
    g: Matrix3<f64>,
    g_off: Vector3<f64>,
    h: SMatrix<f64, 2, 3>,
    h_off: Vector2<f64>,
    q_bl: SymEntries,
    q_bl_sd: Vector3<f64>,
    r: Matrix2<f64>,
    m0: Vector3<f64>,
    p0: Matrix3<f64>,
    empty: SparseHessians,
    stages: Vec<Vec<usize>>,
    qn_sd: Vec<f64>,
}

impl Decoupled {
    fn new() -> Self {
        let q_bl_sd = Vector3::new(0.1, 0.05, 0.0);
        Self {
            g: Matrix3::new(0.9, 0.1, 0.0, 0.0, 0.95, 0.2, 0.0, 0.0, 1.0),
            g_off: Vector3::new(0.1, 0.0, 0.0),
            h: SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.5, 0.0, 1.0, -1.0),
            h_off: Vector2::new(0.2, -0.1),
            q_bl: SymEntries::diagonal(q_bl_sd.map(|s| s * s).as_slice()),
            q_bl_sd,
            r: Matrix2::new(0.2, 0.05, 0.05, 0.3),
            m0: Vector3::new(0.5, -0.2, 1.0),
            p0: Matrix3::new(1.0, 0.3, 0.0, 0.3, 0.5, 0.1, 0.0, 0.1, 0.8),
            empty: SparseHessians::new(),
            stages: vec![vec![0]],
            qn_sd: vec![0.3],
        }
    }

    fn linear_gaussian(&self) -> LinearGaussian<3, 2> {
        LinearGaussian {
            g_mat: self.g,
            g_off: self.g_off,
            h_mat: self.h,
            h_off: self.h_off,
            q: Matrix3::from_diagonal(&self.q_bl_sd.map(|s| s * s)),
            r: self.r,
            m0: self.m0,
            p0: self.p0,
        }
    }
}

impl Partition for Decoupled {
    fn sample_initial(&self, rng: &mut StreamRng, xn: &mut [f64]) {
        xn[0] = normal(rng);
        xn[1] = rng.random();
    }

    fn measurement_cov(&self) -> Vec<f64> {
        self.r.as_slice().to_vec()
    }

    fn layout(&self) -> Layout {
        Layout {
            param_names: names(2, "theta"),
            params: vec![Slot::Marginal(2), Slot::Sampled(1)],
            state_names: names(3, "x"),
            states: vec![Slot::Marginal(0), Slot::Marginal(1), Slot::Sampled(0)],
        }
    }
}

impl ConditionallyQuadratic for Decoupled {
    fn dims(&self) -> QuadraticDims {
        QuadraticDims {
            nn: 2,
            nbl: 3,
            ny: 2,
        }
    }
    fn sampled_stages(&self) -> &[Vec<usize>] {
        &self.stages
    }
    fn sampled_dynamics<T: Real>(
        &self,
        at: SampledAt<'_, T>,
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        let xn_prev = at.prev;
        let [s] = T::per_lane([xn_prev[1]], |[x]| [x.sin()]);
        value[0] = T::splat(0.8) * xn_prev[0] + s;
        jac.add(0, 0, T::splat(0.0));
    }
    fn sampled_hessians(&self, _stage: usize) -> &SparseHessians {
        &self.empty
    }
    fn sampled_noise_sd(&self, _stage: usize) -> &[f64] {
        &self.qn_sd
    }
    fn marginal_dynamics<T: Real>(
        &self,
        _k: usize,
        _xn_prev: &[T],
        _xn_new: &[T],
        m: &[T],
        value: &mut [T],
        d: &mut Sparse<T>,
    ) {
        for r in 0..3 {
            let mut v = T::splat(self.g_off[r]);
            for c in 0..3 {
                v += T::splat(self.g[(r, c)]) * m[c];
                let dv = self.g[(r, c)] - if r == c { 1.0 } else { 0.0 };
                d.add(r, c, T::splat(dv));
            }
            value[r] = v;
        }
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn marginal_noise(&self) -> &SymEntries {
        &self.q_bl
    }
    fn observation<T: Real>(
        &self,
        _k: usize,
        _xn: &[T],
        m: &[T],
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        for r in 0..2 {
            let mut v = T::splat(self.h_off[r]);
            for c in 0..3 {
                v += T::splat(self.h[(r, c)]) * m[c];
                jac.add(r, c, T::splat(self.h[(r, c)]));
            }
            value[r] = v;
        }
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
}

impl Marginalised for Decoupled {
    fn marginal_prior(&self, _rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        mean.copy_from_slice(self.m0.as_slice());
        cov.copy_from_slice(self.p0.as_slice());
    }
}

#[test]
fn decoupled_linear_block_reproduces_the_kalman_filter() {
    let model = Decoupled::new();
    let lg = model.linear_gaussian();
    let ys = simulate(&lg, 60, 1);
    let kf = kalman_filter(&lg, &rows::<2>(&ys)).expect("KF runs");
    for lanes in [false, true] {
        let mut f = MpfEkf2::with_lanes(model.clone(), lanes);
        assert_eq!(f.uses_lanes(), lanes);
        let mut t = Trace::default();
        let s = run(
            &mut f,
            &config(25),
            &ys,
            2,
            &mut stream(2, 0, "mpf"),
            &mut t,
        );
        assert!(s.failure.is_none());
        assert!((s.loglik - kf.loglik).abs() < 1e-9 * kf.loglik.abs().max(1.0));
        for (idx, row) in t.0.iter().enumerate() {
            // row: [θ means (2), θ sds (2), state means (3), state sds (3), loglik inc, ess]
            assert!(
                (row[10] - kf.loglik_increments[idx]).abs() < 1e-9,
                "k={}: {} vs {}",
                idx + 1,
                row[10],
                kf.loglik_increments[idx]
            );
            let (m, c) = (&kf.means[idx], &kf.covs[idx]);
            assert!((row[0] - m[2]).abs() < 1e-9 && (row[2] - c[(2, 2)].sqrt()).abs() < 1e-9);
            for j in 0..2 {
                assert!((row[4 + j] - m[j]).abs() < 1e-9, "k={} state {j}", idx + 1);
                assert!((row[7 + j] - c[(j, j)].sqrt()).abs() < 1e-9);
            }
        }
        assert_eq!(s.health.resamples, (ys.len() / 2) as u64 - 1);
        assert_eq!(s.health.repairs(), 0);
    }
}

/// Model B: fully linear-Gaussian, xⁿ observes x^bl, no Hessians:
/// `xⁿ_k = a xⁿ + cᵀ x^bl + vₙ`, `x^bl_k = A x^bl + b xⁿ + v_bl`, `y_k = hᵀ x^bl_k + d xⁿ_k + η`.
#[derive(Clone)]
struct Coupled {
    a: f64,
    c: [f64; 2],
    big_a: Matrix2<f64>,
    b: [f64; 2],
    h: [f64; 2],
    d: f64,
    qn_sd: Vec<f64>,
    qbl_sd: [f64; 2],
    q_bl: SymEntries,
    r: f64,
    xn0_sd: f64,
    m0: Vector2<f64>,
    p0: Matrix2<f64>,
    empty: SparseHessians,
    stages: Vec<Vec<usize>>,
}

impl Coupled {
    fn new() -> Self {
        let qbl_sd = [0.3, 0.2];
        Self {
            a: 0.7,
            c: [0.5, -0.3],
            big_a: Matrix2::new(0.9, 0.2, 0.0, 0.8),
            b: [0.3, 0.0],
            h: [1.0, 0.5],
            d: 0.4,
            qn_sd: vec![0.5],
            qbl_sd,
            q_bl: SymEntries::diagonal(&[qbl_sd[0] * qbl_sd[0], qbl_sd[1] * qbl_sd[1]]),
            r: 0.25,
            xn0_sd: 1.0,
            m0: Vector2::new(0.5, 0.0),
            p0: Matrix2::identity(),
            empty: SparseHessians::new(),
            stages: vec![vec![0]],
        }
    }

    fn joint(&self) -> LinearGaussian<3, 1> {
        let mut g = Matrix3::zeros();
        g[(0, 0)] = self.a;
        g[(0, 1)] = self.c[0];
        g[(0, 2)] = self.c[1];
        g[(1, 0)] = self.b[0];
        g[(2, 0)] = self.b[1];
        g.fixed_view_mut::<2, 2>(1, 1).copy_from(&self.big_a);
        let mut p0 = Matrix3::zeros();
        p0[(0, 0)] = self.xn0_sd * self.xn0_sd;
        p0.fixed_view_mut::<2, 2>(1, 1).copy_from(&self.p0);
        LinearGaussian {
            g_mat: g,
            g_off: Vector3::zeros(),
            h_mat: SMatrix::<f64, 1, 3>::new(self.d, self.h[0], self.h[1]),
            h_off: Vector1::zeros(),
            q: Matrix3::from_diagonal(&Vector3::new(
                self.qn_sd[0] * self.qn_sd[0],
                self.qbl_sd[0] * self.qbl_sd[0],
                self.qbl_sd[1] * self.qbl_sd[1],
            )),
            r: Matrix1::new(self.r),
            m0: Vector3::new(0.0, self.m0[0], self.m0[1]),
            p0,
        }
    }
}

impl Partition for Coupled {
    fn sample_initial(&self, rng: &mut StreamRng, xn: &mut [f64]) {
        xn[0] = self.xn0_sd * normal(rng);
    }

    fn measurement_cov(&self) -> Vec<f64> {
        vec![self.r]
    }

    fn layout(&self) -> Layout {
        Layout {
            param_names: vec![],
            params: vec![],
            state_names: names(3, "x"),
            states: vec![Slot::Sampled(0), Slot::Marginal(0), Slot::Marginal(1)],
        }
    }
}

impl ConditionallyQuadratic for Coupled {
    fn dims(&self) -> QuadraticDims {
        QuadraticDims {
            nn: 1,
            nbl: 2,
            ny: 1,
        }
    }
    fn sampled_stages(&self) -> &[Vec<usize>] {
        &self.stages
    }
    fn sampled_dynamics<T: Real>(
        &self,
        at: SampledAt<'_, T>,
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        let (xn_prev, m) = (at.prev, at.m);
        value[0] =
            T::splat(self.a) * xn_prev[0] + T::splat(self.c[0]) * m[0] + T::splat(self.c[1]) * m[1];
        jac.add(0, 0, T::splat(self.c[0]));
        jac.add(0, 1, T::splat(self.c[1]));
    }
    fn sampled_hessians(&self, _stage: usize) -> &SparseHessians {
        &self.empty
    }
    fn sampled_noise_sd(&self, _stage: usize) -> &[f64] {
        &self.qn_sd
    }
    fn marginal_dynamics<T: Real>(
        &self,
        _k: usize,
        xn_prev: &[T],
        _xn_new: &[T],
        m: &[T],
        value: &mut [T],
        d: &mut Sparse<T>,
    ) {
        for r in 0..2 {
            let mut v = T::splat(self.b[r]) * xn_prev[0];
            for c in 0..2 {
                v += T::splat(self.big_a[(r, c)]) * m[c];
                let dv = self.big_a[(r, c)] - if r == c { 1.0 } else { 0.0 };
                d.add(r, c, T::splat(dv));
            }
            value[r] = v;
        }
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn marginal_noise(&self) -> &SymEntries {
        &self.q_bl
    }
    fn observation<T: Real>(
        &self,
        _k: usize,
        xn: &[T],
        m: &[T],
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        value[0] =
            T::splat(self.d) * xn[0] + T::splat(self.h[0]) * m[0] + T::splat(self.h[1]) * m[1];
        jac.add(0, 0, T::splat(self.h[0]));
        jac.add(0, 1, T::splat(self.h[1]));
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
}

impl Marginalised for Coupled {
    fn marginal_prior(&self, _rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        mean.copy_from_slice(self.m0.as_slice());
        cov.copy_from_slice(self.p0.as_slice());
    }
}

#[test]
fn coupled_linear_model_gives_unbiased_likelihood() {
    let model = Coupled::new();
    let lg = model.joint();
    let ys = simulate(&lg, 20, 4);
    let exact = kalman_filter(&lg, &rows::<1>(&ys)).unwrap().loglik;
    let mut f = MpfEkf2::new(model);
    let ls: Vec<f64> = (0..300)
        .map(|r| {
            let s = run(
                &mut f,
                &config(100),
                &ys,
                1,
                &mut stream(77, r, "mpf"),
                &mut NoObserver,
            );
            assert!(s.failure.is_none());
            s.loglik
        })
        .collect();
    let (mean, se) = ratio_mean_and_se(&ls, exact);
    eprintln!("mpf-ekf2: exact ℓ = {exact:.4}, mean exp(ℓ̂−ℓ) = {mean:.4} ± {se:.4}");
    assert!(se < 0.05, "relative variance too large: se = {se}");
    assert!((mean - 1.0).abs() < 4.5 * se, "mean ratio {mean} ± {se}");
}

#[test]
fn mpf_lanes_equal_one_particle_at_a_time() {
    for model in [Coupled::new()] {
        let ys = simulate(&model.joint(), 25, 8);
        for np in [3, 8, 13] {
            let mut out = Vec::new();
            for lanes in [false, true] {
                let mut f = MpfEkf2::with_lanes(model.clone(), lanes);
                let mut t = Trace::default();
                let s = run(
                    &mut f,
                    &config(np),
                    &ys,
                    1,
                    &mut stream(1, np as u64, "eq"),
                    &mut t,
                );
                let bits: Vec<Vec<u64>> =
                    t.0.iter()
                        .map(|r| r.iter().map(|v| v.to_bits()).collect())
                        .collect();
                out.push((s.loglik.to_bits(), bits, f.health()));
            }
            assert_eq!(out[0], out[1], "np {np}");
        }
    }
}

/// Model C: bilinear sampled dynamics (non-empty Hessians), 2 dynamic sampled entries and 1
/// static, 3 marginalised: `ψ₀ = xⁿ₀ + 0.1 x₀ + x₀ x₁`, `ψ₁ = 0.5 xⁿ₁ + x₁ x₂ − 0.3 x₂² + xⁿ₂ x₀`.
struct Bilinear {
    sampled_hess: SparseHessians,
    empty: SparseHessians,
    xn0: [f64; 3],
    m0: [f64; 3],
    p0: Matrix3<f64>,
    qn_sd: Vec<f64>,
    q_bl: SymEntries,
    stages: Vec<Vec<usize>>,
}

impl Bilinear {
    fn new() -> Self {
        let mut h = SparseHessians::new();
        h.push(0, 0, 1, 1.0);
        h.push(1, 1, 2, 1.0);
        h.push(1, 2, 2, -0.6);
        Self {
            sampled_hess: h,
            empty: SparseHessians::new(),
            xn0: [0.4, -1.0, 2.0],
            m0: [0.7, -1.3, 0.5],
            p0: Matrix3::new(0.5, 0.2, -0.1, 0.2, 0.8, 0.3, -0.1, 0.3, 0.6),
            qn_sd: vec![0.1, 0.2],
            q_bl: SymEntries::diagonal(&[1e-4, 1e-4, 0.0]),
            stages: vec![vec![0, 1]],
        }
    }
}

impl Partition for Bilinear {
    fn sample_initial(&self, _rng: &mut StreamRng, xn: &mut [f64]) {
        xn.copy_from_slice(&self.xn0);
    }

    fn measurement_cov(&self) -> Vec<f64> {
        vec![0.1]
    }

    fn layout(&self) -> Layout {
        Layout {
            param_names: vec!["s".into()],
            params: vec![Slot::Sampled(2)],
            state_names: names(2, "u"),
            states: vec![Slot::Sampled(0), Slot::Sampled(1)],
        }
    }
}

impl ConditionallyQuadratic for Bilinear {
    fn dims(&self) -> QuadraticDims {
        QuadraticDims {
            nn: 3,
            nbl: 3,
            ny: 1,
        }
    }
    fn sampled_stages(&self) -> &[Vec<usize>] {
        &self.stages
    }
    fn sampled_dynamics<T: Real>(
        &self,
        at: SampledAt<'_, T>,
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        let (xn, m) = (at.prev, at.m);
        let c = T::splat;
        value[0] = xn[0] + c(0.1) * m[0] + m[0] * m[1];
        value[1] = c(0.5) * xn[1] + m[1] * m[2] - c(0.3) * m[2] * m[2] + xn[2] * m[0];
        jac.add(0, 0, c(0.1) + m[1]);
        jac.add(0, 1, m[0]);
        jac.add(1, 0, xn[2]);
        jac.add(1, 1, m[2]);
        jac.add(1, 2, m[1] - c(0.6) * m[2]);
    }
    fn sampled_hessians(&self, _stage: usize) -> &SparseHessians {
        &self.sampled_hess
    }
    fn sampled_noise_sd(&self, _stage: usize) -> &[f64] {
        &self.qn_sd
    }
    fn marginal_dynamics<T: Real>(
        &self,
        _k: usize,
        _xn_prev: &[T],
        _xn_new: &[T],
        m: &[T],
        value: &mut [T],
        _d: &mut Sparse<T>,
    ) {
        value.copy_from_slice(m);
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn marginal_noise(&self) -> &SymEntries {
        &self.q_bl
    }
    fn observation<T: Real>(
        &self,
        _k: usize,
        xn: &[T],
        m: &[T],
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        value[0] = m[0] + xn[0];
        jac.add(0, 0, T::splat(1.0));
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
}

impl Marginalised for Bilinear {
    fn marginal_prior(&self, _rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        mean.copy_from_slice(&self.m0);
        cov.copy_from_slice(self.p0.as_slice());
    }
}

/// One measurement's quadratic map: a constant, a linear part and sparse Hessian entries.
type QuadraticTerm = (f64, Vector3<f64>, Vec<(usize, usize, f64)>);

/// Exact mean and covariance of `f_i(x) = c_i + l_iᵀx + Σ q x_a x_b`, `x ~ N(μ, P)`, plus
/// diagonal noise, by Isserlis' theorem.
fn exact_quadratic_moments(
    terms: &[QuadraticTerm; 2],
    mu: &Vector3<f64>,
    p: &Matrix3<f64>,
    noise_var: &[f64],
) -> (Vector2<f64>, Matrix2<f64>) {
    let mut mean = Vector2::zeros();
    for (i, (c, l, q)) in terms.iter().enumerate() {
        mean[i] = c
            + l.dot(mu)
            + q.iter()
                .map(|&(a, b, v)| v * (mu[a] * mu[b] + p[(a, b)]))
                .sum::<f64>();
    }
    let lin_quad = |l: &Vector3<f64>, (a, b): (usize, usize)| -> f64 {
        (0..3)
            .map(|c| l[c] * (mu[a] * p[(b, c)] + mu[b] * p[(a, c)]))
            .sum()
    };
    let quad_quad = |(a, b): (usize, usize), (c, d): (usize, usize)| -> f64 {
        mu[a] * mu[c] * p[(b, d)]
            + mu[a] * mu[d] * p[(b, c)]
            + mu[b] * mu[c] * p[(a, d)]
            + mu[b] * mu[d] * p[(a, c)]
            + p[(a, c)] * p[(b, d)]
            + p[(a, d)] * p[(b, c)]
    };
    let mut cov = Matrix2::zeros();
    for i in 0..2 {
        for j in 0..2 {
            let (_, li, qi) = &terms[i];
            let (_, lj, qj) = &terms[j];
            let mut s = (li.transpose() * p * lj)[0];
            for &(a, b, v) in qj {
                s += v * lin_quad(li, (a, b));
            }
            for &(a, b, v) in qi {
                s += v * lin_quad(lj, (a, b));
            }
            for &(a, b, v) in qi {
                for &(c, d, w) in qj {
                    s += v * w * quad_quad((a, b), (c, d));
                }
            }
            cov[(i, j)] = s;
        }
        cov[(i, i)] += noise_var[i];
    }
    (mean, cov)
}

/// Keeps the sampled blocks of the last step.
#[derive(Default)]
struct LastSampled(Vec<Vec<f64>>);
impl Observer for LastSampled {
    fn on_finish(&mut self, last: &core_filters::smc::runner::WeightedParticles<'_>) {
        self.0 = (0..last.particles.len())
            .map(|i| last.particles.sampled(i).to_vec())
            .collect();
    }
}

#[test]
fn bilinear_proposal_has_the_exact_moments() {
    let model = Bilinear::new();
    let (xn0, m0, p0) = (model.xn0, Vector3::from(model.m0), model.p0);
    let terms = [
        (xn0[0], Vector3::new(0.1, 0.0, 0.0), vec![(0, 1, 1.0)]),
        (
            0.5 * xn0[1],
            Vector3::new(xn0[2], 0.0, 0.0),
            vec![(1, 2, 1.0), (2, 2, -0.3)],
        ),
    ];
    let (exact_mean, exact_cov) = exact_quadratic_moments(&terms, &m0, &p0, &[0.01, 0.04]);
    let f = MpfEkf2::new(model);
    let (mean, cov) = f
        .particle_step()
        .proposal_moments(0, 1, &xn0, m0.as_slice(), p0.as_slice());
    for i in 0..2 {
        assert!((mean[i] - exact_mean[i]).abs() < 1e-13, "mean {i}");
        for j in 0..2 {
            assert!(
                (cov[i + 2 * j] - exact_cov[(i, j)]).abs() < 1e-13,
                "cov {i}{j}"
            );
        }
    }
    // The particles drawn at step 1 (all from the same (xⁿ₀, m₀, P₀)) are i.i.d. draws of the
    // proposal: their sample moments within Monte-Carlo standard errors.
    let np = 20_000;
    let mut f = MpfEkf2::new(Bilinear::new());
    let mut last = LastSampled::default();
    let s = run(
        &mut f,
        &config(np),
        &[1.0],
        1,
        &mut stream(6, 0, "mpf"),
        &mut last,
    );
    assert!(s.failure.is_none());
    let n = np as f64;
    let xs = &last.0;
    let smean: Vec<f64> = (0..2)
        .map(|i| xs.iter().map(|x| x[i]).sum::<f64>() / n)
        .collect();
    for i in 0..2 {
        let se_mean = (exact_cov[(i, i)] / n).sqrt();
        assert!((smean[i] - exact_mean[i]).abs() < 4.5 * se_mean, "mean {i}");
        for j in 0..2 {
            let c = xs
                .iter()
                .map(|x| (x[i] - smean[i]) * (x[j] - smean[j]))
                .sum::<f64>()
                / (n - 1.0);
            let se =
                ((exact_cov[(i, i)] * exact_cov[(j, j)] + exact_cov[(i, j)].powi(2)) / n).sqrt();
            assert!((c - exact_cov[(i, j)]).abs() < 4.5 * se, "cov {i}{j}");
        }
    }
    assert!(xs.iter().all(|x| x[2] == xn0[2]));
}

#[test]
fn mpf_lanes_equal_one_particle_at_a_time_with_hessians() {
    let ys: Vec<f64> = (0..20).map(|k| (k as f64 * 0.3).sin()).collect();
    for np in [5, 12] {
        let mut out = Vec::new();
        for lanes in [false, true] {
            let mut f = MpfEkf2::with_lanes(Bilinear::new(), lanes);
            let mut t = Trace::default();
            let s = run(
                &mut f,
                &config(np),
                &ys,
                1,
                &mut stream(3, np as u64, "eq"),
                &mut t,
            );
            let bits: Vec<Vec<u64>> =
                t.0.iter()
                    .map(|r| r.iter().map(|v| v.to_bits()).collect())
                    .collect();
            out.push((s.loglik.to_bits(), bits, s.health, s.steps_completed));
        }
        assert_eq!(out[0], out[1], "np {np}");
    }
}

/// One run's output, to the bit: the log-likelihood, every step's posterior row, the repairs.
fn run_bits<M>(f: &mut MpfEkf2<M>, ys: &[f64], np: usize, seed: u64) -> (u64, Vec<Vec<u64>>, u64)
where
    M: core_filters::smc::model::ConditionallyQuadratic,
{
    let mut t = Trace::default();
    let s = run(
        f,
        &config(np),
        ys,
        1,
        &mut stream(seed, np as u64, "blocks"),
        &mut t,
    );
    let bits =
        t.0.iter()
            .map(|r| r.iter().map(|v| v.to_bits()).collect())
            .collect();
    (s.loglik.to_bits(), bits, s.health.repairs())
}

/// Blocks of particles advanced on 1, 2 and 7 threads give the particles of one thread to the
/// bit, with lanes and without, for particle counts that leave a short last block.
#[test]
fn particle_blocks_on_any_number_of_threads_equal_one_thread() {
    let coupled = Coupled::new();
    let ys_coupled = simulate(&coupled.joint(), 25, 8);
    let ys_bilinear: Vec<f64> = (0..20).map(|k| (k as f64 * 0.3).sin()).collect();
    for np in [3, 13, 37] {
        for lanes in [false, true] {
            let one = (
                run_bits(
                    &mut MpfEkf2::with_lanes(coupled.clone(), lanes).with_blocks(false),
                    &ys_coupled,
                    np,
                    1,
                ),
                run_bits(
                    &mut MpfEkf2::with_lanes(Bilinear::new(), lanes).with_blocks(false),
                    &ys_bilinear,
                    np,
                    3,
                ),
            );
            for threads in [1, 2, 7] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let blocks = pool.install(|| {
                    let mut f = MpfEkf2::with_lanes(coupled.clone(), lanes).with_blocks(true);
                    assert!(f.uses_blocks());
                    let a = run_bits(&mut f, &ys_coupled, np, 1);
                    let mut g = MpfEkf2::with_lanes(Bilinear::new(), lanes).with_blocks(true);
                    (a, run_bits(&mut g, &ys_bilinear, np, 3))
                });
                assert_eq!(one, blocks, "np {np}, lanes {lanes}, {threads} threads");
            }
        }
    }
}
