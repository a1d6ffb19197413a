//! Model error in the intervals (`identify::spread`): the parts of a record of the filter's own
//! class, identified with its true noise settings, disagree no more often than the test's 5 %;
//! the parts of the shake-table frame's record disagree on every stiffness, and its intervals
//! widen by their spread.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use identify::record::RunRecord;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn ok(c: &mut Command) {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn read(path: &Path) -> RunRecord {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn agreeing_parts_are_not_taken_for_model_error() {
    let (_tmp, root) = common::temp_dir("sysid-spread-");
    let (mut widened, mut tested) = (0, 0);
    for seed in 11..31 {
        let data = root.join(format!("d{seed}"));
        ok(sysid()
            .args([
                "simulate",
                "--storeys",
                "3",
                "--hysteretic",
                "none",
                "--duration",
                "10",
                "--absolute",
                "--seed",
                &seed.to_string(),
            ])
            .arg("--out")
            .arg(&data));
        for f in ["dataset.json", "truth.csv"] {
            std::fs::remove_file(data.join(f)).unwrap();
        }
        // The settings the data were simulated with: the model and its noise levels are right.
        let record = root.join(format!("r{seed}.json"));
        ok(sysid()
            .args(common::LINEAR_FIELD_FILTER)
            .args([
                "--damping",
                "storey",
                "--noise-fraction",
                "0.1",
                "--process-noise-factor",
                "1",
            ])
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&record));
        let r = read(&record);
        let spread = r.segment_spread.expect("a field record has the spread");
        for p in &spread.parameters {
            if let Some(tau) = p.tau {
                tested += 1;
                widened += usize::from(tau > 0.0);
            }
        }
    }
    // 20 records × 6 parameters; the test fires 5 % of the time on agreeing parts: at most 14
    // of 120 is the 99.9 % quantile of Binomial(120, 0.05).
    assert_eq!(tested, 120);
    assert!(widened <= 14, "{widened} of {tested} parameters widened");
}

#[test]
fn the_frames_parts_disagree_and_its_intervals_widen() {
    let (_tmp, dir) = common::temp_dir("sysid-spread-");
    let data = dir.join("northridge");
    ok(sysid()
        .current_dir(root())
        .args([
            "import",
            "--map",
            "experiments/real/frame-northridge.toml",
            "--out",
        ])
        .arg(&data));
    let record = dir.join("r.json");
    ok(sysid()
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--storeys",
            "3",
            "--hysteretic",
            "none",
            "--masses",
            "1,1,1.2",
            "--damping",
            "storey+mass",
            "--measurement",
            "absolute",
            "--data",
        ])
        .arg(&data)
        .arg("--out")
        .arg(&record));
    let r = read(&record);
    let spread = r.segment_spread.as_ref().expect("the spread");
    let half = |ps: &[identify::observe::ParamIntervals], name: &str| {
        let ci = ps
            .iter()
            .find(|p| p.parameter == name)
            .and_then(|p| p.at(0.95))
            .unwrap();
        ci.hi - ci.lo
    };
    for k in ["k1", "k2", "k3"] {
        let p = spread.parameters.iter().find(|p| p.parameter == k).unwrap();
        assert!(p.tau.unwrap() > 0.0, "{k}: the parts agree: {p:?}");
        let (filter, widened) = (half(&spread.filter_credible, k), half(&r.credible, k));
        // Wider by at least the parts' own spread: 2·1.96·τ ≤ the widened width.
        assert!(
            widened >= 2.0 * 1.959 * p.tau.unwrap() && widened > filter,
            "{k}: {filter} -> {widened}"
        );
    }
}
