//! The sweep harness: thread-count invariance, resume after interruption, shard + merge, and a
//! smoke test of the whole reproduction in `--quick` form.

use std::path::{Path, PathBuf};

use experiments::record::RunRecord;
use experiments::reproduce::{figure_files, reproduce, Options};
use experiments::study::Study;
use experiments::sweep::{merge, run_sweep, Shard, SweepOptions};

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sysid-harness-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A small study: 2 s of the paper preset, all four algorithms, 3 runs, 40 particles.
fn small_study() -> Study {
    let text = r#"
name = "small"
description = "harness test"
[data]
preset = "paper-3dof"
duration = 2.0
[sweep]
algorithms = ["bootstrap", "mln-rbpf", "storvik", "mpf-ekf2"]
runs = 3
master_seed = 7
particles = [40]
[filter]
trace_every = 50
loop_every = 20
"#;
    toml::from_str(text).unwrap()
}

fn sweep(study: &Study, dir: &Path, threads: usize, shard: Shard) -> Vec<RunRecord> {
    let opts = SweepOptions {
        threads,
        shard,
        progress: false,
        label: "test".into(),
    };
    run_sweep(&study.jobs(), Study::job_id, dir, &opts, |j| {
        study.run_job(j)
    })
    .unwrap()
}

fn canonical(records: &[RunRecord]) -> Vec<String> {
    records.iter().map(RunRecord::deterministic_json).collect()
}

fn read_dir_records(dir: &Path) -> Vec<String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| {
            let r: RunRecord = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            r.deterministic_json()
        })
        .collect()
}

#[test]
fn sweeps_are_thread_count_invariant_resumable_and_shardable() {
    let study = small_study();
    let one = temp_dir("t1");
    let two = temp_dir("t2");
    let a = sweep(&study, &one, 1, Shard::default());
    let b = sweep(&study, &two, 2, Shard::default());
    assert_eq!(a.len(), 12);
    assert!(a.iter().all(|r| !r.is_failure()), "a small run failed");
    assert_eq!(
        canonical(&a),
        canonical(&b),
        "1 thread and 2 threads differ"
    );

    // Resume: drop some records (as if the sweep was interrupted) and run again.
    let resumed = temp_dir("resume");
    sweep(&study, &resumed, 2, Shard::default());
    let mut removed = 0;
    for (i, job) in study.jobs().iter().enumerate() {
        if i % 3 != 0 {
            std::fs::remove_file(resumed.join(format!("{}.json", Study::job_id(job)))).unwrap();
            removed += 1;
        }
    }
    assert!(removed > 0);
    let c = sweep(&study, &resumed, 2, Shard::default());
    assert_eq!(canonical(&a), canonical(&c), "resumed sweep differs");
    assert_eq!(
        read_dir_records(&resumed),
        read_dir_records(&one),
        "files differ"
    );

    // Shards 0/2 and 1/2 into separate directories, merged, equal the unsharded sweep.
    let s0 = temp_dir("shard0");
    let s1 = temp_dir("shard1");
    let r0 = sweep(&study, &s0, 1, Shard { index: 0, count: 2 });
    let r1 = sweep(&study, &s1, 1, Shard { index: 1, count: 2 });
    assert_eq!(r0.len() + r1.len(), 12);
    let merged = temp_dir("merged");
    let n = merge(&[s0.clone(), s1.clone()], &merged).unwrap();
    assert_eq!(n, 12);
    assert_eq!(
        read_dir_records(&merged),
        read_dir_records(&one),
        "merged shards differ"
    );
    // Merging the same part twice is idempotent.
    assert_eq!(merge(&[s0], &merged).unwrap(), 0);
}

#[test]
fn quick_reproduction_draws_every_figure_and_the_report() {
    let out = temp_dir("quick");
    let experiments = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    reproduce(&Options {
        experiments,
        out: out.clone(),
        quick: true,
        threads: 0,
        shard: Shard::default(),
        progress: false,
    })
    .unwrap();
    for f in figure_files(&out) {
        experiments::figures::validate_svg(&f).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
    }
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    for needle in [
        "Table I",
        "Fig. 4",
        "Fig. 7",
        "Fig. 8",
        "What matches",
        "Provenance",
    ] {
        assert!(report.contains(needle), "REPORT.md lacks {needle}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(summary["studies"]["fig7"]
        .as_array()
        .is_some_and(|a| a.len() == 4));
}
