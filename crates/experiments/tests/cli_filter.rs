//! `sysid simulate` + `sysid filter` end to end: records, determinism, failures.

use std::path::PathBuf;
use std::process::Command;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-cli-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn simulate(dir: &std::path::Path) {
    let st = sysid()
        .args([
            "simulate",
            "--preset",
            "paper-3dof",
            "--seed",
            "1",
            "--duration",
            "3",
            "--out",
        ])
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
}

fn record_without_timing(path: &std::path::Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("timing");
    v
}

#[test]
fn filter_writes_a_complete_deterministic_record() {
    let (_tmp, dir) = temp_dir("ok");
    let data = dir.join("d");
    simulate(&data);
    for alg in ["bootstrap", "mln-rbpf", "storvik", "mpf-ekf2"] {
        let mut outs = vec![];
        for threads in ["1", "2"] {
            let out = dir.join(format!("{alg}-{threads}.json"));
            let st = sysid()
                .env("RAYON_NUM_THREADS", threads)
                .args([
                    "filter",
                    "--algorithm",
                    alg,
                    "--particles",
                    "50",
                    "--seed",
                    "3",
                    "--data",
                ])
                .arg(&data)
                .arg("--out")
                .arg(&out)
                .output()
                .unwrap();
            // The warnings of 50 particles are expected here; kept out of the test log.
            assert!(
                st.status.success(),
                "{alg} failed: {}",
                String::from_utf8_lossy(&st.stderr)
            );
            outs.push(record_without_timing(&out));
        }
        assert_eq!(outs[0], outs[1], "{alg}: records differ between runs");
        let r = &outs[0];
        for key in [
            "algorithm",
            "seed",
            "particles",
            "param_names",
            "theta_val",
            "theta_sd_final",
            "theta_true",
            "loglik",
            "failures",
            "config",
            "trace",
        ] {
            assert!(r.get(key).is_some(), "{alg}: record lacks {key}");
        }
        assert_eq!(r["param_names"].as_array().unwrap().len(), 9);
        assert!(r["failure"].is_null());
    }
}

#[test]
fn a_hopeless_measurement_is_a_recorded_failure_and_a_nonzero_exit() {
    let (_tmp, dir) = temp_dir("fail");
    let data = dir.join("d");
    simulate(&data);
    // Replace one measured acceleration by 1e11 (within the limits on data values): every
    // particle's likelihood underflows to 0.
    let path = data.join("measured.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cells: Vec<String> = lines[50].split(',').map(String::from).collect();
    cells[2] = "1e11".into();
    lines[50] = cells.join(",");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    // The edited file no longer matches the digest in dataset.json: drop the digests, as in a
    // data set written before they existed.
    let meta_path = data.join("dataset.json");
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&meta_path).unwrap()).unwrap();
    meta.as_object_mut().unwrap().remove("files");
    std::fs::write(&meta_path, serde_json::to_string_pretty(&meta).unwrap()).unwrap();
    let out = dir.join("r.json");
    let o = sysid()
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "30",
            "--data",
        ])
        .arg(&data)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success(), "the run should fail");
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(msg.contains("failed at step"), "{msg}");
    let r = record_without_timing(&out);
    assert!(r["failure"].is_string(), "{r}");
    assert!(r["failures"].as_object().unwrap().values().any(|v| v == 1));
}

#[test]
fn bad_input_is_a_clear_error_not_a_panic() {
    let (_tmp, dir) = temp_dir("bad");
    let o = sysid()
        .args(["filter", "--algorithm", "mpf-ekf2", "--data"])
        .arg(dir.join("missing"))
        .arg("--out")
        .arg(dir.join("r.json"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(
        msg.contains("missing") && !msg.contains("panicked"),
        "{msg}"
    );
    let data = dir.join("d");
    simulate(&data);
    let o = sysid()
        .args([
            "filter",
            "--algorithm",
            "mln-rbpf",
            "--fix",
            "k9=1",
            "--data",
        ])
        .arg(&data)
        .arg("--out")
        .arg(dir.join("r.json"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(msg.contains("k9") && !msg.contains("panicked"), "{msg}");
}

/// `--substeps M`: the MPF-EKF2 and the bootstrap PF run with M transitions per sample and say so
/// in the record (settings and spec); the MLN-RBPF and Storvik refuse it by name, and an
/// out-of-range count is refused naming the field.
#[test]
fn substeps_run_where_offered_and_are_refused_by_name_elsewhere() {
    let (_tmp, dir) = temp_dir("substeps");
    let data = dir.join("d");
    simulate(&data);
    let filter = |alg: &str, m: &str, out: &std::path::Path| {
        sysid()
            .args([
                "filter",
                "--algorithm",
                alg,
                "--particles",
                "40",
                "--seed",
                "3",
            ])
            .args(["--substeps", m, "--data"])
            .arg(&data)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    for alg in ["mpf-ekf2", "bootstrap"] {
        let out = dir.join(format!("{alg}.json"));
        let o = filter(alg, "3", &out);
        assert!(
            o.status.success(),
            "{alg}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let r = record_without_timing(&out);
        assert_eq!(r["config"]["filter"]["substeps"], 3, "{alg}");
        assert_eq!(r["config"]["spec"]["substeps"], 3, "{alg}");
        assert!(r["failure"].is_null(), "{alg}");
        // One transition per sample leaves the key out of the record (fingerprints unchanged).
        let one = dir.join(format!("{alg}-1.json"));
        assert!(filter(alg, "1", &one).status.success());
        let r1 = record_without_timing(&one);
        assert!(r1["config"]["filter"].get("substeps").is_none(), "{alg}");
        assert_ne!(
            r1["theta_val"], r["theta_val"],
            "{alg}: substeps changed nothing"
        );
    }
    for alg in ["mln-rbpf", "storvik"] {
        let o = filter(alg, "2", &dir.join("refused.json"));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{alg}");
        assert!(
            err.contains("substeps") && err.contains("MLN-RBPF/Storvik"),
            "{alg}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
    let o = filter("mpf-ekf2", "0", &dir.join("zero.json"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("`substeps`"), "{err}");
}
