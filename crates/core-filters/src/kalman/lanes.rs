//! The Gaussian measurement update of [`super::kf`] for four independent problems at once, one
//! per SIMD lane (`wide::f64x4`: one AVX2 register, or two SSE2 registers on baseline x86-64).
//!
//! Why: a particle filter with a Gaussian per particle updates hundreds of small, equally shaped
//! problems per step. One 8-dimensional update is short chains of dependent operations (a 4 × 4
//! Cholesky factor, triangular solves) and columns of 8 that fill two registers at most, so it
//! leaves most of the processor idle; four particles side by side fill it.
//!
//! **Bit for bit the scalar update.** Every lane performs the operations of
//! `kf::update_from_residual` (the update of [`super::kf::gaussian_update`]) in the same order: Rust neither fuses a multiply and
//! an add nor reorders floating-point operations, and `sqrt` and division are correctly rounded
//! in SIMD as in scalar code. Where the scalar code skips an operation (a zero Jacobian or factor
//! entry) a lane keeps its old value by a select, not by adding a zero product, which could turn
//! a `−0` into `+0`. The lanes do only the straight path of the scalar update: a lane whose
//! scalar update would leave it (a non-finite input or result, an innovation covariance that
//! needs the documented repair) is reported in the returned mask, and the caller redoes that
//! problem with the scalar update, which counts and reports it exactly as before.
//!
//! Layout: matrices are column-major with the lanes innermost, `m[c][r]` holding entry `(r, c)`
//! of the four matrices, so every inner loop runs down a contiguous column.

// The index loops and `a = a − b` spell out the scalar update's order of operations, which is
// what makes the lanes exact; iterator forms would hide it.
#![allow(clippy::needless_range_loop, clippy::assign_op_pattern)]

use nalgebra::{SMatrix, SVector};
use wide::{f64x4, CmpEq, CmpGt};

use super::kf::PIVOT_REL_TOL;

/// Problems per lane group.
pub const LANES: usize = 4;

/// `R × C` matrices of four problems, column-major: `m[c][r]` is entry `(r, c)`.
pub type LaneMat<const R: usize, const C: usize> = [[f64x4; R]; C];

/// Vectors of four problems.
pub type LaneVec<const N: usize> = [f64x4; N];

/// A mask lane: all bits set (true) or none (false), as the comparisons of `wide` return.
pub type Mask = f64x4;

/// Lane `b` of a mask.
#[inline]
pub fn lane(mask: Mask, b: usize) -> bool {
    mask.move_mask() & (1 << b) != 0
}

/// The lanes in which every entry is finite: `v − v` is `+0` for a finite `v` and NaN
/// otherwise, as in [`super::kf::all_finite`].
#[inline]
#[allow(clippy::eq_op)] // `v − v` is the test itself, not a mistake.
pub fn finite_lanes<const R: usize, const C: usize>(m: &LaneMat<R, C>) -> Mask {
    // Four independent sums: one running sum would be a chain of dependent additions.
    let mut sums = [f64x4::ZERO; 4];
    for (j, col) in m.iter().enumerate() {
        for (i, v) in col.iter().enumerate() {
            let s = &mut sums[(j * R + i) % 4];
            *s = *s + (*v - *v);
        }
    }
    ((sums[0] + sums[1]) + (sums[2] + sums[3])).cmp_eq(f64x4::ZERO)
}

/// The 4 × 4 transpose: lane `j` of output `i` is lane `i` of input `j`.
#[inline(always)]
fn transpose4(v: [f64x4; 4]) -> [f64x4; 4] {
    let a = v.map(|x| x.to_array());
    std::array::from_fn(|i| f64x4::new([a[0][i], a[1][i], a[2][i], a[3][i]]))
}

/// Gathers four matrices into lanes. Columns whose length is a multiple of four move as 4 × 4
/// blocks (four loads and a transpose instead of sixteen single loads).
#[inline]
pub fn gather_mat<const R: usize, const C: usize>(
    out: &mut LaneMat<R, C>,
    a: [&SMatrix<f64, R, C>; LANES],
) {
    if R % 4 == 0 {
        let chunk = |b: usize, c: usize, r: usize| {
            let s = &a[b].as_slice()[c * R + r..c * R + r + 4];
            f64x4::new([s[0], s[1], s[2], s[3]])
        };
        for c in 0..C {
            for r in (0..R).step_by(4) {
                let t = transpose4(std::array::from_fn(|b| chunk(b, c, r)));
                out[c][r..r + 4].copy_from_slice(&t);
            }
        }
    } else {
        for c in 0..C {
            for r in 0..R {
                out[c][r] = f64x4::new([a[0][(r, c)], a[1][(r, c)], a[2][(r, c)], a[3][(r, c)]]);
            }
        }
    }
}

/// Copies the four lanes into four matrices (the inverse of [`gather_mat`]).
#[inline]
pub fn scatter_all<const R: usize, const C: usize>(
    m: &LaneMat<R, C>,
    mut out: [&mut SMatrix<f64, R, C>; LANES],
) {
    if R % 4 == 0 {
        for c in 0..C {
            for r in (0..R).step_by(4) {
                let t = transpose4([m[c][r], m[c][r + 1], m[c][r + 2], m[c][r + 3]]);
                for (o, v) in out.iter_mut().zip(t) {
                    o.as_mut_slice()[c * R + r..c * R + r + 4].copy_from_slice(&v.to_array());
                }
            }
        }
    } else {
        for (b, o) in out.iter_mut().enumerate() {
            scatter_mat(m, b, o);
        }
    }
}

/// Gathers four vectors into lanes.
#[inline]
pub fn gather_vec<const N: usize>(out: &mut LaneVec<N>, a: [&SVector<f64, N>; LANES]) {
    gather_mat(std::array::from_mut(out), a);
}

/// Writes `a` into lane `b`.
#[inline]
pub fn set_lane_mat<const R: usize, const C: usize>(
    m: &mut LaneMat<R, C>,
    b: usize,
    a: &SMatrix<f64, R, C>,
) {
    for c in 0..C {
        for r in 0..R {
            m[c][r].as_array_mut()[b] = a[(r, c)];
        }
    }
}

/// Writes `a` into lane `b`.
#[inline]
pub fn set_lane_vec<const N: usize>(m: &mut LaneVec<N>, b: usize, a: &SVector<f64, N>) {
    for r in 0..N {
        m[r].as_array_mut()[b] = a[r];
    }
}

/// Lane `b` as a matrix.
#[inline]
pub fn get_lane_mat<const R: usize, const C: usize>(
    m: &LaneMat<R, C>,
    b: usize,
) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|r, c| m[c][r].as_array_ref()[b])
}

/// Copies lane `b` into `out`.
#[inline]
pub fn scatter_mat<const R: usize, const C: usize>(
    m: &LaneMat<R, C>,
    b: usize,
    out: &mut SMatrix<f64, R, C>,
) {
    for c in 0..C {
        for r in 0..R {
            out[(r, c)] = m[c][r].as_array_ref()[b];
        }
    }
}

/// Lane `b` as a vector.
#[inline]
pub fn get_lane_vec<const N: usize>(m: &LaneVec<N>, b: usize) -> SVector<f64, N> {
    SVector::from_fn(|r, _| m[r].as_array_ref()[b])
}

/// `A x` summed as nalgebra sums a matrix–vector product: `Σ_j A[:, j] x_j` over the columns in
/// order, starting from the first product.
#[inline]
pub fn mul_vec<const R: usize, const C: usize>(a: &LaneMat<R, C>, x: &LaneVec<C>) -> LaneVec<R> {
    let mut out = [f64x4::ZERO; R];
    for r in 0..R {
        out[r] = a[0][r] * x[0];
    }
    for j in 1..C {
        for r in 0..R {
            out[r] = a[j][r] * x[j] + out[r];
        }
    }
    out
}

/// The scalar code's `if d != 0.0 { … }` in lanes: `where_nonzero!(d, |keep| body)` runs
/// `body`, which writes each result as `keep(new, old)`, with `keep` returning `new` where `d` is
/// non-zero (as Rust evaluates `!=`, so NaN counts) and `old` elsewhere; not at all when `d` is
/// zero in every lane. The body is expanded twice, once for all four lanes without a select:
/// a select before a store becomes a masked store, which is slow on some processors, and a
/// Jacobian's or factor's zeros are nearly always zero in all four lanes at once. (A closure
/// taking the mask as an `Option` ran the updates about 10% slower.)
macro_rules! where_nonzero {
    ($d:expr, |$keep:ident| $body:expr) => {{
        let nz = !$d.cmp_eq(f64x4::ZERO);
        if nz.all() {
            let $keep = |new: f64x4, _old: f64x4| new;
            $body
        } else if nz.any() {
            let $keep = |new: f64x4, old: f64x4| nz.blend(new, old);
            $body
        }
    }};
}

/// The gain side of a Gaussian update in lanes, as [`super::kf::UpdateFactor::new`] computes
/// it: `P Jᵀ` over the non-zeros of `J` and the lower Cholesky factor `C` of
/// `L = J P Jᵀ + S`.
#[derive(Debug, Clone, Copy)]
pub struct LaneFactor<const N: usize, const NY: usize> {
    /// `pjt[r][i]` is entry `(i, r)` of `P Jᵀ`.
    pjt: [[f64x4; N]; NY],
    /// `chol[j][i]` is entry `(i, j)` of `C`.
    chol: [[f64x4; NY]; NY],
}

impl<const N: usize, const NY: usize> Default for LaneFactor<N, NY> {
    fn default() -> Self {
        Self {
            pjt: [[f64x4::ZERO; N]; NY],
            chol: [[f64x4::ZERO; NY]; NY],
        }
    }
}

impl<const N: usize, const NY: usize> LaneFactor<N, NY> {
    /// Factorises the innovation covariance of every lane. `s_add` (shared by the lanes) must
    /// be exactly symmetric, so that `L` is (the scalar code would otherwise symmetrise it
    /// first). Returns the lanes that took the scalar code's straight path: a non-finite
    /// Jacobian or innovation covariance, or a pivot that would need the documented repair,
    /// leaves a lane out.
    pub fn new(
        p: &LaneMat<N, N>,
        jac: &LaneMat<NY, N>,
        s_add: &SMatrix<f64, NY, NY>,
    ) -> (Self, Mask) {
        debug_assert_eq!(
            *s_add,
            s_add.transpose(),
            "the added covariance must be symmetric"
        );
        let zero = f64x4::ZERO;
        // A non-finite Jacobian makes the scalar innovation covariance non-finite, which the
        // scalar code rejects.
        let mut ok = finite_lanes(jac);
        // P Jᵀ over the non-zeros of J (`sparse_pjt`).
        let mut pjt = [[zero; N]; NY];
        for c in 0..N {
            for r in 0..NY {
                let d = jac[c][r];
                where_nonzero!(d, |keep| for i in 0..N {
                    pjt[r][i] = keep(pjt[r][i] + d * p[c][i], pjt[r][i]);
                });
            }
        }
        // L = J P Jᵀ + S, lower triangle over the non-zeros of J, mirrored (`innovation_cov`).
        let mut l = [[zero; NY]; NY];
        for c in 0..N {
            for i in 0..NY {
                let d = jac[c][i];
                where_nonzero!(d, |keep| for j in 0..=i {
                    l[j][i] = keep(l[j][i] + d * pjt[j][c], l[j][i]);
                });
            }
        }
        for j in 0..NY {
            for i in (j + 1)..NY {
                l[i][j] = l[j][i];
            }
        }
        for j in 0..NY {
            for i in 0..NY {
                l[j][i] = l[j][i] + f64x4::splat(s_add[(i, j)]);
            }
        }
        ok = ok & finite_lanes(&l);
        // Cholesky factor of L (`try_cholesky`); a lane whose pivot fails would need the repair.
        let mut chol = [[zero; NY]; NY];
        let rel_tol = f64x4::splat(PIVOT_REL_TOL);
        for j in 0..NY {
            let mut d = l[j][j];
            for k in 0..j {
                d = d - chol[k][j] * chol[k][j];
            }
            ok = ok & d.cmp_gt(zero) & d.cmp_gt(rel_tol * l[j][j]);
            let ljj = d.sqrt();
            chol[j][j] = ljj;
            let inv = ljj * (f64x4::ONE / d);
            for i in (j + 1)..NY {
                let mut s = l[j][i];
                for k in 0..j {
                    s = s - chol[k][i] * chol[k][j];
                }
                chol[j][i] = s * inv;
            }
        }
        (Self { pjt, chol }, ok)
    }

    /// Lane `b`'s factor `C`.
    pub fn chol(&self, b: usize) -> SMatrix<f64, NY, NY> {
        get_lane_mat(&self.chol, b)
    }

    /// `e = C⁻¹ r` (`solve_lower_in_place`).
    pub fn whiten(&self, residual: &LaneVec<NY>) -> LaneVec<NY> {
        let chol = &self.chol;
        let inv_diag: [f64x4; NY] = std::array::from_fn(|i| f64x4::ONE / chol[i][i]);
        let mut e = *residual;
        for i in 0..NY {
            let mut s = e[i];
            for k in 0..i {
                s = s - chol[k][i] * e[k];
            }
            e[i] = s * inv_diag[i];
        }
        e
    }

    /// `m ← m + Wᵀ e`, `P ← P − Wᵀ W` for the whitened innovation `e`, as
    /// [`super::kf::UpdateFactor::apply_whitened`]. Returns the lanes whose gain, mean and
    /// covariance came out finite (the others would be the scalar code's errors). Consumes the
    /// factor: its `P Jᵀ` becomes `Wᵀ` in place.
    pub fn apply_whitened(
        self,
        m: &mut LaneVec<N>,
        p: &mut LaneMat<N, N>,
        e: &LaneVec<NY>,
    ) -> Mask {
        let chol = &self.chol;
        // Wᵀ = (P Jᵀ) C⁻ᵀ column by column: wt[i][r] is entry (r, i).
        let mut wt = self.pjt;
        for i in 0..NY {
            for k in 0..i {
                let c = chol[k][i];
                where_nonzero!(c, |keep| for r in 0..N {
                    wt[i][r] = keep(wt[i][r] - c * wt[k][r], wt[i][r]);
                });
            }
            let inv = f64x4::ONE / chol[i][i];
            for r in 0..N {
                wt[i][r] = wt[i][r] * inv;
            }
        }
        let gain = mul_vec(&wt, e);
        let new_m: LaneVec<N> = std::array::from_fn(|r| m[r] + gain[r]);
        let mut ok = finite_lanes(&[new_m]) & finite_lanes(&wt);
        // P − Wᵀ W on the lower triangle (the scalar update computes the upper one too, then
        // overwrites it with the mirror), then mirrored.
        for c in 0..N {
            for d in 0..NY {
                let a = wt[d][c];
                for r in c..N {
                    p[c][r] = p[c][r] - a * wt[d][r];
                }
            }
        }
        for c in 0..N {
            for r in (c + 1)..N {
                p[r][c] = p[c][r];
            }
        }
        ok = ok & finite_lanes(p);
        *m = new_m;
        ok
    }
}

/// The Gaussian update `m ← m + Wᵀ e`, `P ← P − Wᵀ W` with `e = C⁻¹ residual`, `W = C⁻¹ J P`,
/// `C Cᵀ = J P Jᵀ + S`, in every lane, exactly as `kf::update_from_residual` (the update of
/// [`super::kf::gaussian_update`]) computes it from the residual `y − ŷ`.
///
/// Returns the lanes that took the straight path, the factor `C` (`chol[j][i]` is entry
/// `(i, j)`) and `e`, from which a caller may score the measurement. In the other lanes `m` and `p` hold meaningless values: the caller
/// redoes those problems with the scalar update from their original moments.
pub fn gaussian_update<const N: usize, const NY: usize>(
    m: &mut LaneVec<N>,
    p: &mut LaneMat<N, N>,
    residual: &LaneVec<NY>,
    jac: &LaneMat<NY, N>,
    s_add: &SMatrix<f64, NY, NY>,
) -> (Mask, LaneMat<NY, NY>, LaneVec<NY>) {
    // The scalar update first rejects a non-finite residual.
    let residual_ok = finite_lanes(&[*residual]);
    let (factor, factor_ok) = LaneFactor::new(p, jac, s_add);
    let e = factor.whiten(residual);
    let chol = factor.chol;
    let applied = factor.apply_whitened(m, p, &e);
    (residual_ok & factor_ok & applied, chol, e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::health::Health;
    use crate::kalman::kf::update_from_residual;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// A random update problem with the chain's kind of sparsity (some Jacobian entries zero),
    /// sometimes broken: a non-finite residual or Jacobian entry, or a prior so tight against a
    /// large `J` that the innovation covariance loses definiteness to round-off.
    #[allow(clippy::type_complexity)]
    fn problem(
        rng: &mut Xoshiro256PlusPlus,
    ) -> (
        SVector<f64, 8>,
        SMatrix<f64, 8, 8>,
        SVector<f64, 3>,
        SMatrix<f64, 3, 8>,
    ) {
        let a = SMatrix::<f64, 8, 8>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let scale = SVector::<f64, 8>::from_fn(|_, _| 10f64.powf(rng.random_range(-3.0..1.0)));
        let mut p = SMatrix::<f64, 8, 8>::from_diagonal(&scale)
            * (a * a.transpose())
            * SMatrix::<f64, 8, 8>::from_diagonal(&scale);
        // Exactly symmetric, as the filters keep it.
        for c in 0..8 {
            for r in (c + 1)..8 {
                p[(c, r)] = p[(r, c)];
            }
        }
        let m = SVector::<f64, 8>::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let mut jac = SMatrix::<f64, 3, 8>::from_fn(|_, _| {
            if rng.random_bool(0.4) {
                0.0
            } else {
                rng.random_range(-5.0..5.0)
            }
        });
        let mut residual = SVector::<f64, 3>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        match rng.random_range(0..12) {
            0 => residual[rng.random_range(0..3)] = f64::NAN,
            1 => jac[(rng.random_range(0..3), rng.random_range(0..8))] = f64::INFINITY,
            // Rank-deficient J P Jᵀ with a tiny S: needs the repair, or fails.
            2 => {
                let row = jac.row(0).into_owned();
                jac.set_row(1, &row);
            }
            _ => {}
        }
        (m, p, residual, jac)
    }

    #[test]
    fn lanes_update_bit_for_bit_as_the_scalar_update() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let s_add_cases = [
            SMatrix::<f64, 3, 3>::from_diagonal_element(0.1),
            SMatrix::<f64, 3, 3>::from_diagonal_element(1e-20),
            SMatrix::<f64, 3, 3>::new(0.5, 0.1, 0.0, 0.1, 0.4, -0.05, 0.0, -0.05, 0.3),
        ];
        let (mut straight, mut redone) = (0, 0);
        for round in 0..600 {
            let s_add = s_add_cases[round % 3];
            let problems: [_; LANES] = std::array::from_fn(|_| problem(&mut rng));
            let (mut m, mut p) = ([f64x4::ZERO; 8], [[f64x4::ZERO; 8]; 8]);
            let mut residual = [f64x4::ZERO; 3];
            let mut jac = [[f64x4::ZERO; 3]; 8];
            for (b, (mb, pb, rb, jb)) in problems.iter().enumerate() {
                set_lane_vec(&mut m, b, mb);
                set_lane_mat(&mut p, b, pb);
                set_lane_vec(&mut residual, b, rb);
                set_lane_mat(&mut jac, b, jb);
            }
            let (ok, _, _) = gaussian_update(&mut m, &mut p, &residual, &jac, &s_add);
            for (b, (mb, pb, rb, jb)) in problems.iter().enumerate() {
                let (mut ms, mut ps) = (*mb, *pb);
                let mut health = Health::default();
                let scalar = update_from_residual(&mut ms, &mut ps, rb, jb, &s_add, 1, &mut health);
                // The straight path is exactly the scalar update without repair or error.
                let straight_scalar = scalar.is_ok() && health == Health::default();
                assert_eq!(lane(ok, b), straight_scalar, "lane {b} of round {round}");
                if lane(ok, b) {
                    straight += 1;
                    let (ml, pl) = (get_lane_vec(&m, b), get_lane_mat(&p, b));
                    for (x, y) in ms.iter().chain(ps.iter()).zip(ml.iter().chain(pl.iter())) {
                        assert_eq!(x.to_bits(), y.to_bits(), "lane {b} of round {round}");
                    }
                } else {
                    redone += 1;
                }
            }
        }
        // Both paths were exercised.
        assert!(straight > 1500 && redone > 200, "{straight} {redone}");
    }

    #[test]
    fn mul_vec_sums_as_nalgebra() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for _ in 0..200 {
            let a = SMatrix::<f64, 3, 8>::from_fn(|_, _| rng.random_range(-1e3..1e3));
            let x = SVector::<f64, 8>::from_fn(|_, _| rng.random_range(-1e3..1e3));
            let (mut al, mut xl) = ([[f64x4::ZERO; 3]; 8], [f64x4::ZERO; 8]);
            set_lane_mat(&mut al, 2, &a);
            set_lane_vec(&mut xl, 2, &x);
            let got = get_lane_vec(&mul_vec(&al, &xl), 2);
            for (p, q) in (a * x).iter().zip(got.iter()) {
                assert_eq!(p.to_bits(), q.to_bits());
            }
        }
    }
}
