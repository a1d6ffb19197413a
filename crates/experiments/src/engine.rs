//! The study engine: one way to run any study description ([`Study`], `experiments/*.toml`).
//! Every study command (the paper reproduction, the discretisation, excitations and scaling
//! studies, a user's study, the regression check) runs its jobs through `Engine::sweep` — records written as runs
//! finish, resumable by fingerprint, shardable — and then turns the records into its summary
//! and report; only that last step is the study's own.

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{Context, Result};
use serde::Serialize;

use crate::study::{Job, Study};
use crate::sweep::{run_sweep, write_bytes_atomic, Shard, SweepOptions, SweepOutcome};
use identify::record::RunRecord;

/// How a study command runs, whatever the study: its `[quick]` form or the full one, with how
/// many threads, which part of the sweep, with progress on stderr or not, and whether existing
/// records are reused. Every study command takes one (`sysid reproduce`, `scaling`,
/// `excitations`, `study`, `regression`, and the cluster path's final report).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunMode {
    /// The study's `[quick]` form: fewer runs and particles, a shorter record.
    pub quick: bool,
    /// Worker threads (0: one per core).
    pub threads: usize,
    pub shard: Shard,
    /// Show progress and the summary of each sweep on stderr.
    pub progress: bool,
    /// Reuse the records whose fingerprint matches (otherwise every run is computed).
    pub resume: bool,
}

impl RunMode {
    /// The full study on `threads` threads (0: one per core), every run computed, nothing
    /// printed: how a program or a test embeds a study.
    pub fn quiet(threads: usize) -> Self {
        Self {
            quick: false,
            threads,
            shard: Shard::default(),
            progress: false,
            resume: false,
        }
    }

    /// The report of merged shards: every record reused, nothing computed.
    pub(crate) fn report_merged(quick: bool) -> Self {
        Self {
            quick,
            threads: 1,
            shard: Shard::default(),
            progress: true,
            resume: true,
        }
    }
}

/// How a study is run: where its results go and the [`RunMode`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Engine<'a> {
    /// The study's output directory (records below it, summary and report in it).
    pub out: &'a Path,
    pub mode: RunMode,
}

/// Reads a study file, in its `[quick]` form when asked.
pub fn load(path: &Path, quick: bool) -> Result<Study> {
    let study = Study::load(path)?;
    Ok(if quick { study.quick() } else { study })
}

/// Writes `value` as pretty JSON with a final newline (every `summary.json`).
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    write_bytes_atomic(
        path,
        (serde_json::to_string_pretty(value)? + "\n").as_bytes(),
    )
}

impl Engine<'_> {
    /// Runs `jobs` of `study` into `dir/<id(job)>.json` ([`run_sweep`]): `compute` gives a job's
    /// record; its errors are configuration errors and name the study and the job.
    pub fn sweep(
        &self,
        study: &Study,
        jobs: &[Job],
        dir: &Path,
        id: impl Fn(&Job) -> String + Sync,
        compute: impl Fn(&Job) -> Result<RunRecord> + Sync,
    ) -> Result<SweepOutcome<RunRecord>> {
        let options = SweepOptions {
            threads: self.mode.threads,
            shard: self.mode.shard,
            progress: self.mode.progress,
            label: study.name.clone(),
            resume: self.mode.resume,
        };
        run_sweep(
            jobs,
            &id,
            |job| study.job_fingerprint(job),
            dir,
            &options,
            |job| compute(job).with_context(|| format!("{}: {}", study.name, id(job))),
        )
    }

    /// Whether this is one part of a sharded sweep: then only records are written, and the
    /// summary and report wait for the merged records ([`Engine::shard_note`]).
    pub(crate) fn sharded(&self) -> bool {
        self.mode.shard != Shard::default()
    }

    /// Says on stderr what a shard did and how its records become a report.
    pub(crate) fn shard_note(&self, did: &str) {
        log::info!(
            "shard {}/{}: {did}; merge the shards' records (`sysid merge`) and run the same \
             command without `--shard` and with `--resume` to write the report",
            self.mode.shard.index,
            self.mode.shard.count
        );
    }

    /// Writes `last-run.json` (not committed) with the study's `facts` (wall times, runs).
    pub fn last_run(&self, facts: serde_json::Value) -> Result<()> {
        crate::sweep::last_run::write(self.out, self.mode.threads, facts)
    }
}

/// Records of an earlier sweep that a job may take over: only when the record's fingerprint
/// (data, settings, seed, run, algorithm, numerics version) is the job's, i.e. when computing
/// the job again would give the same record.
#[derive(Debug, Default)]
pub struct Reuse {
    by_fingerprint: HashMap<String, RunRecord>,
    taken: AtomicUsize,
}

impl Reuse {
    /// The completed and failed records alike (a failure is the job's result too).
    pub fn new<'a>(records: impl IntoIterator<Item = &'a RunRecord>) -> Self {
        Self {
            by_fingerprint: records
                .into_iter()
                .filter_map(|r| Some((r.fingerprint.as_ref()?.sha256.clone(), r.clone())))
                .collect(),
            taken: AtomicUsize::new(0),
        }
    }

    /// The job's record: taken over (relabelled with `study`'s name) when an earlier record has
    /// the job's fingerprint, computed otherwise.
    pub fn run(&self, study: &Study, job: &Job) -> Result<RunRecord> {
        if !self.by_fingerprint.is_empty() {
            if let Some(r) = self.by_fingerprint.get(&study.job_fingerprint(job)?) {
                self.taken.fetch_add(1, Ordering::Relaxed);
                let mut r = r.clone();
                r.experiment.clone_from(&study.name);
                return Ok(r);
            }
        }
        study.run_job(job)
    }

    /// How many records were taken over.
    pub fn taken(&self) -> usize {
        self.taken.load(Ordering::Relaxed)
    }
}
