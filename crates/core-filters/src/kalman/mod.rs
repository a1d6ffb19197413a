//! Gaussian filter steps (SPEC §4): pure step functions on fixed-size `nalgebra` storage plus a
//! small whole-data-set driver (STYLE: "the Kalman module is pure step functions").
//!
//! - [`kf`]: [`kf_propagate`], [`kf_update`] and the one [`gaussian_update`] every filter uses,
//!   with [`cholesky_repaired`] (documented, counted repair), [`UpdateFactor`] (the gain side of
//!   an update, shared with the marginalised particle filters), [`log_normal_density_chol`] and
//!   [`FactoredCov`] (a constant noise factorised once);
//! - [`second_order`]: EKF2 Hessian terms from sparse constant Hessians;
//! - [`ekf2`]: [`ekf2_propagate`], [`ekf2_update`], [`ekf2_moments`] (EKF1 = empty Hessians);
//! - [`ukf`]: the scaled unscented transform and a UKF propagate/update pair (baseline);
//! - [`linear`]: a linear-Gaussian model and the exact [`kalman_filter`] driver;
//! - [`table1`]: SPEC Table I by computation;
//! - [`lanes`]: the Gaussian update of four problems at once in SIMD lanes, bit for bit the
//!   scalar one.

pub mod ekf2;
pub mod kf;
pub mod linear;
pub mod second_order;
pub mod table1;
pub mod ukf;

pub use ekf2::{ekf2_moments, ekf2_propagate, ekf2_update};
pub use kf::{
    cholesky_repaired, gaussian_update, kf_propagate, kf_update, log_normal_density_chol,
    FactoredCov, Innovation, UpdateFactor,
};
pub use linear::{kalman_filter, KalmanRun, LinearGaussian};
pub use second_order::second_order_terms;
pub use table1::{table1, table1_rows, Table1Row};
pub use ukf::{ukf_propagate, ukf_update, unscented_transform, UtMoments, UtParams};
