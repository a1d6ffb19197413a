//! Central credible intervals of a scalar posterior (SPEC §9 "Calibration").
//!
//! A particle filter's posterior of one parameter θ has one of two shapes (SPEC §5, §7):
//! - a **weighted sample** `Σ_i w_i δ(θ − θ_i)` when θ is sampled (the bootstrap PF's parameters,
//!   the exponent n of the marginalised filters): [`WeightedSample`];
//! - a **Gaussian mixture** `Σ_i w_i N(θ; μ_i, σ_i²)` when θ is marginalised (per-particle Kalman
//!   means and variances of k, c, β, γ): [`GaussianMixture`].
//!
//! ## Quantile definition
//! For both shapes the p-quantile is the generalised inverse of the (right-continuous) CDF,
//!
//! ```text
//! Q(p) = inf { x : F(x) ≥ p },   0 < p < 1,
//! ```
//!
//! and the central q-credible interval is `[Q((1 − q)/2), Q((1 + q)/2)]`. For a weighted sample
//! F is the weighted empirical CDF (a step function), so Q(p) is the smallest particle value
//! whose cumulative weight reaches p; tied values are one step of their summed weight and
//! zero-weight particles never appear. A mixture whose variances are all zero is the same step
//! function, and [`GaussianMixture`] returns exactly the same quantiles as [`WeightedSample`]
//! for it. Weights need not be normalised: they are divided by their sum.
//!
//! ## Normal CDF
//! Φ(z) = erfc(−z/√2)/2 with the `erfc` of the `libm` crate (the Rust port of FreeBSD msun /
//! Sun fdlibm, maintained by the Rust project, already in our dependency tree): its rational
//! approximations have errors below 2^−57, so erfc is within about one ulp, relative, in the far
//! tails too. Rounding z/√2 adds about z² ulps to Φ(−z) (tested against mpmath within
//! 4 (1 + z²) ulps up to z = 37, where Φ ≈ 6e−300). `libm` is preferred to a hand-written erfc
//! (which would have to match that) and to `statrs` (a whole statistics crate for one
//! function). Upper quantiles (p > ½) are solved on the survival function
//! `S(x) = Σ w_i Φ(−z_i)` so that `1 − F` never loses relative accuracy by cancellation in the
//! upper tail.
//!
//! Nothing here allocates except [`WeightedSample`]'s buffer, which is reused by
//! [`WeightedSample::set`].

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The nominal levels reported for every parameter: central 50 %, 90 % and 95 % intervals.
pub const STANDARD_LEVELS: [f64; 3] = [0.5, 0.9, 0.95];

/// Tolerance of a mixture quantile relative to the smallest component s.d. (the scale on which
/// the CDF varies fastest): a root finder stops within `REL_TOL · min σ_i + 4 ε |x|`.
pub(crate) const REL_TOL: f64 = 1e-12;

/// Half-width of the initial bracket of a mixture quantile, in component standard deviations:
/// Φ(−10) ≈ 7.6e−24, below any probability a credible interval asks for.
const BRACKET_SDS: f64 = 10.0;

/// Iteration cap of the safeguarded Newton iteration. Bisection alone needs
/// log2(bracket width / tolerance) ≈ 45 + log2(max σ / min σ) iterations, so the cap is reached
/// only for component scales more than 10¹⁰⁰ apart.
const MAX_ITER: usize = 400;

/// Points of known CDF value kept between the quantiles of
/// [`GaussianMixture::central_intervals`].
const KNOWN: usize = 16;

/// A central credible interval `[lo, hi]` at level `level` (e.g. 0.9 for the 90 % interval).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CredibleInterval {
    pub level: f64,
    pub lo: f64,
    pub hi: f64,
}

impl CredibleInterval {
    /// Whether `x` lies in the closed interval `[lo, hi]`.
    pub fn contains(&self, x: f64) -> bool {
        self.lo <= x && x <= self.hi
    }

    /// `hi − lo`.
    pub fn width(&self) -> f64 {
        self.hi - self.lo
    }
}

/// Why a credible interval could not be computed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CredibleError {
    /// No particles (or no weighted sample has been set).
    #[error("the posterior has no particles")]
    Empty,
    /// Two input slices of different lengths.
    #[error("{what} has {got} entries but the weights have {expected}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// A NaN or infinite input.
    #[error("{what}[{index}] = {value} is not finite")]
    NonFinite {
        what: &'static str,
        index: usize,
        value: f64,
    },
    /// A negative weight.
    #[error("weights[{index}] = {value} is negative")]
    NegativeWeight { index: usize, value: f64 },
    /// A negative variance.
    #[error("variances[{index}] = {value} is negative")]
    NegativeVariance { index: usize, value: f64 },
    /// All weights are zero (or their sum is not a positive finite number).
    #[error("the weights sum to {total}, not to a positive finite number")]
    ZeroTotalWeight { total: f64 },
    /// A credible level outside (0, 1).
    #[error("credible level {level} is not in (0, 1)")]
    InvalidLevel { level: f64 },
    /// A quantile probability outside (0, 1).
    #[error("probability {p} is not in (0, 1)")]
    InvalidProbability { p: f64 },
    /// `central_intervals` was given an output slice of the wrong length.
    #[error("{levels} levels but room for {out} intervals")]
    OutputLength { levels: usize, out: usize },
    /// No bracket of the quantile could be found (not expected for finite inputs).
    #[error("no bracket found for the {p}-quantile of the mixture")]
    NoBracket { p: f64 },
    /// The quantile iteration did not reach its tolerance within its iteration cap.
    #[error("the {p}-quantile iteration stopped at [{lo}, {hi}] without converging")]
    NotConverged { p: f64, lo: f64, hi: f64 },
}

/// The probabilities `((1 − q)/2, (1 + q)/2)` of a central q-interval.
pub fn central_probabilities(level: f64) -> Result<(f64, f64), CredibleError> {
    if !(level > 0.0 && level < 1.0) {
        return Err(CredibleError::InvalidLevel { level });
    }
    Ok((0.5 * (1.0 - level), 0.5 * (1.0 + level)))
}

/// `out[i] = interval(levels[i])` in order, after checking that `out` has one slot per level:
/// the one loop of every `central_intervals` (`interval` may carry what the earlier levels left).
fn each_level(
    levels: &[f64],
    out: &mut [CredibleInterval],
    mut interval: impl FnMut(f64) -> Result<CredibleInterval, CredibleError>,
) -> Result<(), CredibleError> {
    if levels.len() != out.len() {
        return Err(CredibleError::OutputLength {
            levels: levels.len(),
            out: out.len(),
        });
    }
    for (o, &level) in out.iter_mut().zip(levels) {
        *o = interval(level)?;
    }
    Ok(())
}

fn check_probability(p: f64) -> Result<(), CredibleError> {
    if p > 0.0 && p < 1.0 {
        Ok(())
    } else {
        Err(CredibleError::InvalidProbability { p })
    }
}

fn check_weights(weights: &[f64]) -> Result<f64, CredibleError> {
    if weights.is_empty() {
        return Err(CredibleError::Empty);
    }
    let mut total = 0.0;
    for (index, &value) in weights.iter().enumerate() {
        if !value.is_finite() {
            return Err(CredibleError::NonFinite {
                what: "weights",
                index,
                value,
            });
        }
        if value < 0.0 {
            return Err(CredibleError::NegativeWeight { index, value });
        }
        total += value;
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(CredibleError::ZeroTotalWeight { total });
    }
    Ok(total)
}

fn check_finite(what: &'static str, values: &[f64], expected: usize) -> Result<(), CredibleError> {
    if values.len() != expected {
        return Err(CredibleError::LengthMismatch {
            what,
            expected,
            got: values.len(),
        });
    }
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(CredibleError::NonFinite {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Weighted sample
// ---------------------------------------------------------------------------------------------

/// The posterior of a sampled parameter: particle values with weights, sorted once so that every
/// quantile costs a bisection of the sorted steps, O(log Np). See the module doc for the quantile definition.
#[derive(Debug, Clone, Default)]
pub struct WeightedSample {
    /// Distinct values with positive weight, ascending, each with the cumulative weight up to
    /// and including it.
    steps: Vec<(f64, f64)>,
    /// Sum of the weights (the last cumulative weight).
    total: f64,
}

impl WeightedSample {
    /// An empty sample with room for `capacity` particles; fill it with [`Self::set`].
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            steps: Vec::with_capacity(capacity),
            total: 0.0,
        }
    }

    /// The sample of `values` with (not necessarily normalised) `weights`.
    pub fn new(values: &[f64], weights: &[f64]) -> Result<Self, CredibleError> {
        let mut s = Self::with_capacity(values.len());
        s.set(values, weights)?;
        Ok(s)
    }

    /// Replaces the sample, reusing the buffer (no allocation once its capacity suffices).
    /// O(Np log Np) for the sort. On error the sample is left empty.
    pub fn set(&mut self, values: &[f64], weights: &[f64]) -> Result<(), CredibleError> {
        self.steps.clear();
        self.total = 0.0;
        check_weights(weights)?;
        check_finite("values", values, weights.len())?;
        self.steps.extend(
            values
                .iter()
                .zip(weights)
                .filter(|(_, &w)| w > 0.0)
                .map(|(&v, &w)| (v, w)),
        );
        self.steps.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        // Merge ties into one step and accumulate in ascending order, so that the last
        // cumulative weight is the total by construction (F = 1 exactly at the largest value).
        let mut out = 0;
        let mut cum = 0.0;
        for k in 0..self.steps.len() {
            let (v, w) = self.steps[k];
            cum += w;
            // `-0.0 == 0.0`: equal values are one step whatever their sign bit.
            if out > 0 && self.steps[out - 1].0 == v {
                self.steps[out - 1].1 = cum;
            } else {
                self.steps[out] = (v, cum);
                out += 1;
            }
        }
        self.steps.truncate(out);
        self.total = cum;
        Ok(())
    }

    /// Number of distinct values with positive weight.
    pub fn distinct(&self) -> usize {
        self.steps.len()
    }

    /// The weighted empirical CDF `F(x) = Σ_{θ_i ≤ x} w_i / Σ w_i`.
    pub fn cdf(&self, x: f64) -> f64 {
        if self.steps.is_empty() {
            return f64::NAN;
        }
        let k = self.steps.partition_point(|s| s.0 <= x);
        if k == 0 {
            0.0
        } else {
            self.steps[k - 1].1 / self.total
        }
    }

    /// `Q(p) = inf {x : F(x) ≥ p}`: the smallest value whose cumulative weight reaches `p · Σ w`.
    pub fn quantile(&self, p: f64) -> Result<f64, CredibleError> {
        check_probability(p)?;
        if self.steps.is_empty() {
            return Err(CredibleError::Empty);
        }
        let target = p * self.total;
        // p < 1 so target ≤ total = the last cumulative weight: the index is in range.
        let k = self.steps.partition_point(|s| s.1 < target);
        Ok(self.steps[k.min(self.steps.len() - 1)].0)
    }

    /// The central `level`-credible interval.
    pub fn central_interval(&self, level: f64) -> Result<CredibleInterval, CredibleError> {
        let (pl, pu) = central_probabilities(level)?;
        Ok(CredibleInterval {
            level,
            lo: self.quantile(pl)?,
            hi: self.quantile(pu)?,
        })
    }

    /// The central intervals at each of `levels`, written into `out` (same length); the sort is
    /// shared.
    pub fn central_intervals(
        &self,
        levels: &[f64],
        out: &mut [CredibleInterval],
    ) -> Result<(), CredibleError> {
        each_level(levels, out, |level| self.central_interval(level))
    }
}

// ---------------------------------------------------------------------------------------------
// Gaussian mixture
// ---------------------------------------------------------------------------------------------

/// Φ(z), the standard normal CDF.
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2)
}

/// 1 − Φ(z) = Φ(−z), without cancellation for large z.
pub(crate) fn normal_sf(z: f64) -> f64 {
    0.5 * libm::erfc(z * std::f64::consts::FRAC_1_SQRT_2)
}

/// φ(z), the standard normal density.
pub(crate) fn normal_pdf(z: f64) -> f64 {
    const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
    INV_SQRT_2PI * (-0.5 * z * z).exp()
}

/// Which tail a root finding solves on: `F(x) − p` for p ≤ ½, `(1 − p) − S(x)` above.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tail {
    Lower,
    Upper,
}

impl Tail {
    fn of(p: f64) -> Self {
        if p <= 0.5 {
            Tail::Lower
        } else {
            Tail::Upper
        }
    }
}

/// A point where the CDF (lower tail) or the survival function (upper tail) is known.
#[derive(Debug, Clone, Copy)]
struct Known {
    x: f64,
    tail: Tail,
    value: f64,
    /// Density of the continuous part at x.
    dens: f64,
}

/// The posterior of a marginalised parameter: `Σ_i w_i N(μ_i, σ_i²)` over the particles, a view
/// of the filter's weight, mean and variance slices (no copy). Zero-variance components are point
/// masses; zero-weight components are ignored.
///
/// Cost: every evaluation of the CDF (with its density) is O(Np): one `erfc`, one `exp` and one
/// `sqrt` per component. A quantile of a smooth posterior takes about 8 evaluations (two for the
/// bracket, the start at the mean, four or five Newton steps, one probe that certifies the
/// result); a quantile at a point mass bisects to it, up to about 50. Measured: a central
/// interval of a 200-component mixture costs 16–20 evaluations, the three standard levels
/// together 50 (58 one at a time).
#[derive(Debug, Clone, Copy)]
pub struct GaussianMixture<'a> {
    weights: &'a [f64],
    means: &'a [f64],
    variances: &'a [f64],
    total: f64,
    mean: f64,
    sd: f64,
    /// Length scale of the convergence test: the smallest positive σ_i, or the s.d. of the
    /// mixture when every component is a point mass.
    scale: f64,
    /// min μ_i − 10σ_i and max μ_i + 10σ_i over components of positive weight.
    lo: f64,
    hi: f64,
}

impl<'a> GaussianMixture<'a> {
    /// Validates the inputs (finite, weights ≥ 0 with a positive sum, variances ≥ 0, equal
    /// lengths) and computes the mixture's moments and initial bracket, O(Np).
    pub fn new(
        weights: &'a [f64],
        means: &'a [f64],
        variances: &'a [f64],
    ) -> Result<Self, CredibleError> {
        let total = check_weights(weights)?;
        check_finite("means", means, weights.len())?;
        check_finite("variances", variances, weights.len())?;
        if let Some(index) = variances.iter().position(|&v| v < 0.0) {
            return Err(CredibleError::NegativeVariance {
                index,
                value: variances[index],
            });
        }
        let mut mean = 0.0;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut scale = f64::INFINITY;
        for ((&w, &m), &v) in weights.iter().zip(means).zip(variances) {
            if w > 0.0 {
                mean += w * m;
                let s = v.sqrt();
                if s > 0.0 {
                    scale = scale.min(s);
                }
                lo = lo.min(m - BRACKET_SDS * s);
                hi = hi.max(m + BRACKET_SDS * s);
            }
        }
        mean /= total;
        // Second pass about the mean (no cancellation when |μ| ≫ σ).
        let mut var = 0.0;
        for ((&w, &m), &v) in weights.iter().zip(means).zip(variances) {
            if w > 0.0 {
                var += w * (v + (m - mean) * (m - mean));
            }
        }
        let sd = (var / total).sqrt();
        if scale == f64::INFINITY {
            scale = sd;
        }
        if !(lo.is_finite() && hi.is_finite() && sd.is_finite()) {
            // Finite inputs of extreme magnitude (beyond ~1e307) overflow the bracket.
            return Err(CredibleError::NonFinite {
                what: "mixture bracket",
                index: 0,
                value: if lo.is_finite() { hi } else { lo },
            });
        }
        Ok(Self {
            weights,
            means,
            variances,
            total,
            mean,
            sd,
            scale,
            lo,
            hi,
        })
    }

    /// Posterior mean `Σ w_i μ_i / Σ w_i` (SPEC §7).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Posterior s.d. `sqrt(Σ w_i (σ_i² + (μ_i − mean)²) / Σ w_i)` (SPEC §7).
    pub fn sd(&self) -> f64 {
        self.sd
    }

    /// The mixture CDF `F(x)` (right-continuous: a point mass at x counts).
    pub fn cdf(&self, x: f64) -> f64 {
        self.eval(x, Tail::Lower).0
    }

    /// The survival function `S(x) = 1 − F(x) = P(θ > x)`, accurate in the upper tail.
    pub fn sf(&self, x: f64) -> f64 {
        self.eval(x, Tail::Upper).0
    }

    /// `F(x)` (lower) or `S(x)` (upper), and the density of the continuous part at x. O(Np).
    fn eval(&self, x: f64, tail: Tail) -> (f64, f64) {
        let (mut acc, mut dens) = (0.0, 0.0);
        for ((&w, &m), &v) in self.weights.iter().zip(self.means).zip(self.variances) {
            if w == 0.0 {
                continue;
            }
            if v == 0.0 {
                let counts = match tail {
                    Tail::Lower => m <= x,
                    Tail::Upper => m > x,
                };
                if counts {
                    acc += w;
                }
                continue;
            }
            let s = v.sqrt();
            let z = (x - m) / s;
            acc += w * match tail {
                Tail::Lower => normal_cdf(z),
                Tail::Upper => normal_sf(z),
            };
            dens += w * normal_pdf(z) / s;
        }
        (acc / self.total, dens / self.total)
    }

    /// `g(x)`, increasing in x, with `g(x) ≥ 0 ⟺ F(x) ≥ p`.
    fn g(&self, p: f64, x: f64) -> (f64, f64, Known) {
        let tail = Tail::of(p);
        let (value, dens) = self.eval(x, tail);
        let g = match tail {
            Tail::Lower => value - p,
            // 1 − p is exact for p in [½, 1).
            Tail::Upper => (1.0 - p) - value,
        };
        (
            g,
            dens,
            Known {
                x,
                tail,
                value,
                dens,
            },
        )
    }

    /// `g` at a known point, if it was evaluated on p's tail.
    fn g_of(p: f64, k: &Known) -> Option<f64> {
        let g = match k.tail {
            Tail::Lower => k.value - p,
            Tail::Upper => (1.0 - p) - k.value,
        };
        (k.tail == Tail::of(p)).then_some(g)
    }

    fn tol(&self, x: f64) -> f64 {
        REL_TOL * self.scale + 4.0 * f64::EPSILON * x.abs()
    }

    /// `Q(p) = inf {x : F(x) ≥ p}` by safeguarded Newton iteration (Newton steps on F with the
    /// mixture density, bisection whenever a step leaves the bracket or does not shrink fast
    /// enough). The result lies in a certified bracket `F(a) < p ≤ F(b)` at most three
    /// tolerances wide, a tolerance being `REL_TOL` times the smallest component s.d. plus four
    /// ulps of x. A point mass where F jumps across p is returned exactly.
    pub fn quantile(&self, p: f64) -> Result<f64, CredibleError> {
        check_probability(p)?;
        self.quantile_with(p, &[]).map(|(x, _)| x)
    }

    /// The root finding of [`Self::quantile`], starting from the tightest bracket that `known` points
    /// give. Returns the quantile and the final bracket's end points.
    fn quantile_with(&self, p: f64, known: &[Known]) -> Result<(f64, [Known; 2]), CredibleError> {
        let tail = Tail::of(p);
        if self.sd == 0.0 {
            // All mass at one point.
            let k = Known {
                x: self.mean,
                tail,
                value: f64::NAN,
                dens: f64::NAN,
            };
            return Ok((self.mean, [k, k]));
        }
        // Bracket: g(a) < 0 ≤ g(b), from known points or the initial ±10 σ bracket, widened if
        // needed (a point mass at its end, or p below Φ(−10)).
        let mut ka: Option<Known> = None;
        let mut kb: Option<Known> = None;
        for k in known {
            match Self::g_of(p, k).map(|g| g >= 0.0) {
                Some(false) if ka.is_none_or(|a| k.x > a.x) => ka = Some(*k),
                Some(true) if kb.is_none_or(|b| k.x < b.x) => kb = Some(*k),
                _ => {}
            }
        }
        let widen = (self.hi - self.lo).max(self.sd);
        let mut ka = match ka {
            Some(k) => k,
            None => self.bracket_end(p, self.lo, -widen, |g| g < 0.0)?,
        };
        let mut kb = match kb {
            Some(k) => k,
            None => self.bracket_end(p, self.hi, widen, |g| g >= 0.0)?,
        };

        // Start where Newton is likely to work: the bracket end nearest the root by its Newton
        // distance |g|/f (a shared end is often already within the tolerance), or else the
        // mixture mean (the ±10 σ ends sit where the density vanishes).
        let distance = |k: &Known| match Self::g_of(p, k) {
            Some(g) if k.dens > 0.0 => (g / k.dens).abs(),
            _ => f64::INFINITY,
        };
        let (a, b) = (ka.x, kb.x);
        let nearest = if distance(&ka) <= distance(&kb) {
            ka
        } else {
            kb
        };
        let mut x = if distance(&nearest) < 0.5 * (b - a) {
            nearest.x
        } else if self.mean > a && self.mean < b {
            self.mean
        } else {
            0.5 * (a + b)
        };

        // Safeguarded Newton (Numerical Recipes' rtsafe): keep g(a) < 0 ≤ g(b); take the Newton
        // step when it stays inside the bracket and shrinks fast enough, else bisect.
        let mut dx_old = b - a;
        let mut dx = dx_old;
        let mut answer = None;
        let mut converged = false;
        for _ in 0..MAX_ITER {
            let (g, dens, k) = self.g(p, x);
            if g < 0.0 {
                ka = k;
            } else {
                kb = k;
            }
            let newton = (dens > 0.0).then(|| x - g / dens);
            if let Some(xn) = newton {
                let t = self.tol(x);
                if (xn - x).abs() <= t {
                    // A tiny Newton step is a claim, not a proof (F may be flat at p in
                    // floating point, left of a jump): probe just past the Newton point on the
                    // other side and accept only a bracket of a few tolerances.
                    let y = if g < 0.0 {
                        xn.max(x) + t
                    } else {
                        xn.min(x) - t
                    };
                    if y > ka.x && y < kb.x {
                        let (gy, _, ky) = self.g(p, y);
                        if gy < 0.0 {
                            ka = ky;
                        } else {
                            kb = ky;
                        }
                    }
                    if kb.x - ka.x <= 3.0 * t {
                        answer = Some(xn.clamp(ka.x, kb.x));
                        converged = true;
                        break;
                    }
                    // The probe failed: bisect.
                    x = 0.5 * (ka.x + kb.x);
                    dx_old = kb.x - ka.x;
                    dx = dx_old;
                    continue;
                }
            }
            let (a, b) = (ka.x, kb.x);
            if b - a <= self.tol(b) {
                // Within a small bracket the Newton point is the better estimate of a continuous
                // root (the end b may be a whole tolerance away).
                answer = newton.map(|xn| xn.clamp(a, b));
                converged = true;
                break;
            }
            let use_newton = newton
                .is_some_and(|xn| xn > a && xn < b && (2.0 * g).abs() <= (dx_old * dens).abs());
            dx_old = dx;
            let next = match newton {
                Some(xn) if use_newton => xn,
                _ => 0.5 * (a + b),
            };
            dx = next - x;
            if next <= a || next >= b {
                // No representable point strictly inside the bracket.
                converged = true;
                break;
            }
            x = next;
        }
        let (a, b) = (ka.x, kb.x);
        if !converged {
            return Err(CredibleError::NotConverged { p, lo: a, hi: b });
        }
        // A point mass where F jumps across p is returned exactly: after bisection it is the
        // smallest one in (a, b]; after a Newton step it must also lie within the tolerance of
        // the Newton point (the bracket may then be wide on one side).
        let window = match answer {
            Some(xn) => (
                a.max(xn - 2.0 * self.tol(xn)),
                b.min(xn + 2.0 * self.tol(xn)),
            ),
            None => (a, b),
        };
        let mass = self
            .weights
            .iter()
            .zip(self.means)
            .zip(self.variances)
            .filter(|((&w, &m), &v)| w > 0.0 && v == 0.0 && m > window.0 && m <= window.1)
            .map(|((_, &m), _)| m)
            .fold(None, |acc: Option<f64>, m| {
                Some(acc.map_or(m, |x| x.min(m)))
            });
        let x = match (mass, answer) {
            (Some(m), _) => m,
            (None, Some(xn)) => xn,
            (None, None) => b,
        };
        Ok((x, [ka, kb]))
    }

    /// Walks from `x` by `step`, doubling it, until `accept(g(x))`: one end of a bracket.
    fn bracket_end(
        &self,
        p: f64,
        mut x: f64,
        mut step: f64,
        accept: impl Fn(f64) -> bool,
    ) -> Result<Known, CredibleError> {
        loop {
            let (g, _, k) = self.g(p, x);
            if accept(g) {
                return Ok(k);
            }
            x += step;
            step *= 2.0;
            if !x.is_finite() {
                return Err(CredibleError::NoBracket { p });
            }
        }
    }

    /// The central `level`-credible interval.
    pub fn central_interval(&self, level: f64) -> Result<CredibleInterval, CredibleError> {
        let mut out = [CredibleInterval {
            level,
            lo: f64::NAN,
            hi: f64::NAN,
        }];
        self.central_intervals(&[level], &mut out)?;
        Ok(out[0])
    }

    /// The central intervals at each of `levels` of the mixture truncated to `x ≥ bound` (the
    /// posterior of a parameter held to its physical support, `linalg::support`): the
    /// truncated CDF is (F(x) − F(a))/(1 − F(a)), so its p-quantile is the mixture's
    /// (F(a) + p(1 − F(a)))-quantile. Without mass below `bound` these are
    /// [`Self::central_intervals`] exactly.
    pub fn central_intervals_above(
        &self,
        bound: f64,
        levels: &[f64],
        out: &mut [CredibleInterval],
    ) -> Result<(), CredibleError> {
        let below = self.cdf(bound);
        if below <= 0.0 {
            return self.central_intervals(levels, out);
        }
        let kept = 1.0 - below;
        each_level(levels, out, |level| {
            let (pl, pu) = central_probabilities(level)?;
            let lo = self.quantile((below + pl * kept).min(1.0 - f64::EPSILON))?;
            let hi = self.quantile((below + pu * kept).min(1.0 - f64::EPSILON))?;
            Ok(CredibleInterval {
                level,
                lo: lo.max(bound),
                hi: hi.max(bound),
            })
        })
    }

    /// The central intervals at each of `levels`, written into `out` (same length). The
    /// validation and moments are shared, and each root finding starts from the tightest bracket the
    /// earlier ones left (nested intervals need few further evaluations). No allocation.
    pub fn central_intervals(
        &self,
        levels: &[f64],
        out: &mut [CredibleInterval],
    ) -> Result<(), CredibleError> {
        let mut known = [Known {
            x: f64::NAN,
            tail: Tail::Lower,
            value: f64::NAN,
            dens: f64::NAN,
        }; KNOWN];
        let mut n_known = 0;
        let mut next = 0;
        each_level(levels, out, |level| {
            let (pl, pu) = central_probabilities(level)?;
            let mut ends = [0.0; 2];
            for (end, p) in ends.iter_mut().zip([pl, pu]) {
                let (x, bracket) = self.quantile_with(p, &known[..n_known])?;
                *end = x;
                for k in bracket.into_iter().filter(|k| k.value.is_finite()) {
                    known[next] = k;
                    next = (next + 1) % KNOWN;
                    n_known = (n_known + 1).min(KNOWN);
                }
            }
            Ok(CredibleInterval {
                level,
                lo: ends[0],
                hi: ends[1],
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn central_probabilities_of_the_standard_levels() {
        // 1 − 0.9 rounds to 0.09999999999999998.
        let (pl, pu) = central_probabilities(0.9).unwrap();
        assert!((pl - 0.05).abs() < 1e-16 && pu == 0.95, "{pl} {pu}");
        assert_eq!(central_probabilities(0.5).unwrap(), (0.25, 0.75));
        for bad in [0.0, 1.0, -0.1, 1.5, f64::NAN] {
            assert!(matches!(
                central_probabilities(bad),
                Err(CredibleError::InvalidLevel { .. })
            ));
        }
    }

    #[test]
    fn weighted_sample_merges_ties_and_drops_zero_weights() {
        let s = WeightedSample::new(&[3.0, 1.0, 3.0, 2.0, 9.0], &[0.25, 0.25, 0.25, 0.25, 0.0])
            .unwrap();
        assert_eq!(s.distinct(), 3);
        assert_eq!(s.steps, vec![(1.0, 0.25), (2.0, 0.5), (3.0, 1.0)]);
        assert_eq!(s.cdf(0.0), 0.0);
        assert_eq!(s.cdf(2.5), 0.5);
        assert_eq!(s.cdf(9.0), 1.0);
    }

    #[test]
    fn set_on_bad_input_leaves_the_sample_empty() {
        let mut s = WeightedSample::new(&[1.0, 2.0], &[1.0, 1.0]).unwrap();
        assert!(s.set(&[1.0, f64::NAN], &[1.0, 1.0]).is_err());
        assert_eq!(s.quantile(0.5), Err(CredibleError::Empty));
    }

    #[test]
    fn normal_cdf_in_both_tails() {
        // Φ(−z) to 20 digits (mpmath). The relative condition number of Φ at −z is about z², so
        // rounding z/√2 to a double costs up to ≈ 2 z² ulp; the bound allows 4 (1 + z²) ulp.
        let cases = [
            (0.5, 0.308_537_538_725_986_9),
            (1.0, 0.158_655_253_931_457_05),
            (3.0, 1.349_898_031_630_094_5e-3),
            (5.0, 2.866_515_718_791_939e-7),
            (10.0, 7.619_853_024_160_526e-24),
            (20.0, 2.753_624_118_606_233_7e-89),
            (37.0, 5.725_571_222_524_577e-300),
        ];
        for (z, lower) in cases {
            let tol = 4.0 * f64::EPSILON * (1.0 + z * z);
            let rel = |a: f64| ((a - lower) / lower).abs();
            assert!(
                rel(normal_cdf(-z)) < tol,
                "Φ(−{z}): {}",
                rel(normal_cdf(-z))
            );
            assert!(rel(normal_sf(z)) < tol, "S({z}): {}", rel(normal_sf(z)));
            assert!((normal_cdf(z) - (1.0 - lower)).abs() < 2.0 * f64::EPSILON);
        }
    }
}
