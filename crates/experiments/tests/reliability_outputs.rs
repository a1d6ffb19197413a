//! The third round of the hostile-user test of `sysid`, kept as regression tests: paths in the
//! batch scripts of `sysid cluster submit`, the bound on `sysid loglik --seeds`, how a command
//! ends when its standard output closes early, outputs that are not regular files or are the
//! command's own inputs, and data-set directories holding a directory where a data-set file
//! belongs.
#![cfg(unix)]

use crate::common;

use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    common::temp_dir(&format!("sysid-out-{tag}-"))
}

fn run(args: &[&str], cwd: &Path) -> Output {
    sysid().args(args).current_dir(cwd).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A non-zero exit that is an error message naming `needle`, not a panic or an abort.
fn refused(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "accepted: {err}");
    assert!(
        matches!(o.status.code(), Some(1 | 2)),
        "{:?}: {err}",
        o.status
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(needle), "`{needle}` not in: {err}");
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

const STUDY: &str = r#"
name = "mini"
description = "cluster script test"
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

/// The text of the script printed after the header `# <path>` in a dry run's output.
fn printed_script(printed: &str, path: &Path) -> String {
    let header = format!("# {}\n", path.display());
    let start = printed.find(&header).expect("script header") + header.len();
    let rest = &printed[start..];
    // Each script is followed by a blank line (the `println!` after its final newline).
    rest[..rest.find("\n\n").expect("end of script") + 1].to_string()
}

/// Every line of a generated script is one the tool writes: nothing a path could have
/// started.
fn only_expected_lines(script: &str) {
    for line in script.lines() {
        assert!(
            [
                "#!/bin/bash",
                "# ",
                "#SBATCH --",
                "set -euo pipefail",
                "task=",
                "part=",
                "rm -f ",
                "echo ",
                "exec ",
            ]
            .iter()
            .any(|p| line.starts_with(p)),
            "unexpected line `{line}` in\n{script}"
        );
    }
}

#[test]
fn cluster_scripts_refuse_paths_that_leave_their_line_and_quote_the_others() {
    let (_tmp, dir) = temp_dir("cluster");
    std::fs::write(dir.join("mini.toml"), STUDY).unwrap();
    let submit = |config: &str, out: &str| {
        run(
            &[
                "cluster",
                "submit",
                "study",
                "--config",
                config,
                "--out",
                out,
                "--tasks",
                "2",
                "--dry-run",
            ],
            &dir,
        )
    };

    // The reproducer: a newline in --out made `touch pwned #...` a line of the script.
    let o = submit("mini.toml", "x\ntouch pwned #");
    refused(&o, "--out");
    assert!(!stdout(&o).contains("touch pwned"), "{}", stdout(&o));
    // A directive of its own, smuggled in through a carriage return or a newline.
    for out in ["x\r#SBATCH --wrap=id", "x\n#SBATCH --wrap=id"] {
        let o = submit("mini.toml", out);
        refused(&o, "--out");
        assert!(!stdout(&o).contains("--wrap"), "{}", stdout(&o));
    }
    // Slurm, not the shell, reads `#SBATCH --output=`: whitespace, `#`, `%` and quotes are
    // refused by name rather than misread.
    for out in ["my runs", "a#b", "100%", "it's", "a\"b", "a\\b"] {
        refused(&submit("mini.toml", out), "--out");
    }
    // The config's path is in a header comment and the shard command: a newline is refused.
    let bad_config = dir.join("a\nb.toml");
    std::fs::write(&bad_config, STUDY).unwrap();
    refused(&submit(bad_config.to_str().unwrap(), "ok"), "--config");
    // A config path with spaces is quoted, not refused: it is in no `#SBATCH` line.
    std::fs::write(dir.join("my study.toml"), STUDY).unwrap();
    let o = submit("my study.toml", "ok");
    ok(&o);
    assert!(
        stdout(&o).contains(&format!(
            "--config '{}'",
            dir.join("my study.toml").canonicalize().unwrap().display()
        )),
        "{}",
        stdout(&o)
    );

    // Characters the shell would act on are quoted: the scripts, run by bash, hand the exact
    // paths to the binary.
    let out = dir.join("a&b$c;d(e)|f`g");
    let args_file = dir.join("args.txt");
    let fake = dir.join("fake-sysid");
    std::fs::write(
        &fake,
        format!(
            "#!/bin/sh\nprintf '%s\\n' \"$@\" > '{}'\n",
            args_file.display()
        ),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let o = run(
        &[
            "cluster",
            "submit",
            "study",
            "--config",
            "mini.toml",
            "--out",
            out.to_str().unwrap(),
            "--tasks",
            "2",
            "--sysid",
            fake.to_str().unwrap(),
            "--dry-run",
        ],
        &dir,
    );
    ok(&o);
    let printed = stdout(&o);
    let cluster = out.join("cluster");
    let shard = printed_script(&printed, &cluster.join("shard.sh"));
    let finish = printed_script(&printed, &cluster.join("finish.sh"));
    only_expected_lines(&shard);
    only_expected_lines(&finish);
    let config = dir.join("mini.toml").canonicalize().unwrap();
    let run_script = |text: &str| {
        let o = Command::new("bash")
            .arg("-c")
            .arg(text)
            .env("SLURM_ARRAY_TASK_ID", "1")
            .current_dir(&dir)
            .output()
            .unwrap();
        ok(&o);
        std::fs::read_to_string(&args_file).unwrap()
    };
    let part = cluster.join("parts/shard-1");
    assert_eq!(
        run_script(&shard),
        format!(
            "study\n--config\n{}\n--out\n{}\n--shard\n1/2\n--resume\n--threads\n1\n",
            config.display(),
            part.display()
        )
    );
    assert_eq!(
        run_script(&finish),
        format!("cluster\nfinish\n--out\n{}\n", out.display())
    );
    // Nothing the shell could have run on its own: no file but the fake's.
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "a\nb.toml",
            "args.txt",
            "fake-sysid",
            "mini.toml",
            "my study.toml"
        ]
    );
}

/// 1 s of the paper's data set in `dir/d`.
fn small_data(dir: &Path) -> PathBuf {
    let d = dir.join("d");
    ok(&run(
        &[
            "simulate",
            "--preset",
            "paper-3dof",
            "--duration",
            "1",
            "--seed",
            "1",
            "--out",
            d.to_str().unwrap(),
        ],
        dir,
    ));
    d
}

#[test]
fn loglik_seeds_are_bounded() {
    let (_tmp, dir) = temp_dir("seeds");
    let d = small_data(&dir);
    let limit = experiments::likelihood::MAX_SEEDS.to_string();
    for seeds in ["18446744073709551615", "1000000000", "10001", "0"] {
        let o = run(
            &[
                "loglik",
                "--data",
                d.to_str().unwrap(),
                "--truth",
                "--particles",
                "20",
                "--seeds",
                seeds,
            ],
            &dir,
        );
        refused(&o, "--seeds");
        assert!(stderr(&o).contains(&limit), "{}", stderr(&o));
    }
    // The help states the limit.
    let help = stdout(&run(&["loglik", "--help"], &dir));
    assert!(help.contains(&format!("1 to {limit}")), "{help}");
    // The library function the Python binding calls refuses it too, before any filter runs.
    for seeds in [u64::MAX, 1_000_000_000] {
        let req = experiments::likelihood::LikelihoodRequest {
            data: d.clone(),
            config: None,
            particles: 20,
            seeds,
            truth: true,
        };
        let e = experiments::likelihood::score(&req, &[], &mut |_| {}).unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("--seeds") && e.contains(&limit), "{e}");
    }
}

/// A run record of `d` (a small filter) at `dir/run.json`.
fn small_record(dir: &Path, d: &Path) -> PathBuf {
    let r = dir.join("run.json");
    ok(&run(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "20",
            "--data",
            d.to_str().unwrap(),
            "--out",
            r.to_str().unwrap(),
        ],
        dir,
    ));
    r
}

/// Runs `sysid args` with a standard output whose reader is already gone.
fn with_stdout_closed(args: &[&str], cwd: &Path) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    // Closed before the child starts: its first write finds no reader, whatever the timing.
    drop(reader);
    sysid()
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

/// Ended by SIGPIPE, as a Unix tool whose reader has gone: no panic (exit 101), no message.
fn ended_quietly(o: &Output) {
    let err = stderr(o);
    assert_ne!(o.status.code(), Some(101), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(o.status.signal(), Some(13), "{:?}: {err}", o.status);
}

#[test]
fn a_closed_standard_output_ends_the_command_quietly() {
    let (_tmp, dir) = temp_dir("pipe");
    ended_quietly(&with_stdout_closed(&["filter", "--print-config"], &dir));
    std::fs::write(dir.join("mini.toml"), STUDY).unwrap();
    ended_quietly(&with_stdout_closed(
        &[
            "cluster",
            "submit",
            "study",
            "--config",
            "mini.toml",
            "--out",
            "o",
            "--tasks",
            "2",
            "--dry-run",
        ],
        &dir,
    ));
    // validate writes its --out before it prints.
    let d = small_data(&dir);
    let record = small_record(&dir, &d);
    let out = dir.join("validation.json");
    ended_quietly(&with_stdout_closed(
        &[
            "validate",
            "--draws",
            "0",
            "--record",
            record.to_str().unwrap(),
            "--data",
            d.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
    ));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(v.get("free_run").is_some(), "{v}");
}

/// `path` is still a symbolic link to `target`, and `target` still holds `keep`.
fn link_intact(path: &Path, target: &Path) {
    assert!(std::fs::symlink_metadata(path)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(std::fs::read_link(path).unwrap(), target);
    assert_eq!(std::fs::read_to_string(target).unwrap(), "keep\n");
}

fn mkfifo(path: &Path) {
    let o = Command::new("mkfifo").arg(path).output().unwrap();
    assert!(o.status.success(), "mkfifo: {}", stderr(&o));
}

#[test]
fn outputs_that_are_not_regular_files_or_are_inputs_are_refused() {
    let (_tmp, dir) = temp_dir("outputs");
    let d = small_data(&dir);
    let record = small_record(&dir, &d);
    let record_bytes = std::fs::read(&record).unwrap();
    let measured_bytes = std::fs::read(d.join("measured.csv")).unwrap();
    let target = dir.join("target.txt");
    std::fs::write(&target, "keep\n").unwrap();
    let link = dir.join("link.json");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let fifo = dir.join("fifo.json");
    mkfifo(&fifo);
    let (d_s, r_s) = (d.to_str().unwrap(), record.to_str().unwrap());

    for out in [&link, &fifo] {
        let o_s = out.to_str().unwrap();
        let what = if out == &link {
            "symbolic link"
        } else {
            "named pipe"
        };
        // Refused before the work.
        let o = run(
            &[
                "validate", "--draws", "0", "--record", r_s, "--data", d_s, "--out", o_s,
            ],
            &dir,
        );
        refused(&o, "--out");
        assert!(stderr(&o).contains(what), "{}", stderr(&o));
        let o = run(
            &[
                "loglik",
                "--data",
                d_s,
                "--truth",
                "--particles",
                "20",
                "--seeds",
                "1",
                "--out",
                o_s,
            ],
            &dir,
        );
        refused(&o, "--out");
        // `sysid filter` writes through the same function, which refuses it when writing.
        let o = run(
            &[
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--particles",
                "20",
                "--data",
                d_s,
                "--out",
                o_s,
            ],
            &dir,
        );
        refused(&o, &out.display().to_string());
        assert!(stderr(&o).contains(what), "{}", stderr(&o));
    }
    link_intact(&link, &target);
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());

    // validate --out over its own --record, or over a file of its --data, is refused.
    let o = run(
        &[
            "validate", "--draws", "0", "--record", r_s, "--data", d_s, "--out", r_s,
        ],
        &dir,
    );
    refused(&o, "--record");
    let measured = d.join("measured.csv");
    let o = run(
        &[
            "validate",
            "--draws",
            "0",
            "--record",
            r_s,
            "--data",
            d_s,
            "--out",
            measured.to_str().unwrap(),
        ],
        &dir,
    );
    refused(&o, "--data");
    // Also through another spelling of the same file.
    let other = format!("{}/../d/measured.csv", d.display());
    refused(
        &run(
            &[
                "validate", "--draws", "0", "--record", r_s, "--data", d_s, "--out", &other,
            ],
            &dir,
        ),
        "--data",
    );
    assert_eq!(std::fs::read(&record).unwrap(), record_bytes);
    assert_eq!(std::fs::read(&measured).unwrap(), measured_bytes);

    // A regular file is still replaced: the check refuses only what it should.
    let fine = dir.join("validation.json");
    std::fs::write(&fine, "old\n").unwrap();
    ok(&run(
        &[
            "validate",
            "--draws",
            "0",
            "--record",
            r_s,
            "--data",
            d_s,
            "--out",
            fine.to_str().unwrap(),
        ],
        &dir,
    ));
    assert!(std::fs::read_to_string(&fine).unwrap().starts_with('{'));
}

#[test]
fn a_directory_named_like_a_data_set_file_is_not_deleted() {
    let (_tmp, dir) = temp_dir("dataset");
    for name in ["measured.csv", "truth.csv"] {
        let o = dir.join(format!("o-{name}"));
        std::fs::create_dir_all(o.join(name)).unwrap();
        let precious = o.join(name).join("precious.txt");
        std::fs::write(&precious, "keep\n").unwrap();
        let out = run(
            &[
                "simulate",
                "--preset",
                "paper-3dof",
                "--duration",
                "1",
                "--seed",
                "1",
                "--out",
                o.to_str().unwrap(),
            ],
            &dir,
        );
        refused(&out, &o.display().to_string());
        assert!(stderr(&out).contains(name), "{}", stderr(&out));
        assert_eq!(std::fs::read_to_string(&precious).unwrap(), "keep\n");
    }
    // A link in a data-set file's place is refused too, its target kept.
    let o = dir.join("o-link");
    std::fs::create_dir_all(&o).unwrap();
    let target = dir.join("elsewhere.csv");
    std::fs::write(&target, "keep\n").unwrap();
    std::os::unix::fs::symlink(&target, o.join("measured.csv")).unwrap();
    let out = run(
        &["simulate", "--duration", "1", "--out", o.to_str().unwrap()],
        &dir,
    );
    refused(&out, "symbolic link");
    link_intact(&o.join("measured.csv"), &target);
}

#[test]
fn table1_writes_its_files_only_as_new_or_regular_files() {
    let (_tmp, dir) = temp_dir("table1");
    let out = dir.join("t");
    std::fs::create_dir_all(&out).unwrap();
    let target = dir.join("target.txt");
    std::fs::write(&target, "keep\n").unwrap();
    std::os::unix::fs::symlink(&target, out.join("table1.md")).unwrap();
    let o = run(&["table1", "--out", out.to_str().unwrap()], &dir);
    refused(&o, "symbolic link");
    link_intact(&out.join("table1.md"), &target);
    std::fs::remove_file(out.join("table1.md")).unwrap();
    ok(&run(&["table1", "--out", out.to_str().unwrap()], &dir));
    assert!(std::fs::read_to_string(out.join("table1.md"))
        .unwrap()
        .contains('|'));
}

/// A field study of the frame's shortest recording with one variant, selected: small enough to
/// run three times.
fn mini_field_study(dir: &Path) -> PathBuf {
    mini_field_study_keeping_out(dir, &[])
}

/// The mini study with records `kept_out` (names of `experiments/real/frame-<name>.toml`) kept
/// out of every choice: validated, and identified again by the selected model.
fn mini_field_study_keeping_out(dir: &Path, kept_out: &[&str]) -> PathBuf {
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/real");
    let map = real.join("frame-bonus-event.toml");
    let others: String = kept_out
        .iter()
        .map(|name| {
            format!(
                "[[part.record]]\nname = \"{name}\"\nmap = \"{}\"\nrole = \"validate\"\n",
                real.join(format!("frame-{name}.toml")).display()
            )
        })
        .collect();
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        format!(
            r#"title = "mini"
[[part]]
name = "frame"
title = "frame"
about = "the frame"
common = ["--storeys", "3", "--hysteretic", "none", "--measurement", "absolute", "--masses", "1", "--particles", "50", "--seed", "1"]
[[part.record]]
name = "bonus"
map = "{}"
role = "identify"
{others}[[part.variant]]
name = "mpf"
label = "MPF-EKF2"
algorithm = "mpf-ekf2"
group = "g"
[part.selection]
group = "g"
"#,
            map.display()
        ),
    )
    .unwrap();
    study
}

/// The files under `dir`, recursively.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out
}

/// The SVG figures under `dir` (recursively) and their bytes.
fn figures_under(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    files_under(dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|x| x == "svg"))
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

/// The figures under `out` are those of `whole`, byte for byte; the message names the others.
fn same_figures(out: &Path, whole: &std::collections::BTreeMap<PathBuf, Vec<u8>>) {
    let now = figures_under(out);
    let differ: Vec<_> = whole
        .keys()
        .chain(now.keys())
        .filter(|p| whole.get(*p) != now.get(*p))
        .collect();
    assert!(differ.is_empty(), "missing, cut short or other: {differ:?}");
}

/// Every figure REPORT.md links is there.
fn report_links_only_existing_figures(out: &Path) -> String {
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    for link in report.split("](").skip(1) {
        let target = &link[..link.find(')').unwrap()];
        if target.ends_with(".svg") {
            assert!(
                out.join(target).is_file(),
                "REPORT.md links the absent {target}"
            );
        }
    }
    report
}

#[test]
fn a_resumed_field_study_redraws_broken_figures_and_links_only_existing_ones() {
    let (_tmp, dir) = temp_dir("field-study");
    let study = mini_field_study(&dir);
    let out = dir.join("out");
    let (s, o) = (study.to_str().unwrap(), out.to_str().unwrap());
    ok(&run(&["field-study", "--config", s, "--out", o], &dir));
    let whole = figures_under(&out);
    let figs = out.join("frame/figures/mpf");
    let selected = out.join("frame/selected-free_run.svg");
    for f in [
        figs.join("free_run.svg"),
        figs.join("transfer.svg"),
        selected.clone(),
    ] {
        assert!(whole.contains_key(&f), "{} not drawn", f.display());
    }
    for f in whole.keys() {
        identify::figures::validate_svg(f).unwrap();
    }
    let report = report_links_only_existing_figures(&out);
    assert!(report.contains("frame/selected-transfer.svg"), "{report}");

    // An interrupted study: a figure cut short, one missing, a copy beside the report cut
    // short and one missing. The resumed study puts every figure back as it was.
    let cut = |p: &Path| {
        let b = std::fs::read(p).unwrap();
        std::fs::write(p, &b[..b.len() / 2]).unwrap();
    };
    cut(&figs.join("free_run.svg"));
    std::fs::remove_file(figs.join("transfer.svg")).unwrap();
    cut(&selected);
    std::fs::remove_file(out.join("frame/selected-transfer.svg")).unwrap();
    ok(&run(
        &["field-study", "--config", s, "--out", o, "--resume"],
        &dir,
    ));
    same_figures(&out, &whole);
    report_links_only_existing_figures(&out);

    // A lost figure directory is drawn again; no staging directory is left.
    std::fs::remove_dir_all(out.join("frame/figures")).unwrap();
    ok(&run(
        &["field-study", "--config", s, "--out", o, "--resume"],
        &dir,
    ));
    same_figures(&out, &whole);
    let hidden: Vec<_> = std::fs::read_dir(&figs)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "{hidden:?}");

    // A figure beside the report that is not there is not linked.
    std::fs::remove_file(out.join("frame/selected-transfer.svg")).unwrap();
    ok(&run(
        &["field-study", "--config", s, "--out", o, "--report-only"],
        &dir,
    ));
    let report = report_links_only_existing_figures(&out);
    assert!(report.contains("frame/selected-free_run.svg"), "{report}");
}

/// The files under `dir` (recursively) and when each was last written.
fn written_under(dir: &Path) -> std::collections::BTreeMap<PathBuf, std::time::SystemTime> {
    files_under(dir)
        .into_iter()
        .map(|p| {
            let when = std::fs::metadata(&p).unwrap().modified().unwrap();
            (p, when)
        })
        .collect()
}

/// A resumed field study keeps an output only where what it was computed from is unchanged: a
/// record computed again takes the validation computed from it along, never leaving it beside
/// a record it was not computed from; an output without the digest of its inputs (written by an
/// earlier build, or cut off before its digest) is computed again; the rest is kept untouched.
#[test]
fn a_resumed_field_study_computes_again_what_depends_on_what_changed() {
    let (_tmp, dir) = temp_dir("field-study-depends");
    let study = mini_field_study_keeping_out(&dir, &["sine-1.0"]);
    let out = dir.join("out");
    let (s, o) = (study.to_str().unwrap(), out.to_str().unwrap());
    let resume = ["field-study", "--config", s, "--out", o, "--resume"];
    ok(&run(&["field-study", "--config", s, "--out", o], &dir));
    let part = out.join("frame");
    let (record, validation, selected, data) = (
        part.join("records/mpf.json"),
        part.join("validation/mpf--sine-1.0.json"),
        part.join("records/selected--sine-1.0.json"),
        part.join("data/sine-1.0/measured.csv"),
    );
    for f in [&record, &validation, &selected, &data] {
        assert!(f.is_file(), "{} not written", f.display());
    }
    let when = |f: &Path| std::fs::metadata(f).unwrap().modified().unwrap();
    let outputs = || {
        ["records", "validation", "data"]
            .iter()
            .flat_map(|d| written_under(&part.join(d)))
            .collect::<std::collections::BTreeMap<_, _>>()
    };
    let first = outputs();

    // Nothing changed: every output is kept as it was.
    ok(&run(&resume, &dir));
    assert_eq!(
        outputs(),
        first,
        "an unchanged study computed something again"
    );

    // The identification computed again: its validation with it; the imports and the selected
    // model's run on the other record (from unchanged data and settings) kept.
    std::fs::remove_file(&record).unwrap();
    ok(&run(&resume, &dir));
    assert!(record.is_file());
    assert_ne!(
        when(&validation),
        first[&validation],
        "validation kept beside a new record"
    );
    assert_eq!(when(&data), first[&data]);
    assert_eq!(when(&selected), first[&selected]);

    // A validation without the digest of its inputs is computed again; the rest is kept.
    let (again, record_at) = (when(&validation), when(&record));
    let digest = part.join("logs/validate--mpf--sine-1.0.inputs");
    assert!(digest.is_file(), "{} not written", digest.display());
    std::fs::remove_file(&digest).unwrap();
    ok(&run(&resume, &dir));
    assert_ne!(when(&validation), again);
    assert!(digest.is_file());
    assert_eq!(when(&record), record_at);
}

/// `validate --plot` puts its figures in place as `plot` does: a figure name that is a link is
/// refused, not written through, and a figure cut short is replaced whole.
#[test]
fn validate_plot_puts_each_figure_in_place_whole() {
    let (_tmp, dir) = temp_dir("validate-plot");
    let d = small_data(&dir);
    let record = small_record(&dir, &d);
    let (r, d) = (record.to_str().unwrap(), d.to_str().unwrap());
    let figs = dir.join("figs");
    ok(&run(
        &["validate", "--record", r, "--data", d, "--plot", "figs"],
        &dir,
    ));
    let whole = std::fs::read(figs.join("free_run.svg")).unwrap();
    identify::figures::validate_svg(&figs.join("free_run.svg")).unwrap();
    std::fs::write(figs.join("free_run.svg"), &whole[..whole.len() / 2]).unwrap();
    ok(&run(
        &["validate", "--record", r, "--data", d, "--plot", "figs"],
        &dir,
    ));
    assert_eq!(std::fs::read(figs.join("free_run.svg")).unwrap(), whole);
    let keep = dir.join("keep.txt");
    std::fs::write(&keep, "keep\n").unwrap();
    std::fs::remove_file(figs.join("free_run.svg")).unwrap();
    std::os::unix::fs::symlink(&keep, figs.join("free_run.svg")).unwrap();
    let o = run(
        &["validate", "--record", r, "--data", d, "--plot", "figs"],
        &dir,
    );
    refused(&o, "free_run.svg");
    link_intact(&figs.join("free_run.svg"), &keep);
    let hidden: Vec<_> = std::fs::read_dir(&figs)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "{hidden:?}");
}
