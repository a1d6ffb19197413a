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
//! - [`particle`]: particle filters (bootstrap, MLN-RBPF, Storvik, MPF-EKF2) sharing one weight
//!   routine and one resampling kernel;
//! - [`rng`]: reproducible random streams derived from (master seed, run, purpose);
//! - [`health`] and [`error`]: counted repairs and typed failures.

pub mod error;
pub mod health;
pub mod model;
pub mod rng;

pub use error::FilterError;
pub use health::Health;
