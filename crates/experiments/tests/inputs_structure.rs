//! Any building (SPEC §9): the structure description of simulated data (`--storeys`,
//! `--hysteretic`, `--sensors`) and of field data (`sysid filter` flags or the `[structure]` table),
//! through the library and through the `sysid` binary. Every malformed description is an error
//! naming the file or flag and the field; a simulate → filter round trip with sparse sensors and
//! two hysteretic storeys runs every algorithm.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use identify::field::StructureSettings;
use identify::pipeline::{chain_spec, FilterSettings};
use models::dataset::{generate, load_dir, DatasetConfig, DatasetError, MeasurementKind};

fn sysid() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sysid"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-structure-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn run(args: &[&str]) -> Output {
    sysid().args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// An error exit (1 for a toolkit error, 2 for clap) whose message holds every one of `words`.
fn assert_refused(o: &Output, words: &[&str]) {
    let code = o.status.code();
    let e = stderr(o);
    assert!(
        code == Some(1) || code == Some(2),
        "exit {:?}: {e}",
        o.status
    );
    assert!(!e.contains("panicked"), "{e}");
    for w in words {
        assert!(e.contains(w), "`{w}` missing from: {e}");
    }
}

fn config(storeys: usize, hysteretic: &[usize], sensors: &[usize]) -> DatasetConfig {
    let mut c = DatasetConfig::from_preset("shear-chain", 3).unwrap();
    c.storeys = Some(storeys);
    c.hysteretic = Some(hysteretic.to_vec());
    c.sensors = Some(sensors.to_vec());
    c.duration = Some(1.0);
    c
}

#[test]
fn malformed_descriptions_are_refused_by_field_in_the_library() {
    let cases: [(DatasetConfig, &str, &str); 5] = [
        (config(4, &[1, 5], &[1]), "hysteretic", "storey 5 is above"),
        (config(4, &[1], &[0, 2]), "sensors", "storey 0"),
        (config(4, &[1], &[2, 2]), "sensors", "listed twice"),
        (config(4, &[1], &[]), "sensors", "at least one"),
        (config(4, &[2, 2], &[1]), "hysteretic", "listed twice"),
    ];
    for (c, field, words) in cases {
        match generate(&c) {
            Err(DatasetError::InvalidConfig { field: f, message }) => {
                assert_eq!(f, field, "{message}");
                assert!(message.contains(words), "{message}");
            }
            other => panic!("{field}: {other:?}"),
        }
    }
    // A valid sparse description: channels are the measured storeys, the truth every storey.
    let d = generate(&config(4, &[1, 3], &[2, 4])).unwrap();
    assert_eq!(d.channels(), 2);
    assert_eq!(d.truth.dim(), 2 * 4 + 2);
    assert_eq!(d.meta().structure.unwrap().sensors, [2, 4]);
}

/// Writes a field-data directory (only `measured.csv`) with `header` and a short record.
fn field_dir(dir: &Path, header: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let cols = header.split(',').count();
    let mut text = format!("{header}\n");
    for k in 0..50 {
        let t = k as f64 * 0.01;
        let row: Vec<String> = (1..cols)
            .map(|j| format!("{}", (t * 7.0 + j as f64).sin()))
            .collect();
        text.push_str(&format!("{t},{}\n", row.join(",")));
    }
    let p = dir.join("measured.csv");
    std::fs::write(&p, text).unwrap();
    p
}

fn stated(storeys: usize, hysteretic: &[usize], masses: &[f64]) -> FilterSettings {
    FilterSettings {
        structure: StructureSettings {
            storeys: Some(storeys),
            hysteretic: Some(hysteretic.to_vec()),
            masses: Some(masses.to_vec()),
            measurement: Some(MeasurementKind::Absolute),
            damping: None,
        },
        ..FilterSettings::default()
    }
}

#[test]
fn field_data_structures_are_checked_against_the_header_in_the_library() {
    let (_tmp, dir) = temp_dir("lib");
    field_dir(&dir.join("f"), "t,ug,a1,a3,a5");
    let data = load_dir(&dir.join("f")).unwrap();
    assert_eq!(data.sensors, [1, 3, 5]);
    let err = |s: &FilterSettings| format!("{:#}", chain_spec(&data, None, s).unwrap_err());
    // The header measures storey 5 of a 3-storey building.
    let e = err(&stated(3, &[1], &[1.0]));
    assert!(e.contains("measured.csv") && e.contains("`a5`"), "{e}");
    // Masses of the wrong length; a hysteretic storey above the top.
    let e = err(&stated(5, &[1], &[1.0, 2.0]));
    assert!(e.contains("`masses`") && e.contains("2 masses"), "{e}");
    let e = err(&stated(5, &[6], &[1.0]));
    assert!(e.contains("`hysteretic`") && e.contains("storey 6"), "{e}");
    // Nothing stated: every missing key is named.
    let e = err(&FilterSettings::default());
    for key in [
        "storeys",
        "hysteretic",
        "masses",
        "measurement",
        "field data",
    ] {
        assert!(e.contains(key), "{key}: {e}");
    }
    // A complete description: one value of `masses` is every storey's mass.
    let spec = chain_spec(&data, None, &stated(6, &[1, 4], &[2.0])).unwrap();
    assert_eq!(spec.building.masses(), [2.0; 6]);
    assert_eq!(spec.building.hysteretic(), [0, 3]);
    assert_eq!(spec.sensors.one_based(), [1, 3, 5]);
    assert_eq!(spec.sensors.kind(), MeasurementKind::Absolute);
}

/// `r_noise_fraction` reaches the partitions' q_r for field and simulated data alike: a tenth of
/// the SPEC's fraction gives a tenth of its q_r, element by element; the SPEC's leaves it bit for
/// bit.
#[test]
fn the_process_noise_of_r_follows_its_setting_for_field_and_simulated_data() {
    let (_tmp, dir) = temp_dir("rnoise");
    field_dir(&dir.join("f"), "t,ug,a1,a3,a5");
    let field = load_dir(&dir.join("f")).unwrap();
    let set = generate(&config(4, &[1, 3], &[1, 2, 3, 4])).unwrap();
    let simulated = set.to_loaded();
    let cases = [
        (&field, None, stated(6, &[1, 4], &[2.0])),
        (&simulated, Some(&set.chain), FilterSettings::default()),
    ];
    for (data, chain, spec_settings) in cases {
        let spec = chain_spec(data, chain, &spec_settings).unwrap();
        assert_eq!(spec.q_r.len(), 2);
        let tenth = FilterSettings {
            r_noise_fraction: spec_settings.r_noise_fraction / 10.0,
            ..spec_settings.clone()
        };
        let smaller = chain_spec(data, chain, &tenth).unwrap();
        for (a, b) in smaller.q_r.iter().zip(&spec.q_r) {
            assert!((a / b - 0.1).abs() < 1e-12, "{a} against {b}");
        }
        assert_eq!(smaller.q_vel.to_bits(), spec.q_vel.to_bits());
    }
}

#[test]
fn malformed_descriptions_are_refused_by_flag_in_the_binary() {
    let (_tmp, dir) = temp_dir("bin");
    let out = dir.join("d");
    let o = out.to_str().unwrap();
    let sim = |extra: &[&str]| {
        let mut a = vec!["simulate", "--duration", "1", "--out", o];
        a.extend_from_slice(extra);
        run(&a)
    };
    let cases: [(&[&str], &[&str]); 5] = [
        (
            &["--storeys", "3", "--hysteretic", "4"],
            &["--hysteretic", "storey 4"],
        ),
        (&["--sensors", "0,2"], &["--sensors", "storey 0"]),
        (&["--sensors", "1,1"], &["--sensors", "listed twice"]),
        (&["--sensors", "1,x"], &["--sensors", "`x`"]),
        (&["--hysteretic", "1,,2"], &["--hysteretic"]),
    ];
    for (extra, words) in cases {
        assert_refused(&sim(extra), words);
        assert!(!out.exists(), "{extra:?} wrote a data set");
    }

    // Field data: every missing key is named with its flag and table key.
    let f = dir.join("field");
    let measured = field_dir(&f, "t,ug,a1,a3,a5");
    let r = dir.join("r.json");
    let filter = |extra: &[&str]| {
        let mut a = vec!["filter", "--algorithm", "mpf-ekf2", "--particles", "10"];
        a.extend_from_slice(&["--data", f.to_str().unwrap(), "--out", r.to_str().unwrap()]);
        a.extend_from_slice(extra);
        run(&a)
    };
    let m = measured.display().to_string();
    assert_refused(
        &filter(&[]),
        &[
            &m,
            "--storeys",
            "--hysteretic",
            "--masses",
            "--measurement",
            "[structure]",
        ],
    );
    // Only the measurement kind missing: only it is named.
    let o1 = filter(&["--storeys", "5", "--hysteretic", "1", "--masses", "1"]);
    assert_refused(&o1, &["--measurement", "absolute|relative"]);
    assert!(!stderr(&o1).contains("--storeys"), "{}", stderr(&o1));
    let full = ["--hysteretic", "1", "--measurement", "absolute"];
    // Header against structure, masses of the wrong length, a bad flag value.
    let mut a = vec!["--storeys", "3", "--masses", "1"];
    a.extend_from_slice(&full);
    assert_refused(&filter(&a), &[&m, "`a5`", "--storeys"]);
    let mut a = vec!["--storeys", "5", "--masses", "1,1"];
    a.extend_from_slice(&full);
    assert_refused(&filter(&a), &["--masses", "2 masses", "5 storeys"]);
    let mut a = vec!["--storeys", "5", "--masses", "1,-1,1,1,1"];
    a.extend_from_slice(&full);
    assert_refused(
        &filter(&a),
        &["--masses", "mass of storey 2 is -1, not positive"],
    );
    assert_refused(
        &filter(&[
            "--storeys",
            "5",
            "--masses",
            "1",
            "--hysteretic",
            "1",
            "--measurement",
            "abs",
        ]),
        &["--measurement", "absolute or relative"],
    );
    // A duplicate column of the header.
    field_dir(&f, "t,ug,a1,a1");
    assert_refused(&filter(&[]), &[&m, "`a1`", "twice"]);
    assert!(!r.exists());

    // A flag contradicting dataset.json names both; an agreeing one is accepted.
    let st = sysid()
        .args(["simulate", "--duration", "1", "--storeys", "4", "--out", o])
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", stderr(&st));
    let filt = |extra: &[&str]| {
        let mut a = vec!["filter", "--algorithm", "mln-rbpf", "--particles", "10"];
        a.extend_from_slice(&["--data", o, "--out", r.to_str().unwrap()]);
        a.extend_from_slice(extra);
        run(&a)
    };
    assert_refused(
        &filt(&["--storeys", "5"]),
        &["--storeys", "dataset.json", "storeys = 4"],
    );
    assert_refused(
        &filt(&["--measurement", "absolute"]),
        &["--measurement", "dataset.json", "relative"],
    );
    let cfg = dir.join("c.toml");
    std::fs::write(&cfg, "[structure]\nhysteretic = [2]\n").unwrap();
    assert_refused(
        &filt(&["--config", cfg.to_str().unwrap()]),
        &[
            "[structure] `hysteretic`",
            cfg.to_str().unwrap(),
            "dataset.json",
        ],
    );
    let ok = filt(&["--storeys", "4", "--masses", "1,1,1,1"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
}

fn record(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn sparse_sensors_and_two_hysteretic_storeys_round_trip_through_every_algorithm() {
    let (_tmp, dir) = temp_dir("trip");
    let data = dir.join("d");
    let st = sysid()
        .args([
            "simulate",
            "--storeys",
            "4",
            "--hysteretic",
            "1,3",
            "--sensors",
            "2,4",
            "--absolute",
            "--seed",
            "5",
            "--duration",
            "3",
            "--out",
        ])
        .arg(&data)
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", stderr(&st));
    let header = std::fs::read_to_string(data.join("measured.csv")).unwrap();
    assert!(header.starts_with("t,ug,a2,a4\n"), "{}", &header[..40]);
    let truth = std::fs::read_to_string(data.join("truth.csv")).unwrap();
    assert!(truth.starts_with("t,ug,x1,x2,x3,x4,v1,v2,v3,v4,r1,r3\n"));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("dataset.json")).unwrap()).unwrap();
    let s = &meta["structure"];
    assert_eq!(s["storeys"], 4);
    assert_eq!(s["hysteretic"], serde_json::json!([1, 3]));
    assert_eq!(s["sensors"], serde_json::json!([2, 4]));
    assert_eq!(s["measurement"], "absolute");
    assert_eq!(s["masses"], serde_json::json!([1.0, 1.0, 1.0, 1.0]));

    let names = [
        "k1", "k2", "k3", "k4", "c1", "c2", "c3", "c4", "beta1", "gamma1", "n1", "beta3", "gamma3",
        "n3",
    ];
    for alg in ["bootstrap", "mln-rbpf", "storvik", "mpf-ekf2"] {
        let out = dir.join(format!("{alg}.json"));
        let o = sysid()
            .args(["filter", "--algorithm", alg, "--particles", "40", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        // A physically impossible answer of 40 particles on 3 s exits non-zero with its record
        // written; a configuration error writes nothing.
        assert!(out.exists(), "{alg}: {}", stderr(&o));
        let r = record(&out);
        assert_eq!(r["param_names"], serde_json::json!(names), "{alg}");
        assert_eq!(r["steps_completed"], 600, "{alg}: {}", stderr(&o));
        assert_eq!(r["theta_true"].as_array().unwrap().len(), names.len());
        let spec = &r["config"]["spec"];
        assert_eq!(spec["hysteretic"], serde_json::json!([0, 2]), "{alg}");
        assert_eq!(
            spec["sensors"]["storeys"],
            serde_json::json!([2, 4]),
            "{alg}"
        );
        assert_eq!(spec["sensors"]["kind"], "absolute", "{alg}");
        assert_eq!(spec["r_diag"].as_array().unwrap().len(), 2, "{alg}");
    }

    // The same measurements as field data, described by flags, and by a config table that the
    // flags override.
    let field = dir.join("field");
    std::fs::create_dir_all(&field).unwrap();
    std::fs::copy(data.join("measured.csv"), field.join("measured.csv")).unwrap();
    let cfg = dir.join("field.toml");
    std::fs::write(
        &cfg,
        "[structure]\nstoreys = 4\nhysteretic = [1, 3]\nmasses = [1.0]\nmeasurement = \"relative\"\n",
    )
    .unwrap();
    let out = dir.join("field.json");
    let o = sysid()
        .args(["filter", "--algorithm", "mpf-ekf2", "--particles", "40"])
        .args(["--measurement", "absolute", "--config"])
        .arg(&cfg)
        .arg("--data")
        .arg(&field)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(out.exists(), "{}", stderr(&o));
    let r = record(&out);
    assert_eq!(r["param_names"], serde_json::json!(names));
    assert!(r["theta_true"].is_null());
    let given = &r["config"]["filter"]["structure"];
    assert_eq!(
        given["measurement"], "absolute",
        "the flag overrides the table"
    );
    assert_eq!(given["storeys"], 4);
    assert_eq!(r["config"]["spec"]["sensors"]["kind"], "absolute");
    assert_eq!(
        r["config"]["spec"]["masses"],
        serde_json::json!([1.0, 1.0, 1.0, 1.0])
    );
}

#[test]
fn printed_defaults_and_the_field_example_parse() {
    let o = run(&["filter", "--print-config"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    let parsed: FilterSettings = toml::from_str(&text).unwrap();
    // The printed file is what `sysid filter` runs without a config.
    assert_eq!(parsed, FilterSettings::recommended());
    // Every key of the settings is documented (as a key or a commented example).
    for key in [
        "particles",
        "resampling",
        "ess_threshold",
        "pool",
        "storvik_update",
        "noise_fraction",
        "discretisation",
        "substeps",
        "window",
        "trace_every",
        "validate",
        "loop_every",
        "marginal_prior",
        "[fix]",
        "[structure]",
        "storeys",
        "hysteretic",
        "masses",
        "measurement",
        "[prior]",
    ] {
        assert!(text.contains(key), "{key} missing from --print-config");
    }
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/examples/field.toml");
    let s = identify::limits::load_filter_settings(&example).unwrap();
    assert_eq!(s.structure.storeys, Some(5));
    assert_eq!(s.structure.measurement, Some(MeasurementKind::Absolute));
    assert!(s.structure.hysteretic.is_some() && s.structure.masses.is_some());
}
