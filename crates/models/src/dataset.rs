//! Data generation and data-set directories (SPEC §2).
//!
//! [`generate`] integrates the truth with RK4 under the clean excitation, then adds Gaussian
//! noise of s.d. `noise_fraction × RMS` to every clean acceleration channel and to the
//! excitation. Each noise comes from its own named stream
//! (`core_filters::rng::stream(seed, run, purpose)`): measurement noise from
//! `purpose::MEASUREMENT_NOISE`, excitation noise from `purpose::EXCITATION_NOISE`, a synthetic
//! excitation from `purpose::EXCITATION`. All samples are kept, including row 0 at `t = 0`
//! (the filters use `k = 1..K`).
//!
//! A data-set directory holds
//! - `measured.csv`: header `t,ug,a<s>...` (measured excitation and accelerations), one column
//!   `a<s>` per measured storey `s` (1-based, increasing: `t,ug,a1,a3,a5`); the header is what
//!   says which storeys are measured, with or without `dataset.json`;
//! - `truth.csv` (optional): header `t,ug,x1..xN,v1..vN,r<s>...` with the clean excitation and
//!   the true states of every storey, one `r` column per Bouc–Wen element (1-based storey `s`);
//! - `dataset.json` (optional): [`DatasetMeta`] (config, the structure as a
//!   [`StructureDescription`], true parameters, noise levels, RMS).
//!
//! Numbers are written as the shortest decimal that parses back to the same bits (Rust's `{}`
//! formatting of `f64`, or `{:e}` outside `[1e-5, 1e16)` so that no number takes more than 24
//! characters), so a directory round-trips bit for bit. Every written value is within
//! `±MAX_ABS_VALUE` ([`limits`]), so every data set written loads back.

use crate::building::{Building, BuildingError, Damping};
use crate::description::StructureDescription;
use crate::excitation::{self, rms, GroundMotion, KanaiTajimi};
use crate::integrate::{rk4_substeps, simulate_rk4_substeps, Trajectory};
use crate::limits;
use crate::preset::{Preset, PresetError, HARMONIC_DURATION};
use crate::readers::{self, parse_field, uniform_step, ReadError, Units};
use crate::sensors::SensorLayout;
use crate::structure::ShearChain;
use core_filters::rng::{purpose, stream};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use thiserror::Error;

mod integrity;
pub mod replace;

pub use crate::sensors::MeasurementKind;
pub use integrity::FileDigest;
use integrity::MetaFile;

/// Where the ground acceleration comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ExcitationSource {
    /// The vendored El Centro 1940 N-S record.
    ElCentro,
    /// Kanai–Tajimi / Clough–Penzien filtered white noise from the `excitation` stream.
    KanaiTajimi { params: KanaiTajimi },
    /// `amplitude·sin(omega·t)` (m/s², rad/s).
    Harmonic { amplitude: f64, omega: f64 },
    /// A user CSV record `t,acc`.
    Csv { path: PathBuf, units: Units },
    /// A PEER NGA `.AT2` record.
    At2 { path: PathBuf },
    /// A vendored real record by name ([`crate::ground_motions`], e.g. `loma-prieta-1989`).
    Named { name: String },
}

impl ExcitationSource {
    /// Default amplitude scale of the source: 3.0 for El Centro and the Kanai–Tajimi record
    /// (whose default PGA is El Centro's), 1.0 otherwise (SPEC §2).
    pub fn default_scale(&self) -> f64 {
        match self {
            ExcitationSource::ElCentro | ExcitationSource::KanaiTajimi { .. } => {
                excitation::EL_CENTRO_SCALE
            }
            _ => 1.0,
        }
    }
}

/// Everything that defines a data set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetConfig {
    /// Preset name ([`Preset::NAMES`]).
    pub preset: String,
    /// Storey count override (same per-storey values).
    pub storeys: Option<usize>,
    /// 1-based storeys with a Bouc–Wen element (each with the preset element's β, γ, n);
    /// `None`: the preset's (storey 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hysteretic: Option<Vec<usize>>,
    /// 1-based measured storeys; `None`: every storey.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensors: Option<Vec<usize>>,
    pub excitation: ExcitationSource,
    /// Amplitude scale applied to the excitation.
    pub scale: f64,
    /// Duration (s); `None` keeps the whole record (31.18 s for synthetic inputs).
    pub duration: Option<f64>,
    /// Time step of the data (s).
    pub dt: f64,
    /// Noise s.d. as a fraction of the RMS of each clean signal (0.1 in SPEC §2).
    pub noise_fraction: f64,
    pub measurement: MeasurementKind,
    pub seed: u64,
    pub run: u64,
    /// Mass-proportional damping α of the true structure (the storey+mass damping form,
    /// `crate::structure::Damping`), besides the preset's per-storey dashpots; `None`: the
    /// preset's per-storey damping alone (nothing recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass_damping: Option<f64>,
}

impl DatasetConfig {
    /// The preset's default data set (SPEC §2) for `seed`, run 0.
    pub fn from_preset(preset: &str, seed: u64) -> Result<Self, PresetError> {
        let p = Preset::from_name(preset, None)?;
        let (excitation, scale, duration) = match p.excitation {
            crate::preset::DefaultExcitation::ElCentro { scale } => {
                (ExcitationSource::ElCentro, scale, None)
            }
            crate::preset::DefaultExcitation::Harmonic {
                amplitude,
                omega,
                duration,
            } => (
                ExcitationSource::Harmonic { amplitude, omega },
                1.0,
                Some(duration),
            ),
        };
        Ok(Self {
            preset: preset.to_string(),
            storeys: None,
            hysteretic: None,
            sensors: None,
            excitation,
            scale,
            duration,
            dt: p.dt,
            noise_fraction: 0.1,
            measurement: MeasurementKind::Relative,
            seed,
            run: 0,
            mass_damping: None,
        })
    }
}

impl DatasetConfig {
    /// The preset with the storey count and hysteretic storeys of this config.
    fn preset_structure(&self) -> Result<Preset, DatasetError> {
        let mut p = Preset::from_name(&self.preset, self.storeys)?;
        if let Some(h) = &self.hysteretic {
            let masses = p.chain.masses().to_vec();
            let building =
                Building::from_one_based(masses, h, Damping::Storey).map_err(described)?;
            p.set_hysteretic(building.hysteretic())?;
        }
        Ok(p)
    }

    /// The true structure this config generates (SPEC §1): the preset's values for its storey
    /// count, Bouc–Wen elements at the hysteretic storeys, and mass-proportional damping when
    /// [`DatasetConfig::mass_damping`] is given.
    pub fn chain(&self) -> Result<ShearChain, DatasetError> {
        let chain = self.preset_structure()?.chain;
        match self.mass_damping {
            None => Ok(chain),
            Some(a) => chain
                .with_mass_damping(a)
                .map_err(|e| DatasetError::InvalidConfig {
                    field: "mass_damping",
                    message: e.to_string(),
                }),
        }
    }

    /// The structure as `dataset.json` records it: masses, hysteretic storeys, measured storeys
    /// and measurement kind.
    pub fn description(&self) -> Result<StructureDescription, DatasetError> {
        let chain = self.chain()?;
        let n = chain.storeys();
        let sensors = self.sensors.clone().unwrap_or_else(|| (1..=n).collect());
        let d = StructureDescription::of(chain.building(), sensors, self.measurement);
        d.sensor_layout().map_err(described)?;
        Ok(d)
    }
}

/// A building error as a config error naming the same field.
fn described(e: BuildingError) -> DatasetError {
    DatasetError::InvalidConfig {
        field: e.field,
        message: e.message,
    }
}

/// RMS values of the clean signals over the whole record (SPEC §3 uses them for R and Q).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RmsValues {
    /// Per measured acceleration channel, in header order (relative or absolute as measured).
    pub acc: Vec<f64>,
    /// Clean ground acceleration.
    pub ug: f64,
    /// Per-storey relative velocity.
    pub vel: Vec<f64>,
    /// Per-storey relative displacement.
    pub disp: Vec<f64>,
    /// Per Bouc–Wen element hysteretic variable r.
    pub r: Vec<f64>,
}

/// Standard deviations of the added noises.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseLevels {
    pub fraction: f64,
    /// Per acceleration channel.
    pub acc_sd: Vec<f64>,
    /// Excitation.
    pub ug_sd: f64,
}

/// The content of `dataset.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetMeta {
    pub config: DatasetConfig,
    pub dt: f64,
    pub samples: usize,
    /// Number of storeys N (measured or not).
    pub storeys: usize,
    /// The structure: masses, hysteretic and measured storeys, measurement kind (absent in data
    /// sets written before it was recorded: then the preset's, every storey measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub structure: Option<StructureDescription>,
    /// 0-based element indices of the Bouc–Wen elements.
    pub bouc_wen_storeys: Vec<usize>,
    pub theta_names: Vec<String>,
    pub theta_true: Vec<f64>,
    pub state_names: Vec<String>,
    pub noise: NoiseLevels,
    pub rms: RmsValues,
    /// Per Bouc–Wen element: `max |r|` and its saturation bound (when β+γ > 0).
    pub max_abs_r: Vec<f64>,
    pub saturation: Vec<Option<f64>>,
    pub seed: u64,
    pub run: u64,
}

impl DatasetMeta {
    /// The structure of the data set: as recorded, or for data sets written before it was
    /// recorded, the one their config generates (every storey measured).
    pub fn structure(&self) -> Result<StructureDescription, DatasetError> {
        match &self.structure {
            Some(d) => Ok(d.clone()),
            None => self.config.description(),
        }
    }

    /// The true structure with θ_true (for the validation run).
    pub fn true_chain(&self) -> Result<ShearChain, DatasetError> {
        self.config
            .chain()?
            .with_theta(&self.theta_true)
            .map_err(|e| invalid("theta_true", e.to_string()))
    }
}

/// A generated data set.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    pub config: DatasetConfig,
    pub chain: ShearChain,
    /// The measured storeys and what they measure.
    pub sensors: SensorLayout,
    pub dt: f64,
    pub t: Vec<f64>,
    pub ug_clean: Vec<f64>,
    pub ug_meas: Vec<f64>,
    /// Clean accelerations, row-major `K × channels` (one channel per measured storey).
    pub y_clean: Vec<f64>,
    /// Measured accelerations, row-major `K × channels`.
    pub y_meas: Vec<f64>,
    /// True states at every sample (RK4, clean excitation).
    pub truth: Trajectory,
    pub theta_true: Vec<f64>,
    pub theta_names: Vec<String>,
    pub state_names: Vec<String>,
    pub rms: RmsValues,
    pub noise: NoiseLevels,
}

/// Failures of generation, writing or loading. File-level errors name the file, the line and
/// the field.
#[derive(Debug, Error)]
pub enum DatasetError {
    #[error(transparent)]
    Preset(#[from] PresetError),
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error("invalid dataset config: field `{field}`: {message}")]
    InvalidConfig {
        field: &'static str,
        message: String,
    },
    #[error("the simulated response is not finite at t = {t} (unstable structure or input?)")]
    NonFinite { t: f64 },
    #[error(
        "the simulated response reaches {} at t = {t} s, beyond the limit ±{} on data values \
         (unstable structure or input?)",
        limits::num(*.value),
        limits::num(limits::MAX_ABS_VALUE)
    )]
    Unbounded { t: f64, value: f64 },
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}:{column}: {}", crate::readers::clipped(.message))]
    Json {
        file: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{file}: cannot write (temporary copy {temp}): {source}")]
    Write {
        file: PathBuf,
        temp: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{dir}: {message}")]
    NotADataset { dir: PathBuf, message: String },
    #[error("{file}: {message}")]
    Checksum { file: PathBuf, message: String },
    #[error(
        "{file}:{line}: field `{}`: {}",
        crate::readers::quoted(.field),
        crate::readers::clipped(.message)
    )]
    Mismatch {
        file: PathBuf,
        line: usize,
        field: String,
        message: String,
    },
    /// A data set that [`load_dir`] would refuse, so it is not written.
    #[error("{dir}: not written: field `{field}`: {message} (the data set would not load back)")]
    NotWritable {
        dir: PathBuf,
        field: &'static str,
        message: String,
    },
}

fn invalid(field: &'static str, message: impl Into<String>) -> DatasetError {
    DatasetError::InvalidConfig {
        field,
        message: message.into(),
    }
}

/// The excitation of `config`, scaled, at `config.dt`, truncated to `config.duration`.
///
/// Every size is bounded before it is allocated: the synthetic records' length by
/// [`limits::samples_for_duration`], a user record by its reader, and its resampled length
/// again by [`limits::samples_for_duration`].
pub fn ground_motion(config: &DatasetConfig) -> Result<GroundMotion, DatasetError> {
    check_config(config)?;
    let full = config.duration.unwrap_or(HARMONIC_DURATION);
    let synthetic_len = || {
        limits::samples_for_duration(full, config.dt)
            .map_err(|e| invalid("duration", e.to_string()))
    };
    let raw = match &config.excitation {
        ExcitationSource::ElCentro => crate::ground_motions::el_centro(),
        ExcitationSource::KanaiTajimi { params } => {
            synthetic_len()?;
            check_kanai_tajimi(params)?;
            let mut rng = stream(config.seed, config.run, purpose::EXCITATION);
            excitation::kanai_tajimi(params, full, config.dt, &mut rng)
        }
        ExcitationSource::Harmonic { amplitude, omega } => {
            synthetic_len()?;
            for (field, v) in [("amplitude", *amplitude), ("omega", *omega)] {
                limits::check_range(v, -limits::MAX_ABS_VALUE, limits::MAX_ABS_VALUE)
                    .map_err(|e| invalid(field, e.to_string()))?;
            }
            excitation::harmonic(*amplitude, *omega, full, config.dt)
        }
        ExcitationSource::Csv { path, units } => readers::read_csv(path, *units)?,
        ExcitationSource::At2 { path } => readers::read_at2(path)?,
        ExcitationSource::Named { name } => crate::ground_motions::by_name(name)
            .ok_or_else(|| {
                invalid(
                    "excitation",
                    format!(
                        "no vendored record `{name}` (known: {})",
                        crate::ground_motions::names().join(", ")
                    ),
                )
            })?
            .ground_motion()?,
    };
    // The resampled record covers min(record, requested duration); bound its length first.
    let span = config
        .duration
        .map_or(raw.duration(), |d| d.min(raw.duration()));
    if span > 0.0 {
        limits::samples_for_duration(span, config.dt).map_err(|e| {
            invalid(
                "dt",
                format!(
                    "resampling the {:.6} s record at dt = {} s: {e}",
                    span, config.dt
                ),
            )
        })?;
    }
    let mut gm = raw.scaled(config.scale);
    if (gm.dt - config.dt).abs() > 1e-9 * config.dt {
        gm = gm.resample_linear(config.dt);
    } else {
        gm.dt = config.dt;
    }
    if let Some(d) = config.duration {
        gm = gm.truncated(d);
    }
    if gm.len() < 2 {
        return Err(invalid("duration", "the record has fewer than 2 samples"));
    }
    Ok(gm)
}

/// Checks every size and value of `config` against the [`limits`] (SPEC §2 ranges far
/// beyond any real use), before anything is allocated from them.
pub fn check_config(config: &DatasetConfig) -> Result<(), DatasetError> {
    limits::check_dt(config.dt).map_err(|e| invalid("dt", format!("{e} (s)")))?;
    if !(config.noise_fraction >= 0.0 && config.noise_fraction.is_finite()) {
        return Err(invalid(
            "noise_fraction",
            format!("{} is not a non-negative number", config.noise_fraction),
        ));
    }
    limits::check_noise_fraction(config.noise_fraction)
        .map_err(|e| invalid("noise_fraction", e.to_string()))?;
    limits::check_scale(config.scale).map_err(|e| invalid("scale", e.to_string()))?;
    if let Some(d) = config.duration {
        if !(d > 0.0 && d.is_finite()) {
            return Err(invalid(
                "duration",
                format!("{d} is not a positive duration"),
            ));
        }
        limits::samples_for_duration(d, config.dt)
            .map_err(|e| invalid("duration", format!("{e} (s)")))?;
    }
    if let Some(n) = config.storeys {
        limits::check_storeys(n).map_err(|e| invalid("storeys", e.to_string()))?;
    }
    if config.hysteretic.is_some() || config.sensors.is_some() {
        // The storey lists against the structure they describe (hysteretic storey > N, sensor
        // 0, duplicates, no sensor), each error naming its field.
        config.description()?;
    }
    Ok(())
}

fn check_kanai_tajimi(p: &KanaiTajimi) -> Result<(), DatasetError> {
    for (field, v) in [
        ("omega_g", p.omega_g),
        ("zeta_g", p.zeta_g),
        ("omega_f", p.omega_f),
        ("zeta_f", p.zeta_f),
        ("pga", p.pga),
    ] {
        limits::check_range(v, 0.0, limits::MAX_ABS_VALUE)
            .map_err(|e| invalid(field, e.to_string()))?;
    }
    Ok(())
}

/// Generates the data set of `config` (SPEC §2).
pub fn generate(config: &DatasetConfig) -> Result<Dataset, DatasetError> {
    check_config(config)?;
    let chain = config.chain()?;
    let sensors = config.description()?.sensor_layout().map_err(described)?;
    let gm = ground_motion(config)?;
    let dt = config.dt;
    let ug_clean = gm.acc;
    let kk = ug_clean.len();
    check_input(&chain, &ug_clean, dt)?;
    let truth = simulate_truth(&chain, &ug_clean, dt)?;
    let y_clean = clean_measurements(config, &chain, &sensors, &truth, &ug_clean);
    check_written_values(&truth, &y_clean, sensors.len(), dt)?;
    let rms_values = rms_of_signals(&chain, &truth, &y_clean, sensors.len(), &ug_clean);
    let f = config.noise_fraction;
    let noise = NoiseLevels {
        fraction: f,
        acc_sd: rms_values.acc.iter().map(|r| f * r).collect(),
        ug_sd: f * rms_values.ug,
    };
    let y_meas = with_measurement_noise(config, &y_clean, &noise.acc_sd);
    let ug_meas = with_excitation_noise(config, &ug_clean, noise.ug_sd);
    Ok(Dataset {
        config: config.clone(),
        dt,
        t: (0..kk).map(|k| k as f64 * dt).collect(),
        ug_clean,
        ug_meas,
        y_clean,
        y_meas,
        theta_true: chain.theta(),
        theta_names: chain.theta_names(),
        state_names: chain.state_names(),
        truth,
        chain,
        sensors,
        rms: rms_values,
        noise,
    })
}

/// The truth table (t, ug and the states), the widest one allocated, within the limits on
/// tables; and the input `ug_clean` within the limit on data values, since what is written
/// must load back.
fn check_input(chain: &ShearChain, ug_clean: &[f64], dt: f64) -> Result<(), DatasetError> {
    let kk = ug_clean.len();
    limits::check_table(kk, chain.dim() + 2).map_err(|e| {
        invalid(
            "duration",
            format!("{kk} samples × {} columns of truth: {e}", chain.dim() + 2),
        )
    })?;
    if let Some(k) = ug_clean
        .iter()
        .position(|u| limits::check_value(*u).is_err())
    {
        return Err(DatasetError::Unbounded {
            t: k as f64 * dt,
            value: ug_clean[k],
        });
    }
    Ok(())
}

/// The true response of `chain` to `ug_clean`, refused when it is not finite.
fn simulate_truth(
    chain: &ShearChain,
    ug_clean: &[f64],
    dt: f64,
) -> Result<Trajectory, DatasetError> {
    // Tall chains with stiffness-proportional damping have overdamped top modes too fast for
    // one RK4 step per sample (the 130-storey `building-chain` diverged at dt = 0.005 s): they
    // are integrated with the sub-steps that keep RK4 stable; every other chain with one.
    let truth = simulate_rk4_substeps(chain, ug_clean, dt, rk4_substeps(chain, dt));
    if let Some(k) = truth
        .rows()
        .position(|row| row.iter().any(|v| !v.is_finite()))
    {
        return Err(DatasetError::NonFinite { t: k as f64 * dt });
    }
    Ok(truth)
}

/// The noise-free measured channels, row-major (K × sensors): every storey's acceleration
/// from the truth, then the measured storeys' (absolute when the config says so).
fn clean_measurements(
    config: &DatasetConfig,
    chain: &ShearChain,
    sensors: &SensorLayout,
    truth: &Trajectory,
    ug_clean: &[f64],
) -> Vec<f64> {
    let n = chain.storeys();
    let m = sensors.len();
    let mut all = vec![0.0; n];
    let mut y_clean = vec![0.0; ug_clean.len() * m];
    for (k, row) in y_clean.chunks_exact_mut(m).enumerate() {
        chain.relative_accelerations(truth.state(k), ug_clean[k], &mut all);
        for (y, &s) in row.iter_mut().zip(sensors.storeys()) {
            *y = all[s];
            if config.measurement == MeasurementKind::Absolute {
                *y += ug_clean[k];
            }
        }
    }
    y_clean
}

/// What is written must load back: the first row of the truth or of the channels (`m` a row)
/// with a value beyond the limit on data values is refused, at its time.
fn check_written_values(
    truth: &Trajectory,
    y_clean: &[f64],
    m: usize,
    dt: f64,
) -> Result<(), DatasetError> {
    let beyond = |row: &[f64]| {
        row.iter()
            .copied()
            .find(|v| limits::check_value(*v).is_err())
    };
    let first_beyond = truth
        .rows()
        .zip(y_clean.chunks_exact(m))
        .enumerate()
        .find_map(|(k, (x, y))| beyond(x).or_else(|| beyond(y)).map(|v| (k, v)));
    if let Some((k, value)) = first_beyond {
        return Err(DatasetError::Unbounded {
            t: k as f64 * dt,
            value,
        });
    }
    Ok(())
}

/// RMS of column `j` of the row-major table `buf` of `cols` columns.
fn column_rms(buf: &[f64], cols: usize, j: usize) -> f64 {
    rms(&buf
        .iter()
        .skip(j)
        .step_by(cols)
        .copied()
        .collect::<Vec<_>>())
}

/// RMS of each noise-free signal: the channels (`m` of them), the input and, from the truth,
/// each storey's velocity and displacement and each Bouc–Wen element's `r`.
fn rms_of_signals(
    chain: &ShearChain,
    truth: &Trajectory,
    y_clean: &[f64],
    m: usize,
    ug_clean: &[f64],
) -> RmsValues {
    let n = chain.storeys();
    let d = chain.dim();
    RmsValues {
        acc: (0..m).map(|j| column_rms(y_clean, m, j)).collect(),
        ug: rms(ug_clean),
        vel: (0..n)
            .map(|j| column_rms(truth.as_flat(), d, n + j))
            .collect(),
        disp: (0..n).map(|j| column_rms(truth.as_flat(), d, j)).collect(),
        r: (2 * n..d)
            .map(|j| column_rms(truth.as_flat(), d, j))
            .collect(),
    }
}

/// The measured channels: `y_clean` plus Gaussian noise of s.d. `acc_sd` per channel, from the
/// measurement-noise stream of the config's seed and run.
fn with_measurement_noise(config: &DatasetConfig, y_clean: &[f64], acc_sd: &[f64]) -> Vec<f64> {
    let mut rng = stream(config.seed, config.run, purpose::MEASUREMENT_NOISE);
    let mut y_meas = y_clean.to_vec();
    for row in y_meas.chunks_exact_mut(acc_sd.len()) {
        for (y, sd) in row.iter_mut().zip(acc_sd) {
            let z: f64 = StandardNormal.sample(&mut rng);
            *y += sd * z;
        }
    }
    y_meas
}

/// The measured input: `ug_clean` plus Gaussian noise of s.d. `ug_sd`, from the
/// excitation-noise stream of the config's seed and run.
fn with_excitation_noise(config: &DatasetConfig, ug_clean: &[f64], ug_sd: f64) -> Vec<f64> {
    let mut rng = stream(config.seed, config.run, purpose::EXCITATION_NOISE);
    ug_clean
        .iter()
        .map(|u| {
            let z: f64 = StandardNormal.sample(&mut rng);
            u + ug_sd * z
        })
        .collect()
}

impl Dataset {
    /// Number of samples K (row 0 at t = 0 included).
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Number of acceleration channels (measured storeys).
    pub fn channels(&self) -> usize {
        self.sensors.len()
    }

    /// Measured accelerations at sample `k`.
    pub fn y(&self, k: usize) -> &[f64] {
        let n = self.channels();
        &self.y_meas[k * n..(k + 1) * n]
    }

    /// `max |r|` per Bouc–Wen element over the record.
    pub fn max_abs_r(&self) -> Vec<f64> {
        (0..self.chain.bouc_wen().len())
            .map(|e| {
                let i = self.chain.r_index(e);
                self.truth.rows().fold(0.0_f64, |m, s| m.max(s[i].abs()))
            })
            .collect()
    }

    /// The content of `dataset.json`.
    pub fn meta(&self) -> DatasetMeta {
        DatasetMeta {
            config: self.config.clone(),
            dt: self.dt,
            samples: self.len(),
            storeys: self.chain.storeys(),
            structure: Some(StructureDescription::of(
                self.chain.building(),
                self.sensors.one_based(),
                self.sensors.kind(),
            )),
            bouc_wen_storeys: self.chain.bouc_wen().iter().map(|b| b.storey).collect(),
            theta_names: self.theta_names.clone(),
            theta_true: self.theta_true.clone(),
            state_names: self.state_names.clone(),
            noise: self.noise.clone(),
            rms: self.rms.clone(),
            max_abs_r: self.max_abs_r(),
            saturation: (0..self.chain.bouc_wen().len())
                .map(|e| self.chain.saturation(e))
                .collect(),
            seed: self.config.seed,
            run: self.config.run,
        }
    }

    /// What [`load_dir`] returns for a directory written by [`Dataset::write_dir`].
    pub fn to_loaded(&self) -> LoadedDataset {
        LoadedDataset {
            dt: self.dt,
            t: self.t.clone(),
            ug_meas: self.ug_meas.clone(),
            y_meas: self.y_meas.clone(),
            channels: self.channels(),
            sensors: self.sensors.one_based(),
            truth: Some(LoadedTruth {
                ug_clean: self.ug_clean.clone(),
                states: self.truth.clone(),
                state_names: self.state_names.clone(),
            }),
            meta: Some(self.meta()),
        }
    }

    /// The text of `measured.csv`.
    fn measured_csv(&self) -> String {
        measured_csv_text(
            &self.t,
            &self.ug_meas,
            &self.y_meas,
            &self.sensors.channel_names(),
        )
    }

    /// The text of `truth.csv`.
    fn truth_csv(&self) -> String {
        let mut s = String::from("t,ug");
        for name in &self.state_names {
            write!(s, ",{name}").unwrap();
        }
        s.push('\n');
        for k in 0..self.len() {
            write!(s, "{},{}", Num(self.t[k]), Num(self.ug_clean[k])).unwrap();
            for &v in self.truth.state(k) {
                write!(s, ",{}", Num(v)).unwrap();
            }
            s.push('\n');
        }
        s
    }

    /// Writes `measured.csv`, `truth.csv` and `dataset.json` (which records the size and
    /// SHA-256 of both CSV files) as the directory `dir`.
    ///
    /// The directory is written under a temporary sibling name and renamed into place, so an
    /// interruption leaves either the previous data set or the new one, never a mix and never
    /// nothing (see [`replace`] for the one platform-dependent window). An existing `dir` is
    /// replaced only when it holds nothing but data-set files.
    pub fn write_dir(&self, dir: &Path) -> Result<(), DatasetError> {
        let staging = replace::stage(dir)?;
        match self.write_files(&staging) {
            Ok(()) => staging.commit(),
            Err(e) => {
                staging.abandon();
                Err(e)
            }
        }
    }

    fn write_files(&self, staging: &replace::Staging) -> Result<(), DatasetError> {
        let mut files = BTreeMap::new();
        for (name, text) in [(MEASURED, self.measured_csv()), (TRUTH, self.truth_csv())] {
            write_file(staging, name, text.as_bytes())?;
            files.insert(name.to_string(), FileDigest::of(text.as_bytes()));
        }
        let meta = MetaFile {
            meta: self.meta(),
            files: Some(files),
        };
        let json = serde_json::to_string_pretty(&meta).expect("meta is serialisable");
        write_file(staging, META, json.as_bytes())
    }
}

/// The text of `measured.csv`: header `t,ug,<names>`, then one row per sample; `y` is
/// row-major `t.len() × names.len()`. The one writer of the format, for simulated and imported
/// data alike.
pub(crate) fn measured_csv_text(t: &[f64], ug: &[f64], y: &[f64], names: &[String]) -> String {
    let m = names.len();
    let mut s = String::from("t,ug");
    for name in names {
        write!(s, ",{name}").unwrap();
    }
    s.push('\n');
    for k in 0..t.len() {
        write!(s, "{},{}", Num(t[k]), Num(ug[k])).unwrap();
        for &a in &y[k * m..(k + 1) * m] {
            write!(s, ",{}", Num(a)).unwrap();
        }
        s.push('\n');
    }
    s
}

/// Writes `files` (name, content) as the directory `dir` with the same staging as
/// [`Dataset::write_dir`]: an interruption leaves the previous directory or the new one.
pub(crate) fn write_staged(dir: &Path, files: &[(&str, &[u8])]) -> Result<(), DatasetError> {
    let staging = replace::stage(dir)?;
    let written = files
        .iter()
        .try_for_each(|(name, bytes)| write_file(&staging, name, bytes));
    match written {
        Ok(()) => staging.commit(),
        Err(e) => {
            staging.abandon();
            Err(e)
        }
    }
}

/// An `f64` written as the shortest decimal that parses back to the same bits: plain for
/// `1e-5 ≤ |v| < 1e16` and zero, in exponent form otherwise (plain `{}` would spell `1e-300`
/// with 300 zeros).
struct Num(f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a == 0.0 || (1e-5..1e16).contains(&a) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

/// File names inside a data-set directory.
pub const MEASURED: &str = "measured.csv";
pub(crate) const TRUTH: &str = "truth.csv";
pub const META: &str = "dataset.json";

/// Writes and flushes one file of a staged directory; errors name the real file.
fn write_file(staging: &replace::Staging, name: &str, bytes: &[u8]) -> Result<(), DatasetError> {
    let path = staging.dir.join(name);
    let io = |source| DatasetError::Write {
        file: staging.real(name),
        temp: path.clone(),
        source,
    };
    let mut f = std::fs::File::create(&path).map_err(io)?;
    f.write_all(bytes).map_err(io)?;
    f.sync_all().map_err(io)
}

/// The true states of a loaded directory (`truth.csv`).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedTruth {
    /// Clean excitation.
    pub ug_clean: Vec<f64>,
    pub states: Trajectory,
    pub state_names: Vec<String>,
}

/// A data-set directory as loaded: measured data always, truth and metadata when present
/// (field data has only `measured.csv`).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedDataset {
    pub dt: f64,
    pub t: Vec<f64>,
    pub ug_meas: Vec<f64>,
    /// Row-major `K × channels`.
    pub y_meas: Vec<f64>,
    pub channels: usize,
    /// 1-based measured storey of each channel, increasing (from the header of `measured.csv`).
    pub sensors: Vec<usize>,
    pub truth: Option<LoadedTruth>,
    pub meta: Option<DatasetMeta>,
}

impl LoadedDataset {
    /// The true structure with θ_true when `dataset.json` says what it is (`None` for field
    /// data): the structure of the validation run.
    pub fn true_chain(&self) -> Result<Option<ShearChain>, DatasetError> {
        self.meta.as_ref().map(DatasetMeta::true_chain).transpose()
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Measured accelerations at sample `k`.
    pub fn y(&self, k: usize) -> &[f64] {
        &self.y_meas[k * self.channels..(k + 1) * self.channels]
    }

    /// What [`load_dir`] would refuse in this data set's `measured.csv`: the field and why.
    fn check_writable(&self) -> Result<(), (&'static str, String)> {
        let k = self.len();
        if k < 2 {
            return Err(("t", format!("{k} samples, at least 2 are needed")));
        }
        if self.ug_meas.len() != k {
            return Err((
                "ug",
                format!("{} samples for {k} times", self.ug_meas.len()),
            ));
        }
        limits::check_table(k, self.channels + 2).map_err(|e| ("t", e.to_string()))?;
        if self.y_meas.len() != k * self.channels || self.sensors.len() != self.channels {
            return Err((
                "sensors",
                format!(
                    "{} sensors, {} channels and {} values for {k} samples",
                    self.sensors.len(),
                    self.channels,
                    self.y_meas.len()
                ),
            ));
        }
        if self.sensors.is_empty() {
            return Err(("sensors", "no measured storey".to_string()));
        }
        for (i, &s) in self.sensors.iter().enumerate() {
            if s == 0 || s > limits::MAX_STOREYS {
                return Err((
                    "sensors",
                    format!(
                        "storey {s} is not one of 1 to {} (storeys are numbered from 1)",
                        limits::MAX_STOREYS
                    ),
                ));
            }
            if i > 0 && s <= self.sensors[i - 1] {
                return Err(("sensors", format!("{:?} is not increasing", self.sensors)));
            }
        }
        Ok(())
    }

    /// Writes the measured data alone (`measured.csv`: `t,ug,a<s>...`, numbers that parse back
    /// to the same bits) as the directory `dir`, a field-data set that [`load_dir`] reads.
    /// Written under a temporary name and swapped into place like [`Dataset::write_dir`].
    ///
    /// Only what [`load_dir`] reads back is written: at least two samples, one to
    /// [`limits::MAX_STOREYS`] measured storeys numbered from 1 and increasing, none beyond
    /// [`limits::MAX_STOREYS`], one column per storey and the table within
    /// [`limits::check_table`]; anything else is refused before a file is touched.
    pub fn write_measured_dir(&self, dir: &Path) -> Result<(), DatasetError> {
        self.check_writable()
            .map_err(|(field, message)| DatasetError::NotWritable {
                dir: dir.to_path_buf(),
                field,
                message,
            })?;
        let mut s = String::from("t,ug");
        for storey in &self.sensors {
            write!(s, ",a{storey}").unwrap();
        }
        s.push('\n');
        for k in 0..self.len() {
            write!(s, "{},{}", Num(self.t[k]), Num(self.ug_meas[k])).unwrap();
            for &a in self.y(k) {
                write!(s, ",{}", Num(a)).unwrap();
            }
            s.push('\n');
        }
        let staging = replace::stage(dir)?;
        match write_file(&staging, MEASURED, s.as_bytes()) {
            Ok(()) => staging.commit(),
            Err(e) => {
                staging.abandon();
                Err(e)
            }
        }
    }
}

/// A parsed numeric table: column names from the header and row-major values, with the line
/// number of every row.
struct Table {
    names: Vec<String>,
    values: Vec<f64>,
    lines: Vec<usize>,
}

/// The bytes of a data file, after checking its size against `MAX_FILE_BYTES`. `Ok(None)`
/// when the file does not exist.
fn read_bytes(path: &Path) -> Result<Option<Vec<u8>>, DatasetError> {
    let io = |source| -> DatasetError {
        ReadError::Io {
            file: path.to_path_buf(),
            source,
        }
        .into()
    };
    match std::fs::metadata(path) {
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(e)),
    };
    Ok(Some(crate::readers::read_input(path)?))
}

/// `bytes` as UTF-8 text; the error names the file and the line of the first invalid byte.
fn utf8(path: &Path, bytes: Vec<u8>) -> Result<String, DatasetError> {
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count() + 1;
        DatasetError::Mismatch {
            file: path.to_path_buf(),
            line,
            field: "text".to_string(),
            message: format!("not valid UTF-8 (byte {at})"),
        }
    })
}

/// Parses a CSV table with a header and at most `max_columns` columns, within
/// [`limits::check_table`]. A leading byte-order mark is skipped.
fn parse_table(path: &Path, text: &str, max_columns: usize) -> Result<Table, DatasetError> {
    let mut lines = readers::strip_bom(text).lines().enumerate();
    let names: Vec<String> = match lines.next() {
        Some((_, h)) => h.split(',').map(|s| s.trim().to_string()).collect(),
        None => {
            return Err(ReadError::Empty {
                file: path.to_path_buf(),
                found: 0,
                needed: 2,
            }
            .into())
        }
    };
    if names.len() > max_columns {
        return Err(header_error(
            path,
            "header",
            format!(
                "{} columns, at most {max_columns} expected ({} storeys at most)",
                names.len(),
                limits::MAX_STOREYS
            ),
        ));
    }
    let mut values = Vec::new();
    let mut rows = Vec::new();
    for (i, l) in lines {
        let line = i + 1;
        if l.trim().is_empty() {
            continue;
        }
        if let Err(e) = limits::check_table(rows.len() + 1, names.len()) {
            return Err(readers::limit_error(path, line, &names[0], e).into());
        }
        let fields: Vec<&str> = l.split(',').collect();
        if fields.len() != names.len() {
            return Err(ReadError::ColumnCount {
                file: path.to_path_buf(),
                line,
                expected: names.len(),
                found: fields.len(),
            }
            .into());
        }
        for (j, (name, f)) in names.iter().zip(&fields).enumerate() {
            values.push(if j == 0 {
                readers::parse_time(path, line, name, f)?
            } else {
                parse_field(path, line, name, f)?
            });
        }
        rows.push(line);
    }
    if rows.len() < 2 {
        return Err(ReadError::Empty {
            file: path.to_path_buf(),
            found: rows.len(),
            needed: 2,
        }
        .into());
    }
    Ok(Table {
        names,
        values,
        lines: rows,
    })
}

impl Table {
    fn column(&self, j: usize) -> Vec<f64> {
        self.values
            .iter()
            .skip(j)
            .step_by(self.names.len())
            .copied()
            .collect()
    }
}

fn header_error(file: &Path, field: &str, message: String) -> DatasetError {
    ReadError::Header {
        file: file.to_path_buf(),
        line: 1,
        field: field.to_string(),
        message,
    }
    .into()
}

/// Reads and parses `dataset.json` (`Ok(None)` when absent).
fn read_meta(jpath: &Path) -> Result<Option<(MetaFile, String)>, DatasetError> {
    let Some(bytes) = read_bytes(jpath)? else {
        return Ok(None);
    };
    let text = utf8(jpath, bytes)?;
    let parsed: MetaFile =
        serde_json::from_str(readers::strip_bom(&text)).map_err(|e| DatasetError::Json {
            file: jpath.to_path_buf(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
    Ok(Some((parsed, text)))
}

/// Loads a data-set directory written by [`Dataset::write_dir`] (or by hand: only
/// `measured.csv` is required).
///
/// When `dataset.json` records the digests of the CSV files (data sets written by this
/// version), each file is checked against them before it is parsed, and a file that does not
/// belong is refused by name; older data sets (no digests) and field data (no `dataset.json`)
/// load unchecked. The metadata is checked against the data, the limits and the structure it
/// names.
pub fn load_dir(dir: &Path) -> Result<LoadedDataset, DatasetError> {
    let mpath = dir.join(MEASURED);
    let jpath = dir.join(META);
    let tpath = dir.join(TRUTH);
    let meta_file = read_meta(&jpath)?;
    let digests = meta_file.as_ref().and_then(|(m, _)| m.files.clone());

    let Some(mbytes) = read_bytes(&mpath)? else {
        return Err(measured_not_found(dir, mpath));
    };
    let tbytes = read_bytes(&tpath)?;
    if let Some(files) = &digests {
        verify_digests(
            dir,
            &jpath,
            files,
            [
                (MEASURED, Some(&mbytes), &mpath),
                (TRUTH, tbytes.as_ref(), &tpath),
            ],
        )?;
    }

    let measured = read_measured(&mpath, mbytes)?;
    let (t, sensors) = (measured.t, measured.sensors);
    let meta = match meta_file {
        Some((mf, text)) => {
            integrity::check_meta(&jpath, &text, &mf.meta, t.len(), &mpath, &sensors)?;
            Some(mf.meta)
        }
        None => None,
    };
    let dt = recorded_dt(jpath, meta.as_ref(), measured.dt_grid)?;

    let truth = match tbytes {
        Some(tbytes) => {
            let ttext = utf8(&tpath, tbytes)?;
            // t, ug, x, v and at most one r per storey.
            let tr = parse_table(&tpath, &ttext, 2 + 3 * limits::MAX_STOREYS)?;
            drop(ttext);
            let storeys = meta.as_ref().map(|m| m.storeys);
            Some(check_truth(&tpath, tr, &t, &sensors, storeys, dt)?)
        }
        None => None,
    };
    Ok(LoadedDataset {
        dt,
        t,
        ug_meas: measured.ug_meas,
        y_meas: measured.y_meas,
        channels: sensors.len(),
        sensors,
        truth,
        meta,
    })
}

/// The error for a missing `measured.csv` at `mpath`; when the directory itself is missing,
/// it points at the copy an interrupted write left aside, if any.
fn measured_not_found(dir: &Path, mpath: PathBuf) -> DatasetError {
    let mut message = "not found".to_string();
    if !dir.exists() {
        if let Some(aside) = replace::aside_copies(dir).last() {
            message = format!(
                "not found; an interrupted write left the previous data set at {}",
                aside.display()
            );
        }
    }
    ReadError::Io {
        file: mpath,
        source: std::io::Error::new(std::io::ErrorKind::NotFound, message),
    }
    .into()
}

/// Checks the data files (name, content if present, path) against the digests `files` that
/// `dataset.json` (`jpath`) records: a file it lists other than the data files, a recorded
/// file missing, an unrecorded one present or one with another digest is refused.
fn verify_digests(
    dir: &Path,
    jpath: &Path,
    files: &BTreeMap<String, FileDigest>,
    data: [(&str, Option<&Vec<u8>>, &PathBuf); 2],
) -> Result<(), DatasetError> {
    // Every file it lists is checked: a name other than the two data files is one this
    // reader would never open, so it is refused rather than passed over.
    if let Some(name) = files
        .keys()
        .find(|n| ![MEASURED, TRUTH].contains(&n.as_str()))
    {
        let path = dir.join(name);
        return Err(DatasetError::Checksum {
            message: format!(
                "listed in {} (`files`), but a data set holds only {MEASURED} and {TRUTH}{}",
                jpath.display(),
                if path.exists() {
                    ""
                } else {
                    "; it is missing too"
                }
            ),
            file: path,
        });
    }
    for (name, content, path) in data {
        match (files.get(name), content) {
            (Some(d), Some(c)) => integrity::verify(jpath, path, name, c, d)?,
            (Some(_), None) => {
                return Err(DatasetError::Checksum {
                    file: path.clone(),
                    message: format!("missing, but {} records it", jpath.display()),
                })
            }
            (None, Some(_)) => {
                return Err(DatasetError::Checksum {
                    file: path.clone(),
                    message: format!(
                        "not recorded in {}: it does not belong with this dataset.json",
                        jpath.display()
                    ),
                })
            }
            (None, None) => {}
        }
    }
    Ok(())
}

/// The content of `measured.csv`: the measured storeys its header names, the time column and
/// its uniform step, the input and the channels (row-major).
struct MeasuredTable {
    sensors: Vec<usize>,
    t: Vec<f64>,
    dt_grid: f64,
    ug_meas: Vec<f64>,
    y_meas: Vec<f64>,
}

/// Parses `measured.csv` (`mpath`, its bytes `mbytes`): header, uniform time grid, columns.
fn read_measured(mpath: &Path, mbytes: Vec<u8>) -> Result<MeasuredTable, DatasetError> {
    let mtext = utf8(mpath, mbytes)?;
    let m = parse_table(mpath, &mtext, 2 + limits::MAX_STOREYS)?;
    drop(mtext);
    let sensors = measured_storeys(mpath, &m.names)?;
    let t = m.column(0);
    let times: Vec<(usize, f64)> = m.lines.iter().copied().zip(t.iter().copied()).collect();
    let dt_grid = uniform_step(mpath, &times)?;
    let ug_meas = m.column(1);
    let w = m.names.len();
    let y_meas: Vec<f64> = m
        .values
        .chunks_exact(w)
        .flat_map(|row| row[2..].iter().copied())
        .collect();
    Ok(MeasuredTable {
        sensors,
        t,
        dt_grid,
        ug_meas,
        y_meas,
    })
}

/// The time step: the metadata's (it carries dt exactly; the grid estimate (t_last − t_0)/(K − 1)
/// may differ in the last bit), refused when it is not the grid's `dt_grid`; the grid's when
/// there is no metadata.
fn recorded_dt(
    jpath: PathBuf,
    meta: Option<&DatasetMeta>,
    dt_grid: f64,
) -> Result<f64, DatasetError> {
    match meta {
        Some(meta) => {
            if (meta.dt - dt_grid).abs() > 1e-6 * meta.dt {
                return Err(DatasetError::Mismatch {
                    file: jpath,
                    line: 1,
                    field: "dt".to_string(),
                    message: format!("dt = {} but {MEASURED} has dt = {dt_grid}", meta.dt),
                });
            }
            Ok(meta.dt)
        }
        None => Ok(dt_grid),
    }
}

/// The 1-based measured storeys named by the header of `measured.csv`: `t,ug,a<s>...` with at
/// least one channel, each `a<s>` spelled with its storey number `s ≥ 1`, increasing. Errors
/// name the file and the column.
fn measured_storeys(path: &Path, names: &[String]) -> Result<Vec<usize>, DatasetError> {
    let rule = "the header is `t,ug` then one column `a<s>` per measured storey s (1-based, \
                increasing), e.g. `t,ug,a1,a3,a5`";
    for (j, want) in ["t", "ug"].into_iter().enumerate() {
        if names.get(j).map(String::as_str) != Some(want) {
            let found = names.get(j).map_or("", String::as_str);
            return Err(header_error(
                path,
                if found.is_empty() { want } else { found },
                format!("column {} must be `{want}`: {rule}", j + 1),
            ));
        }
    }
    if names.len() < 3 {
        return Err(header_error(
            path,
            "header",
            format!("no acceleration column: {rule}"),
        ));
    }
    let mut storeys: Vec<usize> = Vec::with_capacity(names.len() - 2);
    for name in &names[2..] {
        let s = name
            .strip_prefix('a')
            .and_then(|d| d.parse::<usize>().ok())
            .filter(|s| format!("a{s}") == *name)
            .ok_or_else(|| header_error(path, name, format!("not a channel name: {rule}")))?;
        if s == 0 {
            return Err(header_error(
                path,
                name,
                "storey 0 does not exist (storeys are numbered from 1)".to_string(),
            ));
        }
        if s > limits::MAX_STOREYS {
            return Err(header_error(
                path,
                name,
                format!(
                    "storey {s} is beyond the {} storeys a building may have",
                    limits::MAX_STOREYS
                ),
            ));
        }
        if storeys.contains(&s) {
            return Err(header_error(
                path,
                name,
                format!("storey {s} is measured twice"),
            ));
        }
        if let Some(&before) = storeys.last() {
            if s < before {
                return Err(header_error(
                    path,
                    name,
                    format!("columns must be in increasing storey order (a{s} after a{before})"),
                ));
            }
        }
        storeys.push(s);
    }
    Ok(storeys)
}

/// Checks the header and the times of `truth.csv` against `measured.csv`.
///
/// `truth.csv` holds every storey: N is `storeys` (from `dataset.json`) or, for data without
/// metadata, the number of `x` columns; every measured storey must be one of them.
fn check_truth(
    tpath: &Path,
    tr: Table,
    t: &[f64],
    sensors: &[usize],
    storeys: Option<usize>,
    dt: f64,
) -> Result<LoadedTruth, DatasetError> {
    let w = tr.names.len();
    let channels = storeys.unwrap_or_else(|| {
        tr.names
            .iter()
            .skip(2)
            .take_while(|n| n.starts_with('x'))
            .count()
    });
    if let Some(&top) = sensors.iter().find(|&&s| s > channels) {
        return Err(header_error(
            tpath,
            "header",
            format!(
                "{channels} storeys, but {MEASURED} has a column a{top} (storey {top}): \
                 truth.csv must hold every storey"
            ),
        ));
    }
    if channels == 0 || w < 2 + 2 * channels || tr.names[0] != "t" || tr.names[1] != "ug" {
        return Err(header_error(
            tpath,
            "header",
            format!(
                "expected `t,ug,x1..x{channels},v1..v{channels},r...`, found `{}`",
                tr.names.join(",")
            ),
        ));
    }
    for j in 0..channels {
        for (off, p) in [(2, "x"), (2 + channels, "v")] {
            let want = format!("{p}{}", j + 1);
            if tr.names[off + j] != want {
                return Err(header_error(
                    tpath,
                    &tr.names[off + j],
                    format!("expected column `{want}`"),
                ));
            }
        }
    }
    if let Some(bad) = tr.names[2 + 2 * channels..]
        .iter()
        .find(|n| !n.starts_with('r'))
    {
        return Err(header_error(
            tpath,
            bad,
            "expected a Bouc–Wen column `r<storey>`".to_string(),
        ));
    }
    let tt = tr.column(0);
    if tt.len() != t.len() {
        return Err(DatasetError::Mismatch {
            file: tpath.to_path_buf(),
            line: *tr.lines.last().unwrap_or(&1),
            field: "t".to_string(),
            message: format!("{} rows, {MEASURED} has {}", tt.len(), t.len()),
        });
    }
    if let Some(k) = (0..t.len()).find(|&k| (tt[k] - t[k]).abs() > 1e-9 * dt) {
        return Err(DatasetError::Mismatch {
            file: tpath.to_path_buf(),
            line: tr.lines[k],
            field: "t".to_string(),
            message: format!("t = {} but {MEASURED} has t = {}", tt[k], t[k]),
        });
    }
    let states: Vec<f64> = tr
        .values
        .chunks_exact(w)
        .flat_map(|row| row[2..].iter().copied())
        .collect();
    Ok(LoadedTruth {
        ug_clean: tr.column(1),
        states: Trajectory::from_flat(w - 2, dt, states),
        state_names: tr.names[2..].to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_and_short_generation() {
        let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
        assert_eq!(c.scale, 3.0);
        assert_eq!(c.excitation, ExcitationSource::ElCentro);
        c.duration = Some(2.0);
        let d = generate(&c).unwrap();
        assert_eq!(d.len(), 401);
        assert_eq!(d.truth.dim(), 7);
        assert_eq!(d.y_meas.len(), 401 * 3);
        assert_eq!(d.theta_true, vec![8., 8., 8., 0.25, 0.25, 0.25, 2., 1., 2.]);
        let h = DatasetConfig::from_preset("paper-3dof-harmonic", 1).unwrap();
        assert_eq!(h.duration, Some(31.18));
        c.noise_fraction = -1.0;
        assert!(matches!(
            generate(&c),
            Err(DatasetError::InvalidConfig {
                field: "noise_fraction",
                ..
            })
        ));
    }

    #[test]
    fn numbers_are_short_and_round_trip() {
        for v in [
            0.0,
            -0.0,
            0.005,
            -1.9307402050781252e-7,
            1e-300,
            -5e-324,
            f64::MAX,
            1e15 + 0.5,
            1e16,
            -1.2345678901234567e-300,
        ] {
            let s = Num(v).to_string();
            assert!(s.len() <= 24, "{s}");
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
        // So the largest table (24 characters and a separator a number) fits in the largest
        // file the readers accept.
        assert!((limits::MAX_CELLS as u64) * 25 < limits::MAX_FILE_BYTES);
        assert_eq!(Num(0.005).to_string(), "0.005");
        assert_eq!(Num(1e-300).to_string(), "1e-300");
    }

    #[test]
    fn a_response_beyond_the_value_limit_is_an_error() {
        let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
        c.excitation = ExcitationSource::Harmonic {
            amplitude: 1e11,
            omega: 4.0,
        };
        c.duration = Some(1.0);
        c.scale = 100.0;
        assert!(matches!(generate(&c), Err(DatasetError::Unbounded { .. })));
    }

    #[test]
    fn absolute_measurement_adds_the_excitation() {
        let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
        c.duration = Some(1.0);
        let rel = generate(&c).unwrap();
        c.measurement = MeasurementKind::Absolute;
        let abs = generate(&c).unwrap();
        for k in 0..rel.len() {
            for j in 0..3 {
                let want = rel.y_clean[3 * k + j] + rel.ug_clean[k];
                assert!((abs.y_clean[3 * k + j] - want).abs() < 1e-12);
            }
        }
    }

    fn noises(d: &Dataset) -> (Vec<Vec<f64>>, Vec<f64>) {
        let n = d.channels();
        let acc = (0..n)
            .map(|j| {
                (0..d.len())
                    .map(|k| d.y_meas[k * n + j] - d.y_clean[k * n + j])
                    .collect()
            })
            .collect();
        let ug = d
            .ug_meas
            .iter()
            .zip(&d.ug_clean)
            .map(|(m, c)| m - c)
            .collect();
        (acc, ug)
    }

    fn corr(a: &[f64], b: &[f64]) -> f64 {
        let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>();
        dot(a, b) / (dot(a, a) * dot(b, b)).sqrt()
    }

    #[test]
    fn same_seed_same_data_and_streams_are_separate() {
        let c = DatasetConfig::from_preset("paper-3dof", 5).unwrap();
        let a = generate(&c).unwrap();
        assert_eq!(a, generate(&c).unwrap());
        let mut c2 = c.clone();
        c2.seed = 6;
        let b = generate(&c2).unwrap();
        assert_eq!(a.truth, b.truth, "the truth does not depend on the seed");
        assert_ne!(a.y_meas, b.y_meas);
        let mut c3 = c.clone();
        c3.run = 1;
        assert_ne!(a.ug_meas, generate(&c3).unwrap().ug_meas);
        // Switching the measurement kind changes the clean channels, not the excitation noise
        // stream: the measured excitation is identical.
        let mut c4 = c.clone();
        c4.measurement = MeasurementKind::Absolute;
        assert_eq!(a.ug_meas, generate(&c4).unwrap().ug_meas);
    }

    #[test]
    fn noise_levels_and_independence() {
        // K = 6237 samples. The sample s.d. of K Gaussian draws has relative standard error
        // 1/sqrt(2K) = 0.009; a sample correlation of independent series has standard error
        // 1/sqrt(K) = 0.0127. Both are checked at 4 standard errors.
        let d = generate(&DatasetConfig::from_preset("paper-3dof", 9).unwrap()).unwrap();
        let kk = d.len() as f64;
        let (acc, ug) = noises(&d);
        let se_sd = 1.0 / (2.0 * kk).sqrt();
        let se_r = 1.0 / kk.sqrt();
        for (j, e) in acc.iter().enumerate() {
            let want = 0.1 * d.rms.acc[j];
            assert_eq!(d.noise.acc_sd[j], want);
            let ratio = rms(e) / want;
            assert!((ratio - 1.0).abs() < 4.0 * se_sd, "channel {j}: {ratio}");
            let r = corr(e, &ug);
            assert!(r.abs() < 4.0 * se_r, "channel {j} vs excitation noise: {r}");
        }
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let r = corr(&acc[i], &acc[j]);
            assert!(r.abs() < 4.0 * se_r, "channels {i}, {j}: {r}");
        }
        let ratio = rms(&ug) / (0.1 * d.rms.ug);
        assert!((ratio - 1.0).abs() < 4.0 * se_sd, "excitation: {ratio}");
        // RMS of the clean signals as defined (SPEC §2).
        assert_eq!(d.rms.ug, rms(&d.ug_clean));
        assert!((d.rms.vel[0] - rms(&d.truth.component(3))).abs() < 1e-15);
    }
}
