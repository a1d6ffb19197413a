//! The Kalman filter steps (SPEC §4) on small fixed-size `nalgebra` matrices, as thin functions
//! on the one Gaussian algebra of the crate ([`crate::linalg::gauss`]): the matrices are handed
//! over as column-major slices and their Jacobians as their non-zero entries, so these steps and
//! the particle filters' marginalised blocks run the same code.
//!
//! Numerical policy (SPEC §4): the innovation covariance `L` is factorised by Cholesky and used
//! only through triangular solves (never an explicit inverse); covariances are exactly symmetric
//! by construction; every repair is counted in [`Health`]; a failure is a typed [`FilterError`],
//! never a panic and never a NaN handed on silently.

use nalgebra::{SMatrix, SVector};

use crate::error::FilterError;
use crate::health::Health;
use crate::linalg::gauss::{factorise, innovation_cov, pjt, Factor};
use crate::linalg::Sparse;

/// Output of a measurement update (STYLE lesson 6): what metrics and tests need, without
/// recomputation.
#[derive(Debug, Clone, Copy)]
pub struct Innovation<const NY: usize> {
    /// `y − ŷ`.
    pub residual: SVector<f64, NY>,
    /// Lower Cholesky factor of `L`, the innovation covariance actually used (after any repair).
    pub chol: SMatrix<f64, NY, NY>,
    /// `log N(y; ŷ, L)`.
    pub loglik: f64,
}

/// Where a step reports to: its time index `k` (carried by every [`FilterError`] it returns) and
/// the [`Health`] counters its repairs are added to. Handed by value to each step function;
/// `StepLog::reborrow` lends it to a sub-step.
#[derive(Debug)]
pub struct StepLog<'a> {
    /// The time step `k`.
    pub step: usize,
    /// Repair counters of the run.
    pub health: &'a mut Health,
}

impl StepLog<'_> {
    /// The same log for a shorter borrow, so that one step can hand it to several sub-steps.
    pub(crate) fn reborrow(&mut self) -> StepLog<'_> {
        StepLog {
            step: self.step,
            health: self.health,
        }
    }
}

/// The non-zero entries of `J`, the form in which [`crate::linalg`] takes a Jacobian.
fn entries<const R: usize, const C: usize>(jac: &SMatrix<f64, R, C>) -> Sparse<f64> {
    Sparse::nonzeros_of(jac.as_slice(), R, C)
}

/// `J P Jᵀ + S` for symmetric `P`: the lower triangle over the non-zeros of `J`, `S`'s lower
/// triangle added, then mirrored, so the result is exactly symmetric.
pub(crate) fn sandwich_plus<const N: usize, const M: usize>(
    jac: &SMatrix<f64, M, N>,
    p: &SMatrix<f64, N, N>,
    s_add: &SMatrix<f64, M, M>,
) -> SMatrix<f64, M, M> {
    let j = entries(jac);
    let mut p_jt = vec![0.0; N * M];
    pjt(&j, p.as_slice(), N, &mut p_jt);
    let mut out = SMatrix::<f64, M, M>::zeros();
    innovation_cov(&j, &p_jt, N, s_add.as_slice(), out.as_mut_slice());
    out
}

/// KF propagate, SPEC §4: `m ← G m + g`, `P ← G P Gᵀ + Q` (exactly symmetric).
///
/// Infallible: a non-finite input is not checked here, it is reported as a typed error by the
/// next update (which checks its innovation covariance and residual).
pub fn kf_propagate<const N: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    g: &SMatrix<f64, N, N>,
    offset: &SVector<f64, N>,
    q: &SMatrix<f64, N, N>,
) {
    *m = g * *m + offset;
    *p = sandwich_plus(g, p, q);
}

/// The one Gaussian measurement update, SPEC §4. Given the predicted measurement `ŷ`, the
/// Jacobian `J` (NY×N) and the additive covariance `S` (`R`, plus for EKF2 the Hessian term):
///
/// `L = J P Jᵀ + S`, `K = P Jᵀ L⁻¹`, `m ← m + K (y − ŷ)`, `P ← P − K L Kᵀ`,
///
/// computed by [`Factor`] (whitened gain, no inverse) with the documented repair of
/// [`factorise`]. On error (`NonFinite` for a non-finite residual, innovation covariance or
/// result, `NotPositiveDefinite` if `L` cannot be factorised even after repair) `m` and `p` are
/// left unchanged; the error carries `log.step` and repairs are counted in `log.health`.
pub fn gaussian_update<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    y_hat: &SVector<f64, NY>,
    jac: &SMatrix<f64, NY, N>,
    s_add: &SMatrix<f64, NY, NY>,
    log: StepLog<'_>,
) -> Result<Innovation<NY>, FilterError> {
    let StepLog { step, health } = log;
    let residual = y - y_hat;
    if residual.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "innovation",
        });
    }
    let mut factor = Factor::new(N, NY);
    if !factorise(
        &mut factor,
        p.as_slice(),
        &entries(jac),
        s_add.as_slice(),
        health,
    ) {
        let which = "innovation covariance";
        return Err(if factor.cov.iter().all(|v| v.is_finite()) {
            FilterError::NotPositiveDefinite { step, which }
        } else {
            FilterError::NonFinite { step, which }
        });
    }
    // Updated on copies: the caller's moments stay as they were if the result is not finite.
    let (mut m_new, mut p_new) = (*m, *p);
    let (loglik, ok) = factor.update(
        m_new.as_mut_slice(),
        p_new.as_mut_slice(),
        residual.as_slice(),
    );
    if !ok {
        return Err(FilterError::NonFinite {
            step,
            which: "filtered moments",
        });
    }
    *m = m_new;
    *p = p_new;
    Ok(Innovation {
        residual,
        chol: SMatrix::from_column_slice(&factor.chol),
        loglik,
    })
}

/// KF update, SPEC §4: `ŷ = H m + h`, then [`gaussian_update`] with `J = H`, `S = R`.
pub fn kf_update<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    h_mat: &SMatrix<f64, NY, N>,
    h_off: &SVector<f64, NY>,
    r: &SMatrix<f64, NY, NY>,
    log: StepLog<'_>,
) -> Result<Innovation<NY>, FilterError> {
    let y_hat = h_mat * *m + h_off;
    gaussian_update(m, p, y, &y_hat, h_mat, r, log)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix3, Vector1, Vector2};

    #[test]
    fn update_leaves_state_untouched_on_error() {
        let mut m = Vector2::new(1.0, 2.0);
        let mut p = Matrix2::identity();
        let mut h = Health::default();
        let y = Vector1::new(f64::NAN);
        let hm = nalgebra::Matrix1x2::new(1.0, 0.0);
        let err = kf_update(
            &mut m,
            &mut p,
            &y,
            &hm,
            &Vector1::zeros(),
            &nalgebra::Matrix1::new(1.0),
            StepLog {
                step: 4,
                health: &mut h,
            },
        )
        .unwrap_err();
        assert_eq!(err.kind(), "non_finite");
        assert_eq!(m, Vector2::new(1.0, 2.0));
        assert_eq!(p, Matrix2::identity());
    }

    #[test]
    fn innovation_covariance_is_exactly_symmetric_and_matches_the_dense_product() {
        let p = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let jac = nalgebra::Matrix2x3::new(0.3, 0.0, -1.7, 0.0, 2.1, 0.4);
        let s = Matrix2::new(0.5, 0.1, 0.1, 0.7);
        let l = sandwich_plus(&jac, &p, &s);
        assert_eq!(l[(0, 1)], l[(1, 0)]);
        assert!((l - (jac * p * jac.transpose() + s)).abs().max() < 1e-13);
    }

    /// The update against the textbook gain `K = P Jᵀ L⁻¹` with an explicit inverse.
    #[test]
    fn update_equals_the_textbook_gain() {
        let p0 = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let m0 = nalgebra::Vector3::new(1.0, -2.0, 0.5);
        let jac = nalgebra::Matrix2x3::new(0.3, 0.0, -1.7, 0.0, 2.1, 0.4);
        let s = Matrix2::new(0.5, 0.1, 0.1, 0.7);
        let y_hat = jac * m0;
        let y = Vector2::new(0.8, -1.3);
        let mut h = Health::default();
        let (mut m1, mut p1) = (m0, p0);
        let inn = gaussian_update(
            &mut m1,
            &mut p1,
            &y,
            &y_hat,
            &jac,
            &s,
            StepLog {
                step: 0,
                health: &mut h,
            },
        )
        .unwrap();
        let l = jac * p0 * jac.transpose() + s;
        let k = p0 * jac.transpose() * l.try_inverse().unwrap();
        assert!((m1 - (m0 + k * (y - y_hat))).abs().max() < 1e-12);
        assert!((p1 - (p0 - k * l * k.transpose())).abs().max() < 1e-12);
        assert_eq!(p1, p1.transpose());
        assert!((inn.chol * inn.chol.transpose() - l).abs().max() < 1e-13);
        let r = y - y_hat;
        let textbook = -0.5 * (r.transpose() * l.try_inverse().unwrap() * r)[0]
            - 0.5 * l.determinant().ln()
            - (2.0 * std::f64::consts::PI).ln();
        assert!((inn.loglik - textbook).abs() < 1e-12);
        assert_eq!(h, Health::default());
    }
}
