//! What the validation without the truth writes into a record ([`crate::validation`]): the
//! free run of the identified model on a record and the comparison of its modes with the
//! measured transfer functions.

use models::integrate::Tolerance;
use models::modal::Mode;
use models::sensors::MeasurementKind;
use serde::{Deserialize, Serialize};

use super::number;

/// The spread of the fit over the band's draws: 2.5 %, 50 % and 97.5 % percentiles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelFit {
    pub channel: String,
    /// Fit of the free run at θ_val, in %.
    #[serde(with = "number::scalar")]
    pub fit_percent: f64,
    /// NRMSE of the free run at θ_val (RMSE / RMS of the measured channel).
    #[serde(with = "number::scalar")]
    pub nrmse: f64,
    /// Fit of the physical model alone (without the discrepancy term), in %; absent when the
    /// free run has no discrepancy.
    #[serde(
        default,
        with = "number::opt_scalar",
        skip_serializing_if = "Option::is_none"
    )]
    pub physical_fit_percent: Option<f64>,
    /// Fit of the band's draws: 2.5, 50 and 97.5 % percentiles (absent without a band).
    #[serde(
        default,
        with = "number::opt_vec",
        skip_serializing_if = "Option::is_none"
    )]
    pub fit_draws: Option<Vec<f64>>,
    /// Per cent of the kept samples of the measured channel inside the predictive band
    /// (`band_lo`..`band_hi`: parameters and model error); absent without a band.
    #[serde(
        default,
        with = "number::opt_scalar",
        skip_serializing_if = "Option::is_none"
    )]
    pub coverage_percent: Option<f64>,
}

/// Where the model error's scale was learned (`crate::validation::prediction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ErrorSource {
    /// On the held-out part of the identifying record (its last `samples` samples), by a θ
    /// identified without them: an out-of-sample scale.
    HeldOut { samples: usize },
    /// On the identifying record by its own θ_val: in-sample, narrower than a new record needs.
    InSample,
}

/// The model-error part of the predictive band (`crate::validation::prediction`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelError {
    pub source: ErrorSource,
    /// The channels it was learned on, in the order of `quantile`.
    pub channels: Vec<String>,
    /// Window of the local scale of the predicted motion (s).
    #[serde(with = "number::scalar")]
    pub window_s: f64,
    /// Per channel: the constant part of the local scale, as a fraction of the predicted RMS.
    #[serde(with = "number::vec")]
    pub floor: Vec<f64>,
    /// Per channel: the 95 % quantile of |y − ŷ| / local scale.
    #[serde(with = "number::vec")]
    pub quantile: Vec<f64>,
}

/// How the band was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BandInfo {
    pub method: String,
    pub purpose: String,
    pub draws: usize,
    /// Draws that were valid structures and integrated; the others are left out (first reason).
    pub valid: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub invalid_reason: Option<String>,
    /// Whether θ was drawn with the posterior's correlations (`theta_correlation`), else
    /// independently (records without correlations).
    #[serde(default)]
    pub correlated: bool,
    /// Whether θ was drawn from the one Gaussian filter's posterior N(θ_val, Σ) itself (kept
    /// inside every 95 % interval), else through the copula of the record's quantiles.
    #[serde(default)]
    pub gaussian: bool,
    /// Whether each θ was shifted to another record's by the spread between the identifying
    /// record's parts (the band of a record kept out of the identification), so that the
    /// draws may leave the record's own 95 % intervals.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub shifted: bool,
}

/// The free run of an identified model on one record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeRun {
    /// What was simulated and how.
    pub method: String,
    pub integrator: Integrator,
    pub measurement: MeasurementKind,
    pub channels: Vec<ChannelFit>,
    /// The band, or why there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band: Option<BandInfo>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band_error: Option<String>,
    /// The model error the band includes, and where it was learned (absent: the band holds
    /// the parameters' spread only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_error: Option<ModelError>,
    /// The discrepancy term added to the physical model's prediction (absent: none was chosen
    /// or none applies); `simulated` and the fits include it, `physical_fit_percent` does not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrepancy: Option<Discrepancy>,
    /// The series below keep one sample in `every`.
    pub every: usize,
    #[serde(with = "number::vec")]
    pub t: Vec<f64>,
    /// Per channel: measured, simulated at θ_val, and the 95 % predictive band: the pointwise
    /// 2.5 % and 97.5 % percentiles of the band's draws widened by the model error (`model_error`)
    /// where there is one (empty without either).
    #[serde(with = "number::vec_vec")]
    pub measured: Vec<Vec<f64>>,
    #[serde(with = "number::vec_vec")]
    pub simulated: Vec<Vec<f64>>,
    #[serde(default, with = "number::vec_vec")]
    pub band_lo: Vec<Vec<f64>>,
    #[serde(default, with = "number::vec_vec")]
    pub band_hi: Vec<Vec<f64>>,
}

/// One mode of a discrepancy term (`crate::validation::discrepancy`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscrepancyMode {
    pub frequency_hz: f64,
    pub damping_ratio: f64,
}

/// The discrepancy term of a free run: linear modes driven by the ground motion, added to the
/// physical model's prediction of each channel (`crate::validation::discrepancy`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Discrepancy {
    /// The channels it was fitted to, in the order of `coefficients`.
    pub channels: Vec<String>,
    pub modes: Vec<DiscrepancyMode>,
    /// Per channel, per mode: the coefficients of `ω² q` and `ω q̇`.
    pub coefficients: Vec<Vec<[f64; 2]>>,
}

impl Discrepancy {
    /// No mode, on `channels`.
    pub fn none(channels: &[String]) -> Self {
        Discrepancy {
            channels: channels.to_vec(),
            modes: Vec::new(),
            coefficients: vec![Vec::new(); channels.len()],
        }
    }

    /// Its modes as `f Hz (ζ %)`, or "none".
    pub fn describe_modes(&self) -> String {
        if self.modes.is_empty() {
            return "none".into();
        }
        self.modes
            .iter()
            .map(|m| {
                format!(
                    "{:.2} Hz ({:.2} %)",
                    m.frequency_hz,
                    100.0 * m.damping_ratio
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A model mode beside the measured peak it is paired with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModePair {
    /// 1-based mode number.
    pub mode: usize,
    pub model_hz: f64,
    pub damping_ratio: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_hz: Option<f64>,
    /// 100·(model − measured)/measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub difference_percent: Option<f64>,
    /// The record's ground-motion power near this mode, in dB below its strongest frequency
    /// (`validation::spectral`); a mode below the band's −30 dB is not excited and not paired.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excitation_db: Option<f64>,
    /// The central 95 % of this mode's natural frequency (Hz) and damping ratio over θ drawn
    /// from the posterior as the free-run band on the record draws it, never shifted as on another
    /// record (`validation::modal_intervals`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_hz_95: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_ratio_95: Option<[f64; 2]>,
    /// The model's undamped mode shape at θ_val over storeys 1..N, its largest component +1
    /// (`validation::shapes`; absent for one storey or one measured channel).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_shape: Vec<f64>,
    /// Per storey, the central 95 % of that shape over θ drawn from the posterior.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_shape_95: Vec<[f64; 2]>,
    /// The measured operating shape at the paired peak: Im H1 per measured channel
    /// (quadrature picking, `validation::spectral::operating_shape`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub operating_shape: Vec<f64>,
    /// The modal assurance criterion between the model's shape on the measured floors and the
    /// operating shape (1: the same shape; 0: orthogonal), and its central 95 % over the draws.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mac: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mac_95: Option<[f64; 2]>,
}

/// Modes of the identified linearised model and the measured transfer functions.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ModalComparison {
    pub linearisation: String,
    pub modes: Vec<Mode>,
    pub overdamped: usize,
    pub method: String,
    pub segment: usize,
    pub segments: usize,
    #[serde(with = "number::scalar")]
    pub resolution_hz: f64,
    /// Bins of the ground motion's band (see [`crate::validation::spectral`]), and |H1| per channel on them.
    #[serde(with = "number::vec")]
    pub frequency_hz: Vec<f64>,
    pub channels: Vec<String>,
    #[serde(with = "number::vec_vec")]
    pub magnitude: Vec<Vec<f64>>,
    pub peaks: Vec<Peak>,
    pub pairs: Vec<ModePair>,
    /// Why a part is missing (the model's modes, or the transfer functions).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub errors: Vec<String>,
}

/// How the free run integrates the equations of motion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Adaptive Dormand–Prince 5(4) ([`models::integrate::simulate_adaptive`], the validation integrator of SPEC §7)
    /// with these tolerances.
    Adaptive(Tolerance),
    /// Classical RK4, one step per sample ([`models::integrate::simulate_rk4`], the data generator's scheme).
    Rk4,
    /// A building without hysteretic element: the exact solution under the ground motion linear
    /// between samples ([`models::integrate::simulate_linear_exact`]), the solution the adaptive
    /// integrator approaches to its tolerance.
    ExactLinear,
}

/// A peak of the summed transfer magnitude.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Peak {
    pub frequency_hz: f64,
    /// Σ over channels of |H1| at the peak's bin.
    pub magnitude: f64,
}
