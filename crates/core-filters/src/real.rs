//! The number type of the Gaussian algebra: one particle (`f64`) or a pack of particles processed
//! side by side in SIMD lanes ([`Pack`], four `f64` in one `wide::f64x4`).
//!
//! Why one trait: the marginalized filters update hundreds of small, equally shaped Gaussians per
//! step. The per-particle step of each filter is written once, generic over [`Real`], and reads
//! like the SPEC; the batch layer ([`crate::smc::batch`]) runs the *same* function with
//! `T = Pack`, four particles per operation. Every operation used here (`+ − × ÷ √`, comparisons
//! and selects) is correctly rounded in SIMD exactly as in scalar code, and Rust never fuses or
//! reorders floating-point operations, so lane `b` of a `Pack` computation is bit for bit the
//! `f64` computation of particle `b`. Functions without an exact SIMD form (`powf`, `ln`) go
//! through [`Real::per_lane`], which calls the scalar function on each lane.
//!
//! Decisions that differ between particles (a Cholesky pivot that fails, a non-finite result) are
//! returned as a [`Real::Mask`]; the batch layer hands a lane whose mask is false back to the
//! scalar path, which takes the documented repair or reports the failure exactly as a lone
//! particle would.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, BitAnd, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use wide::{f64x4, CmpEq, CmpGt, CmpLe, CmpLt};

/// One particle's number (`f64`) or a pack of particles' numbers, one per lane.
pub trait Real:
    Copy
    + Default
    + Debug
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// Particles per value (1 for `f64`).
    const LANES: usize;
    /// A lane-wise truth value.
    type Mask: Copy + Debug + BitAnd<Output = Self::Mask>;

    /// `v` in every lane.
    fn splat(v: f64) -> Self;
    /// Lane `b` (`b < LANES`).
    fn lane(self, b: usize) -> f64;
    /// Sets lane `b`.
    fn set_lane(&mut self, b: usize, v: f64);
    /// A value whose lane `b` is `f(b)`.
    fn from_lanes(f: impl FnMut(usize) -> f64) -> Self;
    /// Correctly rounded square root, lane-wise.
    fn sqrt(self) -> Self;
    /// Absolute value, lane-wise (exact).
    fn abs(self) -> Self;
    /// Lane-wise `self > other`.
    fn gt(self, other: Self) -> Self::Mask;
    /// Lane-wise `self < other`.
    fn lt(self, other: Self) -> Self::Mask;
    /// Lane-wise `self <= other`.
    fn le(self, other: Self) -> Self::Mask;
    /// Lane-wise `self == other`.
    fn eq(self, other: Self) -> Self::Mask;
    /// Lane-wise `if mask { a } else { b }`.
    fn select(mask: Self::Mask, a: Self, b: Self) -> Self;
    /// The mask that is true in every lane.
    fn all_true() -> Self::Mask;
    /// Lane `b` of a mask.
    fn mask_lane(mask: Self::Mask, b: usize) -> bool;
    /// Whether the mask is true in any lane.
    fn any(mask: Self::Mask) -> bool;
    /// Negation of a mask.
    fn not(mask: Self::Mask) -> Self::Mask;

    /// Applies a scalar function of `K` inputs and `M` outputs to each lane (for `powf`, `ln`
    /// and branches on a particle's own values); bit for bit the scalar function in each lane.
    #[inline(always)]
    fn per_lane<const K: usize, const M: usize>(
        inputs: [Self; K],
        f: impl Fn([f64; K]) -> [f64; M],
    ) -> [Self; M] {
        let mut out = [Self::splat(0.0); M];
        for b in 0..Self::LANES {
            let r = f(std::array::from_fn(|i| inputs[i].lane(b)));
            for (o, v) in out.iter_mut().zip(r) {
                o.set_lane(b, v);
            }
        }
        out
    }

    /// `ln` lane by lane (the scalar `f64::ln` in each lane).
    #[inline]
    fn ln(self) -> Self {
        let [y] = Self::per_lane([self], |[x]| [x.ln()]);
        y
    }

    /// `P ← P − Wᵀ W` on the lower triangle of the `n × n` column-major `p`, with `wt = Wᵀ`
    /// (`n × q`): column `c` of `P` loses `Σ_d Wᵀ[c, d] · Wᵀ[c.., d]`. This rank-`q` downdate is
    /// the largest cost of a Gaussian update (`n² q / 2`); `f64` hands large problems to faer.
    #[inline]
    fn downdate_lower(p: &mut [Self], n: usize, wt: &[Self], q: usize) {
        downdate_lower_loops(p, n, wt, q);
    }

    /// The lanes in which `self` is finite: `v − v` is `+0` for finite `v`, NaN otherwise.
    #[inline]
    #[allow(clippy::eq_op)] // `v − v` is the test itself, not a mistake.
    fn finite(self) -> Self::Mask {
        (self - self).eq(Self::splat(0.0))
    }
}

/// The loop form of [`Real::downdate_lower`], the same order of operations for every lane type.
#[inline]
pub(crate) fn downdate_lower_loops<T: Real>(p: &mut [T], n: usize, wt: &[T], q: usize) {
    for c in 0..n {
        let col = &mut p[c * n..(c + 1) * n];
        for d in 0..q {
            let wd = &wt[d * n..(d + 1) * n];
            let a = wd[c];
            for r in c..n {
                col[r] -= a * wd[r];
            }
        }
    }
}

/// Smallest dimension whose downdate [`Real::downdate_lower`] hands to faer for one particle.
/// Below it the plain loops are as fast (the blocked kernel's set-up dominates); above it faer's
/// cache-blocked, vectorised product wins (measured in `benches/`).
pub(crate) const FAER_MIN_DIM: usize = 64;

impl Real for f64 {
    const LANES: usize = 1;
    type Mask = bool;

    /// Large problems go to faer's triangular product (`P += (−1) Wᵀ W` on the lower triangle);
    /// small ones to the plain loops.
    #[inline]
    fn downdate_lower(p: &mut [f64], n: usize, wt: &[f64], q: usize) {
        if n < FAER_MIN_DIM {
            return downdate_lower_loops(p, n, wt, q);
        }
        use faer::linalg::matmul::triangular::{matmul, BlockStructure};
        use faer::{Accum, MatMut, MatRef, Par};
        let dst = MatMut::from_column_major_slice_mut(&mut p[..n * n], n, n);
        let w = MatRef::from_column_major_slice(&wt[..n * q], n, q);
        matmul(
            dst,
            BlockStructure::TriangularLower,
            Accum::Add,
            w,
            BlockStructure::Rectangular,
            w.transpose(),
            BlockStructure::Rectangular,
            -1.0,
            Par::Seq,
        );
    }

    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn lane(self, _b: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn set_lane(&mut self, _b: usize, v: f64) {
        *self = v;
    }
    #[inline(always)]
    fn from_lanes(mut f: impl FnMut(usize) -> f64) -> Self {
        f(0)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn gt(self, other: Self) -> bool {
        self > other
    }
    #[inline(always)]
    fn lt(self, other: Self) -> bool {
        self < other
    }
    #[inline(always)]
    fn le(self, other: Self) -> bool {
        self <= other
    }
    #[inline(always)]
    fn eq(self, other: Self) -> bool {
        self == other
    }
    #[inline(always)]
    fn select(mask: bool, a: Self, b: Self) -> Self {
        if mask {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    fn all_true() -> bool {
        true
    }
    #[inline(always)]
    fn mask_lane(mask: bool, _b: usize) -> bool {
        mask
    }
    #[inline(always)]
    fn any(mask: bool) -> bool {
        mask
    }
    #[inline(always)]
    fn not(mask: bool) -> bool {
        !mask
    }
    #[inline(always)]
    fn ln(self) -> Self {
        f64::ln(self)
    }
}

/// Four particles' numbers in the lanes of one `wide::f64x4` (one AVX2 register, or two SSE2
/// registers on a baseline x86-64 build; the results are the same either way).
#[derive(Clone, Copy, Default, PartialEq)]
#[repr(transparent)]
pub struct Pack(pub f64x4);

/// Lanes of a [`Pack`].
pub(crate) const PACK_LANES: usize = 4;

impl Debug for Pack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Pack{:?}", self.0.to_array())
    }
}

/// A lane mask of a [`Pack`]: all bits set (true) or none (false) per lane.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct PackMask(f64x4);

impl BitAnd for PackMask {
    type Output = PackMask;
    #[inline(always)]
    fn bitand(self, rhs: PackMask) -> PackMask {
        PackMask(self.0 & rhs.0)
    }
}

macro_rules! pack_binop {
    ($tr:ident, $f:ident, $atr:ident, $af:ident, $op:tt) => {
        impl $tr for Pack {
            type Output = Pack;
            #[inline(always)]
            fn $f(self, rhs: Pack) -> Pack {
                Pack(self.0 $op rhs.0)
            }
        }
        impl $atr for Pack {
            #[inline(always)]
            fn $af(&mut self, rhs: Pack) {
                self.0 = self.0 $op rhs.0;
            }
        }
    };
}
pack_binop!(Add, add, AddAssign, add_assign, +);
pack_binop!(Sub, sub, SubAssign, sub_assign, -);
pack_binop!(Mul, mul, MulAssign, mul_assign, *);

impl Div for Pack {
    type Output = Pack;
    #[inline(always)]
    fn div(self, rhs: Pack) -> Pack {
        Pack(self.0 / rhs.0)
    }
}

impl Neg for Pack {
    type Output = Pack;
    #[inline(always)]
    fn neg(self) -> Pack {
        Pack(-self.0)
    }
}

impl Real for Pack {
    const LANES: usize = PACK_LANES;
    type Mask = PackMask;

    #[inline(always)]
    fn splat(v: f64) -> Self {
        Pack(f64x4::splat(v))
    }
    #[inline(always)]
    fn lane(self, b: usize) -> f64 {
        self.0.as_array_ref()[b]
    }
    #[inline(always)]
    fn set_lane(&mut self, b: usize, v: f64) {
        self.0.as_array_mut()[b] = v;
    }
    #[inline(always)]
    fn from_lanes(mut f: impl FnMut(usize) -> f64) -> Self {
        Pack(f64x4::new([f(0), f(1), f(2), f(3)]))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Pack(self.0.sqrt())
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Pack(self.0.abs())
    }
    #[inline(always)]
    fn gt(self, other: Self) -> PackMask {
        PackMask(self.0.cmp_gt(other.0))
    }
    #[inline(always)]
    fn lt(self, other: Self) -> PackMask {
        PackMask(self.0.cmp_lt(other.0))
    }
    #[inline(always)]
    fn le(self, other: Self) -> PackMask {
        PackMask(self.0.cmp_le(other.0))
    }
    #[inline(always)]
    fn eq(self, other: Self) -> PackMask {
        PackMask(self.0.cmp_eq(other.0))
    }
    #[inline(always)]
    fn select(mask: PackMask, a: Self, b: Self) -> Self {
        Pack(mask.0.blend(a.0, b.0))
    }
    #[inline(always)]
    fn all_true() -> PackMask {
        PackMask(f64x4::splat(0.0).cmp_eq(f64x4::splat(0.0)))
    }
    #[inline(always)]
    fn mask_lane(mask: PackMask, b: usize) -> bool {
        mask.0.move_mask() & (1 << b) != 0
    }
    #[inline(always)]
    fn any(mask: PackMask) -> bool {
        mask.0.move_mask() != 0
    }
    #[inline(always)]
    fn not(mask: PackMask) -> PackMask {
        PackMask(!mask.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_lanes_are_the_scalar_operations_bit_for_bit() {
        let a = [1.3, -0.0, 7.25e-300, f64::MAX];
        let b = [0.7, 3.0, -2.5, 1e-10];
        let (pa, pb) = (Pack::from_lanes(|i| a[i]), Pack::from_lanes(|i| b[i]));
        for i in 0..4 {
            assert_eq!((pa + pb).lane(i).to_bits(), (a[i] + b[i]).to_bits());
            assert_eq!((pa - pb).lane(i).to_bits(), (a[i] - b[i]).to_bits());
            assert_eq!((pa * pb).lane(i).to_bits(), (a[i] * b[i]).to_bits());
            assert_eq!((pa / pb).lane(i).to_bits(), (a[i] / b[i]).to_bits());
            assert_eq!(
                pa.abs().sqrt().lane(i).to_bits(),
                a[i].abs().sqrt().to_bits()
            );
            assert_eq!(pa.abs().ln().lane(i).to_bits(), a[i].abs().ln().to_bits());
            assert_eq!(Pack::mask_lane(pa.gt(pb), i), a[i] > b[i]);
        }
    }

    #[test]
    fn large_downdates_by_faer_equal_the_loops_to_round_off() {
        let (n, q) = (FAER_MIN_DIM + 17, 9);
        let wt: Vec<f64> = (0..n * q)
            .map(|i| ((i * 7919) % 1000) as f64 / 500.0 - 1.0)
            .collect();
        let p0: Vec<f64> = (0..n * n)
            .map(|i| ((i * 104729) % 997) as f64 / 100.0)
            .collect();
        let (mut a, mut b) = (p0.clone(), p0.clone());
        f64::downdate_lower(&mut a, n, &wt, q);
        downdate_lower_loops(&mut b, n, &wt, q);
        for c in 0..n {
            for r in c..n {
                let (x, y) = (a[r + c * n], b[r + c * n]);
                assert!(
                    (x - y).abs() <= 1e-12 * (1.0 + y.abs()),
                    "({r}, {c}): {x} vs {y}"
                );
            }
            // The upper triangle is not touched.
            for r in 0..c {
                assert_eq!(a[r + c * n], p0[r + c * n]);
            }
        }
    }

    #[test]
    fn finite_and_select() {
        let p = Pack::from_lanes(|i| [1.0, f64::NAN, f64::INFINITY, -3.0][i]);
        let m = p.finite();
        assert_eq!(
            (0..4).map(|i| Pack::mask_lane(m, i)).collect::<Vec<_>>(),
            [true, false, false, true]
        );
        let s = Pack::select(m, p, Pack::splat(0.0));
        assert_eq!(s.lane(1), 0.0);
        assert_eq!(s.lane(3), -3.0);
        assert!(!Pack::any(Pack::not(Pack::all_true())));
        assert!(!f64::NAN.finite() && 2.0_f64.finite());
    }
}
