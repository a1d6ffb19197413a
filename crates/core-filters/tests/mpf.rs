//! MPF-EKF2 (SPEC §5.4) against exact references:
//! - a model whose marginalised block is linear and unseen by the sampled block: the filter is
//!   the Kalman filter (moments and log-likelihood to round-off);
//! - a fully linear-Gaussian model whose sampled block observes the marginalised one: the filter
//!   is an exact Rao–Blackwellised PF, so its likelihood estimate is unbiased;
//! - a bilinear model: the proposal moments are the exact moments of the bilinear map;
//! - determinism, typed failure on a NaN measurement, and the sparse kernel against the dense
//!   one on the paper-sized chain of SPEC §6.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector1, Vector2, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use core_filters::kalman::{kalman_filter, LinearGaussian};
use core_filters::model::{ConditionallyQuadratic, Layout, Slot, SparseHessians};
use core_filters::particle::mpf::{MpfEkf2, MpfKernel};
use core_filters::particle::{run, Observer, ParticleConfig, ParticleFilter, Posterior, StepInfo};
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::stream;
use core_filters::FilterError;

#[allow(dead_code)]
#[path = "../benches/mpf.rs"]
mod bench;

fn gauss<G: Rng + ?Sized>(rng: &mut G) -> f64 {
    StandardNormal.sample(rng)
}

fn config(particles: usize) -> ParticleConfig {
    ParticleConfig {
        particles,
        resampling: ResamplePolicy::default(),
    }
}

fn names(n: usize, prefix: &str) -> Vec<String> {
    (0..n).map(|i| format!("{prefix}{i}")).collect()
}

// ---------------------------------------------------------------------------------------------
// Model A: x^bl linear-Gaussian and invisible to xⁿ (Jₙ = 0, no Hessians, y independent of xⁿ).
// xⁿ = [dynamic, static], NN = 2, ND = 1, NBL = 3, NY = 2.

struct Decoupled {
    g: Matrix3<f64>,
    g_off: Vector3<f64>,
    h: SMatrix<f64, 2, 3>,
    h_off: Vector2<f64>,
    q_bl_sd: Vector3<f64>,
    r: Matrix2<f64>,
    m0: Vector3<f64>,
    p0: Matrix3<f64>,
    empty: SparseHessians,
    /// Makes `ψₙ` NaN for particles whose static entry exceeds 0.5 (failure-policy test).
    poison: bool,
}

impl Decoupled {
    fn new() -> Self {
        Self {
            g: Matrix3::new(0.9, 0.1, 0.0, 0.0, 0.95, 0.2, 0.0, 0.0, 1.0),
            g_off: Vector3::new(0.1, 0.0, 0.0),
            h: SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.5, 0.0, 1.0, -1.0),
            h_off: Vector2::new(0.2, -0.1),
            q_bl_sd: Vector3::new(0.1, 0.05, 0.0),
            r: Matrix2::new(0.2, 0.05, 0.05, 0.3),
            m0: Vector3::new(0.5, -0.2, 1.0),
            p0: Matrix3::new(1.0, 0.3, 0.0, 0.3, 0.5, 0.1, 0.0, 0.1, 0.8),
            empty: SparseHessians::new(),
            poison: false,
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

impl ConditionallyQuadratic<2, 1, 3, 2> for Decoupled {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> Vector2<f64> {
        Vector2::new(gauss(rng), rng.random())
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(&self, _rng: &mut G) -> (Vector3<f64>, Matrix3<f64>) {
        (self.m0, self.p0)
    }
    fn sampled_dynamics(
        &self,
        _k: usize,
        xn: &Vector2<f64>,
        _m: &Vector3<f64>,
    ) -> (Vector1<f64>, SMatrix<f64, 1, 3>) {
        if self.poison && xn[1] > 0.5 {
            return (Vector1::new(f64::NAN), SMatrix::zeros());
        }
        (Vector1::new(0.8 * xn[0] + xn[1].sin()), SMatrix::zeros())
    }
    fn marginal_dynamics(
        &self,
        _k: usize,
        _xn: &Vector2<f64>,
        m: &Vector3<f64>,
    ) -> (Vector3<f64>, Matrix3<f64>) {
        (self.g * m + self.g_off, self.g)
    }
    fn observation(
        &self,
        _k: usize,
        _xn: &Vector2<f64>,
        m: &Vector3<f64>,
    ) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
        (self.h * m + self.h_off, self.h)
    }
    fn sampled_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn sampled_noise_sd(&self) -> Vector1<f64> {
        Vector1::new(0.3)
    }
    fn marginal_noise_sd(&self) -> Vector3<f64> {
        self.q_bl_sd
    }
    fn measurement_cov(&self) -> Matrix2<f64> {
        self.r
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

/// Simulates `steps` measurements of a linear-Gaussian model.
fn simulate<const N: usize, const NY: usize>(
    lg: &LinearGaussian<N, NY>,
    steps: usize,
    seed: u64,
) -> Vec<SVector<f64, NY>> {
    let mut rng = stream(seed, 0, "test-data");
    let chol_p0 = lg.p0.cholesky().expect("p0 SPD").l();
    let mut z = lg.m0 + chol_p0 * SVector::<f64, N>::from_fn(|_, _| gauss(&mut rng));
    let chol_r = lg.r.cholesky().expect("R SPD").l();
    (0..steps)
        .map(|_| {
            let v = SVector::<f64, N>::from_fn(|i, _| lg.q[(i, i)].sqrt() * gauss(&mut rng));
            z = lg.g_mat * z + lg.g_off + v;
            lg.h_mat * z + lg.h_off + chol_r * SVector::<f64, NY>::from_fn(|_, _| gauss(&mut rng))
        })
        .collect()
}

/// Gaussian-mixture mean and covariance `Σ w m`, `Σ w (P + m mᵀ) − mean meanᵀ` (SPEC §7).
fn mixture<const N: usize>(
    w: &[f64],
    mu: &[SVector<f64, N>],
    cov: &[SMatrix<f64, N, N>],
) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
    let mut mean = SVector::<f64, N>::zeros();
    let mut second = SMatrix::<f64, N, N>::zeros();
    for ((wi, m), p) in w.iter().zip(mu).zip(cov) {
        mean += *wi * m;
        second += *wi * (p + m * m.transpose());
    }
    (mean, second - mean * mean.transpose())
}

#[test]
fn decoupled_linear_block_reproduces_the_kalman_filter() {
    let model = Decoupled::new();
    let lg = model.linear_gaussian();
    let ys = simulate(&lg, 60, 1);
    let kf = kalman_filter(&lg, &ys).expect("KF runs");
    for kernel in [MpfKernel::Sparse, MpfKernel::Dense] {
        let mut f = MpfEkf2::new(Decoupled::new(), config(25)).with_kernel(kernel);
        let mut rng = stream(2, 0, "filter/mpf-ekf2");
        f.initialise(&mut rng);
        let mut loglik = 0.0;
        let mut post = Posterior::for_layout(f.layout());
        for (idx, y) in ys.iter().enumerate() {
            let k = idx + 1;
            let info = f.step(k, y, &mut rng).expect("step");
            loglik += info.loglik_increment;
            assert!(
                (info.loglik_increment - kf.loglik_increments[idx]).abs() < 1e-9,
                "{kernel:?} k={k}: {} vs {}",
                info.loglik_increment,
                kf.loglik_increments[idx]
            );
            let (mean, cov) = mixture(f.weights(), f.marginal_means(), f.marginal_covs());
            assert!(
                (mean - kf.means[idx]).abs().max() < 1e-9,
                "{kernel:?} k={k} mean"
            );
            assert!(
                (cov - kf.covs[idx]).abs().max() < 1e-9,
                "{kernel:?} k={k} cov"
            );
            // The posterior summary reports the same mixture moments by slot.
            f.posterior(&mut post);
            assert!((post.state_mean[1] - kf.means[idx][1]).abs() < 1e-9);
            assert!((post.param_sd[0] - kf.covs[idx][(2, 2)].sqrt()).abs() < 1e-9);
        }
        assert!((loglik - kf.loglik).abs() < 1e-9 * kf.loglik.abs().max(1.0));
        assert_eq!(f.health().resamples, ys.len() as u64 - 1);
        assert_eq!(f.health().repairs(), 0);
    }
}

// ---------------------------------------------------------------------------------------------
// Model B: fully linear-Gaussian, xⁿ observes x^bl (Jₙ ≠ 0), no Hessians. NN = ND = 1, NBL = 2.
//   xⁿ_k = a xⁿ + cᵀ x^bl + vₙ,   x^bl_k = A x^bl + b xⁿ + v_bl,   y_k = Hᵀ x^bl_k + d xⁿ_k + η.

struct Coupled {
    a: f64,
    c: SMatrix<f64, 1, 2>,
    big_a: Matrix2<f64>,
    b: Vector2<f64>,
    h: SMatrix<f64, 1, 2>,
    d: f64,
    qn_sd: f64,
    qbl_sd: Vector2<f64>,
    r: f64,
    xn0_sd: f64,
    m0: Vector2<f64>,
    p0: Matrix2<f64>,
    empty: SparseHessians,
}

impl Coupled {
    fn new() -> Self {
        Self {
            a: 0.7,
            c: SMatrix::<f64, 1, 2>::new(0.5, -0.3),
            big_a: Matrix2::new(0.9, 0.2, 0.0, 0.8),
            b: Vector2::new(0.3, 0.0),
            h: SMatrix::<f64, 1, 2>::new(1.0, 0.5),
            d: 0.4,
            qn_sd: 0.5,
            qbl_sd: Vector2::new(0.3, 0.2),
            r: 0.25,
            xn0_sd: 1.0,
            m0: Vector2::new(0.5, 0.0),
            p0: Matrix2::identity(),
            empty: SparseHessians::new(),
        }
    }

    /// The joint model on `z = [xⁿ; x^bl]`.
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
                self.qn_sd * self.qn_sd,
                self.qbl_sd[0] * self.qbl_sd[0],
                self.qbl_sd[1] * self.qbl_sd[1],
            )),
            r: nalgebra::Matrix1::new(self.r),
            m0: Vector3::new(0.0, self.m0[0], self.m0[1]),
            p0,
        }
    }
}

impl ConditionallyQuadratic<1, 1, 2, 1> for Coupled {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> Vector1<f64> {
        Vector1::new(self.xn0_sd * gauss(rng))
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(&self, _rng: &mut G) -> (Vector2<f64>, Matrix2<f64>) {
        (self.m0, self.p0)
    }
    fn sampled_dynamics(
        &self,
        _k: usize,
        xn: &Vector1<f64>,
        m: &Vector2<f64>,
    ) -> (Vector1<f64>, SMatrix<f64, 1, 2>) {
        (Vector1::new(self.a * xn[0]) + self.c * m, self.c)
    }
    fn marginal_dynamics(
        &self,
        _k: usize,
        xn: &Vector1<f64>,
        m: &Vector2<f64>,
    ) -> (Vector2<f64>, Matrix2<f64>) {
        (self.big_a * m + self.b * xn[0], self.big_a)
    }
    fn observation(
        &self,
        _k: usize,
        xn: &Vector1<f64>,
        m: &Vector2<f64>,
    ) -> (Vector1<f64>, SMatrix<f64, 1, 2>) {
        (self.h * m + Vector1::new(self.d * xn[0]), self.h)
    }
    fn sampled_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn sampled_noise_sd(&self) -> Vector1<f64> {
        Vector1::new(self.qn_sd)
    }
    fn marginal_noise_sd(&self) -> Vector2<f64> {
        self.qbl_sd
    }
    fn measurement_cov(&self) -> nalgebra::Matrix1<f64> {
        nalgebra::Matrix1::new(self.r)
    }
    fn layout(&self) -> Layout {
        Layout {
            param_names: vec![],
            params: vec![],
            state_names: names(3, "z"),
            states: vec![Slot::Sampled(0), Slot::Marginal(0), Slot::Marginal(1)],
        }
    }
}

/// Unbiasedness of the Rao–Blackwellised likelihood estimate: `E[exp(ℓ̂ − ℓ)] = 1`. The test
/// statistic is the mean of `Z_r = exp(ℓ̂_r − ℓ)` over independent runs, compared with 1 in units
/// of its Monte-Carlo standard error estimated from the same runs. With a proposal or update
/// that ignored what xⁿ says about x^bl the estimate would be biased (Z ≪ 1 on average).
#[test]
fn coupled_linear_model_gives_unbiased_likelihood() {
    let model = Coupled::new();
    let lg = model.joint();
    let ys = simulate(&lg, 25, 3);
    let exact = kalman_filter(&lg, &ys).expect("KF runs").loglik;
    let runs = 1000;
    let mut f = MpfEkf2::new(Coupled::new(), config(40));
    let z: Vec<f64> = (0..runs)
        .map(|r| {
            let mut rng = stream(4, r, "filter/mpf-ekf2");
            let s = run(
                &mut f,
                &ys,
                &mut rng,
                &mut core_filters::particle::NoObserver,
            );
            assert!(s.failure.is_none());
            (s.loglik - exact).exp()
        })
        .collect();
    let n = runs as f64;
    let mean = z.iter().sum::<f64>() / n;
    let var = z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let se = (var / n).sqrt();
    // The test has power only if the standard error is small.
    assert!(
        se < 0.05,
        "MC standard error {se} too large for a meaningful test"
    );
    assert!(
        (mean - 1.0).abs() < 4.5 * se,
        "mean exp(ℓ̂ − ℓ) = {mean}, s.e. {se}"
    );
}

// ---------------------------------------------------------------------------------------------
// Model C: bilinear sampled dynamics (non-empty Hessians). NN = 3 (2 dynamic, 1 static),
// NBL = 3, NY = 1.
//   ψ₀ = xⁿ₀ + 0.1 x₀ + x₀ x₁,   ψ₁ = 0.5 xⁿ₁ + x₁ x₂ − 0.3 x₂² + xⁿ₂ x₀.

/// One output as `(constant, linear coefficients, bilinear terms (a, b, q))`.
type QuadraticTerms = (f64, Vector3<f64>, Vec<(usize, usize, f64)>);

struct Bilinear {
    sampled_hess: SparseHessians,
    empty: SparseHessians,
    xn0: Vector3<f64>,
    m0: Vector3<f64>,
    p0: Matrix3<f64>,
    qn_sd: Vector2<f64>,
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
            xn0: Vector3::new(0.4, -1.0, 2.0),
            m0: Vector3::new(0.7, -1.3, 0.5),
            p0: Matrix3::new(0.5, 0.2, -0.1, 0.2, 0.8, 0.3, -0.1, 0.3, 0.6),
            qn_sd: Vector2::new(0.1, 0.2),
        }
    }

    /// Each output as `const + lᵀx + Σ q x_a x_b` for the exact-moment reference.
    fn terms(&self, xn: &Vector3<f64>) -> [QuadraticTerms; 2] {
        [
            (xn[0], Vector3::new(0.1, 0.0, 0.0), vec![(0, 1, 1.0)]),
            (
                0.5 * xn[1],
                Vector3::new(xn[2], 0.0, 0.0),
                vec![(1, 2, 1.0), (2, 2, -0.3)],
            ),
        ]
    }
}

impl ConditionallyQuadratic<3, 2, 3, 1> for Bilinear {
    fn sample_initial<G: Rng + ?Sized>(&self, _rng: &mut G) -> Vector3<f64> {
        self.xn0
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(&self, _rng: &mut G) -> (Vector3<f64>, Matrix3<f64>) {
        (self.m0, self.p0)
    }
    fn sampled_dynamics(
        &self,
        _k: usize,
        xn: &Vector3<f64>,
        m: &Vector3<f64>,
    ) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
        let v = Vector2::new(
            xn[0] + 0.1 * m[0] + m[0] * m[1],
            0.5 * xn[1] + m[1] * m[2] - 0.3 * m[2] * m[2] + xn[2] * m[0],
        );
        let j = SMatrix::<f64, 2, 3>::new(0.1 + m[1], m[0], 0.0, xn[2], m[2], m[1] - 0.6 * m[2]);
        (v, j)
    }
    fn marginal_dynamics(
        &self,
        _k: usize,
        _xn: &Vector3<f64>,
        m: &Vector3<f64>,
    ) -> (Vector3<f64>, Matrix3<f64>) {
        (*m, Matrix3::identity())
    }
    fn observation(
        &self,
        _k: usize,
        xn: &Vector3<f64>,
        m: &Vector3<f64>,
    ) -> (Vector1<f64>, SMatrix<f64, 1, 3>) {
        (
            Vector1::new(m[0] + xn[0]),
            SMatrix::<f64, 1, 3>::new(1.0, 0.0, 0.0),
        )
    }
    fn sampled_hessians(&self) -> &SparseHessians {
        &self.sampled_hess
    }
    fn marginal_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn observation_hessians(&self) -> &SparseHessians {
        &self.empty
    }
    fn sampled_noise_sd(&self) -> Vector2<f64> {
        self.qn_sd
    }
    fn marginal_noise_sd(&self) -> Vector3<f64> {
        Vector3::new(0.01, 0.01, 0.0)
    }
    fn measurement_cov(&self) -> nalgebra::Matrix1<f64> {
        nalgebra::Matrix1::new(0.1)
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

/// Exact mean and covariance of `f_i(x) = c_i + l_iᵀx + Σ q x_a x_b`, `x ~ N(μ, P)`, plus
/// diagonal noise, by Isserlis' theorem:
/// `E[x_a x_b] = μ_a μ_b + P_ab`, `Cov(x_a x_b, x_c) = μ_a P_bc + μ_b P_ac`,
/// `Cov(x_a x_b, x_c x_d) = μ_a μ_c P_bd + μ_a μ_d P_bc + μ_b μ_c P_ad + μ_b μ_d P_ac
///  + P_ac P_bd + P_ad P_bc`.
fn exact_quadratic_moments(
    terms: &[QuadraticTerms; 2],
    mu: &Vector3<f64>,
    p: &Matrix3<f64>,
    noise_var: &Vector2<f64>,
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

#[test]
fn bilinear_proposal_has_the_exact_moments() {
    let model = Bilinear::new();
    let (xn0, m0, p0) = (model.xn0, model.m0, model.p0);
    let (exact_mean, exact_cov) =
        exact_quadratic_moments(&model.terms(&xn0), &m0, &p0, &model.qn_sd.map(|s| s * s));
    // The quadratic terms matter: without them the mean would be off by P01 = 0.2 etc.
    let np = 20_000;
    let mut f = MpfEkf2::new(model, config(np));
    let (mean, cov) = f.proposal_moments(1, &xn0, &m0, &p0);
    assert!(
        (mean - exact_mean).abs().max() < 1e-13,
        "{mean} vs {exact_mean}"
    );
    assert!(
        (cov - exact_cov).abs().max() < 1e-13,
        "{cov} vs {exact_cov}"
    );

    // The particles drawn at step 1 (all from the same (xⁿ₀, m₀, P₀)) are i.i.d. draws of the
    // proposal: check their sample moments with tolerances from the Monte-Carlo standard error.
    let mut rng = stream(6, 0, "filter/mpf-ekf2");
    f.initialise(&mut rng);
    f.step(1, &Vector1::new(1.0), &mut rng).expect("step");
    let xs = f.sampled();
    let n = np as f64;
    let mut smean = Vector2::zeros();
    for x in xs {
        smean += Vector2::new(x[0], x[1]);
    }
    smean /= n;
    let mut scov = Matrix2::zeros();
    for x in xs {
        let d = Vector2::new(x[0], x[1]) - smean;
        scov += d * d.transpose();
    }
    scov /= n - 1.0;
    for i in 0..2 {
        let se_mean = (exact_cov[(i, i)] / n).sqrt();
        assert!((smean[i] - exact_mean[i]).abs() < 4.5 * se_mean, "mean {i}");
        for j in 0..2 {
            // Var of a Gaussian sample covariance: (C_ii C_jj + C_ij²) / n.
            let se =
                ((exact_cov[(i, i)] * exact_cov[(j, j)] + exact_cov[(i, j)].powi(2)) / n).sqrt();
            assert!(
                (scov[(i, j)] - exact_cov[(i, j)]).abs() < 4.5 * se,
                "cov {i}{j}"
            );
        }
    }
    // The static entry is copied.
    assert!(xs.iter().all(|x| x[2] == xn0[2]));
}

// ---------------------------------------------------------------------------------------------

#[derive(Default)]
struct Trace {
    infos: Vec<StepInfo>,
    posts: Vec<Posterior>,
}

impl Observer for Trace {
    fn on_step(&mut self, info: &StepInfo, posterior: &Posterior) {
        self.infos.push(*info);
        self.posts.push(posterior.clone());
    }
}

fn chain_trace(seed: u64, kernel: MpfKernel, policy: ResamplePolicy) -> (Trace, f64) {
    let (model, ys) = bench::chain::dataset(300, 7);
    let cfg = ParticleConfig {
        particles: 100,
        resampling: policy,
    };
    let mut f = MpfEkf2::new(model, cfg).with_kernel(kernel);
    let mut rng = stream(seed, 0, "filter/mpf-ekf2");
    let mut trace = Trace::default();
    let s = run(&mut f, &ys, &mut rng, &mut trace);
    assert!(s.failure.is_none(), "{:?}", s.failure);
    assert_eq!(s.steps_completed, ys.len());
    (trace, s.loglik)
}

#[test]
fn same_seed_gives_identical_traces() {
    let policy = ResamplePolicy::default();
    let (a, la) = chain_trace(1, MpfKernel::Sparse, policy);
    let (b, lb) = chain_trace(1, MpfKernel::Sparse, policy);
    assert_eq!(a.posts, b.posts);
    assert_eq!(a.infos, b.infos);
    assert_eq!(la.to_bits(), lb.to_bits());
    let (c, _) = chain_trace(2, MpfKernel::Sparse, policy);
    assert_ne!(a.posts, c.posts);
}

/// The sparse propagation kernel follows the dense reference over a whole run of the chain
/// (same random draws; only round-off differs).
#[test]
fn sparse_kernel_follows_dense_kernel_on_the_chain() {
    let policy = ResamplePolicy {
        scheme: Scheme::Stratified,
        ess_threshold: Some(0.5),
    };
    let (a, la) = chain_trace(3, MpfKernel::Sparse, policy);
    let (b, lb) = chain_trace(3, MpfKernel::Dense, policy);
    assert!((la - lb).abs() < 1e-8 * la.abs().max(1.0), "{la} vs {lb}");
    for (pa, pb) in a.posts.iter().zip(&b.posts) {
        for (x, y) in pa.param_mean.iter().zip(&pb.param_mean) {
            assert!((x - y).abs() < 1e-8 * y.abs().max(1.0), "{x} vs {y}");
        }
        for (x, y) in pa.state_sd.iter().zip(&pb.state_sd) {
            assert!((x - y).abs() < 1e-8 * y.abs().max(1e-3), "{x} vs {y}");
        }
    }
    // With an ESS threshold not every step resamples.
    let resampled = a.infos.iter().filter(|i| i.resampled).count();
    assert!(resampled > 0 && resampled < a.infos.len());
}

#[test]
fn nan_measurement_ends_the_run_with_a_typed_failure() {
    let (model, mut ys) = bench::chain::dataset(20, 7);
    ys[9][1] = f64::NAN;
    let mut f = MpfEkf2::new(model, config(50));
    let mut rng = stream(1, 0, "filter/mpf-ekf2");
    let s = run(
        &mut f,
        &ys,
        &mut rng,
        &mut core_filters::particle::NoObserver,
    );
    assert_eq!(s.steps_completed, 9);
    assert_eq!(
        s.failure,
        Some(FilterError::NonFinite {
            step: 10,
            which: "measurement"
        })
    );
    assert!(s.loglik.is_finite());
}

/// Particles whose computations fail get weight zero, are counted, and are never chosen as
/// ancestors; the others carry on.
#[test]
fn failing_particles_get_zero_weight_and_are_counted() {
    let mut model = Decoupled::new();
    model.poison = true;
    let np = 200;
    let mut f = MpfEkf2::new(model, config(np));
    let mut rng = stream(8, 0, "filter/mpf-ekf2");
    f.initialise(&mut rng);
    let poisoned = f.sampled().iter().filter(|x| x[1] > 0.5).count();
    assert!(poisoned > 50 && poisoned < 150);
    let y = Vector2::new(0.3, -0.1);
    f.step(1, &y, &mut rng).expect("step 1");
    assert_eq!(f.health().nan_weights, poisoned as u64);
    for (x, w) in f.sampled().iter().zip(f.weights()) {
        assert_eq!(*w == 0.0, x[1] > 0.5);
    }
    // Resampling at the start of step 2 keeps only healthy particles.
    f.step(2, &y, &mut rng).expect("step 2");
    assert!(f.sampled().iter().all(|x| x[1] <= 0.5));
    assert_eq!(f.health().nan_weights, poisoned as u64);
}

/// A measurement far outside the model's reach has a finite, tiny likelihood; an input so large
/// that every particle's innovation overflows ends the run with a typed error, never a panic.
#[test]
fn overflow_in_every_particle_is_a_typed_failure() {
    let (model, ys) = bench::chain::dataset(5, 7);
    let mut f = MpfEkf2::new(model, config(50));
    let mut rng = stream(1, 0, "filter/mpf-ekf2");
    f.initialise(&mut rng);
    f.step(1, &ys[0], &mut rng).expect("step 1");
    let info = f
        .step(2, &Vector3::new(1e3, 0.0, 0.0), &mut rng)
        .expect("step 2");
    assert!(info.loglik_increment.is_finite() && info.loglik_increment < -1e4);

    let (mut model, ys) = bench::chain::dataset(5, 7);
    model.ug[2] = 1e300;
    let mut f = MpfEkf2::new(model, config(50));
    let s = run(
        &mut f,
        &ys,
        &mut rng,
        &mut core_filters::particle::NoObserver,
    );
    assert_eq!(s.steps_completed, 1);
    assert_eq!(s.failure, Some(FilterError::AllWeightsZero { step: 2 }));
}
