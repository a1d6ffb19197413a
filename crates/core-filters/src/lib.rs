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
//! - [`model`]: capability traits a model implements (what laws it states);
//! - [`kalman`]: Gaussian filter steps (KF, EKF, EKF2, UKF) on fixed-size storage;
//! - [`weights`] and [`resampling`]: the one log-domain weight routine and the resampling
//!   schemes over one inverse-CDF kernel, shared by every particle filter;
//! - [`particle`]: particle filters (bootstrap, MLN-RBPF, Storvik, MPF-EKF2), the
//!   [`particle::ParticleFilter`] trait, the generic runner and its observers;
//! - [`rng`]: reproducible random streams derived from (master seed, run, purpose);
//! - [`health`] and [`error`]: counted repairs and typed failures.

pub mod credible;
pub mod error;
pub mod health;
pub mod kalman;
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
