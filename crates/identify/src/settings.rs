//! The filter settings of a run ([`FilterSettings`]): what a config file, a study's `[filter]`
//! table or the command line set, checked by [`crate::limits`] and run by [`crate::pipeline`].

use std::collections::BTreeMap;

use core_filters::resampling::Scheme;
use core_filters::smc::rejuvenation::LiuWest;
use core_filters::smc::storvik::StorvikUpdate;
use models::filtering::{ChainPrior, Discretisation, MarginalPrior};
use serde::{Deserialize, Serialize};

use crate::field::StructureSettings;

/// Filter settings of a run; every field has the SPEC default and is written into the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilterSettings {
    /// Number of particles `Np` (SPEC §3: 500).
    pub particles: usize,
    /// Resampling scheme (SPEC §3: systematic).
    pub resampling: Scheme,
    /// Resample only when ESS < threshold·Np; absent: every step (SPEC §3).
    pub ess_threshold: Option<f64>,
    /// Storvik's step (iii): `linearised` (the paper's) or `exact`.
    pub storvik_update: StorvikUpdate,
    /// Point-mass priors: parameter name → value (e.g. `k1 = 8.0`).
    pub fix: BTreeMap<String, f64>,
    /// Prior of θ; absent: SPEC §3's priors for the data set's structure.
    pub prior: Option<ChainPrior>,
    /// Gaussian prior of the marginalised block.
    pub marginal_prior: MarginalPrior,
    /// Noise fraction used to set R and Q from RMS values (SPEC §3: 0.1).
    pub noise_fraction: f64,
    /// Discretisation of the equations of motion inside the filters (SPEC §3: forward Euler).
    pub discretisation: Discretisation,
    /// Transitions inside the filter per sample interval (1: one, SPEC §3; `"auto"`: chosen from
    /// the prior's building, [`models::filtering::substeps`]); more than one for the MPF-EKF2 and
    /// bootstrap PF only ([`models::filtering::ChainSpec::substeps`]). Absent from a record's
    /// settings when 1.
    #[serde(skip_serializing_if = "Substeps::is_one")]
    pub substeps: Substeps,
    /// The building of field data (`[structure]`: storeys, hysteretic storeys, masses,
    /// measurement kind); data with `dataset.json` carry their own (`field::resolve`).
    #[serde(skip_serializing_if = "StructureSettings::is_empty")]
    pub structure: StructureSettings,
    /// θ_val averages the posterior mean over the last `window` steps (SPEC eq. 26: 80).
    pub window: usize,
    /// Keep one trace step in `trace_every` (0: no trace).
    pub trace_every: usize,
    /// Run the validation integration with θ_val (needs the truth).
    pub validate: bool,
    /// Keep the validation and true hysteresis loops in the record, one point in `loop_every`
    /// (0: no loops).
    pub loop_every: usize,
    /// Independent filters pooled into one answer, splitting `particles` between them (1: one
    /// filter, the paper's). The posterior is the equal-weight mixture of the filters' final
    /// particle posteriors and θ_val the mean of their θ_vals, whose Monte-Carlo s.e. — the
    /// s.d. of the filters' θ_vals over √pool — every record then carries beside its intervals
    /// (`docs/calibration.md`). Absent from a record's settings when 1.
    #[serde(skip_serializing_if = "is_one")]
    pub pool: usize,
    /// Rejuvenation of the sampled static parameters (the Bouc–Wen exponents n of the MLN-RBPF,
    /// Storvik and the MPF-EKF2): after every resampling the Liu–West kernel with this discount
    /// δ, in [1/3, 1] (typical 0.95–0.99), moves them ([`core_filters::smc::rejuvenation`]).
    /// Absent: no move (the SPEC's filters), and absent from a record's settings; the bootstrap
    /// PF is never moved. Each filter of a pool moves its own particles.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rejuvenation: Option<f64>,
    /// Process noise of each hysteretic variable r: its s.d. per step is this fraction of dt ×
    /// the RMS drift velocity of its element (SPEC §3: 0.05, the paper's σ_r). The simulated
    /// truth has no such noise; a tenth of it removes most of the MPF-EKF2's k1 bias at 10
    /// storeys, but made its 20-storey stiffnesses less accurate, so the SPEC's value stays the
    /// default ([`models::filtering::ChainSpec::set_r_noise_fraction`], docs/calibration.md,
    /// "The process noise of r"). Absent from a record's settings when the SPEC's.
    #[serde(skip_serializing_if = "is_spec_r_noise")]
    pub r_noise_fraction: f64,
    /// Hold the marginalised stiffnesses, dampings and α to their physical support (≥ 0) after
    /// every step by moment-matched truncation of each particle's Gaussian
    /// ([`models::filtering::ChainSpec::physical_support`]): an answer is then physical by
    /// construction, never a negative dashpot or an indefinite damping matrix. Absent: off (the
    /// SPEC's unconstrained Gaussians), and absent from a record's settings.
    #[serde(skip_serializing_if = "is_false")]
    pub physical_support: bool,
    /// The velocities' process noise relative to SPEC §3's: its s.d. per step is this factor ×
    /// dt × `noise_fraction` × RMS ü_g (1: the SPEC's). Below 1 the filter must explain the
    /// record through the model's dynamics rather than through noise driving its states — what
    /// a free run (a prediction) rewards; on field data the plan chooses it by held-out
    /// prediction ([`crate::choice`]). Absent from a record's settings when 1.
    #[serde(skip_serializing_if = "is_one_f64")]
    pub process_noise_factor: f64,
    /// Part of each channel's measurement noise as an AR(1) sequence carried by the MPF-EKF2's
    /// Gaussian part (`[coloured_noise]` with `rho` per sample interval and `share` of the
    /// channel's variance; [`models::filtering::ColouredNoise`]): time-correlated prediction
    /// errors that a model error makes go into it instead of into θ. Absent: white noise only
    /// (the SPEC's), and absent from a record's settings.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coloured_noise: Option<models::filtering::ColouredNoise>,
}

/// Transitions per sample interval: a number, or chosen by the rule of
/// [`models::filtering::substeps`] (`"auto"`; on field data with Bouc–Wen elements also by the
/// data-scaled ω₁·dt, `scaled_prior::hysteretic_substeps`; for the MPF-EKF2 with one shared prior
/// Gaussian below 10 storeys also by the velocity lag, `pipeline::LAG_SUBSTEPS`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Substeps {
    Fixed(usize),
    Auto,
}

impl Substeps {
    fn is_one(&self) -> bool {
        *self == Substeps::Fixed(1)
    }
}

impl Default for Substeps {
    fn default() -> Self {
        Substeps::Fixed(1)
    }
}

impl std::fmt::Display for Substeps {
    /// As in a TOML file: `3` or `"auto"`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Substeps::Fixed(n) => write!(f, "{n}"),
            Substeps::Auto => write!(f, "\"auto\""),
        }
    }
}

impl std::str::FromStr for Substeps {
    type Err = String;
    /// `auto` or a whole number (the command line's form).
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Substeps::Auto);
        }
        s.parse()
            .map(Substeps::Fixed)
            .map_err(|_| format!("`{s}`: give a whole number of sub-steps or `auto`"))
    }
}

impl Serialize for Substeps {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Substeps::Fixed(n) => s.serialize_u64(*n as u64),
            Substeps::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for Substeps {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Count(u64),
            Word(String),
        }
        match Repr::deserialize(d)? {
            Repr::Count(n) => Ok(Substeps::Fixed(
                usize::try_from(n).map_err(serde::de::Error::custom)?,
            )),
            Repr::Word(w) if w == "auto" => Ok(Substeps::Auto),
            Repr::Word(w) => Err(serde::de::Error::custom(format!(
                "substeps `{w}`: give a whole number or \"auto\""
            ))),
        }
    }
}

fn is_one(v: &usize) -> bool {
    *v == 1
}

fn is_one_f64(v: &f64) -> bool {
    *v == 1.0
}

fn is_false(v: &bool) -> bool {
    !*v
}

fn is_spec_r_noise(v: &f64) -> bool {
    *v == models::filtering::SPEC_R_NOISE_FRACTION
}

impl Default for FilterSettings {
    fn default() -> Self {
        Self {
            particles: 500,
            resampling: Scheme::Systematic,
            ess_threshold: None,
            storvik_update: StorvikUpdate::Linearised,
            fix: BTreeMap::new(),
            prior: None,
            marginal_prior: MarginalPrior::MomentMatched,
            noise_fraction: 0.1,
            discretisation: Discretisation::Euler,
            substeps: Substeps::Fixed(1),
            structure: StructureSettings::default(),
            window: 80,
            trace_every: 10,
            validate: true,
            loop_every: 4,
            pool: 1,
            rejuvenation: None,
            r_noise_fraction: models::filtering::SPEC_R_NOISE_FRACTION,
            physical_support: false,
            process_noise_factor: 1.0,
            coloured_noise: None,
        }
    }
}

impl FilterSettings {
    /// The settings `sysid filter` uses without a configuration file: the SPEC's, except where
    /// the coverage measurements of `docs/calibration.md` showed them over-confident — resample
    /// only when the ESS falls below half the particles (path degeneracy), pool independent
    /// filters of `PARTICLES_PER_POOLED_FILTER` particles so that the posterior includes their
    /// spread and θ_val comes with its Monte-Carlo s.e. (1000 particles as 8 filters: the 95 %
    /// intervals of k and c of every marginalised filter then hold the truth in 0.92–0.94 of
    /// fresh data sets of the paper's structure, against 0.81–0.84 with 4 filters of 125, at
    /// twice the cost), and semi-implicit Euler inside the filters (forward Euler biases the
    /// dampings, SPEC §9), and as many transitions per sample as the prior's building needs for
    /// its highest mode ([`Substeps::Auto`]; one on the paper's data; for the MPF-EKF2 with one
    /// shared prior Gaussian below 10 storeys also four against a velocity lag above 3 %,
    /// [`crate::pipeline::LAG_SUBSTEPS`]), and the stiffnesses and dampings held to their
    /// physical support (`physical_support`). The paper's studies keep
    /// [`FilterSettings::default`].
    pub fn recommended() -> Self {
        Self {
            particles: RECOMMENDED_PARTICLES,
            ess_threshold: Some(0.5),
            pool: recommended_pool(RECOMMENDED_PARTICLES),
            discretisation: Discretisation::Symplectic,
            substeps: Substeps::Auto,
            physical_support: true,
            ..Self::default()
        }
    }

    /// The recommended settings with `particles` particles when a run asks for a count of its
    /// own (`--particles` without a config): pooled as `recommended_pool` says, so that each
    /// filter keeps `PARTICLES_PER_POOLED_FILTER` particles.
    pub fn recommended_with(particles: Option<usize>) -> Self {
        let mut s = Self::recommended();
        if let Some(p) = particles {
            s.particles = p;
            s.pool = recommended_pool(p);
        }
        s
    }
}

impl FilterSettings {
    /// The Liu–West kernel of `rejuvenation`, `None` without one; a discount outside [1/3, 1]
    /// is an error naming the field.
    pub(crate) fn liu_west(&self) -> crate::error::Result<Option<LiuWest>> {
        self.rejuvenation
            .map(LiuWest::new)
            .transpose()
            .map_err(|e| crate::error::invalid!("field `rejuvenation`: {e}"))
    }
}

/// Particles of the recommended settings ([`FilterSettings::recommended`]).
pub const RECOMMENDED_PARTICLES: usize = 1000;

/// Particles of each pooled filter of the recommended settings: fewer add Monte-Carlo error
/// that pooling then reports rather than removes (8 filters of 62 were less accurate than 4 of
/// 125 at the same cost, `docs/calibration.md`).
pub(crate) const PARTICLES_PER_POOLED_FILTER: usize = 125;

/// The most filters the recommended settings pool.
pub(crate) const MAX_RECOMMENDED_POOL: usize = 8;

/// Filters the recommended settings pool for `particles` particles: one per
/// [`PARTICLES_PER_POOLED_FILTER`], between 1 and [`MAX_RECOMMENDED_POOL`] (500 → 4, 1000 → 8,
/// fewer than 250 → 1).
pub(crate) fn recommended_pool(particles: usize) -> usize {
    (particles / PARTICLES_PER_POOLED_FILTER).clamp(1, MAX_RECOMMENDED_POOL)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recommended pool keeps 125 particles per filter, from 1 to 8 filters; a count asked
    /// for without a config is pooled the same way (500 particles: the 4 filters of 125 that
    /// were the default before 1000 particles).
    #[test]
    fn recommended_pools_hold_125_particles_each() {
        let r = FilterSettings::recommended();
        assert_eq!((r.particles, r.pool), (1000, 8));
        for (p, pool) in [(1, 1), (249, 1), (250, 2), (500, 4), (1000, 8), (5000, 8)] {
            let s = FilterSettings::recommended_with(Some(p));
            assert_eq!((s.particles, s.pool), (p, pool), "{p} particles");
        }
        assert_eq!(FilterSettings::recommended_with(None), r);
    }
}
