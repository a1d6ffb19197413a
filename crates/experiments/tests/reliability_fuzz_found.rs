//! What the fuzz driver (`cargo xtask fuzz`, `experiments::fuzz`) found in its first runs,
//! kept as tests: outputs of `reference`, `information` and `compare-reference` written over
//! the command's own inputs, a lock file that is a named pipe (`merge` waited forever), files
//! asked for that a closed standard output kept from being written, refusals that quoted a
//! mutated value of 100,000 characters whole, an information limit cut short that made
//! `information --limit` panic, a storey count of 2⁶³ that made `filter` panic on field data,
//! and a scaling run's CPU-time file that was a named pipe (`scaling --report-only` waited
//! forever). (A figure name that is a named pipe is in
//! `reliability_figures.rs`; values quoted by the readers in `models`' fuzz corpus.)
#![cfg(unix)]

use crate::common;

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn run(args: &[&str], cwd: &Path) -> Output {
    sysid()
        .args(args)
        .current_dir(cwd)
        .env("RAYON_NUM_THREADS", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// Refused with exit 1 and a message holding every one of `needles`.
fn refused(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{:?}: {err}", o.status);
    for n in needles {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

/// A small simulated data set `d`, a linear one `lin` (3 s: Newton's ascent of the
/// information limit needs it), a record of each and a reference posterior of `d`.
fn inputs(dir: &Path) {
    ok(&run(
        &["simulate", "--duration", "0.5", "--seed", "1", "--out", "d"],
        dir,
    ));
    ok(&run(
        &[
            "simulate",
            "--duration",
            "3",
            "--seed",
            "1",
            "--hysteretic",
            "none",
            "--out",
            "lin",
        ],
        dir,
    ));
    for (data, out) in [("d", "run.json"), ("lin", "runlin.json")] {
        ok(&run(
            &[
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--particles",
                "20",
                "--data",
                data,
                "--out",
                out,
            ],
            dir,
        ));
    }
}

const REFERENCE: [&str; 13] = [
    "reference",
    "--data",
    "d",
    "--particles",
    "10",
    "--iterations",
    "20",
    "--burn-in",
    "5",
    "--probe",
    "2",
    "--out",
    "ref.json",
];

/// `--out` (and `--table`) naming a file the command reads is refused before any work, naming
/// both options; the file is left as it was. (The fuzz driver found `reference --out
/// d/measured.csv` and `information --out lin/measured.csv` replacing the data, exit 0.)
#[test]
fn outputs_of_reference_information_and_compare_reference_are_never_their_inputs() {
    let (_tmp, dir) = common::temp_dir("sysid-found-outputs-");
    inputs(&dir);
    ok(&run(&REFERENCE, &dir));
    let before: Vec<(String, Vec<u8>)> = [
        "d/measured.csv",
        "d/dataset.json",
        "lin/measured.csv",
        "run.json",
        "runlin.json",
        "ref.json",
    ]
    .iter()
    .map(|f| (f.to_string(), std::fs::read(dir.join(f)).unwrap()))
    .collect();
    fn reference<'a>(out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
        let mut a = REFERENCE[..12].to_vec();
        a.push(out);
        a.extend_from_slice(extra);
        a
    }
    for (args, needles) in [
        (reference("d/measured.csv", &[]), vec!["--out", "--data"]),
        (reference("d/dataset.json", &[]), vec!["--out", "--data"]),
        (
            reference("run.json", &["--start-from", "run.json"]),
            vec!["--out", "--start-from"],
        ),
        (
            vec![
                "information",
                "--data",
                "lin",
                "runlin.json",
                "--out",
                "lin/measured.csv",
            ],
            vec!["--out", "--data"],
        ),
        (
            vec![
                "information",
                "--data",
                "lin",
                "runlin.json",
                "--table",
                "runlin.json",
            ],
            vec!["--table", "a record"],
        ),
        (
            vec![
                "compare-reference",
                "--reference",
                "ref.json",
                "run.json",
                "--out",
                "ref.json",
            ],
            vec!["--out", "--reference"],
        ),
    ] {
        let started = Instant::now();
        let o = run(&args, &dir);
        refused(&o, &needles);
        // Refused before the work: no chain, no Newton's ascent.
        assert!(started.elapsed() < Duration::from_secs(10));
    }
    for (f, bytes) in before {
        assert_eq!(std::fs::read(dir.join(&f)).unwrap(), bytes, "{f} changed");
    }
}

/// `sysid merge` into a directory whose lock is a named pipe: refused at once naming it (it
/// waited for a writer to the pipe forever), the pipe left as it is.
#[test]
fn a_lock_that_is_a_named_pipe_is_refused_at_once() {
    let (_tmp, dir) = common::temp_dir("sysid-found-lock-");
    std::fs::write(
        dir.join("mini.toml"),
        "name = \"mini\"\ndescription = \"lock test\"\n[data]\npreset = \"shear-chain\"\n\
         duration = 0.5\n[sweep]\nalgorithms = [\"mpf-ekf2\"]\nruns = 2\nmaster_seed = 3\n\
         particles = [20]\n[filter]\ntrace_every = 0\nloop_every = 0\nvalidate = false\n",
    )
    .unwrap();
    for (part, shard) in [("part0", "0/2"), ("part1", "1/2")] {
        ok(&run(
            &[
                "study",
                "--config",
                "mini.toml",
                "--out",
                part,
                "--shard",
                shard,
                "--threads",
                "1",
            ],
            &dir,
        ));
    }
    std::fs::create_dir(dir.join("m")).unwrap();
    let lock = dir.join("m/.sysid.lock");
    let o = Command::new("mkfifo").arg(&lock).output().unwrap();
    assert!(o.status.success());
    let mut child = sysid()
        .args(["merge", "--into", "m", "part0", "part1"])
        .current_dir(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            panic!("merge still waits on the lock that is a named pipe after 20 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    refused(&o, &[".sysid.lock", "named pipe"]);
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&lock)
        .unwrap()
        .file_type()
        .is_fifo());
}

/// `reference --out` and `information --table` are written before the table is printed: a
/// closed standard output ends the command (SIGPIPE) with the file already there.
#[test]
fn files_asked_for_are_written_before_standard_output() {
    let (_tmp, dir) = common::temp_dir("sysid-found-pipe-");
    inputs(&dir);
    for (args, file) in [
        (REFERENCE.to_vec(), "ref.json"),
        (
            vec![
                "information",
                "--data",
                "lin",
                "runlin.json",
                "--table",
                "t.md",
            ],
            "t.md",
        ),
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = sysid()
            .args(&args)
            .current_dir(&dir)
            .env("RAYON_NUM_THREADS", "1")
            .stdout(Stdio::from(writer))
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        assert_eq!(
            o.status.signal(),
            Some(13),
            "{:?}: {}",
            o.status,
            stderr(&o)
        );
        assert!(dir.join(file).is_file(), "{file} not written");
    }
}

/// A refusal quotes a value of the input by its start and length: a cell of 100,000 brackets
/// in an excitation record, in `truth.csv`, or an AT2 header line of 1,000,000 digits gave
/// messages of 0.2–1 MB.
#[test]
fn refusals_quote_long_values_by_their_start_and_length() {
    let (_tmp, dir) = common::temp_dir("sysid-found-long-");
    let cell = format!("-0.03{}", "{".repeat(100_000));
    std::fs::write(
        dir.join("exc.csv"),
        format!("t,acc\n0,0.1\n0.02,{cell}\n0.04,0.2\n"),
    )
    .unwrap();
    std::fs::write(
        dir.join("rec.AT2"),
        format!(
            "PEER\nSynthetic\nUNITS OF G\n{}\n .1 .2\n",
            "9".repeat(1_000_000)
        ),
    )
    .unwrap();
    for (file, field) in [
        ("exc.csv", "exc.csv:3: field `acc`"),
        ("rec.AT2", "rec.AT2:4"),
    ] {
        let o = run(&["simulate", "--excitation", file, "--out", "s"], &dir);
        refused(&o, &[field, "characters)"]);
        assert!(stderr(&o).len() < 1_000, "{} bytes", stderr(&o).len());
    }
    ok(&run(
        &["simulate", "--duration", "0.5", "--seed", "1", "--out", "d"],
        &dir,
    ));
    let truth = std::fs::read_to_string(dir.join("d/truth.csv")).unwrap();
    let mut lines: Vec<String> = truth.lines().map(str::to_string).collect();
    lines[3] = format!("{}{}", lines[3], "[".repeat(100_000));
    std::fs::write(dir.join("d/truth.csv"), lines.join("\n") + "\n").unwrap();
    // Without the digests, so the reader meets the cell.
    let meta = dir.join("d/dataset.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&meta).unwrap()).unwrap();
    json.as_object_mut().unwrap().remove("files");
    std::fs::write(&meta, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    let o = run(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "20",
            "--data",
            "d",
            "--out",
            "r.json",
        ],
        &dir,
    );
    refused(&o, &["truth.csv:4: field", "characters)"]);
    assert!(stderr(&o).len() < 1_000, "{} bytes", stderr(&o).len());
}

/// An information limit whose `mle` lost an entry (the fuzz driver cut 22 bytes of one) made
/// `information --limit` panic (index out of bounds); it is refused naming the file, the line
/// and the field. So are the other lists of another length and a limit without parameters.
#[test]
fn an_information_limit_of_another_shape_is_refused_by_field() {
    let (_tmp, dir) = common::temp_dir("sysid-found-limit-");
    inputs(&dir);
    ok(&run(
        &["information", "--data", "lin", "--out", "lim.json"],
        &dir,
    ));
    let text = std::fs::read_to_string(dir.join("lim.json")).unwrap();
    let good: serde_json::Value = serde_json::from_str(&text).unwrap();
    ok(&run(
        &["information", "--limit", "lim.json", "runlin.json"],
        &dir,
    ));
    for (field, edit) in [
        ("mle", "pop"),
        ("sd", "push"),
        ("truth", "pop"),
        ("names", "clear"),
    ] {
        let mut v = good.clone();
        let list = v[field].as_array_mut().unwrap();
        match edit {
            "pop" => {
                list.pop();
            }
            "push" => list.push(serde_json::json!(1.0)),
            _ => list.clear(),
        }
        std::fs::write(
            dir.join("bad.json"),
            serde_json::to_string_pretty(&v).unwrap(),
        )
        .unwrap();
        let o = run(&["information", "--limit", "bad.json", "runlin.json"], &dir);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{field}: {err}");
        assert!(
            err.contains("bad.json:") && err.contains(&format!("field `{field}`")),
            "{field}: {err}"
        );
    }
}

/// `filter` on field data with `--storeys 9223372036854775808` (or a `[structure]` that says
/// so) panicked (capacity overflow: one mass per storey); the count is refused by name.
#[test]
fn a_storey_count_beyond_the_limit_is_refused_on_field_data() {
    let (_tmp, dir) = common::temp_dir("sysid-found-storeys-");
    ok(&run(
        &["simulate", "--duration", "0.5", "--seed", "1", "--out", "d"],
        &dir,
    ));
    std::fs::create_dir(dir.join("field")).unwrap();
    std::fs::copy(dir.join("d/measured.csv"), dir.join("field/measured.csv")).unwrap();
    for storeys in ["9223372036854775808", "201", "0"] {
        let o = run(
            &[
                "filter",
                "--data",
                "field",
                "--algorithm",
                "mpf-ekf2",
                "--particles",
                "20",
                "--storeys",
                storeys,
                "--hysteretic",
                "1",
                "--masses",
                "1",
                "--measurement",
                "relative",
                "--out",
                "r.json",
            ],
            &dir,
        );
        refused(&o, &["--storeys"]);
    }
    std::fs::write(
        dir.join("big.toml"),
        "[structure]\nstoreys = 9223372036854775807\nhysteretic = [1]\nmasses = [1.0]\n\
         measurement = \"relative\"\n",
    )
    .unwrap();
    let o = run(
        &[
            "filter",
            "--data",
            "field",
            "--algorithm",
            "mpf-ekf2",
            "--config",
            "big.toml",
            "--out",
            "r.json",
        ],
        &dir,
    );
    refused(&o, &["storeys", "exceeds the maximum 200"]);
}

/// A scaling study's report from records whose CPU-time file is a named pipe: the time counts
/// as unknown and the report is written, at once (it waited on the pipe forever).
#[test]
fn a_cpu_time_file_that_is_a_named_pipe_is_not_waited_on() {
    let (_tmp, dir) = common::temp_dir("sysid-found-cpu-");
    std::fs::write(
        dir.join("sc.toml"),
        "name = \"scaling\"\ndescription = \"cpu test\"\n[data]\npreset = \"building-chain\"\n\
         duration = 0.5\n[sweep]\nalgorithms = [\"mpf-ekf2\"]\nruns = 1\nmaster_seed = 5\n\
         particles = [20]\n[filter]\ntrace_every = 0\nloop_every = 0\nvalidate = false\n\
         [[sweep.structures]]\nlabel = \"n3\"\nstoreys = 3\nscale = 50.0\n",
    )
    .unwrap();
    let args = [
        "scaling",
        "--config",
        "sc.toml",
        "--out",
        "sc",
        "--threads",
        "1",
    ];
    ok(&run(&args, &dir));
    let cpu = std::fs::read_dir(dir.join("sc/records"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "cpu"))
        .expect("a CPU-time file");
    std::fs::remove_file(&cpu).unwrap();
    let o = Command::new("mkfifo").arg(&cpu).output().unwrap();
    assert!(o.status.success());
    let started = Instant::now();
    let report = [&args[..], &["--report-only"]].concat();
    let mut child = sysid()
        .args(&report)
        .current_dir(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            panic!("scaling --report-only still waits on the named pipe after 20 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    ok(&child.wait_with_output().unwrap());
}
