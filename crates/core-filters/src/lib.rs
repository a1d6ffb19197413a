//! # core-filters
//!
//! Kalman-type and particle filters for online Bayesian identification of structures.
//! This crate holds algorithms only: no file or terminal I/O.
//!
//! Notation follows the project SPEC: `k` is the time step, `i` the particle, `Np` the number
//! of particles, `N(a; m, C)` the Gaussian density. Step `k` propagates from `t_{k-1}` to `t_k`
//! with the input at `k-1`; the measurement `y_k` is evaluated with the input at `k`.
//!
//! Layers (kept apart on purpose):
//! - [`model`]: what every model and filter shares (slots, layout, sparse Hessians);
//! - [`linalg`]: the one Gaussian algebra (Cholesky with its documented repair, the measurement
//!   update, EKF2 Hessian terms), on run-time dimensions, for one particle or a SIMD pack;
//! - [`kalman`]: Gaussian filter steps (KF, EKF, EKF2, UKF) as thin functions on [`linalg`],
//!   for Table I and the exactness tests;
//! - [`weights`] and [`resampling`]: the one log-domain weight routine and the resampling
//!   schemes over one inverse-CDF kernel, shared by every particle filter;
//! - [`smc`]: the capability traits a model implements ([`smc::model`]), particle filters
//!   (bootstrap, MLN-RBPF, Storvik, MPF-EKF2), the [`smc::Filter`] adapter trait, the generic
//!   runner and its observers;
//! - [`credible`] and [`pmmh`]: credible intervals and the reference posterior by particle
//!   marginal Metropolis–Hastings;
//! - [`laplace`]: the mode and Gaussian approximation of a smooth log-density from its values
//!   (the information limit of a linear record);
//! - [`real`]: one particle (`f64`) or a pack of particles in SIMD lanes behind one type;
//! - [`rng`]: reproducible random streams derived from (master seed, run, purpose);
//! - [`health`] and [`error`]: counted repairs and typed failures.

pub mod credible;
pub mod error;
pub mod health;
pub mod kalman;
pub mod laplace;
pub mod linalg;
pub mod model;
pub mod pmmh;
pub mod real;
pub mod resampling;
pub mod rng;
pub mod smc;
pub mod weights;

pub use error::FilterError;
pub use health::Health;
