//! Constructed run records for tests of the report, checks and plots.

#![allow(dead_code)]

use std::collections::BTreeMap;

use core_filters::Health;
use identify::metrics::{SignalError, StateErrors};
use identify::observe::Trace;
use identify::record::{Fingerprint, Loop, RunRecord, Timing, Validation, Versions};

/// `sysid filter` on field data of a linear 3-storey building with unit masses, measured as
/// absolute accelerations (the MPF-EKF2, which runs it as one Gaussian filter).
pub const LINEAR_FIELD_FILTER: [&str; 11] = [
    "filter",
    "--algorithm",
    "mpf-ekf2",
    "--storeys",
    "3",
    "--hysteretic",
    "none",
    "--masses",
    "1",
    "--measurement",
    "absolute",
];

/// The README's `sysid filter` of the shake-table frame (`northridge`, masses 1 : 1 : 1.2,
/// dashpots and αM, no hysteresis, absolute accelerations); `--data` and `--out` to add.
/// The settings `linear_field_data` simulates with, stated: the model and its noise levels are
/// right, and the held-out choice has nothing to choose.
pub const LINEAR_FIELD_STATED: [&str; 6] = [
    "--damping",
    "storey",
    "--noise-fraction",
    "0.1",
    "--process-noise-factor",
    "1",
];

pub const FRAME_FILTER: [&str; 13] = [
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
];

/// Runs `sysid` (the binary under test) with `args`; panics with its standard error unless it
/// succeeds; returns its standard output.
pub fn sysid_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .current_dir(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The clean ground motion and time step of the foreign corpus's `sysid simulate`
/// ([`experiments::foreign::GROUND`]: El Centro 1940 × 3, 31.18 s at 200 Hz) with `extra`
/// arguments (another excitation, a duration), written under `dir`.
pub fn foreign_ground(dir: &std::path::Path, extra: &[&str]) -> (Vec<f64>, f64) {
    sysid_out(&experiments::foreign::GROUND, extra, dir);
    experiments::foreign::clean_ground(dir).unwrap()
}

/// [`sysid_ok`] with `args`, then `extra`, then `--out out`.
pub fn sysid_out(args: &[&str], extra: &[&str], out: &std::path::Path) -> String {
    let mut all: Vec<&std::ffi::OsStr> = args
        .iter()
        .chain(extra)
        .map(|a| std::ffi::OsStr::new(*a))
        .collect();
    all.extend(["--out".as_ref(), out.as_os_str()]);
    sysid_ok(all)
}

/// The 95 % credible interval a record (as JSON) reports for parameter `name`.
pub fn interval95(r: &serde_json::Value, name: &str) -> (f64, f64) {
    let p = r["credible"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["parameter"] == name)
        .unwrap();
    let i = p["intervals"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| (i["level"].as_f64().unwrap() - 0.95).abs() < 1e-9)
        .unwrap();
    (i["lo"].as_f64().unwrap(), i["hi"].as_f64().unwrap())
}

/// `sysid import` of the shake-table frame's `northridge` record into `dir`.
pub fn import_frame_northridge(dir: &std::path::Path) {
    sysid_ok([
        std::ffi::OsStr::new("import"),
        "--map".as_ref(),
        "experiments/real/frame-northridge.toml".as_ref(),
        "--out".as_ref(),
        dir.as_os_str(),
    ]);
}

/// `sysid simulate` of a linear 3-storey building (`duration` s, absolute accelerations, the
/// noise stream of `seed`) written into `dir` as field data: only `measured.csv`.
pub fn linear_field_data(dir: &std::path::Path, seed: &str, duration: &str) {
    linear_field_data_with(dir, seed, duration, &[]);
}

/// [`linear_field_data`] with more `sysid simulate` arguments (`--sensors 1,3`, …).
pub fn linear_field_data_with(dir: &std::path::Path, seed: &str, duration: &str, extra: &[&str]) {
    let args = [
        "simulate",
        "--storeys",
        "3",
        "--hysteretic",
        "none",
        "--duration",
        duration,
        "--seed",
        seed,
        "--absolute",
    ];
    sysid_out(&args, extra, dir);
    for f in ["dataset.json", "truth.csv"] {
        std::fs::remove_file(dir.join(f)).unwrap();
    }
}

/// A fresh directory under the system temp dir whose name starts with `prefix`, and the guard
/// that removes it when dropped (also when the test panics).
pub fn temp_dir(prefix: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::Builder::new().prefix(prefix).tempdir().unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

pub const NAMES: [&str; 9] = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
pub const THETA_TRUE: [f64; 9] = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 2.0, 1.0, 2.0];

/// A completed run with θ_val = ratios × θ_true, online and validation state NRMSE `nrmse` on
/// all seven states, no trace, no loops.
pub fn record(algorithm: &str, run: u64, ratios: [f64; 9], nrmse: f64) -> RunRecord {
    let theta_val: Vec<f64> = THETA_TRUE.iter().zip(ratios).map(|(t, r)| t * r).collect();
    let errors = StateErrors {
        names: ["x1", "x2", "x3", "v1", "v2", "v3", "r1"]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        errors: vec![
            SignalError {
                rmse: nrmse,
                cv_rmse: nrmse,
                nrmse,
            };
            7
        ],
    };
    sealed(RunRecord {
        experiment: "constructed".into(),
        algorithm: algorithm.into(),
        seed: 1,
        run,
        particles: 500,
        param_names: NAMES.iter().map(|s| s.to_string()).collect(),
        theta_true: Some(THETA_TRUE.to_vec()),
        rel_error: Some(ratios.iter().map(|r| (r - 1.0).abs()).collect()),
        theta_val,
        window: 80,
        theta_sd_final: THETA_TRUE.iter().map(|v| 0.05 * v).collect(),
        loglik: -100.0,
        steps_total: 1000,
        steps_completed: 1000,
        ess_min: 200.0,
        ess_mean: 450.0,
        distinct_sampled: BTreeMap::new(),
        failures: BTreeMap::new(),
        failure: None,
        health: Health::default(),
        online_states: Some(errors.clone()),
        validation: Some(Validation {
            states: errors,
            loop_validation: None,
            loop_true: None,
            error: None,
        }),
        config: serde_json::json!({}),
        versions: Versions::current(),
        fingerprint: None,
        trace: Trace::default(),
        timing: Timing {
            wall_s: 1.0,
            particle_steps_per_s: 5.0e5,
            validation_s: 0.1,
            realtime_factor: None,
            plan_s: None,
            threads: None,
            particle_blocks: false,
        },
        warnings: Vec::new(),
        credible: Vec::new(),
        theta_correlation: Vec::new(),
        segment_spread: None,
        innovation_checks: Vec::new(),
        residuals: None,
        free_run: None,
        modal: None,
        pool_left_out: vec![],
        plan: None,
        one_gaussian_filter: false,
    })
}

/// `r` with filter settings in its config and the fingerprint of its own algorithm, seed, run
/// and settings, so that it passes the checks of the record reader (call it again after changing
/// any of them).
pub fn sealed(r: RunRecord) -> RunRecord {
    let filter = serde_json::json!({ "particles": r.particles, "window": r.window });
    sealed_with(r, filter)
}

/// [`sealed`] with the filter settings `filter` (which must hold the record's `particles` and
/// `window`).
pub fn sealed_with(mut r: RunRecord, filter: serde_json::Value) -> RunRecord {
    r.config = serde_json::json!({ "filter": filter });
    r.fingerprint = Some(Fingerprint::new(serde_json::json!({
        "algorithm": r.algorithm,
        "seed": r.seed,
        "run": r.run,
        "numerics": r.versions.numerics,
        "filter": filter,
        "data": { "sha256": "constructed", "meta": null },
    })));
    r
}

/// A deterministic, zero-mean perturbation in [−0.5, 0.5) for run `run` and stream `s`.
pub fn wiggle(run: u64, s: u64) -> f64 {
    let mut z = run
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(s.wrapping_mul(0xBF58_476D_1CE4_E5B9));
    z = (z ^ (z >> 30)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

/// A trace relaxing from 1.3 × `from` towards `to`, with s.d.s shrinking; `steps` kept steps.
pub fn trace(from: &[f64], to: &[f64], steps: usize) -> Trace {
    let mut t = Trace {
        every: 10,
        ..Trace::default()
    };
    for k in 0..steps {
        let time = k as f64 * 0.05;
        let w = (-time).exp();
        t.t.push(time);
        t.param_mean.push(
            from.iter()
                .zip(to)
                .map(|(a, b)| 1.3 * a * w + b * (1.0 - w))
                .collect(),
        );
        t.param_sd
            .push(from.iter().map(|a| 0.2 * a.abs() * (0.1 + w)).collect());
        t.ess.push(400.0 - 100.0 * w);
    }
    t
}

/// A loop of a Bouc–Wen-like element of stiffness `k1`.
pub fn hysteresis_loop(k1: f64) -> Loop {
    let phase: Vec<f64> = (0..200)
        .map(|i| i as f64 * 4.0 * std::f64::consts::PI / 200.0)
        .collect();
    Loop {
        x: phase.iter().map(|p| 0.05 * p.sin()).collect(),
        force: phase
            .iter()
            .map(|p| k1 * 0.05 * (p.sin() + 0.4 * p.cos()).tanh())
            .collect(),
    }
}
