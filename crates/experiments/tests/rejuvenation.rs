//! The rejuvenation move of the sampled static parameters (`rejuvenation`, the Liu–West kernel):
//! absent, the runs are those computed before the option existed, to the bit; with δ = 1 or on
//! the bootstrap PF (no static parameter) nothing moves and no draw is taken; on, the Bouc–Wen
//! exponent n of every marginalised filter keeps (nearly) as many values as particles; a run is
//! the same with 1 and 2 threads; a discount outside [1/3, 1] is refused by name.

use std::path::{Path, PathBuf};
use std::process::Command;

use experiments::study::Study;
use experiments::sweep::{run_sweep, Shard, SweepOptions};
use identify::pipeline::{identify, Algorithm, FilterSettings, RunInput};
use identify::record::RunRecord;
use models::dataset::{generate, Dataset, DatasetConfig};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-rejuv-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// `duration` s of the paper's data set (seed 3).
fn data(duration: f64) -> Dataset {
    let mut config = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    config.duration = Some(duration);
    generate(&config).unwrap()
}

fn run(data: &Dataset, alg: Algorithm, s: &FilterSettings) -> RunRecord {
    let loaded = data.to_loaded();
    let input = RunInput {
        data: &loaded,
        chain: Some(&data.chain),
        experiment: "rejuvenation",
        seed: 5,
        run: 0,
        progress: None,
        residuals: false,
    };
    identify(&input, alg, s).unwrap()
}

/// The record as JSON without what names the settings (config, fingerprint) or the time.
fn numbers(r: &RunRecord) -> serde_json::Value {
    let mut v = serde_json::to_value(r).unwrap();
    for key in ["config", "fingerprint", "timing"] {
        v.as_object_mut().unwrap().remove(key);
    }
    v
}

/// Without the field a run is the one computed before the option existed: the committed Fig. 8
/// record (MPF-EKF2, 500 particles, the full paper record) is recomputed to the bit, with the
/// same fingerprint, and its settings are written without the field.
#[test]
fn without_the_field_the_committed_record_is_recomputed_bit_for_bit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let study = Study::load(&root.join("experiments/fig8.toml")).unwrap();
    let jobs = study.jobs();
    assert_eq!(jobs.len(), 1);
    let committed: RunRecord = serde_json::from_str(
        &std::fs::read_to_string(
            root.join("results/paper/records/fig8/mpf-ekf2-np500-systematic-run000.json"),
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(
        study.job_fingerprint(&jobs[0]).unwrap(),
        committed.fingerprint.as_ref().unwrap().sha256,
        "the settings' fingerprint changed"
    );
    let fresh = study.run_job(&jobs[0]).unwrap();
    assert!(fresh.config["filter"].get("rejuvenation").is_none());
    assert_eq!(fresh.deterministic_json(), committed.deterministic_json());
}

/// δ = 1 does not move (h = 0) and the bootstrap PF declares no static parameter: both runs are
/// the run without the field, number for number (no copy, no draw); only the settings differ.
#[test]
fn a_kernel_that_does_not_move_and_the_bootstrap_pf_change_nothing() {
    let d = data(2.0);
    let off = FilterSettings {
        particles: 60,
        validate: false,
        ..FilterSettings::default()
    };
    let still = FilterSettings {
        rejuvenation: Some(1.0),
        ..off.clone()
    };
    let on = FilterSettings {
        rejuvenation: Some(0.95),
        ..off.clone()
    };
    let a = run(&d, Algorithm::MpfEkf2, &off);
    let b = run(&d, Algorithm::MpfEkf2, &still);
    assert_eq!(numbers(&a), numbers(&b));
    assert_eq!(b.config["filter"]["rejuvenation"], 1.0);
    assert_ne!(a.fingerprint, b.fingerprint);
    // The same comparison can fail: a moving kernel changes the run.
    assert_ne!(numbers(&a), numbers(&run(&d, Algorithm::MpfEkf2, &on)));
    let a = run(&d, Algorithm::Bootstrap, &off);
    let b = run(&d, Algorithm::Bootstrap, &on);
    assert_eq!(numbers(&a), numbers(&b));
}

/// On a short record with resampling at every step, n collapses to a few values without the
/// move and keeps nearly one value per particle with it, for the three filters that sample it;
/// every value stays inside the prior's support U(1, 5) (its 95 % interval does).
#[test]
fn the_move_keeps_many_distinct_values_of_n() {
    let d = data(3.0);
    let off = FilterSettings {
        particles: 125,
        validate: false,
        trace_every: 0,
        ..FilterSettings::default()
    };
    let on = FilterSettings {
        rejuvenation: Some(0.98),
        ..off.clone()
    };
    for alg in [Algorithm::MpfEkf2, Algorithm::MlnRbpf, Algorithm::Storvik] {
        let a = run(&d, alg, &off);
        let b = run(&d, alg, &on);
        assert!(a.failure.is_none() && b.failure.is_none(), "{}", alg.name());
        let (na, nb) = (a.distinct_sampled["n"], b.distinct_sampled["n"]);
        assert!(
            na <= 5,
            "{}: {na} distinct values of n without the move",
            alg.name()
        );
        assert!(
            nb >= 100,
            "{}: {nb} distinct values of n with it",
            alg.name()
        );
        let j = b.param_names.iter().position(|p| p == "n").unwrap();
        for iv in &b.credible[j].intervals {
            assert!(1.0 < iv.lo && iv.hi < 5.0, "{}: {iv:?}", alg.name());
        }
    }
}

/// A user prior of n changes the support the move keeps to: n ~ U(1.5, 2.5) stays inside it.
#[test]
fn the_support_is_the_prior_in_use() {
    let d = data(2.0);
    let mut prior = models::filtering::ChainPrior::paper(3, &[0]);
    prior
        .set_prior("n", models::priors::Prior::Uniform { lo: 1.5, hi: 2.5 })
        .unwrap();
    let s = FilterSettings {
        particles: 60,
        validate: false,
        prior: Some(prior),
        rejuvenation: Some(1.0 / 3.0),
        ..FilterSettings::default()
    };
    let r = run(&d, Algorithm::MpfEkf2, &s);
    let j = r.param_names.iter().position(|p| p == "n").unwrap();
    assert!(r.distinct_sampled["n"] >= 50);
    for iv in &r.credible[j].intervals {
        assert!(1.5 < iv.lo && iv.hi < 2.5, "{iv:?}");
    }
}

/// A sweep with the move gives the same records with 1 and 2 threads (pooled filters included).
#[test]
fn a_sweep_with_the_move_is_thread_count_invariant() {
    let text = r#"
name = "rejuv"
description = "rejuvenation test"
[data]
preset = "paper-3dof"
duration = 2.0
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2"]
runs = 2
master_seed = 7
particles = [60]
[filter]
trace_every = 50
loop_every = 0
pool = 2
rejuvenation = 0.97
"#;
    let study: Study = toml::from_str(text).unwrap();
    let records = |threads: usize| {
        let (_tmp, dir) = temp_dir(&format!("t{threads}"));
        let opts = SweepOptions {
            threads,
            shard: Shard::default(),
            progress: false,
            label: "test".into(),
            resume: false,
        };
        let out = run_sweep(
            &study.jobs(),
            Study::job_id,
            |j| study.job_fingerprint(j),
            &dir,
            &opts,
            |j| study.run_job(j),
        )
        .unwrap();
        out.records
            .iter()
            .map(RunRecord::deterministic_json)
            .collect::<Vec<_>>()
    };
    let one = records(1);
    assert_eq!(one.len(), 4);
    assert!(one.iter().all(|r| r.contains("\"rejuvenation\":0.97")));
    assert_eq!(one, records(2), "1 thread and 2 threads differ");
}

/// A discount outside [1/3, 1] is refused by the field's name: in settings, a config file and
/// on the command line.
#[test]
fn a_bad_discount_is_refused_by_name() {
    let d = data(1.0);
    let loaded = d.to_loaded();
    let input = RunInput {
        data: &loaded,
        chain: Some(&d.chain),
        experiment: "rejuvenation",
        seed: 1,
        run: 0,
        progress: None,
        residuals: false,
    };
    for bad in [0.0, 0.3, 1.01, f64::NAN, -1.0] {
        let s = FilterSettings {
            particles: 10,
            rejuvenation: Some(bad),
            ..FilterSettings::default()
        };
        let e = format!(
            "{:#}",
            identify(&input, Algorithm::MpfEkf2, &s).unwrap_err()
        );
        assert!(e.contains("field `rejuvenation`"), "{e}");
    }
    let (_tmp, dir) = temp_dir("bad");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "rejuvenation = 2.0\n").unwrap();
    let e = format!(
        "{:#}",
        identify::limits::load_filter_settings(&config).unwrap_err()
    );
    assert!(
        e.contains("`rejuvenation`") && e.contains("bad.toml"),
        "{e}"
    );
    let data_dir = dir.join("d");
    d.write_dir(&data_dir).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(["filter", "--algorithm", "mpf-ekf2", "--particles", "10"])
        .args(["--rejuvenation", "0.2", "--data"])
        .arg(&data_dir)
        .arg("--out")
        .arg(dir.join("r.json"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("`rejuvenation`"), "{err}");
}

/// A study's `[filter_for.<algorithm>]` keys reach that algorithm's runs only, take part in
/// their fingerprints, and are checked when the study is loaded: an unknown algorithm, an unknown
/// key and a bad value are refused by the table's name.
#[test]
fn a_study_gives_one_algorithm_its_own_keys() {
    let text = |extra: &str| {
        format!(
            r#"
name = "per-algorithm"
description = "per-algorithm keys"
[data]
preset = "paper-3dof"
duration = 1.0
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2"]
runs = 1
master_seed = 7
particles = [20]
[filter]
trace_every = 0
{extra}
"#
        )
    };
    let (_tmp, dir) = temp_dir("filter-for");
    let path = dir.join("s.toml");
    std::fs::write(
        &path,
        text("[filter_for.mpf-ekf2]\nrejuvenation = 0.97\npool = 2"),
    )
    .unwrap();
    let study = Study::load(&path).unwrap();
    let plain: Study = toml::from_str(&text("")).unwrap();
    for job in study.jobs() {
        let s = study.settings(&job).unwrap();
        let base = plain.settings(&job).unwrap();
        if job.algorithm == Algorithm::MpfEkf2 {
            assert_eq!((s.rejuvenation, s.pool), (Some(0.97), 2));
            assert_eq!(
                s,
                FilterSettings {
                    rejuvenation: Some(0.97),
                    pool: 2,
                    ..base
                }
            );
            assert_ne!(
                study.job_fingerprint(&job).unwrap(),
                plain.job_fingerprint(&job).unwrap()
            );
        } else {
            assert_eq!(s, base);
            assert_eq!(
                study.job_fingerprint(&job).unwrap(),
                plain.job_fingerprint(&job).unwrap()
            );
        }
    }
    for (extra, expect) in [
        ("[filter_for.kalman]\npool = 2", "filter_for.kalman"),
        ("[filter_for.mpf-ekf2]\nno_such_key = 1", "no_such_key"),
        ("[filter_for.storvik]\nrejuvenation = 0.2", "`rejuvenation`"),
        ("[filter_for.storvik]\nparticles = 100", "sweep.particles"),
    ] {
        std::fs::write(&path, text(extra)).unwrap();
        let e = format!("{:#}", Study::load(&path).unwrap_err());
        assert!(e.contains(expect) && e.contains("s.toml"), "{extra}: {e}");
    }
}

/// Without a config `sysid filter` gives the MPF-EKF2 with the shared prior Gaussian the
/// recommended rejuvenation and the other filters none; `--rejuvenation 1` (no move) and a config without the key keep the MPF-EKF2
/// without one.
#[test]
fn the_mpf_ekf2_rejuvenates_by_default() {
    let (_tmp, dir) = temp_dir("default");
    let data_dir = dir.join("d");
    data(0.5).write_dir(&data_dir).unwrap();
    let config = dir.join("c.toml");
    std::fs::write(&config, "particles = 20\n").unwrap();
    let mut n = 0;
    let mut rejuvenation = |alg: &str, extra: &[&str]| {
        n += 1;
        let out = dir.join(format!("{alg}-{n}.json"));
        let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
            .args(["filter", "--algorithm", alg, "--particles", "20", "--data"])
            .arg(&data_dir)
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        r["config"]["filter"]["rejuvenation"].as_f64()
    };
    assert_eq!(
        rejuvenation("mpf-ekf2", &[]),
        Some(identify::pipeline::MPF_REJUVENATION)
    );
    for alg in ["mln-rbpf", "storvik", "bootstrap"] {
        assert_eq!(rejuvenation(alg, &[]), None, "{alg}");
    }
    assert_eq!(
        rejuvenation("mpf-ekf2", &["--rejuvenation", "1"]),
        Some(1.0)
    );
    let c = config.to_str().unwrap();
    assert_eq!(rejuvenation("mpf-ekf2", &["--config", c]), None);
    // A linear building has no exponent to move, and its settings say so.
    let mut linear = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    linear.duration = Some(0.5);
    linear.hysteretic = Some(vec![]);
    let linear_dir = dir.join("linear");
    generate(&linear).unwrap().write_dir(&linear_dir).unwrap();
    let out = dir.join("linear.json");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "20",
            "--data",
        ])
        .arg(&linear_dir)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        r["config"]["filter"]["rejuvenation"],
        serde_json::Value::Null
    );
    // On 10 storeys the MPF-EKF2's prior means are per particle and it does not rejuvenate.
    let mut tall = DatasetConfig::from_preset("building-chain", 1).unwrap();
    tall.storeys = Some(10);
    tall.duration = Some(0.1);
    let tall_dir = dir.join("tall");
    generate(&tall).unwrap().write_dir(&tall_dir).unwrap();
    let out = dir.join("tall.json");
    let o = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args([
            "filter",
            "--algorithm",
            "mpf-ekf2",
            "--particles",
            "20",
            "--data",
        ])
        .arg(&tall_dir)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        r["config"]["filter"]["rejuvenation"],
        serde_json::Value::Null
    );
    assert_eq!(
        r["config"]["filter"]["marginal_prior"]["kind"],
        "per_particle"
    );
}
