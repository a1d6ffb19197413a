//! A submission's plan: which study, where its output goes, how it is split, and the command
//! line each piece runs. Written once to `OUT/cluster/plan.json` by `sysid cluster submit`, read
//! by `status`, `resubmit` and `finish`, so that every later step works on the same study.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ClusterError;
use crate::study::{Job, Study};
use crate::sweep::write_bytes_atomic;

/// The studies the tool runs, each through its own subcommand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// The paper reproduction and the discretisation study (`sysid reproduce`; the config is the
    /// directory of study files, `experiments/`).
    Paper,
    /// The scaling study (`sysid scaling`; `experiments/scaling.toml` or a variant of it).
    Scaling,
    /// The excitations study (`sysid excitations`; `experiments/excitations.toml`).
    Excitations,
    /// A study file (`sysid study`), e.g. N filter seeds × algorithms on a record of your own
    /// (`[data] dir = "..."`).
    Study,
}

impl Kind {
    /// The `sysid` subcommand that runs the study.
    pub fn subcommand(self) -> &'static str {
        match self {
            Kind::Paper => "reproduce",
            Kind::Scaling => "scaling",
            Kind::Excitations => "excitations",
            Kind::Study => "study",
        }
    }

    /// The option naming the config (`--experiments` for the directory of the paper's studies).
    fn config_flag(self) -> &'static str {
        match self {
            Kind::Paper => "--experiments",
            _ => "--config",
        }
    }

    /// The config used when none is given (`None`: one must be given).
    pub fn default_config(self) -> Option<&'static str> {
        match self {
            Kind::Paper => Some("experiments"),
            Kind::Scaling => Some("experiments/scaling.toml"),
            Kind::Excitations => Some("experiments/excitations.toml"),
            Kind::Study => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Kind::Paper => "paper",
            Kind::Scaling => "scaling",
            Kind::Excitations => "excitations",
            Kind::Study => "study",
        }
    }
}

/// Scheduler settings passed to every job of the submission (absent: the cluster's defaults).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    /// Time limit of one array task (and of the finish job), in any form `sbatch --time` takes.
    pub time: Option<String>,
    /// Memory of one task, in any form `sbatch --mem` takes.
    pub mem: Option<String>,
    pub account: Option<String>,
    /// At most this many array tasks run at once (`--array=0-63%K`).
    pub max_running: Option<usize>,
}

/// Everything a submission needs to run, check and finish a study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub kind: Kind,
    /// The study file, or for [`Kind::Paper`] the directory of study files (absolute).
    pub config: PathBuf,
    /// The study's output directory (absolute): the merged records and the report.
    pub out: PathBuf,
    /// The study's `[quick]` form.
    pub quick: bool,
    /// Array tasks, one shard each.
    pub tasks: usize,
    /// CPUs of one task, and the sweep threads it runs.
    pub cpus_per_task: usize,
    /// The `sysid` binary the jobs run (absolute; on a file system the nodes share).
    pub sysid: PathBuf,
    pub slurm: SlurmOptions,
}

/// Most array tasks a plan accepts (Slurm's own `MaxArraySize` may be lower and is checked by
/// `sbatch`).
pub(crate) const MAX_TASKS: usize = 100_000;

/// One sweep of a study: its jobs in sweep order (job `j` belongs to shard `j % tasks`) and where
/// their records go.
pub(crate) struct Sweep {
    pub study: Study,
    pub jobs: Vec<Job>,
    /// Record file stems, one per job.
    pub ids: Vec<String>,
    /// The records' directory relative to an output directory (`records` or `records/<study>`).
    pub records: PathBuf,
}

impl Plan {
    /// `OUT/cluster`: the plan, scripts, logs, parts and submissions.
    pub fn dir(&self) -> PathBuf {
        cluster_dir(&self.out)
    }

    pub(crate) fn plan_path(&self) -> PathBuf {
        self.dir().join("plan.json")
    }

    pub(crate) fn shard_script(&self) -> PathBuf {
        self.dir().join("shard.sh")
    }

    pub(crate) fn finish_script(&self) -> PathBuf {
        self.dir().join("finish.sh")
    }

    pub fn logs(&self) -> PathBuf {
        self.dir().join("logs")
    }

    /// The log of array task `i` (every instance of the task appends to it).
    pub(crate) fn shard_log(&self, i: usize) -> PathBuf {
        self.logs().join(format!("shard-{i}.log"))
    }

    pub fn parts(&self) -> PathBuf {
        self.dir().join("parts")
    }

    /// The output directory of shard `i`.
    pub fn part(&self, i: usize) -> PathBuf {
        self.parts().join(format!("shard-{i}"))
    }

    /// A name for the jobs: `sysid-paper`, or `sysid-<study file stem>`.
    pub(crate) fn job_name(&self) -> String {
        if self.kind == Kind::Paper {
            return "sysid-paper".into();
        }
        let stem = self
            .config
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let clean: String = stem
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '-'
                }
            })
            .collect();
        format!("sysid-{clean}")
    }

    /// Checks the settings that do not need the study loaded.
    pub fn check(&self) -> Result<(), ClusterError> {
        if self.tasks == 0 || self.tasks > MAX_TASKS {
            return Err(ClusterError::Invalid(format!(
                "--tasks {}: need 1 to {MAX_TASKS} array tasks",
                self.tasks
            )));
        }
        if self.cpus_per_task == 0 || self.cpus_per_task > 1024 {
            return Err(ClusterError::Invalid(format!(
                "--cpus-per-task {}: need 1 to 1024",
                self.cpus_per_task
            )));
        }
        if self.slurm.max_running == Some(0) {
            return Err(ClusterError::Invalid(
                "--max-running 0: need at least 1".into(),
            ));
        }
        for (flag, path) in [
            ("--config", &self.config),
            ("--out", &self.out),
            ("--sysid", &self.sysid),
        ] {
            check_script_path(flag, path)?;
        }
        check_directive_path("--out", &self.out)?;
        for (flag, value) in [
            ("--partition", &self.slurm.partition),
            ("--time", &self.slurm.time),
            ("--mem", &self.slurm.mem),
            ("--account", &self.slurm.account),
        ] {
            if let Some(v) = value {
                // The value goes into a `#SBATCH` line: anything that could end it or start
                // another directive is refused.
                if v.is_empty()
                    || !v
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_.:,+@=".contains(c))
                {
                    return Err(ClusterError::Invalid(format!(
                        "{flag} `{v}`: only letters, digits and - _ . : , + @ = are accepted"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The command line of shard `task` (without the binary), its part directory given as
    /// `part`.
    pub fn shard_args(&self, task: &str, part: &str) -> Vec<String> {
        let mut args = vec![
            self.kind.subcommand().to_string(),
            self.kind.config_flag().to_string(),
            self.config.display().to_string(),
            "--out".into(),
            part.to_string(),
            "--shard".into(),
            format!("{task}/{}", self.tasks),
            "--resume".into(),
            "--threads".into(),
            self.cpus_per_task.to_string(),
        ];
        if self.quick {
            args.push("--quick".into());
        }
        args
    }

    /// The study's sweeps, as its subcommand runs them.
    pub(crate) fn sweeps(&self) -> Result<Vec<Sweep>, ClusterError> {
        let err = |e: crate::error::Error| ClusterError::Study {
            config: self.config.display().to_string(),
            message: format!("{e:#}"),
        };
        let load = |path: &Path| -> Result<Study, ClusterError> {
            let s = Study::load(path).map_err(err)?;
            Ok(if self.quick { s.quick() } else { s })
        };
        Ok(match self.kind {
            Kind::Paper => {
                let mut sweeps = Vec::new();
                for &name in crate::reproduce::STUDIES
                    .iter()
                    .chain(&crate::discretisation::STUDIES)
                {
                    let path = self.config.join(format!("{name}.toml"));
                    // As in `reproduce`: the section beyond the paper runs when configured.
                    if crate::discretisation::STUDIES.contains(&name) && !path.exists() {
                        continue;
                    }
                    let study = load(&path)?;
                    let jobs = study.jobs();
                    let ids = jobs.iter().map(Study::job_id).collect();
                    sweeps.push(Sweep {
                        study,
                        jobs,
                        ids,
                        records: Path::new("records").join(name),
                    });
                }
                sweeps
            }
            Kind::Scaling | Kind::Excitations | Kind::Study => {
                let study = load(&self.config)?;
                let jobs = match self.kind {
                    Kind::Study => study.jobs(),
                    _ => crate::scaling::sweep_jobs(&study),
                };
                let ids = jobs.iter().map(|j| study.record_id(j)).collect();
                vec![Sweep {
                    study,
                    jobs,
                    ids,
                    records: PathBuf::from("records"),
                }]
            }
        })
    }

    /// Writes the plan to `OUT/cluster/plan.json` (atomically).
    pub fn save(&self) -> Result<(), ClusterError> {
        let path = self.plan_path();
        std::fs::create_dir_all(self.dir()).map_err(|e| ClusterError::file(&self.dir(), e))?;
        let text = serde_json::to_string_pretty(self).map_err(|e| ClusterError::file(&path, e))?;
        write_bytes_atomic(&path, (text + "\n").as_bytes())
            .map_err(|e| ClusterError::file(&path, format!("{e:#}")))
    }

    /// Reads the plan of the submission whose output directory is `out`.
    pub fn load(out: &Path) -> Result<Self, ClusterError> {
        let path = cluster_dir(out).join("plan.json");
        let text = models::readers::read_input_text(&path).map_err(|e| {
            ClusterError::file(
                &path,
                format!(
                    "{e} (is {} the --out of `sysid cluster submit`?)",
                    out.display()
                ),
            )
        })?;
        let plan: Plan = serde_json::from_str(&text)
            .map_err(|e| ClusterError::file(&path, format!("not a submission plan: {e}")))?;
        plan.check()
            .map_err(|e| ClusterError::file(&path, e.to_string()))?;
        Ok(plan)
    }
}

/// A path the scripts name (in a command, quoted, and in a header comment): it must be UTF-8,
/// so that the script names the very file (a lossy conversion would name another), and free of
/// control characters, which no quoting keeps within its line — a newline in a comment or a
/// `#SBATCH` line would start a shell command or a directive of its own.
fn check_script_path(flag: &str, path: &Path) -> Result<(), ClusterError> {
    let Some(text) = path.to_str() else {
        return Err(ClusterError::Invalid(format!(
            "{flag} {}: not valid UTF-8; the batch scripts could not name it exactly",
            path.display()
        )));
    };
    if let Some(c) = text.chars().find(|c| c.is_control()) {
        return Err(ClusterError::Invalid(format!(
            "{flag} {text:?}: contains the control character {c:?}; a path in a batch script \
             must stay on its line"
        )));
    }
    Ok(())
}

/// A path that goes into a `#SBATCH` line (the logs' `--output=OUT/cluster/logs/...`). Slurm,
/// not the shell, reads those lines: whitespace ends the value, `#` starts a comment, quotes
/// and `\` are consumed, and `%` starts a file-name pattern. Rather than rely on how a given
/// Slurm version unquotes a value, such characters are refused.
fn check_directive_path(flag: &str, path: &Path) -> Result<(), ClusterError> {
    let text = path.to_string_lossy();
    if let Some(c) = text
        .chars()
        .find(|c| c.is_whitespace() || "#%'\"\\".contains(*c))
    {
        return Err(ClusterError::Invalid(format!(
            "{flag} {text:?}: contains {c:?}, which Slurm would misread in the scripts' \
             `#SBATCH --output=` line (it takes no whitespace, #, %, quotes or \\); choose \
             a directory without it"
        )));
    }
    Ok(())
}

/// `OUT/cluster`.
pub(crate) fn cluster_dir(out: &Path) -> PathBuf {
    out.join("cluster")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(kind: Kind) -> Plan {
        Plan {
            kind,
            config: "/c/experiments".into(),
            out: "/o".into(),
            quick: true,
            tasks: 8,
            cpus_per_task: 2,
            sysid: "/bin/sysid".into(),
            slurm: SlurmOptions::default(),
        }
    }

    #[test]
    fn each_kind_runs_its_own_subcommand_sharded_and_resumed() {
        let p = plan(Kind::Paper);
        assert_eq!(
            p.shard_args("$task", "$part").join(" "),
            "reproduce --experiments /c/experiments --out $part --shard $task/8 --resume \
             --threads 2 --quick"
        );
        for (kind, sub) in [
            (Kind::Scaling, "scaling --config"),
            (Kind::Excitations, "excitations --config"),
            (Kind::Study, "study --config"),
        ] {
            assert!(plan(kind).shard_args("0", "p").join(" ").starts_with(sub));
        }
    }

    #[test]
    fn bad_settings_are_refused_by_name() {
        let mut p = plan(Kind::Scaling);
        p.tasks = 0;
        assert!(p.check().unwrap_err().to_string().contains("--tasks 0"));
        let mut p = plan(Kind::Scaling);
        p.slurm.time = Some("1:00\n#SBATCH --x".into());
        assert!(p.check().unwrap_err().to_string().contains("--time"));
        let mut p = plan(Kind::Scaling);
        p.slurm.partition = Some("gpu-long".into());
        p.slurm.time = Some("1-00:00:00".into());
        p.slurm.mem = Some("4G".into());
        p.check().unwrap();
    }
}
