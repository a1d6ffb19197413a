//! Each channel's measurement noise learned by maximum likelihood (`sysid filter --learn-noise`,
//! `identify::choice::channel_noise`): on data of the filter's own class with a known, different
//! noise level on each channel, the learned levels recover them and agree with those that
//! maximise the exact Kalman likelihood (θ fixed at the truth: the MPF-EKF2 of a linear chain
//! with every parameter fixed is the Kalman filter of the chain, `models`'
//! `mpf_ekf2_is_the_kalman_filter_of_a_linear_chain`); the plan keeps them; a particle run is
//! refused by name.

use crate::common;

use std::path::Path;

use identify::choice::channel_noise::SEARCH;

/// Noise fractions of the two channels: a1 at 2 % of its clean RMS, a2 at 10 %. The run starts
/// from 10 % on both (`--noise-fraction 0.1`), so a1 must move by a factor 5 and a2 not at all:
/// one scale for every channel cannot pass.
const FRACTIONS: [&str; 2] = ["0.02", "0.1"];

/// A two-storey linear building's field record whose channel a1 carries `FRACTIONS[0]` noise
/// and a2 `FRACTIONS[1]` (the same clean response: one seed, two noise levels, columns
/// spliced), written to `dir/field`; returns the true noise s.d. of each channel.
fn two_level_record(dir: &Path) -> Vec<f64> {
    let mut sd = Vec::new();
    let mut columns = Vec::new();
    for (i, nf) in FRACTIONS.iter().enumerate() {
        let out = dir.join(format!("sim{i}"));
        let args = [
            "simulate",
            "--storeys",
            "2",
            "--hysteretic",
            "none",
            "--duration",
            "10",
            "--seed",
            "3",
            "--absolute",
            "--noise-fraction",
            nf,
        ];
        common::sysid_out(&args, &[], &out);
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("dataset.json")).unwrap())
                .unwrap();
        sd.push(meta["noise"]["acc_sd"][i].as_f64().unwrap());
        columns.push(std::fs::read_to_string(out.join("measured.csv")).unwrap());
    }
    // t, ug and a1 from the first record, a2 from the second.
    let spliced: String = columns[0]
        .lines()
        .zip(columns[1].lines())
        .map(|(a, b)| {
            let a: Vec<&str> = a.split(',').collect();
            let b: Vec<&str> = b.split(',').collect();
            assert_eq!(a[0], b[0], "the two records share their time stamps");
            format!("{},{},{},{}\n", a[0], a[1], a[2], b[3])
        })
        .collect();
    std::fs::create_dir_all(dir.join("field")).unwrap();
    std::fs::write(dir.join("field/measured.csv"), spliced).unwrap();
    sd
}

/// The field flags of the record, its noise stated (nothing for the held-out choice to choose).
const FIELD: [&str; 20] = [
    "filter",
    "--algorithm",
    "mpf-ekf2",
    "--storeys",
    "2",
    "--hysteretic",
    "none",
    "--masses",
    "1",
    "--measurement",
    "absolute",
    "--damping",
    "storey",
    "--noise-fraction",
    "0.1",
    "--process-noise-factor",
    "1",
    "--learn-noise",
    "--seed",
    "1",
];

/// A record, as JSON.
fn read(record: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(record).unwrap()).unwrap()
}

/// Each learned level's 95 % interval in a record's plan.
fn intervals(record: &Path) -> Vec<[f64; 2]> {
    read(record)["plan"]["evidence"]["channel_noise"]["learned_sd_95"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| [i["lo"].as_f64().unwrap(), i["hi"].as_f64().unwrap()])
        .collect()
}

/// The channel-noise evidence of a record's plan: (settled s.d., learned s.d.).
fn learned(record: &Path) -> (Vec<f64>, Vec<f64>) {
    let r = read(record);
    let e = &r["plan"]["evidence"]["channel_noise"];
    let list = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let sd = list(&e["learned_sd"]);
    // The run used them: the record's measurement noise is the learned one.
    let r_diag = list(&r["config"]["spec"]["r_diag"]);
    for (s, r) in sd.iter().zip(&r_diag) {
        assert!((s * s - r).abs() <= 1e-12 * r, "{s}² against r_diag {r}");
    }
    (list(&e["settled_sd"]), sd)
}

#[test]
fn learned_noise_recovers_a_known_noise_level_per_channel_against_the_exact_kalman_likelihood() {
    let (_tmp, dir) = common::temp_dir("learned-noise");
    let truth = two_level_record(&dir);
    let data = dir.join("field");
    let data = data.to_str().unwrap();
    let identified = dir.join("identified.json");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(FIELD)
        .args(["--data", data, "--out", identified.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The noise line says the levels were learned, not the noise fraction's.
    assert!(
        err.contains("measurement noise learned per channel by maximum likelihood"),
        "{err}"
    );
    let (settled, sd) = learned(&identified);
    // θ fixed at the simulated building's: the filter is the exact Kalman filter of the chain.
    let exact = dir.join("exact.json");
    let truth_theta = ["--fix", "k1=8,k2=8,c1=0.25,c2=0.25"];
    common::sysid_out(
        &FIELD,
        &[&["--data", data][..], &truth_theta].concat(),
        &exact,
    );
    let (_, sd_exact) = learned(&exact);

    // The maximum-likelihood estimate of ln σ_i over T samples has s.e. about (S/R)/√(2T), S/R
    // the innovation variance over the noise variance (1.02–1.10 measured here: the whiteness
    // check's variances; 1.25 taken as its bound); the search lands within its last step of the
    // maximum.
    let samples = 2001.0_f64;
    let se = 1.25 / (2.0 * samples).sqrt();
    let last_step = SEARCH.last_step();
    let tol = 4.0 * se + last_step;
    for i in 0..2 {
        let (got, exact, want) = (sd[i].ln(), sd_exact[i].ln(), truth[i].ln());
        assert!(
            (exact - want).abs() <= tol,
            "a{}: exact-likelihood level {} against the true {} (tolerance {tol:.3} in ln)",
            i + 1,
            sd_exact[i],
            truth[i]
        );
        assert!(
            (got - want).abs() <= tol,
            "a{}: learned {} against the true {} (tolerance {tol:.3} in ln)",
            i + 1,
            sd[i],
            truth[i]
        );
        // θ identified with the noise rather than known: within two search steps and one s.e.
        // of the exact likelihood's level.
        assert!(
            (got - exact).abs() <= 2.0 * last_step + se,
            "a{}: learned {} against the exact likelihood's {}",
            i + 1,
            sd[i],
            sd_exact[i]
        );
    }
    // Each level's 95 % interval (Laplace, from the likelihood's curvature) holds the truth and
    // is as wide as the estimate's s.e. says: 1.96 × (S/R)/√(2T) on each side in ln, S/R in
    // [1, 1.25] (the bound above) — allowed [0.9, 1.5]/√(2T) for the curvature's finite
    // difference.
    for (i, [lo, hi]) in intervals(&identified).into_iter().enumerate() {
        assert!(
            lo <= truth[i] && truth[i] <= hi,
            "a{}: [{lo}, {hi}] against the true {}",
            i + 1,
            truth[i]
        );
        let se = (hi / lo).ln() / 2.0 / 1.96;
        let unit = 1.0 / (2.0 * samples).sqrt();
        assert!(
            (0.9 * unit..=1.5 * unit).contains(&se),
            "a{}: s.e. {se:.4} in ln against {unit:.4} × S/R",
            i + 1
        );
    }
    // The levels the run started from are not the truth (the test cannot pass without the
    // search): a1 5× too noisy.
    assert!(
        (settled[0].ln() - truth[0].ln()).abs() > 10.0 * tol,
        "{settled:?}"
    );
}

#[test]
fn a_learned_noise_plan_runs_again_as_printed_and_a_particle_run_is_refused() {
    let (_tmp, dir) = common::temp_dir("learned-noise-plan");
    two_level_record(&dir);
    let data = dir.join("field");
    let data = data.to_str().unwrap();
    let printed = common::sysid_ok(
        FIELD
            .iter()
            .copied()
            .chain(["--data", data, "--print-plan"]),
    );
    assert!(printed.contains("channel_noise"), "{printed}");
    let plan = dir.join("plan.toml");
    std::fs::write(&plan, &printed).unwrap();
    let (a, b) = (dir.join("a.json"), dir.join("b.json"));
    common::sysid_out(&FIELD, &["--data", data], &a);
    let args = ["filter", "--data", data, "--plan", plan.to_str().unwrap()];
    common::sysid_out(&args, &[], &b);
    let theta = |p: &Path| {
        let r = read(p);
        (
            r["theta_val"].clone(),
            r["config"]["spec"]["r_diag"].clone(),
        )
    };
    assert_eq!(theta(&a), theta(&b));

    // A sampling run's log-likelihood is an estimate: refused by name, nothing written.
    let out = dir.join("pf.json");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["filter", "--algorithm", "bootstrap", "--particles", "50"])
        .args(&FIELD[3..])
        .args(["--data", data, "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("--learn-noise needs a run that is one Gaussian filter"),
        "{err}"
    );
    assert!(!out.exists());
}
