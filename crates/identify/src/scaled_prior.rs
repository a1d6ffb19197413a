//! Default priors of field data, scaled from the data (SPEC §3 priors are for the paper's
//! structure: k median 10 for unit masses, about 1.3 rad/s; a stiffer building would be refused by
//! them or identified wrongly).
//!
//! The scale is the building's fundamental circular frequency ω₁ seen in the measured response:
//! the peak of the ratio of the power spectra of the highest measured storey's relative
//! acceleration and of the ground acceleration (so the excitation's own colour cancels), searched
//! on a logarithmic grid from two cycles per record to half the Nyquist frequency, where the
//! ground motion has energy (within 30 dB of its strongest frequency: elsewhere both spectra are
//! noise). With every
//! storey stiffness equal to s (K = s·K₁, K₁ the chain's stiffness matrix for unit stiffnesses),
//! ω₁² = s·λ₁ where λ₁ is the lowest eigenvalue of M⁻¹K₁ for the given masses, so s = ω₁²/λ₁.
//! Damping is stiffness-proportional with a typical ratio ζ = 2% at ω₁ (the paper's structure
//! has 2.0%): c = 2ζ·s/ω₁.
//!
//! The priors are k_j ~ LogNormal(s, 0.5) and c_j ~ LogNormal(2ζs/ω₁, 0.7): wider than SPEC §3's
//! (0.3 and 0.5) because the peak is read at the record's frequency resolution and hysteresis
//! softens the response (the peak sits below the small-amplitude frequency). The Bouc–Wen priors
//! stay SPEC §3's: β, γ and n do not change when a structure is scaled in time.
//!
//! With the storey+mass damping form the 2 % at ω₁ is shared equally: c_j's median is that of
//! a 1 % ratio (ζ − [`ALPHA_DAMPING_RATIO`]) and α ~ LogNormal(2·1 %·ω₁, 1.0)
//! ([`models::filtering::prior::alpha_prior`]; pure mass damping has ζ = α/(2ω)).
//!
//! The same ω₁ sets the sub-steps of a building with Bouc–Wen elements when the filter chooses
//! them (`substeps = "auto"`, `hysteretic_substeps`).

use crate::error::{bail, Result};
use models::dataset::LoadedDataset;
use models::description::StructureDescription;
use models::filtering::prior::{alpha_prior, ALPHA_DAMPING_RATIO};
use models::filtering::ChainPrior;
use models::priors::Prior;
use models::sensors::MeasurementKind;
use nalgebra::{DMatrix, SymmetricEigen};
use serde::Serialize;

/// The damping ratio assumed at ω₁.
pub(crate) const DAMPING_RATIO: f64 = 0.02;
/// Log-s.d. of the stiffness and damping priors.
pub const K_LOG_SD: f64 = 0.5;
pub(crate) const C_LOG_SD: f64 = 0.7;

/// A prior scaled from the data, with what it was read from (printed and recorded).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ScaledPrior {
    /// 1-based storey whose response was analysed.
    pub storey: usize,
    /// Fundamental circular frequency read from the spectra (rad/s).
    pub omega1: f64,
    /// Lowest eigenvalue of M⁻¹K₁ (unit stiffnesses, the given masses).
    pub lambda1: f64,
    /// Median of every k_j: ω₁²/λ₁.
    pub k_median: f64,
    /// Median of every c_j: 2ζ·k/ω₁.
    pub c_median: f64,
    pub damping_ratio: f64,
    /// Median of α (storey+mass damping form only): 2·ζ_α·ω₁.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alpha_median: Option<f64>,
    /// The prior itself (not written: a run's plan holds the prior it runs,
    /// `plan::Model::prior`; read back empty).
    #[serde(skip, default = "no_prior")]
    pub prior: ChainPrior,
}

/// The empty prior a read-back [`ScaledPrior`] holds.
fn no_prior() -> ChainPrior {
    ChainPrior {
        k: Vec::new(),
        c: Vec::new(),
        alpha: None,
        elements: Vec::new(),
    }
}

impl ScaledPrior {
    /// One line for the terminal.
    pub fn describe(&self) -> String {
        let alpha = match self.alpha_median {
            Some(a) => format!(
                ", alpha ~ LogNormal(median {a:.4}, log-sd {}) (mass-proportional damping \
                 giving ζ₁ = {ALPHA_DAMPING_RATIO} at ω₁ alone)",
                models::filtering::prior::ALPHA_LOG_SD
            ),
            None => String::new(),
        };
        format!(
            "prior scaled from the data: ω₁ = {:.4} rad/s ({:.3} Hz) at storey {}, so k_j ~ \
             LogNormal(median {:.4}, log-sd {K_LOG_SD}), c_j ~ LogNormal(median {:.4}, log-sd \
             {C_LOG_SD}) (damping ratio {} at ω₁){alpha}; Bouc–Wen priors as SPEC §3; a \
             `prior` in the config overrides it",
            self.omega1,
            self.omega1 / std::f64::consts::TAU,
            self.storey,
            self.k_median,
            self.c_median,
            self.damping_ratio
        )
    }
}

/// ω₁·dt (data-scaled ω₁, sample interval dt) above which a building with Bouc–Wen elements is
/// sub-stepped when the filter chooses its sub-steps ([`hysteretic_substeps`]).
pub(crate) const HYSTERETIC_SUBSTEP_ABOVE: f64 = 0.01;
/// Largest ω₁·h (h = dt/M, the filter's step) left once it sub-steps.
pub(crate) const HYSTERETIC_MAX_OMEGA1_H: f64 = 0.0035;
/// Most sub-steps the rule chooses: the most it was measured with. A record sampled more
/// coarsely still (the shake-table frame at 120 Hz has ω₁·dt ≈ 0.19 and would ask for 55) gets
/// these 8 and a cost 8 times one step's, not a cost without a measured gain; `--substeps N`
/// chooses more.
pub(crate) const HYSTERETIC_MAX_SUBSTEPS: usize = 8;

/// Sub-steps for a building with Bouc–Wen elements, from the data-scaled ω₁ (rad/s) and the
/// sample interval `dt` (s): 1 while ω₁·dt ≤ [`HYSTERETIC_SUBSTEP_ABOVE`], else the fewest M
/// with ω₁·dt/M ≤ [`HYSTERETIC_MAX_OMEGA1_H`], at most [`HYSTERETIC_MAX_SUBSTEPS`].
///
/// Why ω₁ and not the linear modes' frequency error
/// ([`models::filtering::substeps::auto_substeps`]): the filters update the hysteretic variable
/// explicitly (ṙ at the start of the step), and near yield r relaxes at n·|δv|/r_y (r_y the
/// yield level of r), a rate that for a given ductility grows with the response's frequency. On
/// the paper's chain time-scaled ×4 and sampled at 200 Hz (ω₁·dt = 0.028, its highest mode's
/// frequency error only 0.05 %) one step per sample left k1 4.3 % low on average and up to
/// 11.8 % (12 data sets); 2, 4 and 8 sub-steps left it 2.9, 2.5 and 1.1 % low (worst 9.5, 7.4
/// and 4.9 %), while the same building sampled at 800 Hz (ω₁·dt = 0.0069) needs none (0.9 %
/// low, worst 3.7 %). The paper's data sets (ω₁·dt ≈ 0.007) are below the threshold, and
/// their priors are not scaled from the data anyway. `docs/structures.md`, "Stiff buildings".
pub(crate) fn hysteretic_substeps(omega1: f64, dt: f64) -> usize {
    let x = omega1 * dt;
    if !(x.is_finite() && x > HYSTERETIC_SUBSTEP_ABOVE) {
        return 1;
    }
    ((x / HYSTERETIC_MAX_OMEGA1_H).ceil() as usize).clamp(1, HYSTERETIC_MAX_SUBSTEPS)
}

/// What `hysteretic_substeps` chose for a run (printed and recorded under
/// `config.substeps_hysteretic`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct HystereticSubsteps {
    /// ω₁·dt of the data-scaled ω₁ and the sample interval.
    pub omega1_dt: f64,
    pub above: f64,
    pub max_omega1_h: f64,
    pub substeps: usize,
}

impl HystereticSubsteps {
    pub fn new(omega1: f64, dt: f64) -> Self {
        Self {
            omega1_dt: omega1 * dt,
            above: HYSTERETIC_SUBSTEP_ABOVE,
            max_omega1_h: HYSTERETIC_MAX_OMEGA1_H,
            substeps: hysteretic_substeps(omega1, dt),
        }
    }
}

/// Lowest eigenvalue of M⁻¹K₁ for unit stiffnesses: the symmetric form M^{-1/2}K₁M^{-1/2}.
fn lowest_unit_eigenvalue(masses: &[f64]) -> f64 {
    let n = masses.len();
    let mut k = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        // Element j links storey j−1 (or the ground) to storey j.
        k[(j, j)] += 1.0;
        if j > 0 {
            k[(j - 1, j - 1)] += 1.0;
            k[(j - 1, j)] -= 1.0;
            k[(j, j - 1)] -= 1.0;
        }
    }
    let s: Vec<f64> = masses.iter().map(|m| 1.0 / m.sqrt()).collect();
    for i in 0..n {
        for j in 0..n {
            k[(i, j)] *= s[i] * s[j];
        }
    }
    SymmetricEigen::new(k)
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// Power of `x` (sampled at `dt`) at circular frequency `w` (a single-bin DFT).
fn power(x: &[f64], dt: f64, w: f64) -> f64 {
    let (sin, cos) = (w * dt).sin_cos();
    // Rotate a unit phasor sample by sample (no trigonometry inside the loop).
    let (mut c, mut s) = (1.0_f64, 0.0_f64);
    let (mut re, mut im) = (0.0, 0.0);
    for &v in x {
        re += v * c;
        im -= v * s;
        let c2 = c * cos - s * sin;
        s = s * cos + c * sin;
        c = c2;
    }
    re * re + im * im
}

/// How many times this process has scanned a data set's spectra for [`scaled_prior`] (the
/// plan of a run scans at most once: tested).
pub fn scans() -> usize {
    SCANS.load(std::sync::atomic::Ordering::Relaxed)
}

static SCANS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// The prior of field data with structure `d`, scaled from the measured response.
pub fn scaled_prior(data: &LoadedDataset, d: &StructureDescription) -> Result<ScaledPrior> {
    SCANS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let k = data.len();
    let dt = data.dt;
    let channel = data.channels - 1;
    let storey = data.sensors[channel];
    let relative: Vec<f64> = (0..k)
        .map(|i| {
            let y = data.y(i)[channel];
            match d.measurement {
                MeasurementKind::Relative => y,
                MeasurementKind::Absolute => y - data.ug_meas[i],
            }
        })
        .collect();
    let duration = dt * (k - 1) as f64;
    let (w_lo, w_hi) = (
        2.0 * std::f64::consts::TAU / duration,
        0.5 * std::f64::consts::PI / dt,
    );
    if w_lo >= w_hi || !w_lo.is_finite() {
        bail!(
            "the record ({duration} s at dt = {dt} s) is too short to read the building's \
             frequency from it: give a `prior` in the config"
        );
    }
    const POINTS: usize = 600;
    let ratio = (w_hi / w_lo).powf(1.0 / (POINTS - 1) as f64);
    let grid: Vec<f64> = (0..POINTS).map(|i| w_lo * ratio.powi(i as i32)).collect();
    let pu: Vec<f64> = grid.iter().map(|&w| power(&data.ug_meas, dt, w)).collect();
    // Only where the ground motion has energy (within 30 dB of its strongest frequency): beyond
    // its band both spectra are measurement noise and their ratio means nothing (a record
    // sampled at 0.02 s and interpolated has almost no power near 50 Hz, so the noise of the
    // response over it peaks there).
    let pu_max = pu.iter().cloned().fold(0.0_f64, f64::max);
    let mut best = (0.0_f64, f64::NAN);
    for (&w, &pu) in grid.iter().zip(&pu) {
        if pu > 1e-3 * pu_max && pu > 0.0 {
            let r = power(&relative, dt, w) / pu;
            if r > best.0 {
                best = (r, w);
            }
        }
    }
    let omega1 = best.1;
    if !omega1.is_finite() {
        bail!("no spectral peak in the measured response: give a `prior` in the config");
    }
    let lambda1 = lowest_unit_eigenvalue(&d.masses);
    let k_median = omega1 * omega1 / lambda1;
    let mass_term = d.damping.has_mass_term();
    // With αM the dashpots are centred on the rest of the ratio (module documentation).
    let c_ratio = if mass_term {
        DAMPING_RATIO - ALPHA_DAMPING_RATIO
    } else {
        DAMPING_RATIO
    };
    let c_median = 2.0 * c_ratio * k_median / omega1;
    let building = d.building()?;
    let mut prior = ChainPrior::paper(d.storeys, building.hysteretic());
    prior.k = vec![
        Prior::LogNormal {
            median: k_median,
            log_sd: K_LOG_SD,
        };
        d.storeys
    ];
    prior.c = vec![
        Prior::LogNormal {
            median: c_median,
            log_sd: C_LOG_SD,
        };
        d.storeys
    ];
    let alpha = mass_term.then(|| alpha_prior(omega1));
    prior.alpha = alpha;
    Ok(ScaledPrior {
        storey,
        omega1,
        lambda1,
        k_median,
        c_median,
        damping_ratio: c_ratio,
        alpha_median: mass_term.then_some(2.0 * ALPHA_DAMPING_RATIO * omega1),
        prior,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_chain_eigenvalues_match_the_closed_form() {
        // A uniform chain with unit masses: λ_r = 4 sin²((2r − 1)π / (2(2N + 1))).
        for n in [1, 3, 10] {
            let want = 4.0
                * (std::f64::consts::PI / (2.0 * (2 * n + 1) as f64))
                    .sin()
                    .powi(2);
            let got = lowest_unit_eigenvalue(&vec![1.0; n]);
            assert!((got - want).abs() < 1e-12, "{n}: {got} vs {want}");
        }
        // Doubling every mass halves it.
        let a = lowest_unit_eigenvalue(&[1.0, 1.0, 1.0]);
        let b = lowest_unit_eigenvalue(&[2.0, 2.0, 2.0]);
        assert!((a - 2.0 * b).abs() < 1e-12);
    }

    #[test]
    fn hysteretic_substeps_follow_the_stated_thresholds() {
        // The paper's rate scaled with the building (ω₁·dt ≈ 0.007): one step.
        assert_eq!(hysteretic_substeps(5.54, 0.00125), 1);
        assert_eq!(hysteretic_substeps(1.41, 0.005), 1);
        // Just above the threshold: the fewest M with ω₁·dt/M ≤ 0.0035.
        assert_eq!(hysteretic_substeps(1.0, 0.0101), 3);
        // The ×4 building at 200 Hz: 0.0277/0.0035 = 7.9.
        assert_eq!(hysteretic_substeps(5.53, 0.005), 8);
        // Capped at the most measured (the frame at 120 Hz would ask for 55); nonsense is one
        // step.
        assert_eq!(hysteretic_substeps(0.19 * 120.0, 1.0 / 120.0), 8);
        assert_eq!(hysteretic_substeps(1e3, 0.01), HYSTERETIC_MAX_SUBSTEPS);
        assert_eq!(hysteretic_substeps(f64::NAN, 0.01), 1);
    }

    #[test]
    fn a_single_bin_dft_finds_a_sinusoid() {
        let dt = 0.01;
        let x: Vec<f64> = (0..4000).map(|i| (3.0 * i as f64 * dt).sin()).collect();
        let at = power(&x, dt, 3.0);
        assert!(at > 100.0 * power(&x, dt, 2.5) && at > 100.0 * power(&x, dt, 3.6));
        // |Σ sin(ωt) e^{-iωt}|² = (K/2)² for whole periods.
        assert!((at.sqrt() / 2000.0 - 1.0).abs() < 0.01, "{}", at.sqrt());
    }
}
