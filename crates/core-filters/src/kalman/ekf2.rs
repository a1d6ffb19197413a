//! Second-order extended Kalman filter steps (EKF2, SPEC §4); EKF1 is the special case of empty
//! Hessians. The caller evaluates the map and its Jacobian at the current mean (the model knows
//! how); the constant Hessians come as sparse entry lists ([`SparseHessians`]). The three are
//! handed over together as the map's [`Expansion`] at the mean.
//!
//! For a map that is at most quadratic in the state (the MPF-EKF2 partition of SPEC §5.4, §6),
//! these moments are exact.

use nalgebra::{SMatrix, SVector};

use super::kf::{gaussian_update, sandwich_plus, Innovation, StepLog};
use crate::error::FilterError;
use crate::linalg::SecondOrder;
use crate::model::SparseHessians;

/// The second-order expansion of a map `f: ℝᴺ → ℝ^NO` at the current mean `m`, as the EKF2 steps
/// use it: `f(x) ≈ f(m) + J (x − m) + ½ Σ_i e_i (x − m)ᵀ 𝓗ⁱ (x − m)`.
#[derive(Debug, Clone, Copy)]
pub struct Expansion<'a, const N: usize, const NO: usize> {
    /// `f(m)`.
    pub value: SVector<f64, NO>,
    /// The Jacobian `J = ∂f/∂x` at `m` (NO×N).
    pub jac: SMatrix<f64, NO, N>,
    /// The (constant) Hessians `𝓗ⁱ` as a sparse entry list; empty for EKF1.
    pub hess: &'a SparseHessians,
}

/// The EKF2 terms `½ tr(𝓗ⁱ P)` (a vector over the `NO` outputs) and `½ tr(𝓗ⁱ P 𝓗^{i'} P)`
/// (`NO × NO`) by [`SecondOrder`], which computes them for the outputs that have Hessian entries
/// only; the others are zero.
#[track_caller]
pub fn second_order_terms<const N: usize, const NO: usize>(
    hess: &SparseHessians,
    p: &SMatrix<f64, N, N>,
) -> (SVector<f64, NO>, SMatrix<f64, NO, NO>) {
    let so = SecondOrder::new(hess, N, NO);
    let k = so.len();
    let (mut mean_k, mut cov_k) = (vec![0.0; k], vec![0.0; k * k]);
    so.terms(p.as_slice(), N, &mut mean_k, &mut cov_k);
    let mut mean = SVector::<f64, NO>::zeros();
    let mut cov = SMatrix::<f64, NO, NO>::zeros();
    for g in 0..k {
        mean[so.output(g)] = mean_k[g];
        for h in 0..k {
            cov[(so.output(g), so.output(h))] = cov_k[g + h * k];
        }
    }
    (mean, cov)
}

/// EKF2 propagate, SPEC §4 (EKF1 when `phi.hess` is empty):
/// `m ← φ(m) + ½ Σ_i e_i tr(𝓗ⁱ P)`, `P ← J P Jᵀ + ½ Σ_{i,i'} e_i e_{i'}ᵀ tr(𝓗ⁱ P 𝓗^{i'} P) + Q`.
///
/// `phi` is the expansion of φ at the current `m` (`value` = φ(m), `jac` = ∂φ/∂x); the Hessian
/// terms use the current `P`. Like [`super::kf_propagate`] it does not check for non-finite
/// input: the next update does.
pub fn ekf2_propagate<const N: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    phi: &Expansion<'_, N, N>,
    q: &SMatrix<f64, N, N>,
) {
    let mut new_p = sandwich_plus(&phi.jac, p, q);
    *m = phi.value;
    if !phi.hess.is_empty() {
        let (mean2, cov2) = second_order_terms(phi.hess, p);
        *m += mean2;
        new_p += cov2;
    }
    *p = new_p;
}

/// EKF2 predicted moments of a measurement (or of any map ψ of the Gaussian `N(m, P)`) without
/// updating, SPEC §4 and §5.4 (a), (d):
/// `ŷ = ψ(m) + ½ Σ_i e_i tr(𝓗ⁱ P)` and `L = J P Jᵀ + ½ Σ_{i,i'} e_i e_{i'}ᵀ tr(𝓗ⁱ P 𝓗^{i'} P) + S`.
///
/// `psi` is the expansion of ψ at `m` (`value` = ψ(m), `jac` = ∂ψ/∂x), `s_add` the additive
/// noise covariance.
pub fn ekf2_moments<const N: usize, const NY: usize>(
    p: &SMatrix<f64, N, N>,
    psi: &Expansion<'_, N, NY>,
    s_add: &SMatrix<f64, NY, NY>,
) -> (SVector<f64, NY>, SMatrix<f64, NY, NY>) {
    let mut cov = sandwich_plus(&psi.jac, p, s_add);
    let mut mean = psi.value;
    if !psi.hess.is_empty() {
        let (mean2, cov2) = second_order_terms(psi.hess, p);
        mean += mean2;
        cov += cov2;
    }
    (mean, cov)
}

/// EKF2 update, SPEC §4: `ŷ = ψ(m) + ½ tr(𝓗ⁱ P)`,
/// `L = J P Jᵀ + ½ tr(𝓗ⁱ P 𝓗^{i'} P) + R`, then as [`gaussian_update`] (whose additive covariance
/// is `R` plus the Hessian term). `psi` is the expansion of ψ at the current `m` (`value` = ψ(m),
/// `jac` = ∂ψ/∂x).
pub fn ekf2_update<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    psi: &Expansion<'_, N, NY>,
    r: &SMatrix<f64, NY, NY>,
    log: StepLog<'_>,
) -> Result<Innovation<NY>, FilterError> {
    if psi.hess.is_empty() {
        return gaussian_update(m, p, y, &psi.value, &psi.jac, r, log);
    }
    let (mean2, cov2) = second_order_terms(psi.hess, p);
    let y_hat = psi.value + mean2;
    let s_add = cov2 + r;
    gaussian_update(m, p, y, &y_hat, &psi.jac, &s_add, log)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};

    /// z = x0 x1 with x ~ N(μ, P): exact mean μ0 μ1 + P01 and exact variance
    /// μ1² P00 + μ0² P11 + 2 μ0 μ1 P01 + P00 P11 + P01² (Isserlis).
    #[test]
    fn bilinear_moments_are_exact() {
        let mu = Vector2::new(0.7, -1.3);
        let p = Matrix2::new(0.5, 0.2, 0.2, 0.8);
        let mut h = SparseHessians::new();
        h.push(0, 0, 1, 1.0);
        let value = Vector1::new(mu[0] * mu[1]);
        let jac = Matrix1x2::new(mu[1], mu[0]);
        let psi = Expansion {
            value,
            jac,
            hess: &h,
        };
        let (mean, cov) = ekf2_moments(&p, &psi, &Matrix1::zeros());
        let exact_mean = mu[0] * mu[1] + p[(0, 1)];
        let exact_var = mu[1].powi(2) * p[(0, 0)]
            + mu[0].powi(2) * p[(1, 1)]
            + 2.0 * mu[0] * mu[1] * p[(0, 1)]
            + p[(0, 0)] * p[(1, 1)]
            + p[(0, 1)].powi(2);
        assert!((mean[0] - exact_mean).abs() < 1e-14);
        assert!((cov[(0, 0)] - exact_var).abs() < 1e-14);
    }

    #[test]
    fn propagate_without_hessians_is_linearisation() {
        let mut m = Vector2::new(1.0, 2.0);
        let mut p = Matrix2::new(1.0, 0.1, 0.1, 2.0);
        let jac = Matrix2::new(1.0, 0.5, 0.0, 1.0);
        let value = Vector2::new(3.0, 4.0);
        let q = Matrix2::identity() * 0.01;
        let expected_p = jac * p * jac.transpose() + q;
        let phi = Expansion {
            value,
            jac,
            hess: &SparseHessians::new(),
        };
        ekf2_propagate(&mut m, &mut p, &phi, &q);
        assert_eq!(m, value);
        assert!((p - expected_p).abs().max() < 1e-15);
    }
}
