//! Gaussian algebra on run-time dimensions for the particle filters, generic over [`crate::real::Real`]
//! (one particle, or a pack of particles in SIMD lanes).
//!
//! - [`sparse`]: Jacobians by their structural non-zeros, recorded from the model;
//! - [`gauss`]: Cholesky factors (definite, semidefinite, with the documented repair), the one
//!   Gaussian measurement update (SPEC §4) and log-densities;
//! - [`second_order`]: EKF2 Hessian terms from sparse constant Hessians;
//! - [`propagate`]: the EKF2 propagate for a near-identity Jacobian;
//! - [`pack`]: gather and scatter between particles and pack lanes;
//! - [`support`]: moment-matched truncation of a Gaussian to its physical support.
//!
//! Everything works in caller-owned buffers and allocates nothing after set-up.

pub mod gauss;
pub mod pack;
pub mod propagate;
pub mod second_order;
pub mod sparse;
pub mod support;

pub use gauss::Factor;
pub(crate) use gauss::FactoredNoise;
pub use propagate::{ekf2_propagate_near_identity, PropagateScratch, Propagation, SymEntries};
pub use second_order::SecondOrder;
pub use sparse::Sparse;
pub use support::{truncate_below, LowerBound};
