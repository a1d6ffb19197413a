//! The cases of a hostile-user test of `sysid` (issue 28), kept as regression tests: input
//! limits of `sysid reference`, records that must read back through every reader, checks that
//! every reader makes, and the storey range of `building-chain`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-rel-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn run(args: &[&str], cwd: &Path) -> Output {
    sysid().args(args).current_dir(cwd).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A non-zero exit that is an error message, not a panic or an abort.
fn refused(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "accepted: {err}");
    // 1: an error of the command; 2: one of the command line (clap). Not 101 (panic), not a
    // signal (abort).
    assert!(
        matches!(o.status.code(), Some(1 | 2)),
        "{:?}: {err}",
        o.status
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(needle), "`{needle}` not in: {err}");
}

/// 1 s of the paper's data set in `dir/d`.
fn small_data(dir: &Path) -> PathBuf {
    let d = dir.join("d");
    let o = run(
        &["simulate", "--duration", "1", "--out", d.to_str().unwrap()],
        dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    d
}

#[test]
fn reference_refuses_counts_beyond_its_limits_by_flag() {
    let (_tmp, dir) = temp_dir("reference");
    let d = small_data(&dir);
    let data = d.to_str().unwrap();
    let out = dir.join("ref.json");
    let out = out.to_str().unwrap();
    for (flags, needle) in [
        (vec!["--iterations", "18446744073709551615"], "--iterations"),
        (vec!["--iterations", "1000000000000"], "--iterations"),
        (vec!["--iterations", "100000000"], "--iterations"),
        (vec!["--probe", "1000000000000"], "--probe"),
        (
            vec!["--burn-in", "18446744073709551615", "--iterations", "1"],
            "--burn-in",
        ),
        (vec!["--burn-in", "1000000000000"], "--burn-in"),
        (vec!["--iterations", "0"], "--iterations"),
        (vec!["--particles", "0"], "--particles"),
        (vec!["--estimator", "storvik"], "use mpf-ekf2 or bootstrap"),
        (vec!["--estimator", "mln-rbpf"], "use mpf-ekf2 or bootstrap"),
    ] {
        let mut args = vec!["reference", "--data", data, "--out", out];
        args.extend(&flags);
        refused(&run(&args, &dir), needle);
    }
    assert!(!Path::new(out).exists());
}

#[test]
fn reference_takes_the_structure_of_field_data_from_a_config() {
    let (_tmp, dir) = temp_dir("reference-field");
    let d = small_data(&dir);
    let field = dir.join("field");
    std::fs::create_dir_all(&field).unwrap();
    std::fs::copy(d.join("measured.csv"), field.join("measured.csv")).unwrap();
    let out = dir.join("ref.json");
    let short = [
        "--iterations",
        "4",
        "--burn-in",
        "0",
        "--probe",
        "2",
        "--particles",
        "10",
    ];
    let mut args = vec![
        "reference",
        "--data",
        field.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(short);
    refused(&run(&args, &dir), "--config");
    std::fs::write(
        dir.join("building.toml"),
        "[structure]\nstoreys = 3\nhysteretic = [1]\nmasses = [1.0, 1.0, 1.0]\nmeasurement = \"relative\"\n",
    )
    .unwrap();
    args.extend(["--config", "building.toml"]);
    let o = run(&args, &dir);
    // A 4-iteration chain may not move (then the record is written and the exit says so).
    assert!(
        o.status.success() || stderr(&o).contains("did not move"),
        "{}",
        stderr(&o)
    );
    let r: experiments::reference::ReferenceRecord = identify::record::read::read(&out).unwrap();
    assert_eq!(r.params.len(), 9);
}

/// A run whose residuals hold non-finite numbers (a prior so wide that particles overflow; a
/// constant field record) writes a record that `plot` and `compare-reference` read back.
#[test]
fn records_with_non_finite_residuals_read_back_through_every_reader() {
    let (_tmp, dir) = temp_dir("residuals");
    let d = small_data(&dir);
    std::fs::write(
        dir.join("wide.toml"),
        r#"particles = 200
[prior]
k = [{ kind = "log_normal", median = 10.0, log_sd = 300.0 }, { kind = "log_normal", median = 10.0, log_sd = 0.3 }, { kind = "log_normal", median = 10.0, log_sd = 0.3 }]
c = [{ kind = "log_normal", median = 0.4, log_sd = 0.5 }, { kind = "log_normal", median = 0.4, log_sd = 0.5 }, { kind = "log_normal", median = 0.4, log_sd = 0.5 }]
elements = [{ storey = 0, beta_gamma = { kind = "triangle", beta_max = 5.0 }, n = { kind = "uniform", lo = 1.0, hi = 5.0 } }]
"#,
    )
    .unwrap();
    let field = dir.join("const");
    std::fs::create_dir_all(&field).unwrap();
    let mut csv = String::from("t,ug,a1,a2,a3\n");
    for k in 0..200 {
        csv.push_str(&format!("{:.3},0.5,1.0,1.0,1.0\n", k as f64 * 0.005));
    }
    std::fs::write(field.join("measured.csv"), csv).unwrap();
    let cases: [(&str, Vec<&str>); 2] = [
        (
            "wide",
            vec![
                "--algorithm",
                "bootstrap",
                "--data",
                d.to_str().unwrap(),
                "--config",
                "wide.toml",
            ],
        ),
        (
            "const",
            vec![
                "--algorithm",
                "mln-rbpf",
                "--data",
                "const",
                "--particles",
                "50",
                "--storeys",
                "3",
                "--hysteretic",
                "1",
                "--masses",
                "1",
                "--measurement",
                "relative",
            ],
        ),
    ];
    let mut non_finite = 0;
    for (name, flags) in cases {
        let rec = format!("{name}.json");
        let figs = format!("{name}-figs");
        let mut args = vec!["filter", "--out", &rec, "--plot", &figs];
        args.extend(flags);
        let o = run(&args, &dir);
        let err = stderr(&o);
        // The run may be refused as physically impossible, but never because its own record
        // does not read back.
        assert!(!err.contains("does not read back"), "{name}: {err}");
        assert!(!err.contains("expected f64"), "{name}: {err}");
        assert!(
            dir.join(&figs).join("innovations.svg").exists(),
            "{name}: {err}"
        );
        let text = std::fs::read_to_string(dir.join(&rec)).unwrap();
        non_finite += text.matches("\"NaN\"").count()
            + text.matches("\"inf\"").count()
            + text.matches("\"-inf\"").count();
        let o = run(&["plot", &rec, "--out", &format!("{name}-again")], &dir);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
    }
    // The constant record is the one the issue found: its residuals hold non-finite numbers.
    assert!(non_finite > 0, "no non-finite number was exercised");
}

/// `plot` refuses what `merge` refuses: another schema, θ of the wrong length, more steps
/// completed than there are; a file beyond the size limit is refused by `plot`, `merge` and
/// `compare-reference` before it is read.
#[test]
fn every_reader_makes_the_same_checks() {
    let (_tmp, dir) = temp_dir("checks");
    let d = small_data(&dir);
    let o = run(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--data",
            d.to_str().unwrap(),
            "--particles",
            "10",
            "--out",
            "good.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    write_reference(&dir.join("r.json"));
    let o = run(
        &["compare-reference", "--reference", "r.json", "good.json"],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let good: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("good.json")).unwrap()).unwrap();
    let variant = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = good.clone();
        edit(&mut v);
        std::fs::write(dir.join(name), serde_json::to_string(&v).unwrap()).unwrap();
    };
    variant("schema.json", &|v| {
        v["versions"]["record_schema"] = 99.into()
    });
    variant("theta.json", &|v| {
        v["theta_val"].as_array_mut().unwrap().pop();
    });
    variant("steps.json", &|v| {
        v["steps_completed"] = (v["steps_total"].as_u64().unwrap() + 1).into()
    });
    variant("particles.json", &|v| v["particles"] = 11.into());
    for (name, needle) in [
        ("schema.json", "record schema 99"),
        ("theta.json", "theta_val has 8 entries for 9 parameters"),
        ("steps.json", "exceeds steps_total"),
        (
            "particles.json",
            "`particles` 11 disagrees with the fingerprint",
        ),
    ] {
        refused(&run(&["plot", name, "--out", "figs"], &dir), needle);
        refused(
            &run(&["compare-reference", "--reference", "r.json", name], &dir),
            needle,
        );
    }
    // merge: the same records as sources, and a directory named like a record.
    for (name, needle) in [
        (
            "particles.json",
            "`particles` 11 disagrees with the fingerprint",
        ),
        ("schema.json", "record schema 99"),
        ("x.json", "is not a file"),
    ] {
        let part = dir.join(format!("part-{name}"));
        let s = part.join("records").join("s");
        std::fs::create_dir_all(&s).unwrap();
        if name == "x.json" {
            std::fs::create_dir_all(s.join(name)).unwrap();
        } else {
            std::fs::copy(dir.join(name), s.join(name)).unwrap();
        }
        let into = dir.join(format!("into-{name}"));
        let o = run(
            &[
                "merge",
                part.to_str().unwrap(),
                "--into",
                into.to_str().unwrap(),
            ],
            &dir,
        );
        refused(&o, needle);
    }
    // 3 GiB, sparse: refused by size before a byte is read.
    let big = dir.join("big.json");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(3 << 30)
        .unwrap();
    refused(
        &run(&["plot", "big.json", "--out", "figs"], &dir),
        "bytes, more than",
    );
    refused(
        &run(
            &["compare-reference", "--reference", "big.json", "good.json"],
            &dir,
        ),
        "bytes, more than",
    );
    refused(
        &run(
            &["compare-reference", "--reference", "r.json", "big.json"],
            &dir,
        ),
        "bytes, more than",
    );
    let part = dir.join("part-big");
    std::fs::create_dir_all(part.join("records/s")).unwrap();
    std::fs::rename(&big, part.join("records/s/big.json")).unwrap();
    refused(
        &run(&["merge", "part-big", "--into", "into-big"], &dir),
        "bytes, more than",
    );
}

/// A reference posterior of the paper's nine parameters (constructed: the test is about reading).
fn write_reference(path: &Path) {
    use experiments::reference::ParamSummary;
    use experiments::reference::ReferenceRecord;
    let names = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
    let truth = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 2.0, 1.0, 2.0];
    let r = ReferenceRecord {
        data: "d".into(),
        data_sha256: None,
        steps: 200,
        dt: 0.005,
        estimator: "mpf-ekf2".into(),
        particles: 10,
        iterations: 1000,
        burn_in: 100,
        seed: 1,
        start: truth.to_vec(),
        loglik_at_start_mean: -100.0,
        loglik_at_start_sd: f64::NAN,
        acceptance: 0.3,
        acceptance_burn_in: 0.3,
        evaluations: 1100,
        failed_estimates: 0,
        wall_s: 1.0,
        params: names
            .iter()
            .zip(truth)
            .map(|(n, t)| ParamSummary {
                name: n.to_string(),
                mean: t,
                sd: 0.1 * t,
                quantiles: [0.8 * t, 0.9 * t, t, 1.1 * t, 1.2 * t],
                ess: 500.0,
                truth: Some(t),
            })
            .collect(),
        warnings: Vec::new(),
    };
    identify::record::read::write(path, &r).unwrap();
}

#[test]
fn fix_refuses_a_parameter_given_twice() {
    let (_tmp, dir) = temp_dir("fix");
    let d = small_data(&dir);
    let o = run(
        &[
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--data",
            d.to_str().unwrap(),
            "--fix",
            "k1=8,k1=9",
            "--out",
            "r.json",
        ],
        &dir,
    );
    refused(&o, "k1 is given twice");
}

#[test]
fn a_dataset_json_listing_a_file_it_does_not_hold_is_refused() {
    let (_tmp, dir) = temp_dir("listing");
    let d = small_data(&dir);
    let meta = d.join("dataset.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&meta).unwrap()).unwrap();
    let digest = v["files"]["truth.csv"].clone();
    v["files"]["extra.csv"] = digest;
    std::fs::write(&meta, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let e = models::dataset::load_dir(&d).unwrap_err().to_string();
    assert!(e.contains("extra.csv") && e.contains("missing"), "{e}");
}

#[test]
fn sweeps_refuse_more_threads_than_the_limit() {
    let (_tmp, dir) = temp_dir("threads");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let o = sysid()
        .args(["reproduce", "--quick", "--threads", "100000", "--out"])
        .arg(dir.join("out"))
        .current_dir(root)
        .output()
        .unwrap();
    refused(&o, "--threads");
    assert!(stderr(&o).contains("exceeds the maximum 1024"));
}

#[test]
fn building_chains_simulate_across_the_documented_range() {
    let (_tmp, dir) = temp_dir("building");
    for n in ["150", "200"] {
        let out = format!("b{n}");
        let o = run(
            &[
                "simulate",
                "--preset",
                "building-chain",
                "--storeys",
                n,
                "--duration",
                "5",
                "--out",
                &out,
            ],
            &dir,
        );
        assert!(o.status.success(), "{n} storeys: {}", stderr(&o));
        let data = models::dataset::load_dir(&dir.join(&out)).unwrap();
        assert!(data.y_meas.iter().all(|v| v.is_finite() && v.abs() < 1e4));
    }
}

/// `compare-reference` with the chains of two data sets puts each online record beside the
/// reference of its own data set (named by the data set's digest in both records) and adds the
/// information limit across them, and the chains' warnings; a record of a third data set is
/// refused, naming its file.
#[test]
fn compare_reference_groups_records_by_their_data_set() {
    let (_tmp, dir) = temp_dir("groups");
    for (name, seed) in [("a", "1"), ("b", "2"), ("c", "3")] {
        let o = run(
            &["simulate", "--duration", "1", "--seed", seed, "--out", name],
            &dir,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let o = run(
            &[
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--data",
                name,
                "--particles",
                "20",
                "--out",
                &format!("online-{name}.json"),
            ],
            &dir,
        );
        assert!(o.status.success(), "{}", stderr(&o));
    }
    for name in ["a", "b"] {
        let o = run(
            &[
                "reference",
                "--data",
                name,
                "--particles",
                "10",
                "--burn-in",
                "20",
                "--iterations",
                "40",
                "--probe",
                "2",
                "--start-at-truth",
                "--out",
                &format!("ref-{name}.json"),
            ],
            &dir,
        );
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let refs = ["--reference", "ref-a.json", "--reference", "ref-b.json"];
    let mut args = vec!["compare-reference"];
    args.extend(refs);
    args.extend(["online-a.json", "online-b.json", "--out", "cmp.md"]);
    let o = run(&args, &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let md = std::fs::read_to_string(dir.join("cmp.md")).unwrap();
    assert_eq!(md.matches("## Data set ").count(), 2, "{md}");
    assert!(md.contains("## Across the 2 data sets"), "{md}");
    // Each data set's table holds its one run; the limit table counts both.
    assert_eq!(md.matches("| mpf-ekf2 | 1 |").count(), 18, "{md}");
    assert!(md.contains("| k1 | mpf-ekf2 | 2 |"), "{md}");
    // 40 kept iterations: the chains' few effective samples are said in the file, not only on
    // the terminal.
    assert!(md.contains("Warnings on the reference chains"), "{md}");
    assert!(md.contains("ref-a.json: k1: chain ESS"), "{md}");
    let mut args = vec!["compare-reference"];
    args.extend(refs);
    args.extend(["online-a.json", "online-c.json"]);
    refused(&run(&args, &dir), "online-c.json");
}

/// A record whose `config` was edited after the run — the sensors' kind, which decides the
/// building `validate` models — is refused by every reader, `validate` included, naming the
/// file and the `config`; the unedited record is accepted (issue 50, item 10).
#[test]
fn a_record_with_an_edited_config_is_refused_before_it_is_used() {
    let (_tmp, dir) = temp_dir("config-edit");
    // Field data (measured.csv alone): nothing but the record says what the building is.
    let sim = small_data(&dir);
    let d = dir.join("f");
    std::fs::create_dir(&d).unwrap();
    std::fs::copy(sim.join("measured.csv"), d.join("measured.csv")).unwrap();
    let o = run(
        &[
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
            "relative",
            "--data",
            "f",
            "--out",
            "run.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    // Written again unedited, through serde_json: still accepted.
    std::fs::write(dir.join("same.json"), serde_json::to_string(&v).unwrap()).unwrap();
    let o = run(&["validate", "--record", "same.json", "--data", "f"], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let kind = &mut v["config"]["spec"]["sensors"]["kind"];
    assert_eq!(kind, "relative");
    *kind = "absolute".into();
    std::fs::write(dir.join("edited.json"), serde_json::to_string(&v).unwrap()).unwrap();
    for args in [
        &["validate", "--record", "edited.json", "--data", "f"][..],
        &[
            "validate",
            "--record",
            "edited.json",
            "--data",
            "f",
            "--out",
            "v.json",
        ],
        &["plot", "edited.json", "--out", "figs"],
    ] {
        let o = run(args, &dir);
        refused(&o, "edited.json");
        refused(&o, "`config` is not the one it was written with");
    }
    assert!(!dir.join("v.json").exists());
}
