//! `sysid filter`: one identification run on a data-set directory, written as a run record.

use std::path::{Path, PathBuf};

use crate::console::Console;
use crate::error::{bail, Result};
use core_filters::resampling::Scheme;
use core_filters::smc::storvik::StorvikUpdate;
use models::sensors::MeasurementKind;

use identify::identification::{
    commented_defaults, finish, identify_plan, load_request_data, plan_request, FilterRequest,
};
use identify::pipeline::Algorithm;
use identify::plan::RunPlan;
use identify::record::RunRecord;

/// Arguments of `sysid filter`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Algorithm: bootstrap, mln-rbpf, storvik or mpf-ekf2.
    #[arg(long, required_unless_present_any = ["print_config", "plan"])]
    pub algorithm: Option<Algorithm>,
    /// Data-set directory as written by `sysid simulate` (`measured.csv`; `truth.csv` and
    /// `dataset.json` optional).
    #[arg(long, required_unless_present = "print_config")]
    pub data: Option<PathBuf>,
    #[arg(long, help = identify::rules::help_particles())]
    pub particles: Option<usize>,
    /// Master seed of the filter's random stream (default 1).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Run index (with the seed, selects the filter's stream; default 0).
    #[arg(long)]
    pub run: Option<u64>,
    #[arg(long, help = identify::rules::help_threads())]
    pub threads: Option<usize>,
    /// Where to write the run record (JSON).
    #[arg(long, required_unless_present_any = ["print_config", "plan_only", "print_plan"])]
    pub out: Option<PathBuf>,
    /// Settle the run's plan — building, prior, noise levels, particles and pooling, sub-steps,
    /// rejuvenation, seeds, and every choice a default rule made with its reason — print it,
    /// and exit without running.
    #[arg(long, conflicts_with_all = ["print_plan", "plan"])]
    pub plan_only: bool,
    /// Settle the run's plan and print it as TOML (for `--plan FILE`), and exit without running.
    #[arg(long, conflicts_with = "plan")]
    pub print_plan: bool,
    /// Run exactly the plan in this TOML file (as `--print-plan` writes it) on `--data`, the
    /// data it was settled on: its record equals the record of the run it was printed for. The
    /// options that settle a plan (algorithm, particles, config, structure, …) are refused
    /// beside it.
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "algorithm", "particles", "seed", "run", "resampling", "ess_threshold", "storvik_update",
        "discretisation", "substeps", "rejuvenation", "config", "fix", "experiment", "storeys",
        "hysteretic", "masses", "measurement", "damping", "noise_fraction",
        "process_noise_factor", "coloured_noise", "learn_noise",
    ])]
    pub plan: Option<PathBuf>,
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
    #[arg(long, help = identify::rules::help_substeps())]
    pub substeps: Option<identify::settings::Substeps>,
    #[arg(long, value_name = "DELTA", help = identify::rules::help_rejuvenation())]
    pub rejuvenation: Option<f64>,
    /// TOML file with filter settings (priors, noise fraction, masses, …) over the SPEC's (the
    /// paper's) defaults; command-line options override it. Without it: the recommended
    /// settings of docs/calibration.md.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Fix parameters at values, e.g. `k1=8,n=2`.
    #[arg(long)]
    pub fix: Option<String>,
    /// Noise fraction nf: the measurement noise s.d. nf × RMS of each channel, the velocities'
    /// process noise dt × nf × RMS ü_g (SPEC §3). Without --config the default is 0.1; on field
    /// data of a linear building it is chosen by held-out prediction (docs/validation.md) unless
    /// given here; for a particle run (hysteretic storeys, or another filter), on its linear
    /// counterpart under the MPF-EKF2, then taken only if the particle run itself predicts the
    /// held-out part better with it (two partial particle runs).
    #[arg(long)]
    pub noise_fraction: Option<f64>,
    /// The velocities' process noise relative to SPEC §3's (1: the SPEC's). Chosen with the
    /// noise fraction on field data of a linear building unless given here.
    #[arg(long)]
    pub process_noise_factor: Option<f64>,
    /// Coloured measurement noise `RHO,SHARE` (MPF-EKF2): the part SHARE (in (0, 1)) of each
    /// channel's measurement variance is an AR(1) sequence with coefficient RHO (in [0, 1)) per
    /// sample interval, one more state per channel in the filter's Gaussian part, so that
    /// prediction errors correlated in time go into it rather than into the parameters
    /// (docs/validation.md, "Coloured measurement noise"). Default: white noise only.
    #[arg(long, value_name = "RHO,SHARE", value_parser = parse_coloured_noise)]
    pub coloured_noise: Option<models::filtering::ColouredNoise>,
    /// Learn each channel's measurement noise s.d. by maximum likelihood once the plan is
    /// settled (θ integrated out by the filter, the settled level the prior's median; each
    /// level with a 95 % interval; the process noise as settled), and run with it. A run that
    /// is one Gaussian filter only (the MPF-EKF2 on a linear building). Not the
    /// default: on real records it predicts the free run worse than the noise chosen on
    /// held-out data (docs/validation.md, "Noise learned by maximum likelihood").
    #[arg(long)]
    pub learn_noise: bool,
    /// Experiment name written into the record (default `cli`).
    #[arg(long)]
    pub experiment: Option<String>,
    /// Field data (no dataset.json): number of storeys N.
    #[arg(long)]
    pub storeys: Option<usize>,
    /// Field data: 1-based storeys with a Bouc–Wen element, e.g. `1,4`, or `none`.
    #[arg(long)]
    pub hysteretic: Option<String>,
    /// Field data: storey masses `m1,...,mN`, or one value for every storey. Approximate: m1
    /// sets the scale, and where the noise levels are chosen on held-out data (a linear
    /// building, no config) with a sensor on every storey, the ratios m_j/m1 are identified by
    /// the likelihood and taken when they predict every floor of the held-out part better
    /// (docs/validation.md).
    #[arg(long)]
    pub masses: Option<String>,
    /// Field data: what the accelerometers record, absolute (ẍ + ü_g, real accelerometers) or
    /// relative (ẍ).
    #[arg(long)]
    pub measurement: Option<MeasurementKind>,
    /// Damping form of the model: storey (per-storey dashpots c1..cN, the default) or
    /// storey+mass (also mass-proportional damping αM, θ gains `alpha` after c1..cN; MPF-EKF2
    /// and bootstrap PF). Data with dataset.json must agree with the form they record. Left
    /// open on field data where the noise is chosen on held-out data, the choice tries both
    /// forms on two or more storeys; one storey keeps storey (its dashpot and the mass term act
    /// on the same velocity: only c1/m1 + alpha is identified).
    #[arg(long, value_parser = parse_damping)]
    pub damping: Option<models::structure::Damping>,
}

fn parse_damping(s: &str) -> Result<models::structure::Damping, String> {
    s.parse()
        .map_err(|e: models::structure::UnknownDamping| e.to_string())
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

/// `RHO,SHARE` of `--coloured-noise`, each checked for its range.
fn parse_coloured_noise(s: &str) -> Result<models::filtering::ColouredNoise, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [rho, share] = parts[..] else {
        return Err(format!("`{s}` is not RHO,SHARE (e.g. 0.97,0.8)"));
    };
    let number = |name: &str, v: &str| {
        v.parse::<f64>()
            .map_err(|_| format!("{name} `{v}` is not a number"))
    };
    let c = models::filtering::ColouredNoise {
        rho: number("RHO", rho)?,
        share: number("SHARE", share)?,
    };
    c.validate().map_err(|e| e.to_string())?;
    Ok(c)
}

/// Runs `sysid filter`, its text to `con`.
pub fn run(args: Args, con: &mut Console) -> Result<()> {
    if args.print_config {
        write!(con.out(), "{}", commented_defaults())?;
        return Ok(());
    }
    let Some(data_dir) = args.data.clone() else {
        bail!("--data is required");
    };
    let (data, chain) = load_request_data(&data_dir)?;
    // `--threads` holds the whole run to its pool: the held-out choice of the plan scores its
    // candidates side by side, as the pooled filters run.
    let pool = match args.threads {
        Some(n) if n == 0 || n > 1024 => bail!("--threads {n}: give 1 to 1024 threads"),
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| crate::error::invalid!("--threads {n}: {e}"))?,
        ),
        None => None,
    };
    let on_threads = |f: &(dyn Fn() -> Result<RunPlan> + Sync)| match &pool {
        Some(p) => p.install(f),
        None => f(),
    };
    let started = std::time::Instant::now();
    let plan = match &args.plan {
        Some(file) => {
            let name = file.display().to_string();
            let text = identify::limits::read_text_file(file, "run plan")?;
            let plan = RunPlan::from_toml(&text, &name)?;
            plan.check_data(&data, &name)?;
            plan
        }
        None => {
            let Some(algorithm) = args.algorithm else {
                bail!("--algorithm is required (or --plan FILE)");
            };
            let asked = request(&args, algorithm, data_dir.clone());
            on_threads(&|| plan_request(&asked, &data, chain.as_ref()))?
        }
    };
    // The time it took to settle the plan (its choices identify on their own), for the record;
    // none for a plan given whole.
    let plan_s = args.plan.is_none().then(|| started.elapsed().as_secs_f64());
    if args.plan_only {
        write!(con.out(), "{}", plan.describe())?;
        return Ok(());
    }
    if args.print_plan {
        write!(con.out(), "{}", plan.to_toml()?)?;
        return Ok(());
    }
    let Some(out) = args.out.clone() else {
        bail!("--out is required");
    };
    // Refused before the run, not after it: an output that is not a regular file, or is one
    // of the run's inputs.
    let mut inputs: Vec<(&str, &Path)> = vec![("--data", &data_dir)];
    for (flag, file) in [("--config", &args.config), ("--plan", &args.plan)] {
        if let Some(f) = file {
            inputs.push((flag, f));
        }
    }
    identify::record::atomic::check_output(&out, "--out", &inputs)?;
    for d in &plan.decisions {
        writeln!(con.err(), "{d}")?;
    }
    let steps = data.len().saturating_sub(1);
    let shown = Shown::new(&plan, steps, steps as f64 * data.dt, con.terminal());
    let progress = |done, total| shown.tell(done, total);
    let run = || identify_plan(&plan, &data, chain.as_ref(), &|| false, Some(&progress));
    let identified = match &pool {
        Some(p) => p.install(run),
        None => run(),
    };
    shown.finish();
    let mut identified = identified?;
    identified.record.timing.plan_s = plan_s;
    if let Some(noise) = &identified.noise {
        writeln!(con.err(), "{noise}")?;
    }
    let outcome = report(identified.record, &out, con);
    // The figures of a failed or implausible run are drawn too: they show what went wrong.
    if let Some(dir) = &args.plot {
        let drawn = identify::plot::plot(&out, dir)?;
        for note in &drawn.skipped {
            writeln!(con.err(), "note: {note}")?;
        }
        writeln!(
            con.err(),
            "{} figures in {}",
            drawn.written.len(),
            dir.display()
        )?;
    }
    outcome
}

/// How far a run is, shown to a person: a bar on a terminal, otherwise the pace of a long run
/// ([`crate::pace`]: after 10 s and every minute). Counted over every pooled filter, from 0 to
/// steps × filters.
struct Shown {
    bar: Option<indicatif::ProgressBar>,
    pace: std::sync::Mutex<crate::pace::Pace>,
}

impl Shown {
    fn new(plan: &RunPlan, steps: usize, record_s: f64, terminal: bool) -> Self {
        let total = steps * plan.settings.pool.max(1);
        let label = plan.algorithm.name();
        let bar = terminal.then(|| {
            let bar = indicatif::ProgressBar::new(total as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{prefix:>10} [{bar:30}] {pos}/{len} steps, ETA {eta}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar.set_prefix(label);
            bar
        });
        let pace = crate::pace::Pace::new(label, total, record_s);
        Self {
            bar,
            pace: std::sync::Mutex::new(pace),
        }
    }

    fn tell(&self, done: usize, _total: usize) {
        match &self.bar {
            Some(bar) => bar.set_position(done as u64),
            None => self
                .pace
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .step(done),
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// The request the flags make.
fn request(args: &Args, algorithm: Algorithm, data: PathBuf) -> FilterRequest {
    FilterRequest {
        algorithm,
        data,
        config: args.config.clone(),
        particles: args.particles,
        resampling: args.resampling,
        ess_threshold: args.ess_threshold,
        storvik_update: args.storvik_update,
        discretisation: args.discretisation,
        substeps: args.substeps,
        rejuvenation: args.rejuvenation,
        fix: args.fix.clone(),
        noise_fraction: args.noise_fraction,
        process_noise_factor: args.process_noise_factor,
        coloured_noise: args.coloured_noise,
        learn_noise: args.learn_noise,
        experiment: args.experiment.clone().unwrap_or_else(|| "cli".into()),
        seed: args.seed.unwrap_or(1),
        run: args.run.unwrap_or(0),
        storeys: args.storeys,
        hysteretic: args.hysteretic.clone(),
        masses: args.masses.clone(),
        measurement: args.measurement,
        damping: args.damping,
    }
}

/// Finishes a run ([`finish`]: warnings attached, record written), prints the summary table on
/// the console's output and the warnings on its errors, and returns the run's rejection, if
/// any, as the error of a non-zero exit.
fn report(record: RunRecord, out: &Path, con: &mut Console) -> Result<()> {
    let finished = finish(record, out)?;
    writeln!(con.err(), "{}", finished.headline())?;
    write!(con.out(), "{}", finished.summary())?;
    for w in &finished.record.warnings {
        writeln!(con.err(), "warning: {}", w.message)?;
    }
    finished.verdict()?;
    Ok(())
}
