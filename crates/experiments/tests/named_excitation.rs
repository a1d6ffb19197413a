//! `sysid simulate --excitation <name>`: the vendored PEER records by name, recorded in
//! `dataset.json`, filtered like any other data set; an unknown name is not a record.

use std::path::PathBuf;
use std::process::Command;

fn sysid(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(args)
        .output()
        .unwrap()
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-named-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

#[test]
fn a_named_record_simulates_and_filters() {
    let (_tmp, dir) = temp_dir("ok");
    let d = dir.join("d");
    let d = d.to_str().unwrap();
    let o = sysid(&[
        "simulate",
        "--excitation",
        "loma-prieta-1989",
        "--duration",
        "2",
        "--seed",
        "1",
        "--out",
        d,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta = std::fs::read_to_string(dir.join("d/dataset.json")).unwrap();
    assert!(
        meta.contains("\"named\"") && meta.contains("loma-prieta-1989"),
        "{meta}"
    );
    // 2 s at the preset's dt = 0.005 s: 401 rows and the header.
    let rows = std::fs::read_to_string(dir.join("d/measured.csv"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(rows, 402);
    let r = dir.join("r.json");
    let o = sysid(&[
        "filter",
        "--algorithm",
        "mpf-ekf2",
        "--data",
        d,
        "--particles",
        "20",
        "--seed",
        "1",
        "--out",
        r.to_str().unwrap(),
    ]);
    // Two seconds with 20 particles need not give a plausible answer (exit 1 names why);
    // the record is written either way and nothing panics.
    assert!(
        o.status.code().is_some_and(|c| c <= 1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(r.exists());
}

#[test]
fn an_unknown_name_is_not_a_record() {
    let (_tmp, dir) = temp_dir("bad");
    let d = dir.join("d");
    let o = sysid(&[
        "simulate",
        "--excitation",
        "kobe-1995",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    // Not a vendored name: read as a CSV path, which does not exist, and the error names it.
    assert!(err.contains("kobe-1995"), "{err}");
}
