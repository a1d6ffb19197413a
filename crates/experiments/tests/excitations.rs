//! The excitations study: the `excitation` and `scale` fields of a structure (parsing,
//! refusals, the data configuration they make), the committed `experiments/excitations.toml`
//! (every record yields the paper's structure as much as the paper's El Centro, and its
//! verdicts are declared), and a small study end to end. The verdict's test on constructed
//! structures is in `tests/verdict.rs`.

use std::path::{Path, PathBuf};

use experiments::engine::RunMode;
use experiments::excitations;
use experiments::scaling::structures::structure_values;
use experiments::scaling::Options;
use experiments::study::Study;
use identify::figures::validate_svg;
use models::dataset::ExcitationSource;

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-excitations-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const SMALL: &str = r#"
name = "small-excitations"
description = "excitations test"
[data]
preset = "paper-3dof"
duration = 1.0
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2"]
runs = 2
master_seed = 5
particles = [30]
[filter]
trace_every = 0
loop_every = 0
validate = false

[[verdicts]]
statement = "the stiffness error varies"
test = "differs-from-first"
metric = "k-error"
algorithms = ["mln-rbpf"]
threshold = 0.01

[[verdicts]]
statement = "the stiffness error varies"
test = "differs-from-first"
metric = "k-error"
algorithms = ["mpf-ekf2"]
threshold = 0.01

[[sweep.structures]]
label = "control"
storeys = 3

[[sweep.structures]]
label = "loma"
storeys = 3
excitation = "loma-prieta-1989"
scale = 6.49
"#;

fn write_study(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("study.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn excitation_field_reaches_the_data_and_bad_ones_are_named() {
    let (_tmp, dir) = temp_dir("field");
    let study = Study::load(&write_study(&dir, SMALL)).unwrap();
    let control = study.structure_config(Some(0), 0).unwrap();
    assert_eq!(control.excitation, ExcitationSource::ElCentro);
    assert_eq!(control.scale, 3.0);
    let loma = study.structure_config(Some(1), 0).unwrap();
    assert_eq!(
        loma.excitation,
        ExcitationSource::Named {
            name: "loma-prieta-1989".into()
        }
    );
    assert_eq!(loma.scale, 6.49);
    // Different excitations, different fingerprints (no record is reused across them).
    let jobs = study.jobs();
    let fp = |i: usize| {
        study
            .job_fingerprint(jobs.iter().find(|j| j.structure == Some(i)).unwrap())
            .unwrap()
    };
    assert_ne!(fp(0), fp(1));
    for (bad, needle) in [
        (
            "excitation = \"kobe-1995\"",
            "no vendored record is named `kobe-1995`",
        ),
        ("scale = -2.0", "field `scale`"),
        ("scale = 1e9", "field `scale`"),
    ] {
        let text = if bad.starts_with("scale") {
            SMALL.replace("scale = 6.49", bad)
        } else {
            SMALL.replace("excitation = \"loma-prieta-1989\"", bad)
        };
        let err = format!("{:#}", Study::load(&write_study(&dir, &text)).unwrap_err());
        assert!(err.contains(needle) && err.contains("loma"), "{bad}: {err}");
        if needle.contains("vendored") {
            assert!(
                err.contains("northridge-1994"),
                "the list of records: {err}"
            );
        }
    }
}

#[test]
fn the_committed_study_yields_every_record_like_the_paper() {
    let study = Study::load(&workspace().join("experiments/excitations.toml")).unwrap();
    assert_eq!(study.data.preset, "paper-3dof");
    assert!(study.sweep.runs >= 20);
    assert_eq!(study.verdicts.len(), 3);
    assert!(study.verdicts.iter().all(|v| v.threshold == Some(0.01)));
    let values = structure_values(&study).unwrap();
    assert_eq!(values.len(), 5);
    let control = values[0].yielding[0].1;
    assert!((control - 0.654).abs() < 0.005, "paper: {control}");
    for v in &values[1..] {
        let r = v.yielding[0].1;
        assert!(
            (r - control).abs() < 0.01,
            "{}: {r} against {control}",
            v.label
        );
    }
}

#[test]
fn small_study_end_to_end() {
    let (_tmp, dir) = temp_dir("e2e");
    let out = dir.join("out");
    let opts = Options {
        config: write_study(&dir, SMALL),
        out: out.clone(),
        mode: RunMode::quiet(2),
        report_only: false,
    };
    let cells = excitations::run(&opts).unwrap();
    assert_eq!(cells.len(), 4);
    assert!(cells
        .iter()
        .all(|c| c.runs == 2 && c.k_error_mean.is_finite()));
    validate_svg(&out.join("errors_by_excitation.svg")).unwrap();
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    assert!(report.contains("## Beyond the paper: other ground motions"));
    assert!(report.contains("loma-prieta-1989"));
    // Two runs per cell: too few for a verdict; one paragraph for the statement, a row for
    // each algorithm.
    assert_eq!(
        report.matches("| **not resolved** |").count(),
        2,
        "{report}"
    );
    assert_eq!(
        report
            .matches("Statement, per algorithm: *the stiffness error varies*")
            .count(),
        1
    );
    assert!(
        report.contains("Bonferroni z = 1.96 of the 1 comparisons"),
        "{report}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["rows"].as_array().unwrap().len(), 4);
    let verdict = &summary["verdicts"][1];
    assert_eq!(
        (&verdict["algorithm"], &verdict["verdict"]),
        (&"mpf-ekf2".into(), &"NotResolved".into())
    );
    assert_eq!(verdict["differences"][0][0], "loma");
    assert_eq!(verdict["differences"][0][1]["n"], 2);
}
