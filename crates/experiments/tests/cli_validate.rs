//! Validation without the truth through the binary: a field-data `sysid filter` run carries the
//! free run and the modes in its record and summary, `sysid plot` draws them, and `sysid
//! validate` predicts another record of the same building (cross-validation) and refuses
//! another building or a bad record.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-validate-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn run(args: &[&str], paths: &[&Path]) -> Output {
    let mut c = sysid();
    c.args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().unwrap()
}

/// `sysid simulate` of the paper's building, then kept as field data (only `measured.csv`).
fn field_data(dir: &Path, seed: &str, excitation: &str, storeys: &str) {
    let out = run(
        &[
            "simulate",
            "--preset",
            "paper-3dof",
            "--seed",
            seed,
            "--excitation",
            excitation,
            "--storeys",
            storeys,
            "--duration",
            "15",
            "--out",
        ],
        &[dir],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn strip_to_field(dir: &Path) {
    std::fs::remove_file(dir.join("dataset.json")).unwrap();
    std::fs::remove_file(dir.join("truth.csv")).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn cross_validation_end_to_end() {
    let (_tmp, dir) = temp_dir("e2e");
    let (d1, d2, d4) = (dir.join("d1"), dir.join("d2"), dir.join("d4"));
    field_data(&d1, "1", "elcentro", "3");
    field_data(&d2, "2", "kanai-tajimi", "3");
    field_data(&d4, "3", "elcentro", "4");
    strip_to_field(&d1);
    let rec = dir.join("r.json");
    let figs = dir.join("figs");
    let out = sysid()
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "200",
            "--storeys",
            "3",
            "--hysteretic",
            "1",
            "--masses",
            "1",
            "--measurement",
            "relative",
        ])
        .arg("--data")
        .arg(&d1)
        .arg("--out")
        .arg(&rec)
        .arg("--plot")
        .arg(&figs)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("free run of the identified model"),
        "{stdout}"
    );
    assert!(stdout.contains("modes of the identified model"), "{stdout}");
    // The record: a fit per channel, the model identified well enough that its free run
    // explains most of its own record (noise of 10 % alone caps the fit near 90 %), a band.
    let r = json(&rec);
    let channels = r["free_run"]["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 3);
    for c in channels {
        let fit = c["fit_percent"].as_f64().unwrap();
        assert!(fit > 60.0 && fit < 95.0, "{c}");
        assert_eq!(c["fit_draws"].as_array().unwrap().len(), 3);
    }
    assert_eq!(r["free_run"]["band"]["purpose"], "validation-band");
    assert_eq!(r["modal"]["pairs"].as_array().unwrap().len(), 3);
    for f in ["free_run.svg", "transfer.svg"] {
        identify::figures::validate_svg(&figs.join(f)).unwrap();
    }

    // Cross-validation on another record of the same building (simulated with its own
    // dataset.json, which must agree) under another excitation.
    let v = dir.join("v.json");
    let out = sysid()
        .args(["validate", "--record"])
        .arg(&rec)
        .arg("--data")
        .arg(&d2)
        .arg("--out")
        .arg(&v)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("cross-validation"), "{stdout}");
    let res = json(&v);
    let channels = res["free_run"]["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 3);
    for c in channels {
        assert!(c["fit_percent"].as_f64().unwrap() > 60.0, "{c}");
    }
    assert_eq!(res["theta_val"], r["theta_val"]);
    // Deterministic: the same band again.
    let v2 = dir.join("v2.json");
    let st = sysid()
        .args(["validate", "--record"])
        .arg(&rec)
        .arg("--data")
        .arg(&d2)
        .arg("--out")
        .arg(&v2)
        .output()
        .unwrap();
    assert!(st.status.success());
    assert_eq!(json(&v2)["free_run"], res["free_run"]);

    // Another building is refused by name.
    let out = sysid()
        .args(["validate", "--record"])
        .arg(&rec)
        .arg("--data")
        .arg(&d4)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("another building") && err.contains("storeys 4 against 3"),
        "{err}"
    );
    // As field data, its column a4 does not exist in the identified building.
    strip_to_field(&d4);
    let out = sysid()
        .args(["validate", "--record"])
        .arg(&rec)
        .arg("--data")
        .arg(&d4)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("column a4"), "{err}");
    // A file that is not a record, and a bad option.
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{\"x\": 1}").unwrap();
    let out = sysid()
        .args(["validate", "--record"])
        .arg(&bad)
        .arg("--data")
        .arg(&d2)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("bad.json"), "{err}");
    let out = sysid()
        .args(["validate", "--draws", "1", "--record"])
        .arg(&rec)
        .arg("--data")
        .arg(&d2)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--draws"), "{err}");
}
