//! `sysid loglik` ([`experiments::likelihood`]): the record's support of fixed answers, with
//! the truth known — a perturbed answer lies outside the 95 % likelihood region, the truth's
//! own values not, the same request gives the same numbers, and bad requests are refused by
//! name.

use crate::common;

use std::path::{Path, PathBuf};

use experiments::likelihood::{score, Candidate, LikelihoodRequest, Verdict};
use models::dataset::{generate, DatasetConfig};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-loglik-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

/// 3 s of the paper's data set (seed 5) in `dir/data`.
fn data_dir(dir: &Path) -> PathBuf {
    let mut config = DatasetConfig::from_preset("paper-3dof", 5).unwrap();
    config.duration = Some(3.0);
    let d = dir.join("data");
    generate(&config).unwrap().write_dir(&d).unwrap();
    d
}

/// A run record whose θ_val is `ratios` × θ_true, written to `dir/name.json`.
fn answer(dir: &Path, name: &str, ratios: [f64; 9]) -> PathBuf {
    let p = dir.join(format!("{name}.json"));
    let r = common::record("mpf-ekf2", 0, ratios, 0.05);
    std::fs::write(&p, serde_json::to_string(&r).unwrap()).unwrap();
    p
}

fn request(data: PathBuf) -> LikelihoodRequest {
    LikelihoodRequest {
        data,
        config: None,
        particles: 60,
        seeds: 2,
        truth: true,
    }
}

#[test]
fn a_wrong_answer_lies_outside_the_region_and_the_truth_does_not() {
    let (_tmp, dir) = temp_dir("verdicts");
    let data = data_dir(&dir);
    let mut low_k1 = [1.0; 9];
    low_k1[0] = 0.6;
    let records = [
        answer(&dir, "exact", [1.0; 9]),
        answer(&dir, "low-k1", low_k1),
    ];
    let candidates: Vec<Candidate> = records
        .iter()
        .map(|p| Candidate::from_record(p).unwrap())
        .collect();
    let mut lines = 0;
    let c = score(&request(data.clone()), &candidates, &mut |_| lines += 1).unwrap();
    assert_eq!(lines, 6, "one line per estimate");
    assert_eq!(c.params, 9);
    let labels: Vec<&str> = c.scored.iter().map(|s| s.label.as_str()).collect();
    assert!(
        labels[2] == "truth" && labels[0].ends_with("exact.json"),
        "{labels:?}"
    );
    // The record holding θ_true and the truth itself are the same θ with the same seeds: the
    // same estimates, bit for bit.
    assert_eq!(c.scored[0].estimates, c.scored[2].estimates);
    let v = c.verdicts();
    assert_eq!(v[1], Verdict::Outside, "{:?}", c.scored);
    assert!(
        matches!(v[0], Verdict::Best | Verdict::NotShownOutside),
        "{v:?}"
    );
    assert!(
        c.scored[0].mean() - c.scored[1].mean() > 3.0 * c.region_nats,
        "k1 40 % low costs far more than the region: {:?}",
        c.scored
    );
    // The same request again: the same numbers.
    let again = score(&request(data), &candidates, &mut |_| {}).unwrap();
    assert_eq!(again, c);
}

/// The message of the error `score` refuses `req` with.
fn refusal(req: &LikelihoodRequest, candidates: &[Candidate]) -> String {
    score(req, candidates, &mut |_| {}).unwrap_err().to_string()
}

#[test]
fn bad_requests_are_refused_by_name() {
    let (_tmp, dir) = temp_dir("refused");
    let data = data_dir(&dir);
    let one = [Candidate::from_record(&answer(&dir, "a", [1.0; 9])).unwrap()];
    let mut no_seeds = request(data.clone());
    no_seeds.seeds = 0;
    let mut no_particles = request(data.clone());
    no_particles.particles = 0;
    for (req, flag) in [(no_seeds, "--seeds"), (no_particles, "--particles")] {
        let e = refusal(&req, &one);
        assert!(e.contains(flag), "{e}");
    }
    // An answer of another building is refused.
    let mut other = one[0].clone();
    other.label = "other".into();
    other.names.pop();
    other.theta.pop();
    let e = refusal(&request(data.clone()), &[one[0].clone(), other]);
    assert!(e.contains("must be of that building"), "{e}");
    // --truth alone scores the truth (one answer: the best).
    let truth = score(&request(data.clone()), &[], &mut |_| {}).unwrap();
    assert_eq!(truth.scored.len(), 1);
    assert_eq!(truth.scored[0].label, "truth");
    assert!(truth.scored[0].mean().is_finite());
    // A failed run has no answer to score.
    let mut r = common::record("mpf-ekf2", 0, [1.0; 9], 0.05);
    r.theta_val = vec![f64::NAN; 9];
    let p = dir.join("failed.json");
    std::fs::write(&p, serde_json::to_string(&r).unwrap()).unwrap();
    let e = Candidate::from_record(&p).unwrap_err();
    assert!(e.to_string().contains("failed.json"), "{e}");
    // Field data without a config: the building is unknown.
    let field = dir.join("field");
    std::fs::create_dir_all(&field).unwrap();
    std::fs::copy(data.join("measured.csv"), field.join("measured.csv")).unwrap();
    let e = refusal(
        &LikelihoodRequest {
            truth: false,
            ..request(field)
        },
        &one,
    );
    assert!(e.contains("--config"), "{e}");
}
