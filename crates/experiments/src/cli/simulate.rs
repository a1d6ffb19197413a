//! `sysid simulate`: simulate a structure under an excitation and write a data-set directory
//! (`measured.csv`, `truth.csv`, `dataset.json`; SPEC §2).
//!
//! Every flag is checked against `models::limits` before anything is generated, and the
//! directory is written under a temporary name and swapped into place
//! ([`models::dataset::Dataset::write_dir`]): an interrupted `simulate` leaves the previous data
//! set or the new one, never a mix.

use anyhow::{bail, Context};
use models::dataset::{self, DatasetConfig, ExcitationSource, MeasurementKind};
use models::excitation::KanaiTajimi;
use models::limits;
use models::preset::{HARMONIC_AMPLITUDE, HARMONIC_OMEGA};
use models::readers::Units;
use std::path::PathBuf;

/// Units of a CSV excitation record.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum UnitsArg {
    /// Multiples of g = 9.81 m/s².
    G,
    /// m/s².
    #[value(name = "m/s2")]
    Ms2,
}

/// Arguments of `sysid simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Structure preset: paper-3dof, paper-3dof-harmonic or shear-chain.
    #[arg(long, default_value = "paper-3dof")]
    pub preset: String,
    /// Master seed of the random streams.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index (selects independent noise streams for the same seed).
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Output directory: a new directory, or an existing data set to replace.
    #[arg(long)]
    pub out: PathBuf,
    /// Excitation: elcentro, kanai-tajimi, harmonic, a vendored real record by name
    /// (el-centro-1940, loma-prieta-1989, … : see data/ground_motions/PROVENANCE.md), or a path to
    /// a `.csv` (`t,acc`) or `.AT2` record. Default: the preset's own.
    #[arg(long)]
    pub excitation: Option<String>,
    /// Units of a CSV record.
    #[arg(long, value_enum, default_value = "g")]
    pub units: UnitsArg,
    /// Amplitude scale (default: 3.0 for El Centro and Kanai–Tajimi, 1.0 otherwise).
    #[arg(long)]
    pub scale: Option<f64>,
    /// Duration in seconds (default: the whole record, 31.18 s for synthetic inputs).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Number of storeys (same per-storey values as the preset).
    #[arg(long)]
    pub storeys: Option<usize>,
    /// Storeys with a Bouc–Wen element, 1-based and increasing, e.g. `1,4` (each with the
    /// preset's β = 2, γ = 1, n = 2), or `none` for a linear building. Default: storey 1.
    #[arg(long)]
    pub hysteretic: Option<String>,
    /// Measured storeys, 1-based and increasing, e.g. `1,3,5`. Default: every storey.
    #[arg(long)]
    pub sensors: Option<String>,
    /// Measure absolute accelerations ẍ + ü_g instead of relative ones.
    #[arg(long)]
    pub absolute: bool,
    /// Noise s.d. as a fraction of each clean signal's RMS.
    #[arg(long, default_value_t = 0.1)]
    pub noise_fraction: f64,
}

fn excitation_source(arg: &str, units: UnitsArg) -> ExcitationSource {
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
            units: match units {
                UnitsArg::G => Units::G,
                UnitsArg::Ms2 => Units::MetersPerSecond2,
            },
        },
    }
}

/// Parses a comma list of 1-based storeys (`1,4`); `none` (when allowed) is the empty list.
/// Errors name the flag.
pub fn parse_storeys(flag: &str, s: &str, allow_none: bool) -> anyhow::Result<Vec<usize>> {
    if allow_none && s.trim() == "none" {
        return Ok(Vec::new());
    }
    s.split(',')
        .map(|part| {
            let part = part.trim();
            part.parse::<usize>().map_err(|_| {
                anyhow::anyhow!(
                    "{flag}: `{part}` is not a storey number (a comma list of storeys numbered \
                     from 1, e.g. 1,4{})",
                    if allow_none { ", or none" } else { "" }
                )
            })
        })
        .collect()
}

/// Checks the flags a user gives against the limits; errors name the flag.
fn check_flags(args: &Args) -> anyhow::Result<()> {
    if let Some(n) = args.storeys {
        limits::check_storeys(n).context("--storeys")?;
    }
    if let Some(s) = args.scale {
        limits::check_scale(s).context("--scale")?;
    }
    limits::check_noise_fraction(args.noise_fraction).context("--noise-fraction")?;
    if let Some(d) = args.duration {
        if !(d > 0.0 && d.is_finite()) {
            bail!("--duration: {d} is not a positive number of seconds");
        }
    }
    Ok(())
}

/// The data-set configuration the flags of `sysid simulate` describe (everything but `--out`),
/// checked against the limits; errors name the flag. The Python package's `simulate` uses it
/// too, so that both accept and refuse the same settings with the same messages.
pub fn dataset_config(args: &Args) -> anyhow::Result<DatasetConfig> {
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
            bail!("--{field}: {message}");
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
        limits::samples_for_duration(d, config.dt)
            .with_context(|| format!("--duration at dt = {} s", config.dt))?;
    }
    Ok(config)
}

/// Runs `sysid simulate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = dataset_config(&args)?;
    let ds = dataset::generate(&config)?;
    ds.write_dir(&args.out)
        .with_context(|| format!("writing the data set to {}", args.out.display()))?;
    let meta = ds.meta();
    let r_summary: Vec<String> = meta
        .max_abs_r
        .iter()
        .zip(&meta.saturation)
        .zip(&meta.bouc_wen_storeys)
        .map(|((m, s), st)| match s {
            Some(s) => format!("max|r{}|/sat = {:.3}", st + 1, m / s),
            None => format!("max|r{}| = {:.4}", st + 1, m),
        })
        .collect();
    let acc: Vec<String> = ds
        .sensors
        .channel_names()
        .iter()
        .zip(&ds.rms.acc)
        .map(|(c, a)| format!("{c} {a:.4}"))
        .collect();
    println!(
        "{}: {} storeys, {} accelerations at storeys {:?}; {} samples, dt = {} s, {:.2} s; {}; \
         RMS ug = {:.4}, acc = [{}] m/s²",
        args.out.display(),
        ds.chain.storeys(),
        ds.sensors.kind(),
        ds.sensors.one_based(),
        ds.len(),
        ds.dt,
        ds.t.last().copied().unwrap_or(0.0),
        if r_summary.is_empty() {
            "linear (no Bouc–Wen element)".to_string()
        } else {
            r_summary.join(", ")
        },
        ds.rms.ug,
        acc.join(", ")
    );
    Ok(())
}
