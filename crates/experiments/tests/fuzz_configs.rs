//! Property-based fuzzing of the TOML readers: study files (`experiments::study::Study`) and
//! filter config files (`identify::pipeline::FilterSettings`, read by
//! `identify::limits::load_filter_settings`). Valid files are mutated (the mutations of
//! `models/tests/fuzz_common`); each reader must neither panic nor abort, and either return
//! settings that pass the limits or an error whose message names the file.
//!
//! Fixed seeds, 1,500 cases per target. Inputs that once were accepted wrongly or crashed are
//! kept in `tests/fuzz_corpus/<target>/` and replayed.

#[path = "../../models/tests/fuzz_common/mod.rs"]
mod fuzz_common;

use experiments::study::Study;
use fuzz_common::{apply, mutations, run, scratch};
use identify::limits::{check_filter_settings, load_filter_settings};
use identify::pipeline::FilterSettings;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn names(msg: &str, file: &Path) -> Result<(), TestCaseError> {
    prop_assert!(
        msg.contains(&file.display().to_string()),
        "the message does not name {}: {msg}",
        file.display()
    );
    Ok(())
}

fn check_study(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("study.toml");
    std::fs::write(&path, bytes).unwrap();
    match Study::load(&path) {
        Ok(s) => {
            prop_assert!(!s.sweep.algorithms.is_empty() && s.sweep.runs > 0);
            Ok(())
        }
        Err(e) => names(&format!("{e:#}"), &path),
    }
}

fn check_filter(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("filter.toml");
    std::fs::write(&path, bytes).unwrap();
    match load_filter_settings(&path) {
        Ok(s) => {
            prop_assert!(check_filter_settings(&s).is_ok());
            Ok(())
        }
        Err(e) => names(&format!("{e:#}"), &path),
    }
}

/// An information limit (`sysid information --limit`): read, then used as a summary and a
/// table, or refused naming the file.
fn check_limit(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    use experiments::information::{table, InformationLimit};
    let path = dir.join("lim.json");
    std::fs::write(&path, bytes).unwrap();
    match InformationLimit::read(&path) {
        Ok(l) => {
            prop_assert_eq!(l.summaries().len(), l.names.len());
            prop_assert!(table(&l, &[]).is_ok());
            Ok(())
        }
        Err(e) => names(&format!("{e:#}"), &path),
    }
}

fn study_seeds() -> Vec<Vec<u8>> {
    ["fig4", "fig5", "fig6", "fig7", "fig8"]
        .iter()
        .map(|n| std::fs::read(repo().join(format!("experiments/{n}.toml"))).unwrap())
        .collect()
}

fn filter_seeds() -> Vec<Vec<u8>> {
    let defaults = toml::to_string(&FilterSettings::default()).unwrap();
    let custom = "particles = 300\nresampling = \"stratified\"\ness_threshold = 0.5\n\
                  noise_fraction = 0.1\nwindow = 80\n\
                  trace_every = 10\nvalidate = false\nloop_every = 0\n\n[fix]\nk1 = 8.0\nn = 2.0\n\n\
                  [structure]\nstoreys = 3\nhysteretic = [1]\nmasses = [1.0, 1.0, 1.0]\n\
                  measurement = \"absolute\"\n";
    vec![defaults.into_bytes(), custom.as_bytes().to_vec()]
}

#[test]
fn fuzz_study_files() {
    let (_tmp, dir) = scratch("study");
    let seeds = study_seeds();
    run(
        "study",
        11,
        1_500,
        (0..seeds.len(), mutations()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_study(&dir, &apply(&seeds[i], &m)),
    );
}

#[test]
fn fuzz_filter_configs() {
    let (_tmp, dir) = scratch("filter");
    let seeds = filter_seeds();
    // The seeds themselves are valid.
    for s in &seeds {
        std::fs::write(dir.join("filter.toml"), s).unwrap();
        load_filter_settings(&dir.join("filter.toml")).unwrap();
    }
    run(
        "filter",
        12,
        1_500,
        (0..seeds.len(), mutations()),
        |(i, m)| apply(&seeds[*i], m),
        |(i, m)| check_filter(&dir, &apply(&seeds[i], &m)),
    );
}

/// Every input of the corpus is handled.
#[test]
fn corpus_inputs_are_handled() {
    let (_tmp, dir) = scratch("config-corpus");
    let mut count = 0;
    for target in ["study", "filter", "information-limit"] {
        let corpus = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fuzz_corpus")
            .join(target);
        for file in fuzz_common::corpus(&corpus) {
            let bytes = std::fs::read(&file).unwrap();
            let r = match target {
                "study" => check_study(&dir, &bytes),
                "filter" => check_filter(&dir, &bytes),
                _ => check_limit(&dir, &bytes),
            };
            if let Err(e) = r {
                panic!("{}: {e}", file.display());
            }
            count += 1;
        }
    }
    assert!(count >= 3, "the corpus holds {count} inputs");
}
