//! Capability traits a model implements (STYLE lessons 1–2).
//!
//! A model only *states laws*: maps, Jacobians, sparse Hessians, noise levels and priors. Filters
//! consume them. A model may implement several traits; the Bouc–Wen chain of the `models` crate
//! implements all three through its partitions, and small linear-Gaussian test models implement
//! what they can, which is what makes the exactness tests possible.
//!
//! Conventions shared by every trait:
//! - The model owns its known input sequence (e.g. the measured ground acceleration).
//! - `transition`-like methods at step `k` map quantities at `k-1` (with the input at `k-1`) to
//!   step `k`; `observation`-like methods at step `k` use the input at `k`.
//! - Process noise is Gaussian with a diagonal covariance given by standard deviations; an entry
//!   with standard deviation zero is propagated exactly (static parameters, copied entries).
//! - Dimensions are const generics so that hot loops use fixed-size `nalgebra` types.

use nalgebra::{SMatrix, SVector};
use rand::Rng;

/// Where a named quantity (a parameter of θ or a physical state) lives in a filter's
/// representation: an entry of the sampled (particle) vector or of the marginalised Gaussian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Entry `i` of the sampled vector (averaged over particles).
    Sampled(usize),
    /// Entry `i` of the marginalised Gaussian (mixture of per-particle Gaussians).
    Marginal(usize),
}

/// Names and slots of the parameters θ and the physical states, in the model's order.
/// Filters use it to report posterior means and standard deviations by name.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub param_names: Vec<String>,
    pub params: Vec<Slot>,
    pub state_names: Vec<String>,
    pub states: Vec<Slot>,
}

/// One non-zero second derivative `∂²f_output / ∂x_a ∂x_b = value`.
///
/// Symmetric pairs are listed once: an entry with `a != b` stands for both `(a, b)` and `(b, a)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HessianEntry {
    pub output: usize,
    pub a: usize,
    pub b: usize,
    pub value: f64,
}

/// The Hessians of a vector-valued map as a sparse entry list (SPEC §4: never dense n×n×n).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SparseHessians {
    entries: Vec<HessianEntry>,
}

impl SparseHessians {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `∂²f_output/∂x_a∂x_b = value` (and its symmetric twin when `a != b`).
    pub fn push(&mut self, output: usize, a: usize, b: usize, value: f64) {
        self.entries.push(HessianEntry {
            output,
            a,
            b,
            value,
        });
    }

    /// The entries, each symmetric pair listed once.
    pub fn entries(&self) -> &[HessianEntry] {
        &self.entries
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The dense Hessian of component `output` (n×n), for tests and diagnostics only.
    pub fn dense(&self, output: usize, n: usize) -> nalgebra::DMatrix<f64> {
        let mut h = nalgebra::DMatrix::zeros(n, n);
        for e in self.entries.iter().filter(|e| e.output == output) {
            h[(e.a, e.b)] += e.value;
            if e.a != e.b {
                h[(e.b, e.a)] += e.value;
            }
        }
        h
    }
}

/// A general state-space model with an augmented state (bootstrap PF, SPEC §5.1):
/// `x_k = propagate(k, x_{k-1}) + v_k`, `v_k ~ N(0, diag(sd²))`, `y_k ~ N(measure(k, x_k), R)`.
pub trait StateSpace<const NX: usize, const NY: usize> {
    /// Draws `x_0` from the prior.
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NX>;
    /// Deterministic part of the transition from `k-1` to `k`.
    fn propagate(&self, k: usize, x: &SVector<f64, NX>) -> SVector<f64, NX>;
    /// Standard deviations of the process noise (zero for static entries).
    fn process_noise_sd(&self) -> SVector<f64, NX>;
    /// Mean of `y_k` given `x_k`.
    fn measure(&self, k: usize, x: &SVector<f64, NX>) -> SVector<f64, NY>;
    /// Measurement noise covariance `R`.
    fn measurement_cov(&self) -> SMatrix<f64, NY, NY>;
    /// Where θ and the physical states live in `x`.
    fn layout(&self) -> Layout;
}

/// A mixed linear/nonlinear model, linear in a static block `z` given the sampled block `u`
/// (MLN-RBPF and Storvik, SPEC §5.2–5.3):
///
/// `u_k = f(u_{k-1}) + F(u_{k-1}) z + v_u`, `y_k = h(u_k) + H(u_k) z + η`, `z` static.
///
/// Only `NL` rows of `F` can be non-zero ("linked" rows, e.g. the velocity and hysteresis rows);
/// the other rows of `u` do not depend on `z`. The model returns `F` restricted to those rows, so
/// the pseudo-measurement update never factorises a singular covariance.
#[allow(non_snake_case)]
pub trait ConditionallyLinear<const NU: usize, const NZ: usize, const NL: usize, const NY: usize> {
    /// Draws the sampled block `u_0` from its prior.
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NU>;
    /// Mean and covariance of the Gaussian prior of `z` for one particle. Deterministic for the
    /// moment-matched prior (SPEC §3); a per-particle prior draws from `rng`.
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        rng: &mut G,
    ) -> (SVector<f64, NZ>, SMatrix<f64, NZ, NZ>);
    /// Indices (into `u`) of the rows of `F` that may be non-zero, in increasing order.
    fn linked_rows(&self) -> [usize; NL];
    /// `(f(u_{k-1}), F_L(u_{k-1}))`: the affine-in-`z` transition to step `k`; `F_L` holds the
    /// linked rows of `F` only.
    fn transition(
        &self,
        k: usize,
        u: &SVector<f64, NU>,
    ) -> (SVector<f64, NU>, SMatrix<f64, NL, NZ>);
    /// Standard deviations of `v_u` (zero for copied entries such as `n`).
    fn process_noise_sd(&self) -> SVector<f64, NU>;
    /// `(h(u_k), H(u_k))`: the affine-in-`z` measurement at step `k`.
    fn observation(
        &self,
        k: usize,
        u: &SVector<f64, NU>,
    ) -> (SVector<f64, NY>, SMatrix<f64, NY, NZ>);
    /// `J_u = ∂/∂u [H(u) z + h(u)]` at `(u_k, z)` (Storvik's linearisation, SPEC §5.3 (iii)).
    fn observation_jacobian_u(
        &self,
        k: usize,
        u: &SVector<f64, NU>,
        z: &SVector<f64, NZ>,
    ) -> SMatrix<f64, NY, NU>;
    /// Measurement noise covariance `R`.
    fn measurement_cov(&self) -> SMatrix<f64, NY, NY>;
    /// Where θ and the physical states live.
    fn layout(&self) -> Layout;
}

/// A model that, given a small sampled block `xⁿ`, is at most quadratic (in practice bilinear) in
/// the marginalised block `x^bl`, so that EKF2 moments are exact (MPF-EKF2, SPEC §5.4 and §6).
///
/// `xⁿ` has `NN` entries: the first `ND` are dynamic (they evolve and act as a
/// pseudo-measurement of `x^bl`), the remaining `NN - ND` are static and copied.
///
/// Maps are returned as their value and Jacobian at the point `m`; their Hessians with respect to
/// `x^bl` are constant (they depend on the structure and the time step only, which holds for the
/// shear chain) and are supplied once as sparse entry lists.
pub trait ConditionallyQuadratic<
    const NN: usize,
    const ND: usize,
    const NBL: usize,
    const NY: usize,
>
{
    /// Draws the sampled block `xⁿ_0` from its prior.
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NN>;
    /// Mean and covariance of the Gaussian prior of `x^bl` for one particle.
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        rng: &mut G,
    ) -> (SVector<f64, NBL>, SMatrix<f64, NBL, NBL>);
    /// `ψₙ` at `(xⁿ_{k-1}, x^bl = m)`: value and Jacobian w.r.t. `x^bl` of the dynamic sampled
    /// entries at step `k` (without noise).
    fn sampled_dynamics(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, ND>, SMatrix<f64, ND, NBL>);
    /// `φ_bl` at `(xⁿ_{k-1}, x^bl = m)`: value and Jacobian of the marginalised transition.
    fn marginal_dynamics(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, NBL>, SMatrix<f64, NBL, NBL>);
    /// Measurement map at `(xⁿ_k, x^bl = m)` with the input at `k`: value and Jacobian.
    fn observation(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, NY>, SMatrix<f64, NY, NBL>);
    /// Constant Hessians of `ψₙ` w.r.t. `x^bl` (outputs `0..ND`).
    fn sampled_hessians(&self) -> &SparseHessians;
    /// Constant Hessians of `φ_bl` w.r.t. `x^bl` (outputs `0..NBL`).
    fn marginal_hessians(&self) -> &SparseHessians;
    /// Constant Hessians of the measurement map w.r.t. `x^bl` (outputs `0..NY`).
    fn observation_hessians(&self) -> &SparseHessians;
    /// Standard deviations of the process noise of the dynamic sampled entries (`Qₙ`).
    fn sampled_noise_sd(&self) -> SVector<f64, ND>;
    /// Standard deviations of the process noise of `x^bl` (`Q_bl`, zero for parameters).
    fn marginal_noise_sd(&self) -> SVector<f64, NBL>;
    /// Measurement noise covariance `R`.
    fn measurement_cov(&self) -> SMatrix<f64, NY, NY>;
    /// Where θ and the physical states live.
    fn layout(&self) -> Layout;
}
