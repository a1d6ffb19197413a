//! Submitting a study, submitting its failed shards again, and finishing it.

use std::path::PathBuf;

use super::plan::Plan;
use super::scheduler::{self, Submission};
use super::script::{finish_script, shard_script};
use super::status::status;
use super::ClusterError;
use crate::engine::RunMode;
use crate::sweep::lock::{utc_now, DirLock};
use crate::sweep::{merge, study_pairs, write_bytes_atomic};
use identify::record::RunRecord;

/// What `submit` or `resubmit` will do or did.
#[derive(Debug, Clone)]
pub struct Submitted {
    /// The `sbatch` command lines, in order (`<array job>` stands for the array's id).
    pub commands: Vec<String>,
    /// The submission, when it was made (not on a dry run).
    pub(crate) submission: Option<Submission>,
}

/// `0-3,7,9-10` for the shards 0, 1, 2, 3, 7, 9, 10 (sorted), with `%K` when at most K may run.
pub(crate) fn array_spec(shards: &[usize], max_running: Option<usize>) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < shards.len() {
        let mut j = i;
        while j + 1 < shards.len() && shards[j + 1] == shards[j] + 1 {
            j += 1;
        }
        parts.push(match j > i {
            true => format!("{}-{}", shards[i], shards[j]),
            false => shards[i].to_string(),
        });
        i = j + 1;
    }
    let mut spec = parts.join(",");
    if let Some(k) = max_running {
        spec.push_str(&format!("%{k}"));
    }
    spec
}

/// Checks the plan against its study: every task must have work.
fn check_against_study(plan: &Plan) -> Result<usize, ClusterError> {
    plan.check()?;
    let sweeps = plan.sweeps()?;
    let largest = sweeps.iter().map(|s| s.jobs.len()).max().unwrap_or(0);
    if plan.tasks > largest {
        return Err(ClusterError::Invalid(format!(
            "--tasks {}: the study's largest sweep has {largest} runs, so {} task(s) would have \
             nothing to do",
            plan.tasks,
            plan.tasks - largest
        )));
    }
    Ok(sweeps.iter().map(|s| s.jobs.len()).sum())
}

fn write_script(path: &std::path::Path, text: &str) -> Result<(), ClusterError> {
    write_bytes_atomic(path, text.as_bytes())
        .map_err(|e| ClusterError::file(path, format!("{e:#}")))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| ClusterError::file(path, e))?;
    }
    Ok(())
}

/// The `sbatch` arguments of the array for `shards`, and of the finish job after `after`.
fn array_args(plan: &Plan, shards: &[usize]) -> Vec<String> {
    vec![format!(
        "--array={}",
        array_spec(shards, plan.slurm.max_running)
    )]
}

fn finish_args(after: &[String]) -> Vec<String> {
    vec![format!("--dependency=afterany:{}", after.join(":"))]
}

fn shown(script: &std::path::Path, args: &[String]) -> String {
    format!("sbatch --parsable {} {}", args.join(" "), script.display())
}

/// Submits the study: writes the plan and both scripts into `OUT/cluster/`, submits the array
/// (one task per shard) and the finish job after it. On a dry run writes nothing and returns
/// the scripts' text beside the commands. Returns the number of runs too.
pub fn submit(plan: &Plan, dry_run: bool) -> Result<(Submitted, usize, [String; 2]), ClusterError> {
    let runs = check_against_study(plan)?;
    let scripts = [shard_script(plan), finish_script(plan)];
    let all: Vec<usize> = (0..plan.tasks).collect();
    let a_args = array_args(plan, &all);
    let mut commands = planned_commands(plan, &a_args, &[]);
    if dry_run {
        return Ok((
            Submitted {
                commands,
                submission: None,
            },
            runs,
            scripts,
        ));
    }
    if plan.plan_path().exists() {
        return Err(ClusterError::Invalid(format!(
            "{} already holds a submission ({}): see `sysid cluster status --out {}`, submit its \
             failed shards again with `sysid cluster resubmit`, or choose another --out",
            plan.out.display(),
            plan.plan_path().display(),
            plan.out.display()
        )));
    }
    for d in [plan.logs(), plan.parts()] {
        std::fs::create_dir_all(&d).map_err(|e| ClusterError::file(&d, e))?;
    }
    write_script(&plan.shard_script(), &scripts[0])?;
    write_script(&plan.finish_script(), &scripts[1])?;
    plan.save()?;
    let submission = submit_array(plan, &a_args, all, &[], &mut commands)?;
    Ok((
        Submitted {
            commands,
            submission: Some(submission),
        },
        runs,
        scripts,
    ))
}

/// Submits again the shards that are incomplete and no longer queued, with a new finish job
/// after them and after every earlier array that still has queued shards; cancels the earlier
/// finish jobs still waiting (they would report the resubmitted shards as missing). `None`
/// when no shard needs it.
pub fn resubmit(plan: &Plan, dry_run: bool) -> Result<Option<Submitted>, ClusterError> {
    let st = status(plan, true)?;
    if let Some(e) = &st.scheduler_error {
        return Err(ClusterError::Scheduler {
            command: "squeue".into(),
            message: format!(
                "{e}; without the queue a shard still running could be submitted twice"
            ),
        });
    }
    let failed = st.failed_shards();
    if failed.is_empty() {
        return Ok(None);
    }
    let earlier: Vec<String> = scheduler::submissions(plan)?
        .into_iter()
        .filter(|s| {
            st.shards.iter().any(|x| {
                x.queued
                    .as_ref()
                    .is_some_and(|(job, _)| job.starts_with(&format!("{}_", s.array_job)))
            })
        })
        .map(|s| s.array_job)
        .collect();
    let stale_finish: Vec<String> = st.finish_queued.iter().map(|(j, _)| j.clone()).collect();
    let a_args = array_args(plan, &failed);
    let mut commands = Vec::new();
    if !stale_finish.is_empty() {
        commands.push(format!("scancel {}", stale_finish.join(" ")));
    }
    commands.extend(planned_commands(plan, &a_args, &earlier));
    if dry_run {
        return Ok(Some(Submitted {
            commands,
            submission: None,
        }));
    }
    scheduler::scancel(&stale_finish)?;
    let submission = submit_array(plan, &a_args, failed, &earlier, &mut commands)?;
    Ok(Some(Submitted {
        commands,
        submission: Some(submission),
    }))
}

/// The `sbatch` commands of an array (its arguments `a_args`) and of the finish job after it and
/// after the `earlier` arrays, the array's job id still a placeholder: what a dry run shows.
fn planned_commands(plan: &Plan, a_args: &[String], earlier: &[String]) -> Vec<String> {
    let after: Vec<String> = std::iter::once("<array job>".to_string())
        .chain(earlier.iter().cloned())
        .collect();
    vec![
        shown(&plan.shard_script(), a_args),
        shown(&plan.finish_script(), &finish_args(&after)),
    ]
}

/// Submits the array of `shards` (its `sbatch` arguments `a_args`) and the finish job after it
/// and after the `earlier` arrays, writes the finish job's actual command into the last of
/// `commands`, and records the submission.
fn submit_array(
    plan: &Plan,
    a_args: &[String],
    shards: Vec<usize>,
    earlier: &[String],
    commands: &mut [String],
) -> Result<Submission, ClusterError> {
    let array_job = scheduler::sbatch(&plan.shard_script(), a_args)?;
    let after: Vec<String> = std::iter::once(array_job.clone())
        .chain(earlier.iter().cloned())
        .collect();
    let f_args = finish_args(&after);
    if let Some(last) = commands.last_mut() {
        *last = shown(&plan.finish_script(), &f_args);
    }
    let finish_job = submit_finish(plan, &array_job, &shards, &f_args)?;
    let submission = Submission {
        array_job,
        finish_job,
        shards,
        submitted: utc_now(),
    };
    scheduler::record_submission(plan, submission.clone())?;
    Ok(submission)
}

/// Submits the finish job after an array that is already submitted. Should that fail, the
/// array is recorded all the same (without a finish job), so that `status` sees its tasks and
/// `resubmit` does not submit them twice; the error says how to finish by hand.
fn submit_finish(
    plan: &Plan,
    array_job: &str,
    shards: &[usize],
    args: &[String],
) -> Result<String, ClusterError> {
    scheduler::sbatch(&plan.finish_script(), args).or_else(|e| {
        scheduler::record_submission(
            plan,
            Submission {
                array_job: array_job.to_string(),
                finish_job: String::new(),
                shards: shards.to_vec(),
                submitted: utc_now(),
            },
        )?;
        Err(ClusterError::Scheduler {
            command: "sbatch finish.sh".into(),
            message: format!(
                "{e}; array job {array_job} is submitted: once it has ended, run `sysid cluster \
                 finish --out {}`",
                plan.out.display()
            ),
        })
    })
}

/// What `finish` did.
#[derive(Debug, Clone)]
pub struct Finished {
    pub merged: crate::sweep::MergeReport,
    pub runs: usize,
}

/// Merges every part into the output directory, checks that every run of the study has a
/// usable record, and writes the report with the study's own subcommand (`--resume`: every run
/// loaded, none computed). When runs are missing, stops after the merge with the status,
/// which names the failed shards and why.
pub fn finish(plan: &Plan) -> Result<Finished, ClusterError> {
    let parts: Vec<PathBuf> = (0..plan.tasks)
        .map(|i| plan.part(i))
        .filter(|p| p.join("records").is_dir())
        .collect();
    let merged = {
        let _lock =
            DirLock::acquire(&plan.out).map_err(|e| ClusterError::Sweep(format!("{e:#}")))?;
        let pairs =
            study_pairs(&parts, &plan.out).map_err(|e| ClusterError::Sweep(format!("{e:#}")))?;
        merge::<RunRecord>(&pairs).map_err(|e| ClusterError::Sweep(format!("merge: {e:#}")))?
    };
    let st = status(plan, true)?;
    if st.merged < st.total {
        return Err(ClusterError::Incomplete {
            missing: st.total - st.merged,
            total: st.total,
            hint: format!("no report written.\n{}", st.render(plan).trim_end()),
        });
    }
    report(plan).map_err(|e| ClusterError::Sweep(format!("report: {e:#}")))?;
    Ok(Finished {
        merged,
        runs: st.total,
    })
}

/// The study's report from the merged records, by the study's own code path.
fn report(plan: &Plan) -> crate::error::Result<()> {
    let (config, out) = (plan.config.clone(), plan.out.clone());
    match plan.kind {
        super::Kind::Paper => {
            crate::reproduce::reproduce(&crate::reproduce::Options {
                experiments: config,
                out,
                mode: RunMode::report_merged(plan.quick),
            })?;
        }
        super::Kind::Scaling | super::Kind::Excitations => {
            let opts = crate::scaling::Options {
                config,
                out,
                mode: RunMode::report_merged(plan.quick),
                report_only: false,
            };
            match plan.kind {
                super::Kind::Scaling => crate::scaling::run(&opts)?,
                _ => crate::excitations::run(&opts)?,
            };
        }
        super::Kind::Study => {
            // The report is in REPORT.md (the study logs where).
            crate::user_study::run(&crate::user_study::Options {
                config,
                out,
                mode: RunMode::report_merged(plan.quick),
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_specs_compress_runs_of_shards() {
        assert_eq!(array_spec(&[0, 1, 2, 3], None), "0-3");
        assert_eq!(array_spec(&[0, 1, 2, 3, 7, 9, 10], Some(4)), "0-3,7,9-10%4");
        assert_eq!(array_spec(&[5], None), "5");
    }
}
