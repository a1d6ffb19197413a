//! The two batch scripts of a submission: `shard.sh`, run by every task of the job array, and
//! `finish.sh`, the job that depends on the array.

use super::plan::Plan;

/// `value` as one word for the shell (single-quoted; a `'` inside closes, escapes and reopens).
pub(crate) fn quote(value: &str) -> String {
    if !value.is_empty()
        && value
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@".contains(c))
    {
        return value.to_string();
    }
    format!("'{}'", value.replace('\'', r"'\''"))
}

/// The `#SBATCH` lines every job of the submission shares.
fn common_directives(plan: &Plan) -> String {
    let mut s = String::new();
    for (flag, value) in [
        ("partition", &plan.slurm.partition),
        ("time", &plan.slurm.time),
        ("mem", &plan.slurm.mem),
        ("account", &plan.slurm.account),
    ] {
        if let Some(v) = value {
            s.push_str(&format!("#SBATCH --{flag}={v}\n"));
        }
    }
    s
}

/// The array script: one shard per task, resumed, into the task's own part directory.
///
/// `--requeue` lets Slurm put a pre-empted task back in the queue, and `--resume` makes the new
/// instance reuse every record the old one finished (records are written atomically, so the
/// runs in flight when it was stopped are the only ones computed again). The log is opened in
/// append mode so that every instance of a task adds to the same file.
pub(crate) fn shard_script(plan: &Plan) -> String {
    let part = format!("{}/shard-", plan.parts().display());
    let args: Vec<String> = plan
        .shard_args("${task}", "${part}")
        .into_iter()
        .map(|a| match a.as_str() {
            "${part}" => "\"$part\"".to_string(),
            _ if a.contains("${task}") => format!("\"{a}\""),
            _ => quote(&a),
        })
        .collect();
    format!(
        "#!/bin/bash
# One shard per array task of this study (`sysid {kind}`):
#   {config}
# written by `sysid cluster submit`, which submitted it with `sbatch --array=0-{last}`;
# `sysid cluster resubmit` submits it again with the shards that have no complete set of
# records.
#SBATCH --job-name={name}
#SBATCH --output={logs}/shard-%a.log
#SBATCH --open-mode=append
#SBATCH --cpus-per-task={cpus}
#SBATCH --requeue
{common}set -euo pipefail
task=${{SLURM_ARRAY_TASK_ID:?run this script as a Slurm array task: sbatch --array=...}}
part={part_q}\"$task\"
# Slurm runs one instance of an array task at a time, and `sysid cluster resubmit` refuses a
# shard that is still queued: a lock in this shard's own directory was left by an earlier
# instance that was pre-empted or cancelled, possibly on another node, whose lock the sweep
# would otherwise refuse to take over.
rm -f \"$part/.sysid.lock\"
echo \"shard $task/{tasks} on $(hostname) (job ${{SLURM_JOB_ID:-?}}, restart ${{SLURM_RESTART_COUNT:-0}}) at $(date -u +%Y-%m-%dT%H:%M:%SZ)\"
exec {sysid} {args}
",
        kind = plan.kind.subcommand(),
        config = plan.config.display(),
        last = plan.tasks - 1,
        name = plan.job_name(),
        logs = plan.logs().display(),
        cpus = plan.cpus_per_task,
        common = common_directives(plan),
        part_q = quote(&part),
        tasks = plan.tasks,
        sysid = quote(&plan.sysid.display().to_string()),
        args = args.join(" "),
    )
}

/// The finish script: merge the parts, check every run, write the report (`sysid cluster
/// finish`). It depends on the array with `afterany`, so it runs however the tasks ended and
/// names the shards that failed instead of waiting for them forever.
pub(crate) fn finish_script(plan: &Plan) -> String {
    format!(
        "#!/bin/bash
# Merges the shards of this study (`sysid {kind}`):
#   {config}
# checks that every run has its record and writes the report; written by `sysid cluster
# submit`, submitted with `--dependency=afterany:<array job>`.
#SBATCH --job-name={name}-finish
#SBATCH --output={logs}/finish-%j.log
#SBATCH --cpus-per-task=1
{common}set -euo pipefail
exec {sysid} cluster finish --out {out}
",
        kind = plan.kind.subcommand(),
        config = plan.config.display(),
        name = plan.job_name(),
        logs = plan.logs().display(),
        common = common_directives(plan),
        sysid = quote(&plan.sysid.display().to_string()),
        out = quote(&plan.out.display().to_string()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::{Kind, SlurmOptions};

    #[test]
    fn quoting_keeps_every_path_one_word() {
        assert_eq!(quote("/a/b-c.toml"), "/a/b-c.toml");
        assert_eq!(quote("/my runs/x"), "'/my runs/x'");
        assert_eq!(quote("it's"), r"'it'\''s'");
        assert_eq!(quote(""), "''");
    }

    #[test]
    fn scripts_carry_the_shard_command_and_the_directives() {
        let plan = Plan {
            kind: Kind::Scaling,
            config: "/w/experiments/scaling.toml".into(),
            out: "/w/results/a&b$c".into(),
            quick: false,
            tasks: 64,
            cpus_per_task: 1,
            sysid: "/w/target/release/sysid".into(),
            slurm: SlurmOptions {
                partition: Some("long".into()),
                time: Some("02:00:00".into()),
                ..SlurmOptions::default()
            },
        };
        let s = shard_script(&plan);
        assert!(
            s.contains("#SBATCH --partition=long\n#SBATCH --time=02:00:00\n"),
            "{s}"
        );
        assert!(s.contains("#SBATCH --requeue"), "{s}");
        assert!(
            s.contains(
                "exec /w/target/release/sysid scaling --config /w/experiments/scaling.toml \
                 --out \"$part\" --shard \"${task}/64\" --resume --threads 1\n"
            ),
            "{s}"
        );
        assert!(
            s.contains("part='/w/results/a&b$c/cluster/parts/shard-'\"$task\""),
            "{s}"
        );
        let f = finish_script(&plan);
        assert!(
            f.contains("exec /w/target/release/sysid cluster finish --out '/w/results/a&b$c'"),
            "{f}"
        );
        assert!(!f.contains("--array"), "{f}");
    }
}
