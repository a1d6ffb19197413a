//! Linear-Gaussian test models for the particle filters, with their exact Kalman references.
//!
//! - [`Linked`]: scalar `u` driven by a static scalar `z`,
//!   `u_k = a u_{k−1} + b z + v`, `y_k = c u_k + d z + η`. As a [`StateSpace`] (augmented
//!   `x = [u, z]`) for the bootstrap PF, and as a [`ConditionallyLinear`] model (`z` marginalised,
//!   the single row of `u` linked) for MLN-RBPF and Storvik. The exact likelihood is the KF on
//!   `[u, z]` ([`Linked::joint_kalman`]); the exact posterior of `z` is a grid over `z` of KFs on
//!   `u` ([`Linked::kalman_given_z`]).
//! - [`StaticOnly`]: a `ConditionallyLinear` model whose `F_L` is zero and whose `H`, `h` are
//!   constant, so each particle's Gaussian is the exact KF of `z` ([`StaticOnly::kalman`]).
#![allow(dead_code, non_snake_case)]

use core_filters::kalman::LinearGaussian;
use core_filters::model::{ConditionallyLinear, Layout, Slot, StateSpace};
use nalgebra::{Matrix1, Matrix2, SMatrix, SVector, Vector1, Vector2};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

fn normal<G: Rng + ?Sized>(rng: &mut G) -> f64 {
    StandardNormal.sample(rng)
}

/// `u_k = a u_{k−1} + b z + v`, `v ~ N(0, q_sd²)`; `y_k = c u_k + d z + η`, `η ~ N(0, r_sd²)`;
/// `u_0 ~ N(u0_mean, u0_sd²)`, `z ~ N(z_mean, z_sd²)` independent.
#[derive(Debug, Clone, Copy)]
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
}

impl Linked {
    /// Simulates `y_1..y_T` with the static parameter fixed at `z`.
    pub fn simulate<G: Rng + ?Sized>(&self, z: f64, t: usize, rng: &mut G) -> Vec<Vector1<f64>> {
        let mut u = self.u0_mean + self.u0_sd * normal(rng);
        (0..t)
            .map(|_| {
                u = self.a * u + self.b * z + self.q_sd * normal(rng);
                Vector1::new(self.c * u + self.d * z + self.r_sd * normal(rng))
            })
            .collect()
    }

    /// The KF on `[u, z]`: exact `log p(y_1:T)` and filtered moments.
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

impl StateSpace<2, 1> for Linked {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, 2> {
        Vector2::new(
            self.u0_mean + self.u0_sd * normal(rng),
            self.z_mean + self.z_sd * normal(rng),
        )
    }
    fn propagate(&self, _k: usize, x: &SVector<f64, 2>) -> SVector<f64, 2> {
        Vector2::new(self.a * x[0] + self.b * x[1], x[1])
    }
    fn process_noise_sd(&self) -> SVector<f64, 2> {
        Vector2::new(self.q_sd, 0.0)
    }
    fn measure(&self, _k: usize, x: &SVector<f64, 2>) -> SVector<f64, 1> {
        Vector1::new(self.c * x[0] + self.d * x[1])
    }
    fn measurement_cov(&self) -> SMatrix<f64, 1, 1> {
        Matrix1::new(self.r_sd * self.r_sd)
    }
    fn layout(&self) -> Layout {
        Layout {
            param_names: vec!["z".into()],
            params: vec![Slot::Sampled(1)],
            state_names: vec!["u".into()],
            states: vec![Slot::Sampled(0)],
        }
    }
}

impl ConditionallyLinear<1, 1, 1, 1> for Linked {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, 1> {
        Vector1::new(self.u0_mean + self.u0_sd * normal(rng))
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        _rng: &mut G,
    ) -> (SVector<f64, 1>, SMatrix<f64, 1, 1>) {
        (
            Vector1::new(self.z_mean),
            Matrix1::new(self.z_sd * self.z_sd),
        )
    }
    fn linked_rows(&self) -> [usize; 1] {
        [0]
    }
    fn transition(&self, _k: usize, u: &SVector<f64, 1>) -> (SVector<f64, 1>, SMatrix<f64, 1, 1>) {
        (Vector1::new(self.a * u[0]), Matrix1::new(self.b))
    }
    fn process_noise_sd(&self) -> SVector<f64, 1> {
        Vector1::new(self.q_sd)
    }
    fn observation(&self, _k: usize, u: &SVector<f64, 1>) -> (SVector<f64, 1>, SMatrix<f64, 1, 1>) {
        (Vector1::new(self.c * u[0]), Matrix1::new(self.d))
    }
    fn observation_jacobian_u(
        &self,
        _k: usize,
        _u: &SVector<f64, 1>,
        _z: &SVector<f64, 1>,
    ) -> SMatrix<f64, 1, 1> {
        Matrix1::new(self.c)
    }
    fn measurement_cov(&self) -> SMatrix<f64, 1, 1> {
        Matrix1::new(self.r_sd * self.r_sd)
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

/// `u` a random walk unrelated to `z` (its linked row has `F_L = 0`), `z ∈ R²` static with
/// `y_k = H z + h + η`, `H`, `h` constant and `R` full. Every particle's Gaussian is the exact KF.
#[derive(Debug, Clone, Copy)]
pub struct StaticOnly {
    pub H: Matrix2<f64>,
    pub h: Vector2<f64>,
    pub r: Matrix2<f64>,
    pub z_mean: Vector2<f64>,
    pub z_cov: Matrix2<f64>,
}

impl StaticOnly {
    pub fn example() -> Self {
        Self {
            H: Matrix2::new(1.0, 0.5, -0.3, 2.0),
            h: Vector2::new(0.2, -1.0),
            r: Matrix2::new(0.5, 0.1, 0.1, 0.8),
            z_mean: Vector2::new(1.0, -0.5),
            z_cov: Matrix2::new(2.0, 0.3, 0.3, 1.0),
        }
    }

    pub fn simulate<G: Rng + ?Sized>(
        &self,
        z: Vector2<f64>,
        t: usize,
        rng: &mut G,
    ) -> Vec<Vector2<f64>> {
        let l = self.r.cholesky().unwrap().l();
        (0..t)
            .map(|_| self.H * z + self.h + l * Vector2::new(normal(rng), normal(rng)))
            .collect()
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

impl ConditionallyLinear<1, 2, 1, 2> for StaticOnly {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, 1> {
        Vector1::new(normal(rng))
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        _rng: &mut G,
    ) -> (SVector<f64, 2>, SMatrix<f64, 2, 2>) {
        (self.z_mean, self.z_cov)
    }
    fn linked_rows(&self) -> [usize; 1] {
        [0]
    }
    fn transition(&self, _k: usize, u: &SVector<f64, 1>) -> (SVector<f64, 1>, SMatrix<f64, 1, 2>) {
        (*u, SMatrix::<f64, 1, 2>::zeros())
    }
    fn process_noise_sd(&self) -> SVector<f64, 1> {
        Vector1::new(0.3)
    }
    fn observation(
        &self,
        _k: usize,
        _u: &SVector<f64, 1>,
    ) -> (SVector<f64, 2>, SMatrix<f64, 2, 2>) {
        (self.h, self.H)
    }
    fn observation_jacobian_u(
        &self,
        _k: usize,
        _u: &SVector<f64, 1>,
        _z: &SVector<f64, 2>,
    ) -> SMatrix<f64, 2, 1> {
        SMatrix::<f64, 2, 1>::zeros()
    }
    fn measurement_cov(&self) -> SMatrix<f64, 2, 2> {
        self.r
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

/// exp(ℓ̂_r − ℓ) over seeds: mean, and its Monte-Carlo standard error from the same samples.
pub fn ratio_mean_and_se(logliks: &[f64], exact: f64) -> (f64, f64) {
    let n = logliks.len() as f64;
    let ratios: Vec<f64> = logliks.iter().map(|l| (l - exact).exp()).collect();
    let mean = ratios.iter().sum::<f64>() / n;
    let var = ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}
