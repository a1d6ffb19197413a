//! Property-based fuzzing of the import's readers, in the style of `fuzz_readers.rs`: the
//! sensor CSV reader, the CSMIP V2 reader, the channel map and the whole import (a mutated
//! sensor file through alignment and repairs). Valid inputs — excerpts of the real files in
//! `tests/fixtures/import/` and a map — are mutated (`fuzz_common`), and for every input the
//! code must neither panic nor abort, and either return data holding the guarantees the rest of
//! the tool relies on (bounded sizes and values, strictly increasing clocks, one value per
//! sample) or an error naming the file.
//!
//! Fixed seeds, 5,000 cases in all. Inputs that once crashed a reader are kept in
//! `tests/fuzz_corpus/<target>/` and replayed by `import_corpus_inputs_are_handled`.

use crate::fuzz_common;

use fuzz_common::{apply, mutations, run, scratch};
use models::import::channel_map::ChannelMap;
use models::import::csmip::read_v2;
use models::import::import;
use models::import::sensor_csv::{read_sensor_csv, CsvColumns, TimeUnits};
use models::limits;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/import")
        .join(name)
}

fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_corpus")
        .join(target)
}

fn names(msg: &str, files: &[&Path]) -> Result<(), TestCaseError> {
    prop_assert!(
        files.iter().any(|f| msg.contains(&f.display().to_string())),
        "the message names none of {files:?}: {msg}"
    );
    Ok(())
}

fn bounded(values: &[f64]) -> Result<(), TestCaseError> {
    prop_assert!(
        values.iter().all(|v| limits::check_value(*v).is_ok()),
        "a value beyond the limits was accepted"
    );
    Ok(())
}

fn xsens_columns() -> CsvColumns {
    CsvColumns {
        time: "SampleTimeFine".into(),
        time_units: TimeUnits::Microseconds,
        column: "Acc_X".into(),
        header_lines: None,
        drop_non_finite: false,
    }
}

fn check_sensor_csv(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("sensor.csv");
    std::fs::write(&path, bytes).unwrap();
    match read_sensor_csv(&path, &xsens_columns()) {
        Ok(c) => {
            prop_assert!(c.values.len() >= 2 && c.values.len() <= limits::MAX_SAMPLES);
            prop_assert_eq!(c.times.len(), c.values.len());
            prop_assert_eq!(c.lines.len(), c.values.len());
            prop_assert!(c.times.windows(2).all(|w| w[1] > w[0]));
            prop_assert!(c.times.iter().all(|t| limits::check_time(*t).is_ok()));
            bounded(&c.values)
        }
        Err(e) => names(&e.to_string(), &[&path]),
    }
}

fn check_v2(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("CHAN.V2");
    std::fs::write(&path, bytes).unwrap();
    match read_v2(&path) {
        Ok(r) => {
            prop_assert!(r.acc.len() >= 2 && r.acc.len() <= limits::MAX_SAMPLES);
            prop_assert!(limits::check_dt(r.dt).is_ok());
            bounded(&r.acc)
        }
        Err(e) => names(&e.to_string(), &[&path]),
    }
}

/// A map of the two real Xsens excerpts of `sine-1.0` (their clocks one sample apart), copied
/// into `dir` so that the fuzzed data file sits beside it.
fn map_text() -> String {
    "[options]\nmax_gap = 0.05\n\n[ground]\nfile = \"ground.csv\"\nformat = \"sensor-csv\"\n\
     time = \"SampleTimeFine\"\ntime_units = \"us\"\ncolumn = \"Acc_X\"\nunits = \"m/s2\"\n\n\
     [[storey]]\nstorey = 2\nfile = \"floor.csv\"\nformat = \"sensor-csv\"\n\
     time = \"SampleTimeFine\"\ntime_units = \"us\"\ncolumn = \"Acc_X\"\nunits = \"m/s2\"\n"
        .to_string()
}

fn setup(dir: &Path) {
    std::fs::copy(fixture("xsens-sine-1.0-ground.csv"), dir.join("ground.csv")).unwrap();
    std::fs::copy(fixture("xsens-sine-1.0-floor-2.csv"), dir.join("floor.csv")).unwrap();
}

/// Import through `map`; an import must hold its guarantees, an error name a file: the map or
/// a file of `dir` (a mutated map names other files).
fn check_import(dir: &Path, map: &Path) -> Result<(), TestCaseError> {
    let files = [map, dir];
    let m = match ChannelMap::load(map) {
        Ok(m) => m,
        Err(e) => return names(&e.to_string(), &files),
    };
    match import(&m) {
        Ok(d) => {
            let k = d.ug.len();
            prop_assert!((2..=limits::MAX_SAMPLES).contains(&k));
            prop_assert!(limits::check_dt(d.dt).is_ok(), "dt {}", d.dt);
            prop_assert_eq!(d.y.len(), k * d.sensors().len());
            bounded(&d.ug)?;
            bounded(&d.y)
        }
        Err(e) => {
            let msg = e.to_string();
            // Every channel named is one of the map's files.
            if msg.starts_with("no span of time") {
                return Ok(());
            }
            names(&msg, &files)
        }
    }
}

fn check_map(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("channels.toml");
    std::fs::write(&path, bytes).unwrap();
    check_import(dir, &path)
}

fn check_data(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    std::fs::write(dir.join("floor.csv"), bytes).unwrap();
    check_import(dir, &dir.join("channels.toml"))
}

fn seeded(n: usize) -> impl Strategy<Value = (usize, Vec<fuzz_common::Mutation>)> {
    (0..n, mutations())
}

fn sensor_seeds() -> Vec<Vec<u8>> {
    ["xsens-northridge-ground.csv", "xsens-sine-1.0-floor-2.csv"]
        .iter()
        .map(|f| std::fs::read(fixture(f)).unwrap())
        .collect()
}

fn v2_seeds() -> Vec<Vec<u8>> {
    [
        "CHAN003-excerpt.V2",
        "CHAN007-excerpt.V2",
        "CHAN07-1979-excerpt.V2",
    ]
    .iter()
    .map(|f| std::fs::read(fixture(f)).unwrap())
    .collect()
}

#[test]
fn fuzz_sensor_csv() {
    let (_tmp, dir) = scratch("sensor-csv");
    let seeds = sensor_seeds();
    run(
        "sensor-csv",
        11,
        1_500,
        seeded(seeds.len()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_sensor_csv(&dir, &apply(&seeds[i], &m)),
    );
}

#[test]
fn fuzz_csmip_v2() {
    let (_tmp, dir) = scratch("v2");
    let seeds = v2_seeds();
    run(
        "v2",
        12,
        1_500,
        seeded(seeds.len()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_v2(&dir, &apply(&seeds[i], &m)),
    );
}

#[test]
fn fuzz_channel_map() {
    let (_tmp, dir) = scratch("channel-map");
    setup(&dir);
    let seed = map_text().into_bytes();
    run(
        "channel-map",
        13,
        1_000,
        mutations(),
        |m| apply(&seed, m),
        |m| check_map(&dir, &apply(&seed, &m)),
    );
}

#[test]
fn fuzz_import_of_a_mutated_recording() {
    let (_tmp, dir) = scratch("import");
    setup(&dir);
    std::fs::write(dir.join("channels.toml"), map_text()).unwrap();
    let seed = std::fs::read(fixture("xsens-sine-1.0-floor-2.csv")).unwrap();
    run(
        "import",
        14,
        1_000,
        mutations(),
        |m| apply(&seed, m),
        |m| check_data(&dir, &apply(&seed, &m)),
    );
}

/// Every input of the corpus (inputs that once crashed the import) is handled.
#[test]
fn import_corpus_inputs_are_handled() {
    let (_tmp, dir) = scratch("import-corpus");
    setup(&dir);
    std::fs::write(dir.join("channels.toml"), map_text()).unwrap();
    let mut count = 0;
    for (target, check) in [
        ("sensor-csv", check_sensor_csv as fn(&Path, &[u8]) -> _),
        ("v2", check_v2),
        ("import", check_data),
    ] {
        for file in fuzz_common::corpus(&corpus_dir(target)) {
            let bytes = std::fs::read(&file).unwrap();
            if let Err(e) = check(&dir, &bytes) {
                panic!("{}: {e}", file.display());
            }
            count += 1;
        }
    }
    assert!(count >= 4, "the corpus holds {count} inputs");
}
