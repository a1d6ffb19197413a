//! `sysid cluster` without a scheduler: the shard command lines a submission's array script
//! runs, executed one by one here, then the finish job's step (merge, check, report) — the
//! result must equal the study run in one piece, timings aside; a missing shard stops the
//! finish before the report and is named; a dry run writes nothing. The same path against a
//! real Slurm, with a cancelled and resubmitted task: `tests/cluster/run.sh`.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use experiments::cluster::compare::compare;
use experiments::cluster::status::status;
use experiments::cluster::submit::{finish, submit};
use experiments::cluster::{ClusterError, Kind, Plan, SlurmOptions};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    common::temp_dir(&format!("sysid-cluster-{tag}-"))
}

/// A study with a structure axis: its records go flat into `records/`, each with a `.cpu`
/// sidecar, so the merge must carry both.
const STRUCTURES: &str = r#"
name = "cluster-structures"
description = "cluster test"
[data]
preset = "shear-chain"
duration = 1.0
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2"]
runs = 3
master_seed = 11
particles = [30]
[filter]
trace_every = 0
loop_every = 0
validate = false

[[sweep.structures]]
label = "n2"
storeys = 2

[[sweep.structures]]
label = "n3"
storeys = 3
duration = 0.5
"#;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn plan(root: &Path, kind: Kind, config: &Path, tasks: usize) -> Plan {
    Plan {
        kind,
        config: config.to_path_buf(),
        out: root.join("out"),
        quick: false,
        tasks,
        cpus_per_task: 1,
        sysid: PathBuf::from(env!("CARGO_BIN_EXE_sysid")),
        slurm: SlurmOptions::default(),
    }
}

/// Runs shard `i` with the command line of the plan's array script.
fn run_shard(plan: &Plan, i: usize) {
    let part = plan.part(i);
    let o = sysid()
        .args(plan.shard_args(&i.to_string(), &part.display().to_string()))
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "shard {i}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn a_structure_study_run_as_shards_and_finished_equals_the_study_run_whole() {
    let (_tmp, root) = temp_dir("structures");
    let config = root.join("study.toml");
    std::fs::write(&config, STRUCTURES).unwrap();
    let plan = plan(&root, Kind::Scaling, &config, 4);
    plan.save().unwrap();
    for i in 0..plan.tasks {
        run_shard(&plan, i);
    }
    let before = status(&plan, false).unwrap();
    assert_eq!((before.total, before.in_parts, before.merged), (12, 12, 0));
    assert!(before.failed_shards().is_empty());

    let done = finish(&plan).unwrap();
    assert_eq!((done.runs, done.merged.copied), (12, 12));
    let records = plan.out.join("records");
    let cpu = std::fs::read_dir(&records)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "cpu")
        })
        .count();
    assert_eq!(
        cpu, 12,
        "the .cpu sidecars were not merged with their records"
    );
    assert!(plan.out.join("REPORT.md").is_file());

    let local = root.join("local");
    let o = sysid()
        .args(["scaling", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&local)
        .args(["--threads", "2"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let diffs = compare(&local, &plan.out).unwrap();
    assert!(diffs.is_empty(), "{diffs:#?}");

    // The comparison is not blind: a changed record is a difference.
    let one = std::fs::read_dir(&records)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "json"))
        .unwrap();
    let text = std::fs::read_to_string(&one).unwrap();
    let changed = text.replacen("\"seed\": ", "\"seed\": 1", 1);
    assert_ne!(changed, text);
    std::fs::write(&one, changed).unwrap();
    assert_eq!(compare(&local, &plan.out).unwrap().len(), 1);
}

#[test]
fn a_missing_shard_stops_the_finish_before_the_report_and_is_named() {
    let (_tmp, root) = temp_dir("missing");
    let config = root.join("study.toml");
    std::fs::write(&config, STRUCTURES).unwrap();
    let plan = plan(&root, Kind::Study, &config, 3);
    plan.save().unwrap();
    run_shard(&plan, 0);
    run_shard(&plan, 2);
    let err = finish(&plan).unwrap_err();
    let text = err.to_string();
    assert!(
        matches!(
            err,
            ClusterError::Incomplete {
                missing: 4,
                total: 12,
                ..
            }
        ),
        "{text}"
    );
    assert!(text.contains("shard 1: 0 of 4 runs done"), "{text}");
    assert!(!plan.out.join("REPORT.md").exists());
    // The finished shards were merged all the same, and the status says what is left.
    let st = status(&plan, false).unwrap();
    assert_eq!((st.merged, st.failed_shards()), (8, vec![1]));
    run_shard(&plan, 1);
    finish(&plan).unwrap();
    assert!(plan.out.join("REPORT.md").is_file());
}

#[test]
fn a_dry_run_writes_nothing_and_too_many_tasks_are_refused() {
    let (_tmp, root) = temp_dir("dry");
    let config = root.join("study.toml");
    std::fs::write(&config, STRUCTURES).unwrap();
    let p = plan(&root, Kind::Study, &config, 4);
    let (submitted, runs, scripts) = submit(&p, true).unwrap();
    assert_eq!(runs, 12);
    assert!(!p.out.exists(), "a dry run wrote {}", p.out.display());
    assert!(submitted.commands[0].contains("--array=0-3"));
    assert!(scripts[0].contains("--shard \"${task}/4\""));
    let too_many = plan(&root, Kind::Study, &config, 13);
    let e = submit(&too_many, true).unwrap_err().to_string();
    assert!(e.contains("--tasks 13") && e.contains("12 runs"), "{e}");
    let bad = root.join("bad.toml");
    std::fs::write(&bad, STRUCTURES.replace("runs = 3", "runs = \"x\"")).unwrap();
    let e = submit(&plan(&root, Kind::Study, &bad, 2), true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.toml"), "{e}");
}
