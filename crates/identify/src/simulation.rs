//! The data set a simulation request describes (the flags of `sysid simulate`, and the Python
//! package's `simulate`): a preset, an excitation, the building's storeys and sensors, checked
//! against `models::limits` before anything is generated.

use models::dataset::{self, DatasetConfig, ExcitationSource, MeasurementKind};
use models::excitation::KanaiTajimi;
use models::limits::{self, LimitError};
use models::preset::{PresetError, HARMONIC_AMPLITUDE, HARMONIC_OMEGA};
use models::readers::Units;
use std::path::PathBuf;

/// Why a simulation request is refused; every message names the flag of `sysid simulate`.
#[derive(Debug, thiserror::Error)]
pub enum SimulationError {
    /// A value outside its limits (`flag` names it, the source says why).
    #[error("{flag}")]
    Limit {
        flag: String,
        #[source]
        source: LimitError,
    },
    /// An entry of a storey list that is no storey number.
    #[error(
        "{flag}: `{part}` is not a storey number (a comma list of storeys numbered from 1, e.g. \
         1,4{})",
        if *allow_none { ", or none" } else { "" }
    )]
    NotAStorey {
        flag: String,
        part: String,
        allow_none: bool,
    },
    /// A duration that is not a positive number of seconds.
    #[error("--duration: {0} is not a positive number of seconds")]
    Duration(f64),
    /// A storey list that does not fit the building (`--hysteretic`, `--sensors`).
    #[error("--{flag}: {message}")]
    StoreyList { flag: String, message: String },
    #[error(transparent)]
    Preset(#[from] PresetError),
}

crate::error::domain_error!(SimulationError);

/// What to simulate: every flag of `sysid simulate` but `--out`.
#[derive(Debug, Clone)]
pub struct SimulationRequest {
    /// Structure preset: paper-3dof, paper-3dof-harmonic, shear-chain (the paper's storey values, any --storeys) or building-chain (k = 2000 per storey, the scaling study's buildings: docs/scaling.md)
    pub preset: String,
    /// Master seed of the random streams.
    pub seed: u64,
    /// Run index (selects independent noise streams for the same seed).
    pub run: u64,
    /// Excitation: elcentro, kanai-tajimi, harmonic, a vendored record's name, or a path to a
    /// `.csv` (`t,acc`) or `.AT2` record; `None`: the preset's own.
    pub excitation: Option<String>,
    /// Units of a CSV record.
    pub units: Units,
    /// Amplitude scale (default: the excitation's).
    pub scale: Option<f64>,
    /// Duration in seconds (default: the whole record).
    pub duration: Option<f64>,
    /// Number of storeys.
    pub storeys: Option<usize>,
    /// Storeys with a Bouc–Wen element as text (`1,4` or `none`).
    pub hysteretic: Option<String>,
    /// Measured storeys as text (`1,3,5`).
    pub sensors: Option<String>,
    /// Measure absolute accelerations ẍ + ü_g instead of relative ones.
    pub absolute: bool,
    /// Noise s.d. as a fraction of each clean signal's RMS.
    pub noise_fraction: f64,
}

fn excitation_source(arg: &str, units: Units) -> ExcitationSource {
    match arg {
        "elcentro" | "el-centro" => ExcitationSource::ElCentro,
        "kanai-tajimi" => ExcitationSource::KanaiTajimi {
            params: KanaiTajimi::default(),
        },
        "harmonic" => ExcitationSource::Harmonic {
            amplitude: HARMONIC_AMPLITUDE,
            omega: HARMONIC_OMEGA,
        },
        name if models::ground_motions::by_name(name).is_some() => ExcitationSource::Named {
            name: name.to_string(),
        },
        path if path.to_ascii_lowercase().ends_with(".at2") => ExcitationSource::At2 {
            path: PathBuf::from(path),
        },
        path => ExcitationSource::Csv {
            path: PathBuf::from(path),
            units,
        },
    }
}

/// Parses a comma list of 1-based storeys (`1,4`); `none` (when allowed) is the empty list.
/// Errors name the flag.
pub(crate) fn parse_storeys(
    flag: &str,
    s: &str,
    allow_none: bool,
) -> Result<Vec<usize>, SimulationError> {
    if allow_none && s.trim() == "none" {
        return Ok(Vec::new());
    }
    s.split(',')
        .map(|part| {
            let part = part.trim();
            part.parse::<usize>()
                .map_err(|_| SimulationError::NotAStorey {
                    flag: flag.to_string(),
                    part: part.to_string(),
                    allow_none,
                })
        })
        .collect()
}

/// Checks the flags a user gives against the limits; errors name the flag.
fn check_flags(args: &SimulationRequest) -> Result<(), SimulationError> {
    let flag = |flag: &str| {
        let flag = flag.to_string();
        move |source| SimulationError::Limit { flag, source }
    };
    if let Some(n) = args.storeys {
        limits::check_storeys(n).map_err(flag("--storeys"))?;
    }
    if let Some(s) = args.scale {
        limits::check_scale(s).map_err(flag("--scale"))?;
    }
    limits::check_noise_fraction(args.noise_fraction).map_err(flag("--noise-fraction"))?;
    if let Some(d) = args.duration {
        if !(d > 0.0 && d.is_finite()) {
            return Err(SimulationError::Duration(d));
        }
    }
    Ok(())
}

/// The data-set configuration a request describes, checked against the limits; errors name the
/// flag of `sysid simulate`. The Python package's `simulate` uses it too, so that both accept and
/// refuse the same settings with the same messages.
pub fn dataset_config(args: &SimulationRequest) -> Result<DatasetConfig, SimulationError> {
    check_flags(args)?;
    let mut config = DatasetConfig::from_preset(&args.preset, args.seed)?;
    config.run = args.run;
    config.storeys = args.storeys;
    if let Some(h) = &args.hysteretic {
        config.hysteretic = Some(parse_storeys("--hysteretic", h, true)?);
    }
    if let Some(s) = &args.sensors {
        config.sensors = Some(parse_storeys("--sensors", s, false)?);
    }
    // The storey lists against the building, each error naming its flag.
    if let Err(models::dataset::DatasetError::InvalidConfig { field, message }) =
        dataset::check_config(&config)
    {
        if field == "hysteretic" || field == "sensors" {
            return Err(SimulationError::StoreyList {
                flag: field.to_string(),
                message,
            });
        }
    }
    config.noise_fraction = args.noise_fraction;
    if let Some(e) = &args.excitation {
        config.excitation = excitation_source(e, args.units);
        config.scale = config.excitation.default_scale();
        if !matches!(config.excitation, ExcitationSource::Harmonic { .. }) {
            config.duration = None;
        }
    }
    if let Some(s) = args.scale {
        config.scale = s;
    }
    if args.duration.is_some() {
        config.duration = args.duration;
    }
    if args.absolute {
        config.measurement = MeasurementKind::Absolute;
    }
    if let Some(d) = config.duration {
        limits::samples_for_duration(d, config.dt).map_err(|source| SimulationError::Limit {
            flag: format!("--duration at dt = {} s", config.dt),
            source,
        })?;
    }
    Ok(config)
}
