//! `sysid simulate` and the command line: interrupted writes never destroy a data set, flags
//! are bounded and named in errors, negative numbers are values, mismatched data-set files are
//! refused by `filter`.

use models::dataset::{generate, load_dir, DatasetConfig, LoadedDataset};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Instant;

fn sysid() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sysid"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-inputs-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn run(args: &[&str]) -> Output {
    sysid().args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// An exit through an error (1 for a toolkit error, 2 for clap), never a panic (101) or a signal.
fn assert_error_exit(o: &Output, what: &str) {
    let code = o.status.code();
    assert!(
        code == Some(1) || code == Some(2),
        "{what}: exit {:?}, stderr {}",
        o.status,
        stderr(o)
    );
    assert!(!stderr(o).contains("panicked"), "{what}: {}", stderr(o));
}

/// What `sysid simulate --seed <seed> --preset paper-3dof` (whole record) loads back as.
fn expected(seed: u64) -> LoadedDataset {
    generate(&DatasetConfig::from_preset("paper-3dof", seed).unwrap())
        .unwrap()
        .to_loaded()
}

/// splitmix64: fixed-seed delays without a dependency.
struct Delays(u64);
impl Delays {
    fn next_unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn simulate_args(seed: u64, out: &Path) -> Vec<String> {
    vec![
        "simulate".into(),
        "--preset".into(),
        "paper-3dof".into(),
        "--seed".into(),
        seed.to_string(),
        "--out".into(),
        out.display().to_string(),
    ]
}

/// `simulate` killed (SIGKILL) at random points of its run, over and over into the same
/// directory, leaves after every kill either the previous data set or the new one, complete
/// and loadable: never a mix of the two and never nothing.
#[test]
fn simulate_killed_at_random_points_leaves_the_old_or_the_new_data_set() {
    let (_tmp, dir) = temp_dir("kill");
    let ds = dir.join("ds");
    let sets = [expected(1), expected(2)];
    let st = sysid().args(simulate_args(1, &ds)).output().unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert_eq!(load_dir(&ds).unwrap(), sets[0]);
    // The length of one uninterrupted run sets the range of the kill times.
    let start = Instant::now();
    let st = sysid().args(simulate_args(2, &ds)).output().unwrap();
    let full = start.elapsed();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let mut current = 2u64;
    let mut delays = Delays(18);
    let (mut kept_old, mut got_new, mut mid_write) = (0, 0, 0);
    const KILLS: usize = 60;
    for i in 0..KILLS {
        let seed = 3 - current;
        let mut child = sysid()
            .args(simulate_args(seed, &ds))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Uniform over 1.2 × a full run: some kills land after the end.
        let pid = child.id();
        std::thread::sleep(full.mul_f64(1.2 * delays.next_unit()));
        let _ = child.kill();
        child.wait().unwrap();
        let loaded = load_dir(&ds).unwrap_or_else(|e| {
            panic!("kill {i}: the data set does not load: {e}");
        });
        let now = loaded.meta.as_ref().unwrap().seed;
        assert!(now == current || now == seed, "kill {i}: seed {now}");
        assert_eq!(
            loaded,
            sets[now as usize - 1],
            "kill {i}: a mix of data sets"
        );
        if now == seed {
            got_new += 1;
        } else {
            kept_old += 1;
        }
        // This child's staging directory left behind: the kill landed while the files were
        // written or swapped in (the next run removes it, its writer being gone).
        let prefix = format!(".ds.tmp-{pid}-");
        if std::fs::read_dir(&dir).unwrap().any(|e| {
            e.unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with(&prefix)
        }) {
            mid_write += 1;
        }
        current = now;
    }
    eprintln!(
        "{KILLS} kills over {:.0} ms runs: {kept_old} kept the old data set, {got_new} wrote \
         the new one; {mid_write} while the files were written",
        full.as_secs_f64() * 1e3
    );
    // Both outcomes happened, and kills landed while the files were being written.
    assert!(kept_old > 0 && got_new > 0, "{kept_old} / {got_new}");
    assert!(mid_write > 0, "no kill landed during the write");
    // One uninterrupted run removes every leftover of the killed ones.
    let st = sysid().args(simulate_args(1, &ds)).output().unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["ds".to_string()]);
}

#[test]
fn negative_numbers_are_values() {
    let (_tmp, dir) = temp_dir("negative");
    let out = dir.join("flipped");
    let o = run(&[
        "simulate",
        "--scale",
        "-1",
        "--duration",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(load_dir(&out).unwrap().meta.unwrap().config.scale, -1.0);
    // An unsigned option given a negative number: clap's "invalid value", naming the flag.
    let o = run(&["simulate", "--seed", "-1", "--out", "x"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("invalid value '-1' for '--seed <SEED>'"),
        "{}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("unexpected argument"));
}

#[test]
fn simulate_flags_are_bounded_and_named() {
    let (_tmp, dir) = temp_dir("flags");
    let ds = dir.join("ds");
    let o = run(&["simulate", "--duration", "1", "--out", ds.to_str().unwrap()]);
    assert!(o.status.success());
    let before = load_dir(&ds).unwrap();
    let at2 = dir.join("huge.AT2");
    std::fs::write(
        &at2,
        "PEER\nEVENT\nUNITS OF G\nNPTS= 1e30, DT= .0050 SEC\n .1 .2\n",
    )
    .unwrap();
    let csv = dir.join("late.csv");
    std::fs::write(&csv, "t,acc\n0,0.1\n1e300,0.2\n").unwrap();
    let cases: [(&[&str], &str); 8] = [
        (&["--noise-fraction", "1e308"], "--noise-fraction"),
        (&["--noise-fraction", "-0.5"], "--noise-fraction"),
        (&["--storeys", "1000000000"], "--storeys"),
        (&["--duration", "1e12"], "--duration"),
        (&["--duration", "inf"], "--duration"),
        (&["--scale", "1e300"], "--scale"),
        (&["--excitation", at2.to_str().unwrap()], "NPTS"),
        (&["--excitation", csv.to_str().unwrap()], "late.csv:3"),
    ];
    for (flags, named) in cases {
        let mut args = vec!["simulate", "--out", ds.to_str().unwrap()];
        args.extend_from_slice(flags);
        let o = run(&args);
        assert_error_exit(&o, named);
        assert!(stderr(&o).contains(named), "{flags:?}: {}", stderr(&o));
        // The data set already there is untouched.
        assert_eq!(load_dir(&ds).unwrap(), before, "{flags:?}");
    }
    // `--noise-fraction 1e308` once wrote a data set containing −inf.
    let fresh = dir.join("fresh");
    let o = run(&[
        "simulate",
        "--noise-fraction",
        "1e308",
        "--out",
        fresh.to_str().unwrap(),
    ]);
    assert_error_exit(&o, "noise fraction");
    assert!(!fresh.exists());
    // A directory holding anything else is never replaced.
    let o = run(&["simulate", "--out", dir.to_str().unwrap()]);
    assert_error_exit(&o, "--out DIR with other files");
    assert!(stderr(&o).contains("not a data-set file"), "{}", stderr(&o));
    assert!(at2.exists() && ds.exists());
}

#[test]
fn filter_refuses_files_of_different_data_sets() {
    let (_tmp, dir) = temp_dir("mixed");
    let (one, two, mixed) = (dir.join("s1"), dir.join("s2"), dir.join("mixed"));
    for (seed, out) in [("1", &one), ("2", &two)] {
        let o = run(&[
            "simulate",
            "--seed",
            seed,
            "--duration",
            "2",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success());
    }
    // Seed-2 data with seed-1 metadata, as a kill between files once left (and `filter` ran).
    std::fs::create_dir_all(&mixed).unwrap();
    std::fs::copy(one.join("dataset.json"), mixed.join("dataset.json")).unwrap();
    std::fs::copy(one.join("truth.csv"), mixed.join("truth.csv")).unwrap();
    std::fs::copy(two.join("measured.csv"), mixed.join("measured.csv")).unwrap();
    let rec = dir.join("rec.json");
    let o = run(&[
        "filter",
        "--algorithm",
        "bootstrap",
        "--particles",
        "10",
        "--data",
        mixed.to_str().unwrap(),
        "--out",
        rec.to_str().unwrap(),
    ]);
    assert_error_exit(&o, "mixed data set");
    let measured = mixed.join("measured.csv").display().to_string();
    assert!(stderr(&o).contains(&measured), "{}", stderr(&o));
    assert!(!rec.exists());
}
