//! Studies on a cluster: any sweep the tool runs, as a Slurm job array (`sysid cluster`,
//! `docs/cluster.md`).
//!
//! A submission reuses the sweep machinery unchanged: each array task runs one shard of the
//! study (`--shard i/n --resume`) into a part directory of its own, and a finish job that depends
//! on the whole array (`afterany`) merges the parts ([`crate::sweep::merge`]), checks that every
//! run of the study has a record whose fingerprint matches its job, and only then writes the
//! report, from the merged records, exactly as a local `--resume` run would. A shard that failed
//! or was cancelled is named with the reason its log gives; `resubmit` runs only those shards
//! again.
//!
//! - [`plan`]: the study kinds, the submission's settings (`OUT/cluster/plan.json`) and the
//!   command line of a shard and of the report;
//! - [`script`]: the two batch scripts;
//! - `scheduler`: `sbatch`, `squeue` and `scancel`;
//! - [`status`]: what is done, queued and missing, per run and per shard;
//! - [`submit`]: submit, resubmit the failed shards, finish (merge, check, report);
//! - [`compare`]: two output directories compared with the timings set aside.

pub mod compare;
pub mod plan;
pub(crate) mod scheduler;
pub mod script;
pub mod status;
pub mod submit;

pub use plan::{Kind, Plan, SlurmOptions};

/// What can go wrong in a cluster submission, its status or its finish.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// A file of the submission could not be read, written or parsed.
    #[error("{path}: {message}")]
    File { path: String, message: String },
    /// A setting of the submission is out of range or inconsistent.
    #[error("{0}")]
    Invalid(String),
    /// The study could not be loaded or its jobs enumerated.
    #[error("study {config}: {message}")]
    Study { config: String, message: String },
    /// A scheduler command failed or answered something unexpected.
    #[error("`{command}`: {message}")]
    Scheduler { command: String, message: String },
    /// The merge or the report failed.
    #[error("{0}")]
    Sweep(String),
    /// Runs of the study have no usable record: the finish stops before the report.
    #[error("{missing} of {total} runs have no record; {hint}")]
    Incomplete {
        missing: usize,
        total: usize,
        hint: String,
    },
}

crate::error::domain_error!(ClusterError);

impl ClusterError {
    pub(crate) fn file(path: &std::path::Path, e: impl std::fmt::Display) -> Self {
        ClusterError::File {
            path: path.display().to_string(),
            message: e.to_string(),
        }
    }
}
