//! The Slurm commands a submission uses — `sbatch`, `squeue`, `scancel` — and the list of jobs
//! it submitted (`OUT/cluster/submissions.json`).
//!
//! Completion is read from `squeue` (what is still queued or running) and from the records
//! themselves (what is done), never from `sacct`, which needs an accounting daemon many small
//! clusters do not run.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde::{Deserialize, Serialize};

use super::plan::Plan;
use super::ClusterError;
use crate::sweep::write_bytes_atomic;

/// One submission of the array (the first, or a resubmission of some shards) and its finish job.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Submission {
    pub array_job: String,
    pub finish_job: String,
    /// The shards this array runs.
    pub shards: Vec<usize>,
    /// UTC time of the submission.
    pub submitted: String,
}

/// The submissions of a plan, oldest first.
pub fn submissions(plan: &Plan) -> Result<Vec<Submission>, ClusterError> {
    let path = plan.dir().join("submissions.json");
    if !path.exists() && path.symlink_metadata().is_err() {
        return Ok(Vec::new());
    }
    let text = models::readers::read_input_text(&path).map_err(|e| ClusterError::file(&path, e))?;
    serde_json::from_str(&text).map_err(|e| ClusterError::file(&path, e))
}

/// Appends a submission to `OUT/cluster/submissions.json` (rewritten atomically).
pub(crate) fn record_submission(plan: &Plan, s: Submission) -> Result<(), ClusterError> {
    let path = plan.dir().join("submissions.json");
    let mut all = submissions(plan)?;
    all.push(s);
    let text = serde_json::to_string_pretty(&all).map_err(|e| ClusterError::file(&path, e))?;
    write_bytes_atomic(&path, (text + "\n").as_bytes())
        .map_err(|e| ClusterError::file(&path, format!("{e:#}")))
}

fn run(cmd: &mut Command) -> Result<String, ClusterError> {
    let shown = format!("{cmd:?}").replace('"', "");
    let out = cmd.output().map_err(|e| ClusterError::Scheduler {
        command: shown.clone(),
        message: format!("{e} (is Slurm installed and on PATH?)"),
    })?;
    if !out.status.success() {
        return Err(ClusterError::Scheduler {
            command: shown,
            message: format!(
                "exited with {}: {}",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        });
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The job id in `sbatch --parsable`'s answer (`<id>` or `<id>;<cluster>`).
pub(crate) fn parse_job_id(answer: &str) -> Option<String> {
    let id = answer.trim().split(';').next()?.trim();
    (!id.is_empty() && id.chars().all(|c| c.is_ascii_digit())).then(|| id.to_string())
}

/// Submits `script` with extra `sbatch` arguments; returns the job id.
pub fn sbatch(script: &Path, args: &[String]) -> Result<String, ClusterError> {
    let answer = run(Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .arg(script))?;
    parse_job_id(&answer).ok_or_else(|| ClusterError::Scheduler {
        command: format!("sbatch {}", script.display()),
        message: format!("answered `{}`, not a job id", answer.trim()),
    })
}

/// Cancels jobs.
pub fn scancel(jobs: &[String]) -> Result<(), ClusterError> {
    if jobs.is_empty() {
        return Ok(());
    }
    run(Command::new("scancel").args(jobs)).map(|_| ())
}

/// A job or array task still known to `squeue`: its state and the scheduler's reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Queued {
    pub state: String,
    pub reason: String,
}

/// What `squeue` says about the given jobs: keyed by (job id, array task) — the task is `None`
/// for a job that is not an array. Pending tasks of an array are listed one by one (`-r`).
pub fn squeue(jobs: &[String]) -> Result<BTreeMap<(String, Option<usize>), Queued>, ClusterError> {
    if jobs.is_empty() {
        return Ok(BTreeMap::new());
    }
    let answer = run(Command::new("squeue")
        .args(["-h", "-r", "-o", "%F|%K|%T|%r", "--jobs"])
        .arg(jobs.join(",")))?;
    Ok(parse_squeue(&answer))
}

/// Job states `squeue` may still show for a moment after a job ended (while its end is being
/// recorded): such a job no longer counts as queued.
const ENDED: [&str; 11] = [
    "COMPLETING",
    "COMPLETED",
    "CANCELLED",
    "FAILED",
    "TIMEOUT",
    "PREEMPTED",
    "NODE_FAIL",
    "OUT_OF_MEMORY",
    "BOOT_FAIL",
    "DEADLINE",
    "SPECIAL_EXIT",
];

/// Parses `squeue -h -r -o '%F|%K|%T|%r'` lines (array job id, task, state, reason); jobs in a
/// state that means they ended are left out.
pub(crate) fn parse_squeue(answer: &str) -> BTreeMap<(String, Option<usize>), Queued> {
    answer
        .lines()
        .filter_map(|line| {
            let mut f = line.trim().split('|');
            let (job, task, state, reason) = (f.next()?, f.next()?, f.next()?, f.next()?);
            let job = job.trim().to_string();
            if job.is_empty() || ENDED.contains(&state.trim()) {
                return None;
            }
            Some((
                (job, task.trim().parse::<usize>().ok()),
                Queued {
                    state: state.trim().to_string(),
                    reason: reason.trim().to_string(),
                },
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_ids_and_queue_lines_are_parsed() {
        assert_eq!(parse_job_id("1234\n").as_deref(), Some("1234"));
        assert_eq!(parse_job_id("77;cluster1").as_deref(), Some("77"));
        assert_eq!(parse_job_id("Submitted batch job 5"), None);
        let q = parse_squeue(
            "12|3|RUNNING|None\n12|4|PENDING|Resources\n13|N/A|PENDING|Dependency\n\
             12|5|COMPLETING|None\n",
        );
        assert_eq!(q[&("12".into(), Some(3))].state, "RUNNING");
        assert_eq!(q[&("12".into(), Some(4))].reason, "Resources");
        assert_eq!(q[&("13".into(), None)].reason, "Dependency");
        assert_eq!(q.len(), 3);
    }
}
