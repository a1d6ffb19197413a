//! The sweep harness: thread-count invariance, resume after interruption (only records whose
//! fingerprint matches are reused), shard + merge, and a smoke test of the whole reproduction in
//! `--quick` form: on an empty directory it executes every run, a changed study config is
//! computed again even with `--resume`, an unchanged one is reused.

use std::path::{Path, PathBuf};

use experiments::engine::RunMode;
use experiments::reproduce::{figure_files, reproduce, Done, Options};
use experiments::study::Study;
use experiments::sweep::{merge, run_sweep, Recompute, Shard, SweepOptions, SweepOutcome};
use identify::record::RunRecord;

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-harness-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
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

fn sweep_with(
    study: &Study,
    dir: &Path,
    threads: usize,
    shard: Shard,
    resume: bool,
) -> SweepOutcome<RunRecord> {
    let opts = SweepOptions {
        threads,
        shard,
        progress: false,
        label: "test".into(),
        resume,
    };
    run_sweep(
        &study.jobs(),
        Study::job_id,
        |j| study.job_fingerprint(j),
        dir,
        &opts,
        |j| study.run_job(j),
    )
    .unwrap()
}

fn sweep(study: &Study, dir: &Path, threads: usize, shard: Shard) -> Vec<RunRecord> {
    sweep_with(study, dir, threads, shard, false).records
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
    let (_tmp_one, one) = temp_dir("t1");
    let (_tmp_two, two) = temp_dir("t2");
    let a = sweep(&study, &one, 1, Shard::default());
    let b = sweep(&study, &two, 2, Shard::default());
    assert_eq!(a.len(), 12);
    assert!(a.iter().all(|r| !r.is_failure()), "a small run failed");
    assert_eq!(
        canonical(&a),
        canonical(&b),
        "1 thread and 2 threads differ"
    );

    // Every record carries the fingerprint its job predicts.
    for (job, r) in study.jobs().iter().zip(&a) {
        assert_eq!(
            r.fingerprint.as_ref().unwrap().sha256,
            study.job_fingerprint(job).unwrap()
        );
    }

    // Resume: drop some records (as if the sweep was interrupted) and run again.
    let (_tmp_resumed, resumed) = temp_dir("resume");
    sweep(&study, &resumed, 2, Shard::default());
    let mut removed = 0;
    for (i, job) in study.jobs().iter().enumerate() {
        if i % 3 != 0 {
            std::fs::remove_file(resumed.join(format!("{}.json", Study::job_id(job)))).unwrap();
            removed += 1;
        }
    }
    assert!(removed > 0);
    let c = sweep_with(&study, &resumed, 2, Shard::default(), true);
    assert_eq!((c.executed, c.reused), (removed, 12 - removed));
    assert_eq!(c.recomputed.get(&Recompute::Missing), Some(&removed));
    assert_eq!(
        canonical(&a),
        canonical(&c.records),
        "resumed sweep differs"
    );
    assert_eq!(
        read_dir_records(&resumed),
        read_dir_records(&one),
        "files differ"
    );
    // Without --resume every run is computed again.
    let again = sweep_with(&study, &resumed, 2, Shard::default(), false);
    assert_eq!((again.executed, again.reused), (12, 0));
    assert_eq!(again.recomputed.get(&Recompute::NotResuming), Some(&12));

    // A changed master seed or duration: nothing is reused, even when resuming.
    for change in [
        |s: &mut Study| s.sweep.master_seed += 1,
        |s: &mut Study| s.data.duration = Some(1.5),
    ] {
        let mut changed = study.clone();
        change(&mut changed);
        let d = sweep_with(&changed, &resumed, 2, Shard::default(), true);
        assert_eq!((d.executed, d.reused), (12, 0));
        assert_eq!(d.recomputed.get(&Recompute::FingerprintChanged), Some(&12));
        // Put the original records back for what follows.
        let back = sweep_with(&study, &resumed, 2, Shard::default(), true);
        assert_eq!(back.executed, 12);
    }

    // A damaged record is computed again, with the reason.
    let victim = resumed.join(format!("{}.json", Study::job_id(&study.jobs()[5])));
    let text = std::fs::read(&victim).unwrap();
    std::fs::write(&victim, &text[..text.len() / 2]).unwrap();
    let e = sweep_with(&study, &resumed, 2, Shard::default(), true);
    assert_eq!((e.executed, e.reused), (1, 11));
    assert_eq!(e.recomputed.get(&Recompute::Unreadable), Some(&1));
    assert_eq!(read_dir_records(&resumed), read_dir_records(&one));

    // Shards 0/2 and 1/2 into separate directories, merged, equal the unsharded sweep.
    let (_tmp_s0, s0) = temp_dir("shard0");
    let (_tmp_s1, s1) = temp_dir("shard1");
    let r0 = sweep(&study, &s0, 1, Shard { index: 0, count: 2 });
    let r1 = sweep(&study, &s1, 1, Shard { index: 1, count: 2 });
    assert_eq!(r0.len() + r1.len(), 12);
    let (_tmp_merged, merged) = temp_dir("merged");
    let pairs = |parts: &[&PathBuf]| -> Vec<(PathBuf, PathBuf)> {
        parts
            .iter()
            .map(|p| ((*p).clone(), merged.clone()))
            .collect()
    };
    let n = merge::<RunRecord>(&pairs(&[&s0, &s1])).unwrap();
    assert_eq!((n.copied, n.present, n.replaced.len()), (12, 0, 0));
    assert_eq!(
        read_dir_records(&merged),
        read_dir_records(&one),
        "merged shards differ"
    );
    // Merging the same part twice is idempotent.
    let again = merge::<RunRecord>(&pairs(&[&s0])).unwrap();
    assert_eq!((again.copied, again.present), (0, 6));
}

/// Every file under `dir` (recursively) with its bytes.
fn dir_bytes(dir: &Path) -> std::collections::BTreeMap<std::path::PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if !p.ends_with(".sysid.lock") {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn quick(experiments: &Path, out: &Path, resume: bool) -> Done {
    reproduce(&Options {
        experiments: experiments.to_path_buf(),
        out: out.to_path_buf(),
        mode: RunMode {
            quick: true,
            resume,
            ..RunMode::quiet(0)
        },
    })
    .unwrap()
}

#[test]
fn quick_reproduction_draws_every_figure_and_the_report() {
    let (_tmp_out, out) = temp_dir("quick");
    let experiments = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    // A fresh output directory: every run is executed.
    let done = quick(&experiments, &out, false);
    // 22 runs of the paper's studies, 2 × 12 of the discretisation studies.
    assert_eq!(done.total, 46);
    assert_eq!((done.executed, done.reused), (46, 0));
    for f in figure_files(&out)
        .into_iter()
        .chain(experiments::discretisation::figure_files(&out))
    {
        identify::figures::validate_svg(&f).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
    }
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    for needle in [
        "Table I",
        "Fig. 4",
        "Fig. 7",
        "Fig. 8",
        "What matches",
        "Provenance",
        "Beyond the paper: discretisation",
        "### 100 Hz against 200 Hz",
    ] {
        assert!(report.contains(needle), "REPORT.md lacks {needle}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(summary["studies"]["fig7"]
        .as_array()
        .is_some_and(|a| a.len() == 4));
    let last_run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("last-run.json")).unwrap()).unwrap();
    assert_eq!(last_run["facts"]["runs"]["executed"], 46);

    // The same configs with --resume: everything is reused.
    let same = quick(&experiments, &out, true);
    assert_eq!((same.executed, same.reused), (0, 46));

    // Recomputing every run (no --resume) agrees with the records, so every file but
    // last-run.json stays byte for byte as it was: a reproduction that agrees leaves the
    // committed results unchanged (run-to-run timings live in last-run.json only).
    let before = dir_bytes(&out);
    let again = quick(&experiments, &out, false);
    assert_eq!((again.executed, again.reused), (46, 0));
    let after = dir_bytes(&out);
    assert_eq!(
        before.keys().collect::<Vec<_>>(),
        after.keys().collect::<Vec<_>>()
    );
    for (path, bytes) in &before {
        if path.ends_with("last-run.json") {
            continue;
        }
        assert!(after[path] == *bytes, "{} changed", path.display());
    }

    // Changed configs (fig7's master seed, fig4's quick duration) with --resume: the records of
    // those studies are computed again, the others reused.
    let (_tmp_changed, changed) = temp_dir("quick-changed-configs");
    for name in experiments::reproduce::STUDIES {
        let file = format!("{name}.toml");
        let mut text = std::fs::read_to_string(experiments.join(&file)).unwrap();
        match name {
            "fig7" => text = text.replace("master_seed = 2016", "master_seed = 2017"),
            "fig4" => text = text.replace("duration = 8.0", "duration = 7.0"),
            _ => {}
        }
        std::fs::write(changed.join(&file), text).unwrap();
    }
    let redone = quick(&changed, &out, true);
    assert_eq!((redone.executed, redone.reused), (16 + 1, 5));
}
