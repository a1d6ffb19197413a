//! One identification run, end to end: data set + algorithm + settings + seed → [`RunRecord`].
//!
//! Configuration errors (an unknown parameter to fix, a storey count that is not compiled in, an
//! invalid prior) are returned as errors before anything runs. Numerical failures *inside* the
//! run are not errors here: they end the run early and are written into the record, so a sweep
//! of 50 runs never aborts because of one.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::error::{bail, invalid, Context, Result};
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::{purpose, stream};
use core_filters::smc::bootstrap::BootstrapPf;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::mpf::MpfEkf2;
use core_filters::smc::storvik::Storvik;
use core_filters::smc::{run, Filter, SmcConfig};
use models::dataset::LoadedDataset;
use models::filtering::{AugmentedChain, ChainPrior, ChainSpec, MlnChain, MpfChain, RmsLevels};
use models::integrate::{simulate_adaptive, Tolerance};
use models::sensors::MeasurementKind;
use models::structure::{Damping, ShearChain};
use serde::{Deserialize, Serialize};

use crate::field::resolve_for_run;
use crate::metrics::{relative_errors, ErrorSums, StateErrors};
use crate::observe::{Recorder, TruthStates};
use crate::pool::Driven;
use crate::record::{Fingerprint, Loop, RunRecord, Timing, Validation, Versions};
pub use crate::settings::FilterSettings;
use crate::settings::Substeps;

/// The identification algorithms (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Algorithm {
    Bootstrap,
    MlnRbpf,
    Storvik,
    MpfEkf2,
}

impl Algorithm {
    pub const ALL: [Algorithm; 4] = [
        Algorithm::Bootstrap,
        Algorithm::MlnRbpf,
        Algorithm::Storvik,
        Algorithm::MpfEkf2,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Algorithm::Bootstrap => "bootstrap",
            Algorithm::MlnRbpf => "mln-rbpf",
            Algorithm::Storvik => "storvik",
            Algorithm::MpfEkf2 => "mpf-ekf2",
        }
    }

    /// Name used in figures and reports.
    pub fn label(self) -> &'static str {
        match self {
            Algorithm::Bootstrap => "Bootstrap PF",
            Algorithm::MlnRbpf => "MLN-RBPF",
            Algorithm::Storvik => "Storvik",
            Algorithm::MpfEkf2 => "MPF-EKF2",
        }
    }
}

impl std::str::FromStr for Algorithm {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Algorithm::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown algorithm `{s}` (expected bootstrap, mln-rbpf, storvik or mpf-ekf2)"
                )
            })
    }
}

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
/// sub-steps ([`crate::scaled_prior::hysteretic_substeps`], `substeps = "auto"`), pooled as
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

/// What a run is given: the data, and when known the true structure (for the validation run).
pub struct RunInput<'a> {
    pub data: &'a LoadedDataset,
    /// The true structure, with θ_true (for validation); `None` for field data.
    pub chain: Option<&'a ShearChain>,
    pub experiment: &'a str,
    pub seed: u64,
    pub run: u64,
    /// Show a progress bar on stderr (when it is a terminal).
    pub progress: bool,
    /// Record the one-step prediction errors at every step ([`crate::residuals`]; `sysid
    /// filter` does, sweeps do not: their records stay small).
    pub residuals: bool,
}

/// Root mean square of a signal.
fn rms_of(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (s / n.max(1) as f64).sqrt()
}

/// RMS values that set Q and R (SPEC §3): from the data set's metadata and truth (clean signals)
/// when present, otherwise estimated from the measured signals. `storeys` is N, `sensors` the
/// 0-based storey of each channel, `hysteretic` the 0-based storeys of the hysteretic elements
/// (one drift-velocity RMS each).
fn rms_levels(
    data: &LoadedDataset,
    storeys: usize,
    sensors: &[usize],
    kind: MeasurementKind,
    hysteretic: &[usize],
    nf: f64,
) -> RmsLevels {
    let k = data.len();
    let n = storeys;
    if let Some(meta) = &data.meta {
        // The drift velocity of element j is v_j − v_{j−1}: from the true states when present.
        let drift = hysteretic
            .iter()
            .map(|&j| match &data.truth {
                Some(t) => rms_of((0..t.states.len()).map(|i| {
                    let st = t.states.state(i);
                    st[n + j] - if j == 0 { 0.0 } else { st[n + j - 1] }
                })),
                None => meta.rms.vel[j],
            })
            .collect();
        return RmsLevels {
            acc: meta.rms.acc.clone(),
            ug: meta.rms.ug,
            drift_velocity: drift,
        };
    }
    // Field data: a measured channel holds the clean signal plus noise of s.d. nf·RMS(clean),
    // so RMS(measured) = RMS(clean)·√(1 + nf²).
    let clean = (1.0 + nf * nf).sqrt();
    let m = sensors.len();
    let acc: Vec<f64> = (0..m)
        .map(|c| rms_of((0..k).map(|i| data.y(i)[c])) / clean)
        .collect();
    let ug = rms_of(data.ug_meas.iter().copied()) / clean;
    // Relative velocity of channel c: the trapezoidal integral of its relative acceleration
    // (absolute minus ü_g for absolute data) with its linear trend removed (the drift of
    // integrated noise).
    let relative = |i: usize, c: usize| -> f64 {
        let y = data.y(i)[c];
        match kind {
            MeasurementKind::Relative => y,
            MeasurementKind::Absolute => y - data.ug_meas[i],
        }
    };
    let velocity = |c: usize| -> Vec<f64> {
        let mut v = vec![0.0; k];
        for i in 1..k {
            v[i] = v[i - 1] + 0.5 * data.dt * (relative(i - 1, c) + relative(i, c));
        }
        let slope = v[k - 1] / (k.max(2) - 1) as f64;
        v.iter()
            .enumerate()
            .map(|(i, x)| x - slope * i as f64)
            .collect()
    };
    let channel = |storey: usize| sensors.iter().position(|&s| s == storey);
    let drift = hysteretic
        .iter()
        .map(|&j| {
            match (channel(j), j.checked_sub(1).map(channel)) {
                // The element's storey and the one below (or the ground) are measured.
                (Some(c), None) => rms_of(velocity(c).into_iter()),
                (Some(c), Some(Some(b))) => {
                    let (vj, vb) = (velocity(c), velocity(b));
                    rms_of(vj.iter().zip(&vb).map(|(a, b)| a - b))
                }
                // Otherwise the mean drift per storey below the nearest measured storey s
                // (above j when there is one): RMS v_s / (s + 1). A scale only, for the
                // hysteretic variable's process noise (q_r = 0.05·dt·RMS δv, SPEC §3).
                _ => {
                    let c = sensors.iter().position(|&s| s >= j).unwrap_or(m - 1);
                    rms_of(velocity(c).into_iter()) / (sensors[c] + 1) as f64
                }
            }
        })
        .collect();
    RmsLevels {
        acc,
        ug,
        drift_velocity: drift,
    }
}

/// Builds the specification of a run's filter partitions: the structure of the data
/// ([`resolve_for_run`]: `dataset.json`, else the true chain, else the settings' `[structure]`
/// for field data — refused when incomplete), the measured storeys of the header, noise levels
/// from RMS values (SPEC §3), the prior and the discretisation.
pub fn chain_spec(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    s: &FilterSettings,
) -> Result<ChainSpec> {
    let structure = resolve_for_run(data, chain, &s.structure)?;
    let n = structure.storeys;
    let building = structure.building()?;
    let hysteretic = building.hysteretic().to_vec();
    let sensors = structure.sensor_layout()?;
    if sensors.len() != data.channels {
        bail!(
            "{} sensors in the structure, {} channels in the data",
            sensors.len(),
            data.channels
        );
    }
    let rms = rms_levels(
        data,
        n,
        sensors.storeys(),
        sensors.kind(),
        &hysteretic,
        s.noise_fraction,
    );
    let mut spec = ChainSpec::from_rms(
        data.dt,
        building.clone().with_damping(Damping::Storey),
        sensors,
        data.ug_meas.clone(),
        &rms,
        s.noise_fraction,
    )?;
    spec.marginal_prior = s.marginal_prior;
    spec.set_r_noise_fraction(s.r_noise_fraction)?;
    spec.discretisation = s.discretisation;
    spec.substeps = match s.substeps {
        Substeps::Fixed(m) => m,
        // Chosen per algorithm once the prior is known (`resolve_substeps`).
        Substeps::Auto => 1,
    };
    // The building's damping form, whose α gets its prior below.
    spec.building = building;
    // Default priors: SPEC §3's for simulated data (the paper's scale); for field data scaled
    // from the measured response (`scaled_prior`).
    let mut prior = match (&s.prior, is_field_data(data, chain)) {
        (Some(p), _) => p.clone(),
        (None, true) => crate::scaled_prior::scaled_prior(data, &structure)?.prior,
        // Simulated data: the preset's (SPEC §3's, carried to the structure's values for a
        // preset whose storeys are not the paper's).
        (None, false) => match (data.meta.as_ref(), chain) {
            (Some(meta), Some(chain)) if chain.storeys() == n => {
                models::preset::Preset::default_prior(&meta.config.preset, chain, &hysteretic)
            }
            _ => ChainPrior::paper(n, &hysteretic),
        },
    };
    // The storey+mass form's α: a default prior centred from the structure's first mode
    // (`models::filtering::prior::alpha_prior`) unless the prior states one. A given `[prior]`
    // without `alpha` is refused by the spec's validation, naming `prior.alpha`.
    if structure.damping.has_mass_term() && prior.alpha.is_none() && s.prior.is_none() {
        prior.alpha = Some(match (is_field_data(data, chain), chain) {
            (false, Some(chain)) => {
                let w1 = models::modal::modes(chain)
                    .ok()
                    .and_then(|m| m.modes.first().map(|m| m.frequency_hz))
                    .context(
                        "the true structure has no under-damped mode to centre α's prior on",
                    )?
                    * std::f64::consts::TAU;
                models::filtering::prior::alpha_prior(w1)
            }
            _ => crate::scaled_prior::scaled_prior(data, &structure)?
                .prior
                .alpha
                .context("the scaled prior of the storey+mass form has α")?,
        });
    }
    for (name, value) in &s.fix {
        prior
            .fix(name, *value)
            .with_context(|| format!("fixing {name} = {value}"))?;
    }
    spec.prior = prior;
    spec.validate()?;
    Ok(spec)
}

/// Field data: neither `dataset.json` nor a known true structure.
pub fn is_field_data(data: &LoadedDataset, chain: Option<&ShearChain>) -> bool {
    data.meta.is_none() && chain.is_none()
}

/// The data-scaled default prior of a field-data run (printed by `sysid filter` and recorded
/// under `config.prior_from_data`), `None` when the run uses another prior.
pub fn prior_from_data(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    s: &FilterSettings,
) -> Result<Option<crate::scaled_prior::ScaledPrior>> {
    if s.prior.is_some() || !is_field_data(data, chain) {
        return Ok(None);
    }
    let structure = resolve_for_run(data, chain, &s.structure)?;
    Ok(Some(crate::scaled_prior::scaled_prior(data, &structure)?))
}

/// What `substeps = "auto"` chose for a run: by the linear modes of the prior's building
/// ([`models::filtering::substeps`]), on field data with Bouc–Wen elements by the data-scaled
/// ω₁·dt ([`crate::scaled_prior::hysteretic_substeps`]) and, for the MPF-EKF2 with one shared
/// prior Gaussian below [`PER_PARTICLE_MIN_STOREYS`] storeys, by the velocity lag
/// ([`LagSubsteps`]); the run takes the largest.
#[derive(Debug, Clone, Copy, Default)]
pub struct AutoChoice {
    pub linear: Option<models::filtering::substeps::AutoSubsteps>,
    pub hysteretic: Option<crate::scaled_prior::HystereticSubsteps>,
    pub lag: Option<LagSubsteps>,
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

/// What the velocity-lag rule ([`LAG_SUBSTEPS`]) chose (printed and recorded under
/// `config.substeps_lag`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LagSubsteps {
    /// Stiffness error of the velocity lag with one step per sample.
    pub lag_one: f64,
    /// Above this lag (of the step the other rules chose) the rule sub-steps.
    pub above: f64,
    pub substeps: usize,
}

/// Resolves `substeps = "auto"` for the algorithms that sub-step (MPF-EKF2, bootstrap PF);
/// MLN-RBPF and Storvik keep one transition per sample. `scaled` is the run's data-scaled
/// prior ([`prior_from_data`]), if it has one. Returns what was chosen automatically (nothing
/// for a fixed number).
pub fn resolve_substeps(
    algorithm: Algorithm,
    spec: &mut ChainSpec,
    s: &FilterSettings,
    scaled: Option<&crate::scaled_prior::ScaledPrior>,
) -> AutoChoice {
    if s.substeps != Substeps::Auto {
        return AutoChoice::default();
    }
    let sub_steps = !matches!(algorithm, Algorithm::MlnRbpf | Algorithm::Storvik);
    let mut a = models::filtering::substeps::auto_substeps(spec);
    if !sub_steps {
        a.substeps = 1;
        a.error_chosen = a.error_one;
    }
    spec.substeps = a.substeps;
    let hysteretic = match scaled {
        Some(p) if sub_steps && !spec.building.hysteretic().is_empty() => {
            let h = crate::scaled_prior::HystereticSubsteps::new(p.omega1, spec.dt);
            spec.substeps = spec.substeps.max(h.substeps);
            Some(h)
        }
        _ => None,
    };
    let above = models::filtering::substeps::LAG_NOTED_ABOVE;
    let lag = (algorithm == Algorithm::MpfEkf2
        && s.marginal_prior == models::filtering::MarginalPrior::MomentMatched
        && !spec.building.hysteretic().is_empty()
        && spec.building.storeys() < PER_PARTICLE_MIN_STOREYS
        && a.lag_one / spec.substeps as f64 > above)
        .then(|| {
            spec.substeps = spec.substeps.max(LAG_SUBSTEPS);
            LagSubsteps {
                lag_one: a.lag_one,
                above,
                substeps: LAG_SUBSTEPS,
            }
        });
    AutoChoice {
        linear: Some(a),
        hysteretic,
        lag,
    }
}

/// The filter of `algorithm` on the partitions of `spec` (no size table: every dimension is the
/// structure's).
pub fn build_filter(
    algorithm: Algorithm,
    spec: ChainSpec,
    s: &FilterSettings,
) -> Result<Box<dyn Filter>> {
    Ok(match algorithm {
        Algorithm::Bootstrap => Box::new(BootstrapPf::new(AugmentedChain::new(spec)?)),
        Algorithm::MlnRbpf => Box::new(MlnRbpf::new(MlnChain::new(spec)?)),
        Algorithm::Storvik => Box::new(Storvik::new(MlnChain::new(spec)?, s.storvik_update)),
        Algorithm::MpfEkf2 => Box::new(MpfEkf2::new(MpfChain::new(spec)?)),
    })
}

pub use crate::error::Interrupted;

/// Which filter of a pool [`drive`] runs, when the whole run started (its pace is timed over
/// all the pool's filters, [`crate::pace`]) and whether its caller asks it to stop.
#[derive(Clone, Copy)]
struct Member<'a> {
    index: usize,
    started: Instant,
    stop: &'a dyn Fn() -> bool,
}

/// Runs filter `member.index` of a pool (0: the only filter of an unpooled run, on the stream
/// `filter/<algorithm>`; member m > 0 on `filter/<algorithm>/pool<m>`).
fn drive(
    filter: &mut dyn Filter,
    input: &RunInput,
    s: &FilterSettings,
    algorithm: Algorithm,
    pc: &SmcConfig,
    member: Member<'_>,
    predictor: Option<crate::residuals::Predictor>,
) -> Driven {
    let Member {
        index: member,
        started,
        stop,
    } = member;
    let data = input.data;
    let layout = filter.layout().clone();
    // Truth rows in the filter's state order, when the truth is known.
    let truth_rows: Option<Vec<Vec<f64>>> = data.truth.as_ref().and_then(|t| {
        let cols: Option<Vec<usize>> = layout
            .state_names
            .iter()
            .map(|n| t.state_names.iter().position(|m| m == n))
            .collect();
        cols.map(|cols| {
            (0..t.states.len())
                .map(|k| cols.iter().map(|&c| t.states.state(k)[c]).collect())
                .collect()
        })
    });
    let steps = data.len() - 1;
    let ny = data.channels;
    let ys: Vec<f64> = (1..=steps)
        .flat_map(|k| data.y(k).iter().copied())
        .collect();
    let mut recorder = Recorder::new(
        steps,
        s.window,
        s.trace_every,
        data.dt,
        layout.params.len(),
        layout.states.len(),
        truth_rows.as_ref().map(|rows| TruthStates { rows }),
    );
    if input.progress && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        let bar = indicatif::ProgressBar::new(steps as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{prefix:>10} [{bar:30}] {pos}/{len} steps, ETA {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        bar.set_prefix(algorithm.name());
        recorder.progress = Some(bar);
    } else if input.progress {
        let pooled = s.pool.max(1);
        recorder.pace = Some(crate::pace::Pace::new(
            algorithm.name(),
            steps * pooled,
            steps as f64 * data.dt,
            started,
            member * steps,
        ));
    }
    recorder.keep_final = s.pool > 1;
    recorder.predictor = predictor;
    recorder.stop = Some(stop);
    let name = match member {
        0 => format!("{}/{}", purpose::FILTER, algorithm.name()),
        m => format!("{}/{}/pool{m}", purpose::FILTER, algorithm.name()),
    };
    let mut rng = stream(input.seed, input.run, &name);
    let start = Instant::now();
    let summary = run(filter, pc, &ys, ny, &mut rng, &mut recorder);
    let wall_s = start.elapsed().as_secs_f64();
    if let Some(bar) = &recorder.progress {
        bar.finish_and_clear();
    }
    Driven {
        distinct: std::mem::take(&mut recorder.distinct),
        credible: std::mem::take(&mut recorder.credible),
        param_names: layout.param_names.clone(),
        theta_val: recorder.theta_val(),
        theta_sd_final: recorder.last.param_sd.clone(),
        online: truth_rows
            .as_ref()
            .map(|_| StateErrors::from_sums(&layout.state_names, &recorder.state_sums)),
        final_particles: recorder.final_particles.take(),
        residuals: recorder.predictor.take().map(|p| p.finish()),
        tail_loglik: recorder.tail_loglik,
        tail_steps: recorder.tail_steps,
        left_out: Vec::new(),
        trace: recorder.trace,
        summary,
        wall_s,
    }
}

/// Runs one algorithm on one data set and returns its record.
pub fn identify(input: &RunInput, algorithm: Algorithm, s: &FilterSettings) -> Result<RunRecord> {
    identify_stoppable(input, algorithm, s, &|| false)
}

/// [`identify`], asking `stop` before every filter step whether to stop (an interactive caller's
/// Ctrl-C): when it answers `true` the run ends and the error is [`Interrupted`]
/// ([`crate::error::Error::interrupted`]); nothing else differs, so a run that is not stopped returns the
/// record [`identify`] returns.
pub fn identify_stoppable(
    input: &RunInput,
    algorithm: Algorithm,
    s: &FilterSettings,
    stop: &dyn Fn() -> bool,
) -> Result<RunRecord> {
    let data = input.data;
    if data.len() < 2 {
        bail!(
            "the data set has {} samples; at least 2 are needed",
            data.len()
        );
    }
    crate::limits::check_filter_settings(s)?;
    let mut spec = chain_spec(data, input.chain, s)?;
    let scaled = prior_from_data(data, input.chain, s)?;
    let auto = resolve_substeps(algorithm, &mut spec, s, scaled.as_ref());
    if let (Some(h), true) = (auto.hysteretic, input.progress) {
        if h.substeps > 1 {
            eprintln!(
                "sub-steps: {} per sample (auto: Bouc–Wen elements and ω₁·dt = {:.4} above {}; \
                 ω₁·dt/{} = {:.4} ≤ {})",
                spec.substeps,
                h.omega1_dt,
                h.above,
                h.substeps,
                h.omega1_dt / h.substeps as f64,
                h.max_omega1_h
            );
        }
    }
    if let (Some(l), true) = (auto.lag, input.progress) {
        eprintln!(
            "sub-steps: {} per sample (auto: the MPF-EKF2 with one shared prior Gaussian on a \
             hysteretic building below {PER_PARTICLE_MIN_STOREYS} storeys, whose velocity lag \
             with one step, {:.1} %, is above {:.0} %; measured to lower the stiffness error at \
             5 storeys at about 3 times the cost: docs/calibration.md, \"The prior or the \
             size?\"; --substeps 1 to keep one step)",
            spec.substeps,
            100.0 * l.lag_one,
            100.0 * l.above
        );
    }
    if let (Some(a), true) = (auto.linear, input.progress) {
        if a.substeps == 1 && a.error_one > models::filtering::substeps::SUBSTEP_ABOVE {
            eprintln!(
                "warning: the prior's building has modes up to {:.2} Hz (ω·dt = {:.2}): one step \
                 per sample shifts that mode by {:.1} %, and {} cannot sub-step; its frequencies \
                 and stiffnesses carry that bias (MPF-EKF2 and the bootstrap PF sub-step)",
                a.omega_max / std::f64::consts::TAU,
                a.omega_max * spec.dt,
                100.0 * a.error_one,
                algorithm.label()
            );
        }
        if a.substeps > 1 {
            eprintln!(
                "sub-steps: {} per sample (auto: the prior's building has modes up to {:.2} Hz, \
                 ω·dt = {:.2}; one step per sample would shift that mode by {:.1} %, {} by {:.2} %)",
                a.substeps,
                a.omega_max / std::f64::consts::TAU,
                a.omega_max * spec.dt,
                100.0 * a.error_one,
                a.substeps,
                100.0 * a.error_chosen
            );
        }
        // The lag of the run's step (proportional to it): the Bouc–Wen rule may have raised
        // the sub-steps beyond the linear rule's.
        let lag = a.lag_one / spec.substeps as f64;
        if lag > models::filtering::substeps::LAG_NOTED_ABOVE {
            eprintln!(
                "note: with {} step(s) per sample the model favours stiffnesses up to {:.1} % \
                 low (with the prior's central dashpots and springs), most at the top storeys \
                 (the semi-implicit step's velocity lag; docs/calibration.md, \"The top \
                 storeys' bias\"). --substeps M divides it by M; on the scaling study's \
                 buildings 4 took the MPF-EKF2's mean stiffness error from 3.5 to 2.0 % at 5 \
                 storeys with one shared prior Gaussian (which is why `auto` takes them there) \
                 and did not pay with per-particle prior means (5 and 10 storeys; worse at 20), \
                 at about 3 times the cost (docs/calibration.md, \"The prior or the size?\")",
                spec.substeps,
                100.0 * lag
            );
        }
    }
    let pc = SmcConfig {
        particles: s.particles,
        resampling: ResamplePolicy {
            scheme: s.resampling,
            ess_threshold: s.ess_threshold,
        },
        rejuvenation: s.liu_west()?,
    };
    let mut filter = build_filter(algorithm, spec.clone(), s)?;
    // One-step-ahead prediction errors when asked for (`sysid filter`): every filter of a pool
    // computes its own (one noise-free step per time step), and the record keeps those of the
    // first filter the pool keeps (`pool::combine`).
    let predictor = || -> Result<Option<crate::residuals::Predictor>> {
        if !input.residuals {
            return Ok(None);
        }
        let ys = (1..data.len()).flat_map(|k| data.y(k).to_vec()).collect();
        let channels = data.sensors.iter().map(|j| format!("a{j}")).collect();
        Ok(Some(crate::residuals::Predictor::new(
            spec.clone(),
            ys,
            channels,
        )?))
    };
    // The pace of a long run is timed over all its pooled filters ([`crate::pace`]).
    let started = Instant::now();
    let shape = filter.shape();
    crate::limits::check_particle_cloud(
        s.particles,
        shape.sampled + shape.marginal * (shape.marginal + 1),
    )?;
    let d = if s.pool > 1 {
        if s.particles < s.pool {
            bail!(
                "field `pool`: {} particles cannot make {} filters",
                s.particles,
                s.pool
            );
        }
        // Np/M particles each, the first Np mod M filters one more.
        let (each, extra) = (s.particles / s.pool, s.particles % s.pool);
        let layout = filter.layout().clone();
        let members: Vec<Driven> = (0..s.pool)
            .map(|m| {
                let member = SmcConfig {
                    particles: each + usize::from(m < extra),
                    ..pc
                };
                let p = predictor()?;
                let who = Member {
                    index: m,
                    started,
                    stop,
                };
                interrupted(
                    drive(filter.as_mut(), input, s, algorithm, &member, who, p),
                    data.len() - 1,
                )
            })
            .collect::<Result<_>>()?;
        crate::pool::combine(&layout, members, data.channels)
    } else {
        if s.pool == 0 {
            bail!("field `pool`: 0 filters (1 runs one filter)");
        }
        let who = Member {
            index: 0,
            started,
            stop,
        };
        interrupted(
            drive(filter.as_mut(), input, s, algorithm, &pc, who, predictor()?),
            data.len() - 1,
        )?
    };

    let steps = data.len() - 1;
    let theta_true = data.meta.as_ref().map(|m| m.theta_true.clone());
    if let Some(t) = &theta_true {
        if t.len() != d.param_names.len() {
            return Err(invalid!(
                "the data set's true θ has {} entries, the filter's θ {}",
                t.len(),
                d.param_names.len()
            ));
        }
    }
    let validation_start = Instant::now();
    let validation = match (s.validate, input.chain, &data.truth) {
        (true, Some(chain), Some(truth)) if d.summary.failure.is_none() => {
            Some(validate(chain, &d.theta_val, truth, data.dt, s.loop_every))
        }
        _ => None,
    };
    let validation_s = validation_start.elapsed().as_secs_f64();
    let mut failures = BTreeMap::new();
    if let Some(f) = &d.summary.failure {
        failures.insert(f.kind().to_string(), 1);
    }
    // A pooled filter's failure is counted even when the pool's answer stands without it.
    if d.summary.failure.is_none() {
        for kind in d.left_out.iter().filter_map(|l| l.failure_kind.clone()) {
            *failures.entry(kind).or_insert(0) += 1;
        }
    }
    let mut config = serde_json::json!({
        "algorithm": algorithm.name(),
        "filter": s,
        "data": data.meta.as_ref().map(|m| serde_json::to_value(&m.config).ok()),
        "spec": {
            "dt": spec.dt, "masses": spec.building.masses(),
            "hysteretic": spec.building.hysteretic(),
            "sensors": spec.sensors, "q_disp": spec.q_disp, "q_vel": spec.q_vel,
            "q_r": spec.q_r, "r_diag": spec.r_diag, "prior": spec.prior,
            "discretisation": spec.discretisation,
        },
    });
    if spec.substeps != 1 {
        config["spec"]["substeps"] = spec.substeps.into();
    }
    if let Some(a) = auto.linear {
        config["substeps_auto"] = serde_json::to_value(a).expect("serialisable");
    }
    if let Some(h) = auto.hysteretic {
        config["substeps_hysteretic"] = serde_json::to_value(h).expect("serialisable");
    }
    if let Some(l) = auto.lag {
        config["substeps_lag"] = serde_json::to_value(l).expect("serialisable");
    }
    if !spec.building.damping().is_default() {
        config["spec"]["damping"] = spec.building.damping().name().into();
    }
    if let Some(p) = scaled {
        config["prior_from_data"] = serde_json::to_value(p).expect("serialisable");
    }
    let mut record = RunRecord {
        experiment: input.experiment.to_string(),
        algorithm: algorithm.name().to_string(),
        seed: input.seed,
        run: input.run,
        particles: s.particles,
        rel_error: theta_true
            .as_ref()
            .map(|t| relative_errors(&d.theta_val, t)),
        theta_true,
        param_names: d.param_names,
        theta_val: d.theta_val,
        window: s.window,
        theta_sd_final: d.theta_sd_final,
        loglik: d.summary.loglik,
        steps_total: steps,
        steps_completed: d.summary.steps_completed,
        ess_min: d.summary.ess_min.unwrap_or(f64::NAN),
        ess_mean: d.summary.ess_mean.unwrap_or(f64::NAN),
        distinct_sampled: d.distinct.into_iter().collect(),
        failures,
        failure: d.summary.failure.as_ref().map(|f| f.to_string()),
        health: d.summary.health,
        online_states: d.online,
        validation,
        config,
        versions: Versions::current(),
        fingerprint: Some(Fingerprint::of_run(
            algorithm.name(),
            input.seed,
            input.run,
            s,
            data,
        )),
        trace: d.trace,
        timing: Timing {
            wall_s: d.wall_s,
            particle_steps_per_s: (s.particles * d.summary.steps_completed) as f64
                / d.wall_s.max(1e-12),
            validation_s,
        },
        warnings: Vec::new(),
        credible: d.credible,
        innovation_checks: d
            .residuals
            .as_ref()
            .map(crate::residuals::channel_checks)
            .unwrap_or_default(),
        residuals: d.residuals,
        free_run: None,
        modal: None,
        pool_left_out: d.left_out,
    };
    // A result that is physically impossible or rests on few particles says so (issue 16).
    record.warnings = crate::checks::check(&record);
    Ok(record)
}

/// A driven filter, or [`Interrupted`] when it was stopped.
fn interrupted(d: Driven, steps: usize) -> Result<Driven> {
    if let Some(core_filters::error::FilterError::Interrupted { step }) = d.summary.failure {
        return Err(Interrupted { step, steps }.into());
    }
    Ok(d)
}

/// The validation run (SPEC §7): θ_val, zero initial conditions, clean excitation, adaptive
/// Dormand–Prince 5(4); errors against the true states and the hysteresis loops.
fn validate(
    chain: &ShearChain,
    theta_val: &[f64],
    truth: &models::dataset::LoadedTruth,
    dt: f64,
    loop_every: usize,
) -> Validation {
    let names = truth.state_names.clone();
    let fail = |e: String| Validation {
        states: StateErrors {
            names: names.clone(),
            errors: vec![],
        },
        loop_validation: None,
        loop_true: None,
        error: Some(e),
    };
    let model = match chain.with_theta(theta_val) {
        Ok(m) => m,
        Err(e) => return fail(format!("θ_val is not a valid structure: {e}")),
    };
    let traj = match simulate_adaptive(&model, &truth.ug_clean, dt, Tolerance::default()) {
        Ok(t) => t,
        Err(e) => return fail(format!("validation integration failed: {e}")),
    };
    let mut sums = vec![ErrorSums::default(); names.len()];
    for k in 0..traj.len().min(truth.states.len()) {
        for (j, s) in sums.iter_mut().enumerate() {
            s.add(traj.state(k)[j], truth.states.state(k)[j]);
        }
    }
    let loops = |c: &ShearChain, t: &models::integrate::Trajectory| -> Loop {
        let mut l = Loop::default();
        for k in (0..t.len()).step_by(loop_every.max(1)) {
            l.x.push(c.element_drift(t.state(k), 0));
            l.force.push(c.restoring_force(t.state(k), 0));
        }
        l
    };
    let keep = loop_every > 0 && !chain.bouc_wen().is_empty();
    Validation {
        states: StateErrors::from_sums(&names, &sums),
        loop_validation: keep.then(|| loops(&model, &traj)),
        loop_true: keep.then(|| loops(chain, &truth.states)),
        error: None,
    }
}
