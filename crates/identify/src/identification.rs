//! One identification as `sysid filter` runs it: the filter settings (a config file's or the
//! recommended ones, under the command line's overrides), the building of field data resolved
//! from flags and the config's `[structure]` table, the run, the validation of field data, and
//! the decision on the finished record ([`finish`]).
//!
//! The command line only parses its flags into a [`FilterRequest`] and prints what
//! [`identify_request`] and [`finish`] return.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::error::{Context, Result};
use core_filters::resampling::Scheme;
use core_filters::smc::storvik::StorvikUpdate;
use models::dataset::{load_dir, LoadedDataset, MEASURED};
use models::sensors::MeasurementKind;

use crate::checks;
use crate::field::StructureSettings;
use crate::pipeline::{Algorithm, FilterSettings, RunInput};
pub use crate::plan::Target;
use crate::plan::{Decision, RunPlan};
use crate::record::RunRecord;
use crate::simulation::parse_storeys;

/// A malformed `--fix` list (`name=value,name=value`).
#[derive(Debug, thiserror::Error)]
pub enum FixError {
    #[error("--fix: `{0}` is not of the form name=value")]
    NotNameValue(String),
    #[error("--fix: value `{value}` of {name} is not a number")]
    NotANumber {
        name: String,
        value: String,
        #[source]
        source: std::num::ParseFloatError,
    },
    #[error("--fix: value of {0} is not finite")]
    NotFinite(String),
    #[error("--fix: {0} is given twice")]
    Twice(String),
}

crate::error::domain_error!(FixError);

/// Parses `name=value,name=value`.
pub fn parse_fix(s: &str) -> Result<BTreeMap<String, f64>, FixError> {
    let mut out = BTreeMap::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, value) = part
            .split_once('=')
            .ok_or_else(|| FixError::NotNameValue(part.to_string()))?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|source| FixError::NotANumber {
                name: name.to_string(),
                value: value.to_string(),
                source,
            })?;
        if !v.is_finite() {
            return Err(FixError::NotFinite(name.to_string()));
        }
        if out.insert(name.trim().to_string(), v).is_some() {
            return Err(FixError::Twice(name.trim().to_string()));
        }
    }
    Ok(out)
}

/// Every key of a filter config (`--config`) with the value `sysid filter` uses without a config
/// ([`FilterSettings::recommended`]) and its meaning, as a TOML file that parses back to those
/// settings. A config turns off the rules that depend on the building (rejuvenation, particle
/// count, per-particle prior: [`crate::rules`]), so `--config` of this file does not run what no
/// config runs; `--print-plan` and `--plan` do (the printed text says so).
pub fn commented_defaults() -> String {
    let d = FilterSettings::recommended();
    let paper = FilterSettings::default();
    [
        defaults_preamble(&paper),
        sampling_and_noise_keys(&d),
        model_and_record_keys(&d),
        marginal_prior_keys(),
        TABLE_KEYS.to_string(),
    ]
    .concat()
}

/// The preamble of [`commented_defaults`]: what the file is, where its values come from, and
/// that a config turns off the building's rules (`paper`: the paper's settings, for absent keys).
fn defaults_preamble(paper: &FilterSettings) -> String {
    format!(
        r#"# Filter settings of `sysid filter --config FILE.toml` (and the [filter] table of a study).
# Shown with the values `sysid filter` uses without --config (the recommended settings, whose
# interval coverage is measured in docs/calibration.md). A key absent from a file takes the
# paper's value instead (ess_threshold absent, pool = 1, discretisation = "{paper_disc}").
# Command-line options override the file. With a config the rules that depend on the building
# (the MPF-EKF2's rejuvenation, particle count and per-particle prior; see `sysid filter --help`)
# do not apply: this file does not run exactly what no config runs. To rerun a run exactly,
# write its plan (`sysid filter … --print-plan > plan.toml`) and run `--plan plan.toml`.

"#,
        paper_disc = paper.discretisation.name(),
    )
}

/// The keys of the particles, resampling, pooling and noise levels with their recommended
/// values `d`.
fn sampling_and_noise_keys(d: &FilterSettings) -> String {
    let q = |v: &dyn erased::Show| v.show();
    format!(
        r#"# Number of particles Np (SPEC §3).
particles = {particles}
# Resampling scheme: "systematic", "stratified", "multinomial" or "residual".
resampling = {resampling}
# Resample only when ESS < ess_threshold × particles, in (0, 1]; absent: every step (SPEC §3).
ess_threshold = {ess}
# Independent filters pooled into one run (the particles split between them); θ_val is their
# mean and its Monte-Carlo s.e. is reported (docs/calibration.md). 1: one filter (the paper's).
# Without a config, --particles P pools one filter per 125 particles (1 to 8).
pool = {pool}
# Storvik's step (iii): "linearised" (the paper's) or "exact".
storvik_update = {storvik}
# Noise fraction nf: R and Q are set from nf × RMS of the signals (SPEC §3). Without --config, on
# field data of a linear building, chosen with process_noise_factor (and the damping form when no
# --damping is given) by the free-run fit of the record's second half by energy, which the
# candidates were not identified on (docs/validation.md).
noise_fraction = {nf}
# The velocities' process noise relative to SPEC §3's (s.d. factor × dt × nf × RMS ü_g).
process_noise_factor = {pnf}
"#,
        ess = q(&d
            .ess_threshold
            .expect("the recommended settings resample on the ESS")),
        pool = d.pool,
        particles = d.particles,
        resampling = q(&d.resampling),
        storvik = q(&d.storvik_update),
        nf = q(&d.noise_fraction),
        pnf = q(&d.process_noise_factor),
    )
}

/// The keys of the model inside the filter (support, r's noise, discretisation, sub-steps) and
/// of what the record keeps, with their recommended values `d`.
fn model_and_record_keys(d: &FilterSettings) -> String {
    let q = |v: &dyn erased::Show| v.show();
    format!(
        r#"# Hold the marginalised stiffnesses, dampings and α at ≥ 0 after every step (moment-matched
# truncation of each Gaussian): answers physical by construction. The paper's filters: false.
physical_support = {physical}
# Process noise of each hysteretic variable r: s.d. per step r_noise_fraction × dt × RMS drift
# velocity of its element (SPEC §3: 0.05, the paper's σ_r; the simulated truth has none). A tenth
# of it removes most of the MPF-EKF2's k1 bias at 10 storeys but made 20 storeys less accurate
# (docs/calibration.md, "The process noise of r").
r_noise_fraction = {rnf}
# Discretisation inside the filters: "euler" (the paper's), "symplectic", "rk4" (bootstrap only).
discretisation = {disc}
# Coloured measurement noise (MPF-EKF2 only): the part `share` of each channel's measurement
# variance is an AR(1) sequence with coefficient `rho` per sample interval, one more state per
# channel in the filter's Gaussian part (docs/validation.md, "Coloured measurement noise").
# Absent: white noise only (the SPEC's). As a table at the end of the file, e.g.
#   [coloured_noise]
#   rho = 0.97
#   share = 0.8
# Transitions inside the filter per sample interval (dt/substeps each, ü_g interpolated), for
# data sampled coarsely relative to the structure's highest modes; "auto": where one step would
# shift the highest mode of the prior's building by more than 2 %, enough sub-steps to bring it
# under 0.5 % (one on the paper's data); more than one for MPF-EKF2 and bootstrap PF only.
substeps = {substeps}
# θ_val averages the posterior mean over the last `window` steps (SPEC eq. 26).
window = {window}
# Keep one trace step in `trace_every` in the record (0: no trace).
trace_every = {trace}
# Run the validation integration with θ_val when the truth is known (SPEC §7).
validate = {validate}
# Keep one hysteresis-loop point in `loop_every` in the record (0: no loops).
loop_every = {loops}
"#,
        rnf = q(&d.r_noise_fraction),
        physical = d.physical_support,
        disc = q(&d.discretisation),
        substeps = d.substeps,
        window = d.window,
        trace = d.trace_every,
        validate = d.validate,
        loops = d.loop_every,
    )
}

/// The keys of the marginalised block's prior and of the rejuvenation of the sampled exponents.
fn marginal_prior_keys() -> String {
    format!(
        r#"# Gaussian prior of the marginalised block: {{ kind = "moment_matched" }} (one moment-matched
# Gaussian) or {{ kind = "per_particle", rel_sd = 0.1 }} (means drawn per particle). Without
# --config the MPF-EKF2 takes per_particle when a storey carries no sensor (docs/scaling.md) or
# the building has 10 storeys or more (docs/calibration.md).
marginal_prior = {{ kind = "moment_matched" }}
# Rejuvenation of the sampled Bouc–Wen exponents n (MLN-RBPF, Storvik, MPF-EKF2): after every
# resampling the Liu–West kernel with discount δ in [1/3, 1] moves them; absent (or 1): no move.
# Without --config the MPF-EKF2 takes {mpf_rejuvenation} (not with per-particle prior means) and the
# others none (docs/calibration.md).
# rejuvenation = {mpf_rejuvenation}

"#,
        mpf_rejuvenation = crate::pipeline::MPF_REJUVENATION,
    )
}

/// The tables of a config, commented out: point-mass priors, the building of field data and the
/// prior of θ.
const TABLE_KEYS: &str = r#"# Point-mass priors: parameter name = value (k1..kN, c1..cN, alpha with the storey+mass damping
# form, beta, gamma, n; with several hysteretic elements beta4, gamma4, n4 for the element at
# storey 4).
[fix]
# k1 = 8.0

# The building of field data (no dataset.json); data sets with dataset.json carry their own and
# a key here must agree with it. See docs/structures.md.
[structure]
# Number of storeys N.
# storeys = 3
# 1-based storeys with a Bouc–Wen element ([] for a linear building).
# hysteretic = [1]
# Storey masses m1..mN, or one value for every storey ([1.0]: k and c per unit mass).
# masses = [1.0, 1.0, 1.0]
# What the accelerometers record: "absolute" (ẍ + ü_g, real accelerometers) or "relative" (ẍ).
# measurement = "absolute"
# Damping form: "storey" (per-storey dashpots c1..cN, the default) or "storey+mass" (also
# mass-proportional damping αM: storey j gains −α m_j v_j; θ gains alpha after c1..cN).
# damping = "storey"

# Prior of θ; absent: SPEC §3's for the structure (k ~ LogNormal(10, 0.3), c ~ LogNormal(0.4,
# 0.5), per element (β, γ) uniform on the triangle 0 ≤ β ≤ 5, |γ| ≤ β, n ~ U(1, 5)). When given,
# it has one entry per storey in k and c and one element per hysteretic storey (0-based storey):
# [prior]
# k = [{ kind = "log_normal", median = 10.0, log_sd = 0.3 }, ...]
# c = [{ kind = "log_normal", median = 0.4, log_sd = 0.5 }, ...]
# alpha = { kind = "log_normal", median = 0.5, log_sd = 1.0 }  (storey+mass damping only)
# elements = [{ storey = 0, beta_gamma = { kind = "triangle", beta_max = 5.0 }, n = { kind = "uniform", lo = 1.0, hi = 5.0 } }]
"#;

/// A value as TOML writes it (through serde, so the printed defaults are the real ones).
mod erased {
    pub(crate) trait Show {
        fn show(&self) -> String;
    }
    impl<T: serde::Serialize> Show for T {
        fn show(&self) -> String {
            #[derive(serde::Serialize)]
            struct W<'a, T> {
                v: &'a T,
            }
            let text = toml::to_string(&W { v: self }).expect("a default serialises");
            text.trim()
                .strip_prefix("v = ")
                .expect("one key")
                .to_string()
        }
    }
}

/// One identification as `sysid filter` asks for it: every flag but `--out`, `--plot` and
/// `--print-config`, the lists still in their command-line form (errors name the flag).
#[derive(Debug, Clone)]
pub struct FilterRequest {
    pub algorithm: Algorithm,
    /// Data-set directory.
    pub data: PathBuf,
    /// TOML file of filter settings; `None`: [`FilterSettings::recommended`].
    pub config: Option<PathBuf>,
    pub particles: Option<usize>,
    pub resampling: Option<Scheme>,
    pub ess_threshold: Option<f64>,
    pub storvik_update: Option<StorvikUpdate>,
    pub discretisation: Option<models::filtering::Discretisation>,
    pub substeps: Option<crate::settings::Substeps>,
    /// Liu–West discount of the rejuvenation move (`rejuvenation`).
    pub rejuvenation: Option<f64>,
    /// Fixed parameters, `name=value,…`.
    pub fix: Option<String>,
    /// Noise fraction and process-noise factor, over the config's (stated: not chosen by
    /// [`crate::choice`]).
    pub noise_fraction: Option<f64>,
    pub process_noise_factor: Option<f64>,
    /// Coloured measurement noise, over the config's.
    pub coloured_noise: Option<models::filtering::ColouredNoise>,
    /// Each channel's measurement noise learned by maximum likelihood after the plan is
    /// settled ([`crate::choice::channel_noise`]).
    pub learn_noise: bool,
    pub experiment: String,
    pub seed: u64,
    pub run: u64,
    /// Field data: number of storeys.
    pub storeys: Option<usize>,
    /// Field data: 1-based hysteretic storeys, `1,4` or `none`.
    pub hysteretic: Option<String>,
    /// Field data: storey masses `m1,...,mN`, or one value.
    pub masses: Option<String>,
    pub measurement: Option<MeasurementKind>,
    pub damping: Option<models::structure::Damping>,
}

/// The structure flags as a `[structure]` table; errors name the flag.
fn structure_flags(args: &FilterRequest) -> Result<StructureSettings> {
    let masses = match &args.masses {
        Some(m) => Some(
            m.split(',')
                .map(|part| {
                    let part = part.trim();
                    part.parse::<f64>().ok().with_context(|| {
                        format!("--masses: `{part}` is not a number (a comma list m1,...,mN, or one value)")
                    })
                })
                .collect::<Result<Vec<f64>>>()?,
        ),
        None => None,
    };
    Ok(StructureSettings {
        storeys: args.storeys,
        hysteretic: match &args.hysteretic {
            Some(h) => Some(parse_storeys("--hysteretic", h, true)?),
            None => None,
        },
        masses,
        measurement: args.measurement,
        damping: args.damping,
    })
}

/// The noise levels of a field-data run, chosen from the measured signals (SPEC §3): the
/// plan's [`crate::plan::Model`].
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseLevels {
    pub noise_fraction: f64,
    /// Measurement noise variances, one per channel.
    pub r_diag: Vec<f64>,
    /// Process noise s.d. of the displacements.
    pub q_disp: f64,
    /// Process noise s.d. of the velocities.
    pub q_vel: f64,
    /// Process noise s.d. of the hysteretic variables.
    pub q_r: Vec<f64>,
    /// The coloured part of the measurement noise, if any.
    pub coloured: Option<models::filtering::ColouredNoise>,
    /// Whether the measurement noise was learned per channel (`--learn-noise`) rather than
    /// the noise fraction's.
    pub learned: bool,
}

impl NoiseLevels {
    fn of(plan: &RunPlan) -> Self {
        NoiseLevels {
            noise_fraction: plan.settings.noise_fraction,
            r_diag: plan.model.r_diag.clone(),
            q_disp: plan.model.q_disp,
            q_vel: plan.model.q_vel,
            q_r: plan.model.q_r.clone(),
            coloured: plan.model.coloured_noise,
            learned: plan.evidence.channel_noise.is_some(),
        }
    }
}

impl fmt::Display for NoiseLevels {
    /// The line `sysid filter` prints; a value that is not finite (recorded as JSON `null`) is
    /// left out of a list and shown as `?` alone.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let list = |v: &[f64], g: fn(f64) -> f64| -> String {
            v.iter()
                .filter(|x| x.is_finite())
                .map(|&x| format!("{:.3e}", g(x)))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let num = |x: f64| {
            if x.is_finite() {
                format!("{x:.3e}")
            } else {
                "?".to_string()
            }
        };
        let coloured = match self.coloured {
            Some(c) => format!(
                "; of each channel's measurement variance the part {} is coloured, AR(1) with \
                 ρ {} per sample, carried by the filter",
                c.share, c.rho
            ),
            None => String::new(),
        };
        let learned = if self.learned {
            "; measurement noise learned per channel by maximum likelihood"
        } else {
            ""
        };
        write!(
            f,
            "noise levels from the data (noise fraction {}{learned}): measurement s.d. [{}] m/s²{coloured}, process s.d. x {}, v {}, r [{}] (recorded under config.spec)",
            self.noise_fraction,
            list(&self.r_diag, f64::sqrt),
            num(self.q_disp),
            num(self.q_vel),
            list(&self.q_r, |x| x),
        )
    }
}

/// A finished identification, before its record is written ([`finish`]).
#[derive(Debug)]
pub struct Identified {
    pub record: RunRecord,
    /// Field data: the noise levels the run chose from the data; `None` for simulated data.
    pub noise: Option<NoiseLevels>,
}

/// The options of a run that override a filter setting (`sysid filter`'s flags, the Python
/// `identify`'s keywords).
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    pub particles: Option<usize>,
    pub resampling: Option<Scheme>,
    pub ess_threshold: Option<f64>,
    pub discretisation: Option<models::filtering::Discretisation>,
    pub substeps: Option<crate::settings::Substeps>,
    pub storvik_update: Option<StorvikUpdate>,
    /// Liu–West discount of the rejuvenation move.
    pub rejuvenation: Option<f64>,
    /// Fixed parameters, added to the settings' own.
    pub fix: BTreeMap<String, f64>,
}

impl Overrides {
    /// `settings` with these options over them.
    pub fn apply(&self, mut settings: FilterSettings) -> FilterSettings {
        if let Some(p) = self.particles {
            settings.particles = p;
        }
        if let Some(r) = self.resampling {
            settings.resampling = r;
        }
        if self.ess_threshold.is_some() {
            settings.ess_threshold = self.ess_threshold;
        }
        if self.rejuvenation.is_some() {
            settings.rejuvenation = self.rejuvenation;
        }
        if let Some(d) = self.discretisation {
            settings.discretisation = d;
        }
        if let Some(m) = self.substeps {
            settings.substeps = m;
        }
        if let Some(u) = self.storvik_update {
            settings.storvik_update = u;
        }
        settings.fix.extend(self.fix.clone());
        settings
    }
}

/// The settings of a request: the config file's (or the recommended ones) under the request's
/// overrides.
fn request_settings(req: &FilterRequest) -> Result<FilterSettings> {
    let settings = match &req.config {
        Some(path) => crate::limits::load_filter_settings(path)?,
        None => FilterSettings::recommended_with(req.particles),
    };
    let overrides = Overrides {
        particles: req.particles,
        resampling: req.resampling,
        ess_threshold: req.ess_threshold,
        discretisation: req.discretisation,
        substeps: req.substeps,
        storvik_update: req.storvik_update,
        rejuvenation: req.rejuvenation,
        fix: match &req.fix {
            Some(f) => parse_fix(f)?,
            None => BTreeMap::new(),
        },
    };
    let mut settings = overrides.apply(settings);
    if let Some(nf) = req.noise_fraction {
        settings.noise_fraction = nf;
    }
    if let Some(pf) = req.process_noise_factor {
        settings.process_noise_factor = pf;
    }
    if let Some(c) = req.coloured_noise {
        settings.coloured_noise = Some(c);
    }
    Ok(settings)
}

/// The settings [`crate::plan::settle`] settles for `t` (seed 0, run 0), and its decisions, in
/// order, to `note`.
pub fn settle(
    t: &Target,
    settings: FilterSettings,
    note: &mut dyn FnMut(&Decision),
) -> Result<FilterSettings> {
    let plan = crate::plan::settle(t.request(settings, 0, 0, ""))?;
    plan.decisions.iter().for_each(note);
    Ok(plan.settings)
}

/// The data of a request, loaded, with the true structure when the data set says what it is.
pub fn load_request_data(
    dir: &Path,
) -> Result<(LoadedDataset, Option<models::structure::ShearChain>)> {
    let data: LoadedDataset =
        load_dir(dir).with_context(|| format!("loading data set {}", dir.display()))?;
    let chain = data
        .true_chain()
        .context("rebuilding the data set's structure")?;
    Ok((data, chain))
}

/// Settles the plan of a request ([`crate::plan::settle`]) on its loaded data: the settings
/// (the config's or the recommended ones under the flags), the building (simulated data carry
/// theirs and a stated key must agree with it; field data take the flags over the config's
/// `[structure]` table and are refused by name when incomplete) and every default rule.
pub fn plan_request(
    req: &FilterRequest,
    data: &LoadedDataset,
    chain: Option<&models::structure::ShearChain>,
) -> Result<RunPlan> {
    let settings = request_settings(req)?;
    let flags = structure_flags(req)?;
    let measured = req.data.join(MEASURED);
    let config_name = req.config.as_ref().map(|p| p.display().to_string());
    let target = Target {
        algorithm: req.algorithm,
        data,
        chain,
        measured: &measured,
        flags: &flags,
        config: config_name.as_deref(),
        particles_asked: req.particles.is_some(),
    };
    let plan =
        crate::plan::settle(target.request(settings.clone(), req.seed, req.run, &req.experiment))?;
    let stated = crate::choice::Stated {
        noise_fraction: req.noise_fraction.is_some(),
        process_noise_factor: req.process_noise_factor.is_some(),
    };
    let plan = crate::choice::choose(plan, &target, &settings, stated)?;
    if req.learn_noise {
        return crate::choice::channel_noise::learn(plan, data);
    }
    Ok(plan)
}

/// Runs a settled plan as `sysid filter` does: the run (progress shown, prediction errors
/// kept), the plan written into the record, and for field data the validation without the
/// truth (free run, modes; docs/validation.md).
pub fn identify_plan(
    plan: &RunPlan,
    data: &LoadedDataset,
    chain: Option<&models::structure::ShearChain>,
    stop: &(dyn Fn() -> bool + Sync),
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<Identified> {
    let input = RunInput {
        data,
        chain,
        experiment: &plan.experiment,
        seed: plan.seed,
        run: plan.run,
        progress,
        residuals: true,
    };
    let mut record = crate::pipeline::execute(plan, &input, stop)?;
    record.plan = Some(serde_json::to_value(plan).context("recording the plan")?);
    // The digest of the record's `config`, so that an edit of the building a later `validate`
    // or `plot` would use is refused. Only in the records of an identification: a study's
    // records are their study description and fingerprint, and stay as committed.
    record.fingerprint = record
        .fingerprint
        .take()
        .map(|f| f.with_config(&record.config));
    let mut noise = None;
    if data.meta.is_none() && record.failure.is_none() {
        // Field data: the intervals include the spread of θ between the record's parts
        // (model error, docs/validation.md), before the band and the modes draw from them.
        let (widened, spread) = crate::spread::reported(
            &record.param_names,
            &record.credible,
            &record.trace,
            plan.holds_bounds(),
        );
        if spread.is_some() {
            record.credible = widened;
            record.segment_spread = spread;
        }
    }
    if data.meta.is_none() {
        // Field data: validation without the truth (free run, modes; docs/validation.md).
        // The band's model error: the chosen candidate's, learned on the part of the record
        // it did not fit (in-sample when the held-out choice did not run).
        let held_out = plan.evidence.held_out_error();
        let modes = plan
            .evidence
            .discrepancy
            .as_ref()
            .map_or(&[][..], |c| c.modes());
        let started = std::time::Instant::now();
        crate::validation::attach(&mut record, data, &plan.building, held_out, modes);
        record.timing.validation_s += started.elapsed().as_secs_f64();
        // The noise levels were chosen from the measured signals (SPEC §3).
        noise = Some(NoiseLevels::of(plan));
    }
    Ok(Identified { record, noise })
}

/// Runs the identification a request asks for: its plan ([`plan_request`]), whose decisions
/// `note` hears in order before the run starts, then [`identify_plan`].
pub fn identify_request(
    req: &FilterRequest,
    note: &mut dyn FnMut(&Decision),
) -> Result<Identified> {
    let (data, chain) = load_request_data(&req.data)?;
    let started = std::time::Instant::now();
    let plan = plan_request(req, &data, chain.as_ref())?;
    let plan_s = started.elapsed().as_secs_f64();
    plan.decisions.iter().for_each(note);
    let mut identified = identify_plan(&plan, &data, chain.as_ref(), &|| false, None)?;
    identified.record.timing.plan_s = Some(plan_s);
    Ok(identified)
}

/// Seconds of record filtered per second of computation (the record's `config.spec.dt` × the
/// steps completed over the wall time); `None` without a spec or a time.
pub fn realtime_factor(r: &RunRecord) -> Option<f64> {
    if r.timing.realtime_factor.is_some() {
        return r.timing.realtime_factor;
    }
    let dt = r.config.get("spec")?.get("dt")?.as_f64()?;
    let wall = r.timing.wall_s;
    (wall > 0.0 && dt > 0.0).then(|| r.steps_completed as f64 * dt / wall)
}

/// Why a finished run is not an identification to use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejected {
    #[error("the run failed at step {step} of {total}: {failure} (record written to {})", .out.display())]
    Failed {
        step: usize,
        total: usize,
        failure: String,
        out: PathBuf,
    },
    #[error("the result is physically impossible ({}): not an identification to use (record with its warnings written to {})", .parameters.join(", "), .out.display())]
    Impossible {
        parameters: Vec<String>,
        out: PathBuf,
    },
}

crate::error::domain_error!(Rejected);

/// A finished run with its plausibility warnings, its record written.
#[derive(Debug)]
pub struct Finished {
    pub record: RunRecord,
    /// Where the record was written.
    pub out: PathBuf,
}

impl Finished {
    /// The line on the run (algorithm, steps, log-likelihood, pace, record path).
    pub fn headline(&self) -> String {
        let record = &self.record;
        let mut realtime =
            realtime_factor(record).map_or(String::new(), |f| format!(", {f:.1}× real time"));
        if let (true, Some(n)) = (record.timing.particle_blocks, record.timing.threads) {
            realtime += &format!(", particle blocks on {n} threads");
        }
        // The run is not the whole of it: on field data the plan's choices identify on their
        // own before it, and the free run and modes follow it.
        if let Some(p) = record.timing.plan_s {
            realtime += &format!("; plan settled in {p:.2} s before it");
        }
        if record.free_run.is_some() || record.modal.is_some() {
            realtime += &format!(
                ", free run and modes {:.2} s after it",
                record.timing.validation_s
            );
        }
        format!(
            "{}: {} of {} steps, loglik {:.2}, {:.2} s ({:.2} M particle-steps/s{realtime}); record {}",
            record.algorithm,
            record.steps_completed,
            record.steps_total,
            record.loglik,
            record.timing.wall_s,
            record.timing.particle_steps_per_s / 1e6,
            self.out.display()
        )
    }

    /// The summary table and the validation summary.
    pub fn summary(&self) -> String {
        checks::summary_table(&self.record)
            + &crate::validation::summary(self.record.free_run.as_ref(), self.record.modal.as_ref())
    }

    /// The exit decision of `sysid filter`: an error when the run failed or its answer is
    /// physically impossible.
    pub fn verdict(&self) -> Result<(), Rejected> {
        let record = &self.record;
        if let Some(f) = &record.failure {
            return Err(Rejected::Failed {
                step: record.steps_completed + 1,
                total: record.steps_total,
                failure: f.clone(),
                out: self.out.clone(),
            });
        }
        if checks::is_fatal(&record.warnings) {
            let parameters = record
                .warnings
                .iter()
                .filter(|w| w.kind.is_fatal())
                .filter_map(|w| w.parameter.clone())
                .collect();
            return Err(Rejected::Impossible {
                parameters,
                out: self.out.clone(),
            });
        }
        Ok(())
    }
}

/// Attaches the plausibility warnings (`checks::check`) to a finished run and writes its record
/// (in every case, also for a run [`Finished::verdict`] rejects).
pub fn finish(mut record: RunRecord, out: &Path) -> Result<Finished> {
    record.warnings = checks::check(&record);
    // Written, then read back by the reader every command uses: a record `plot` or
    // `compare-reference` would refuse is an error here, not a success.
    crate::record::read::write(out, &record)?;
    Ok(Finished {
        record,
        out: out.to_path_buf(),
    })
}
