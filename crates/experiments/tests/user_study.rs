//! A study on a data directory (`[data] dir = ...`, `sysid study`): every run filters the same
//! record with its own streams, and the report gives θ_val's mean, run-to-run spread and the
//! posterior s.d. per algorithm and parameter.

use std::path::PathBuf;
use std::process::Command;

use models::dataset::{generate, DatasetConfig};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-user-study-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// A fresh directory holding the study file `s.toml` with `text`: (guard, directory, file).
fn study_file(tag: &str, text: &str) -> (tempfile::TempDir, PathBuf, PathBuf) {
    let (tmp, dir) = temp_dir(tag);
    let config = dir.join("s.toml");
    std::fs::write(&config, text).unwrap();
    (tmp, dir, config)
}

const STUDY: &str = r#"
name = "own-record"
description = "three filter seeds on one record"

[data]
dir = "d"

[sweep]
algorithms = ["mpf-ekf2", "mln-rbpf"]
runs = 3
master_seed = 5
particles = [40]

[filter]
trace_every = 0
loop_every = 0
validate = false
"#;

#[test]
fn a_study_on_a_data_directory_runs_every_seed_on_the_same_record() {
    let (_tmp, dir) = temp_dir("ok");
    let mut c = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    c.duration = Some(1.0);
    generate(&c).unwrap().write_dir(&dir.join("d")).unwrap();
    std::fs::write(dir.join("study.toml"), STUDY).unwrap();
    let out = dir.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["study", "--config"])
        .arg(dir.join("study.toml"))
        .arg("--out")
        .arg(&out)
        .args(["--threads", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let last_run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("last-run.json")).unwrap()).unwrap();
    assert_eq!(last_run["facts"]["runs"]["executed"], 6);
    let algs = summary["algorithms"].as_array().unwrap();
    assert_eq!(algs.len(), 2);
    for a in algs {
        assert_eq!(a["runs"], 3);
        let k1 = &a["params"][0];
        assert_eq!(k1["param"], "k1");
        assert_eq!(k1["runs"], 3);
        // Different filter streams on the same data: the answers differ, and the truth is known.
        assert!(k1["spread"].as_f64().unwrap() > 0.0);
        assert_eq!(k1["truth"], 8.0);
    }
    // One record per algorithm and seed.
    let records: Vec<_> = std::fs::read_dir(out.join("records"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
        .collect();
    assert_eq!(records.len(), 6);
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    assert!(report.contains("run-to-run s.d."), "{report}");
    // The figures: valid SVGs, linked from the report, one category per parameter.
    for f in ["theta_val.svg", "sd_over_spread.svg"] {
        identify::figures::validate_svg(&out.join(f)).unwrap();
        assert!(report.contains(&format!("({f})")), "{f} not linked");
        let svg = std::fs::read_to_string(out.join(f)).unwrap();
        assert!(
            svg.contains("\nk1\n") && svg.contains("\ngamma\n"),
            "{f}: parameter labels"
        );
    }
    assert!(std::fs::read_to_string(out.join("theta_val.svg"))
        .unwrap()
        .contains("θ_val / truth"));
}

#[test]
fn a_study_names_its_data_once() {
    let (_tmp, dir) = temp_dir("bad");
    let both = STUDY.replace("dir = \"d\"", "dir = \"d\"\npreset = \"paper-3dof\"");
    std::fs::write(dir.join("both.toml"), both).unwrap();
    let err = experiments::study::Study::load(&dir.join("both.toml"))
        .unwrap_err()
        .to_string();
    let chain = format!("{err:#}");
    assert!(chain.contains("both.toml"), "{chain}");
    let e = experiments::study::Study::load(&dir.join("both.toml")).unwrap_err();
    assert!(format!("{e:#}").contains("not both"), "{e:#}");
    // A directory that is not a data set is refused by name.
    std::fs::write(dir.join("missing.toml"), STUDY).unwrap();
    let e = experiments::study::Study::load(&dir.join("missing.toml")).unwrap_err();
    assert!(format!("{e:#}").contains("field `dir`"), "{e:#}");
}

/// The report says what the spread over runs is: the Monte-Carlo error alone when every run
/// filters one record, the data's spread as well when every run generates its own data set.
#[test]
fn the_report_says_what_the_spread_over_runs_measures() {
    use experiments::user_study::markdown;
    let one = markdown("s", "d", "dir", true, &[]);
    assert!(one.contains("the spread over runs is the Monte-Carlo error of one run's answer"));
    let preset = markdown("s", "d", "preset paper-3dof", false, &[]);
    assert!(
        preset.contains("Every run generates its own data set"),
        "{preset}"
    );
    assert!(
        !preset.contains("Every run filters this record"),
        "{preset}"
    );
}

/// A study on a preset knows the truth: its report gives the coverage of the credible intervals
/// per algorithm and parameter, and the pooled 95 % coverage of the stiffnesses and dampings,
/// counted from the records; and it decides the statements its file declares, on its records.
#[test]
fn a_preset_study_reports_the_coverage_of_its_intervals() {
    let (_tmp, dir, config) = study_file(
        "preset",
        r#"
name = "tiny"
description = "three data sets of the paper's structure"
[data]
preset = "paper-3dof"
duration = 2.0
[sweep]
algorithms = ["mpf-ekf2"]
runs = 3
master_seed = 7
particles = [40]
[filter]
trace_every = 0
loop_every = 0
validate = false
[[verdicts]]
statement = "every run completes"
test = "no-failures"
algorithms = ["mpf-ekf2"]
[[verdicts]]
statement = "mean stiffness error below 1000"
test = "below"
metric = "k-error"
algorithms = ["mpf-ekf2"]
threshold = 1000
[[verdicts]]
statement = "mean stiffness error below 0"
test = "below"
metric = "k-error"
algorithms = ["mpf-ekf2"]
threshold = 0
"#,
    );
    let out = dir.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["study", "--threads", "1", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    assert!(
        report.contains("### Coverage of the credible intervals"),
        "{report}"
    );
    // The pooled count, recomputed from the records.
    let (mut covered, mut pairs) = (0, 0);
    for e in std::fs::read_dir(out.join("records")).unwrap() {
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(e.unwrap().path()).unwrap()).unwrap();
        let truth = r["theta_true"].as_array().unwrap();
        for (j, name) in r["param_names"].as_array().unwrap().iter().enumerate() {
            let name = name.as_str().unwrap();
            if !(name.starts_with('k') || name.starts_with('c')) {
                continue;
            }
            let (lo, hi) = crate::common::interval95(&r, name);
            let t = truth[j].as_f64().unwrap();
            pairs += 1;
            if lo <= t && t <= hi {
                covered += 1;
            }
        }
    }
    assert_eq!(pairs, 18);
    let line = format!("hold the truth in {covered} of {pairs} (run, parameter) pairs");
    assert!(report.contains(&line), "{line}\n{report}");
    // The declared statements, decided on the three runs: the mean of the per-run stiffness
    // errors (each ≥ 0) recomputed from the records is what the evidence shows.
    assert!(report.contains("### Verdicts"), "{report}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let findings = summary["verdicts"][0]["findings"].as_array().unwrap();
    let verdicts: Vec<&str> = findings
        .iter()
        .map(|f| f["verdict"].as_str().unwrap())
        .collect();
    let mut k_errors = Vec::new();
    for e in std::fs::read_dir(out.join("records")).unwrap() {
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(e.unwrap().path()).unwrap()).unwrap();
        let names = r["param_names"].as_array().unwrap();
        let err = r["rel_error"].as_array().unwrap();
        let k: Vec<f64> = names
            .iter()
            .zip(err)
            .filter(|(n, _)| n.as_str().unwrap().starts_with('k'))
            .map(|(_, e)| e.as_f64().unwrap())
            .collect();
        k_errors.push(k.iter().sum::<f64>() / k.len() as f64);
    }
    let n = k_errors.len() as f64;
    let mean = k_errors.iter().sum::<f64>() / n;
    let se = (k_errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    // Below 0 holds for no error; it does not hold once the ±2 s.e. interval is above 0.
    let at_zero = if mean - 2.0 * se > 0.0 {
        "DoesNotHold"
    } else {
        "NotResolved"
    };
    assert_eq!(verdicts, ["Holds", "Holds", at_zero], "{findings:#?}");
    let shown = format!("{:.2}%", 100.0 * mean);
    assert!(
        findings[1]["evidence"]
            .as_str()
            .unwrap()
            .starts_with(&shown),
        "{shown}: {findings:#?}"
    );
}

/// A verdict compares algorithms run by run: a sweep with two particle counts has two records
/// per run and algorithm, and its file is refused with the reason.
#[test]
fn verdicts_need_one_record_per_run_and_algorithm() {
    let (_tmp, _, config) = study_file(
        "verdict-arms",
        r#"
name = "arms"
description = "two particle counts"
[data]
preset = "paper-3dof"
[sweep]
algorithms = ["mpf-ekf2", "storvik"]
runs = 2
master_seed = 7
particles = [40, 80]
[[verdicts]]
statement = "MPF-EKF2 lower stiffness error"
test = "lower"
metric = "k-error"
algorithms = ["mpf-ekf2"]
than = ["storvik"]
"#,
    );
    let e = format!(
        "{:#}",
        experiments::study::Study::load(&config).unwrap_err()
    );
    assert!(
        e.contains("s.toml") && e.contains("one particle count"),
        "{e}"
    );
}
