//! The scaled unscented transform (Julier 2002; parameters α, β, κ) and a UKF propagate/update
//! pair, kept as a baseline Gaussian filter and for SPEC Table I.
//!
//! Sigma points live on the stack (`2N + 1` points stored as the centre plus two `[_; N]` arrays).
//! Weights: `λ = α²(N + κ) − N`, `W_m⁰ = λ/(N + λ)`, `W_c⁰ = W_m⁰ + 1 − α² + β`,
//! `Wᵢ = 1/(2(N + λ))`; points `m`, `m ± sqrt(N + λ) Sⱼ` with `S Sᵀ = P` (Cholesky).
//!
//! The moments are accumulated around the centre image `f(m)` so that the large, opposite-signed
//! weights of a small α never meet (see [`unscented_transform`]).

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

use super::kf::{Innovation, StepLog};
use crate::error::FilterError;
use crate::linalg::gauss::{cholesky_repaired, solve_lower, whitened_loglik};

/// Lower Cholesky factor of `a` by [`cholesky_repaired`] (repairs counted, failures typed).
fn factor<const N: usize>(
    a: &SMatrix<f64, N, N>,
    which: &'static str,
    log: StepLog<'_>,
) -> Result<SMatrix<f64, N, N>, FilterError> {
    let l = cholesky_repaired(a.as_slice(), N, log.step, which, log.health)?;
    Ok(SMatrix::from_column_slice(&l))
}

/// `(a + aᵀ)/2`: round-off only, not counted.
fn symmetrised<const N: usize>(a: SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    (a + a.transpose()) * 0.5
}

/// Parameters of the scaled unscented transform.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UtParams {
    /// Spread of the sigma points (`0 < α ≤ 1`).
    pub alpha: f64,
    /// Prior knowledge of the distribution (2 is optimal for a Gaussian).
    pub beta: f64,
    /// Secondary scaling.
    pub kappa: f64,
}

impl Default for UtParams {
    fn default() -> Self {
        Self {
            alpha: 1e-3,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

/// Moments of `y = f(x)`, `x ~ N(m, P)`, by the unscented transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UtMoments<const N: usize, const M: usize> {
    /// Approximate `E[y]`.
    pub mean: SVector<f64, M>,
    /// Approximate `Cov[y]`.
    pub cov: SMatrix<f64, M, M>,
    /// Approximate `Cov[x, y]` (N×M).
    pub cross: SMatrix<f64, N, M>,
}

/// Scaled unscented transform of `f` at `N(m, P)`.
///
/// With `eᵢ = f(xᵢ) − f(m)` and `ē = Σᵢ Wᵢ eᵢ` (sum over the `2N` outer points), the usual
/// weighted sums are rewritten exactly as `mean = f(m) + ē`,
/// `cov = Σᵢ Wᵢ eᵢ eᵢᵀ + (β − α²) ē ēᵀ`, `cross = Σⱼ Wⱼ sⱼ (eⱼ⁺ − eⱼ⁻)ᵀ`, which avoids the
/// cancellation of the weights `W⁰ ≈ −1/α²` for small α.
///
/// `P` is factorised by [`cholesky_repaired`] (repairs counted in `log.health`; a failure is an
/// error at `log.step`). `α²(N + κ) ≤ 0` is a programmer error (assert).
#[track_caller]
pub fn unscented_transform<const N: usize, const M: usize, F>(
    m: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
    f: F,
    params: &UtParams,
    log: StepLog<'_>,
) -> Result<UtMoments<N, M>, FilterError>
where
    F: Fn(&SVector<f64, N>) -> SVector<f64, M>,
{
    let spread2 = params.alpha * params.alpha * (N as f64 + params.kappa);
    assert!(
        spread2 > 0.0 && spread2.is_finite(),
        "unscented transform needs α²(N + κ) > 0, got {spread2}"
    );
    let step = log.step;
    let chol = factor(p, "unscented transform covariance", log)?;
    let scale = spread2.sqrt();
    let w = 0.5 / spread2;
    let y0 = f(m);
    let mut e_plus = [SVector::<f64, M>::zeros(); N];
    let mut e_minus = [SVector::<f64, M>::zeros(); N];
    let mut e_bar = SVector::<f64, M>::zeros();
    for j in 0..N {
        let s = chol.column(j) * scale;
        e_plus[j] = f(&(m + s)) - y0;
        e_minus[j] = f(&(m - s)) - y0;
        e_bar += (e_plus[j] + e_minus[j]) * w;
    }
    let mut cov = e_bar * e_bar.transpose() * (params.beta - params.alpha * params.alpha);
    let mut cross = SMatrix::<f64, N, M>::zeros();
    for j in 0..N {
        cov += (e_plus[j] * e_plus[j].transpose() + e_minus[j] * e_minus[j].transpose()) * w;
        let s = chol.column(j) * scale;
        cross += s * (e_plus[j] - e_minus[j]).transpose() * w;
    }
    let out = UtMoments {
        mean: y0 + e_bar,
        cov: symmetrised(cov),
        cross,
    };
    if out
        .mean
        .iter()
        .chain(out.cov.iter())
        .any(|v| !v.is_finite())
    {
        return Err(FilterError::NonFinite {
            step,
            which: "unscented transform moments",
        });
    }
    Ok(out)
}

/// UKF propagate: `(m, P) ← UT(φ) + (0, Q)`. On error `m` and `p` are unchanged.
pub fn ukf_propagate<const N: usize, F>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    phi: F,
    q: &SMatrix<f64, N, N>,
    params: &UtParams,
    log: StepLog<'_>,
) -> Result<(), FilterError>
where
    F: Fn(&SVector<f64, N>) -> SVector<f64, N>,
{
    let ut = unscented_transform(m, p, phi, params, log)?;
    *m = ut.mean;
    *p = ut.cov + q;
    Ok(())
}

/// UKF update with `y = ψ(x) + η`, `η ~ N(0, R)`: `ŷ`, `S_yy`, `C_xy` by the UT,
/// `L = S_yy + R`, `K = C_xy L⁻¹` (Cholesky solves), `m ← m + K (y − ŷ)`, `P ← P − K L Kᵀ`.
/// On error `m` and `p` are unchanged.
pub fn ukf_update<const N: usize, const NY: usize, F>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    psi: F,
    r: &SMatrix<f64, NY, NY>,
    params: &UtParams,
    mut log: StepLog<'_>,
) -> Result<Innovation<NY>, FilterError>
where
    F: Fn(&SVector<f64, N>) -> SVector<f64, NY>,
{
    let step = log.step;
    let ut = unscented_transform(m, p, psi, params, log.reborrow())?;
    let residual = y - ut.mean;
    if residual.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "innovation",
        });
    }
    let chol = factor(&(ut.cov + r), "innovation covariance", log)?;
    // W = C⁻¹ C_xyᵀ, so K L Kᵀ = Wᵀ W and K r = Wᵀ C⁻¹ r.
    let mut wm = ut.cross.transpose();
    for column in wm.as_mut_slice().chunks_exact_mut(NY) {
        solve_lower(chol.as_slice(), NY, column);
    }
    let mut e = residual;
    solve_lower(chol.as_slice(), NY, e.as_mut_slice());
    let new_m = *m + wm.tr_mul(&e);
    let new_p = symmetrised(*p - wm.tr_mul(&wm));
    if new_m.iter().chain(new_p.iter()).any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "filtered moments",
        });
    }
    *m = new_m;
    *p = new_p;
    Ok(Innovation {
        residual,
        chol,
        loglik: whitened_loglik(e.as_slice(), chol.as_slice(), NY),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::health::Health;
    use nalgebra::{Matrix2, Vector1, Vector2};

    #[test]
    fn linear_map_moments_are_exact_for_any_alpha() {
        let m = Vector2::new(0.3, -1.0);
        let p = Matrix2::new(2.0, 0.3, 0.3, 0.5);
        let a = nalgebra::Matrix1x2::new(1.5, -2.0);
        for alpha in [1e-3, 0.5, 1.0] {
            let params = UtParams {
                alpha,
                beta: 2.0,
                kappa: 0.0,
            };
            let mut h = Health::default();
            let log = StepLog {
                step: 0,
                health: &mut h,
            };
            let ut = unscented_transform(&m, &p, |x| a * x, &params, log).unwrap();
            // Rounding of the sigma points `m ± s` (ε |m|) is amplified by the weights 1/(2α²N)
            // in the mean: allow 64 ε ‖a‖₁ max|m| / α².
            let tol = 64.0 * f64::EPSILON * 3.5 * 1.0 / (alpha * alpha);
            assert!((ut.mean - a * m).abs().max() < tol);
            assert!((ut.cov - a * p * a.transpose()).abs().max() < 1e-9);
            assert!((ut.cross - p * a.transpose()).abs().max() < 1e-9);
        }
    }

    #[test]
    fn ukf_update_on_linear_measurement_equals_kf() {
        let m0 = Vector2::new(0.3, -1.0);
        let p0 = Matrix2::new(2.0, 0.3, 0.3, 0.5);
        let hm = nalgebra::Matrix1x2::new(1.0, 2.0);
        let r = nalgebra::Matrix1::new(0.4);
        let y = Vector1::new(0.9);
        let (mut m1, mut p1) = (m0, p0);
        let mut h = Health::default();
        let i1 = ukf_update(
            &mut m1,
            &mut p1,
            &y,
            |x| hm * x,
            &r,
            &UtParams::default(),
            StepLog {
                step: 1,
                health: &mut h,
            },
        )
        .unwrap();
        let (mut m2, mut p2) = (m0, p0);
        let log = StepLog {
            step: 1,
            health: &mut h,
        };
        let i2 = crate::kalman::kf_update(&mut m2, &mut p2, &y, &hm, &Vector1::zeros(), &r, log)
            .unwrap();
        assert!((m1 - m2).abs().max() < 1e-8);
        assert!((p1 - p2).abs().max() < 1e-8);
        assert!((i1.loglik - i2.loglik).abs() < 1e-8);
    }
}
