//! Capability traits a model implements, on run-time dimensions (STYLE lessons 1–2).
//!
//! A model only *states laws*: maps, Jacobians (by their structural non-zeros, [`Sparse`]),
//! constant sparse Hessians, noise levels and priors. The particle filters of [`crate::smc`]
//! consume them. What every model provides is [`Partition`]; each capability trait extends it with
//! what its filter needs. The Bouc–Wen chain of the `models` crate implements all three traits
//! through its partitions; small linear-Gaussian test models implement what they can, which is
//! what makes the exactness tests possible.
//!
//! Conventions shared by every trait:
//! - The model owns its known input sequence (the measured ground acceleration).
//! - A transition at step `k` maps quantities at `k−1` (with the input at `k−1`) to step `k`; an
//!   observation at step `k` uses the input at `k`.
//! - Maps that a filter evaluates for many particles are generic over [`Real`], so that the batch
//!   layer evaluates them for a pack of particles at once; a model implements them with ordinary
//!   arithmetic (`Real` has `+ − × ÷`, `abs`, `sqrt`, and [`Real::per_lane`] for anything else,
//!   which keeps every lane bit for bit the scalar computation).
//! - A Jacobian is written entry by entry into a [`Sparse`] (`start`, `add`…, `finish`); the
//!   model must write the same `(row, col)` sequence at every call, whatever the values (the
//!   first call records the pattern).
//! - Covariances are column-major `Vec<f64>`.
//!
//! **Stages.** A semi-implicit discretisation updates some entries from the new values of others
//! (velocities first, then displacements and hysteretic variables with the new velocities). The
//! transitions of [`ConditionallyLinear`] and the sampled dynamics of [`ConditionallyQuadratic`]
//! are therefore split into *stages*: stage `s` sets its rows from the state at `k−1` and the rows
//! already set by stages `< s`. Forward Euler has a single stage. The filters sample and condition
//! stage by stage, which keeps each stage's map linear (MLN-RBPF, Storvik) or at most bilinear
//! (MPF-EKF2) in the marginalised block.

use crate::linalg::{Sparse, SymEntries};
use crate::model::{Layout, SparseHessians};
use crate::real::Real;
use crate::rng::StreamRng;

use super::rejuvenation::StaticParam;

/// What every model provides, whatever it leaves to the particles (the sampled block: all of
/// `x` for [`StateSpace`], `u` for [`ConditionallyLinear`], `xⁿ` for [`ConditionallyQuadratic`])
/// and whatever it marginalises. The capability traits add only what their filter needs besides.
pub trait Partition: Send + Sync {
    /// Draws the sampled block at step 0 from its prior.
    fn sample_initial(&self, rng: &mut StreamRng, sampled: &mut [f64]);
    /// Measurement noise covariance `R` (`ny × ny`).
    fn measurement_cov(&self) -> Vec<f64>;
    /// Where θ and the physical states live.
    fn layout(&self) -> Layout;
    /// The static entries of the sampled block (set by no stage, copied from the ancestor) that a
    /// rejuvenation move may change, with their supports ([`super::rejuvenation`]); none by
    /// default.
    fn static_params(&self) -> Vec<StaticParam> {
        Vec::new()
    }
}

/// A model with a marginalised Gaussian block (the MLN-RBPF's and Storvik's `z`, the MPF-EKF2's
/// `x^bl`): what [`ConditionallyLinear`] and [`ConditionallyQuadratic`] share besides
/// [`Partition`], so that their filters draw a particle's initial state in one way.
pub trait Marginalised: Partition {
    /// Mean and covariance (column-major, the block's dimension squared) of the Gaussian prior of
    /// the marginalised block for one particle (deterministic for the moment-matched prior,
    /// SPEC §3; a per-particle prior draws).
    fn marginal_prior(&self, rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]);
    /// Entries of the marginalised block held to their physical support after every step
    /// (`linalg::support`); none by default.
    fn lower_bounds(&self) -> Vec<crate::linalg::LowerBound> {
        Vec::new()
    }
}

/// A general state-space model with an augmented state (bootstrap PF, SPEC §5.1):
/// `x_k = propagate(k, x_{k−1}, ξ_k)` with standard normal `ξ_k` (the model applies its own noise
/// structure), `y_k ~ N(measure(k, x_k), R)`.
pub trait StateSpace: Partition {
    /// Dimension of `x`.
    fn dim(&self) -> usize;
    /// Number of measurements.
    fn ny(&self) -> usize;
    /// Number of standard normal draws per particle and step (`ξ_k`).
    fn noise_dim(&self) -> usize;
    /// `out = x_k` from `x = x_{k−1}` and the draws `xi` (length [`StateSpace::noise_dim`]).
    fn propagate(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]);
    /// `out` = mean of `y_k` given `x_k`.
    fn measure(&self, k: usize, x: &[f64], out: &mut [f64]);
}

/// Dimensions of a [`ConditionallyLinear`] model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinearDims {
    /// Sampled block `u`.
    pub nu: usize,
    /// Marginalised static block `z`.
    pub nz: usize,
    /// Measurements.
    pub ny: usize,
}

/// One stage of a transition: the rows of `u_k` it sets, and which of them depend on `z`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stage {
    /// Indices into `u` of the rows set by this stage, in order.
    pub rows: Vec<usize>,
    /// The subset of `rows` whose map depends on `z` ("linked" rows), in the order of `rows`.
    pub linked: Vec<usize>,
}

impl Stage {
    /// Position in [`Stage::rows`] of each linked row.
    #[track_caller]
    pub(crate) fn linked_positions(&self) -> Vec<usize> {
        self.linked
            .iter()
            .map(|l| {
                self.rows
                    .iter()
                    .position(|r| r == l)
                    .expect("a linked row is one of the stage's rows")
            })
            .collect()
    }

    /// Process-noise covariance of the linked rows (`l × l`, diagonal, column-major) from the
    /// s.d. `sd` of every row of `u`: the noise of the stage's pseudo-measurement of `z`.
    pub(crate) fn linked_noise_cov(&self, sd: &[f64]) -> Vec<f64> {
        let l = self.linked.len();
        let mut q_l = vec![0.0; l * l];
        for (i, &r) in self.linked.iter().enumerate() {
            q_l[i + i * l] = sd[r] * sd[r];
        }
        q_l
    }
}

/// A mixed linear/nonlinear model, linear in a static block `z` given the sampled block `u`
/// (MLN-RBPF and Storvik, SPEC §5.2–5.3), with a staged transition (module docs):
///
/// stage `s`: `u_k[rows_s] = f_s + F_s z + v`, with `f_s`, `F_s` functions of `u_{k−1}` and of
/// the rows of `u_k` set by earlier stages; `F_s` is non-zero only on the linked rows;
/// `y_k = h(u_k) + H(u_k) z + η`, `z` static.
///
/// Rows of `u` set by no stage are static and copied (e.g. the Bouc–Wen exponent `n`).
#[allow(non_snake_case)]
pub trait ConditionallyLinear: Marginalised {
    fn dims(&self) -> LinearDims;
    /// The stages of the transition, in order.
    fn stages(&self) -> &[Stage];
    /// Standard deviations of the process noise of every row of `u` (zero for copied rows).
    fn process_noise_sd(&self) -> &[f64];
    /// Stage `stage` of the transition to step `k`: `f[i]` for row `rows[i]` of the stage, and
    /// `F` (`linked.len() × nz`, row `l` for `linked[l]`). `u_new` holds the rows set by earlier
    /// stages (other entries are unspecified).
    fn transition<T: Real>(
        &self,
        stage: usize,
        k: usize,
        u_prev: &[T],
        u_new: &[T],
        f: &mut [T],
        F: &mut Sparse<T>,
    );
    /// `(h(u_k), H(u_k))` (`H` is `ny × nz`).
    fn observation<T: Real>(&self, k: usize, u: &[T], h: &mut [T], H: &mut Sparse<T>);
    /// `J_u = ∂/∂u [H(u) z + h(u)]` at `(u_k, z)` (`ny × nu`; Storvik's linearisation,
    /// SPEC §5.3 (iii)).
    fn observation_jacobian_u<T: Real>(&self, k: usize, u: &[T], z: &[T], J: &mut Sparse<T>);
    /// `∂u_k/∂z` of the whole transition at `z` along the sampled path (`nu × nz`; for forward
    /// Euler the linked rows of `F`). Storvik's linearised update writes `y_k` through it.
    fn transition_sensitivity<T: Real>(
        &self,
        k: usize,
        u_prev: &[T],
        u_new: &[T],
        z: &[T],
        S: &mut Sparse<T>,
    );
}

/// Dimensions of a [`ConditionallyQuadratic`] model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QuadraticDims {
    /// Sampled block `xⁿ` (dynamic entries and static ones).
    pub nn: usize,
    /// Marginalised block `x^bl`.
    pub nbl: usize,
    /// Measurements.
    pub ny: usize,
}

/// Where stage `stage` of ψ is evaluated (SPEC §5.4): the transition to step `k`, the particle's
/// xⁿ_{k−1} (`prev`), the rows of xⁿ_k set by earlier stages (`new`; other entries unspecified)
/// and the marginalised block at `x^bl = m`.
#[derive(Debug, Clone, Copy)]
pub struct SampledAt<'a, T> {
    /// Index of the stage (into [`ConditionallyQuadratic::sampled_stages`]).
    pub stage: usize,
    /// Step of the transition (`k − 1 → k`).
    pub k: usize,
    /// xⁿ_{k−1}.
    pub prev: &'a [T],
    /// xⁿ_k: the rows of earlier stages are set, the others unspecified.
    pub new: &'a [T],
    /// The point `x^bl = m`.
    pub m: &'a [T],
}

/// A model that, given a small sampled block `xⁿ`, is at most quadratic (in practice bilinear) in
/// the marginalised block `x^bl`, so that EKF2 moments are exact (MPF-EKF2, SPEC §5.4 and §6).
///
/// The dynamic entries of `xⁿ` are set stage by stage (module docs); entries set by no stage are
/// static and copied. Maps are returned as their value and Jacobian with respect to `x^bl` at the
/// point `m`; their Hessians with respect to `x^bl` are constant (they depend on the structure and
/// the time step only) and are supplied once as sparse entry lists.
pub trait ConditionallyQuadratic: Marginalised {
    fn dims(&self) -> QuadraticDims;
    /// Per stage, the indices into `xⁿ` of the dynamic entries it sets.
    fn sampled_stages(&self) -> &[Vec<usize>];
    /// `ψ` of stage `at.stage` at `(xⁿ_{k−1}, xⁿ_k rows of earlier stages, x^bl = m)` (see
    /// [`SampledAt`]): `value[i]` for entry `stages[at.stage][i]` (without noise), `jac` its
    /// Jacobian w.r.t. `x^bl`.
    fn sampled_dynamics<T: Real>(&self, at: SampledAt<'_, T>, value: &mut [T], jac: &mut Sparse<T>);
    /// Constant Hessians of stage `stage`'s `ψ` w.r.t. `x^bl` (outputs index the stage's rows).
    fn sampled_hessians(&self, stage: usize) -> &SparseHessians;
    /// Process-noise s.d. of stage `stage`'s entries (`Qₙ`, diagonal).
    fn sampled_noise_sd(&self, stage: usize) -> &[f64];
    /// `φ_bl` at `(xⁿ_{k−1}, xⁿ_k, x^bl = m)`: `value` (`nbl`) and `D = ∂φ_bl/∂x^bl − I`.
    fn marginal_dynamics<T: Real>(
        &self,
        k: usize,
        xn_prev: &[T],
        xn_new: &[T],
        m: &[T],
        value: &mut [T],
        d: &mut Sparse<T>,
    );
    /// Constant Hessians of `φ_bl` w.r.t. `x^bl` (outputs `0..nbl`).
    fn marginal_hessians(&self) -> &SparseHessians;
    /// Process-noise covariance `Q_bl` of `x^bl` (zero for parameters).
    fn marginal_noise(&self) -> &SymEntries;
    /// Measurement map at `(xⁿ_k, x^bl = m)` with the input at `k`: value (`ny`) and Jacobian.
    fn observation<T: Real>(
        &self,
        k: usize,
        xn: &[T],
        m: &[T],
        value: &mut [T],
        jac: &mut Sparse<T>,
    );
    /// Constant Hessians of the measurement map w.r.t. `x^bl` (outputs `0..ny`).
    fn observation_hessians(&self) -> &SparseHessians;
    /// Transitions per measurement interval, `M`: one filter step advances through `M`
    /// transitions (indices `(k−1)M+1 ..= kM` of the model's time grid) and then weights with
    /// `y_k` at index `kM`. 1 for a model on the measurement grid.
    fn substeps(&self) -> usize {
        1
    }
}
