//! Filter partitions of the N-storey Bouc–Wen shear chain (SPEC §5).
//!
//! The chain (SPEC §1, generalised to N ≥ 1 storeys and known masses m_j): element j links
//! storey j−1 to storey j (storey 0 is the ground). Element 1 is a Bouc–Wen spring with a dashpot,
//! force F_1 = k1·r1 + c1·ẋ1; elements j ≥ 2 are linear, F_j = k_j (x_j − x_{j−1}) +
//! c_j (ẋ_j − ẋ_{j−1}). The equations of motion are
//!
//! ```text
//! m_j ẍ_j = −m_j ü_g − F_j + F_{j+1}            (F_{N+1} = 0)
//! ṙ1 = ẋ1 − β |ẋ1| |r1|^(n−1) r1 − γ ẋ1 |r1|^n   (SPEC eq. 22)
//! ```
//!
//! which for N = 3 and unit masses are exactly SPEC §1. θ = [k1..kN, c1..cN, β, γ, n]; the physical
//! states are x1..xN, ẋ1..ẋN (named `v1..vN`) and r1.
//!
//! Three partitions implement the `core_filters::model` traits:
//! - [`augmented::AugmentedChain`]: the augmented state for the bootstrap PF (SPEC §5.1);
//! - [`mln::MlnChain`]: the mixed linear/nonlinear partition of MLN-RBPF and Storvik (SPEC §5.2–5.3);
//! - [`mpf::MpfChain`]: the conditionally bilinear partition of MPF-EKF2 (SPEC §5.4, §6).
//!
//! All take the same [`FilterSpec`]. Discretisation is forward Euler with step `dt` (SPEC §3): the
//! transition from k−1 to k uses `ug[k−1]`, the measurement at k uses `ug[k]`. Every partition
//! evaluates the element forces through the one kernel of this module, so the three agree to
//! round-off (tested in `tests/partition_derivatives.rs`).
//!
//! ```
//! use core_filters::model::ConditionallyQuadratic;
//! use models::partition::{FilterSpec, PaperMpf, PartitionError};
//! use nalgebra::{SVector, Vector3};
//!
//! // SPEC §3 settings from RMS values of the clean signals (3 storeys, unit masses).
//! let ug = vec![0.0; 101];
//! let spec = FilterSpec::from_rms(0.005, vec![1.0; 3], ug, &[2.0, 3.0, 4.0], 3.0, 0.5, 0.1)?;
//! let mpf = PaperMpf::new(spec)?;
//! // y_2 has 7 constant second derivatives (SPEC §6), y_1 and y_3 have 3 and 4.
//! assert_eq!(mpf.observation_hessians().entries().len(), 14);
//! let (y, jac) = mpf.observation(1, &Vector3::new(0.1, 0.2, 2.0), &SVector::<f64, 13>::zeros());
//! assert_eq!((y.len(), jac.ncols()), (3, 13));
//! # Ok::<(), PartitionError>(())
//! ```

pub mod augmented;
pub mod mln;
pub mod mpf;

pub use augmented::{AugmentedChain, PaperAugmented};
pub use mln::{MlnChain, PaperMln};
pub use mpf::{MpfChain, PaperMpf};

use crate::priors::{ParameterPrior, PriorError};
use rand::Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// What the accelerometers measure (SPEC §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeasurementKind {
    /// Relative accelerations ẍ_j (eq. 29b: h = −ü_g).
    #[default]
    Relative,
    /// Absolute accelerations ẍ_j + ü_g (h has no ü_g term).
    Absolute,
}

/// Gaussian prior of the marginalised block (SPEC §3).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MarginalPrior {
    /// One Gaussian moment-matched to the priors, identical for all particles.
    #[default]
    MomentMatched,
    /// Per-particle means drawn from the true priors, covariance diag((rel_sd·mean)²) where
    /// `mean` is the particle's drawn mean. Parameters with a point-mass prior keep variance 0.
    /// Note that a draw of γ close to 0 gets a correspondingly small variance.
    PerParticle { rel_sd: f64 },
}

/// Everything the partitions need: structure constants, measured excitation, noise levels and
/// priors (SPEC §3). Independent of the simulation code on purpose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilterSpec {
    /// Euler time step (s).
    pub dt: f64,
    /// Storey masses m_1..m_N (known); N = `masses.len()`.
    pub masses: Vec<f64>,
    /// Measured ground acceleration, `ug[k] = ü_g,meas(t_k)`, k = 0..=K.
    pub ug: Vec<f64>,
    /// Process-noise s.d. of the displacements.
    pub q_disp_sd: f64,
    /// Process-noise s.d. of the velocities.
    pub q_vel_sd: f64,
    /// Process-noise s.d. of r1.
    pub q_r_sd: f64,
    /// Measurement-noise variances R_ii, one per channel (storey).
    pub r_diag: Vec<f64>,
    #[serde(default)]
    pub measurement: MeasurementKind,
    pub prior: ParameterPrior,
    #[serde(default)]
    pub marginal_prior: MarginalPrior,
}

/// Invalid partition construction.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PartitionError {
    /// A const dimension of the partition type does not match the number of storeys.
    #[error("{what}: the type has dimension {got}, {n_storeys} storeys need {expected}")]
    DimensionMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
        n_storeys: usize,
    },
    /// A field of the [`FilterSpec`] is invalid.
    #[error("invalid filter spec: {field}: {reason}")]
    InvalidSpec { field: &'static str, reason: String },
    /// The prior is invalid.
    #[error(transparent)]
    Prior(#[from] PriorError),
}

fn invalid(field: &'static str, reason: impl Into<String>) -> PartitionError {
    PartitionError::InvalidSpec {
        field,
        reason: reason.into(),
    }
}

impl FilterSpec {
    /// SPEC §3 settings from RMS values of the clean simulated signals:
    /// R_ii = (nf·RMS ẍ_i)² + (nf·RMS ü_g)² (the excitation error enters y through h = −ü_g);
    /// Q: displacements (1e−6)², velocities (dt·nf·RMS ü_g)², r1 (dt·0.05·RMS ẋ1)² (the paper's
    /// σ_r = dt × 5% RMS ẋ, independent of `nf`). Prior: [`ParameterPrior::paper`]; relative
    /// measurements; moment-matched marginal prior. `noise_fraction` is 0.1 in the paper.
    pub fn from_rms(
        dt: f64,
        masses: Vec<f64>,
        ug: Vec<f64>,
        rms_acc: &[f64],
        rms_ug: f64,
        rms_v1: f64,
        noise_fraction: f64,
    ) -> Result<Self, PartitionError> {
        let n = masses.len();
        if rms_acc.len() != n {
            return Err(invalid(
                "rms_acc",
                format!("{} values for {n} storeys", rms_acc.len()),
            ));
        }
        for (field, v) in [
            ("rms_ug", rms_ug),
            ("rms_v1", rms_v1),
            ("noise_fraction", noise_fraction),
        ]
        .into_iter()
        .chain(rms_acc.iter().map(|&a| ("rms_acc", a)))
        {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(field, format!("{v} is not a non-negative number")));
            }
        }
        let nf = noise_fraction;
        let spec = Self {
            dt,
            ug,
            q_disp_sd: 1e-6,
            q_vel_sd: dt * nf * rms_ug,
            q_r_sd: dt * 0.05 * rms_v1,
            r_diag: rms_acc
                .iter()
                .map(|a| (nf * a).powi(2) + (nf * rms_ug).powi(2))
                .collect(),
            measurement: MeasurementKind::Relative,
            prior: ParameterPrior::paper(n),
            marginal_prior: MarginalPrior::MomentMatched,
            masses,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Number of storeys N.
    pub fn n_storeys(&self) -> usize {
        self.masses.len()
    }

    /// Checks every field (the constructors of the partitions call it).
    pub fn validate(&self) -> Result<(), PartitionError> {
        let n = self.n_storeys();
        if n == 0 {
            return Err(invalid("masses", "at least one storey is required"));
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(invalid("dt", format!("{} is not positive", self.dt)));
        }
        if let Some(m) = self.masses.iter().find(|m| !(m.is_finite() && **m > 0.0)) {
            return Err(invalid("masses", format!("mass {m} is not positive")));
        }
        if self.ug.is_empty() {
            return Err(invalid("ug", "the excitation is empty"));
        }
        if let Some(k) = self.ug.iter().position(|u| !u.is_finite()) {
            return Err(invalid("ug", format!("sample {k} is not finite")));
        }
        for (field, v) in [
            ("q_disp_sd", self.q_disp_sd),
            ("q_vel_sd", self.q_vel_sd),
            ("q_r_sd", self.q_r_sd),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(field, format!("{v} is not a non-negative s.d.")));
            }
        }
        if self.r_diag.len() != n {
            return Err(invalid(
                "r_diag",
                format!("{} variances for {n} channels", self.r_diag.len()),
            ));
        }
        if let Some(r) = self.r_diag.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
            return Err(invalid("r_diag", format!("variance {r} is not positive")));
        }
        if self.prior.n_storeys() != n {
            return Err(invalid(
                "prior",
                format!(
                    "{} stiffness priors for {n} storeys",
                    self.prior.n_storeys()
                ),
            ));
        }
        self.prior.validate()?;
        if let MarginalPrior::PerParticle { rel_sd } = self.marginal_prior {
            if !(rel_sd.is_finite() && rel_sd >= 0.0) {
                return Err(invalid(
                    "marginal_prior",
                    format!("rel_sd {rel_sd} is negative"),
                ));
            }
        }
        Ok(())
    }
}

/// Names of the physical states: `x1..xN, v1..vN, r1`.
pub fn state_names(n_storeys: usize) -> Vec<String> {
    let mut names: Vec<String> = (1..=n_storeys).map(|j| format!("x{j}")).collect();
    names.extend((1..=n_storeys).map(|j| format!("v{j}")));
    names.push("r1".to_string());
    names
}

pub(crate) fn check_dim(
    what: &'static str,
    got: usize,
    expected: usize,
    n_storeys: usize,
) -> Result<(), PartitionError> {
    if got == expected {
        Ok(())
    } else {
        Err(PartitionError::DimensionMismatch {
            what,
            expected,
            got,
            n_storeys,
        })
    }
}

/// A point (states, θ) of the chain seen through one partition's storage. Storeys are 1-based.
pub(crate) trait ChainPoint {
    fn x(&self, j: usize) -> f64;
    fn v(&self, j: usize) -> f64;
    fn r1(&self) -> f64;
    fn k(&self, j: usize) -> f64;
    fn c(&self, j: usize) -> f64;
    fn beta(&self) -> f64;
    fn gamma(&self) -> f64;
    fn n(&self) -> f64;
}

/// `(|r|^(n−1)·r, |r|^n)`, the two nonlinear Bouc–Wen terms, with their limit 0 at r = 0
/// (n > 0), which avoids `0^(n−1) = ∞` times 0 for n < 1.
#[inline]
pub(crate) fn bouc_wen_terms(r: f64, n: f64) -> (f64, f64) {
    let a = r.abs();
    if a == 0.0 {
        (0.0, 0.0)
    } else {
        let p = a.powf(n - 1.0);
        (p * r, p * a)
    }
}

/// The shared force kernel and constants of the chain.
#[derive(Debug, Clone)]
pub(crate) struct ChainCore {
    pub n: usize,
    pub dt: f64,
    pub inv_mass: Vec<f64>,
    pub measurement: MeasurementKind,
    /// Moment-matched θ means and variances (SPEC §3), computed once.
    pub theta_mean: Vec<f64>,
    pub theta_var: Vec<f64>,
}

impl ChainCore {
    pub fn new(spec: &FilterSpec) -> Result<Self, PartitionError> {
        spec.validate()?;
        let (theta_mean, theta_var) = spec.prior.moments();
        Ok(Self {
            n: spec.n_storeys(),
            dt: spec.dt,
            inv_mass: spec.masses.iter().map(|m| 1.0 / m).collect(),
            measurement: spec.measurement,
            theta_mean,
            theta_var,
        })
    }

    /// `(d_j, dv_j)` with F_j = k_j·d_j + c_j·dv_j: (r1, ẋ1) for j = 1, the storey drifts otherwise.
    #[inline]
    pub fn element_coefficients(p: &impl ChainPoint, j: usize) -> (f64, f64) {
        if j == 1 {
            (p.r1(), p.v(1))
        } else {
            (p.x(j) - p.x(j - 1), p.v(j) - p.v(j - 1))
        }
    }

    /// Force F_j of element j.
    #[inline]
    pub fn element_force(p: &impl ChainPoint, j: usize) -> f64 {
        let (d, dv) = Self::element_coefficients(p, j);
        p.k(j) * d + p.c(j) * dv
    }

    /// `ground + (−F_j + F_{j+1}) / m_j`; `ground` is −ü_g for the relative acceleration.
    #[inline]
    pub fn acceleration(&self, p: &impl ChainPoint, j: usize, ground: f64) -> f64 {
        let mut net = -Self::element_force(p, j);
        if j < self.n {
            net += Self::element_force(p, j + 1);
        }
        ground + net * self.inv_mass[j - 1]
    }

    /// ṙ1 (SPEC eq. 22).
    #[inline]
    pub fn r1_rate(p: &impl ChainPoint) -> f64 {
        let v1 = p.v(1);
        let (a, b) = bouc_wen_terms(p.r1(), p.n());
        v1 - p.beta() * v1.abs() * a - p.gamma() * v1 * b
    }

    /// `∂ṙ1/∂β, ∂ṙ1/∂γ` = (−|ẋ1||r1|^(n−1) r1, −ẋ1|r1|^n).
    #[inline]
    pub fn r1_rate_shape_gradient(p: &impl ChainPoint) -> (f64, f64) {
        let v1 = p.v(1);
        let (a, b) = bouc_wen_terms(p.r1(), p.n());
        (-v1.abs() * a, -v1 * b)
    }

    /// The ground term of the Euler transition from k−1 to k: −ü_g,meas(k−1).
    #[inline]
    pub fn transition_ground(ug: &[f64], k: usize) -> f64 {
        assert!(k >= 1, "the transition to step k needs k >= 1");
        -ug[k - 1]
    }

    /// The ground term of the measurement at k: −ü_g,meas(k) (relative) or 0 (absolute).
    #[inline]
    pub fn measurement_ground(&self, ug: &[f64], k: usize) -> f64 {
        match self.measurement {
            MeasurementKind::Relative => -ug[k],
            MeasurementKind::Absolute => 0.0,
        }
    }

    /// Mean and variance of the Gaussian prior of θ for one particle (SPEC §3), written into
    /// `mean` and `var` (length 2N+3). Called once per particle at start-up.
    pub fn marginal_theta_prior<G: Rng + ?Sized>(
        &self,
        spec: &FilterSpec,
        rng: &mut G,
        mean: &mut [f64],
        var: &mut [f64],
    ) {
        match spec.marginal_prior {
            MarginalPrior::MomentMatched => {
                mean.copy_from_slice(&self.theta_mean);
                var.copy_from_slice(&self.theta_var);
            }
            MarginalPrior::PerParticle { rel_sd } => {
                spec.prior.sample_into(rng, mean);
                for ((v, m), v0) in var.iter_mut().zip(mean.iter()).zip(&self.theta_var) {
                    *v = if *v0 > 0.0 { (rel_sd * m).powi(2) } else { 0.0 };
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec3() -> FilterSpec {
        FilterSpec::from_rms(
            0.005,
            vec![1.0; 3],
            vec![0.0; 11],
            &[2.0, 3.0, 4.0],
            5.0,
            0.6,
            0.1,
        )
        .unwrap()
    }

    #[test]
    fn from_rms_follows_spec_section_3() {
        let s = spec3();
        assert_eq!(s.q_disp_sd, 1e-6);
        assert!((s.q_vel_sd - 0.005 * 0.1 * 5.0).abs() < 1e-15);
        assert!((s.q_r_sd - 0.005 * 0.05 * 0.6).abs() < 1e-15);
        for (r, a) in s.r_diag.iter().zip([2.0, 3.0, 4.0]) {
            let expected: f64 = (0.1 * a) * (0.1 * a) + 0.5 * 0.5;
            assert!((r - expected).abs() < 1e-14, "{r} vs {expected}");
        }
        assert_eq!(s.prior, ParameterPrior::paper(3));
        assert_eq!(s.measurement, MeasurementKind::Relative);
        assert_eq!(s.marginal_prior, MarginalPrior::MomentMatched);
    }

    #[test]
    fn validation_reports_the_bad_field() {
        let field = |s: &FilterSpec| match s.validate() {
            Err(PartitionError::InvalidSpec { field, .. }) => field,
            other => panic!("expected InvalidSpec, got {other:?}"),
        };
        let mut s = spec3();
        s.dt = 0.0;
        assert_eq!(field(&s), "dt");
        let mut s = spec3();
        s.masses[1] = -1.0;
        assert_eq!(field(&s), "masses");
        let mut s = spec3();
        s.r_diag.pop();
        assert_eq!(field(&s), "r_diag");
        let mut s = spec3();
        s.ug[3] = f64::NAN;
        assert_eq!(field(&s), "ug");
        let mut s = spec3();
        s.q_vel_sd = -1.0;
        assert_eq!(field(&s), "q_vel_sd");
        let mut s = spec3();
        s.prior = ParameterPrior::paper(2);
        assert_eq!(field(&s), "prior");
        let mut s = spec3();
        s.prior.n = crate::priors::Prior::Uniform { lo: 5.0, hi: 1.0 };
        assert!(matches!(s.validate(), Err(PartitionError::Prior(_))));
        assert!(matches!(
            FilterSpec::from_rms(0.005, vec![1.0; 3], vec![0.0], &[1.0], 1.0, 1.0, 0.1),
            Err(PartitionError::InvalidSpec {
                field: "rms_acc",
                ..
            })
        ));
    }

    #[test]
    fn spec_round_trips_through_serde() {
        let mut s = spec3();
        s.measurement = MeasurementKind::Absolute;
        s.marginal_prior = MarginalPrior::PerParticle { rel_sd: 0.05 };
        let json = serde_json::to_string(&s).unwrap();
        assert!(json.contains(r#""measurement":"absolute""#), "{json}");
        let back: FilterSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn bouc_wen_terms_are_finite_at_zero() {
        assert_eq!(bouc_wen_terms(0.0, 0.5), (0.0, 0.0));
        let (a, b) = bouc_wen_terms(-0.5, 2.0);
        assert!((a - (-0.25)).abs() < 1e-15 && (b - 0.25).abs() < 1e-15);
        let (a, b) = bouc_wen_terms(0.3, 1.0);
        assert!((a - 0.3).abs() < 1e-15 && (b - 0.3).abs() < 1e-15);
    }
}
