//! `sysid filter`: one identification run on a data-set directory, written as a run record.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use core_filters::resampling::Scheme;
use core_filters::smc::storvik::StorvikUpdate;
use models::dataset::{load_dir, MEASURED, META};
use models::sensors::MeasurementKind;

use crate::checks;
use crate::cli::simulate::parse_storeys;
use crate::field::{self, StructureSettings};
use crate::pipeline::{identify, Algorithm, FilterSettings, RunInput};
use crate::record::RunRecord;
use crate::sweep::write_atomic;

/// Arguments of `sysid filter`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Algorithm: bootstrap, mln-rbpf, storvik or mpf-ekf2.
    #[arg(long)]
    pub algorithm: Algorithm,
    /// Data-set directory as written by `sysid simulate` (`measured.csv`; `truth.csv` and
    /// `dataset.json` optional).
    #[arg(long)]
    pub data: PathBuf,
    /// Number of particles (default 500, or the config file's value).
    #[arg(long)]
    pub particles: Option<usize>,
    /// Master seed of the filter's random stream.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run index (with the seed, selects the filter's stream).
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Where to write the run record (JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Resampling scheme: systematic, stratified, multinomial or residual.
    #[arg(long)]
    pub resampling: Option<Scheme>,
    /// Resample only when ESS < threshold × particles (default without --config: 0.5; with a
    /// config file: its value, or every step).
    #[arg(long)]
    pub ess_threshold: Option<f64>,
    /// Storvik's update of step (iii): linearised (the paper's) or exact.
    #[arg(long, value_parser = parse_storvik)]
    pub storvik_update: Option<StorvikUpdate>,
    /// Discretisation of the equations of motion inside the filter: euler (the paper's),
    /// symplectic (semi-implicit Euler: velocities first), or rk4 (bootstrap PF only).
    #[arg(long)]
    pub discretisation: Option<models::filtering::Discretisation>,
    /// TOML file with filter settings (priors, noise fraction, masses, …) over the SPEC's (the
    /// paper's) defaults; command-line options override it. Without it: the recommended
    /// settings of docs/calibration.md.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Fix parameters at values, e.g. `k1=8,n=2`.
    #[arg(long)]
    pub fix: Option<String>,
    /// Experiment name written into the record.
    #[arg(long, default_value = "cli")]
    pub experiment: String,
    /// Field data (no dataset.json): number of storeys N.
    #[arg(long)]
    pub storeys: Option<usize>,
    /// Field data: 1-based storeys with a Bouc–Wen element, e.g. `1,4`, or `none`.
    #[arg(long)]
    pub hysteretic: Option<String>,
    /// Field data: storey masses `m1,...,mN`, or one value for every storey.
    #[arg(long)]
    pub masses: Option<String>,
    /// Field data: what the accelerometers record, absolute (ẍ + ü_g, real accelerometers) or
    /// relative (ẍ).
    #[arg(long)]
    pub measurement: Option<MeasurementKind>,
}

/// The structure flags as a `[structure]` table; errors name the flag.
fn structure_flags(args: &Args) -> Result<StructureSettings> {
    let masses = match &args.masses {
        Some(m) => Some(
            m.split(',')
                .map(|part| {
                    let part = part.trim();
                    part.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite() && *v > 0.0)
                        .with_context(|| {
                            format!("--masses: `{part}` is not a positive mass (a comma list m1,...,mN, or one value)")
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
    })
}

/// A flag's name for a key of the `[structure]` table.
fn flag_name(key: &str) -> String {
    format!("--{key}")
}

fn parse_storvik(s: &str) -> Result<StorvikUpdate, String> {
    match s {
        "linearised" | "linearized" => Ok(StorvikUpdate::Linearised),
        "exact" => Ok(StorvikUpdate::Exact),
        _ => Err(format!(
            "unknown Storvik update `{s}` (expected linearised or exact)"
        )),
    }
}

/// Parses `name=value,name=value`.
pub fn parse_fix(s: &str) -> Result<BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (name, value) = part
            .split_once('=')
            .with_context(|| format!("--fix: `{part}` is not of the form name=value"))?;
        let v: f64 = value
            .trim()
            .parse()
            .with_context(|| format!("--fix: value `{value}` of {name} is not a number"))?;
        if !v.is_finite() {
            bail!("--fix: value of {name} is not finite");
        }
        out.insert(name.trim().to_string(), v);
    }
    Ok(out)
}

/// Runs `sysid filter`.
pub fn run(args: Args) -> Result<()> {
    let mut settings = match &args.config {
        Some(path) => crate::limits::load_filter_settings(path)?,
        None => FilterSettings::recommended(),
    };
    if let Some(p) = args.particles {
        settings.particles = p;
    }
    if let Some(r) = args.resampling {
        settings.resampling = r;
    }
    if args.ess_threshold.is_some() {
        settings.ess_threshold = args.ess_threshold;
    }
    if let Some(d) = args.discretisation {
        settings.discretisation = d;
    }
    if let Some(u) = args.storvik_update {
        settings.storvik_update = u;
    }
    if let Some(f) = &args.fix {
        settings.fix.extend(parse_fix(f)?);
    }
    let flags = structure_flags(&args)?;
    let data = load_dir(&args.data)
        .with_context(|| format!("loading data set {}", args.data.display()))?;
    let measured = args.data.join(MEASURED);
    let config_name = args
        .config
        .as_ref()
        .map_or_else(String::new, |p| p.display().to_string());
    let table_name = |key: &str| format!("[structure] `{key}` in {config_name}");
    let both_name = |key: &str| format!("{} (or {})", flag_name(key), field::table_key(key));
    if data.meta.is_some() {
        // Simulated data carry their structure: a stated key must agree with it.
        field::resolve(&data, None, &flags, &measured, &flag_name)?;
        field::resolve(&data, None, &settings.structure, &measured, &table_name)?;
        settings.structure = StructureSettings::default();
    } else {
        // Field data: flags over the config table; refused by name when incomplete.
        settings.structure.overlay(&flags);
        let d = field::resolve(&data, None, &settings.structure, &measured, &both_name)?;
        eprintln!(
            "field data: {} storeys, masses {:?}, hysteretic storeys {:?}, {} accelerations at storeys {:?} (no {META})",
            d.storeys, d.masses, d.hysteretic, d.measurement, d.sensors
        );
    }
    // The true structure, for the validation run, when the data set says what it is.
    let chain = match &data.meta {
        Some(meta) => Some(
            meta.true_chain()
                .context("rebuilding the data set's structure")?,
        ),
        None => None,
    };
    let input = RunInput {
        data: &data,
        chain: chain.as_ref(),
        experiment: &args.experiment,
        seed: args.seed,
        run: args.run,
        progress: true,
    };
    let record = identify(&input, args.algorithm, &settings)?;
    finish(record, &args.out)
}

/// Attaches the plausibility warnings (`checks::check`) to a finished run, writes its record,
/// prints the summary table on stdout and the warnings on stderr, and returns an error — a
/// non-zero exit of `sysid filter` — when the run failed or its answer is physically impossible.
/// The record is written in every case.
pub fn finish(mut record: RunRecord, out: &Path) -> Result<()> {
    record.warnings = checks::check(&record);
    write_atomic(out, &record)?;
    eprintln!(
        "{}: {} of {} steps, loglik {:.2}, {:.2} s ({:.2} M particle-steps/s); record {}",
        record.algorithm,
        record.steps_completed,
        record.steps_total,
        record.loglik,
        record.timing.wall_s,
        record.timing.particle_steps_per_s / 1e6,
        out.display()
    );
    print!("{}", checks::summary_table(&record));
    for w in &record.warnings {
        eprintln!("warning: {}", w.message);
    }
    if let Some(f) = &record.failure {
        bail!(
            "the run failed at step {} of {}: {f} (record written to {})",
            record.steps_completed + 1,
            record.steps_total,
            out.display()
        );
    }
    if checks::is_fatal(&record.warnings) {
        let params: Vec<&str> = record
            .warnings
            .iter()
            .filter(|w| w.kind.is_fatal())
            .filter_map(|w| w.parameter.as_deref())
            .collect();
        bail!(
            "the result is physically impossible ({}): not an identification to use (record with its warnings written to {})",
            params.join(", "),
            out.display()
        );
    }
    Ok(())
}
