//! `sysid merge` as a user runs it: killed at random points it never leaves a record that fails
//! to read, and running it again completes the merge; corrupt source records are named and
//! nothing is written; a second writer to an output directory is refused with the holder named,
//! and the lock of a killed writer is taken over.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};
use std::time::{Duration, Instant};

use experiments::study::Study;
use experiments::sweep::lock::{DirLock, LOCK_FILE};
use experiments::sweep::{read_record, run_sweep, SweepOptions};
use identify::record::RunRecord;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-merge-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// Two shard outputs (`part0/records/s/`, `part1/records/s/`) of a study of `runs` runs × 2
/// algorithms on 1 s of data with a trace at every step (records of some 40 kB).
fn shards(root: &Path, runs: u64) -> Vec<PathBuf> {
    let study: Study = toml::from_str(&format!(
        r#"
name = "s"
description = "merge test"
[data]
preset = "paper-3dof"
duration = 1.0
[sweep]
algorithms = ["bootstrap", "mpf-ekf2"]
runs = {runs}
master_seed = 3
particles = [10]
[filter]
trace_every = 1
loop_every = 1
"#
    ))
    .unwrap();
    (0..2)
        .map(|i| {
            let part = root.join(format!("part{i}"));
            let opts = SweepOptions {
                threads: 2,
                shard: format!("{i}/2").parse().unwrap(),
                progress: false,
                label: "s".into(),
                resume: false,
            };
            run_sweep(
                &study.jobs(),
                Study::job_id,
                |j| study.job_fingerprint(j),
                &part.join("records/s"),
                &opts,
                |j| study.run_job(j),
            )
            .unwrap();
            part
        })
        .collect()
}

fn merge_cmd(parts: &[PathBuf], into: &Path) -> Command {
    let mut c = sysid();
    c.arg("merge").args(parts).arg("--into").arg(into);
    c
}

fn json_files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|r| r.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    v.retain(|p| p.extension().is_some_and(|x| x == "json"));
    v.sort();
    v
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// SplitMix64: a fixed, seeded sequence of kill delays.
struct SplitMix(u64);
impl SplitMix {
    fn next_unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn merge_killed_at_random_points_never_leaves_an_unreadable_record() {
    let (_tmp, root) = temp_dir("kill");
    let parts = shards(&root, 120);
    let sources: Vec<PathBuf> = parts
        .iter()
        .flat_map(|p| json_files(&p.join("records/s")))
        .collect();
    assert_eq!(sources.len(), 240);

    // How long an uninterrupted merge takes here.
    let scratch = root.join("scratch");
    let t0 = Instant::now();
    let o = merge_cmd(&parts, &scratch).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let full = t0.elapsed();

    // The target starts with what an older tool could leave: a truncated record under a name
    // a source also has, and a temporary file of a dead process. When a merge completes before
    // its kill, the target is reset to this state, so that every kill meets a merge at work.
    let target = root.join("target");
    let dst = target.join("records/s");
    let victim = sources[7].file_name().unwrap().to_owned();
    let stale_tmp = dst.join("x.json.tmp4294967");
    let reset = || {
        let _ = std::fs::remove_dir_all(&target);
        std::fs::create_dir_all(&dst).unwrap();
        let text = std::fs::read(&sources[7]).unwrap();
        std::fs::write(dst.join(&victim), &text[..text.len() / 2]).unwrap();
        std::fs::write(&stale_tmp, b"{").unwrap();
    };
    reset();

    let mut rng = SplitMix(20261123);
    let (kills, mut interrupted, mut partial) = (24, 0, 0);
    for _ in 0..kills {
        let delay = full.mul_f64(rng.next_unit());
        let mut child: Child = merge_cmd(&parts, &target)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(delay);
        if child.try_wait().unwrap().is_none() {
            interrupted += 1;
        }
        child.kill().ok();
        child.wait().unwrap();
        let present = json_files(&dst).len();
        partial += usize::from(present > 1 && present < sources.len());
        for f in json_files(&dst) {
            if f.file_name() == Some(victim.as_os_str()) {
                // The truncated record is replaced atomically, or still the old one.
                continue;
            }
            read_record::<RunRecord>(&f)
                .unwrap_or_else(|e| panic!("after a kill at {delay:?}: {e:#}"));
        }
        if present == sources.len() {
            reset();
        }
    }
    eprintln!(
        "uninterrupted merge {full:?}; {interrupted} of {kills} kills interrupted a merge, \
         {partial} while it was writing"
    );
    assert!(
        interrupted >= kills / 4 && partial >= 2,
        "only {interrupted} of {kills} kills interrupted a merge, {partial} while it was \
         writing (merge took {full:?})"
    );
    // Leave a half-merged target for the final run.
    reset();
    let mut child = merge_cmd(&parts, &target)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    while json_files(&dst).len() < 20 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(Duration::from_millis(1));
    }
    child.kill().ok();
    child.wait().unwrap();

    // Run again: the merge completes, replaces the truncated record, cleans the temporary file
    // and takes over the stale lock if a kill left one.
    let o = merge_cmd(&parts, &target).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stale_tmp.exists(), "stale temporary file left behind");
    let left: Vec<_> = std::fs::read_dir(&dst)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.contains(".tmp"))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
    assert!(
        !target.join(LOCK_FILE).exists(),
        "lock left after a clean exit"
    );
    let merged = json_files(&dst);
    assert_eq!(merged.len(), sources.len());
    for src in &sources {
        let name = src.file_name().unwrap();
        assert_eq!(
            std::fs::read(dst.join(name)).unwrap(),
            std::fs::read(src).unwrap(),
            "{name:?} differs from its source"
        );
    }
    // And once more: nothing to do.
    let o = merge_cmd(&parts, &target).output().unwrap();
    assert!(o.status.success());
    assert!(
        stderr(&o).contains("0 copied, 0 replaced, 240 already present"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_truncated_target_record_is_replaced_and_a_corrupt_source_is_named() {
    let (_tmp, root) = temp_dir("corrupt");
    let parts = shards(&root, 3);
    let target = root.join("target");
    let dst = target.join("records/s");
    std::fs::create_dir_all(&dst).unwrap();
    let src = json_files(&parts[0].join("records/s"));
    let name = src[0].file_name().unwrap();
    let text = std::fs::read(&src[0]).unwrap();
    std::fs::write(dst.join(name), &text[..100]).unwrap();
    let o = merge_cmd(&parts, &target).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("replaced"), "{}", stderr(&o));
    assert!(stderr(&o).contains("cut short"), "{}", stderr(&o));
    assert_eq!(std::fs::read(dst.join(name)).unwrap(), text);

    // A truncated record inside a part: named, non-zero exit, nothing written.
    let bad = src[1].clone();
    let t = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, &t[..t.len() - 10]).unwrap();
    let fresh = root.join("fresh");
    let o = merge_cmd(&parts, &fresh).output().unwrap();
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains(&bad.display().to_string()), "{e}");
    assert!(e.contains("nothing was written"), "{e}");
    assert!(json_files(&fresh.join("records/s")).is_empty());
}

#[test]
fn a_second_writer_is_refused_with_the_holder_named() {
    let (_tmp, root) = temp_dir("lock");
    let parts = shards(&root, 1);
    let target = root.join("target");

    // This process holds the lock: merge and reproduce are refused, naming it.
    let lock = DirLock::acquire(&target).unwrap();
    let me = format!("pid {}", std::process::id());
    for mut cmd in [merge_cmd(&parts, &target), {
        let mut c = sysid();
        c.args(["reproduce", "--quick", "--out"]).arg(&target);
        c
    }] {
        let o = cmd.output().unwrap();
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains("in use by") && e.contains(&me), "{e}");
    }
    drop(lock);

    // A running reproduction holds its output directory: a merge into it is refused, naming
    // the reproduction; once it is killed, the next merge takes its lock over.
    let experiments = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let mut child = sysid()
        .args(["reproduce", "--quick", "--threads", "1", "--experiments"])
        .arg(&experiments)
        .arg("--out")
        .arg(&target)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    while !target.join(LOCK_FILE).exists() {
        assert!(Instant::now() < deadline, "the reproduction took no lock");
        assert!(
            child.try_wait().unwrap().is_none(),
            "reproduction ended early"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = merge_cmd(&parts, &target).output().unwrap();
    let e = stderr(&o);
    assert!(!o.status.success(), "a merge ran beside a reproduction");
    assert!(e.contains(&format!("pid {}", child.id())), "{e}");
    assert!(e.contains("reproduce"), "{e}");
    child.kill().unwrap();
    child.wait().unwrap();
    let o = merge_cmd(&parts, &target).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("taking over the lock"),
        "{}",
        stderr(&o)
    );
}
