//! A time-invariant linear-Gaussian state-space model and a whole-data-set Kalman filter driver
//! (SPEC §4). It is the exact reference against which particle filters are tested: for this
//! model the KF log-likelihood and filtered moments are exact.

use nalgebra::{SMatrix, SVector};

use super::kf::{kf_propagate, kf_update, StepLog};
use crate::error::FilterError;
use crate::health::Health;

/// `z_k = G z_{k−1} + g + v`, `v ~ N(0, Q)`; `y_k = H z_k + h + η`, `η ~ N(0, R)`;
/// `z_0 ~ N(m0, P0)` (SPEC §4).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGaussian<const N: usize, const NY: usize> {
    /// Transition matrix `G`.
    pub g_mat: SMatrix<f64, N, N>,
    /// Transition offset `g`.
    pub g_off: SVector<f64, N>,
    /// Measurement matrix `H`.
    pub h_mat: SMatrix<f64, NY, N>,
    /// Measurement offset `h`.
    pub h_off: SVector<f64, NY>,
    /// Process noise covariance `Q`.
    pub q: SMatrix<f64, N, N>,
    /// Measurement noise covariance `R`.
    pub r: SMatrix<f64, NY, NY>,
    /// Prior mean of `z_0`.
    pub m0: SVector<f64, N>,
    /// Prior covariance of `z_0`.
    pub p0: SMatrix<f64, N, N>,
}

/// Result of [`kalman_filter`] over a whole data set.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanRun<const N: usize> {
    /// `log p(y_1:T)`.
    pub loglik: f64,
    /// `log p(y_k | y_1:k−1)` for k = 1..T (index k−1).
    pub loglik_increments: Vec<f64>,
    /// Filtered means `E[z_k | y_1:k]` for k = 1..T (index k−1).
    pub means: Vec<SVector<f64, N>>,
    /// Filtered covariances `Cov[z_k | y_1:k]` for k = 1..T (index k−1).
    pub covs: Vec<SMatrix<f64, N, N>>,
    /// Repairs made during the run.
    pub health: Health,
}

/// Runs the KF over `ys` (`ys[0]` is `y_1`; step `k` propagates from `k−1` then updates with
/// `y_k`), SPEC §4. A failure of any step ends the run with its typed error.
pub fn kalman_filter<const N: usize, const NY: usize>(
    model: &LinearGaussian<N, NY>,
    ys: &[SVector<f64, NY>],
) -> Result<KalmanRun<N>, FilterError> {
    let mut m = model.m0;
    let mut p = model.p0;
    let mut health = Health::default();
    let mut run = KalmanRun {
        loglik: 0.0,
        loglik_increments: Vec::with_capacity(ys.len()),
        means: Vec::with_capacity(ys.len()),
        covs: Vec::with_capacity(ys.len()),
        health,
    };
    for (idx, y) in ys.iter().enumerate() {
        let k = idx + 1;
        kf_propagate(&mut m, &mut p, &model.g_mat, &model.g_off, &model.q);
        let inn = kf_update(
            &mut m,
            &mut p,
            y,
            &model.h_mat,
            &model.h_off,
            &model.r,
            StepLog {
                step: k,
                health: &mut health,
            },
        )?;
        run.loglik += inn.loglik;
        run.loglik_increments.push(inn.loglik);
        run.means.push(m);
        run.covs.push(p);
    }
    run.health = health;
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix1, Vector1};

    #[test]
    fn static_scalar_with_no_noise_recovers_sample_mean() {
        // z static with flat-ish prior: the filtered mean tends to the sample mean of y.
        let model = LinearGaussian::<1, 1> {
            g_mat: Matrix1::new(1.0),
            g_off: Vector1::zeros(),
            h_mat: Matrix1::new(1.0),
            h_off: Vector1::zeros(),
            q: Matrix1::zeros(),
            r: Matrix1::new(1.0),
            m0: Vector1::zeros(),
            p0: Matrix1::new(1e12),
        };
        let ys: Vec<_> = [1.0, 2.0, 4.0, 5.0]
            .iter()
            .map(|&v| Vector1::new(v))
            .collect();
        let run = kalman_filter(&model, &ys).unwrap();
        assert!((run.means[3][0] - 3.0).abs() < 1e-9);
        assert!((run.covs[3][(0, 0)] - 0.25).abs() < 1e-9);
        assert_eq!(run.means.len(), 4);
        let sum: f64 = run.loglik_increments.iter().sum();
        assert!((sum - run.loglik).abs() < 1e-12);
    }
}
