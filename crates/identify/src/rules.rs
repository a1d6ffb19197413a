//! The default rules of a run: each a named constant or function with the measurement that
//! justified it cited in its doc. [`crate::plan::settle`] applies them, in one place, and
//! records every choice they make in the run's plan ([`crate::plan::Decision`]).
//!
//! The rules that depend on the building or the data:
//! - the MPF-EKF2's prior Gaussian per particle ([`per_particle_reason`], [`SPARSE_REL_SD`],
//!   [`PER_PARTICLE_MIN_STOREYS`]);
//! - its rejuvenation of the exponents n with the shared Gaussian ([`MPF_REJUVENATION`]);
//! - its particle count on coarsely sampled hysteretic field data ([`HYSTERETIC_PARTICLES`]);
//! - the sub-steps against the velocity lag ([`LAG_SUBSTEPS`]); the sub-steps of the prior's
//!   linear modes ([`models::filtering::substeps`]) and of the data-scaled ω₁·dt
//!   (`crate::scaled_prior::hysteretic_substeps`) are stated where they are computed.
//!
//! The settings a run starts from (the recommended ones without a config, the config's with
//! one, [`crate::settings::FilterSettings::recommended`]) and the data-scaled prior of field
//! data ([`crate::scaled_prior`]) complete the list.

use models::filtering::ChainSpec;
use serde::{Deserialize, Serialize};

use crate::algorithm::Algorithm;
use crate::settings::FilterSettings;

impl FilterSettings {
    /// [`FilterSettings::recommended`] for `algorithm` on a building of `storeys` storeys whose
    /// 1-based storeys `unmeasured` carry no sensor ([`unmeasured_storeys`]): the MPF-EKF2 starts
    /// every particle from its own prior mean ([`models::filtering::MarginalPrior::PerParticle`]
    /// with s.d. [`SPARSE_REL_SD`] × that mean) instead of one moment-matched Gaussian when a
    /// storey carries no sensor or the building has at least [`PER_PARTICLE_MIN_STOREYS`]
    /// storeys ([`per_particle_reason`]). Otherwise: the recommended settings.
    ///
    /// With the shared Gaussian the MPF-EKF2 also rejuvenates its sampled exponents n with the
    /// Liu–West discount [`MPF_REJUVENATION`] (measured to help there; with per-particle prior
    /// means on 10 storeys it did not, see the constant).
    pub fn recommended_for(algorithm: Algorithm, storeys: usize, unmeasured: &[usize]) -> Self {
        let mut s = Self::recommended();
        if algorithm == Algorithm::MpfEkf2 {
            if per_particle_reason(storeys, unmeasured).is_some() {
                s.marginal_prior = models::filtering::MarginalPrior::PerParticle {
                    rel_sd: SPARSE_REL_SD,
                };
            } else {
                s.rejuvenation = Some(MPF_REJUVENATION);
            }
        }
        s
    }
}

/// The Liu–West discount δ of the MPF-EKF2's default rejuvenation of its sampled exponents n.
/// Measured with the other recommended settings (`docs/calibration.md`, "Rejuvenation of the
/// sampled exponents"): on 24 fresh paper data sets its mean |c error| went from 6.27 % to
/// 5.37 % (paired difference −0.90 ± 0.43 points), |k error| from 1.68 % to 1.46 %, 95 %
/// coverage of k and c from 0.903 to 0.910; on four data sets with a reference posterior k1's
/// error went from 2.61 % to 1.84 %. The MLN-RBPF and Storvik keep no move: on the same 24 data
/// sets Storvik's |k error| rose from 2.59 % to 3.05 % (+0.47 ± 0.23) and its coverage fell from
/// 0.951 to 0.910, and the MLN-RBPF's |c error| rose from 13.10 % to 13.92 %. With per-particle
/// prior means (10 storeys, six data sets) the move made the MPF-EKF2 no better (mean |k error|
/// 3.7 → 4.7 %, |c error| 31.5 → 48.2 %, paired +1.0 ± 0.9 and +16.7 ± 11.0 points), so where
/// its prior is per particle ([`per_particle_reason`]) it does not rejuvenate by default.
pub const MPF_REJUVENATION: f64 = 0.98;

/// The MPF-EKF2's particle count without a config or `--particles` on field data of a building
/// with Bouc–Wen elements and one shared prior Gaussian whose data-scaled ω₁·dt asks for
/// sub-steps (`crate::scaled_prior::hysteretic_substeps`, `substeps = "auto"`), pooled as
/// 8 filters of 500 (chosen in [`crate::identification::settle`]).
///
/// Measured (`docs/structures.md`, "Stiff buildings"): the paper's chain time-scaled ×4
/// (k = 128) sampled at 200 Hz, absolute accelerations, data-scaled priors, 8 sub-steps. With
/// 1000 particles k1 comes out low (the filter's bias, smaller with more particles): on 12 data
/// sets (noise seeds 201–212) the worst k error was 6.1 %, and on 24 never used before
/// (301–324) 7.7 % with 2 of 24 data sets beyond 5 %. With 4000: at most 4.0 % and 4.1 %,
/// mean |k error| 1.26 → 0.81 % on the fresh 24 (paired −0.44 ± 0.11 points), k1 −2.15 →
/// −1.40 % on average, at 4.0 times the wall time (6.1 → 24.5 s a run). Elsewhere (the paper's
/// structure, simulated data with their own priors) four times the particles take a third off
/// the stiffness error but decide no goal, and the default stays
/// [`crate::settings::RECOMMENDED_PARTICLES`].
pub const HYSTERETIC_PARTICLES: usize = 4000;

/// From this many storeys on, the MPF-EKF2's default prior is per particle even with every
/// storey measured. Measured with `sysid filter`'s settings otherwise (`docs/calibration.md`,
/// "Coverage on fresh data sets"; 12 data sets each): at 10 storeys the mean stiffness error is
/// 4.1 % per particle against 16.0 % with one moment-matched Gaussian (95 % coverage of k 0.87
/// against 0.82, of c 0.67 against 0.57); at 5 storeys 5.0 % against 3.1 %, and on the paper's
/// 3 storeys the shared Gaussian is also the better one (c error 7.2 % against 11.5 %), so below
/// 10 storeys the default stays SPEC §3's.
pub const PER_PARTICLE_MIN_STOREYS: usize = 10;

/// Why the MPF-EKF2's default prior Gaussian is per particle on this building, or `None`: the
/// one-shared-Gaussian EKF over the 4N + 1 marginalised values loses its particles where
/// storeys carry no sensor (`docs/scaling.md`, "Sparse sensors at 20 and 40 storeys": it drives
/// the unmeasured stiffnesses to zero or below within the first seconds) and is far less
/// accurate on tall buildings ([`PER_PARTICLE_MIN_STOREYS`]).
pub fn per_particle_reason(storeys: usize, unmeasured: &[usize]) -> Option<String> {
    if !unmeasured.is_empty() {
        let v: Vec<String> = unmeasured.iter().map(|s| s.to_string()).collect();
        Some(format!("storeys {} carry no sensor", v.join(", ")))
    } else if storeys >= PER_PARTICLE_MIN_STOREYS {
        Some(format!(
            "{storeys} storeys (at least {PER_PARTICLE_MIN_STOREYS})"
        ))
    } else {
        None
    }
}

/// Relative s.d. of each particle's prior Gaussian that [`FilterSettings::recommended_for`]
/// gives the MPF-EKF2 when a storey carries no sensor (the value measured in `docs/scaling.md`).
pub const SPARSE_REL_SD: f64 = 0.1;

/// The 1-based storeys of `spec`'s building that carry no sensor, in increasing order.
pub fn unmeasured_storeys(spec: &ChainSpec) -> Vec<usize> {
    let measured = spec.sensors.storeys();
    (0..spec.n_storeys())
        .filter(|j| !measured.contains(j))
        .map(|j| j + 1)
        .collect()
}

/// Sub-steps the MPF-EKF2 takes against the semi-implicit step's velocity lag
/// ([`models::filtering::substeps::damping_lag_error`]) when its prior Gaussian is one shared,
/// moment-matched one, the building has Bouc–Wen elements and fewer than
/// [`PER_PARTICLE_MIN_STOREYS`] storeys, and the lag left by the other rules exceeds
/// [`models::filtering::substeps::LAG_NOTED_ABOVE`].
///
/// Measured (`docs/calibration.md`, "Five and forty storeys with today's defaults" and "The
/// prior or the size?"; 8 × 125, paired by data set): on the 5-storey building (lag 9.3 %) the
/// mean stiffness error went from 3.49 to 2.00 % on 24 data sets (−1.50 ± 0.29 points) and from
/// 2.77 to 1.61 % on 12 fresh ones (−1.16 ± 0.20), coverage of k and c 0.85 → 0.93 and
/// 0.88 → 0.93; on the 3-storey one (lag 5.2 %) 2.30 → 2.08 % (−0.22 ± 0.38, not resolved),
/// coverage 0.86 → 0.93; about three times the cost. With per-particle prior means the same
/// sub-steps did not pay (5 storeys −0.34 ± 0.37, the difference of the two gains 1.16 ± 0.44;
/// 10 storeys −0.16 ± 0.37; 20 storeys +1.14 ± 0.23), hence the condition on the prior.
pub const LAG_SUBSTEPS: usize = 4;

/// Largest frequency shift of the highest mode left by the sub-steps on field data (a prior
/// scaled from the data) when the run is one Gaussian filter (a linear building under the
/// MPF-EKF2), where a sub-step costs little.
///
/// Why tighter than [`models::filtering::substeps::MAX_FREQUENCY_ERROR`]: a field
/// identification is judged by its free run, which simulates the identified continuous-time
/// building; the filter's stiffness absorbs the frequency shift of its own step, and a lightly
/// damped mode rings over about 1/(2πζ) cycles, so a shift ε puts ≈ ε/ζ radians of phase into
/// the prediction. Measured on the stiff one-storey shake-table frame (22.0 Hz, ζ ≈ 0.5 %,
/// 120 Hz; docs/real-frame.md, "A stiff one-storey frame"): 4 sub-steps (0.35 %) gave a free-run
/// fit of 46.1 % on its El Centro record, 16 (0.02 %) 62.6 % (SRIM 61.4 %); judged on the
/// shared three-storey frame, which it barely moves (67.7 / 73.7 / 75.4 → 68.5 / 74.0 / 75.0 at
/// 10 sub-steps).
pub const FIELD_FREQUENCY_ERROR: f64 = 0.0005;

/// Largest move of a stiffness, in its posterior s.d., when the sub-steps of a run that is one
/// Gaussian filter on field data double ([`crate::choice::substeps`]): below it the count is
/// taken. A first-order bias about that size keeps a 95 % interval's coverage at 94.6 %. Chosen
/// from that coverage, not fitted; measured on the foreign corpus's `in-class` record, where the
/// rules' 3 sub-steps left k3's interval 3 half-widths from the truth and 64 hold it
/// (docs/validation.md, "Sub-steps checked by doubling").
pub const SUBSTEP_CHECK_TOLERANCE: f64 = 0.25;

/// What the field rule ([`FIELD_FREQUENCY_ERROR`]) chose (printed and recorded under
/// `config.substeps_field`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FieldSubsteps {
    /// The highest mode's frequency shift with one step and with `substeps`.
    pub error_one: f64,
    pub error_chosen: f64,
    pub substeps: usize,
}

impl FieldSubsteps {
    /// The fewest sub-steps that bring the shift of the mode at `omega_max_dt` (ω·dt) to
    /// [`FIELD_FREQUENCY_ERROR`], at most `MAX_SUBSTEPS`; `None` where one step already does.
    pub fn new(omega_max_dt: f64) -> Option<Self> {
        use models::filtering::substeps::frequency_error;
        let error_one = frequency_error(omega_max_dt);
        if error_one <= FIELD_FREQUENCY_ERROR {
            return None;
        }
        let max = models::filtering::MAX_SUBSTEPS;
        let substeps = (1..=max)
            .find(|&m| frequency_error(omega_max_dt / m as f64) <= FIELD_FREQUENCY_ERROR)
            .unwrap_or(max);
        Some(FieldSubsteps {
            error_one,
            error_chosen: frequency_error(omega_max_dt / substeps as f64),
            substeps,
        })
    }
}

/// What the velocity-lag rule ([`LAG_SUBSTEPS`]) chose (printed and recorded under
/// `config.substeps_lag`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LagSubsteps {
    /// Stiffness error of the velocity lag with one step per sample.
    pub lag_one: f64,
    /// Above this lag (of the step the other rules chose) the rule sub-steps.
    pub above: f64,
    pub substeps: usize,
}

/// Whether the MPF-EKF2 of `spec` samples nothing: a building without hysteretic element (no
/// sampled velocity, r or exponent) whose marginalised block starts from one shared prior
/// Gaussian. Every particle then carries the same Gaussian, the weights stay equal, and the
/// filter is one EKF2 computed once per particle: a run asked for by a person is that one
/// filter (1 particle, no pool). Measured on the shake-table frame of `data/real/` (3 storeys,
/// storey+mass damping, 1000 particles as 8 filters): 122 s against 0.94 s with one particle,
/// θ_val equal to 12 significant digits (k1 2874.372842648326 against 2874.372842648327); the
/// pooled filters differ only in their random streams, which a filter that samples nothing
/// never draws from (docs/performance.md, "Nothing sampled, nothing repeated").
pub fn samples_nothing(algorithm: Algorithm, spec: &ChainSpec) -> bool {
    algorithm == Algorithm::MpfEkf2
        && spec.building.hysteretic().is_empty()
        && spec.marginal_prior == models::filtering::MarginalPrior::MomentMatched
}

/// `sysid filter --particles`'s help, from the rules that choose the count (so that the help
/// cannot disagree with them).
pub fn help_particles() -> String {
    use crate::settings::{recommended_pool, PARTICLES_PER_POOLED_FILTER, RECOMMENDED_PARTICLES};
    format!(
        "Number of particles. With --config: the config's value. Without: \
         {RECOMMENDED_PARTICLES} as {} pooled filters; for the MPF-EKF2 on field data of a \
         hysteretic building sampled coarsely for its first mode, {HYSTERETIC_PARTICLES} as {} × \
         {} (docs/structures.md, \"Stiff buildings\"); a P given here is pooled as one filter \
         per {PARTICLES_PER_POOLED_FILTER} particles, 1 to {}. Whatever the count, the MPF-EKF2 \
         on a building without hysteretic element and one shared prior Gaussian samples \
         nothing and runs as one Gaussian filter (1 particle). `--plan-only` shows the count a \
         run takes and why",
        recommended_pool(RECOMMENDED_PARTICLES),
        recommended_pool(HYSTERETIC_PARTICLES),
        HYSTERETIC_PARTICLES / recommended_pool(HYSTERETIC_PARTICLES),
        crate::settings::MAX_RECOMMENDED_POOL,
    )
}

/// `sysid filter --threads`'s help, from the batch layer's limit for particle blocks (so that
/// the help cannot disagree with it).
pub fn help_threads() -> String {
    format!(
        "Worker threads for the pooled filters of the run, which run side by side, and for the \
         particle blocks of each filter of a tall building (marginalised dimension {} or more) \
         (default: every core, or RAYON_NUM_THREADS where it is set); the record is the same \
         for any count",
        core_filters::smc::batch::PARALLEL_MIN_DIM
    )
}

/// `sysid filter --rejuvenation`'s help, from [`MPF_REJUVENATION`] and the rule that applies
/// it.
pub fn help_rejuvenation() -> String {
    format!(
        "Move the sampled Bouc–Wen exponents n (MLN-RBPF, Storvik, MPF-EKF2) after every \
         resampling with the Liu–West kernel of this discount δ, in [1/3, 1] (typical \
         0.95–0.99; 1: no move; docs/calibration.md). Default without --config: δ = \
         {MPF_REJUVENATION} for the MPF-EKF2 with one shared prior Gaussian on a hysteretic \
         building, no move otherwise (other filters, per-particle prior means from \
         {PER_PARTICLE_MIN_STOREYS} storeys or with unmeasured storeys); with --config: the \
         config's `rejuvenation`, absent = no move"
    )
}

/// `sysid filter --substeps`'s help, from the three sub-step rules' constants.
pub fn help_substeps() -> String {
    use crate::scaled_prior::{
        HYSTERETIC_MAX_OMEGA1_H, HYSTERETIC_MAX_SUBSTEPS, HYSTERETIC_SUBSTEP_ABOVE,
    };
    use models::filtering::substeps::{LAG_NOTED_ABOVE, MAX_FREQUENCY_ERROR, SUBSTEP_ABOVE};
    format!(
        "Transitions inside the filter per sample interval (MPF-EKF2 and bootstrap PF), for data \
         sampled coarsely relative to the structure's highest modes: a number, or `auto` (the \
         default without --config; with one, the config's `substeps`, absent = 1). `auto` takes the \
         largest of four rules: where one step per sample would shift the highest mode of the \
         prior's building by more than {:.1} %, enough sub-steps to bring that shift under {:.1} \
         % (docs/real-frame.md); on field data of a linear building under the MPF-EKF2 (one \
         Gaussian filter), enough to bring it under {:.2} % (docs/real-frame.md); on field data with Bouc–Wen elements whose data-scaled ω₁·dt \
         exceeds {HYSTERETIC_SUBSTEP_ABOVE}, enough to bring it to {HYSTERETIC_MAX_OMEGA1_H}, \
         at most {HYSTERETIC_MAX_SUBSTEPS} (docs/structures.md); and for the MPF-EKF2 with one \
         shared prior Gaussian on a Bouc–Wen building below {PER_PARTICLE_MIN_STOREYS} storeys \
         whose velocity lag exceeds {:.0} %, {LAG_SUBSTEPS} (docs/calibration.md, \"The prior \
         or the size?\"). Then, on field data of a linear building under the MPF-EKF2 (one \
         Gaussian filter), the count is doubled (at most {}) until a doubling moves every \
         stiffness by at most {SUBSTEP_CHECK_TOLERANCE} of its posterior s.d. \
         (docs/validation.md, \"Sub-steps checked by doubling\"); a number given here is kept",
        100.0 * SUBSTEP_ABOVE,
        100.0 * MAX_FREQUENCY_ERROR,
        100.0 * FIELD_FREQUENCY_ERROR,
        100.0 * LAG_NOTED_ABOVE,
        models::filtering::MAX_SUBSTEPS,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_field_rule_takes_the_fewest_sub_steps_under_its_shift() {
        use models::filtering::substeps::frequency_error;
        // The stiff one-storey frame: 22 Hz at 120 Hz, ω·dt = 1.15.
        let f = FieldSubsteps::new(1.15).unwrap();
        assert_eq!(f.substeps, 11);
        assert!(f.error_chosen <= FIELD_FREQUENCY_ERROR);
        assert!(frequency_error(1.15 / 10.0) > FIELD_FREQUENCY_ERROR);
        // A mode sampled finely enough needs none.
        assert!(FieldSubsteps::new(0.05).is_none());
    }
}
