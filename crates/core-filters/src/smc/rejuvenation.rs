//! Rejuvenation of the sampled static parameters: the Liu–West (2001) kernel-shrinkage move.
//!
//! A sampled entry that no stage of a transition sets (the Bouc–Wen exponent n of the MLN-RBPF,
//! Storvik and MPF-EKF2 partitions) is copied from ancestor to particle and never moved, so
//! every resampling removes values and none is ever made: after a few hundred resamplings a
//! filter holds a handful of distinct values. The runner ([`super::runner`]) can move such
//! entries right after it resamples, when the particles are equally weighted:
//!
//! for every static parameter j, in an unbounded coordinate `u = T(θ)` ([`Support`]), with `ū`
//! and `V` the mean and variance (divisor `Np`) of `u` over the resampled particles,
//!
//! `u_i ← a·u_i + (1 − a)·ū + h·√V·ε_i`,  `a = (3δ − 1)/(2δ)`,  `h² = 1 − a²`,
//!
//! `ε_i` standard normal, `δ` the discount ([`LiuWest`]), then `θ_i = T⁻¹(u_i)`. The new cloud has
//! mean `ū` and variance `a²V + h²V = V` in expectation: the move keeps the first two moments of
//! `u` and gives the static parameter new values.
//!
//! Draws: one standard normal per particle and static parameter, parameter by parameter, particle
//! by particle, from the filter's stream that the runner resamples with, so a run stays a
//! function of its seed. A model declares its static parameters and their supports
//! ([`super::model::Partition::static_params`]); a model that declares none is never moved and
//! takes no draw.

use rand_distr::{Distribution, StandardNormal};

use crate::rng::StreamRng;

use super::store::Particles;

/// Smallest distance from a bound of an [`Support::Interval`], as a fraction of its width, at
/// which a value enters the transform: a value on a bound (the prior `U(lo, hi)` can draw `lo`)
/// or within this margin of it is moved this far inside, so that its logit is finite
/// (|u| ≤ 20.8).
pub(crate) const BOUND_MARGIN: f64 = 1e-9;

/// Support of a static parameter, from its prior, and the transform to an unbounded coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Support {
    /// `[lo, hi]` (finite, `lo < hi`): `u = logit((θ − lo)/(hi − lo))`.
    Interval { lo: f64, hi: f64 },
    /// `(lo, ∞)`: `u = ln(θ − lo)`.
    Above { lo: f64 },
}

impl Support {
    /// `u = T(θ)`. A value on or outside a bound is first brought inside: within
    /// `BOUND_MARGIN`·(hi − lo) of a bound of an interval, at least the smallest positive
    /// normal number above `lo` for a half-line. Finite for every finite `θ`.
    #[inline]
    pub fn to_unbounded(self, theta: f64) -> f64 {
        match self {
            Support::Interval { lo, hi } => {
                let p = ((theta - lo) / (hi - lo)).clamp(BOUND_MARGIN, 1.0 - BOUND_MARGIN);
                (p / (1.0 - p)).ln()
            }
            Support::Above { lo } => (theta - lo).max(f64::MIN_POSITIVE).ln(),
        }
    }

    /// `θ = T⁻¹(u)`, strictly inside the support: for an interval within `BOUND_MARGIN` of
    /// the bounds as [`Support::to_unbounded`] and never on a bound (also where the width is
    /// below the rounding of `lo`); for a half-line above `lo` and at most `f64::MAX`.
    #[inline]
    pub fn from_unbounded(self, u: f64) -> f64 {
        match self {
            Support::Interval { lo, hi } => {
                let p = (1.0 / (1.0 + (-u).exp())).clamp(BOUND_MARGIN, 1.0 - BOUND_MARGIN);
                (lo + (hi - lo) * p).clamp(lo.next_up(), hi.next_down())
            }
            Support::Above { lo } => (lo + u.exp()).clamp(lo.next_up(), f64::MAX),
        }
    }

    /// Whether `theta` lies strictly inside the support.
    pub fn contains_strictly(self, theta: f64) -> bool {
        match self {
            Support::Interval { lo, hi } => lo < theta && theta < hi,
            Support::Above { lo } => lo < theta && theta <= f64::MAX,
        }
    }
}

/// A static entry of the sampled block: its index and its support.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticParam {
    /// Index into the sampled block.
    pub index: usize,
    pub support: Support,
}

/// A discount outside `[1/3, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "the Liu–West discount δ = {0} is not in [1/3, 1] (the shrinkage a = (3δ − 1)/(2δ) must lie \
     in [0, 1]; typical δ: 0.95–0.99)"
)]
pub struct DiscountError(pub f64);

/// The Liu–West kernel with discount `δ` (module docs): shrinkage `a = (3δ − 1)/(2δ)` and
/// kernel spread `h = √(1 − a²)`. `δ = 1` is no move; `δ = 1/3` replaces every value by a draw of
/// `N(ū, V)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiuWest {
    discount: f64,
}

impl LiuWest {
    /// The kernel of discount `δ ∈ [1/3, 1]`; otherwise (or not finite) a typed error.
    pub fn new(discount: f64) -> Result<Self, DiscountError> {
        if (1.0 / 3.0..=1.0).contains(&discount) {
            Ok(Self { discount })
        } else {
            Err(DiscountError(discount))
        }
    }

    pub fn discount(&self) -> f64 {
        self.discount
    }

    /// `a = (3δ − 1)/(2δ)`.
    pub fn shrinkage(&self) -> f64 {
        (3.0 * self.discount - 1.0) / (2.0 * self.discount)
    }

    /// `h = √(1 − a²)`.
    pub fn spread(&self) -> f64 {
        let a = self.shrinkage();
        (1.0 - a * a).max(0.0).sqrt()
    }

    /// Whether the kernel moves anything (`h > 0`, i.e. `δ < 1`).
    pub fn moves(&self) -> bool {
        self.spread() > 0.0
    }

    /// The move of one parameter's values `u` (equally weighted): `u_i ← a·u_i + (1 − a)·ū +
    /// h·√V·ε_i` with `ε_i = eps()` in particle order, `ū` and `V` the mean and variance of `u`
    /// (divisor `u.len()`). Returns `false` and leaves `u` (and the draws) untouched when `u` is
    /// empty or holds a non-finite value.
    pub fn shrink(&self, u: &mut [f64], mut eps: impl FnMut() -> f64) -> bool {
        let n = u.len() as f64;
        if u.is_empty() || u.iter().any(|v| !v.is_finite()) {
            return false;
        }
        let mean = u.iter().sum::<f64>() / n;
        let var = u.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        let (a, h) = (self.shrinkage(), self.spread());
        let (centre, scale) = ((1.0 - a) * mean, h * var.sqrt());
        for v in u.iter_mut() {
            *v = a * *v + centre + scale * eps();
        }
        true
    }
}

/// The move as the runner applies it: the kernel, the static parameters, and a buffer of one
/// value per particle (allocated once).
pub struct Rejuvenation {
    kernel: LiuWest,
    params: Vec<StaticParam>,
    u: Vec<f64>,
}

impl Rejuvenation {
    /// The move of `params` for `np` particles; `None` when there is nothing to move (no static
    /// parameter, or `δ = 1`), so that a run without a move takes no extra draw.
    pub fn new(kernel: LiuWest, params: &[StaticParam], np: usize) -> Option<Self> {
        (kernel.moves() && !params.is_empty()).then(|| Self {
            kernel,
            params: params.to_vec(),
            u: vec![0.0; np],
        })
    }

    /// Moves every static parameter of the (equally weighted) `particles`, with the draws of
    /// `rng` (module docs). No allocation.
    pub fn apply(&mut self, particles: &mut Particles, rng: &mut StreamRng) {
        let np = particles.len();
        assert_eq!(np, self.u.len(), "one buffer entry per particle");
        for p in &self.params {
            let (j, support) = (p.index, p.support);
            for (i, u) in self.u.iter_mut().enumerate() {
                *u = support.to_unbounded(particles.sampled(i)[j]);
            }
            if self
                .kernel
                .shrink(&mut self.u, || StandardNormal.sample(&mut *rng))
            {
                for (i, u) in self.u.iter().enumerate() {
                    particles.particle_mut(i).sampled[j] = support.from_unbounded(*u);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_discount_is_checked_and_gives_the_liu_west_constants() {
        for bad in [0.0, 0.1, 0.33, 1.0 + 1e-12, f64::NAN, f64::INFINITY, -0.9] {
            assert_eq!(LiuWest::new(bad).unwrap_err().0.to_bits(), bad.to_bits());
        }
        let k = LiuWest::new(0.98).unwrap();
        assert!((k.shrinkage() - 1.94 / 1.96).abs() < 1e-15);
        assert!((k.shrinkage().powi(2) + k.spread().powi(2) - 1.0).abs() < 1e-15);
        assert!(k.moves());
        assert!(!LiuWest::new(1.0).unwrap().moves());
        let third = LiuWest::new(1.0 / 3.0).unwrap();
        assert_eq!((third.shrinkage(), third.spread()), (0.0, 1.0));
    }

    #[test]
    fn transforms_invert_each_other_inside_the_support() {
        let s = Support::Interval { lo: 1.0, hi: 5.0 };
        for theta in [1.001, 1.5, 3.0, 4.999] {
            assert!((s.from_unbounded(s.to_unbounded(theta)) - theta).abs() < 1e-12);
        }
        let h = Support::Above { lo: 0.0 };
        for theta in [1e-6, 0.3, 2.0, 1e6] {
            let back = h.from_unbounded(h.to_unbounded(theta));
            assert!((back - theta).abs() <= 1e-14 * theta);
        }
    }
}
