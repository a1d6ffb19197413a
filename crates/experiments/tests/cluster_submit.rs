//! `sysid cluster submit` and `resubmit` against stand-ins for `sbatch`, `squeue` and `scancel`
//! (shell scripts first on PATH that log their arguments and hand out job ids from 101 on): the
//! array and its finish job are submitted with the dependency on the array's real id, the
//! commands printed say so, and every submission is recorded; a resubmission sends only the
//! shard that is neither complete nor queued, cancels the waiting finish job, and makes the new
//! finish job wait for the new array and for the earlier one that still has a queued shard.
#![cfg(unix)]

use crate::common;

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const STUDY: &str = r#"
name = "cluster-submit"
description = "cluster submission test"
[data]
preset = "shear-chain"
duration = 0.5
[sweep]
algorithms = ["mpf-ekf2"]
runs = 2
master_seed = 3
particles = [20]
[filter]
trace_every = 0
loop_every = 0
validate = false
"#;

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    common::temp_dir(&format!("sysid-cluster-{tag}-"))
}

fn script(path: &Path, body: &str) {
    std::fs::write(path, format!("#!/bin/sh\n{body}")).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// Stand-ins for the Slurm commands in `root/bin`, logging to `root/slurm.log`; `squeue`
/// answers with the contents of `root/queue` (empty until the test writes it).
fn fake_slurm(root: &Path) -> PathBuf {
    let bin = root.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let (log, counter, queue) = (
        root.join("slurm.log"),
        root.join("next-id"),
        root.join("queue"),
    );
    std::fs::write(&counter, "101\n").unwrap();
    std::fs::write(&queue, "").unwrap();
    script(
        &bin.join("sbatch"),
        &format!(
            "echo \"sbatch $*\" >> '{log}'\nn=$(cat '{counter}')\necho $((n + 1)) > '{counter}'\n\
             echo \"$n\"\n",
            log = log.display(),
            counter = counter.display()
        ),
    );
    script(
        &bin.join("scancel"),
        &format!("echo \"scancel $*\" >> '{}'\n", log.display()),
    );
    script(
        &bin.join("squeue"),
        &format!(
            "echo \"squeue $*\" >> '{}'\ncat '{}'\n",
            log.display(),
            queue.display()
        ),
    );
    bin
}

fn sysid(bin: &Path, args: &[&str]) -> Output {
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(args)
        .env("PATH", path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "sysid {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn submissions(out: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(out.join("cluster/submissions.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn submissions_chain_the_finish_job_to_the_arrays_real_ids() {
    let (_tmp, root) = temp_dir("submit");
    let bin = fake_slurm(&root);
    let config = root.join("study.toml");
    std::fs::write(&config, STUDY).unwrap();
    let out = root.join("out");
    let (config_s, out_s) = (config.display().to_string(), out.display().to_string());
    let shard = out.join("cluster/shard.sh").display().to_string();
    let finish = out.join("cluster/finish.sh").display().to_string();

    let o = sysid(
        &bin,
        &[
            "cluster", "submit", "study", "--config", &config_s, "--out", &out_s, "--tasks", "2",
        ],
    );
    let printed = String::from_utf8_lossy(&o.stdout);
    assert!(
        printed.contains(&format!("sbatch --parsable --array=0-1 {shard}")),
        "{printed}"
    );
    assert!(
        printed.contains(&format!(
            "sbatch --parsable --dependency=afterany:101 {finish}"
        )),
        "{printed}"
    );
    let s = submissions(&out);
    assert_eq!(s.len(), 1);
    assert_eq!(
        (&s[0]["array_job"], &s[0]["finish_job"], &s[0]["shards"]),
        (
            &serde_json::json!("101"),
            &serde_json::json!("102"),
            &serde_json::json!([0, 1])
        )
    );

    // Shard 1 still pending in array 101, the finish job 102 waiting; shard 0 gone and with
    // no record: only shard 0 is submitted again.
    std::fs::write(
        root.join("queue"),
        "101|1|PENDING|Resources\n102|N/A|PENDING|Dependency\n",
    )
    .unwrap();
    let o = sysid(&bin, &["cluster", "resubmit", "--out", &out_s]);
    let printed: Vec<String> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    assert_eq!(
        printed,
        vec![
            "scancel 102".to_string(),
            format!("sbatch --parsable --array=0 {shard}"),
            format!("sbatch --parsable --dependency=afterany:103:101 {finish}"),
        ]
    );
    let s = submissions(&out);
    assert_eq!(s.len(), 2);
    assert_eq!(
        (&s[1]["array_job"], &s[1]["finish_job"], &s[1]["shards"]),
        (
            &serde_json::json!("103"),
            &serde_json::json!("104"),
            &serde_json::json!([0])
        )
    );
    let log = std::fs::read_to_string(root.join("slurm.log")).unwrap();
    let calls: Vec<&str> = log.lines().filter(|l| !l.starts_with("squeue")).collect();
    assert_eq!(
        calls,
        vec![
            format!("sbatch --parsable --array=0-1 {shard}"),
            format!("sbatch --parsable --dependency=afterany:101 {finish}"),
            "scancel 102".to_string(),
            format!("sbatch --parsable --array=0 {shard}"),
            format!("sbatch --parsable --dependency=afterany:103:101 {finish}"),
        ]
    );
}
