//! The Gaussian measurement update of SPEC §4 on run-time dimensions, generic over [`Real`] (one
//! particle or a pack of four), with Jacobians given by their structural non-zeros ([`Sparse`]).
//!
//! For a Gaussian `N(m, P)` (`n` states), a measurement Jacobian `J` (`q × n`), an additive
//! covariance `S` (`R`, plus for EKF2 the Hessian term) and a predicted measurement `ŷ`:
//!
//! ```text
//! L = J P Jᵀ + S = C Cᵀ          (lower Cholesky factor C; never an inverse)
//! W = C⁻¹ J P                    (the whitened gain, held transposed: Wᵀ = P Jᵀ C⁻ᵀ)
//! e = C⁻¹ (y − ŷ)                (the whitened innovation)
//! m ← m + Wᵀ e,   P ← P − Wᵀ W   (= m + K (y − ŷ), P − K L Kᵀ with K = P Jᵀ L⁻¹)
//! log N(y; ŷ, L) = −½ |e|² − Σ_j ln C_jj − (q/2) ln 2π
//! ```
//!
//! A sampled pseudo-measurement `ŷ + C ξ` has whitened innovation `ξ` itself
//! ([`Factor::condition_on_draw`]), so the proposal and pseudo-measurement update of the
//! marginalized filters share one factorisation and need no solve.
//!
//! Layout: column-major slices; `P` is kept exactly symmetric (lower triangle computed, then
//! mirrored). Costs: `P Jᵀ` is `n · nnz(J)`; the downdate `P − Wᵀ W` is `n² q / 2` and dominates
//! for large `n` (see [`Real::downdate_lower`]).
//!
//! Numerical policy (SPEC §4): the generic functions here compute the *straight path* and report,
//! per lane, whether it was valid (a pivot clearly positive, every result finite). For one
//! particle [`factorise`] adds the documented repair (`jittered_cholesky`: bounded diagonal
//! jitter, counted in [`Health`]); a pack lane whose straight path fails is redone by that scalar
//! code. [`cholesky_repaired`] is the same repair with typed errors for one-off factorisations.

// `v − v` is the finiteness test itself (+0 for a finite v, NaN otherwise), not a mistake.
#![allow(clippy::eq_op)]

use crate::error::FilterError;
use crate::health::Health;
use crate::real::Real;

use super::sparse::Sparse;

/// `ln(2π)`.
pub(crate) const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// A Cholesky pivot is accepted only if it exceeds this fraction of its own diagonal entry: a
/// smaller pivot is round-off, not information (the matrix is numerically singular).
pub(crate) const PIVOT_REL_TOL: f64 = 16.0 * f64::EPSILON;

/// Relative diagonal jitter tried in turn when a factorisation fails: the diagonal is scaled by
/// `1 + τ`. The largest value bounds the perturbation of the covariance to one part in a million.
pub(crate) const JITTER_STEPS: [f64; 4] = [1e-12, 1e-10, 1e-8, 1e-6];

/// A pivot below this fraction of the largest diagonal entry is a direction of zero variance in a
/// positive *semi*-definite factorisation ([`psd_cholesky`]); below minus this fraction the
/// matrix is indefinite.
pub(crate) const PSD_PIVOT_REL_TOL: f64 = 1e-12;

#[inline(always)]
fn zero<T: Real>() -> T {
    T::splat(0.0)
}

/// Column `j` of a Cholesky recurrence ([`cholesky`], [`psd_cholesky`]) up to its pivot: zeroes
/// the column's upper part and returns the pivot `d = a_jj − Σ_{k<j} l_jk²` (columns `< j` of
/// `l` done).
#[inline(always)]
fn pivot<T: Real>(a: &[T], q: usize, l: &mut [T], j: usize) -> T {
    for i in 0..j {
        l[i + j * q] = zero();
    }
    let mut d = a[j + j * q];
    for k in 0..j {
        let ljk = l[j + k * q];
        d -= ljk * ljk;
    }
    d
}

/// Entry `(i, j)` below the pivot before its scaling: `a_ij − Σ_{k<j} l_ik l_jk`.
#[inline(always)]
fn below_pivot<T: Real>(a: &[T], q: usize, l: &[T], i: usize, j: usize) -> T {
    let mut s = a[i + j * q];
    for k in 0..j {
        s -= l[i + k * q] * l[j + k * q];
    }
    s
}

/// Lower Cholesky factor `l` (`q × q`, column-major, upper part zero) of the symmetric `a`
/// (lower triangle read). Returns the lanes whose every pivot was clearly positive
/// (`d > 0` and `d > 16 ε a_jj`; a NaN or infinity fails). A failing lane goes on with
/// meaningless values, which the mask disowns.
#[inline]
pub fn cholesky<T: Real>(a: &[T], q: usize, l: &mut [T]) -> T::Mask {
    let mut ok = T::all_true();
    let tol = T::splat(PIVOT_REL_TOL);
    for j in 0..q {
        let d = pivot(a, q, l, j);
        ok = ok & d.gt(zero()) & d.gt(tol * a[j + j * q]);
        let ljj = d.sqrt();
        l[j + j * q] = ljj;
        // 1/ljj as ljj/d: the square root and the division run side by side.
        let inv = ljj * (T::splat(1.0) / d);
        for i in (j + 1)..q {
            l[i + j * q] = below_pivot(a, q, l, i, j) * inv;
        }
    }
    ok
}

/// Lower factor `l` with `l lᵀ = a` for a symmetric positive *semi*-definite `a` (Storvik's draw
/// from `N(μ, C)` when some directions of `C` have zero variance, e.g. fixed parameters): a pivot
/// within `±1e-12 · max_j a_jj` of zero gives a zero column (that direction has no spread). Returns
/// the lanes where `a` was finite and no pivot clearly negative.
#[inline]
pub(crate) fn psd_cholesky<T: Real>(a: &[T], q: usize, l: &mut [T]) -> T::Mask {
    let mut finite = zero::<T>();
    let mut max_diag = zero::<T>();
    for j in 0..q {
        for i in 0..q {
            let v = a[i + j * q];
            finite += v - v;
        }
        let d = a[j + j * q];
        max_diag = T::select(d.gt(max_diag), d, max_diag);
    }
    let mut ok = finite.eq(zero());
    let tol = T::splat(PSD_PIVOT_REL_TOL) * max_diag;
    for j in 0..q {
        let d = pivot(a, q, l, j);
        ok = ok & T::not(d.lt(-tol));
        let zero_col = d.le(tol);
        let ljj = d.sqrt();
        l[j + j * q] = T::select(zero_col, zero(), ljj);
        let inv = ljj * (T::splat(1.0) / d);
        for i in (j + 1)..q {
            l[i + j * q] = T::select(zero_col, zero(), below_pivot(a, q, l, i, j) * inv);
        }
    }
    ok
}

/// Solves `l x = b` in place for the lower-triangular `l` (`q × q`).
#[inline]
pub(crate) fn solve_lower<T: Real>(l: &[T], q: usize, b: &mut [T]) {
    for i in 0..q {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i + k * q] * b[k];
        }
        b[i] = s / l[i + i * q];
    }
}

/// `out = l x` for the lower-triangular `l` (`q × q`), summed over the columns in order.
#[inline]
pub(crate) fn lower_mul<T: Real>(l: &[T], q: usize, x: &[T], out: &mut [T]) {
    out[..q].fill(zero());
    for j in 0..q {
        let xj = x[j];
        for i in j..q {
            out[i] += l[i + j * q] * xj;
        }
    }
}

/// `Σ_j ln l_jj = ½ ln det(l lᵀ)`: one logarithm of the product of the pivots, the sum of
/// logarithms when that product under- or overflows (lane by lane).
#[inline]
pub(crate) fn log_det_half<T: Real>(l: &[T], q: usize) -> T {
    let mut prod = T::splat(1.0);
    for j in 0..q {
        prod *= l[j + j * q];
    }
    T::from_lanes(|b| {
        let p = prod.lane(b);
        if p.is_normal() {
            p.ln()
        } else {
            (0..q).map(|j| l[j + j * q].lane(b).ln()).sum()
        }
    })
}

/// `log N(r; 0, l lᵀ)` from the whitened residual `e = l⁻¹ r`: `−½|e|² − Σ ln l_jj − (q/2) ln 2π`.
#[inline]
pub(crate) fn whitened_loglik<T: Real>(e: &[T], l: &[T], q: usize) -> T {
    let mut sq = zero::<T>();
    for v in &e[..q] {
        sq += *v * *v;
    }
    T::splat(-0.5) * sq - log_det_half(l, q) - T::splat(0.5 * q as f64 * LN_2PI)
}

/// `out = P Jᵀ` (`n × q`) over the entries of `J` (`q × n`): column `r` of the product
/// accumulates `J[r, c] · P[:, c]`, a contiguous column of the symmetric `P`.
#[inline]
pub(crate) fn pjt<T: Real>(j: &Sparse<T>, p: &[T], n: usize, out: &mut [T]) {
    out[..n * j.nrows()].fill(zero());
    for e in 0..j.nnz() {
        let (r, c, v) = j.entry(e);
        let pc = &p[c * n..(c + 1) * n];
        let oc = &mut out[r * n..(r + 1) * n];
        for i in 0..n {
            oc[i] += v * pc[i];
        }
    }
}

/// `out = J (P Jᵀ) + S` (`q × q`) with the lower triangle of `J P Jᵀ` computed over the entries of
/// `J` and `S` added before mirroring, so that for symmetric `S` the result is exactly symmetric.
#[inline]
pub(crate) fn innovation_cov<T: Real>(
    j: &Sparse<T>,
    pjt: &[T],
    n: usize,
    s_add: &[T],
    out: &mut [T],
) {
    let q = j.nrows();
    out[..q * q].fill(zero());
    for e in 0..j.nnz() {
        let (i, c, v) = j.entry(e);
        for k in 0..=i {
            out[i + k * q] += v * pjt[c + k * n];
        }
    }
    for k in 0..q {
        for i in k..q {
            out[i + k * q] += s_add[i + k * q];
        }
        for i in (k + 1)..q {
            out[k + i * q] = out[i + k * q];
        }
    }
}

/// `Wᵀ = (P Jᵀ) C⁻ᵀ` in place on `pjt` (`n × q`), column by column:
/// `Wᵀ_i = (P Jᵀ_i − Σ_{k<i} C_ik Wᵀ_k) / C_ii`.
#[inline]
pub(crate) fn whiten_gain<T: Real>(chol: &[T], q: usize, wt: &mut [T], n: usize) {
    for i in 0..q {
        for k in 0..i {
            let c = chol[i + k * q];
            let (done, rest) = wt.split_at_mut(i * n);
            let wk = &done[k * n..(k + 1) * n];
            let wi = &mut rest[..n];
            for r in 0..n {
                wi[r] -= c * wk[r];
            }
        }
        let inv = T::splat(1.0) / chol[i + i * q];
        for v in &mut wt[i * n..(i + 1) * n] {
            *v *= inv;
        }
    }
}

/// `mean ← mean + Wᵀ e` and `P ← P − Wᵀ W` (lower triangle, then mirrored). Returns the lanes
/// whose new mean, gain and covariance are all finite; in a lane that is not, `mean` and `p`
/// hold meaningless values (the particle is given weight zero by its filter).
#[inline]
pub(crate) fn apply_whitened<T: Real>(
    mean: &mut [T],
    p: &mut [T],
    n: usize,
    wt: &[T],
    q: usize,
    e: &[T],
) -> T::Mask {
    let mut check = zero::<T>();
    for d in 0..q {
        let ed = e[d];
        let wd = &wt[d * n..(d + 1) * n];
        for r in 0..n {
            mean[r] += wd[r] * ed;
        }
    }
    for r in 0..n {
        let v = mean[r];
        check += v - v;
    }
    for v in &wt[..n * q] {
        check += *v - *v;
    }
    T::downdate_lower(p, n, wt, q);
    for c in 0..n {
        for r in c..n {
            let v = p[r + c * n];
            check += v - v;
        }
        for r in (c + 1)..n {
            p[c + r * n] = p[r + c * n];
        }
    }
    check.eq(zero())
}

/// The gain side of a Gaussian update, computed once: `P Jᵀ`, `L = J P Jᵀ + S` and its factor
/// `C`, with their scratch (allocated once per filter, reused every step).
#[derive(Debug, Clone)]
pub struct Factor<T> {
    n: usize,
    q: usize,
    /// `P Jᵀ` (`n × q`); after `whiten_gain`, `Wᵀ`.
    pub pjt: Vec<T>,
    /// `L` (`q × q`).
    pub cov: Vec<T>,
    /// Lower factor `C` of `L`.
    pub chol: Vec<T>,
    /// Whitened innovation `e` (`q`).
    pub e: Vec<T>,
    /// Scratch of the repair.
    jittered: Vec<T>,
}

impl<T: Real> Factor<T> {
    /// Scratch for `n` states and `q` measurements.
    pub fn new(n: usize, q: usize) -> Self {
        Self {
            n,
            q,
            pjt: vec![zero(); n * q],
            cov: vec![zero(); q * q],
            chol: vec![zero(); q * q],
            e: vec![zero(); q],
            jittered: vec![zero(); q * q],
        }
    }

    pub fn dims(&self) -> (usize, usize) {
        (self.n, self.q)
    }

    /// The straight path: `P Jᵀ`, `L = J P Jᵀ + S`, `C = chol(L)`. Returns the lanes whose
    /// factorisation needed no repair.
    #[inline]
    pub fn compute(&mut self, p: &[T], j: &Sparse<T>, s_add: &[T]) -> T::Mask {
        debug_assert_eq!((j.nrows(), j.ncols()), (self.q, self.n));
        pjt(j, p, self.n, &mut self.pjt);
        innovation_cov(j, &self.pjt, self.n, s_add, &mut self.cov);
        cholesky(&self.cov, self.q, &mut self.chol)
    }

    /// Draws `pred + C ξ` into `draw` and conditions `(mean, P)` on it (whitened innovation `ξ`).
    /// Returns the lanes whose draw and result are finite.
    #[inline]
    pub fn condition_on_draw(
        &mut self,
        mean: &mut [T],
        p: &mut [T],
        pred: &[T],
        xi: &[T],
        draw: &mut [T],
    ) -> T::Mask {
        let q = self.q;
        lower_mul(&self.chol, q, xi, draw);
        let mut check = zero::<T>();
        for i in 0..q {
            draw[i] += pred[i];
            check += draw[i] - draw[i];
        }
        whiten_gain(&self.chol, q, &mut self.pjt, self.n);
        apply_whitened(mean, p, self.n, &self.pjt, q, xi) & check.eq(zero())
    }

    /// The update with the residual `y − ŷ`; returns `log N(y; ŷ, L)` and the lanes whose
    /// residual and result are finite.
    #[inline]
    pub fn update(&mut self, mean: &mut [T], p: &mut [T], residual: &[T]) -> (T, T::Mask) {
        let q = self.q;
        let mut check = zero::<T>();
        for i in 0..q {
            self.e[i] = residual[i];
            check += residual[i] - residual[i];
        }
        solve_lower(&self.chol, q, &mut self.e);
        let loglik = whitened_loglik(&self.e, &self.chol, q);
        whiten_gain(&self.chol, q, &mut self.pjt, self.n);
        let ok = apply_whitened(mean, p, self.n, &self.pjt, q, &self.e);
        (loglik, ok & check.eq(zero()))
    }
}

/// [`Factor::compute`], and for one particle (`T::LANES == 1`) whose straight path failed the
/// documented repair of `jittered_cholesky` (counted in `health`). A pack returns its
/// straight-path mask: the batch layer redoes a failing lane as one particle. Returns the lanes
/// that have a factor; a particle without one gets weight zero from its filter (a per-particle
/// failure is counted, not returned as an error: it does not end the run). A non-finite `L` is
/// not repaired and not counted: the caller sees the failed lane and the non-finite entries.
#[inline]
pub fn factorise<T: Real>(
    factor: &mut Factor<T>,
    p: &[T],
    j: &Sparse<T>,
    s_add: &[T],
    health: &mut Health,
) -> T::Mask {
    let ok = factor.compute(p, j, s_add);
    if T::LANES > 1 || T::mask_lane(ok, 0) || !all_finite(&factor.cov) {
        return ok;
    }
    if jittered_cholesky(
        &factor.cov,
        factor.q,
        &mut factor.jittered,
        &mut factor.chol,
        health,
    ) {
        T::all_true()
    } else {
        ok
    }
}

/// Whether every entry of lane 0 is finite (`v − v` is `+0` for a finite `v`, NaN otherwise).
#[inline]
fn all_finite<T: Real>(a: &[T]) -> bool {
    let mut check = zero::<T>();
    for v in a {
        check += *v - *v;
    }
    T::mask_lane(check.eq(zero()), 0)
}

/// The documented repair (SPEC §4) of a finite symmetric `a` (`q × q`) whose plain
/// factorisation failed, for one particle (lane 0):
///
/// 1. the diagonal of `a` is scaled by `1 + τ`, τ = 1e-12, 1e-10, 1e-8, 1e-6 in turn (a
///    non-positive diagonal entry receives `τ` times the largest diagonal entry instead) and the
///    factorisation with the relative pivot test is tried again;
/// 2. success increments `health.jitter_added` (once per factorisation that needed it) and
///    leaves the factor in `l`; if even τ = 1e-6 fails, `health.cholesky_failures` is
///    incremented and `false` returned.
///
/// `jittered` is `q × q` scratch. This is the only jitter loop of the crate: the particle
/// filters ([`factorise`]) and the one-off factorisations ([`cholesky_repaired`]) both use it.
pub(crate) fn jittered_cholesky<T: Real>(
    a: &[T],
    q: usize,
    jittered: &mut [T],
    l: &mut [T],
    health: &mut Health,
) -> bool {
    let mut max_diag = zero::<T>();
    for j in 0..q {
        let d = a[j + j * q];
        max_diag = T::select(d.gt(max_diag), d, max_diag);
    }
    jittered[..q * q].copy_from_slice(&a[..q * q]);
    for tau in JITTER_STEPS {
        for j in 0..q {
            let d = a[j + j * q];
            jittered[j + j * q] = T::select(
                d.gt(zero()),
                d * T::splat(1.0 + tau),
                d + T::splat(tau) * max_diag,
            );
        }
        if T::mask_lane(cholesky(jittered, q, l), 0) {
            health.jitter_added += 1;
            return true;
        }
    }
    health.cholesky_failures += 1;
    false
}

/// Lower Cholesky factor of a symmetric `a` with the documented repair, for one-off uses (the
/// constant `R`, the unscented transform, tests):
///
/// 1. a non-finite entry → `Err(NonFinite { step, which })`;
/// 2. an asymmetry beyond round-off (`|a_ij − a_ji| > 1e-9 sqrt(a_ii a_jj)`) is counted in
///    `health.symmetrised` and `(A + Aᵀ)/2` is factorised;
/// 3. Cholesky with the relative pivot test, then the repair of `jittered_cholesky`;
/// 4. if that fails too, `Err(NotPositiveDefinite { step, which })`.
pub fn cholesky_repaired(
    a: &[f64],
    q: usize,
    step: usize,
    which: &'static str,
    health: &mut Health,
) -> Result<Vec<f64>, FilterError> {
    if a[..q * q].iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite { step, which });
    }
    let mut s = a[..q * q].to_vec();
    let mut asymmetric = false;
    for j in 0..q {
        for i in (j + 1)..q {
            let (aij, aji) = (a[i + j * q], a[j + i * q]);
            if aij != aji {
                let scale = (a[i + i * q] * a[j + j * q]).abs().sqrt();
                asymmetric |= (aij - aji).abs() > 1e-9 * scale;
                let m = 0.5 * (aij + aji);
                s[i + j * q] = m;
                s[j + i * q] = m;
            }
        }
    }
    if asymmetric {
        health.symmetrised += 1;
    }
    let mut l = vec![0.0; q * q];
    if cholesky(&s, q, &mut l) || jittered_cholesky(&s, q, &mut vec![0.0; q * q], &mut l, health) {
        return Ok(l);
    }
    Err(FilterError::NotPositiveDefinite { step, which })
}

/// A constant Gaussian noise `N(0, R)` factorised once (the measurement noise of the bootstrap
/// PF and of Storvik's weights): every density costs one triangular solve and no logarithm.
#[derive(Debug, Clone)]
pub(crate) struct FactoredNoise {
    q: usize,
    chol: Vec<f64>,
    /// `1 / C_ii`.
    inv_diag: Vec<f64>,
    /// Whether `R` is diagonal (the usual case: independent sensors), so that the whitened
    /// residual is `r_i / C_ii` with no solve.
    diagonal: bool,
    /// `−½ ln det R − (q/2) ln 2π`.
    log_norm: f64,
}

impl FactoredNoise {
    /// Factorises `r` (`q × q`) with the repair of [`cholesky_repaired`] (reported as step 0).
    pub fn new(
        r: &[f64],
        q: usize,
        which: &'static str,
        health: &mut Health,
    ) -> Result<Self, FilterError> {
        let chol = cholesky_repaired(r, q, 0, which, health)?;
        let log_norm = -log_det_half(&chol, q) - 0.5 * q as f64 * LN_2PI;
        let inv_diag = (0..q).map(|i| 1.0 / chol[i + i * q]).collect();
        let diagonal = (0..q).all(|j| (j + 1..q).all(|i| chol[i + j * q] == 0.0));
        Ok(Self {
            q,
            chol,
            inv_diag,
            diagonal,
            log_norm,
        })
    }

    /// A noise factorised once at set-up ([`FactoredNoise::new`]), as step `k` of a filter sees
    /// it: the factor, or the failure of its factorisation dated at step `k` (a filter whose `R`
    /// could not be factorised fails every step with it).
    pub(crate) fn at_step(
        noise: &Result<FactoredNoise, FilterError>,
        k: usize,
    ) -> Result<&FactoredNoise, FilterError> {
        match noise {
            Ok(n) => Ok(n),
            Err(FilterError::NotPositiveDefinite { which, .. }) => {
                Err(FilterError::NotPositiveDefinite { step: k, which })
            }
            Err(FilterError::NonFinite { which, .. }) => {
                Err(FilterError::NonFinite { step: k, which })
            }
            Err(e) => Err(e.clone()),
        }
    }

    /// `log N(r; 0, R)`; `scratch` has length `q` and is overwritten.
    #[inline]
    pub(crate) fn log_density<T: Real>(&self, residual: &[T], scratch: &mut [T]) -> T {
        let q = self.q;
        if self.diagonal {
            let mut sq = zero::<T>();
            for (r, d) in residual[..q].iter().zip(&self.inv_diag) {
                let e = *r * T::splat(*d);
                sq += e * e;
            }
            return T::splat(-0.5) * sq + T::splat(self.log_norm);
        }
        scratch[..q].copy_from_slice(&residual[..q]);
        for i in 0..q {
            let mut s = scratch[i];
            for k in 0..i {
                s -= T::splat(self.chol[i + k * q]) * scratch[k];
            }
            scratch[i] = s / T::splat(self.chol[i + i * q]);
        }
        let mut sq = zero::<T>();
        for v in &scratch[..q] {
            sq += *v * *v;
        }
        T::splat(-0.5) * sq + T::splat(self.log_norm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Column-major 3 × 3 SPD matrix used below.
    const A: [f64; 9] = [4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0];

    fn dense(a: &[f64], q: usize) -> DMatrix<f64> {
        DMatrix::from_column_slice(q, q, a)
    }

    #[test]
    fn cholesky_of_spd_matrix_reconstructs_it_without_repair() {
        let mut h = Health::default();
        let l = cholesky_repaired(&A, 3, 0, "a", &mut h).unwrap();
        let l = dense(&l, 3);
        assert!((&l * l.transpose() - dense(&A, 3)).abs().max() < 1e-14);
        assert_eq!(l[(0, 1)], 0.0);
        assert_eq!(h, Health::default());
    }

    #[test]
    fn asymmetry_beyond_round_off_is_counted() {
        let a = [2.0, 0.5 + 1e-3, 0.5, 1.0];
        let mut h = Health::default();
        let l = dense(&cholesky_repaired(&a, 2, 3, "a", &mut h).unwrap(), 2);
        assert_eq!(h.symmetrised, 1);
        assert!(((&l * l.transpose())[(1, 0)] - (0.5 + 0.5e-3)).abs() < 1e-14);
        // Round-off asymmetry is not counted.
        let b = [2.0, 0.5 * (1.0 + f64::EPSILON), 0.5, 1.0];
        let mut h = Health::default();
        cholesky_repaired(&b, 2, 3, "b", &mut h).unwrap();
        assert_eq!(h.symmetrised, 0);
    }

    #[test]
    fn negative_definite_matrix_is_a_typed_error() {
        let a = [1.0, 0.0, 0.0, -1.0];
        let mut h = Health::default();
        let err = cholesky_repaired(&a, 2, 7, "a", &mut h).unwrap_err();
        assert_eq!(
            err,
            FilterError::NotPositiveDefinite {
                step: 7,
                which: "a"
            }
        );
        assert_eq!(h.cholesky_failures, 1);
        let a = [1.0, f64::NAN, f64::NAN, 1.0];
        let err = cholesky_repaired(&a, 2, 8, "a", &mut h).unwrap_err();
        assert_eq!(
            err,
            FilterError::NonFinite {
                step: 8,
                which: "a"
            }
        );
    }

    /// One particle: a factorisation that fails only by round-off is repaired and counted; a
    /// clearly indefinite one is counted as a failure and its lane reported.
    #[test]
    fn factorise_repairs_one_particle_and_counts() {
        let p = [1.0, 1.0, 1.0, 1.0];
        let j = Sparse::nonzeros_of(&[1.0, 0.0, 0.0, 1.0], 2, 2);
        let mut f = Factor::<f64>::new(2, 2);
        let mut h = Health::default();
        assert!(factorise(
            &mut f,
            &p,
            &j,
            &[1e-300, 0.0, 0.0, 1e-300],
            &mut h
        ));
        assert_eq!((h.jitter_added, h.cholesky_failures), (1, 0));
        assert!(!factorise(&mut f, &p, &j, &[0.0, 0.0, 0.0, -0.5], &mut h));
        assert_eq!((h.jitter_added, h.cholesky_failures), (1, 1));
        // A non-finite L is neither repaired nor counted.
        assert!(!factorise(
            &mut f,
            &p,
            &j,
            &[f64::NAN, 0.0, 0.0, 1.0],
            &mut h
        ));
        assert_eq!((h.jitter_added, h.cholesky_failures), (1, 1));
    }

    #[test]
    fn triangular_solve_and_product_invert_each_other() {
        let mut h = Health::default();
        let l = cholesky_repaired(&A, 3, 0, "a", &mut h).unwrap();
        let b = [1.0, -2.0, 0.5];
        let mut x = b;
        solve_lower(&l, 3, &mut x);
        assert!(
            (dense(&l, 3) * DVector::from_column_slice(&x) - DVector::from_column_slice(&b))
                .abs()
                .max()
                < 1e-14
        );
        let mut back = [0.0; 3];
        lower_mul(&l, 3, &x, &mut back);
        assert!(back.iter().zip(&b).all(|(u, v)| (u - v).abs() < 1e-14));
    }

    #[test]
    fn log_det_half_survives_underflow_of_the_pivot_product() {
        let mut l = [0.0; 9];
        l[0] = 1e-120;
        l[4] = 1e-120;
        l[8] = 3.0;
        let expected = 2.0 * (1e-120_f64).ln() + 3.0_f64.ln();
        assert!((log_det_half(&l, 3) - expected).abs() < 1e-12 * expected.abs());
        let l = [2.0, 0.3, -0.1, 0.0, 0.5, 0.2, 0.0, 0.0, 4.0];
        assert!((log_det_half(&l, 3) - (4.0_f64).ln()).abs() < 1e-15);
    }

    #[test]
    fn factored_noise_density_equals_the_textbook_one() {
        let mut h = Health::default();
        let res = [0.3, -1.2, 2.5];
        let r = dense(&A, 3);
        let rv = DVector::from_column_slice(&res);
        let textbook = -0.5 * (rv.transpose() * r.clone().try_inverse().unwrap() * &rv)[0]
            - 0.5 * r.determinant().ln()
            - 1.5 * LN_2PI;
        let noise = FactoredNoise::new(&A, 3, "R", &mut h).unwrap();
        assert!((noise.log_density(&res, &mut [0.0; 3]) - textbook).abs() < 1e-12);
        // Diagonal R: no solve, the same density.
        let d = [4.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 3.0];
        let noise = FactoredNoise::new(&d, 3, "R", &mut h).unwrap();
        let direct: f64 = res
            .iter()
            .zip([4.0_f64, 5.0, 3.0])
            .map(|(e, v)| -0.5 * e * e / v - 0.5 * v.ln() - 0.5 * LN_2PI)
            .sum();
        assert!((noise.log_density(&res, &mut [0.0; 3]) - direct).abs() < 1e-12);
        let e = [0.7 / 2.0];
        let expected = -0.5 * (0.7_f64 / 2.0).powi(2) - 2.0_f64.ln() - 0.5 * LN_2PI;
        assert!((whitened_loglik(&e, &[2.0], 1) - expected).abs() < 1e-15);
    }

    /// The failure to factorise a noise at set-up (dated step 0) is the failure of every step,
    /// dated at that step; a factorised noise passes through.
    #[test]
    fn a_noise_that_could_not_be_factorised_fails_each_step_at_its_own_date() {
        let mut h = Health::default();
        let indefinite = FactoredNoise::new(&[1.0, 0.0, 0.0, -1.0], 2, "R", &mut h);
        assert_eq!(
            indefinite.as_ref().err(),
            Some(&FilterError::NotPositiveDefinite {
                step: 0,
                which: "R"
            })
        );
        assert_eq!(
            FactoredNoise::at_step(&indefinite, 7).err(),
            Some(FilterError::NotPositiveDefinite {
                step: 7,
                which: "R"
            })
        );
        let nan = FactoredNoise::new(&[f64::NAN], 1, "R", &mut h);
        assert_eq!(
            FactoredNoise::at_step(&nan, 3).err(),
            Some(FilterError::NonFinite {
                step: 3,
                which: "R"
            })
        );
        let ok = FactoredNoise::new(&[4.0], 1, "R", &mut h);
        let n = FactoredNoise::at_step(&ok, 5).unwrap();
        assert!(std::ptr::eq(n, ok.as_ref().unwrap()));
    }

    /// A pseudo-measurement drawn as `ŷ + C ξ` updated through its whitened innovation `ξ` gives
    /// the same moments as the ordinary update with that measurement, and both equal the
    /// textbook gain `K = P Jᵀ L⁻¹`.
    #[test]
    fn conditioning_on_a_draw_equals_the_ordinary_update_with_that_measurement() {
        let m0 = [1.0, -2.0, 0.5];
        // J = [[0.3, 0, −1.7], [0, 2.1, 0.4]] column-major, S = [[0.5, 0.1], [0.1, 0.7]].
        let jd = [0.3, 0.0, 0.0, 2.1, -1.7, 0.4];
        let j = Sparse::nonzeros_of(&jd, 2, 3);
        let s = [0.5, 0.1, 0.1, 0.7];
        let mut y_hat = [0.0; 2];
        j.mul_add(&m0, &mut y_hat);
        let xi = [0.8, -1.3];
        let mut f = Factor::<f64>::new(3, 2);
        assert!(f.compute(&A, &j, &s));
        let (mut m1, mut p1) = (m0, A);
        let mut y = [0.0; 2];
        assert!(f.condition_on_draw(&mut m1, &mut p1, &y_hat, &xi, &mut y));
        let l = dense(&f.cov, 2);
        let c = dense(&f.chol, 2);
        let drawn = DVector::from_column_slice(&y_hat) + &c * DVector::from_column_slice(&xi);
        assert!((DVector::from_column_slice(&y) - &drawn).abs().max() < 1e-13);
        let mut g = Factor::<f64>::new(3, 2);
        assert!(g.compute(&A, &j, &s));
        let (mut m2, mut p2) = (m0, A);
        let residual = [y[0] - y_hat[0], y[1] - y_hat[1]];
        let (_, ok) = g.update(&mut m2, &mut p2, &residual);
        assert!(ok);
        assert!(m1.iter().zip(&m2).all(|(a, b)| (a - b).abs() < 1e-13));
        assert!(p1.iter().zip(&p2).all(|(a, b)| (a - b).abs() < 1e-13));
        assert_eq!(dense(&p1, 3), dense(&p1, 3).transpose());
        let (jm, pm) = (DMatrix::from_column_slice(2, 3, &jd), dense(&A, 3));
        let k = &pm * jm.transpose() * l.clone().try_inverse().unwrap();
        let r = DVector::from_column_slice(&residual);
        let m_ref = DVector::from_column_slice(&m0) + &k * &r;
        let p_ref = &pm - &k * &l * k.transpose();
        assert!((DVector::from_column_slice(&m1) - m_ref).abs().max() < 1e-12);
        assert!((dense(&p1, 3) - p_ref).abs().max() < 1e-12);
    }

    #[test]
    fn all_finite_detects_every_kind_of_non_finite_entry() {
        let mut a = [1.0, -2.0, 0.0, f64::MAX, -f64::MAX, 1e-310, 3.0, 4.0, 5.0];
        assert!(all_finite(&a));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -f64::NAN] {
            a[7] = bad;
            assert!(!all_finite(&a), "{bad} not detected");
        }
    }
}
