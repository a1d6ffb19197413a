//! The Kalman filter step functions (SPEC §4) and the one Gaussian measurement update every
//! Gaussian filter of the crate shares (KF, EKF1, EKF2, and the marginalised blocks of the
//! Rao–Blackwellised particle filters).
//!
//! Everything here works on fixed-size `nalgebra` storage and allocates nothing.
//!
//! Numerical policy (SPEC §4): the innovation covariance `L` is factorised by Cholesky and used
//! only through triangular solves (never an explicit inverse); covariances are symmetrised; every
//! repair is counted in [`Health`]; a failure is a typed [`FilterError`], never a panic and never
//! a NaN handed on silently.

use nalgebra::{SMatrix, SVector};

use crate::error::FilterError;
use crate::health::Health;

/// `ln(2π)`.
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// A Cholesky pivot is accepted only if it exceeds this fraction of its own diagonal entry: a
/// smaller pivot is round-off, not information (the matrix is numerically singular).
const PIVOT_REL_TOL: f64 = 16.0 * f64::EPSILON;

/// Relative diagonal jitter tried in turn when the factorisation fails: the diagonal is scaled by
/// `1 + τ`. The largest value bounds the perturbation of the covariance to one part in a million.
const JITTER_STEPS: [f64; 4] = [1e-12, 1e-10, 1e-8, 1e-6];

/// Asymmetry `|a_ij − a_ji|` above this fraction of `sqrt(a_ii a_jj)` (the Cauchy–Schwarz bound of
/// an entry of a covariance) is more than round-off and is counted as a repair.
const ASYMMETRY_REL_TOL: f64 = 1e-9;

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

/// Plain Cholesky factorisation with a relative pivot test; `None` if a pivot is not clearly
/// positive (this also rejects NaN).
fn try_cholesky<const N: usize>(a: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    let mut l = SMatrix::<f64, N, N>::zeros();
    for j in 0..N {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        // Written so that a NaN pivot also fails.
        let clearly_positive = d > 0.0 && d > PIVOT_REL_TOL * a[(j, j)];
        if !clearly_positive {
            return None;
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in (j + 1)..N {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / ljj;
        }
    }
    Some(l)
}

/// Lower Cholesky factor of a covariance with the documented repair (SPEC §4):
///
/// 1. any non-finite entry → `Err(FilterError::NonFinite { step, which })`;
/// 2. the matrix is symmetrised, `(A + Aᵀ)/2`; if the asymmetry exceeded round-off
///    (`|a_ij − a_ji| > 1e-9 sqrt(a_ii a_jj)`), `health.symmetrised` is incremented;
/// 3. Cholesky is tried; a pivot below `16 ε` of its diagonal entry counts as a failure;
/// 4. on failure the diagonal is scaled by `1 + τ`, τ = 1e-12, 1e-10, 1e-8, 1e-6 in turn
///    (`health.jitter_added` is incremented once per factorisation that needed it); a zero or
///    negative diagonal entry receives `τ` times the largest diagonal entry instead;
/// 5. if even τ = 1e-6 fails, `health.cholesky_failures` is incremented and
///    `Err(FilterError::NotPositiveDefinite { step, which })` is returned.
pub fn cholesky_repaired<const N: usize>(
    a: &SMatrix<f64, N, N>,
    step: usize,
    which: &'static str,
    health: &mut Health,
) -> Result<SMatrix<f64, N, N>, FilterError> {
    if a.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite { step, which });
    }
    let mut s = *a;
    let mut asymmetric = false;
    for j in 0..N {
        for i in (j + 1)..N {
            let (aij, aji) = (a[(i, j)], a[(j, i)]);
            if aij != aji {
                let scale = (a[(i, i)] * a[(j, j)]).abs().sqrt();
                if (aij - aji).abs() > ASYMMETRY_REL_TOL * scale {
                    asymmetric = true;
                }
                let mean = 0.5 * (aij + aji);
                s[(i, j)] = mean;
                s[(j, i)] = mean;
            }
        }
    }
    if asymmetric {
        health.symmetrised += 1;
    }
    if let Some(l) = try_cholesky(&s) {
        return Ok(l);
    }
    let max_diag = (0..N).map(|j| s[(j, j)]).fold(0.0_f64, f64::max);
    for tau in JITTER_STEPS {
        let mut jittered = s;
        for j in 0..N {
            let d = s[(j, j)];
            jittered[(j, j)] = if d > 0.0 {
                d * (1.0 + tau)
            } else {
                d + tau * max_diag
            };
        }
        if let Some(l) = try_cholesky(&jittered) {
            health.jitter_added += 1;
            return Ok(l);
        }
    }
    health.cholesky_failures += 1;
    Err(FilterError::NotPositiveDefinite { step, which })
}

/// Solves `L X = B` in place for lower-triangular `L` (forward substitution, column by column).
pub(crate) fn solve_lower_in_place<const N: usize, const C: usize>(
    l: &SMatrix<f64, N, N>,
    b: &mut SMatrix<f64, N, C>,
) {
    for c in 0..C {
        for i in 0..N {
            let mut s = b[(i, c)];
            for k in 0..i {
                s -= l[(i, k)] * b[(k, c)];
            }
            b[(i, c)] = s / l[(i, i)];
        }
    }
}

/// `log N(r; 0, L Lᵀ)` from the residual `r` and the lower factor `L`:
/// `−½ |L⁻¹ r|² − Σ ln L_jj − (N/2) ln 2π`.
pub fn log_normal_density_chol<const N: usize>(
    residual: &SVector<f64, N>,
    chol: &SMatrix<f64, N, N>,
) -> f64 {
    let mut e = *residual;
    solve_lower_in_place(chol, &mut e);
    let log_det_half: f64 = (0..N).map(|j| chol[(j, j)].ln()).sum();
    -0.5 * e.norm_squared() - log_det_half - 0.5 * (N as f64) * LN_2PI
}

/// Replaces `p` by `(p + pᵀ)/2` (round-off only; not counted).
pub(crate) fn symmetrise<const N: usize>(p: &mut SMatrix<f64, N, N>) {
    for j in 0..N {
        for i in (j + 1)..N {
            let mean = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = mean;
            p[(j, i)] = mean;
        }
    }
}

/// `J P Jᵀ` for symmetric `P`, computing the lower triangle only and mirroring it (the result is
/// exactly symmetric and costs 1.5 instead of 2 matrix products). Columns of `Jᵀ` and of `P Jᵀ`
/// are contiguous, so every dot product runs over contiguous memory.
pub(crate) fn sandwich<const N: usize, const M: usize>(
    jac: &SMatrix<f64, M, N>,
    p: &SMatrix<f64, N, N>,
) -> SMatrix<f64, M, M> {
    let jt = jac.transpose();
    let pjt = p * jt;
    let mut out = SMatrix::<f64, M, M>::zeros();
    for j in 0..M {
        let col = pjt.column(j);
        for i in j..M {
            let v = jt.column(i).dot(&col);
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
    }
    out
}

/// KF propagate, SPEC §4: `m ← G m + g`, `P ← G P Gᵀ + Q` (symmetrised).
///
/// Allocation-free and infallible: a non-finite input is not checked here, it is reported as a
/// typed error by the next update (which checks its innovation covariance and residual).
pub fn kf_propagate<const N: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    g: &SMatrix<f64, N, N>,
    offset: &SVector<f64, N>,
    q: &SMatrix<f64, N, N>,
) {
    *m = g * *m + offset;
    *p = sandwich(g, p) + q;
    symmetrise(p);
}

/// The one Gaussian measurement update, SPEC §4. Given the predicted measurement `ŷ`, the
/// Jacobian `J` (NY×N) and the additive covariance `S` (`R`, plus for EKF2 the Hessian term):
///
/// `L = J P Jᵀ + S`, `K = P Jᵀ L⁻¹`, `m ← m + K (y − ŷ)`, `P ← P − K L Kᵀ` (symmetrised).
///
/// With `L = C Cᵀ` (lower Cholesky, [`cholesky_repaired`]) and `W = C⁻¹ J P`, the update is
/// `m ← m + Wᵀ C⁻¹ (y − ŷ)` and `P ← P − Wᵀ W`: two triangular solves, no inverse.
///
/// On error (`NonFinite` for a non-finite residual, innovation covariance or result,
/// `NotPositiveDefinite` if `L` cannot be factorised even after repair) `m` and `p` are left
/// unchanged.
#[allow(clippy::too_many_arguments)]
pub fn gaussian_update<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    y_hat: &SVector<f64, NY>,
    jac: &SMatrix<f64, NY, N>,
    s_add: &SMatrix<f64, NY, NY>,
    step: usize,
    health: &mut Health,
) -> Result<Innovation<NY>, FilterError> {
    let residual = y - y_hat;
    if residual.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "innovation",
        });
    }
    // J P (NY×N); P is symmetric so (J P)ᵀ = P Jᵀ.
    let jp = jac * *p;
    let l_cov = jp * jac.transpose() + s_add;
    let chol = cholesky_repaired(&l_cov, step, "innovation covariance", health)?;
    let mut w = jp;
    solve_lower_in_place(&chol, &mut w);
    let mut e = residual;
    solve_lower_in_place(&chol, &mut e);
    let new_m = *m + w.tr_mul(&e);
    let mut new_p = *p - w.tr_mul(&w);
    symmetrise(&mut new_p);
    if new_m.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "filtered mean",
        });
    }
    if new_p.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            step,
            which: "filtered covariance",
        });
    }
    *m = new_m;
    *p = new_p;
    let log_det_half: f64 = (0..NY).map(|j| chol[(j, j)].ln()).sum();
    let loglik = -0.5 * e.norm_squared() - log_det_half - 0.5 * (NY as f64) * LN_2PI;
    Ok(Innovation {
        residual,
        chol,
        loglik,
    })
}

/// KF update, SPEC §4: `ŷ = H m + h`, then [`gaussian_update`] with `J = H`, `S = R`.
#[allow(clippy::too_many_arguments)]
pub fn kf_update<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    y: &SVector<f64, NY>,
    h_mat: &SMatrix<f64, NY, N>,
    h_off: &SVector<f64, NY>,
    r: &SMatrix<f64, NY, NY>,
    step: usize,
    health: &mut Health,
) -> Result<Innovation<NY>, FilterError> {
    let y_hat = h_mat * *m + h_off;
    gaussian_update(m, p, y, &y_hat, h_mat, r, step, health)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix3, Vector1, Vector2};

    /// Solves `Lᵀ X = B` in place for lower-triangular `L` (back substitution).
    fn solve_lower_transpose_in_place<const N: usize, const C: usize>(
        l: &SMatrix<f64, N, N>,
        b: &mut SMatrix<f64, N, C>,
    ) {
        for c in 0..C {
            for i in (0..N).rev() {
                let mut s = b[(i, c)];
                for k in (i + 1)..N {
                    s -= l[(k, i)] * b[(k, c)];
                }
                b[(i, c)] = s / l[(i, i)];
            }
        }
    }

    #[test]
    fn cholesky_of_spd_matrix_reconstructs_it_without_repair() {
        let a = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let mut h = Health::default();
        let l = cholesky_repaired(&a, 0, "a", &mut h).unwrap();
        assert!((l * l.transpose() - a).abs().max() < 1e-14);
        assert_eq!(l[(0, 1)], 0.0);
        assert_eq!(h, Health::default());
    }

    #[test]
    fn asymmetry_beyond_round_off_is_counted() {
        let a = Matrix2::new(2.0, 0.5, 0.5 + 1e-3, 1.0);
        let mut h = Health::default();
        let l = cholesky_repaired(&a, 3, "a", &mut h).unwrap();
        assert_eq!(h.symmetrised, 1);
        assert!((l * l.transpose())[(1, 0)] - (0.5 + 0.5e-3) < 1e-14);
        // Round-off asymmetry is not counted.
        let b = Matrix2::new(2.0, 0.5, 0.5 * (1.0 + f64::EPSILON), 1.0);
        let mut h = Health::default();
        cholesky_repaired(&b, 3, "b", &mut h).unwrap();
        assert_eq!(h.symmetrised, 0);
    }

    #[test]
    fn negative_definite_matrix_is_a_typed_error() {
        let a = Matrix2::new(1.0, 0.0, 0.0, -1.0);
        let mut h = Health::default();
        let err = cholesky_repaired(&a, 7, "a", &mut h).unwrap_err();
        assert_eq!(
            err,
            FilterError::NotPositiveDefinite {
                step: 7,
                which: "a"
            }
        );
        assert_eq!(h.cholesky_failures, 1);
    }

    #[test]
    fn log_density_matches_scalar_formula() {
        let r = Vector1::new(0.7);
        let l = nalgebra::Matrix1::new(2.0);
        let expected = -0.5 * (0.7_f64 / 2.0).powi(2) - 2.0_f64.ln() - 0.5 * LN_2PI;
        assert!((log_normal_density_chol(&r, &l) - expected).abs() < 1e-15);
    }

    #[test]
    fn triangular_solves_invert_the_factor() {
        let a = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let mut h = Health::default();
        let l = cholesky_repaired(&a, 0, "a", &mut h).unwrap();
        let b = Matrix3::new(1.0, 2.0, 3.0, -1.0, 0.5, 0.0, 2.0, 1.0, -2.0);
        let mut x = b;
        solve_lower_in_place(&l, &mut x);
        solve_lower_transpose_in_place(&l, &mut x);
        assert!((a * x - b).abs().max() < 1e-13);
    }

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
            4,
            &mut h,
        )
        .unwrap_err();
        assert_eq!(err.kind(), "non_finite");
        assert_eq!(m, Vector2::new(1.0, 2.0));
        assert_eq!(p, Matrix2::identity());
    }
}
