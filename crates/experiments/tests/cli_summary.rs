//! `sysid filter` through the real binary: the terminal summary table and the warnings written
//! into the record.

use std::process::Command;

#[test]
fn filter_prints_a_summary_table_and_records_its_warnings() {
    let tmp = tempfile::Builder::new()
        .prefix("sysid-summary-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    let data = dir.join("d");
    let st = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["simulate", "--preset", "paper-3dof", "--seed", "1"])
        .args(["--duration", "3", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let out = dir.join("r.json");
    // The paper's settings: a configuration file over the SPEC defaults, here empty.
    let paper = dir.join("paper.toml");
    std::fs::write(&paper, "").unwrap();
    // The bootstrap PF with 50 particles over 600 steps, resampling at every step: its static
    // parameters coalesce onto a few ancestors (SPEC §8, Fig. 4).
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["filter", "--algorithm", "bootstrap", "--particles", "50"])
        .arg("--config")
        .arg(&paper)
        .args(["--seed", "3", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains("95% credible interval"), "{stdout}");
    for name in ["k1", "c3", "beta", "gamma", "n"] {
        assert!(
            stdout.lines().any(|l| l.starts_with(name)),
            "{name}: {stdout}"
        );
    }
    assert!(stdout.contains("RESTS ON FEW PARTICLES"), "{stdout}");
    // Simulated data: the true values beside the answer (k1 = 8 in the paper's building), and
    // what ✗ means.
    assert!(stdout.contains("true θ"), "{stdout}");
    let k1 = stdout.lines().find(|l| l.starts_with("k1")).unwrap();
    assert!(k1.contains("8.0000"), "{k1}");
    assert!(stdout.contains("✗: outside the 95 % interval"), "{stdout}");
    assert!(stderr.contains("warning: ") && stderr.contains("distinct particle value"));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let w = r["warnings"].as_array().expect("warnings in the record");
    assert!(
        w.iter().any(|w| w["kind"] == "few_distinct"),
        "{}",
        r["warnings"]
    );
    // The real-time factor: seconds of record (600 steps of 5 ms) per second of computation.
    let t = &r["timing"];
    let f = t["realtime_factor"].as_f64().expect("a real-time factor");
    let want = 600.0 * 0.005 / t["wall_s"].as_f64().unwrap();
    assert!((f - want).abs() <= 1e-9 * want, "{f} vs {want}");
    // The record carries the 50/90/95 % intervals of every parameter.
    let c = r["credible"].as_array().expect("intervals in the record");
    assert_eq!(c.len(), 9);
    assert!(c
        .iter()
        .all(|p| p["intervals"].as_array().unwrap().len() == 3));
    assert!(r["config"]["filter"].get("pool").is_none());

    // Without a configuration file: the recommended settings, one pooled filter per 125
    // particles (here 2) that report the Monte-Carlo s.e. of θ_val.
    let out = dir.join("recommended.json");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["filter", "--algorithm", "mpf-ekf2", "--particles", "250"])
        .args(["--seed", "3", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("θ_val MC s.e."), "{stdout}");
    assert!(stdout.contains("2 filters pooled"), "{stdout}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["config"]["filter"]["pool"], 2);
    assert_eq!(r["config"]["filter"]["ess_threshold"], 0.5);
}
