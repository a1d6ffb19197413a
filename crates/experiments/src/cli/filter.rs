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

/// Arguments of `sysid filter`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Algorithm: bootstrap, mln-rbpf, storvik or mpf-ekf2.
    #[arg(long, required_unless_present = "print_config")]
    pub algorithm: Option<Algorithm>,
    /// Data-set directory as written by `sysid simulate` (`measured.csv`; `truth.csv` and
    /// `dataset.json` optional).
    #[arg(long, required_unless_present = "print_config")]
    pub data: Option<PathBuf>,
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
    #[arg(long, required_unless_present = "print_config")]
    pub out: Option<PathBuf>,
    /// Also draw the run's figures into this directory (as `sysid plot RECORD --out DIR`).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Print every key of a `--config` file with its default and meaning, and exit.
    #[arg(long)]
    pub print_config: bool,
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
    /// Transitions inside the filter per sample interval (MPF-EKF2 and bootstrap PF), for data
    /// sampled coarsely relative to the structure's highest modes; measured effect in
    /// docs/scaling.md. Default 1.
    #[arg(long)]
    pub substeps: Option<usize>,
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
    /// Damping form of the model: storey (per-storey dashpots c1..cN, the default) or
    /// storey+mass (also mass-proportional damping αM, θ gains `alpha` after c1..cN; MPF-EKF2
    /// and bootstrap PF). Data with dataset.json must agree with the form they record.
    #[arg(long, value_parser = parse_damping)]
    pub damping: Option<models::structure::Damping>,
}

fn parse_damping(s: &str) -> Result<models::structure::Damping, String> {
    s.parse()
        .map_err(|e: models::structure::UnknownDamping| e.to_string())
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
        damping: args.damping,
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
        if out.insert(name.trim().to_string(), v).is_some() {
            bail!("--fix: {} is given twice", name.trim());
        }
    }
    Ok(out)
}

/// Every key of a filter config (`--config`) with the value `sysid filter` uses without a config
/// ([`FilterSettings::recommended`]) and its meaning, as a TOML file that parses back to those
/// settings: `--print-config > f.toml` then `--config f.toml` runs exactly what no config runs.
pub fn commented_defaults() -> String {
    let d = FilterSettings::recommended();
    let paper = FilterSettings::default();
    let q = |v: &dyn erased::Show| v.show();
    format!(
        r#"# Filter settings of `sysid filter --config FILE.toml` (and the [filter] table of a study).
# Shown with the values `sysid filter` uses without --config (the recommended settings, whose
# interval coverage is measured in docs/calibration.md). A key absent from a file takes the
# paper's value instead (ess_threshold absent, pool = 1, discretisation = "{paper_disc}").
# Command-line options override the file.

# Number of particles Np (SPEC §3).
particles = {particles}
# Resampling scheme: "systematic", "stratified", "multinomial" or "residual".
resampling = {resampling}
# Resample only when ESS < ess_threshold × particles, in (0, 1]; absent: every step (SPEC §3).
ess_threshold = {ess}
# Independent filters pooled into one run (the particles split between them); θ_val is their
# mean and its Monte-Carlo s.e. is reported (docs/calibration.md). 1: one filter (the paper's).
pool = {pool}
# Storvik's step (iii): "linearised" (the paper's) or "exact".
storvik_update = {storvik}
# Noise fraction nf: R and Q are set from nf × RMS of the signals (SPEC §3).
noise_fraction = {nf}
# Discretisation inside the filters: "euler" (the paper's), "symplectic", "rk4" (bootstrap only).
discretisation = {disc}
# Transitions inside the filter per sample interval (dt/substeps each, ü_g interpolated), for
# data sampled coarsely relative to the structure's highest modes (measured effect:
# docs/scaling.md); MPF-EKF2 and bootstrap PF only.
substeps = {substeps}
# θ_val averages the posterior mean over the last `window` steps (SPEC eq. 26).
window = {window}
# Keep one trace step in `trace_every` in the record (0: no trace).
trace_every = {trace}
# Run the validation integration with θ_val when the truth is known (SPEC §7).
validate = {validate}
# Keep one hysteresis-loop point in `loop_every` in the record (0: no loops).
loop_every = {loops}
# Gaussian prior of the marginalised block: {{ kind = "moment_matched" }} (one moment-matched
# Gaussian) or {{ kind = "per_particle", rel_sd = 0.1 }} (means drawn per particle).
marginal_prior = {{ kind = "moment_matched" }}

# Point-mass priors: parameter name = value (k1..kN, c1..cN, alpha with the storey+mass damping
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
# k = [{{ kind = "log_normal", median = 10.0, log_sd = 0.3 }}, ...]
# c = [{{ kind = "log_normal", median = 0.4, log_sd = 0.5 }}, ...]
# alpha = {{ kind = "log_normal", median = 0.5, log_sd = 1.0 }}  (storey+mass damping only)
# elements = [{{ storey = 0, beta_gamma = {{ kind = "triangle", beta_max = 5.0 }}, n = {{ kind = "uniform", lo = 1.0, hi = 5.0 }} }}]
"#,
        paper_disc = paper.discretisation.name(),
        ess = q(&d
            .ess_threshold
            .expect("the recommended settings resample on the ESS")),
        pool = d.pool,
        particles = d.particles,
        resampling = q(&d.resampling),
        storvik = q(&d.storvik_update),
        nf = q(&d.noise_fraction),
        disc = q(&d.discretisation),
        substeps = d.substeps,
        window = d.window,
        trace = d.trace_every,
        validate = d.validate,
        loops = d.loop_every,
    )
}

/// A value as TOML writes it (through serde, so the printed defaults are the real ones).
mod erased {
    pub trait Show {
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

/// Runs `sysid filter`.
pub fn run(args: Args) -> Result<()> {
    if args.print_config {
        print!("{}", commented_defaults());
        return Ok(());
    }
    let (Some(algorithm), Some(data_dir), Some(out)) =
        (args.algorithm, args.data.clone(), args.out.clone())
    else {
        bail!("--algorithm, --data and --out are required");
    };
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
    if let Some(m) = args.substeps {
        settings.substeps = m;
    }
    if let Some(u) = args.storvik_update {
        settings.storvik_update = u;
    }
    if let Some(f) = &args.fix {
        settings.fix.extend(parse_fix(f)?);
    }
    let flags = structure_flags(&args)?;
    let data =
        load_dir(&data_dir).with_context(|| format!("loading data set {}", data_dir.display()))?;
    let measured = data_dir.join(MEASURED);
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
            "field data: {} storeys, masses {:?}, hysteretic storeys {:?}, {} accelerations at storeys {:?}, {} damping (no {META})",
            d.storeys, d.masses, d.hysteretic, d.measurement, d.sensors, d.damping
        );
    }
    // The true structure, for the validation run, when the data set says what it is.
    let chain = data
        .true_chain()
        .context("rebuilding the data set's structure")?;
    let input = RunInput {
        data: &data,
        chain: chain.as_ref(),
        experiment: &args.experiment,
        seed: args.seed,
        run: args.run,
        progress: true,
        residuals: true,
    };
    if let Some(p) = crate::pipeline::prior_from_data(&data, chain.as_ref(), &settings)? {
        eprintln!("{}", p.describe());
    }
    let mut record = identify(&input, algorithm, &settings)?;
    if data.meta.is_none() {
        // Field data: validation without the truth (free run, modes; docs/validation.md).
        let d = field::resolve_for_run(&data, chain.as_ref(), &settings.structure)?;
        crate::validation::attach(&mut record, &data, &d);
    }
    if data.meta.is_none() {
        // Field data: the noise levels were chosen from the measured signals (SPEC §3); say which.
        let spec = &record.config["spec"];
        let sd = |v: &serde_json::Value| -> String {
            let items: Vec<String> = v
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|x| x.as_f64())
                        .map(|x| format!("{:.3e}", x.sqrt()))
                        .collect()
                })
                .unwrap_or_default();
            items.join(", ")
        };
        let num =
            |v: &serde_json::Value| v.as_f64().map_or("?".to_string(), |x| format!("{x:.3e}"));
        let list = |v: &serde_json::Value| -> String {
            let items: Vec<String> = v
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|x| x.as_f64())
                        .map(|x| format!("{x:.3e}"))
                        .collect()
                })
                .unwrap_or_default();
            items.join(", ")
        };
        eprintln!(
            "noise levels from the data (noise fraction {}): measurement s.d. [{}] m/s², process s.d. x {}, v {}, r [{}] (recorded under config.spec)",
            settings.noise_fraction,
            sd(&spec["r_diag"]),
            num(&spec["q_disp"]),
            num(&spec["q_vel"]),
            list(&spec["q_r"]),
        );
    }
    let outcome = finish(record, &out);
    // The figures of a failed or implausible run are drawn too: they show what went wrong.
    if let Some(dir) = &args.plot {
        let drawn = crate::figures::run::plot(&out, dir)?;
        for note in &drawn.skipped {
            eprintln!("note: {note}");
        }
        eprintln!("{} figures in {}", drawn.written.len(), dir.display());
    }
    outcome
}

/// Attaches the plausibility warnings (`checks::check`) to a finished run, writes its record,
/// prints the summary table on stdout and the warnings on stderr, and returns an error — a
/// non-zero exit of `sysid filter` — when the run failed or its answer is physically impossible.
/// The record is written in every case.
pub fn finish(mut record: RunRecord, out: &Path) -> Result<()> {
    record.warnings = checks::check(&record);
    // Written, then read back by the reader every command uses: a record `plot` or
    // `compare-reference` would refuse is an error here, not a success.
    crate::record::read::write(out, &record)?;
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
    print!(
        "{}",
        crate::validation::summary(record.free_run.as_ref(), record.modal.as_ref())
    );
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
