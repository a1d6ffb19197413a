//! `sysid information` ([`experiments::information`]): on a linear building the limit's θ̂ is the
//! likelihood's maximum and its s.d.s are the likelihood's curvature there (checked against the
//! exact likelihood itself), the same request gives the same numbers, and a hysteretic record or
//! another data set's run record is refused by name.

use crate::common;

use std::path::{Path, PathBuf};

use experiments::information::{information_limit, summary, table, InformationLimit, REL_STEP};
use experiments::likelihood::{Candidate, LikelihoodModel, ScoredData};
use identify::field::StructureSettings;
use identify::pipeline::{identify, Algorithm, RunInput};
use identify::settings::FilterSettings;
use models::dataset::{generate, load_dir, DatasetConfig, LoadedDataset, MEASURED};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-information-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// 4 s of a 3-storey building-chain data set (seed 7), linear or with its preset's Bouc–Wen
/// storey, in `dir/name`.
fn data_dir(dir: &Path, name: &str, linear: bool) -> PathBuf {
    let mut config = DatasetConfig::from_preset("building-chain", 7).unwrap();
    config.storeys = Some(3);
    config.duration = Some(4.0);
    if linear {
        config.hysteretic = Some(vec![]);
    }
    let d = dir.join(name);
    generate(&config).unwrap().write_dir(&d).unwrap();
    d
}

fn on<'a>(data: &'a LoadedDataset, measured: &'a Path, name: &'a str) -> ScoredData<'a> {
    static FLAGS: std::sync::OnceLock<StructureSettings> = std::sync::OnceLock::new();
    ScoredData {
        data,
        chain: None,
        measured,
        name,
        flags: FLAGS.get_or_init(StructureSettings::default),
        settings: None,
        config: None,
    }
}

#[test]
fn the_limit_is_the_likelihoods_maximum_and_its_curvature() {
    let (_tmp, dir) = temp_dir("maximum");
    let d = data_dir(&dir, "linear", true);
    let data = load_dir(&d).unwrap();
    let chain = data.true_chain().unwrap();
    let measured = d.join(MEASURED);
    let mut scored = on(&data, &measured, "linear");
    scored.chain = chain.as_ref();
    let mut lines = 0;
    let limit = information_limit(&scored, None, REL_STEP, &mut |_| lines += 1).unwrap();
    assert!(lines >= 3, "a line per stencil: {lines}");
    assert_eq!(limit.names.len(), 6);
    assert!(limit.loglik_mle >= limit.loglik_start);
    // Half an s.d. either side of θ̂ along each axis, the exact log-likelihood falls by
    // ½·(½)²/ρ where ρ = 1 − R² of that axis on the others; the s.d.s are the marginal ones
    // (√diag of the inverse), so the fall along one axis is at least 0.125 nats. θ̂ is the
    // maximum: no point of the test is above it.
    let model = LikelihoodModel::settle(&scored).unwrap();
    let at = |theta: Vec<f64>| {
        let c = Candidate {
            label: "probe".into(),
            names: limit.names.clone(),
            theta,
        };
        model.loglik(&c, 1, 1, &|| false).unwrap()
    };
    let top = at(limit.mle.clone());
    assert!(
        (top - limit.loglik_mle).abs() < 1e-9,
        "{top} {}",
        limit.loglik_mle
    );
    for j in 0..6 {
        for s in [0.5, -0.5] {
            let mut th = limit.mle.clone();
            th[j] += s * limit.sd[j];
            let fall = top - at(th);
            assert!(
                fall > 0.125 * 0.9 && fall < 0.125 * 60.0,
                "{}: a fall of {fall} nats half an s.d. from θ̂",
                limit.names[j]
            );
        }
    }
    // The same request, the same numbers.
    let again = information_limit(&scored, None, REL_STEP, &mut |_| {}).unwrap();
    assert_eq!(again.mle, limit.mle);
    assert_eq!(again.sd, limit.sd);
    // An online run on the same data is matched to the limit by the data set's identity and put
    // beside it: its errors in the per-parameter table, and the summary's goal rows.
    let input = RunInput {
        data: &data,
        chain: chain.as_ref(),
        experiment: "information",
        seed: 3,
        run: 0,
        progress: None,
        residuals: false,
    };
    let s = FilterSettings {
        particles: 100,
        pool: 1,
        trace_every: 0,
        loop_every: 0,
        validate: false,
        ..FilterSettings::recommended()
    };
    let run = identify(&input, Algorithm::MpfEkf2, &s).unwrap();
    let t = table(&limit, std::slice::from_ref(&run)).unwrap();
    assert!(t.contains("mpf-ekf2 run 0 error"), "{t}");
    // Started at the truth, the table says whether the model puts it inside the region, and
    // the verdict is the one the numbers give (2 × gain against χ²_6(0.95) = 12.59); a limit
    // started elsewhere states none.
    let outside = 2.0 * (limit.loglik_mle - limit.loglik_start) > 12.59;
    let verdict = if outside {
        "The truth lies OUTSIDE"
    } else {
        "The truth lies inside"
    };
    assert!(t.contains(verdict) && t.contains("χ²_6(0.95)"), "{t}");
    let elsewhere = InformationLimit {
        start: "online".into(),
        ..limit.clone()
    };
    let t2 = table(&elsewhere, std::slice::from_ref(&run)).unwrap();
    assert!(!t2.contains("The truth lies"), "{t2}");
    let text = summary(std::slice::from_ref(&limit), std::slice::from_ref(&run)).unwrap();
    assert!(text.contains("| mpf-ekf2 | all k | 3 |"), "{text}");
    assert!(text.contains("| k3 | mpf-ekf2 | 1 |"), "{text}");
    // A run record of another data set is refused by name, in the table and the summary.
    let other = common::record("mpf-ekf2", 0, [1.0; 9], 0.05);
    let e = table(&limit, std::slice::from_ref(&other))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("not those of") || e.contains("not identified on"),
        "{e}"
    );
    let e = summary(std::slice::from_ref(&limit), &[run, other])
        .unwrap_err()
        .to_string();
    assert!(e.contains("belongs to none"), "{e}");
}

#[test]
fn a_hysteretic_record_and_bad_steps_are_refused() {
    let (_tmp, dir) = temp_dir("refused");
    let d = data_dir(&dir, "hysteretic", false);
    let data = load_dir(&d).unwrap();
    let measured = d.join(MEASURED);
    let scored = on(&data, &measured, "hysteretic");
    let e = format!(
        "{:#}",
        information_limit(&scored, None, REL_STEP, &mut |_| {}).unwrap_err()
    );
    assert!(
        e.contains("hysteretic storeys") && e.contains("sysid reference"),
        "{e}"
    );
    let e = format!(
        "{:#}",
        information_limit(&scored, None, 0.5, &mut |_| {}).unwrap_err()
    );
    assert!(e.contains("--step"), "{e}");
}
