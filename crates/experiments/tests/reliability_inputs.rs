//! Every input is a regular file within the size limit, checked before it is read (issue 50,
//! item 7): a symbolic link to `/dev/zero`, a named pipe and a sparse file of 3 GiB, given as
//! each input of each command, are refused at once with an error naming the file, instead of
//! being read without bound or waiting forever for a writer.
#![cfg(unix)]

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Longer than any of these refusals takes (they read nothing), far shorter than reading
/// `/dev/zero` up to the size limit or waiting on a pipe.
const PATIENCE: Duration = Duration::from_secs(20);

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `sysid args` in `cwd`, killing it when it takes longer than [`PATIENCE`] (a hang).
/// Returns its output and how long it ran.
fn run_within(args: &[&str], cwd: &Path) -> (Output, Duration) {
    let started = Instant::now();
    let mut child = sysid()
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    loop {
        if child.try_wait().unwrap().is_some() {
            return (child.wait_with_output().unwrap(), started.elapsed());
        }
        if started.elapsed() > PATIENCE {
            child.kill().unwrap();
            let o = child.wait_with_output().unwrap();
            panic!(
                "`sysid {}` still running after {PATIENCE:?} (a hang or an unbounded read): {}",
                args.join(" "),
                stderr(&o)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The three hostile inputs in `dir`: a link to `/dev/zero`, a named pipe, a 3 GiB sparse file,
/// each with the given file name and a word its refusal must hold.
fn hostile(dir: &Path, name: &str) -> Vec<(PathBuf, &'static str)> {
    std::fs::create_dir_all(dir).unwrap();
    let zero = dir.join(format!("zero-{name}"));
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let fifo = dir.join(format!("fifo-{name}"));
    let o = Command::new("mkfifo").arg(&fifo).output().unwrap();
    assert!(o.status.success(), "mkfifo: {}", stderr(&o));
    let huge = dir.join(format!("huge-{name}"));
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(3 << 30)
        .unwrap();
    vec![
        (zero, "a device"),
        (fifo, "a named pipe"),
        (huge, "more than the"),
    ]
}

/// `args` with `{}` replaced by `path` refuse it quickly, naming it and saying why.
fn refuses_each(args: &[&str], inputs: &[(PathBuf, &str)], cwd: &Path) -> Duration {
    let mut slowest = Duration::ZERO;
    for (path, why) in inputs {
        let p = path.to_str().unwrap();
        let a: Vec<String> = args.iter().map(|a| a.replace("{}", p)).collect();
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let (o, took) = run_within(&a, cwd);
        let err = stderr(&o);
        assert!(
            matches!(o.status.code(), Some(1 | 2)),
            "`sysid {}`: {:?}: {err}",
            a.join(" "),
            o.status
        );
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains(p) && err.contains(why),
            "`sysid {}`: the refusal does not name {p} and say `{why}`: {err}",
            a.join(" ")
        );
        slowest = slowest.max(took);
    }
    slowest
}

const STUDY: &str = r#"
name = "mini"
description = "input test"
[data]
preset = "shear-chain"
duration = 0.5
[sweep]
algorithms = ["mpf-ekf2"]
runs = 1
master_seed = 3
[filter]
particles = 20
"#;

#[test]
fn every_input_is_a_regular_file_within_the_size_limit() {
    let (_tmp, dir) = common::temp_dir("sysid-inputs-");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    // A small data set and a record of it.
    let (o, _) = run_within(
        &["simulate", "--duration", "1", "--seed", "1", "--out", "d"],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let (o, _) = run_within(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "20",
            "--data",
            "d",
            "--out",
            "run.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));

    let mut slowest = Duration::ZERO;
    let mut check = |args: &[&str], name: &str| {
        let inputs = hostile(&dir.join("hostile"), name);
        slowest = slowest.max(refuses_each(args, &inputs, &dir));
    };
    // Channel map of `import`.
    check(&["import", "--map", "{}", "--out", "imported"], "map.toml");
    // A data file named by a map: the frame's map with its ground file replaced.
    let map = std::fs::read_to_string(root.join("experiments/real/frame-bonus-event.toml"))
        .unwrap()
        .replace(
            "../../data/real/",
            &format!("{}/", root.join("data/real").display()),
        );
    let ground = "file = \"";
    let at = map.find("[ground]").unwrap();
    let start = at + map[at..].find(ground).unwrap() + ground.len();
    let end = start + map[start..].find('"').unwrap();
    for (i, input) in hostile(&dir.join("hostile"), "ground.csv")
        .iter()
        .enumerate()
    {
        let m = dir.join(format!("map-{i}.toml"));
        let text = format!("{}{}{}", &map[..start], input.0.display(), &map[end..]);
        std::fs::write(&m, text).unwrap();
        slowest = slowest.max(refuses_each(
            &["import", "--map", m.to_str().unwrap(), "--out", "imported"],
            std::slice::from_ref(input),
            &dir,
        ));
    }
    // `--config` of `filter` and of `field-study`, the excitation of `simulate`.
    let mut check = |args: &[&str], name: &str| {
        let inputs = hostile(&dir.join("hostile"), name);
        slowest = slowest.max(refuses_each(args, &inputs, &dir));
    };
    check(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--data",
            "d",
            "--config",
            "{}",
            "--out",
            "x.json",
        ],
        "filter.toml",
    );
    check(
        &["field-study", "--config", "{}", "--out", "fs"],
        "study.toml",
    );
    check(
        &[
            "simulate",
            "--excitation",
            "{}",
            "--units",
            "g",
            "--out",
            "s",
        ],
        "excitation.csv",
    );
    // A record read by `validate --record` and `plot`.
    check(
        &["validate", "--record", "{}", "--data", "d"],
        "validate.json",
    );
    check(&["plot", "{}", "--out", "figs"], "plot.json");
    // Study files: `study --config`, `cluster submit --config`.
    std::fs::write(dir.join("mini.toml"), STUDY).unwrap();
    check(
        &["study", "--config", "{}", "--out", "st"],
        "study-file.toml",
    );
    check(
        &[
            "cluster",
            "submit",
            "study",
            "--config",
            "{}",
            "--out",
            "cl",
            "--tasks",
            "2",
            "--dry-run",
        ],
        "cluster.toml",
    );
    // A data set whose `measured.csv` is one of them.
    for (i, (path, why)) in hostile(&dir.join("hostile"), "measured.csv")
        .into_iter()
        .enumerate()
    {
        let data = dir.join(format!("field-{i}"));
        std::fs::create_dir(&data).unwrap();
        let measured = data.join("measured.csv");
        if why == "a device" {
            std::os::unix::fs::symlink("/dev/zero", &measured).unwrap();
        } else {
            std::fs::rename(&path, &measured).unwrap();
        }
        let (o, took) = run_within(
            &[
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--data",
                data.to_str().unwrap(),
                "--out",
                "y.json",
            ],
            &dir,
        );
        let err = stderr(&o);
        assert!(matches!(o.status.code(), Some(1 | 2)), "{err}");
        assert!(
            err.contains(measured.to_str().unwrap()) && err.contains(why),
            "{err}"
        );
        slowest = slowest.max(took);
    }
    eprintln!("slowest refusal: {slowest:?}");
}

/// The frame's map with its data files made absolute, so that it can be written anywhere.
fn frame_map(root: &Path) -> String {
    std::fs::read_to_string(root.join("experiments/real/frame-bonus-event.toml"))
        .unwrap()
        .replace(
            "../../data/real/",
            &format!("{}/", root.join("data/real").display()),
        )
}

/// Messages that were unclear (issue 50, item 11) name the file, the line and the key.
#[test]
fn refusals_name_the_key_the_line_and_no_temporary_file() {
    let (_tmp, dir) = common::temp_dir("sysid-inputs-messages-");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let map = frame_map(&root);
    let refused = |args: &[&str], needles: &[&str], absent: &[&str]| {
        let (o, _) = run_within(args, &dir);
        let err = stderr(&o);
        assert!(
            matches!(o.status.code(), Some(1 | 2)),
            "{:?}: {err}",
            o.status
        );
        for n in needles {
            assert!(err.contains(n), "`{n}` not in: {err}");
        }
        for a in absent {
            assert!(!err.contains(a), "`{a}` in: {err}");
        }
        err
    };
    // Channel-map errors name the key (within its table), not the value or a placeholder.
    for (name, edit, line) in [
        ("neg.toml", "storey = -1", 31),
        ("string.toml", "storey = \"1\"", 31),
    ] {
        let m = dir.join(name);
        std::fs::write(&m, map.replacen("storey = 1\n", &format!("{edit}\n"), 1)).unwrap();
        let at = format!("{name}:{line}: key `storey.storey`");
        refused(
            &["import", "--map", m.to_str().unwrap(), "--out", "o"],
            &[&at],
            &["key `-1`", "key `map`"],
        );
    }
    // A byte that is not UTF-8 in a header or comment: the file and its line.
    let ground = root.join("data/real/shake-table/bonus-event/ground.csv");
    let mut bytes = std::fs::read(&ground).unwrap();
    let second = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    bytes.insert(second + 2, 0xff);
    let bad = dir.join("ground.csv");
    std::fs::write(&bad, bytes).unwrap();
    let m = dir.join("utf8.toml");
    std::fs::write(
        &m,
        map.replace(ground.to_str().unwrap(), bad.to_str().unwrap()),
    )
    .unwrap();
    refused(
        &["import", "--map", m.to_str().unwrap(), "--out", "o"],
        &[&format!("{}:2: not UTF-8", bad.display())],
        &[],
    );
    std::fs::write(dir.join("exc.csv"), b"t,acc\n# comment \xff\n0,0\n0.01,1\n").unwrap();
    refused(
        &["simulate", "--excitation", "exc.csv", "--out", "s"],
        &["exc.csv:2: not UTF-8"],
        &[],
    );
    // A deeply nested study is refused with its line and column, not echoed whole.
    let nested = format!("name = {}{}\n", "[".repeat(100_000), "]".repeat(100_000));
    std::fs::write(dir.join("nested.toml"), nested).unwrap();
    let err = refused(
        &["study", "--config", "nested.toml", "--out", "st"],
        &["nested.toml:1:"],
        &["[[[[[[[[[["],
    );
    assert!(err.len() < 1_000, "{} characters: {err}", err.len());
    let err = refused(
        &["field-study", "--config", "nested.toml", "--out", "fs"],
        &["nested.toml:1:"],
        &["[[[[[[[[[["],
    );
    assert!(err.len() < 1_000, "{} characters", err.len());
    // `--report-only` without a study's output says so, naming no temporary file.
    refused(
        &[
            "field-study",
            "--config",
            root.join("experiments/real/study.toml").to_str().unwrap(),
            "--out",
            "nothing-here",
            "--report-only",
        ],
        &[
            "--out nothing-here: no such directory",
            "run the study first",
        ],
        &[".tmp"],
    );
}

/// A field-data set the reader would refuse is not written (issue 50, item 9: the Python
/// `field_data(...).write` wrote sets of 0 or 1 samples and a sensor at storey 2**63 as
/// `a9223372036854775808`, which `load_dataset` then accepted beyond the 200-storey limit).
#[test]
fn data_sets_that_would_not_load_back_are_not_written_nor_read() {
    use models::dataset::{load_dir, LoadedDataset};
    let (_tmp, dir) = common::temp_dir("sysid-inputs-write-");
    let set = |k: usize, sensors: Vec<usize>| LoadedDataset {
        dt: 0.01,
        t: (0..k).map(|i| i as f64 * 0.01).collect(),
        ug_meas: vec![0.5; k],
        y_meas: vec![0.25; k * sensors.len()],
        channels: sensors.len(),
        sensors,
        truth: None,
        meta: None,
    };
    for (name, data, needle) in [
        ("none", set(0, vec![1]), "0 samples, at least 2"),
        ("one", set(1, vec![1]), "1 samples, at least 2"),
        (
            "huge",
            set(5, vec![1 << 63]),
            "storey 9223372036854775808 is not one of 1 to 200",
        ),
        (
            "201",
            set(5, vec![3, 201]),
            "storey 201 is not one of 1 to 200",
        ),
        (
            "zero",
            set(5, vec![0, 2]),
            "storey 0 is not one of 1 to 200",
        ),
        ("order", set(5, vec![2, 1]), "[2, 1] is not increasing"),
    ] {
        let out = dir.join(name);
        let e = data.write_measured_dir(&out).unwrap_err().to_string();
        assert!(
            e.contains(needle) && e.contains(out.to_str().unwrap()),
            "{name}: {e}"
        );
        assert!(!out.exists(), "{name}: written");
    }
    // What is written loads back, at both ends of the storey range.
    for sensors in [vec![1], vec![1, 200]] {
        let out = dir.join(format!("ok-{}", sensors.len()));
        let data = set(2, sensors);
        data.write_measured_dir(&out).unwrap();
        let back = load_dir(&out).unwrap();
        assert_eq!((back.len(), &back.sensors), (2, &data.sensors));
    }
    // The reader refuses a storey beyond the limit, naming the file, line and column.
    let out = dir.join("beyond");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(
        out.join("measured.csv"),
        "t,ug,a9223372036854775808\n0,0,1\n0.01,0,1\n",
    )
    .unwrap();
    let e = load_dir(&out).unwrap_err().to_string();
    assert!(
        e.contains("measured.csv:1: field `a9223372036854775808`")
            && e.contains("beyond the 200 storeys"),
        "{e}"
    );
}

/// What an import decided silently (issue 50, item 12), now refused by name: a storey file cut
/// short to 3 rows (it trimmed the whole import to 2 samples, exit 0), a storey clock ticking at
/// twice or half the ground's rate (resampled), and one file mapped as two storeys through a
/// symbolic link (the duplicate check compared paths only).
#[test]
fn imports_refuse_a_short_channel_another_rate_and_a_linked_duplicate() {
    let (_tmp, dir) = common::temp_dir("sysid-inputs-import-");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let map = frame_map(&root);
    let storey1 = root.join("data/real/shake-table/bonus-event/floor-2.csv");
    let text = std::fs::read_to_string(&storey1).unwrap();
    // The sensor file with its data rows changed by `edit` (index, time stamp in µs, line).
    let variant = |name: &str, edit: &dyn Fn(usize, i64, &str) -> Option<String>| -> PathBuf {
        let mut out = String::new();
        let mut row = 0;
        let mut t0 = None;
        for line in text.lines() {
            let t = line.split(',').next().and_then(|t| t.parse::<i64>().ok());
            match t {
                Some(t) => {
                    let t0 = *t0.get_or_insert(t);
                    if let Some(l) = edit(row, t - t0, line) {
                        out.push_str(&l);
                        out.push('\n');
                    }
                    row += 1;
                }
                None => {
                    out.push_str(line);
                    out.push('\n');
                }
            }
        }
        let p = dir.join(name);
        std::fs::write(&p, out).unwrap();
        p
    };
    let with_storey1 = |name: &str, file: &Path| -> PathBuf {
        let m = dir.join(name);
        std::fs::write(
            &m,
            map.replace(storey1.to_str().unwrap(), file.to_str().unwrap()),
        )
        .unwrap();
        m
    };
    let import = |m: &Path| {
        run_within(
            &["import", "--map", m.to_str().unwrap(), "--out", "o"],
            &dir,
        )
        .0
    };
    // The map as shipped imports.
    let o = import(&with_storey1("as-is.toml", &storey1));
    assert!(o.status.success(), "{}", stderr(&o));
    let refused = |m: &Path, file: &Path, needle: &str| {
        let o = import(m);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains(file.to_str().unwrap())
                && err.contains("storey 1")
                && err.contains(needle),
            "`{needle}` about {} not in: {err}",
            file.display()
        );
    };
    let short = variant("short.csv", &|row, _, l| (row < 3).then(|| l.to_string()));
    refused(
        &with_storey1("short.toml", &short),
        &short,
        "a file cut short?",
    );
    for (name, factor, needle) in [("fast.csv", 2.0, "+100.0 %"), ("slow.csv", 0.5, "-50.0 %")] {
        let file = variant(name, &|_, dt, l| {
            let value = l.split(',').nth(1).unwrap();
            Some(format!(
                "{},{value}",
                1_000_000 + (dt as f64 * factor) as i64
            ))
        });
        refused(&with_storey1(&format!("{name}.toml"), &file), &file, needle);
    }
    // Storey 2 reads storey 1's file through a link.
    let link = dir.join("link.csv");
    std::os::unix::fs::symlink(&storey1, &link).unwrap();
    let storey2 = root.join("data/real/shake-table/bonus-event/floor-1.csv");
    let m = dir.join("linked.toml");
    std::fs::write(
        &m,
        map.replace(storey2.to_str().unwrap(), link.to_str().unwrap()),
    )
    .unwrap();
    let o = import(&m);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("linked.toml") && err.contains("reads the same signal as storey 1"),
        "{err}"
    );
}
