//! Gaussian filter steps (SPEC §4) on small fixed-size `nalgebra` matrices: pure step functions
//! plus a small whole-data-set driver (STYLE: "the Kalman module is pure step functions"). They
//! are thin functions on the one Gaussian algebra of the crate, [`crate::linalg`]; they serve
//! Table I and the exactness tests the particle filters are checked against.
//!
//! - [`kf`]: [`kf_propagate`], [`kf_update`] and the one [`gaussian_update`] (the [`Innovation`]
//!   it returns), and the [`StepLog`] (time step and [`crate::Health`]) every fallible step
//!   reports to;
//! - [`ekf2`]: [`ekf2_propagate`], [`ekf2_update`], [`ekf2_moments`] on a map's second-order
//!   [`Expansion`] at the mean (EKF1 = empty Hessians), with the Hessian terms of
//!   [`crate::linalg::SecondOrder`];
//! - [`ukf`]: the scaled unscented transform and a UKF propagate/update pair (baseline);
//! - [`linear`]: a linear-Gaussian model and the exact [`kalman_filter`] driver;
//! - [`table1`](mod@table1): SPEC Table I by computation.

pub mod ekf2;
pub mod kf;
pub mod linear;
pub mod table1;
pub mod ukf;

pub use ekf2::{ekf2_moments, ekf2_propagate, ekf2_update, second_order_terms, Expansion};
pub use kf::{gaussian_update, kf_propagate, kf_update, Innovation, StepLog};
pub use linear::{kalman_filter, KalmanRun, LinearGaussian};
pub use table1::{table1, table1_rows, Table1Row};
pub use ukf::{ukf_propagate, ukf_update, unscented_transform, UtMoments, UtParams};
