//! How many transitions per sample interval the filter needs when it is asked to choose
//! (`substeps = "auto"`, the default of `sysid filter`).
//!
//! Real structures are often stiff relative to their logger's sampling rate. The filters'
//! discretisations are stable well beyond what matters here (semi-implicit Euler up to ω·h = 2),
//! but they shift the frequencies they can represent: an undamped mode of the semi-implicit
//! Euler step turns by θ per step with cos θ = 1 − (ωh)²/2, so a filter that follows the
//! measured oscillation identifies a stiffness whose continuous-time frequency is low by
//! θ/(ωh) − 1 — 3.4 % at ωh = 0.87, the third mode of the shake-table frame at 120 Hz
//! (`docs/real-frame.md`). The rule: when one step per sample would shift the highest undamped
//! mode of the prior's building (the prior's central stiffnesses, the given masses) by more than
//! [`SUBSTEP_ABOVE`], the smallest number of sub-steps M that brings the shift to at most
//! [`MAX_FREQUENCY_ERROR`] — one rule for every scheme. Below [`SUBSTEP_ABOVE`] one step is kept:
//! there sub-stepping was not measured to help (no resolved gain on the scaling study's buildings
//! up to ω·dt = 0.45, `docs/scaling.md`) and on the 20-storey building with sparse sensors
//! (a 1.1 % shift) two sub-steps left k1 and k10 20 % low, outside their intervals, where one
//! step held them.

use super::ChainSpecOf;
use super::MAX_SUBSTEPS;
use crate::law::HysteresisLaw;
use crate::priors::Prior;
use serde::Serialize;

/// Relative frequency shift above which the filter sub-steps.
pub const SUBSTEP_ABOVE: f64 = 0.02;
/// Largest relative frequency shift left once it sub-steps.
pub const MAX_FREQUENCY_ERROR: f64 = 0.005;

/// Relative frequency error θ/x − 1 of the semi-implicit Euler step for an undamped mode at
/// x = ω·h (|x| < 2; infinite beyond, where the step is unstable).
pub fn frequency_error(x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 2.0 {
        return f64::INFINITY;
    }
    (1.0 - 0.5 * x * x).acos() / x - 1.0
}

/// The highest undamped natural frequency (rad/s) of the shear chain with storey stiffnesses `k`
/// and masses `m`: the square root of the largest eigenvalue of M⁻¹K, computed as that of the
/// symmetric M^(−1/2) K M^(−1/2) (K tridiagonal: row j holds k_j + k_{j+1} on the diagonal and
/// −k_{j+1} beside it; the roof has no k_{N+1}).
pub fn highest_frequency(k: &[f64], m: &[f64]) -> f64 {
    let n = k.len();
    let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        let up = if j + 1 < n { k[j + 1] } else { 0.0 };
        a[(j, j)] = (k[j] + up) / m[j];
        if j + 1 < n {
            let off = -k[j + 1] / (m[j] * m[j + 1]).sqrt();
            a[(j, j + 1)] = off;
            a[(j + 1, j)] = off;
        }
    }
    a.symmetric_eigenvalues().max().max(0.0).sqrt()
}

/// The central value of a prior: the median of a log-normal, the middle of a uniform.
fn centre(p: &Prior) -> f64 {
    match *p {
        Prior::LogNormal { median, .. } => median,
        Prior::Uniform { lo, hi } => 0.5 * (lo + hi),
        Prior::Fixed { value } => value,
    }
}

/// The choice and what it rests on (written into the run record).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AutoSubsteps {
    pub substeps: usize,
    /// The highest undamped mode of the prior's building (rad/s).
    pub omega_max: f64,
    /// Its frequency error with one transition per sample, and with `substeps`.
    pub error_one: f64,
    pub error_chosen: f64,
}

/// One step when `frequency_error(ω_max·dt) ≤ SUBSTEP_ABOVE`; otherwise the smallest
/// M ≤ [`MAX_SUBSTEPS`] with `frequency_error(ω_max·dt/M) ≤ MAX_FREQUENCY_ERROR` (M =
/// `MAX_SUBSTEPS` when none is enough; the record then shows the error that remains).
pub fn auto_substeps<L: HysteresisLaw>(spec: &ChainSpecOf<L>) -> AutoSubsteps {
    let k: Vec<f64> = spec.prior.k.iter().map(centre).collect();
    let omega_max = highest_frequency(&k, spec.building.masses());
    let x = omega_max * spec.dt;
    let substeps = if frequency_error(x) <= SUBSTEP_ABOVE {
        1
    } else {
        (1..=MAX_SUBSTEPS)
            .find(|&m| frequency_error(x / m as f64) <= MAX_FREQUENCY_ERROR)
            .unwrap_or(MAX_SUBSTEPS)
    };
    AutoSubsteps {
        substeps,
        omega_max,
        error_one: frequency_error(x),
        error_chosen: frequency_error(x / substeps as f64),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_semi_implicit_step_turns_by_the_angle_of_its_eigenvalues() {
        // Eigenvalues of [[1, h], [−ω²h, 1 − ω²h²]] (v then x with the new v): unit modulus,
        // argument θ; compare with the closed form.
        for x in [0.05f64, 0.3, 0.87, 1.5] {
            let (a, d) = (1.0 - x * x, 1.0);
            let tr = a + d; // trace; determinant 1
            let theta = (0.5 * tr).acos();
            assert!((frequency_error(x) - (theta / x - 1.0)).abs() < 1e-12);
        }
        assert!((frequency_error(0.867) - 0.034).abs() < 0.001);
        assert!(frequency_error(2.5).is_infinite());
    }

    #[test]
    fn the_highest_mode_of_a_uniform_chain_is_exact() {
        // Uniform chain, k = m = 1: highest mode 2 sin((2N−1)π/(2(2N+1))); one storey: √(k/m).
        for n in [1usize, 3, 10, 40] {
            let exact = 2.0
                * ((2 * n - 1) as f64 * std::f64::consts::PI / (2.0 * (2 * n + 1) as f64)).sin();
            let w = highest_frequency(&vec![1.0; n], &vec![1.0; n]);
            assert!((w - exact).abs() < 1e-10, "N = {n}: {w} against {exact}");
        }
        assert!((highest_frequency(&[610.0], &[2.0]) - 305f64.sqrt()).abs() < 1e-10);
        // Two storeys, hand computation: k = (2, 1), m = (1, 1): M⁻¹K = [[3, −1], [−1, 1]],
        // eigenvalues 2 ± √2.
        let w = highest_frequency(&[2.0, 1.0], &[1.0, 1.0]);
        assert!((w - (2.0 + 2f64.sqrt()).sqrt()).abs() < 1e-12);
    }
}
