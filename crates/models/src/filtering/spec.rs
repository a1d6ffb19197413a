//! [`ChainSpec`]: everything the run-time partitions need (SPEC §3, §9), validated field by field.

use super::discretisation::Discretisation;
use super::prior::ChainPriorOf;
use super::prior::MarginalPrior;
use crate::building::{Building, BuildingError, Damping};
use crate::ground_between::GroundBetween;
use crate::law::{BoucWenLaw, HysteresisLaw};
use crate::priors::PriorError;
use crate::sensors::{MeasurementKind, SensorError, SensorLayout};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Invalid spec or partition construction; every message names the field.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpecError {
    #[error("invalid chain spec: {field}: {reason}")]
    Invalid { field: &'static str, reason: String },
    #[error("invalid chain spec: {0}")]
    Building(#[from] BuildingError),
    #[error("invalid chain spec: {0}")]
    Sensors(#[from] SensorError),
    #[error("invalid chain spec: prior: {0}")]
    Prior(#[from] PriorError),
    #[error(
        "invalid chain spec: discretisation: the {partition} partition does not support {discretisation} \
         (it is not linear in the marginalised parameters given the sampled path)"
    )]
    Unsupported {
        partition: &'static str,
        discretisation: Discretisation,
    },
    #[error(
        "invalid chain spec: substeps: the {partition} filter runs one transition per sample \
         (substeps = 1); sub-stepping is offered by the MPF-EKF2 and the bootstrap PF, whose \
         steps advance through the sub-steps between two measurements"
    )]
    SubstepsUnsupported { partition: &'static str },
    #[error(
        "invalid chain spec: damping: the {partition} partition does not support the {damping} \
         damping form ({reason}); use the MPF-EKF2 or the bootstrap PF"
    )]
    DampingUnsupported {
        partition: &'static str,
        damping: Damping,
        reason: &'static str,
    },
}

fn invalid(field: &'static str, reason: impl Into<String>) -> SpecError {
    SpecError::Invalid {
        field,
        reason: reason.into(),
    }
}

/// The chain, data and filter settings of the run-time partitions.
///
/// Storeys are 0-based in the building; the sensor layout takes and prints them 1-based. The
/// hysteretic elements follow the law `L` (its parameters' priors are in `prior`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, bound = "")]
pub struct ChainSpecOf<L: HysteresisLaw> {
    /// Time step (s).
    pub dt: f64,
    /// Masses (known), hysteretic storeys and damping form ([`Damping`]: per-storey dashpots,
    /// the default of SPEC §1, or with the mass-proportional term `αM` as well, whose α then has
    /// a prior in `prior.alpha` and sits in θ after `c1..cN`).
    pub building: Building,
    /// Measured storeys and measurement kind.
    pub sensors: SensorLayout,
    /// Measured ground acceleration `ug[k] = ü_g,meas(t_k)`, k = 0..=K.
    pub ug: Vec<f64>,
    /// Process-noise s.d. of the displacements.
    pub q_disp: f64,
    /// Process-noise s.d. of the velocities.
    pub q_vel: f64,
    /// Process-noise s.d. of each hysteretic variable (one per element).
    pub q_r: Vec<f64>,
    /// Measurement-noise variances, one per sensor.
    pub r_diag: Vec<f64>,
    pub prior: ChainPriorOf<L>,
    #[serde(default)]
    pub marginal_prior: MarginalPrior,
    #[serde(default)]
    pub discretisation: Discretisation,
    /// Transitions inside the filter per measurement interval (1: one per sample, SPEC §3).
    /// With `M > 1` the filter advances the discretised equations `M` times with `dt/M`
    /// between two measurements — `ü_g` interpolated linearly between its samples, each
    /// sub-step's process-noise variance `1/M` of the per-sample value so that the noise added
    /// over one sample interval is unchanged — and weights once with the measurement. For data
    /// sampled coarsely relative to the structure's highest modes; on the scaling study's
    /// buildings (ω·dt up to 0.45) four sub-steps changed no stiffness error beyond its test's
    /// threshold (`docs/scaling.md`).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub substeps: usize,
    /// Hold the marginalised stiffnesses, dampings and α to k, c, α ≥ 0 after every step by
    /// moment-matched truncation (`core_filters::linalg::support`): the answer is then physical
    /// by construction. Off in the SPEC's filters (the paper's Gaussians are unconstrained).
    #[serde(default, skip_serializing_if = "is_false")]
    pub physical_support: bool,
    /// Part of each channel's measurement noise is coloured, an AR(1) state per channel in the
    /// marginalised Gaussian ([`ColouredNoise`]); `None`: all of it white (SPEC §3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coloured_noise: Option<ColouredNoise>,
    /// `ü_g` between its samples on the sub-steps' grid ([`crate::ground_between`]): linear
    /// (SPEC §2, the default) or band-limited (a recorded ground motion).
    #[serde(default, skip_serializing_if = "GroundBetween::is_linear")]
    pub ground_between: GroundBetween,
    /// Known signals each channel adds with unknown coefficients ([`Regressors`]), marginalised
    /// in the Gaussian part (MPF-EKF2 only). Built by the caller from the data (never read
    /// from a file).
    #[serde(skip)]
    pub regressors: Option<Regressors>,
}

/// Known signals `s_c(k)` (one value per sample, k = 0..=K, as `ug`) that every channel adds
/// with its own unknown coefficients: `y_i(k) = h_i(x_k, θ) + Σ_c β_ic s_c(k) + noise`, each
/// `β_ic ~ N(0, prior_sd[i·C + c]²)` a static entry of the marginalised Gaussian, so the Kalman
/// part identifies them with θ (the observation is linear in them with the known Jacobian
/// `s_c(k)`). For a discrepancy term: the responses of extra linear modes to the ground motion.
#[derive(Debug, Clone, PartialEq)]
pub struct Regressors {
    pub columns: Vec<Vec<f64>>,
    /// Prior s.d. of β, channel-major (channel i, column c at `i·C + c`).
    pub prior_sd: Vec<f64>,
}

/// Coloured measurement noise: of each channel's variance `r_diag[i]`, the part `share` is an
/// AR(1) sequence `e_k = ρ e_{k−1} + w_k` (stationary variance `share·r_diag[i]`, started from
/// it), the rest white. `e` is one more state per channel of the marginalised Gaussian, so the
/// Kalman part carries it exactly (it is linear): the one-step prediction errors that a model
/// error makes correlated in time go into `e` rather than into θ (docs/validation.md,
/// "Coloured measurement noise"). MPF-EKF2 only.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColouredNoise {
    /// AR(1) coefficient per sample interval, in [0, 1).
    pub rho: f64,
    /// Part of each channel's measurement variance that is coloured, in (0, 1).
    pub share: f64,
}

impl ColouredNoise {
    /// ρ within [0, 1) and the share within (0, 1).
    pub fn validate(&self) -> Result<(), SpecError> {
        if !(self.rho.is_finite() && (0.0..1.0).contains(&self.rho)) {
            return Err(invalid(
                "coloured_noise.rho",
                format!("{} is not within [0, 1)", self.rho),
            ));
        }
        if !(self.share.is_finite() && self.share > 0.0 && self.share < 1.0) {
            return Err(invalid(
                "coloured_noise.share",
                format!("{} is not within (0, 1)", self.share),
            ));
        }
        Ok(())
    }

    /// (AR coefficient, innovation variance) per transition of a grid of `substeps` transitions
    /// per sample interval, for a stationary variance `var`: ρ^(1/M) and (1 − ρ^(2/M))·var, so
    /// that M transitions make the per-sample AR(1).
    pub fn per_transition(&self, substeps: usize, var: f64) -> (f64, f64) {
        let a = self.rho.powf(1.0 / substeps as f64);
        (a, (1.0 - a * a) * var)
    }
}

/// The spec of a chain with Bouc–Wen elements.
pub type ChainSpec = ChainSpecOf<BoucWenLaw>;

/// The paper's process noise of a hysteretic variable (SPEC §3): s.d. per step
/// 0.05 × dt × RMS of its element's drift velocity.
pub const SPEC_R_NOISE_FRACTION: f64 = 0.05;

/// Largest accepted [`ChainSpecOf::substeps`].
pub const MAX_SUBSTEPS: usize = 64;

fn one() -> usize {
    1
}

fn is_one(v: &usize) -> bool {
    *v == 1
}

fn is_false(v: &bool) -> bool {
    !*v
}

/// RMS values of the clean simulated signals from which [`ChainSpecOf::from_rms`] sets the noise
/// levels (SPEC §3).
#[derive(Debug, Clone, PartialEq)]
pub struct RmsLevels {
    /// RMS of the measured channel of each sensor (in the layout's kind).
    pub acc: Vec<f64>,
    /// RMS of the ground acceleration.
    pub ug: f64,
    /// RMS of the drift velocity δv of each hysteretic element.
    pub drift_velocity: Vec<f64>,
}

impl<L: HysteresisLaw> ChainSpecOf<L> {
    /// SPEC §3 settings from RMS values, generalised: R_ii = (nf·RMS a_i)² + (nf·RMS ü_g)² for
    /// relative data, (nf·RMS a_i)² for absolute data (the excitation error does not enter an
    /// absolute measurement); q_vel = dt·nf·RMS ü_g; q_r\[e\] = dt·0.05·RMS δv_e (the paper's σ_r,
    /// independent of nf); q_disp = 1e−6. Prior [`ChainPriorOf::paper`], moment-matched marginal
    /// prior, forward Euler. `noise_fraction` is 0.1 in the paper. The prior has no `alpha`, so
    /// `building` has the per-storey damping form here.
    pub fn from_rms(
        dt: f64,
        building: Building,
        sensors: SensorLayout,
        ug: Vec<f64>,
        rms: &RmsLevels,
        noise_fraction: f64,
    ) -> Result<Self, SpecError> {
        if rms.acc.len() != sensors.len() {
            return Err(invalid(
                "rms.acc",
                format!("{} values for {} sensors", rms.acc.len(), sensors.len()),
            ));
        }
        let hysteretic = building.hysteretic();
        if rms.drift_velocity.len() != hysteretic.len() {
            return Err(invalid(
                "rms.drift_velocity",
                format!(
                    "{} values for {} hysteretic elements",
                    rms.drift_velocity.len(),
                    hysteretic.len()
                ),
            ));
        }
        let named = [("rms.ug", rms.ug), ("noise_fraction", noise_fraction)];
        let acc = rms.acc.iter().map(|&a| ("rms.acc", a));
        let dv = rms
            .drift_velocity
            .iter()
            .map(|&a| ("rms.drift_velocity", a));
        for (field, v) in named.into_iter().chain(acc).chain(dv) {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(field, format!("{v} is not a non-negative number")));
            }
        }
        let nf = noise_fraction;
        let excitation = match sensors.kind() {
            MeasurementKind::Relative => (nf * rms.ug).powi(2),
            MeasurementKind::Absolute => 0.0,
        };
        let spec = Self {
            dt,
            prior: ChainPriorOf::paper(building.storeys(), hysteretic),
            q_disp: 1e-6,
            q_vel: dt * nf * rms.ug,
            q_r: rms
                .drift_velocity
                .iter()
                .map(|v| dt * SPEC_R_NOISE_FRACTION * v)
                .collect(),
            r_diag: rms
                .acc
                .iter()
                .map(|a| (nf * a).powi(2) + excitation)
                .collect(),
            building,
            sensors,
            ug,
            marginal_prior: MarginalPrior::MomentMatched,
            discretisation: Discretisation::Euler,
            substeps: 1,
            physical_support: false,
            coloured_noise: None,
            ground_between: Default::default(),
            regressors: None,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Sets the process noise of every hysteretic variable to `fraction` × dt × its element's
    /// RMS drift velocity, in place of [`SPEC_R_NOISE_FRACTION`] (the value [`Self::from_rms`]
    /// sets): `q_r[e]` is scaled by `fraction / SPEC_R_NOISE_FRACTION`, so the SPEC's fraction
    /// leaves it bit for bit. A non-positive or non-finite fraction is refused.
    pub fn set_r_noise_fraction(&mut self, fraction: f64) -> Result<(), SpecError> {
        if !(fraction.is_finite() && fraction > 0.0) {
            return Err(invalid(
                "r_noise_fraction",
                format!("{fraction} is not a positive number"),
            ));
        }
        if fraction != SPEC_R_NOISE_FRACTION {
            let scale = fraction / SPEC_R_NOISE_FRACTION;
            self.q_r.iter_mut().for_each(|q| *q *= scale);
        }
        Ok(())
    }

    /// Number of storeys N.
    pub fn n_storeys(&self) -> usize {
        self.building.storeys()
    }

    /// Checks every field; the partitions' constructors call it.
    pub fn validate(&self) -> Result<(), SpecError> {
        self.check_storey_counts()?;
        self.check_time_and_input()?;
        self.check_noise()?;
        self.check_prior_against_building()
    }

    /// The sensor layout and the prior made for the building's storeys; the layout itself
    /// valid.
    fn check_storey_counts(&self) -> Result<(), SpecError> {
        let n = self.n_storeys();
        if self.sensors.n_storeys() != n {
            return Err(invalid(
                "masses",
                format!(
                    "{n} masses, but the sensor layout was made for {} storeys",
                    self.sensors.n_storeys()
                ),
            ));
        }
        if self.prior.n_storeys() != n || self.prior.c.len() != n {
            return Err(invalid(
                "masses",
                format!(
                    "{n} masses, but the prior has {} stiffness and {} damping priors",
                    self.prior.n_storeys(),
                    self.prior.c.len()
                ),
            ));
        }
        // Re-validate the layout itself (it may come from deserialisation of a changed file).
        SensorLayout::new(n, &self.sensors.one_based(), self.sensors.kind())?;
        Ok(())
    }

    /// A positive step, sub-steps within limits, and an input of at least one step, finite.
    fn check_time_and_input(&self) -> Result<(), SpecError> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(invalid("dt", format!("{} is not positive", self.dt)));
        }
        if !(1..=MAX_SUBSTEPS).contains(&self.substeps) {
            return Err(invalid(
                "substeps",
                format!("{} is not within 1..={MAX_SUBSTEPS}", self.substeps),
            ));
        }
        if self.ug.len() < 2 {
            return Err(invalid(
                "ug",
                "at least two samples (one step) are required",
            ));
        }
        if let Some(k) = self.ug.iter().position(|u| !u.is_finite()) {
            return Err(invalid("ug", format!("sample {k} is not finite")));
        }
        Ok(())
    }

    /// Process noise s.d.s non-negative (one per hysteretic element for `q_r`), measurement
    /// variances positive (one per sensor).
    fn check_noise(&self) -> Result<(), SpecError> {
        for (field, v) in [("q_disp", self.q_disp), ("q_vel", self.q_vel)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(field, format!("{v} is not a non-negative s.d.")));
            }
        }
        let hysteretic = self.building.hysteretic();
        if self.q_r.len() != hysteretic.len() {
            return Err(invalid(
                "q_r",
                format!(
                    "{} values for {} hysteretic elements",
                    self.q_r.len(),
                    hysteretic.len()
                ),
            ));
        }
        if let Some(q) = self.q_r.iter().find(|q| !(q.is_finite() && **q >= 0.0)) {
            return Err(invalid("q_r", format!("{q} is not a non-negative s.d.")));
        }
        if self.r_diag.len() != self.sensors.len() {
            return Err(invalid(
                "r_diag",
                format!(
                    "{} variances for {} sensors",
                    self.r_diag.len(),
                    self.sensors.len()
                ),
            ));
        }
        if let Some(r) = self.r_diag.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
            return Err(invalid("r_diag", format!("variance {r} is not positive")));
        }
        if let Some(c) = &self.coloured_noise {
            c.validate()?;
        }
        if let Some(r) = &self.regressors {
            if let Some(c) = r.columns.iter().find(|c| c.len() != self.ug.len()) {
                return Err(invalid(
                    "regressors",
                    format!(
                        "a column of {} values for {} samples",
                        c.len(),
                        self.ug.len()
                    ),
                ));
            }
            if r.columns.iter().flatten().any(|v| !v.is_finite()) {
                return Err(invalid("regressors", "a value is not finite"));
            }
            if r.prior_sd.len() != r.columns.len() * self.sensors.len()
                || r.prior_sd.iter().any(|s| !(s.is_finite() && *s > 0.0))
            {
                return Err(invalid(
                    "regressors.prior_sd",
                    "not one positive s.d. per channel and column",
                ));
            }
        }
        Ok(())
    }

    /// The prior describes the building's elements and damping form, is valid itself, and
    /// its per-particle spread (if any) is a non-negative number.
    fn check_prior_against_building(&self) -> Result<(), SpecError> {
        if self.prior.hysteretic_storeys() != self.building.hysteretic() {
            return Err(invalid(
                "prior",
                "the element priors are not at the hysteretic storeys, in order",
            ));
        }
        let damping = self.building.damping();
        if self.prior.damping() != damping {
            return Err(invalid(
                "prior.alpha",
                match damping {
                    Damping::StoreyMass => {
                        "the storey+mass damping form needs a prior for alpha".to_string()
                    }
                    Damping::Storey => {
                        format!("a prior for alpha is given, but the damping form is {damping}")
                    }
                },
            ));
        }
        self.prior.validate()?;
        if let MarginalPrior::PerParticle { rel_sd } = self.marginal_prior {
            if !(rel_sd.is_finite() && rel_sd >= 0.0) {
                return Err(invalid(
                    "marginal_prior",
                    format!("rel_sd {rel_sd} is not a non-negative number"),
                ));
            }
        }
        Ok(())
    }
}
