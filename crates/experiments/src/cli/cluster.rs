//! `sysid cluster`: run a study as a Slurm job array (`docs/cluster.md`): `submit`, `status`,
//! `resubmit`, `finish` (what the finish job runs) and `compare` (a cluster result against a
//! local one, timings aside).

use std::path::{Path, PathBuf};

use crate::error::{bail, Context, Result};

use crate::cluster::status::status;
use crate::cluster::submit::{finish, resubmit, submit};
use crate::cluster::{compare, Kind, Plan, SlurmOptions};

/// Arguments of `sysid cluster`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Write the job-array and finish scripts into OUT/cluster/ and submit them.
    Submit(SubmitArgs),
    /// Runs done, running, queued and failed (with the reason), from the records and `squeue`.
    Status(OutArgs),
    /// Submit again only the shards that are incomplete and no longer queued.
    Resubmit(ResubmitArgs),
    /// Merge the shards, check every run, write the report (the finish job runs this).
    Finish(OutArgs),
    /// Compare two output directories of one study, timings aside (exit 1 when they differ).
    Compare(CompareArgs),
}

#[derive(Debug, clap::Args)]
pub struct SubmitArgs {
    /// Which study: paper (`sysid reproduce`), scaling, excitations, or study (`sysid study`,
    /// any study file, e.g. one with `[data] dir`).
    #[arg(value_enum)]
    pub kind: Kind,
    /// The study file, or for `paper` the directory of study files [default: experiments,
    /// experiments/scaling.toml, experiments/excitations.toml; required for `study`].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory of the study (merged records and report); the submission's scripts,
    /// logs and shard outputs go to OUT/cluster/.
    #[arg(long)]
    pub out: PathBuf,
    /// Array tasks, one shard of the study each.
    #[arg(long)]
    pub tasks: usize,
    /// CPUs per task (the sweep threads of a shard).
    #[arg(long, default_value_t = 1)]
    pub cpus_per_task: usize,
    /// The study's `[quick]` form.
    #[arg(long)]
    pub quick: bool,
    /// Slurm partition.
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit of one task (sbatch --time), e.g. 02:00:00.
    #[arg(long)]
    pub time: Option<String>,
    /// Memory of one task (sbatch --mem), e.g. 2G.
    #[arg(long)]
    pub mem: Option<String>,
    /// Slurm account.
    #[arg(long)]
    pub account: Option<String>,
    /// At most this many tasks at once (sbatch --array=...%K).
    #[arg(long)]
    pub max_running: Option<usize>,
    /// The sysid binary the jobs run (on a file system the nodes share) [default: this one].
    #[arg(long)]
    pub sysid: Option<PathBuf>,
    /// Print the scripts and the sbatch commands; write and submit nothing.
    #[arg(long)]
    pub dry_run: bool,
}

#[derive(Debug, clap::Args)]
pub struct OutArgs {
    /// The output directory given to `sysid cluster submit`.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct ResubmitArgs {
    /// The output directory given to `sysid cluster submit`.
    #[arg(long)]
    pub out: PathBuf,
    /// Print what would be submitted; submit nothing.
    #[arg(long)]
    pub dry_run: bool,
}

#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    pub a: PathBuf,
    pub b: PathBuf,
}

/// Runs `sysid cluster`.
pub fn run(args: Args, con: &mut crate::console::Console) -> Result<()> {
    match args.command {
        Command::Submit(a) => run_submit(a, con),
        Command::Status(a) => {
            let plan = Plan::load(&a.out)?;
            write!(con.out(), "{}", status(&plan, true)?.render(&plan))?;
            Ok(())
        }
        Command::Resubmit(a) => {
            let plan = Plan::load(&a.out)?;
            match resubmit(&plan, a.dry_run)? {
                None => {
                    write!(con.out(), "{}", status(&plan, true)?.render(&plan))?;
                    writeln!(con.err(), "no shard to submit again")?;
                }
                Some(s) => {
                    for c in &s.commands {
                        writeln!(con.out(), "{c}")?;
                    }
                    if let Some(sub) = s.submission {
                        writeln!(
                            con.err(),
                            "submitted shards {:?} as array job {}, finish job {}",
                            sub.shards,
                            sub.array_job,
                            sub.finish_job
                        )?;
                    }
                }
            }
            Ok(())
        }
        Command::Finish(a) => {
            let plan = Plan::load(&a.out)?;
            let done = finish(&plan)?;
            writeln!(
                con.err(),
                "finished {}: {} runs; merge copied {}, replaced {}, {} already present",
                plan.out.display(),
                done.runs,
                done.merged.copied,
                done.merged.replaced.len(),
                done.merged.present
            )?;
            Ok(())
        }
        Command::Compare(a) => {
            let diffs = compare::compare(&a.a, &a.b)?;
            if diffs.is_empty() {
                writeln!(
                    con.out(),
                    "{} and {} hold the same result (timings aside)",
                    a.a.display(),
                    a.b.display()
                )?;
                return Ok(());
            }
            for d in &diffs {
                writeln!(con.out(), "{d}")?;
            }
            bail!("{} difference(s)", diffs.len())
        }
    }
}

fn absolute(path: &Path, what: &str) -> Result<PathBuf> {
    std::fs::canonicalize(path).with_context(|| format!("{what} {}", path.display()))
}

fn run_submit(a: SubmitArgs, con: &mut crate::console::Console) -> Result<()> {
    let config = match (&a.config, a.kind.default_config()) {
        (Some(c), _) => c.clone(),
        (None, Some(d)) => PathBuf::from(d),
        (None, None) => bail!("`{}` needs --config FILE.toml", a.kind.name()),
    };
    if a.kind != Kind::Paper {
        // Checked as given, before its link (if any) is resolved: a link to /dev/zero is named
        // as the user wrote it.
        models::readers::check_input_file(&config).context("--config")?;
    }
    let config = absolute(&config, "--config")?;
    if (a.kind == Kind::Paper) != config.is_dir() {
        bail!(
            "--config {}: `paper` takes the directory of study files, the others a study file",
            config.display()
        );
    }
    let sysid = match &a.sysid {
        Some(p) => absolute(p, "--sysid")?,
        None => std::env::current_exe().context("locating the sysid binary")?,
    };
    // The output directory need not exist yet; its absolute path goes into the scripts.
    let out = if a.out.is_absolute() {
        a.out.clone()
    } else {
        std::env::current_dir()
            .context("reading the current directory")?
            .join(&a.out)
    };
    let plan = Plan {
        kind: a.kind,
        config,
        out,
        quick: a.quick,
        tasks: a.tasks,
        cpus_per_task: a.cpus_per_task,
        sysid,
        slurm: SlurmOptions {
            partition: a.partition,
            time: a.time,
            mem: a.mem,
            account: a.account,
            max_running: a.max_running,
        },
    };
    let (submitted, runs, scripts) = submit(&plan, a.dry_run)?;
    if a.dry_run {
        writeln!(
            con.out(),
            "# {}\n{}",
            plan.shard_script().display(),
            scripts[0]
        )?;
        writeln!(
            con.out(),
            "# {}\n{}",
            plan.finish_script().display(),
            scripts[1]
        )?;
        writeln!(
            con.out(),
            "# {runs} runs in {} shards; would run:",
            plan.tasks
        )?;
        for c in &submitted.commands {
            writeln!(con.out(), "{c}")?;
        }
        return Ok(());
    }
    for c in &submitted.commands {
        writeln!(con.out(), "{c}")?;
    }
    if let Some(s) = submitted.submission {
        writeln!(
            con.err(),
            "submitted {runs} runs in {} shards: array job {}, finish job {} (logs in {}); \
             follow with `sysid cluster status --out {}`",
            plan.tasks,
            s.array_job,
            s.finish_job,
            plan.logs().display(),
            plan.out.display()
        )?;
    }
    Ok(())
}
