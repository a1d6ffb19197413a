//! Hysteresis laws of the chain's elements: the [`HysteresisLaw`] trait, and one file per law.
//!
//! A law is everything that is specific to one kind of hysteretic element: its rate and the
//! partials the filters differentiate, the names of its parameters (which of them enter the rate
//! linearly), its parameter record and that record's validation, the prior of its parameters
//! (with the moments from which the marginalised filters build their Gaussian prior) and the
//! record's JSON form. The shear chain (`crate::structure::ShearChainOf`), the priors of θ
//! (`crate::filtering::prior::ChainPriorOf`) and the filter partitions (`crate::filtering`) are
//! generic over it and monomorphised, so a law costs no dynamic dispatch in a filter's step.
//!
//! - [`bouc_wen`]: the Bouc–Wen law of SPEC eq. 22, the toolkit's law (θ = (β, γ), φ = (n));
//! - [`plastic`]: a smoothed elastic–perfectly-plastic law (θ = (ρ), φ = (m)), which the tests
//!   run through the simulator and the partitions to show that a law is one file.
//!
//! Adding a law is one file under `law/` implementing [`HysteresisLaw`] and its `mod` line here.

pub mod bouc_wen;
pub mod plastic;

pub use bouc_wen::{BoucWen, BoucWenLaw, BoucWenPrior};

use crate::priors::{Prior, PriorError};
use core_filters::real::Real;
use rand::Rng;
use serde::de::DeserializeOwned;
use serde::Serialize;
use thiserror::Error;

/// Largest number of linear parameters of a law (the partitions keep a law's basis
/// `[g₀, g₁, …]` in a stack array of `1 + MAX_LINEAR` entries); checked at compile time for
/// every law a partition is built with.
pub(crate) const MAX_LINEAR: usize = 4;
/// Largest number of parameters (linear and nonlinear) of a law.
pub(crate) const MAX_PARAMS: usize = 8;

/// An impossible parameter of one element, named by the law, the element's storey (0-based) and
/// the parameter.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LawError {
    #[error("{law} element at storey {storey}: {what} must be finite, got {value}")]
    NonFinite {
        law: &'static str,
        storey: usize,
        what: &'static str,
        value: f64,
    },
    #[error("{law} element at storey {storey}: {what} = {value} must be {requirement}")]
    OutOfRange {
        law: &'static str,
        storey: usize,
        what: &'static str,
        value: f64,
        requirement: &'static str,
    },
}

/// What a law's element record and prior are: small values, shared between threads, written
/// to and read from JSON.
pub trait LawData:
    std::fmt::Debug + Clone + Copy + PartialEq + Send + Sync + Serialize + DeserializeOwned
{
}

impl<T> LawData for T where
    T: std::fmt::Debug + Clone + Copy + PartialEq + Send + Sync + Serialize + DeserializeOwned
{
}

/// A hysteresis law of one element, written so that the filter partitions can see which
/// parameters enter linearly:
///
/// `ṙ = g₀(δv, r; φ) + Σ_i θ_i g_i(δv, r; φ)`
///
/// with θ the law's *linear* shape parameters (marginalised by the MLN-RBPF, Storvik and the
/// MPF-EKF2) and φ its *nonlinear* parameters (sampled). `δv` is the element's drift velocity and
/// `r` its hysteretic variable; the element's force is `k r + c δv`. A law is normalised so that
/// `ṙ = δv` at `r = 0` (the initial tangent stiffness of the element is its `k`, which the modal
/// analysis of the linearised chain uses).
///
/// An element's parameters are ordered θ then φ, in the order of [`HysteresisLaw::LINEAR`] and
/// [`HysteresisLaw::NONLINEAR`]; that is their order in the chain's parameter vector.
///
/// The rate methods are generic over [`Real`]: anything without an exact SIMD form (`powf`, a
/// branch on a particle's own value) goes through [`Real::per_lane`], so that lane `b` of a
/// [`core_filters::real::Pack`] evaluation is bit for bit the `f64` evaluation of particle `b`.
pub trait HysteresisLaw:
    std::fmt::Debug + Clone + Copy + Default + PartialEq + Send + Sync + 'static
{
    /// The law's name in messages.
    const NAME: &'static str;
    /// Names of the linear shape parameters θ, in order.
    const LINEAR: &'static [&'static str];
    /// Names of the nonlinear parameters φ, in order.
    const NONLINEAR: &'static [&'static str];
    /// `LINEAR.len()`.
    const NLIN: usize = Self::LINEAR.len();
    /// `NONLINEAR.len()`.
    const NNONLIN: usize = Self::NONLINEAR.len();
    /// Parameters per element, `NLIN + NNONLIN`.
    const NPARAMS: usize = Self::NLIN + Self::NNONLIN;

    /// One element's parameter record (its 0-based storey and its parameter values), as the
    /// truth simulator holds it; its JSON form is the record's serde form.
    type Element: LawData;
    /// The prior of one element's parameters (its 0-based storey and the distributions); its
    /// JSON form is that of a filter configuration's `prior.elements` entries.
    type Prior: LawData;

    /// `g[0] = g₀`, `g[1 + i] = g_i` (`g.len() == 1 + NLIN`).
    fn basis<T: Real>(&self, dv: T, r: T, phi: &[T], g: &mut [T]);

    /// The rate `ṙ` at (θ, φ) (the truth simulator's form).
    fn rate<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> T;

    /// `(∂ṙ/∂δv, ∂ṙ/∂r)` at (θ, φ).
    fn rate_partials<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> (T, T);

    /// [`HysteresisLaw::basis`] into `g` and [`HysteresisLaw::rate_partials`] at one point, for a
    /// caller that needs both (Storvik's linearisation); a law may share their common terms.
    #[inline]
    fn basis_and_partials<T: Real>(
        &self,
        dv: T,
        r: T,
        theta: &[T],
        phi: &[T],
        g: &mut [T],
    ) -> (T, T) {
        self.basis(dv, r, phi, g);
        self.rate_partials(dv, r, theta, phi)
    }

    /// The record of an element at `storey` with parameters `params` (θ then φ, `NPARAMS`
    /// values), not validated.
    fn element(storey: usize, params: &[f64]) -> Self::Element;

    /// 0-based storey of an element.
    fn storey(element: &Self::Element) -> usize;

    /// Writes an element's parameters (θ then φ) into `out` (`NPARAMS` values).
    fn params(element: &Self::Element, out: &mut [f64]);

    /// Checks an element's parameters (finite, inside the law's domain).
    fn validate(element: &Self::Element) -> Result<(), LawError>;

    /// The bound of `|r|` that the element approaches under continued loading, when it has one.
    fn saturation(_element: &Self::Element) -> Option<f64> {
        None
    }

    /// The rate of an element at `(δv, r)`: [`HysteresisLaw::rate`] at its parameters.
    #[inline]
    fn element_rate(&self, element: &Self::Element, dv: f64, r: f64) -> f64 {
        let mut p = [0.0; MAX_PARAMS];
        Self::params(element, &mut p[..Self::NPARAMS]);
        self.rate(dv, r, &p[..Self::NLIN], &p[Self::NLIN..Self::NPARAMS])
    }

    /// The default prior of an element at `storey` (SPEC §3 for Bouc–Wen).
    fn default_prior(storey: usize) -> Self::Prior;

    /// 0-based storey of an element prior.
    fn prior_storey(prior: &Self::Prior) -> usize;

    /// Checks the hyper-parameters; `names` are the element's parameter names in θ (as the
    /// chain writes them, e.g. `n4`), for the messages.
    fn validate_prior(prior: &Self::Prior, names: &[String]) -> Result<(), PriorError>;

    /// Writes one draw of the element's parameters (θ then φ) into `out`.
    fn sample_prior<G: Rng + ?Sized>(prior: &Self::Prior, rng: &mut G, out: &mut [f64]);

    /// Writes one draw of the nonlinear parameters φ alone into `out` (the sampled block of the
    /// marginalised filters at the start).
    fn sample_nonlinear<G: Rng + ?Sized>(prior: &Self::Prior, rng: &mut G, out: &mut [f64]);

    /// The scalar prior of nonlinear parameter `i` (φ order): its support bounds the
    /// rejuvenation move of the sampled static parameters.
    fn nonlinear_prior(prior: &Self::Prior, i: usize) -> &Prior;

    /// Means and variances of the element's parameters (θ then φ; uncorrelated): the Gaussian
    /// moment-matched to the prior, of which the marginalised filters keep the linear ones.
    fn prior_moments(prior: &Self::Prior, mean: &mut [f64], var: &mut [f64]);

    /// Makes parameter `i` (0-based within the element, θ then φ) a point mass at `value`.
    fn fix_prior(prior: &mut Self::Prior, i: usize, value: f64);

    /// Replaces the prior of parameter `i` by the scalar prior `scalar`; `false` when that
    /// parameter's prior is not a scalar one (then nothing changes).
    fn set_prior(prior: &mut Self::Prior, i: usize, scalar: Prior) -> bool;
}

/// Sign with `sgn(0) = 0` (the derivative of `|·|` at its kink taken as 0).
#[inline]
pub(crate) fn sgn(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}
