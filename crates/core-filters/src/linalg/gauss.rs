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
//! per lane, whether it was valid (a pivot clearly positive, every result finite). The scalar
//! wrapper [`Factor::compute_repaired`] adds the documented repair (bounded diagonal jitter,
//! counted in [`Health`]) and typed errors; a pack lane whose straight path fails is redone by
//! that scalar code.

#![allow(clippy::needless_range_loop)]
// index loops spell out the order of operations
// `v − v` is the finiteness test itself (+0 for a finite v, NaN otherwise), not a mistake.
#![allow(clippy::eq_op)]

use crate::error::FilterError;
use crate::health::Health;
use crate::real::Real;

use super::sparse::Sparse;

/// `ln(2π)`.
pub const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// A Cholesky pivot is accepted only if it exceeds this fraction of its own diagonal entry: a
/// smaller pivot is round-off, not information (the matrix is numerically singular).
pub const PIVOT_REL_TOL: f64 = 16.0 * f64::EPSILON;

/// Relative diagonal jitter tried in turn when a factorisation fails: the diagonal is scaled by
/// `1 + τ`. The largest value bounds the perturbation of the covariance to one part in a million.
pub const JITTER_STEPS: [f64; 4] = [1e-12, 1e-10, 1e-8, 1e-6];

/// A pivot below this fraction of the largest diagonal entry is a direction of zero variance in a
/// positive *semi*-definite factorisation ([`psd_cholesky`]); below minus this fraction the
/// matrix is indefinite.
pub const PSD_PIVOT_REL_TOL: f64 = 1e-12;

#[inline(always)]
fn zero<T: Real>() -> T {
    T::splat(0.0)
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
        for i in 0..j {
            l[i + j * q] = zero();
        }
        let mut d = a[j + j * q];
        for k in 0..j {
            let ljk = l[j + k * q];
            d -= ljk * ljk;
        }
        ok = ok & d.gt(zero()) & d.gt(tol * a[j + j * q]);
        let ljj = d.sqrt();
        l[j + j * q] = ljj;
        // 1/ljj as ljj/d: the square root and the division run side by side.
        let inv = ljj * (T::splat(1.0) / d);
        for i in (j + 1)..q {
            let mut s = a[i + j * q];
            for k in 0..j {
                s -= l[i + k * q] * l[j + k * q];
            }
            l[i + j * q] = s * inv;
        }
    }
    ok
}

/// Lower factor `l` with `l lᵀ = a` for a symmetric positive *semi*-definite `a` (Storvik's draw
/// from `N(μ, C)` when some directions of `C` have zero variance, e.g. fixed parameters): a pivot
/// within `±1e-12 · max_j a_jj` of zero gives a zero column (that direction has no spread). Returns
/// the lanes where `a` was finite and no pivot clearly negative.
#[inline]
pub fn psd_cholesky<T: Real>(a: &[T], q: usize, l: &mut [T]) -> T::Mask {
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
        for i in 0..j {
            l[i + j * q] = zero();
        }
        let mut d = a[j + j * q];
        for k in 0..j {
            let ljk = l[j + k * q];
            d -= ljk * ljk;
        }
        ok = ok & T::not(d.lt(-tol));
        let zero_col = d.le(tol);
        let ljj = d.sqrt();
        l[j + j * q] = T::select(zero_col, zero(), ljj);
        let inv = ljj * (T::splat(1.0) / d);
        for i in (j + 1)..q {
            let mut s = a[i + j * q];
            for k in 0..j {
                s -= l[i + k * q] * l[j + k * q];
            }
            l[i + j * q] = T::select(zero_col, zero(), s * inv);
        }
    }
    ok
}

/// Solves `l x = b` in place for the lower-triangular `l` (`q × q`).
#[inline]
pub fn solve_lower<T: Real>(l: &[T], q: usize, b: &mut [T]) {
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
pub fn lower_mul<T: Real>(l: &[T], q: usize, x: &[T], out: &mut [T]) {
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
pub fn log_det_half<T: Real>(l: &[T], q: usize) -> T {
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
pub fn whitened_loglik<T: Real>(e: &[T], l: &[T], q: usize) -> T {
    let mut sq = zero::<T>();
    for v in &e[..q] {
        sq += *v * *v;
    }
    T::splat(-0.5) * sq - log_det_half(l, q) - T::splat(0.5 * q as f64 * LN_2PI)
}

/// `out = P Jᵀ` (`n × q`) over the entries of `J` (`q × n`): column `r` of the product
/// accumulates `J[r, c] · P[:, c]`, a contiguous column of the symmetric `P`.
#[inline]
pub fn pjt<T: Real>(j: &Sparse<T>, p: &[T], n: usize, out: &mut [T]) {
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
pub fn innovation_cov<T: Real>(j: &Sparse<T>, pjt: &[T], n: usize, s_add: &[T], out: &mut [T]) {
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
pub fn whiten_gain<T: Real>(chol: &[T], q: usize, wt: &mut [T], n: usize) {
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
pub fn apply_whitened<T: Real>(
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
    /// `P Jᵀ` (`n × q`); after [`Factor::whiten`], `Wᵀ`.
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
/// documented repair of [`Factor::compute_repaired`] (counted in `health`). A pack returns its
/// straight-path mask: the batch layer redoes a failing lane as one particle. Returns the lanes
/// that have a factor; a particle without one gets weight zero from its filter (a per-particle
/// failure is counted, not returned as an error: it does not end the run).
#[inline]
pub fn factorise<T: Real>(
    factor: &mut Factor<T>,
    p: &[T],
    j: &Sparse<T>,
    s_add: &[T],
    health: &mut Health,
) -> T::Mask {
    let ok = factor.compute(p, j, s_add);
    if T::LANES > 1 || T::mask_lane(ok, 0) {
        return ok;
    }
    let q = factor.q;
    let a = &factor.cov;
    let mut finite = zero::<T>();
    for v in &a[..q * q] {
        finite += *v - *v;
    }
    if !T::mask_lane(finite.eq(zero()), 0) {
        return ok;
    }
    let mut max_diag = zero::<T>();
    for j in 0..q {
        let d = a[j + j * q];
        max_diag = T::select(d.gt(max_diag), d, max_diag);
    }
    let jit = &mut factor.jittered;
    jit[..q * q].copy_from_slice(&a[..q * q]);
    for tau in JITTER_STEPS {
        for j in 0..q {
            let d = a[j + j * q];
            jit[j + j * q] = T::select(
                d.gt(zero()),
                d * T::splat(1.0 + tau),
                d + T::splat(tau) * max_diag,
            );
        }
        let fixed = cholesky(jit, q, &mut factor.chol);
        if T::mask_lane(fixed, 0) {
            health.jitter_added += 1;
            return fixed;
        }
    }
    health.cholesky_failures += 1;
    ok
}

impl Factor<f64> {
    /// [`Factor::compute`] with the documented repair (SPEC §4) for one particle:
    ///
    /// 1. a non-finite entry of `L` → `Err(NonFinite { step, which })`;
    /// 2. Cholesky with the relative pivot test;
    /// 3. on failure the diagonal of `L` is scaled by `1 + τ`, τ = 1e-12, 1e-10, 1e-8, 1e-6 in
    ///    turn (`health.jitter_added` once per factorisation that needed it); a non-positive
    ///    diagonal entry receives `τ` times the largest diagonal entry instead;
    /// 4. if even τ = 1e-6 fails, `health.cholesky_failures` is incremented and
    ///    `Err(NotPositiveDefinite { step, which })` is returned.
    ///
    /// `L` is exactly symmetric by construction, so no symmetrisation is needed here.
    pub fn compute_repaired(
        &mut self,
        p: &[f64],
        j: &Sparse<f64>,
        s_add: &[f64],
        step: usize,
        which: &'static str,
        health: &mut Health,
    ) -> Result<(), FilterError> {
        if self.compute(p, j, s_add) {
            return Ok(());
        }
        factor_with_jitter(&self.cov, self.q, &mut self.chol, step, which, health)
    }
}

/// Steps 1, 3 and 4 of [`Factor::compute_repaired`] for a symmetric `a` (`q × q`) whose plain
/// factorisation failed.
pub fn factor_with_jitter(
    a: &[f64],
    q: usize,
    l: &mut [f64],
    step: usize,
    which: &'static str,
    health: &mut Health,
) -> Result<(), FilterError> {
    if a[..q * q].iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite { step, which });
    }
    let max_diag = (0..q).map(|j| a[j + j * q]).fold(0.0_f64, f64::max);
    let mut jittered = a[..q * q].to_vec();
    for tau in JITTER_STEPS {
        for j in 0..q {
            let d = a[j + j * q];
            jittered[j + j * q] = if d > 0.0 {
                d * (1.0 + tau)
            } else {
                d + tau * max_diag
            };
        }
        if cholesky(&jittered, q, l) {
            health.jitter_added += 1;
            return Ok(());
        }
    }
    health.cholesky_failures += 1;
    Err(FilterError::NotPositiveDefinite { step, which })
}

/// Lower Cholesky factor of a symmetric `a` with the documented repair, for one-off uses (the
/// constant `R`, tests): counts an asymmetry beyond round-off in `health.symmetrised`
/// (`|a_ij − a_ji| > 1e-9 sqrt(a_ii a_jj)`), factorises `(A + Aᵀ)/2`, then as
/// [`Factor::compute_repaired`].
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
    if cholesky(&s, q, &mut l) {
        return Ok(l);
    }
    factor_with_jitter(&s, q, &mut l, step, which, health)?;
    Ok(l)
}

/// A constant Gaussian noise `N(0, R)` factorised once (the measurement noise of the bootstrap
/// PF and of Storvik's weights): every density costs one triangular solve and no logarithm.
#[derive(Debug, Clone)]
pub struct FactoredNoise {
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

    /// `log N(r; 0, R)`; `scratch` has length `q` and is overwritten.
    #[inline]
    pub fn log_density<T: Real>(&self, residual: &[T], scratch: &mut [T]) -> T {
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

    /// The lower factor of `R`.
    pub fn chol(&self) -> &[f64] {
        &self.chol
    }
}
