//! The sub-step check end to end (`identify::choice::substeps`, docs/validation.md, "Sub-steps
//! checked by doubling"): on the foreign corpus's `in-class` record (the filter's own class,
//! exactly measured ground motion, 5 % white noise; the record `cargo xtask reproduce-foreign`
//! identifies), `sysid filter` with the minimal flags doubles the rules' sub-steps until the
//! stiffnesses stop moving, runs the count it ended with, and its stiffness intervals hold the
//! truth where the rules' count's do not; a stated count is kept unchecked.

use crate::common;

use std::path::Path;

use experiments::foreign;

/// Runs `sysid filter` with the minimal flags (and `extra`) on `data`; returns the record.
fn identify(data: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let seed = foreign::SEED.to_string();
    let mut args = vec!["filter"];
    args.extend(foreign::MINIMAL_FLAGS);
    args.extend(["--seed", &seed, "--data", data.to_str().unwrap()]);
    common::sysid_out(&args, extra, out);
    serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

#[test]
fn sub_steps_are_doubled_until_the_stiffnesses_stop_moving_and_then_hold_the_truth() {
    let (_tmp, root) = common::temp_dir("sysid-substep-check-");
    let (ug, dt) = common::foreign_ground(&root.join("ground"), &[]);
    // The corpus's control: a shear chain with Rayleigh damping (k 1200 / 1000 / 800), case 0.
    let case = foreign::cases().into_iter().next().unwrap();
    assert_eq!(case.name, "in-class");
    let clean = foreign::respond(&case.structure, &ug, dt);
    let mut rng = core_filters::rng::stream(foreign::SEED, 0, "foreign identify");
    let rec = foreign::measure(&case.sensing, &ug, clean, &mut rng);
    let data = root.join("data");
    foreign::write(&rec, dt, &data).unwrap();
    let truth = [1200.0, 1000.0, 800.0];

    let r = identify(&data, &root.join("checked.json"), &[]);
    let plan = &r["plan"];
    let checks = plan["evidence"]["substep_checks"]
        .as_array()
        .expect("the checks are recorded");
    // First on the part the held-out choice identifies on, from the rules' count; then on the
    // whole record from the count found (unless that is already the largest).
    let rules = plan["evidence"]["substeps"]["field"]["substeps"].as_u64();
    let first_part = plan["evidence"]["held_out"]["identified_samples"].as_u64();
    assert_eq!(checks[0]["whole"].as_bool(), Some(false));
    assert_eq!(checks[0]["samples"].as_u64(), first_part);
    assert_eq!(checks[0]["runs"][0]["substeps"].as_u64(), rules);
    let max = models::filtering::MAX_SUBSTEPS as u64;
    let last_count = |c: &serde_json::Value| {
        let runs = c["runs"].as_array().unwrap();
        runs.last().unwrap()["substeps"].as_u64().unwrap()
    };
    if last_count(&checks[0]) < max {
        assert_eq!(checks.len(), 2, "{checks:?}");
        assert_eq!(checks[1]["whole"].as_bool(), Some(true));
        assert_eq!(
            checks[1]["runs"][0]["substeps"].as_u64(),
            Some(last_count(&checks[0]))
        );
    }
    let tolerance = identify::choice::substeps::TOLERANCE;
    for check in checks {
        assert_eq!(check["tolerance"].as_f64(), Some(tolerance));
        let runs = check["runs"].as_array().unwrap();
        // Each count doubles the last (at most the largest).
        for w in runs.windows(2) {
            let (a, b) = (
                w[0]["substeps"].as_u64().unwrap(),
                w[1]["substeps"].as_u64().unwrap(),
            );
            assert_eq!(b, (2 * a).min(max));
        }
        // Every step up but the last moved a stiffness by more than the tolerance; the last by
        // at most it, and so it converged.
        let moved: Vec<f64> = runs[1..]
            .iter()
            .map(|x| x["moved"]["sd"].as_f64().unwrap())
            .collect();
        let (last, before) = moved.split_last().expect("at least one step up");
        assert!(*last <= tolerance, "{moved:?}");
        assert!(before.iter().all(|m| *m > tolerance), "{moved:?}");
        assert_eq!(check["converged"].as_bool(), Some(true));
        for x in &runs[1..] {
            assert!(x["moved"]["parameter"].as_str().unwrap().starts_with('k'));
        }
    }
    // The run takes the last check's count; after a check on the whole record, its θ_val is
    // that check's last run's, bit for bit.
    let last = checks.last().unwrap();
    let final_run = last["runs"].as_array().unwrap().last().unwrap();
    assert_eq!(plan["model"]["substeps"], final_run["substeps"]);
    if last["whole"].as_bool() == Some(true) {
        assert_eq!(r["theta_val"], final_run["theta_val"]);
    }
    // The decisions `sysid filter` prints (on standard error) are in the plan, one per check.
    let said: Vec<&str> = plan["decisions"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|d| d["rule"] == "choice::substeps::converge")
        .map(|d| d["why"].as_str().unwrap())
        .collect();
    assert_eq!(said.len(), checks.len());
    assert!(said[0].starts_with("sub-steps checked on the first"));
    if checks.len() == 2 {
        assert!(said[1].starts_with("sub-steps checked on the whole record"));
    }
    // The checked run's stiffness intervals hold the truth.
    for (k, name) in truth.iter().zip(["k1", "k2", "k3"]) {
        let (lo, hi) = common::interval95(&r, name);
        assert!(lo <= *k && *k <= hi, "{name}: {k} outside [{lo}, {hi}]");
    }

    // A count the user states is kept, unchecked; at the rules' count (3) a stiffness interval
    // misses the truth: the step's bias the check removes.
    let r = identify(&data, &root.join("stated.json"), &["--substeps", "3"]);
    assert!(r["plan"]["evidence"]["substep_checks"].is_null());
    assert_eq!(r["plan"]["model"]["substeps"].as_u64(), Some(3));
    assert_eq!(rules, Some(3));
    let missed: Vec<&str> = ["k1", "k2", "k3"]
        .into_iter()
        .zip(truth)
        .filter(|(name, k)| {
            let (lo, hi) = common::interval95(&r, name);
            !(lo <= *k && *k <= hi)
        })
        .map(|(name, _)| name)
        .collect();
    assert!(
        !missed.is_empty(),
        "the rules' count already held the truth"
    );
}
