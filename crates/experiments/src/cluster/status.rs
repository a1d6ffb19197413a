//! What a submission has done: every run of the study looked up in the merged output and in its
//! shard's part directory (done only when its record reads back, passes its checks and carries
//! the job's fingerprint, as `--resume` decides), and every shard's place in the queue
//! (`squeue`) or, for a shard that is neither complete nor queued, why it stopped (the last
//! error its log shows).

use std::fmt::Write as _;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::plan::Plan;
use super::scheduler::{self, Queued};
use super::ClusterError;
use crate::sweep::{read_record, SweepRecord};
use identify::record::RunRecord;

/// Where a run stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum RunState {
    /// Its record is in the merged output.
    Merged,
    /// Its record is in its shard's part directory, not merged yet.
    InPart,
    /// A record exists but cannot be used (unreadable, or computed from other inputs).
    Unusable(String),
    /// No record.
    Missing,
}

impl RunState {
    pub fn done(&self) -> bool {
        matches!(self, RunState::Merged | RunState::InPart)
    }
}

/// One shard: its runs, how many are done, and where it is.
#[derive(Debug, Clone)]
pub(crate) struct ShardStatus {
    pub index: usize,
    pub runs: usize,
    pub done: usize,
    /// Unusable records of the shard (path and reason), if any.
    pub unusable: Vec<(PathBuf, String)>,
    /// The shard's array task as `squeue` shows it, if it is still queued or running.
    pub queued: Option<(String, Queued)>,
    /// Why an incomplete shard that is no longer queued stopped (from its log).
    pub why: Option<String>,
}

impl ShardStatus {
    pub fn complete(&self) -> bool {
        self.done == self.runs
    }

    /// Incomplete and no longer queued: to be submitted again.
    pub fn failed(&self) -> bool {
        !self.complete() && self.queued.is_none()
    }
}

/// The state of a submission.
#[derive(Debug, Clone)]
pub struct Status {
    pub total: usize,
    pub merged: usize,
    pub in_parts: usize,
    pub(crate) shards: Vec<ShardStatus>,
    /// Finish jobs still queued, with their state.
    pub(crate) finish_queued: Vec<(String, Queued)>,
    /// Why the queue could not be read (then no shard counts as queued).
    pub scheduler_error: Option<String>,
}

impl Status {
    pub fn done(&self) -> usize {
        self.merged + self.in_parts
    }

    pub fn failed_shards(&self) -> Vec<usize> {
        self.shards
            .iter()
            .filter(|s| s.failed())
            .map(|s| s.index)
            .collect()
    }

    /// A report for the terminal.
    pub fn render(&self, plan: &Plan) -> String {
        let mut s = String::new();
        let count = |f: &dyn Fn(&ShardStatus) -> bool| -> (usize, usize) {
            self.shards
                .iter()
                .filter(|x| f(x))
                .fold((0, 0), |(n, r), x| (n + 1, r + x.runs - x.done))
        };
        let running =
            count(&|x| !x.complete() && x.queued.as_ref().is_some_and(|q| q.1.state == "RUNNING"));
        let waiting =
            count(&|x| !x.complete() && x.queued.as_ref().is_some_and(|q| q.1.state != "RUNNING"));
        let failed = count(&|x| x.failed());
        let _ = writeln!(
            s,
            "{} ({}) — {} runs in {} shards, output {}",
            plan.config.display(),
            plan.kind.name(),
            self.total,
            plan.tasks,
            plan.out.display()
        );
        let _ = writeln!(
            s,
            "runs: {} done ({} merged, {} in parts), {} in running shards, {} in queued \
             shards, {} in failed shards",
            self.done(),
            self.merged,
            self.in_parts,
            running.1,
            waiting.1,
            failed.1
        );
        let complete = self.shards.iter().filter(|x| x.complete()).count();
        let _ = writeln!(
            s,
            "shards: {complete} complete, {} running, {} queued, {} failed",
            running.0, waiting.0, failed.0
        );
        if let Some(e) = &self.scheduler_error {
            let _ = writeln!(s, "queue not read ({e}): no shard is counted as queued");
        }
        for x in self.shards.iter().filter(|x| !x.complete()) {
            let _ = write!(s, "  shard {}: {} of {} runs done", x.index, x.done, x.runs);
            match (&x.queued, &x.why) {
                (Some((job, q)), _) => {
                    let _ = write!(s, "; {} (job {job}, {})", q.state, q.reason);
                }
                (None, Some(why)) => {
                    let _ = write!(s, "; not queued: {why}");
                }
                (None, None) => {}
            }
            let _ = writeln!(s);
            for (path, why) in x.unusable.iter().take(3) {
                let _ = writeln!(s, "    {}: {why}", path.display());
            }
        }
        for (job, q) in &self.finish_queued {
            let _ = writeln!(s, "finish job {job}: {} ({})", q.state, q.reason);
        }
        let failed = self.failed_shards();
        if !failed.is_empty() {
            let _ = writeln!(
                s,
                "resubmit the {} failed shard(s): sysid cluster resubmit --out {}",
                failed.len(),
                plan.out.display()
            );
        } else if self.done() == self.total && self.merged < self.total {
            let _ = writeln!(
                s,
                "every run is done; merge and report: sysid cluster finish --out {}",
                plan.out.display()
            );
        }
        s
    }
}

/// Whether `path` holds a usable record of the job with fingerprint `expected` (computed only
/// when a record exists).
fn usable(
    path: &Path,
    expected: &dyn Fn() -> crate::error::Result<String>,
) -> Result<Option<Result<(), String>>, ClusterError> {
    if !path.exists() {
        return Ok(None);
    }
    let record: RunRecord = match read_record(path) {
        Ok(r) => r,
        Err(e) => return Ok(Some(Err(format!("{e:#}")))),
    };
    let want = expected().map_err(|e| ClusterError::Study {
        config: path.display().to_string(),
        message: format!("{e:#}"),
    })?;
    Ok(Some(match record.fingerprint() {
        Some(f) if f == want => Ok(()),
        Some(_) => Err("computed from other inputs (another fingerprint)".into()),
        None => Err("has no fingerprint (older version)".into()),
    }))
}

/// Every run of the plan's study, with its shard and state.
pub(crate) fn runs(plan: &Plan) -> Result<Vec<(usize, PathBuf, RunState)>, ClusterError> {
    let sweeps = plan.sweeps()?;
    let items: Vec<(usize, usize)> = sweeps
        .iter()
        .enumerate()
        .flat_map(|(s, sw)| (0..sw.jobs.len()).map(move |j| (s, j)))
        .collect();
    items
        .par_iter()
        .map(|&(s, j)| {
            let sweep = &sweeps[s];
            let shard = j % plan.tasks;
            let rel = sweep.records.join(format!("{}.json", sweep.ids[j]));
            let expected = || sweep.study.job_fingerprint(&sweep.jobs[j]);
            let merged = plan.out.join(&rel);
            let part = plan.part(shard).join(&rel);
            let state = match usable(&merged, &expected)? {
                Some(Ok(())) => RunState::Merged,
                merged_state => match usable(&part, &expected)? {
                    Some(Ok(())) => RunState::InPart,
                    Some(Err(why)) => RunState::Unusable(why),
                    None => match merged_state {
                        Some(Err(why)) => RunState::Unusable(why),
                        _ => RunState::Missing,
                    },
                },
            };
            Ok((shard, rel, state))
        })
        .collect()
}

/// The state of a submission; with `query`, the queue is read with `squeue`.
pub fn status(plan: &Plan, query: bool) -> Result<Status, ClusterError> {
    let runs = runs(plan)?;
    let submissions = scheduler::submissions(plan)?;
    let (queue, scheduler_error) = if query && !submissions.is_empty() {
        let jobs: Vec<String> = submissions
            .iter()
            .flat_map(|s| [s.array_job.clone(), s.finish_job.clone()])
            .filter(|j| !j.is_empty())
            .collect();
        match scheduler::squeue(&jobs) {
            Ok(q) => (q, None),
            Err(e) => (Default::default(), Some(e.to_string())),
        }
    } else {
        (Default::default(), None)
    };
    let mut shards: Vec<ShardStatus> = (0..plan.tasks)
        .map(|index| ShardStatus {
            index,
            runs: 0,
            done: 0,
            unusable: Vec::new(),
            queued: None,
            why: None,
        })
        .collect();
    let (mut merged, mut in_parts) = (0, 0);
    for (shard, rel, state) in &runs {
        let x = &mut shards[*shard];
        x.runs += 1;
        match state {
            RunState::Merged => merged += 1,
            RunState::InPart => in_parts += 1,
            RunState::Unusable(why) => x.unusable.push((rel.clone(), why.clone())),
            RunState::Missing => {}
        }
        x.done += usize::from(state.done());
    }
    for x in &mut shards {
        // The newest submission that ran this shard and is still queued.
        x.queued = submissions
            .iter()
            .rev()
            .filter(|s| s.shards.contains(&x.index))
            .find_map(|s| {
                queue
                    .get(&(s.array_job.clone(), Some(x.index)))
                    .map(|q| (format!("{}_{}", s.array_job, x.index), q.clone()))
            });
        if !x.complete() && x.queued.is_none() {
            x.why = Some(why_stopped(
                &plan.shard_log(x.index),
                !submissions.is_empty(),
            ));
        }
    }
    let finish_queued = submissions
        .iter()
        .filter_map(|s| {
            queue
                .get(&(s.finish_job.clone(), None))
                .map(|q| (s.finish_job.clone(), q.clone()))
        })
        .collect();
    Ok(Status {
        total: runs.len(),
        merged,
        in_parts,
        shards,
        finish_queued,
        scheduler_error,
    })
}

/// The last line of a shard's log that says why it stopped: an error, a cancellation, a time or
/// memory limit; else its last line.
pub(crate) fn why_stopped(log: &Path, submitted: bool) -> String {
    let Ok(mut f) = std::fs::File::open(log) else {
        return if submitted {
            format!("never started (no log {})", log.display())
        } else {
            "not submitted".into()
        };
    };
    // The end of the log is enough: progress lines come every 10 s, the reason last.
    let len = f.metadata().map_or(0, |m| m.len());
    let _ = f.seek(SeekFrom::Start(len.saturating_sub(64 * 1024)));
    let mut text = String::new();
    let mut bytes = Vec::new();
    if f.read_to_end(&mut bytes).is_ok() {
        text = String::from_utf8_lossy(&bytes).into_owned();
    }
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    let telling = lines.iter().rev().find(|l| {
        let low = l.to_ascii_lowercase();
        [
            "error",
            "cancelled",
            "time limit",
            "preempt",
            "oom",
            "killed",
        ]
        .iter()
        .any(|w| low.contains(w))
    });
    match telling.or(lines.last()) {
        Some(line) => format!("{} says `{line}`", log.display()),
        None => format!("its log {} is empty", log.display()),
    }
}
