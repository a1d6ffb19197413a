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
//!
//! **The semi-implicit step's velocity lag** (reported, not part of the rule). The
//! semi-implicit step advances the velocity first and the displacement with the new velocity,
//! so its velocity stands half a step behind its displacement (v_n ≈ v(t_n − h/2)). A dashpot
//! fed that velocity in a mode of frequency ω carries, besides its damping, a force in phase
//! with the displacement, c·ω²·h/2 per unit displacement, and a model that reproduces the
//! recorded accelerations needs a stiffness lower by as much: relative to it
//! [`damping_lag_error`], (c/k)·ω²·h/2 = ζ·ω·h for a mode of damping ratio ζ, first order in h.
//! On the scaling study's buildings (2 % first-mode damping from storey dashpots, so the
//! highest mode is damped 26 % at 10 storeys and 50 % at 20) it is 11.7 % and 23 % at
//! dt = 0.005 s, and the exact likelihood of a linear 10-storey record peaks at a roof storey
//! 9.5 % too soft with one step per sample and at the truth with four sub-steps
//! (`docs/calibration.md`, "The top storeys' bias"). The MPF-EKF2 with four sub-steps lost that
//! bias at the roof but did not lower its mean stiffness error at 10 storeys, was less accurate
//! at 20 and cost 2.8 and 3.1 times as much; at 5 storeys (one shared prior Gaussian) it did
//! lower it, 2.8 → 1.6 % on 12 fresh data sets at 3 times the cost, and at 3 storeys not
//! resolvably (`docs/calibration.md`, "Five and forty storeys with today's defaults"). So this
//! module's rule does not sub-step for it: a lag of the same size (9.3 % at 5 storeys, 11.7 %
//! at 10) was worth removing in one case and not in the other. At 5 storeys with the 10-storey
//! settings (per-particle prior means) the gain was −0.34 ± 0.37 points against −1.50 ± 0.29
//! with the shared Gaussian on the same 24 data sets (difference 1.16 ± 0.44): what decides it
//! is the prior, not the size (`docs/calibration.md`, "The prior or the size?"). The lag rule
//! therefore lives where the prior is known, with the filter settings
//! (`experiments::pipeline::LAG_SUBSTEPS`: four sub-steps for the MPF-EKF2 with one shared
//! prior Gaussian below 10 storeys). Every automatic choice records the lag
//! ([`AutoSubsteps::lag_one`]) and `sysid filter` notes the lag of the run's step above
//! [`LAG_NOTED_ABOVE`]. Forward Euler's velocity is not staggered (0 there); its own damping
//! bias is in `docs/discretisation.md`.

use super::ChainSpecOf;
use super::Discretisation;
use super::MAX_SUBSTEPS;
use crate::law::HysteresisLaw;
use crate::priors::Prior;
use serde::Serialize;

/// Relative frequency shift above which the filter sub-steps.
pub const SUBSTEP_ABOVE: f64 = 0.02;
/// Largest relative frequency shift left once it sub-steps.
pub const MAX_FREQUENCY_ERROR: f64 = 0.005;
/// Velocity-lag stiffness error ([`damping_lag_error`]) above which `sysid filter` notes it.
pub const LAG_NOTED_ABOVE: f64 = 0.03;

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

/// Relative stiffness error of the semi-implicit Euler step of length `h` from its velocity's
/// half-step lag, in the mode of frequency `omega` (rad/s), for the storey whose dashpot is
/// largest relative to its spring: max_j (c_j/k_j)·ω²·h/2 (module docs). 0 without damping.
pub fn damping_lag_error(k: &[f64], c: &[f64], omega: f64, h: f64) -> f64 {
    let ratio = k
        .iter()
        .zip(c)
        .map(|(&k, &c)| if k > 0.0 { c / k } else { 0.0 })
        .fold(0.0, f64::max);
    0.5 * ratio * omega * omega * h
}

/// The highest undamped natural frequency (rad/s) of the shear chain with storey stiffnesses `k`
/// and masses `m`: the square root of the largest eigenvalue of M⁻¹K, computed as that of the
/// symmetric M^(−1/2) K M^(−1/2) (K tridiagonal: row j holds k_j + k_{j+1} on the diagonal and
/// −k_{j+1} beside it; the roof has no k_{N+1}).
pub(crate) fn highest_frequency(k: &[f64], m: &[f64]) -> f64 {
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct AutoSubsteps {
    pub substeps: usize,
    /// The highest undamped mode of the prior's building (rad/s).
    pub omega_max: f64,
    /// Its frequency error with one transition per sample, and with `substeps`.
    pub error_one: f64,
    pub error_chosen: f64,
    /// The semi-implicit step's velocity-lag stiffness error ([`damping_lag_error`]) with one
    /// transition per sample; 0 for the other schemes. Reported only. With M transitions it is
    /// `lag_one / M` (the lag is proportional to the step), so it is not stored again.
    pub lag_one: f64,
}

/// One step when `frequency_error(ω_max·dt) ≤ SUBSTEP_ABOVE`; otherwise the smallest
/// M ≤ [`MAX_SUBSTEPS`] with `frequency_error(ω_max·dt/M) ≤ MAX_FREQUENCY_ERROR` (M =
/// `MAX_SUBSTEPS` when none is enough; the record then shows the error that remains). The
/// velocity lag of the semi-implicit scheme is computed alongside, with the prior's central
/// stiffnesses and dashpots, and does not enter the choice (module docs).
pub fn auto_substeps<L: HysteresisLaw>(spec: &ChainSpecOf<L>) -> AutoSubsteps {
    let k: Vec<f64> = spec.prior.k.iter().map(centre).collect();
    let c: Vec<f64> = spec.prior.c.iter().map(centre).collect();
    let omega_max = highest_frequency(&k, spec.building.masses());
    let x = omega_max * spec.dt;
    let substeps = if frequency_error(x) <= SUBSTEP_ABOVE {
        1
    } else {
        (1..=MAX_SUBSTEPS)
            .find(|&m| frequency_error(x / m as f64) <= MAX_FREQUENCY_ERROR)
            .unwrap_or(MAX_SUBSTEPS)
    };
    let lag_one = match spec.discretisation {
        Discretisation::Symplectic => damping_lag_error(&k, &c, omega_max, spec.dt),
        Discretisation::Euler | Discretisation::Rk4 => 0.0,
    };
    AutoSubsteps {
        substeps,
        omega_max,
        error_one: frequency_error(x),
        error_chosen: frequency_error(x / substeps as f64),
        lag_one,
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

    #[test]
    fn the_velocity_lag_error_is_zeta_omega_h_of_the_highest_mode() {
        // The scaling study's 10-storey building: k = 2000, c = 11.97 per unit mass (2 %
        // first-mode damping), dt = 0.005: (c/k)·ω_max²·dt/2 = 11.7 %, a tenth at ten sub-steps.
        let (k, c) = (vec![2000.0; 10], vec![11.968768511784665; 10]);
        let w = highest_frequency(&k, &[1.0; 10]);
        let e = damping_lag_error(&k, &c, w, 0.005);
        assert!((e - 0.117029).abs() < 1e-5, "{e}");
        assert!((damping_lag_error(&k, &c, w, 0.0005) - 0.1 * e).abs() < 1e-15);
        // ζ·ω·h for the mode: with C = (c/k)·K the mode's damping ratio is (c/k)·ω/2.
        let zeta = 0.5 * (c[0] / k[0]) * w;
        assert!((e - zeta * w * 0.005).abs() < 1e-15);
        // The storey with the largest c/k decides; no dashpots, no lag.
        let mut c2 = c.clone();
        c2[9] *= 2.0;
        assert!((damping_lag_error(&k, &c2, w, 0.005) - 2.0 * e).abs() < 1e-12);
        assert_eq!(damping_lag_error(&k, &[0.0; 10], w, 0.005), 0.0);
    }

    fn spec_of(n: usize, discretisation: Discretisation) -> crate::filtering::ChainSpec {
        use crate::filtering::RmsLevels;
        use crate::sensors::{MeasurementKind, SensorLayout};
        let building =
            crate::building::Building::new(vec![1.0; n], vec![], Default::default()).unwrap();
        let storeys: Vec<usize> = (1..=n).collect();
        let sensors = SensorLayout::new(n, &storeys, MeasurementKind::Relative).unwrap();
        let rms = RmsLevels {
            acc: vec![1.0; n],
            ug: 1.0,
            drift_velocity: vec![],
        };
        let mut spec = crate::filtering::ChainSpec::from_rms(
            0.005,
            building,
            sensors,
            vec![0.0; 10],
            &rms,
            0.1,
        )
        .unwrap();
        spec.prior.k = vec![
            Prior::LogNormal {
                median: 2000.0,
                log_sd: 0.3
            };
            n
        ];
        spec.prior.c = vec![
            Prior::LogNormal {
                median: 11.968768511784665,
                log_sd: 0.5
            };
            n
        ];
        spec.discretisation = discretisation;
        spec
    }

    #[test]
    fn the_lag_is_reported_and_does_not_change_the_choice() {
        // 10 storeys: the highest mode's frequency error is 0.83 % (one step), the lag 11.7 %.
        let a = auto_substeps(&spec_of(10, Discretisation::Symplectic));
        assert_eq!(a.substeps, 1, "{a:?}");
        assert!(a.error_one < SUBSTEP_ABOVE, "{a:?}");
        assert!((a.lag_one - 0.117029).abs() < 1e-5, "{a:?}");
        assert!(a.lag_one > LAG_NOTED_ABOVE);
        // Forward Euler's velocity is not staggered.
        let e = auto_substeps(&spec_of(10, Discretisation::Euler));
        assert_eq!((e.substeps, e.lag_one), (1, 0.0), "{e:?}");
        // Where the frequency rule sub-steps, its count is kept: the fewest that bring the
        // frequency error to 0.5 %, however large the lag left.
        let mut coarse = spec_of(10, Discretisation::Symplectic);
        coarse.dt = 0.02;
        let c = auto_substeps(&coarse);
        let x = c.omega_max * coarse.dt;
        let fewest = (1..=MAX_SUBSTEPS)
            .find(|&m| frequency_error(x / m as f64) <= MAX_FREQUENCY_ERROR)
            .unwrap();
        assert!(fewest > 1);
        assert_eq!(c.substeps, fewest, "{c:?}");
        assert!(c.lag_one / c.substeps as f64 > LAG_NOTED_ABOVE, "{c:?}");
    }
}
