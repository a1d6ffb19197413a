//! One-step-ahead prediction errors (`identify::residuals`): from the true states and θ they
//! are the measurement noise (white, variance ≈ 1 once divided by the noise s.d.), whatever
//! filter's layout the posterior comes in; a run of `sysid filter` records them and `sysid plot`
//! draws their panels.

use std::process::Command;

use core_filters::smc::Posterior;
use identify::pipeline::{build_filter, chain_spec, Algorithm, FilterSettings};
use identify::residuals::{channel_checks, Predictor};
use models::dataset::{generate, DatasetConfig};
use models::filtering::Discretisation;

#[test]
fn predictions_from_the_truth_leave_only_the_noise() {
    let mut config = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    config.duration = Some(10.0);
    let set = generate(&config).unwrap();
    let data = set.to_loaded();
    let settings = FilterSettings {
        discretisation: Discretisation::Symplectic,
        ..FilterSettings::default()
    };
    let spec = chain_spec(&data, Some(&set.chain), &settings).unwrap();
    for algorithm in [Algorithm::MpfEkf2, Algorithm::MlnRbpf] {
        let layout = build_filter(algorithm, spec.clone(), &settings)
            .unwrap()
            .layout()
            .clone();
        // The truth's own integrator, so that only the noise is left.
        let mut exact = spec.clone();
        exact.discretisation = Discretisation::Rk4;
        let ys: Vec<f64> = (1..data.len()).flat_map(|k| data.y(k).to_vec()).collect();
        let channels = vec!["a1".to_string(), "a2".into(), "a3".into()];
        let mut p = Predictor::new(exact, ys, channels).unwrap();
        p.start(&layout);
        let truth = data.truth.as_ref().unwrap();
        let mut post = Posterior::for_layout(&layout);
        for (j, name) in layout.param_names.iter().enumerate() {
            let i = set.theta_names.iter().position(|n| n == name).unwrap();
            post.param_mean[j] = set.theta_true[i];
        }
        for k in 1..data.len() {
            for (j, name) in layout.state_names.iter().enumerate() {
                let i = truth.state_names.iter().position(|n| n == name).unwrap();
                post.state_mean[j] = truth.states.state(k)[i];
            }
            p.step(k, &post);
        }
        let res = p.finish();
        assert_eq!(res.t.len(), data.len() - 2, "{algorithm:?}");
        for c in channel_checks(&res) {
            // The prediction from the true state misses only the measurement noise and the
            // excitation's noise, which R accounts for: variance 1 within a few s.e.
            // (s.e. of a variance of n = 1998 normal values: √(2/n) ≈ 0.03).
            assert!(
                (c.variance - 1.0).abs() < 0.15,
                "{algorithm:?} {}: variance {}",
                c.channel,
                c.variance
            );
            assert!(
                c.mean.abs() < 0.1,
                "{algorithm:?} {}: mean {}",
                c.channel,
                c.mean
            );
            assert!(
                c.white,
                "{algorithm:?} {}: Q = {} ≥ {}",
                c.channel, c.ljung_box, c.critical
            );
        }
    }
}

#[test]
fn filter_records_prediction_errors_and_plot_draws_them() {
    let tmp = tempfile::Builder::new()
        .prefix("sysid-residuals-")
        .tempdir()
        .unwrap();
    let d = tmp.path();
    let sysid = env!("CARGO_BIN_EXE_sysid");
    let ok = |args: &[&str]| {
        let o = Command::new(sysid).args(args).output().unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
    };
    let data = d.join("data");
    let rec = d.join("run.json");
    let figs = d.join("figs");
    ok(&[
        "simulate",
        "--preset",
        "paper-3dof",
        "--seed",
        "2",
        "--duration",
        "6",
        "--out",
        data.to_str().unwrap(),
    ]);
    let text = ok(&[
        "filter",
        "--algorithm",
        "mpf-ekf2",
        "--data",
        data.to_str().unwrap(),
        "--particles",
        "100",
        "--seed",
        "2",
        "--out",
        rec.to_str().unwrap(),
    ]);
    assert!(
        text.contains("a2: one-step prediction errors / noise s.d."),
        "{text}"
    );
    let r: identify::record::RunRecord =
        serde_json::from_str(&std::fs::read_to_string(&rec).unwrap()).unwrap();
    assert_eq!(r.innovation_checks.len(), 3);
    let res = r.residuals.as_ref().unwrap();
    assert_eq!(res.t.len(), 1199);
    // The check leaves out the first quarter of the steps (the learning transient).
    assert!(r
        .innovation_checks
        .iter()
        .all(|c| c.variance.is_finite() && c.n == 1199 - 300));
    ok(&[
        "plot",
        rec.to_str().unwrap(),
        "--out",
        figs.to_str().unwrap(),
    ]);
    for f in [
        "convergence.svg",
        "ess.svg",
        "hysteresis.svg",
        "accelerations.svg",
        "innovations.svg",
        "innovation_acf.svg",
    ] {
        identify::figures::validate_svg(&figs.join(f)).unwrap();
    }
}

#[test]
fn field_data_in_one_command_prints_and_plots() {
    // The newcomer's case: only `measured.csv` of a 3-storey building, one command.
    let tmp = tempfile::Builder::new()
        .prefix("sysid-field-one-")
        .tempdir()
        .unwrap();
    let d = tmp.path();
    let sysid = env!("CARGO_BIN_EXE_sysid");
    let data = d.join("data");
    let field = d.join("field");
    let o = Command::new(sysid)
        .args(["simulate", "--preset", "paper-3dof", "--seed", "4", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::create_dir_all(&field).unwrap();
    std::fs::copy(data.join("measured.csv"), field.join("measured.csv")).unwrap();
    let figs = d.join("figs");
    let o = Command::new(sysid)
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "200",
            "--seed",
            "4",
        ])
        .args(["--storeys", "3", "--hysteretic", "1", "--masses", "1,1,1"])
        .args(["--measurement", "relative", "--data"])
        .arg(&field)
        .arg("--out")
        .arg(d.join("run.json"))
        .arg("--plot")
        .arg(&figs)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("prior scaled from the data"), "{out}");
    // A sensible identification: every k within 15 % of the truth (8).
    let r: identify::record::RunRecord =
        serde_json::from_str(&std::fs::read_to_string(d.join("run.json")).unwrap()).unwrap();
    for (name, v) in r.param_names.iter().zip(&r.theta_val) {
        if name.starts_with('k') {
            assert!((v / 8.0 - 1.0).abs() < 0.15, "{name} = {v}\n{out}");
        }
    }
    for f in [
        "convergence.svg",
        "ess.svg",
        "accelerations.svg",
        "innovations.svg",
        "innovation_acf.svg",
    ] {
        identify::figures::validate_svg(&figs.join(f)).unwrap();
    }
    // No truth, no validation run: the loop is skipped with a note, not drawn.
    assert!(!figs.join("hysteresis.svg").exists());
    assert!(out.contains("note:"), "{out}");
}
