//! Property-based fuzzing of every reader of `models`: excitation CSV, AT2, `measured.csv`,
//! `truth.csv` and `dataset.json`. Valid files are mutated (see `fuzz_common`) and each reader
//! must, for every mutated input, neither panic nor abort, and either return data that hold
//! the guarantees the rest of the tool relies on (bounded sizes and values, consistent
//! metadata), or an error whose message names the file.
//!
//! Fixed seeds; the numbers of cases are below (about 9,000 in all, a few seconds in the test
//! profile). Inputs that once crashed a reader are kept in `tests/fuzz_corpus/<target>/` and
//! replayed by `corpus_inputs_are_handled`.

use crate::fuzz_common;

use fuzz_common::{apply, mutations, run, scratch};
use models::dataset::{generate, ground_motion, load_dir, DatasetConfig, ExcitationSource};
use models::dataset::{FileDigest, LoadedDataset};
use models::limits;
use models::preset::Preset;
use models::readers::{read_at2, read_csv, Units};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_corpus")
        .join(target)
}

/// The error message names `file`.
/// The longest message a refusal may have: a value of the input is quoted by its start and
/// length, never echoed whole (a cell of 100,000 brackets was).
const LONGEST_MESSAGE: usize = 1_000;

fn names(msg: &str, file: &Path) -> Result<(), TestCaseError> {
    prop_assert!(
        msg.contains(&file.display().to_string()),
        "the message does not name {}: {msg}",
        file.display()
    );
    prop_assert!(
        msg.len() <= LONGEST_MESSAGE,
        "a message of {} characters: {}…",
        msg.len(),
        msg.chars().take(300).collect::<String>()
    );
    Ok(())
}

fn bounded(values: &[f64], what: &str) -> Result<(), TestCaseError> {
    if let Some(v) = values.iter().find(|v| limits::check_value(**v).is_err()) {
        prop_assert!(false, "{what}: value {v} beyond the limits was accepted");
    }
    Ok(())
}

/// A record read from a user file, then resampled as `simulate --excitation FILE` does.
fn check_record(
    path: &Path,
    source: ExcitationSource,
    read: impl Fn() -> Result<(), String>,
) -> Result<(), TestCaseError> {
    if let Err(msg) = read() {
        return names(&msg, path);
    }
    let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
    c.excitation = source;
    c.duration = None;
    match ground_motion(&c) {
        Ok(gm) => {
            prop_assert!(gm.len() >= 2 && gm.len() <= limits::MAX_SAMPLES);
            prop_assert!(limits::check_dt(gm.dt).is_ok());
            prop_assert!(gm.acc.iter().all(|a| a.is_finite()));
        }
        Err(e) => {
            let msg = e.to_string();
            // A record that reads but cannot be resampled is a setting error (named field),
            // anything about the file names it.
            if !msg.starts_with("invalid dataset config") {
                names(&msg, path)?;
            }
        }
    }
    Ok(())
}

fn check_csv(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("record.csv");
    std::fs::write(&path, bytes).unwrap();
    check_record(
        &path,
        ExcitationSource::Csv {
            path: path.clone(),
            units: Units::G,
        },
        || {
            let gm = read_csv(&path, Units::G).map_err(|e| e.to_string())?;
            if gm.acc.len() < 2 || limits::check_dt(gm.dt).is_err() {
                return Err(format!("accepted {} samples at dt {}", gm.acc.len(), gm.dt));
            }
            Ok(())
        },
    )
}

fn check_at2(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("record.AT2");
    std::fs::write(&path, bytes).unwrap();
    check_record(&path, ExcitationSource::At2 { path: path.clone() }, || {
        let gm = read_at2(&path).map_err(|e| e.to_string())?;
        if gm.acc.len() < 2 || limits::check_dt(gm.dt).is_err() {
            return Err(format!("accepted {} samples at dt {}", gm.acc.len(), gm.dt));
        }
        Ok(())
    })
}

/// The guarantees of a loaded data set that the filters and reports rely on.
fn check_loaded(d: &LoadedDataset) -> Result<(), TestCaseError> {
    let k = d.len();
    prop_assert!((2..=limits::MAX_SAMPLES).contains(&k));
    prop_assert!((1..=limits::MAX_STOREYS).contains(&d.channels));
    prop_assert_eq!(d.y_meas.len(), k * d.channels);
    prop_assert_eq!(d.ug_meas.len(), k);
    prop_assert!(limits::check_dt(d.dt).is_ok(), "dt {}", d.dt);
    bounded(&d.y_meas, "y_meas")?;
    bounded(&d.ug_meas, "ug_meas")?;
    if let Some(tr) = &d.truth {
        prop_assert!(tr.states.dim() >= 2 * d.channels);
        prop_assert_eq!(tr.states.as_flat().len(), k * tr.states.dim());
        prop_assert_eq!(tr.ug_clean.len(), k);
        bounded(tr.states.as_flat(), "truth")?;
    }
    if let Some(m) = &d.meta {
        let n = d.channels;
        prop_assert_eq!(m.rms.acc.len(), n);
        prop_assert_eq!(m.rms.vel.len(), n);
        prop_assert_eq!(m.rms.disp.len(), n);
        prop_assert_eq!(m.noise.acc_sd.len(), n);
        prop_assert!(m
            .rms
            .acc
            .iter()
            .chain(&m.rms.vel)
            .all(|v| v.is_finite() && *v >= 0.0));
        prop_assert!(m.rms.ug.is_finite() && m.rms.ug >= 0.0);
        // What `sysid filter` does with the metadata: rebuild the true structure.
        let chain = Preset::from_name(&m.config.preset, m.config.storeys);
        prop_assert!(chain.is_ok(), "preset: {:?}", chain.err());
        let chain = chain.unwrap().chain;
        prop_assert_eq!(chain.storeys(), n);
        prop_assert!(chain.with_theta(&m.theta_true).is_ok());
    }
    Ok(())
}

/// Loads `dir`; an error must name one of `files`.
fn check_dir(dir: &Path, files: &[&str]) -> Result<(), TestCaseError> {
    match load_dir(dir) {
        Ok(d) => check_loaded(&d),
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(
                files
                    .iter()
                    .any(|f| msg.contains(&dir.join(f).display().to_string())),
                "the message names none of {files:?}: {msg}"
            );
            prop_assert!(
                msg.len() <= LONGEST_MESSAGE,
                "a message of {} characters: {}…",
                msg.len(),
                msg.chars().take(300).collect::<String>()
            );
            Ok(())
        }
    }
}

/// A short valid data set: (measured.csv, truth.csv, dataset.json without digests).
fn template() -> (Vec<u8>, Vec<u8>, serde_json::Value) {
    let mut c = DatasetConfig::from_preset("paper-3dof", 7).unwrap();
    c.duration = Some(0.1);
    let (_tmp, dir) = scratch("template");
    generate(&c).unwrap().write_dir(&dir.join("ds")).unwrap();
    let read = |f: &str| std::fs::read(dir.join("ds").join(f)).unwrap();
    let mut meta: serde_json::Value = serde_json::from_slice(&read("dataset.json")).unwrap();
    meta.as_object_mut().unwrap().remove("files");
    (read("measured.csv"), read("truth.csv"), meta)
}

/// Writes a data set whose dataset.json records the digests of the (possibly mutated) CSVs,
/// so that the parsers, not the digest check, meet the mutation.
fn write_consistent(dir: &Path, measured: &[u8], truth: &[u8], meta: &serde_json::Value) {
    let mut meta = meta.clone();
    meta["files"] = serde_json::json!({
        "measured.csv": FileDigest::of(measured),
        "truth.csv": FileDigest::of(truth),
    });
    std::fs::write(dir.join("measured.csv"), measured).unwrap();
    std::fs::write(dir.join("truth.csv"), truth).unwrap();
    std::fs::write(
        dir.join("dataset.json"),
        serde_json::to_vec_pretty(&meta).unwrap(),
    )
    .unwrap();
}

const ALL: [&str; 3] = ["measured.csv", "truth.csv", "dataset.json"];

fn check_field_measured(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    std::fs::write(dir.join("measured.csv"), bytes).unwrap();
    check_dir(dir, &["measured.csv"])
}

fn check_dataset_csv(
    dir: &Path,
    which: &str,
    bytes: &[u8],
    t: &(Vec<u8>, Vec<u8>, serde_json::Value),
) -> Result<(), TestCaseError> {
    let (m, tr) = if which == "measured.csv" {
        (bytes, &t.1[..])
    } else {
        (&t.0[..], bytes)
    };
    write_consistent(dir, m, tr, &t.2);
    check_dir(dir, &ALL)
}

fn check_meta(
    dir: &Path,
    bytes: &[u8],
    t: &(Vec<u8>, Vec<u8>, serde_json::Value),
) -> Result<(), TestCaseError> {
    std::fs::write(dir.join("measured.csv"), &t.0).unwrap();
    std::fs::write(dir.join("truth.csv"), &t.1).unwrap();
    std::fs::write(dir.join("dataset.json"), bytes).unwrap();
    check_dir(dir, &ALL)
}

/// A longer CSV seed than the fixture (30 samples), so line mutations land in the data.
fn csv_seeds() -> Vec<Vec<u8>> {
    let mut long = String::from("t,acc\n");
    for k in 0..30 {
        long.push_str(&format!(
            "{},{}\n",
            k as f64 * 0.01,
            (k as f64 * 0.3).sin() * 0.1
        ));
    }
    vec![
        std::fs::read(fixture("record.csv")).unwrap(),
        long.into_bytes(),
    ]
}

fn at2_seeds() -> Vec<Vec<u8>> {
    vec![
        std::fs::read(fixture("nga_west2.AT2")).unwrap(),
        std::fs::read(fixture("nga_old.AT2")).unwrap(),
    ]
}

fn seeded(n: usize) -> impl Strategy<Value = (usize, Vec<fuzz_common::Mutation>)> {
    (0..n, mutations())
}

#[test]
fn fuzz_excitation_csv() {
    let (_tmp, dir) = scratch("csv");
    let seeds = csv_seeds();
    run(
        "csv",
        1,
        2_000,
        seeded(seeds.len()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_csv(&dir, &apply(&seeds[i], &m)),
    );
}

#[test]
fn fuzz_at2() {
    let (_tmp, dir) = scratch("at2");
    let seeds = at2_seeds();
    run(
        "at2",
        2,
        2_000,
        seeded(seeds.len()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_at2(&dir, &apply(&seeds[i], &m)),
    );
}

#[test]
fn fuzz_field_measured_csv() {
    let (_tmp, dir) = scratch("field");
    let t = template();
    run(
        "measured",
        3,
        1_500,
        mutations(),
        |m| apply(&t.0, m),
        |m| check_field_measured(&dir, &apply(&t.0, &m)),
    );
}

#[test]
fn fuzz_dataset_csv_files() {
    let (_tmp, dir) = scratch("dataset");
    let t = template();
    let which = |i: usize| ALL[i % 2];
    let seed = |i: usize| if which(i) == ALL[0] { &t.0 } else { &t.1 };
    run(
        "dataset",
        4,
        1_500,
        seeded(2),
        |(i, m)| apply(seed(*i), m),
        |(i, m)| check_dataset_csv(&dir, which(i), &apply(seed(i), &m), &t),
    );
}

#[test]
fn fuzz_dataset_json() {
    let (_tmp, dir) = scratch("meta");
    let t = template();
    let seed = serde_json::to_vec_pretty(&t.2).unwrap();
    run(
        "meta",
        5,
        2_000,
        mutations(),
        |m| apply(&seed, m),
        |m| check_meta(&dir, &apply(&seed, &m), &t),
    );
}

/// Every input of the corpus (inputs that once crashed a reader) is handled.
#[test]
fn corpus_inputs_are_handled() {
    let (_tmp, dir) = scratch("corpus");
    let t = template();
    let mut count = 0;
    for target in [
        "csv",
        "at2",
        "measured",
        "dataset-measured",
        "dataset-truth",
        "meta",
    ] {
        for file in fuzz_common::corpus(&corpus_dir(target)) {
            let bytes = std::fs::read(&file).unwrap();
            let sub = dir.join(target);
            std::fs::create_dir_all(&sub).unwrap();
            let r = match target {
                "csv" => check_csv(&sub, &bytes),
                "at2" => check_at2(&sub, &bytes),
                "measured" => check_field_measured(&sub, &bytes),
                "dataset-measured" => check_dataset_csv(&sub, "measured.csv", &bytes, &t),
                "dataset-truth" => check_dataset_csv(&sub, "truth.csv", &bytes, &t),
                _ => check_meta(&sub, &bytes, &t),
            };
            if let Err(e) = r {
                panic!("{}: {e}", file.display());
            }
            count += 1;
        }
    }
    assert!(count >= 10, "the corpus holds {count} inputs");
}
