//! The physical support of a Gaussian: moment-matched truncation below a bound.
//!
//! A marginalised filter carries stiffness and damping as Gaussian unknowns, and a Gaussian
//! reaches below zero. Where model error pushes a damping through zero, the answer becomes
//! physically impossible (a negative dashpot, an indefinite damping matrix). Truncating the
//! Gaussian to `x_j ≥ a` after every update and replacing it by the Gaussian of the same first
//! two moments (Simon & Simon 2010, "Constrained Kalman filtering via density function
//! truncation") keeps every mean inside the support by construction, while the other
//! components move with `x_j` through their covariance — exact for one constraint, since given
//! `x_j` the others stay Gaussian:
//!
//! ```text
//! α = (a − m_j)/σ,  λ = φ(α)/(1 − Φ(α)),  μ' = m_j + σλ,  σ'² = σ²(1 + αλ − λ²)
//! m ← m + P e_j (μ' − m_j)/σ²,   P ← P − P e_j e_jᵀ P (σ² − σ'²)/σ⁴
//! ```
//!
//! A Gaussian is truncated only where a bounded mean has left the support ([`truncate_below`]),
//! so a Gaussian whose means lie inside is left bit for bit unchanged; several bounds are applied
//! one after the other (the usual sequential approximation).

/// `x[index] ≥ bound` for one entry of a Gaussian block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LowerBound {
    pub index: usize,
    pub bound: f64,
}

/// The truncated moments of a standard normal cut below at `alpha`: the mean shift `λ` (the
/// inverse Mills ratio) and the variance factor `1 + αλ − λ²`, stable far into the tail.
pub(crate) fn truncated_standard(alpha: f64) -> (f64, f64) {
    let lambda = if alpha < 25.0 {
        crate::credible::normal_pdf(alpha) / crate::credible::normal_sf(alpha)
    } else {
        // Asymptotic series of the Mills ratio: φ/Q ≈ α + 1/α − 2/α³ + 10/α⁵ (the erfc ratio
        // loses digits past here).
        let a2 = alpha * alpha;
        alpha + 1.0 / alpha - 2.0 / (alpha * a2) + 10.0 / (alpha * a2 * a2)
    };
    // 1 + αλ − λ² = 1 − λ(λ − α); for large α it tends to 1/α², kept positive.
    let factor = (1.0 - lambda * (lambda - alpha)).max(1e-12);
    (lambda, factor)
}

/// Where the mean of a bounded entry has left its support (`mean[j] < bound`), replaces the
/// Gaussian `N(mean, cov)` (`cov` column-major, `n × n`) by the Gaussian of its moments truncated
/// to `x_j ≥ bound`. Only a mean outside is truncated: truncating at every step a Gaussian that
/// merely reaches past its bound would push the mean of a static parameter away from the bound
/// step after step, with a shrinking variance (to about 8 s.d. above it). A truncation moves the
/// other entries through their covariance and can push another bounded mean out, so the bounds
/// are swept again (at most `MAX_SWEEPS` times); a mean still outside after that is set on its
/// bound. Returns how many truncations were made. Allocates nothing.
pub fn truncate_below(mean: &mut [f64], cov: &mut [f64], bounds: &[LowerBound]) -> usize {
    let n = mean.len();
    debug_assert_eq!(cov.len(), n * n);
    let mut applied = 0;
    for _ in 0..MAX_SWEEPS {
        let mut moved = false;
        for b in bounds {
            if truncate_one(mean, cov, n, b) {
                applied += 1;
                moved = true;
            }
        }
        if !moved {
            return applied;
        }
    }
    for b in bounds {
        if mean[b.index] < b.bound {
            mean[b.index] = b.bound;
        }
    }
    applied
}

/// Sweeps of [`truncate_below`] over its bounds before a mean left outside is set on its bound.
pub(crate) const MAX_SWEEPS: usize = 8;

/// One bound's truncation when the mean is outside; whether it was made.
fn truncate_one(mean: &mut [f64], cov: &mut [f64], n: usize, b: &LowerBound) -> bool {
    let j = b.index;
    let var = cov[j + j * n];
    // A NaN mean or variance is left for the filter's own checks.
    let outside = mean[j] < b.bound;
    let proper = var > 0.0 && var.is_finite();
    if !outside || !proper {
        return false;
    }
    let sd = var.sqrt();
    let alpha = (b.bound - mean[j]) / sd;
    let (lambda, factor) = truncated_standard(alpha);
    let shift = sd * lambda / var;
    let shrink = (1.0 - factor) / var;
    // m ← m + P_{·j} (μ' − m_j)/σ², P ← P − P_{·j} P_{j·} (σ² − σ'²)/σ⁴, with the column P_{·j}
    // read before P changes (column j is overwritten last).
    for r in 0..n {
        mean[r] += cov[r + j * n] * shift;
    }
    // Each entry as (P_rj P_cj)·shrink: the product commutes exactly, so a symmetric P stays
    // symmetric bit for bit.
    for c in 0..n {
        let pcj = cov[c + j * n];
        if pcj == 0.0 || c == j {
            continue;
        }
        for r in 0..n {
            cov[r + c * n] -= (cov[r + j * n] * pcj) * shrink;
        }
    }
    let pjj = cov[j + j * n];
    for r in 0..n {
        cov[r + j * n] -= (cov[r + j * n] * pjj) * shrink;
    }
    // Round-off must not leave the truncated mean outside.
    if mean[j] < b.bound {
        mean[j] = b.bound;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Moments of N(m, C) restricted to x_j ≥ a by importance sampling on a grid: exact
    /// quadrature in the bounded coordinate, closed form for the others.
    fn reference(m: [f64; 2], c: [[f64; 2]; 2], a: f64) -> ([f64; 2], [[f64; 2]; 2]) {
        // x0 constrained; x1 | x0 ~ N(m1 + c10/c00 (x0 − m0), c11 − c10²/c00).
        let (s0, b) = (c[0][0].sqrt(), c[1][0] / c[0][0]);
        let cond = c[1][1] - c[1][0] * c[1][0] / c[0][0];
        let (lo, hi, steps) = (a, m[0] + 12.0 * s0, 400_000);
        let h = (hi - lo) / steps as f64;
        let (mut z, mut e0, mut e00) = (0.0, 0.0, 0.0);
        for i in 0..=steps {
            let x = lo + i as f64 * h;
            let w = if i == 0 || i == steps { 0.5 } else { 1.0 };
            let p = w * (-0.5 * ((x - m[0]) / s0).powi(2)).exp();
            z += p;
            e0 += p * x;
            e00 += p * x * x;
        }
        let (mu0, v0) = (e0 / z, e00 / z - (e0 / z).powi(2));
        let mu1 = m[1] + b * (mu0 - m[0]);
        let c01 = b * v0;
        let c11 = cond + b * b * v0;
        ([mu0, mu1], [[v0, c01], [c01, c11]])
    }

    #[test]
    fn one_bound_matches_the_truncated_moments() {
        for &(m0, a) in &[(-0.01, 0.0), (-0.2, 0.0), (-3.0, 0.0), (0.4, 0.5)] {
            let m = [m0, 2.0];
            let c = [[0.25, 0.1], [0.1, 0.5]];
            let mut mean = m.to_vec();
            let mut cov = vec![c[0][0], c[1][0], c[0][1], c[1][1]];
            let bounds = [LowerBound { index: 0, bound: a }];
            assert_eq!(truncate_below(&mut mean, &mut cov, &bounds), 1);
            let (rm, rc) = reference(m, c, a);
            for i in 0..2 {
                assert!(
                    (mean[i] - rm[i]).abs() < 1e-6,
                    "{m0} {a}: mean {i} {mean:?} {rm:?}"
                );
                for j in 0..2 {
                    let v = cov[i + 2 * j];
                    assert!(
                        (v - rc[i][j]).abs() < 1e-6,
                        "{m0} {a}: cov {i}{j} {v} {rc:?}"
                    );
                }
            }
            assert!(mean[0] > a);
            assert_eq!(cov[1], cov[2], "symmetric");
        }
    }

    #[test]
    fn a_gaussian_whose_means_are_inside_is_unchanged() {
        // c's mean 0.25 is 0.5 s.d. above its bound: inside, so untouched.
        let mut mean = vec![8.0, 0.25];
        let mut cov = vec![0.01, 1e-4, 1e-4, 0.25];
        let (m0, c0) = (mean.clone(), cov.clone());
        let bounds = [
            LowerBound {
                index: 0,
                bound: 0.0,
            },
            LowerBound {
                index: 1,
                bound: 0.0,
            },
        ];
        assert_eq!(truncate_below(&mut mean, &mut cov, &bounds), 0);
        assert_eq!((mean, cov), (m0, c0));
    }

    #[test]
    fn far_tail_stays_finite_and_inside() {
        for &alpha in &[10.0, 24.9, 25.1, 40.0, 1e3] {
            let (l, f) = truncated_standard(alpha);
            assert!(
                l > alpha && f > 0.0 && f < 1.0 / (alpha * alpha) * 1.01,
                "{alpha} {l} {f}"
            );
        }
        let mut mean = vec![-50.0];
        let mut cov = vec![1.0];
        truncate_below(
            &mut mean,
            &mut cov,
            &[LowerBound {
                index: 0,
                bound: 0.0,
            }],
        );
        assert!(
            mean[0] > 0.0 && mean[0] < 0.05 && cov[0] > 0.0 && cov[0] < 1e-3,
            "{mean:?} {cov:?}"
        );
    }
}
