//! Linear-Gaussian test models for the run-time-dimension particle filters, with their exact
//! Kalman references (the same models as `common`, stated through the `smc::model` traits).
//!
//! - [`Linked`]: scalar `u` driven by a static scalar `z`, `u_k = a u_{k−1} + b z + v`,
//!   `y_k = c u_k + d z + η`: a `ConditionallyLinear` model (`z` marginalised, the row of `u`
//!   linked) and, as [`Augmented`], a `StateSpace` (augmented `[u, z]`).
//! - [`StaticOnly`]: `u` a random walk unrelated to `z ∈ R²`, `y_k = H z + h + η` with `H`, `h`
//!   constant and `R` full: every particle's Gaussian is the exact KF of `z`.
#![allow(dead_code, non_snake_case)]

use core_filters::kalman::LinearGaussian;
use core_filters::linalg::Sparse;
use core_filters::model::{Layout, Slot};
use core_filters::real::Real;
use core_filters::rng::StreamRng;
use core_filters::smc::model::{
    ConditionallyLinear, LinearDims, Marginalised, Partition, Stage, StateSpace,
};
use nalgebra::{Matrix1, Matrix2, SMatrix, Vector1, Vector2};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

pub fn normal<G: Rng + ?Sized>(rng: &mut G) -> f64 {
    StandardNormal.sample(rng)
}

#[derive(Debug, Clone)]
pub struct Linked {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub q_sd: f64,
    pub r_sd: f64,
    pub u0_mean: f64,
    pub u0_sd: f64,
    pub z_mean: f64,
    pub z_sd: f64,
    /// From this step on, `H` is written as two half entries instead of one: the same matrix
    /// with another sparsity pattern than the declared one (a model bug the filters must report).
    pub pattern_changes_at: usize,
    stages: Vec<Stage>,
    sd: Vec<f64>,
}

impl Linked {
    pub fn example() -> Self {
        Self {
            a: 0.8,
            b: 0.5,
            c: 1.0,
            d: 0.4,
            q_sd: 0.3,
            r_sd: 0.5,
            u0_mean: 0.0,
            u0_sd: 0.5,
            z_mean: 1.0,
            z_sd: 0.5,
            pattern_changes_at: usize::MAX,
            stages: vec![Stage {
                rows: vec![0],
                linked: vec![0],
            }],
            sd: vec![0.3],
        }
    }

    /// The model as one augmented state, for the bootstrap PF.
    pub fn augmented(&self) -> Augmented {
        Augmented(self.clone())
    }

    /// The same model with `y_k = c u_k + d z + η` for another `c`.
    pub fn with_c(mut self, c: f64) -> Self {
        self.c = c;
        self
    }

    /// Simulates `y_1..y_T` (flat) with the static parameter fixed at `z`.
    pub fn simulate<G: Rng + ?Sized>(&self, z: f64, t: usize, rng: &mut G) -> Vec<f64> {
        let mut u = self.u0_mean + self.u0_sd * normal(rng);
        (0..t)
            .map(|_| {
                u = self.a * u + self.b * z + self.q_sd * normal(rng);
                self.c * u + self.d * z + self.r_sd * normal(rng)
            })
            .collect()
    }

    /// The KF on `[u, z]`: exact `log p(y_1:T)`.
    pub fn joint_kalman(&self) -> LinearGaussian<2, 1> {
        LinearGaussian {
            g_mat: Matrix2::new(self.a, self.b, 0.0, 1.0),
            g_off: Vector2::zeros(),
            h_mat: SMatrix::<f64, 1, 2>::new(self.c, self.d),
            h_off: Vector1::zeros(),
            q: Matrix2::new(self.q_sd * self.q_sd, 0.0, 0.0, 0.0),
            r: Matrix1::new(self.r_sd * self.r_sd),
            m0: Vector2::new(self.u0_mean, self.z_mean),
            p0: Matrix2::new(self.u0_sd * self.u0_sd, 0.0, 0.0, self.z_sd * self.z_sd),
        }
    }

    /// The KF on `u` for a known `z`: `log p(y_1:T | z)`.
    pub fn kalman_given_z(&self, z: f64) -> LinearGaussian<1, 1> {
        LinearGaussian {
            g_mat: Matrix1::new(self.a),
            g_off: Vector1::new(self.b * z),
            h_mat: Matrix1::new(self.c),
            h_off: Vector1::new(self.d * z),
            q: Matrix1::new(self.q_sd * self.q_sd),
            r: Matrix1::new(self.r_sd * self.r_sd),
            m0: Vector1::new(self.u0_mean),
            p0: Matrix1::new(self.u0_sd * self.u0_sd),
        }
    }
}

/// [`Linked`] as one augmented state `x = [u, z]` (bootstrap PF).
#[derive(Debug, Clone)]
pub struct Augmented(pub Linked);

impl Partition for Linked {
    fn sample_initial(&self, rng: &mut StreamRng, u: &mut [f64]) {
        u[0] = self.u0_mean + self.u0_sd * normal(rng);
    }
    fn measurement_cov(&self) -> Vec<f64> {
        vec![self.r_sd * self.r_sd]
    }
    fn layout(&self) -> Layout {
        Layout {
            param_names: vec!["z".into()],
            params: vec![Slot::Marginal(0)],
            state_names: vec!["u".into()],
            states: vec![Slot::Sampled(0)],
        }
    }
}

impl Partition for Augmented {
    fn sample_initial(&self, rng: &mut StreamRng, x: &mut [f64]) {
        self.0.sample_initial(rng, &mut x[..1]);
        x[1] = self.0.z_mean + self.0.z_sd * normal(rng);
    }
    fn measurement_cov(&self) -> Vec<f64> {
        self.0.measurement_cov()
    }
    fn layout(&self) -> Layout {
        Layout {
            params: vec![Slot::Sampled(1)],
            ..self.0.layout()
        }
    }
}

impl StateSpace for Augmented {
    fn dim(&self) -> usize {
        2
    }
    fn ny(&self) -> usize {
        1
    }
    fn noise_dim(&self) -> usize {
        1
    }
    fn propagate(&self, _k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let m = &self.0;
        out[0] = m.a * x[0] + m.b * x[1] + m.q_sd * xi[0];
        out[1] = x[1];
    }
    fn measure(&self, _k: usize, x: &[f64], out: &mut [f64]) {
        out[0] = self.0.c * x[0] + self.0.d * x[1];
    }
}

impl ConditionallyLinear for Linked {
    fn dims(&self) -> LinearDims {
        LinearDims {
            nu: 1,
            nz: 1,
            ny: 1,
        }
    }
    fn stages(&self) -> &[Stage] {
        &self.stages
    }
    fn process_noise_sd(&self) -> &[f64] {
        &self.sd
    }
    fn transition<T: Real>(
        &self,
        _stage: usize,
        _k: usize,
        u_prev: &[T],
        _u_new: &[T],
        f: &mut [T],
        F: &mut Sparse<T>,
    ) {
        f[0] = T::splat(self.a) * u_prev[0];
        F.add(0, 0, T::splat(self.b));
    }
    fn observation<T: Real>(&self, k: usize, u: &[T], h: &mut [T], H: &mut Sparse<T>) {
        h[0] = T::splat(self.c) * u[0];
        if k < self.pattern_changes_at {
            H.add(0, 0, T::splat(self.d));
        } else {
            H.add(0, 0, T::splat(0.5 * self.d));
            H.add(0, 0, T::splat(0.5 * self.d));
        }
    }
    fn observation_jacobian_u<T: Real>(&self, _k: usize, _u: &[T], _z: &[T], J: &mut Sparse<T>) {
        J.add(0, 0, T::splat(self.c));
    }
    fn transition_sensitivity<T: Real>(
        &self,
        _k: usize,
        _u_prev: &[T],
        _u_new: &[T],
        _z: &[T],
        S: &mut Sparse<T>,
    ) {
        S.add(0, 0, T::splat(self.b));
    }
}

impl Marginalised for Linked {
    fn marginal_prior(&self, _rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        mean[0] = self.z_mean;
        cov[0] = self.z_sd * self.z_sd;
    }
}

#[derive(Debug, Clone)]
pub struct StaticOnly {
    pub H: Matrix2<f64>,
    pub h: Vector2<f64>,
    pub r: Matrix2<f64>,
    pub z_mean: Vector2<f64>,
    pub z_cov: Matrix2<f64>,
    stages: Vec<Stage>,
    sd: Vec<f64>,
}

impl StaticOnly {
    pub fn example() -> Self {
        Self {
            H: Matrix2::new(1.0, 0.5, -0.3, 2.0),
            h: Vector2::new(0.2, -1.0),
            r: Matrix2::new(0.5, 0.1, 0.1, 0.8),
            z_mean: Vector2::new(1.0, -0.5),
            z_cov: Matrix2::new(2.0, 0.3, 0.3, 1.0),
            // The row of u is linked with F = 0: its proposal is the noise alone.
            stages: vec![Stage {
                rows: vec![0],
                linked: vec![0],
            }],
            sd: vec![0.3],
        }
    }

    pub fn simulate<G: Rng + ?Sized>(&self, z: Vector2<f64>, t: usize, rng: &mut G) -> Vec<f64> {
        let l = self.r.cholesky().unwrap().l();
        let mut out = Vec::new();
        for _ in 0..t {
            let y = self.H * z + self.h + l * Vector2::new(normal(rng), normal(rng));
            out.extend([y[0], y[1]]);
        }
        out
    }

    /// The exact KF of the static `z` (`G = I`, `Q = 0`).
    pub fn kalman(&self) -> LinearGaussian<2, 2> {
        LinearGaussian {
            g_mat: Matrix2::identity(),
            g_off: Vector2::zeros(),
            h_mat: self.H,
            h_off: self.h,
            q: Matrix2::zeros(),
            r: self.r,
            m0: self.z_mean,
            p0: self.z_cov,
        }
    }
}

impl Partition for StaticOnly {
    fn sample_initial(&self, rng: &mut StreamRng, u: &mut [f64]) {
        u[0] = normal(rng);
    }

    fn measurement_cov(&self) -> Vec<f64> {
        self.r.as_slice().to_vec()
    }

    fn layout(&self) -> Layout {
        Layout {
            param_names: vec!["z0".into(), "z1".into()],
            params: vec![Slot::Marginal(0), Slot::Marginal(1)],
            state_names: vec!["u".into()],
            states: vec![Slot::Sampled(0)],
        }
    }
}

impl ConditionallyLinear for StaticOnly {
    fn dims(&self) -> LinearDims {
        LinearDims {
            nu: 1,
            nz: 2,
            ny: 2,
        }
    }
    fn stages(&self) -> &[Stage] {
        &self.stages
    }
    fn process_noise_sd(&self) -> &[f64] {
        &self.sd
    }
    fn transition<T: Real>(
        &self,
        _stage: usize,
        _k: usize,
        u_prev: &[T],
        _u_new: &[T],
        f: &mut [T],
        F: &mut Sparse<T>,
    ) {
        f[0] = u_prev[0];
        F.add(0, 0, T::splat(0.0));
    }
    fn observation<T: Real>(&self, _k: usize, _u: &[T], h: &mut [T], H: &mut Sparse<T>) {
        h[0] = T::splat(self.h[0]);
        h[1] = T::splat(self.h[1]);
        for c in 0..2 {
            for r in 0..2 {
                H.add(r, c, T::splat(self.H[(r, c)]));
            }
        }
    }
    fn observation_jacobian_u<T: Real>(&self, _k: usize, _u: &[T], _z: &[T], J: &mut Sparse<T>) {
        J.add(0, 0, T::splat(0.0));
    }
    fn transition_sensitivity<T: Real>(
        &self,
        _k: usize,
        _u_prev: &[T],
        _u_new: &[T],
        _z: &[T],
        S: &mut Sparse<T>,
    ) {
        S.add(0, 0, T::splat(0.0));
    }
}

impl Marginalised for StaticOnly {
    fn marginal_prior(&self, _rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        mean.copy_from_slice(self.z_mean.as_slice());
        cov.copy_from_slice(self.z_cov.as_slice());
    }
}

/// exp(ℓ̂_r − ℓ) over seeds: mean, and its Monte-Carlo standard error from the same samples.
pub fn ratio_mean_and_se(logliks: &[f64], exact: f64) -> (f64, f64) {
    let n = logliks.len() as f64;
    let ratios: Vec<f64> = logliks.iter().map(|l| (l - exact).exp()).collect();
    let mean = ratios.iter().sum::<f64>() / n;
    let var = ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}
