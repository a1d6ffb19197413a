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
pub(crate) const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// A Cholesky pivot is accepted only if it exceeds this fraction of its own diagonal entry: a
/// smaller pivot is round-off, not information (the matrix is numerically singular).
pub(crate) const PIVOT_REL_TOL: f64 = 16.0 * f64::EPSILON;

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

/// Whether every entry is finite. `v − v` is `+0` for a finite `v` and NaN for ±∞ or NaN, so
/// the sum of those differences is zero exactly when every entry is finite. Summed in eight
/// independent lanes over the contiguous storage, the loop vectorises with the baseline
/// instruction set (a per-entry `is_finite` with early exit, or nalgebra's element iterator, runs
/// one entry at a time in the hot loops).
#[inline]
#[allow(clippy::eq_op)] // `v − v` is the test itself, not a mistake.
pub(crate) fn all_finite<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>) -> bool {
    let s = a.as_slice();
    let mut lanes = [0.0_f64; 8];
    let mut chunks = s.chunks_exact(8);
    for chunk in &mut chunks {
        for (lane, v) in lanes.iter_mut().zip(chunk) {
            *lane += v - v;
        }
    }
    let rest: f64 = chunks.remainder().iter().map(|v| v - v).sum();
    lanes.iter().sum::<f64>() + rest == 0.0
}

/// What a Cholesky factorisation does with a pivot `d` (the diagonal entry after elimination).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Pivot {
    /// `l_jj = √d`.
    Accept,
    /// The matrix is not (semi)definite: give up.
    Fail,
}

/// Lower Cholesky factor of `a` (dot-product form) with the pivot rule `decide(j, d)`; `None` as
/// soon as a pivot fails ([`try_cholesky`] gives the rule of a definite matrix).
#[inline]
pub(crate) fn cholesky_with<const N: usize>(
    a: &SMatrix<f64, N, N>,
    decide: impl Fn(usize, f64) -> Pivot,
) -> Option<SMatrix<f64, N, N>> {
    let mut l = SMatrix::<f64, N, N>::zeros();
    for j in 0..N {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        match decide(j, d) {
            Pivot::Fail => return None,
            Pivot::Accept => {}
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        // 1/ljj as ljj/d: the square root and the division run side by side instead of one
        // after the other (this chain of pivots is the latency of the whole factorisation).
        let inv = ljj * (1.0 / d);
        for i in (j + 1)..N {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s * inv;
        }
    }
    Some(l)
}

/// Plain Cholesky factorisation with a relative pivot test; `None` if a pivot is not clearly
/// positive (this also rejects NaN).
fn try_cholesky<const N: usize>(a: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    cholesky_with(a, |j, d| {
        // Written so that a NaN pivot also fails.
        if d > 0.0 && d > PIVOT_REL_TOL * a[(j, j)] {
            Pivot::Accept
        } else {
            Pivot::Fail
        }
    })
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
    if !all_finite(a) {
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
/// The pivots are inverted once: a division costs several multiplications, and a solve against
/// a `J P` block has one per entry.
pub(crate) fn solve_lower_in_place<const N: usize, const C: usize>(
    l: &SMatrix<f64, N, N>,
    b: &mut SMatrix<f64, N, C>,
) {
    let inv_diag: [f64; N] = std::array::from_fn(|i| 1.0 / l[(i, i)]);
    for c in 0..C {
        for i in 0..N {
            let mut s = b[(i, c)];
            for k in 0..i {
                s -= l[(i, k)] * b[(k, c)];
            }
            b[(i, c)] = s * inv_diag[i];
        }
    }
}

/// `Σ_j ln L_jj` for a lower Cholesky factor, i.e. `½ ln det(L Lᵀ)`. One logarithm of the product
/// of the pivots; the sum of logarithms is the fallback when that product under- or overflows.
#[inline]
pub(crate) fn log_det_half<const N: usize>(chol: &SMatrix<f64, N, N>) -> f64 {
    let product: f64 = (0..N).map(|j| chol[(j, j)]).product();
    if product.is_normal() {
        product.ln()
    } else {
        (0..N).map(|j| chol[(j, j)].ln()).sum()
    }
}

/// `log N(r; 0, L Lᵀ)` from the whitened residual `e = L⁻¹ r` and the lower factor `L`:
/// `−½ |e|² − Σ ln L_jj − (N/2) ln 2π`.
#[inline]
pub(crate) fn whitened_loglik<const N: usize>(
    e: &SVector<f64, N>,
    chol: &SMatrix<f64, N, N>,
) -> f64 {
    -0.5 * e.norm_squared() - log_det_half(chol) - 0.5 * (N as f64) * LN_2PI
}

/// `log N(r; 0, L Lᵀ)` from the residual `r` and the lower factor `L`:
/// `−½ |L⁻¹ r|² − Σ ln L_jj − (N/2) ln 2π`.
pub fn log_normal_density_chol<const N: usize>(
    residual: &SVector<f64, N>,
    chol: &SMatrix<f64, N, N>,
) -> f64 {
    let mut e = *residual;
    solve_lower_in_place(chol, &mut e);
    whitened_loglik(&e, chol)
}

/// A constant Gaussian noise `N(0, R)` factorised once (the measurement noise of the particle
/// filters): every density then costs one triangular solve and no logarithm.
#[derive(Debug, Clone, Copy)]
pub struct FactoredCov<const N: usize> {
    chol: SMatrix<f64, N, N>,
    /// `−½ ln det R − (N/2) ln 2π`.
    log_norm: f64,
}

impl<const N: usize> FactoredCov<N> {
    /// Factorises `cov` with the documented repair of [`cholesky_repaired`] (counted in
    /// `health`, reported as step 0).
    pub fn new(
        cov: &SMatrix<f64, N, N>,
        which: &'static str,
        health: &mut Health,
    ) -> Result<Self, FilterError> {
        let chol = cholesky_repaired(cov, 0, which, health)?;
        let log_norm = -log_det_half(&chol) - 0.5 * (N as f64) * LN_2PI;
        Ok(Self { chol, log_norm })
    }

    /// `log N(r; 0, R)`; equal to [`log_normal_density_chol`] with this factor.
    #[inline]
    pub fn log_density(&self, residual: &SVector<f64, N>) -> f64 {
        let mut e = *residual;
        solve_lower_in_place(&self.chol, &mut e);
        -0.5 * e.norm_squared() + self.log_norm
    }
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

/// Calls `f(r, c, J[r, c])` for every non-zero entry of `J`, column by column (so sums built
/// from it run over `c` in increasing order). The Jacobians of the partitioned chain have a
/// handful of non-zeros per row.
#[inline(always)]
fn for_each_nonzero<const R: usize, const C: usize>(
    jac: &SMatrix<f64, R, C>,
    mut f: impl FnMut(usize, usize, f64),
) {
    for c in 0..C {
        for r in 0..R {
            let d = jac[(r, c)];
            if d != 0.0 {
                f(r, c, d);
            }
        }
    }
}

/// `P Jᵀ` (N×NO) over the non-zeros of `J`: column `r` of the product accumulates
/// `J[r, j] · P[:, j]`, a contiguous column.
pub(crate) fn sparse_pjt<const NO: usize, const N: usize>(
    jac: &SMatrix<f64, NO, N>,
    p: &SMatrix<f64, N, N>,
) -> SMatrix<f64, N, NO> {
    let mut pjt = SMatrix::<f64, N, NO>::zeros();
    for_each_nonzero(jac, |r, j, d| {
        for i in 0..N {
            pjt[(i, r)] += d * p[(i, j)];
        }
    });
    pjt
}

/// `J (P Jᵀ) + S` with the lower triangle of `J P Jᵀ` computed over the non-zeros of `J` and
/// mirrored: for symmetric `S` the result is exactly symmetric.
pub(crate) fn innovation_cov<const NY: usize, const N: usize>(
    pjt: &SMatrix<f64, N, NY>,
    jac: &SMatrix<f64, NY, N>,
    s_add: &SMatrix<f64, NY, NY>,
) -> SMatrix<f64, NY, NY> {
    let mut l = SMatrix::<f64, NY, NY>::zeros();
    for_each_nonzero(jac, |i, c, d| {
        for j in 0..=i {
            l[(i, j)] += d * pjt[(c, j)];
        }
    });
    for j in 0..NY {
        for i in (j + 1)..NY {
            l[(j, i)] = l[(i, j)];
        }
    }
    l + s_add
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

/// The gain side of a Gaussian measurement update, computed once per update: `P Jᵀ` and the
/// lower Cholesky factor `C` of the innovation covariance `L = J P Jᵀ + S`. The marginalised
/// particle filters factorise `L` first because it is also their proposal covariance
/// ([`UpdateFactor::condition_on_draw`]).
///
/// Layout: everything is held transposed (`P Jᵀ`, `Wᵀ`) so that each inner loop runs down a
/// contiguous column of length `N`.
#[derive(Debug, Clone, Copy)]
pub struct UpdateFactor<const N: usize, const NY: usize> {
    pjt: SMatrix<f64, N, NY>,
    /// Lower Cholesky factor of `L` (after any repair).
    chol: SMatrix<f64, NY, NY>,
}

impl<const N: usize, const NY: usize> UpdateFactor<N, NY> {
    /// `P Jᵀ` over the non-zeros of `J`, `L = J P Jᵀ + S` (exactly symmetric for symmetric `S`)
    /// and its factor by [`cholesky_repaired`] (same repair, counting and errors).
    pub fn new(
        p: &SMatrix<f64, N, N>,
        jac: &SMatrix<f64, NY, N>,
        s_add: &SMatrix<f64, NY, NY>,
        step: usize,
        which: &'static str,
        health: &mut Health,
    ) -> Result<Self, FilterError> {
        let pjt = sparse_pjt(jac, p);
        let l_cov = innovation_cov(&pjt, jac, s_add);
        let chol = cholesky_repaired(&l_cov, step, which, health)?;
        Ok(Self { pjt, chol })
    }

    /// Draws `mean + C ξ` from `N(mean, L)` and conditions `(m, P)` on it; returns the draw.
    /// This is the proposal and pseudo-measurement update of the marginalised particle filters
    /// (MLN-RBPF (a)+(b), MPF-EKF2 (a)+(b)): the proposal covariance is the innovation
    /// covariance, so the whitened innovation `C⁻¹ (draw − mean)` is `ξ` itself and the update
    /// needs no solve. A non-finite draw is `NonFinite("innovation")`, as in [`gaussian_update`];
    /// on error `m` and `p` are as [`UpdateFactor::apply_whitened`] leaves them.
    pub fn condition_on_draw(
        &self,
        m: &mut SVector<f64, N>,
        p: &mut SMatrix<f64, N, N>,
        mean: &SVector<f64, NY>,
        xi: &SVector<f64, NY>,
        step: usize,
    ) -> Result<SVector<f64, NY>, FilterError> {
        let drawn = mean + self.chol * xi;
        if !all_finite(&drawn) {
            return Err(FilterError::NonFinite {
                step,
                which: "innovation",
            });
        }
        self.apply_whitened(m, p, xi, step)?;
        Ok(drawn)
    }

    /// The update given the whitened innovation `e = C⁻¹ (y − ŷ)`: with `W = C⁻¹ J P`,
    /// `m ← m + Wᵀ e`, `P ← P − Wᵀ W` (lower triangle mirrored, so `P` stays exactly
    /// symmetric). A sampled pseudo-measurement `ŷ + C ξ` has whitened innovation `ξ`, so no
    /// solve is needed for it.
    ///
    /// On a non-finite gain or mean `m` and `p` are left unchanged. `P` is downdated in place (a
    /// copy of it would cost as much as the downdate), so if only the downdated covariance
    /// overflows, `p` is left non-finite and the error says so; every filter of the crate then
    /// stops using those moments.
    pub fn apply_whitened(
        &self,
        m: &mut SVector<f64, N>,
        p: &mut SMatrix<f64, N, N>,
        e: &SVector<f64, NY>,
        step: usize,
    ) -> Result<(), FilterError> {
        // Wᵀ = (P Jᵀ) C⁻ᵀ, column by column: Wᵀ_i = (P Jᵀ_i − Σ_{k<i} C_ik Wᵀ_k) / C_ii.
        let mut wt = self.pjt;
        for i in 0..NY {
            for k in 0..i {
                let c = self.chol[(i, k)];
                if c != 0.0 {
                    for r in 0..N {
                        wt[(r, i)] -= c * wt[(r, k)];
                    }
                }
            }
            let inv = 1.0 / self.chol[(i, i)];
            for r in 0..N {
                wt[(r, i)] *= inv;
            }
        }
        let new_m = *m + wt * e;
        if !all_finite(&new_m) || !all_finite(&wt) {
            return Err(FilterError::NonFinite {
                step,
                which: "filtered mean",
            });
        }
        // P − Wᵀ W by whole columns (fixed length, so the loop vectorises): column c loses
        // Σ_d Wᵀ[c, d] · Wᵀ[:, d]. Then the lower triangle is mirrored, so P is exactly
        // symmetric whatever the rounding.
        for c in 0..N {
            for d in 0..NY {
                let a = wt[(c, d)];
                for r in 0..N {
                    p[(r, c)] -= a * wt[(r, d)];
                }
            }
        }
        for c in 0..N {
            for r in (c + 1)..N {
                p[(c, r)] = p[(r, c)];
            }
        }
        if !all_finite(p) {
            return Err(FilterError::NonFinite {
                step,
                which: "filtered covariance",
            });
        }
        *m = new_m;
        Ok(())
    }
}

/// The update of [`gaussian_update`] from the residual `y − ŷ`; returns the factor and the
/// whitened residual `e = C⁻¹ (y − ŷ)`, from which the caller may score the measurement (Storvik's
/// update of its sufficient statistics does not, and computes no logarithm).
pub(crate) fn update_from_residual<const N: usize, const NY: usize>(
    m: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    residual: &SVector<f64, NY>,
    jac: &SMatrix<f64, NY, N>,
    s_add: &SMatrix<f64, NY, NY>,
    step: usize,
    health: &mut Health,
) -> Result<(SMatrix<f64, NY, NY>, SVector<f64, NY>), FilterError> {
    if !all_finite(residual) {
        return Err(FilterError::NonFinite {
            step,
            which: "innovation",
        });
    }
    let factor = UpdateFactor::new(p, jac, s_add, step, "innovation covariance", health)?;
    let mut e = *residual;
    solve_lower_in_place(&factor.chol, &mut e);
    factor.apply_whitened(m, p, &e, step)?;
    Ok((factor.chol, e))
}

/// The one Gaussian measurement update, SPEC §4. Given the predicted measurement `ŷ`, the
/// Jacobian `J` (NY×N) and the additive covariance `S` (`R`, plus for EKF2 the Hessian term):
///
/// `L = J P Jᵀ + S`, `K = P Jᵀ L⁻¹`, `m ← m + K (y − ŷ)`, `P ← P − K L Kᵀ` (symmetrised).
///
/// With `L = C Cᵀ` (lower Cholesky, [`cholesky_repaired`]) and `W = C⁻¹ J P`, the update is
/// `m ← m + Wᵀ C⁻¹ (y − ŷ)` and `P ← P − Wᵀ W`: two triangular solves, no inverse
/// ([`UpdateFactor`]).
///
/// On error (`NonFinite` for a non-finite residual, innovation covariance or result,
/// `NotPositiveDefinite` if `L` cannot be factorised even after repair) `m` and `p` are left
/// unchanged, except in the one case [`UpdateFactor::apply_whitened`] documents (a finite gain
/// whose downdated covariance overflows).
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
    let (chol, e) = update_from_residual(m, p, &residual, jac, s_add, step, health)?;
    let loglik = whitened_loglik(&e, &chol);
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

    #[test]
    fn log_det_half_survives_underflow_of_the_pivot_product() {
        let mut l = Matrix3::identity() * 1e-120;
        l[(2, 2)] = 3.0;
        let expected = 2.0 * (1e-120_f64).ln() + 3.0_f64.ln();
        assert!((log_det_half(&l) - expected).abs() < 1e-12 * expected.abs());
        let l = Matrix3::new(2.0, 0.0, 0.0, 0.3, 0.5, 0.0, -0.1, 0.2, 4.0);
        assert!((log_det_half(&l) - (4.0_f64).ln()).abs() < 1e-15);
    }

    #[test]
    fn factored_noise_density_equals_the_direct_one() {
        let r = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let mut h = Health::default();
        let noise = FactoredCov::new(&r, "R", &mut h).unwrap();
        let chol = cholesky_repaired(&r, 0, "R", &mut h).unwrap();
        let res = nalgebra::Vector3::new(0.3, -1.2, 2.5);
        let direct = log_normal_density_chol(&res, &chol);
        assert!((noise.log_density(&res) - direct).abs() < 1e-14);
        // Against the textbook formula with an explicit inverse and determinant.
        let textbook = -0.5 * (res.transpose() * r.try_inverse().unwrap() * res)[0]
            - 0.5 * r.determinant().ln()
            - 1.5 * LN_2PI;
        assert!((direct - textbook).abs() < 1e-12);
    }

    #[test]
    fn innovation_covariance_is_exactly_symmetric_and_matches_the_dense_product() {
        let p = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let jac = nalgebra::Matrix2x3::new(0.3, 0.0, -1.7, 0.0, 2.1, 0.4);
        let s = Matrix2::new(0.5, 0.1, 0.1, 0.7);
        let pjt = sparse_pjt(&jac, &p);
        assert!((pjt - p * jac.transpose()).abs().max() < 1e-14);
        let l = innovation_cov(&pjt, &jac, &s);
        assert_eq!(l[(0, 1)], l[(1, 0)]);
        assert!((l - (jac * p * jac.transpose() + s)).abs().max() < 1e-13);
    }

    /// A pseudo-measurement drawn as `ŷ + C ξ` updated through its whitened innovation `ξ` gives
    /// the same moments as the ordinary update with that measurement.
    #[test]
    fn conditioning_on_a_draw_equals_the_ordinary_update_with_that_measurement() {
        let p0 = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0);
        let m0 = nalgebra::Vector3::new(1.0, -2.0, 0.5);
        let jac = nalgebra::Matrix2x3::new(0.3, 0.0, -1.7, 0.0, 2.1, 0.4);
        let s = Matrix2::new(0.5, 0.1, 0.1, 0.7);
        let y_hat = jac * m0;
        let xi = Vector2::new(0.8, -1.3);
        let mut h = Health::default();
        let factor = UpdateFactor::new(&p0, &jac, &s, 0, "L", &mut h).unwrap();
        let (mut m1, mut p1) = (m0, p0);
        let y = factor
            .condition_on_draw(&mut m1, &mut p1, &y_hat, &xi, 0)
            .unwrap();
        // The draw is ŷ + C ξ with C the factor of L.
        let chol = cholesky_repaired(&(jac * p0 * jac.transpose() + s), 0, "L", &mut h).unwrap();
        assert!((y - (y_hat + chol * xi)).abs().max() < 1e-13);
        let (mut m2, mut p2) = (m0, p0);
        gaussian_update(&mut m2, &mut p2, &y, &y_hat, &jac, &s, 0, &mut h).unwrap();
        assert!((m1 - m2).abs().max() < 1e-13);
        assert!((p1 - p2).abs().max() < 1e-13);
        assert_eq!(p1, p1.transpose());
        // Against the textbook gain K = P Jᵀ L⁻¹.
        let l = jac * p0 * jac.transpose() + s;
        let k = p0 * jac.transpose() * l.try_inverse().unwrap();
        assert!((m1 - (m0 + k * (y - y_hat))).abs().max() < 1e-12);
        assert!((p1 - (p0 - k * l * k.transpose())).abs().max() < 1e-12);
        assert_eq!(h, Health::default());
    }

    #[test]
    fn all_finite_detects_every_kind_of_non_finite_entry() {
        let mut a = Matrix3::new(1.0, -2.0, 0.0, f64::MAX, -f64::MAX, 1e-310, 3.0, 4.0, 5.0);
        assert!(all_finite(&a));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -f64::NAN] {
            a[(2, 1)] = bad;
            assert!(!all_finite(&a), "{bad} not detected");
        }
    }
}
