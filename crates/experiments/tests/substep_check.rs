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

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
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
    let check = &plan["evidence"]["substep_convergence"];
    let runs = check["runs"]
        .as_array()
        .expect("the check's runs are recorded");
    let tolerance = check["tolerance"].as_f64().unwrap();
    assert_eq!(tolerance, identify::choice::substeps::TOLERANCE);
    // It starts from the rules' count and doubles (at most the largest count).
    let rules = plan["evidence"]["substeps"]["field"]["substeps"]
        .as_u64()
        .unwrap();
    assert_eq!(runs[0]["substeps"].as_u64(), Some(rules));
    for w in runs.windows(2) {
        let (a, b) = (
            w[0]["substeps"].as_u64().unwrap(),
            w[1]["substeps"].as_u64().unwrap(),
        );
        assert_eq!(b, (2 * a).min(models::filtering::MAX_SUBSTEPS as u64));
    }
    // Every step up but the last moved a stiffness by more than the tolerance; the last by at
    // most it, and so it converged.
    let moved: Vec<f64> = runs[1..]
        .iter()
        .map(|x| x["moved"]["sd"].as_f64().unwrap())
        .collect();
    assert!(runs.len() >= 2, "{check}");
    let (last, before) = moved.split_last().unwrap();
    assert!(*last <= tolerance, "{moved:?}");
    assert!(before.iter().all(|m| *m > tolerance), "{moved:?}");
    assert_eq!(check["converged"].as_bool(), Some(true));
    for x in &runs[1..] {
        assert!(x["moved"]["parameter"].as_str().unwrap().starts_with('k'));
    }
    // The run is the check's last: its count and its θ_val, bit for bit.
    let final_run = runs.last().unwrap();
    assert_eq!(plan["model"]["substeps"], final_run["substeps"]);
    assert_eq!(r["theta_val"], final_run["theta_val"]);
    // The decision `sysid filter` prints (on standard error) is in the plan.
    let decision = plan["decisions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["rule"] == "choice::substeps::converge")
        .expect("the check's decision");
    assert!(decision["why"]
        .as_str()
        .unwrap()
        .starts_with("sub-steps checked on the whole record"));
    // The checked run's stiffness intervals hold the truth; the rules' count's (θ_val ± 1.96
    // s.d. of its run) miss it on at least one stiffness: the step's bias the check removes.
    for (k, name) in truth.iter().zip(["k1", "k2", "k3"]) {
        let p = r["credible"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["parameter"] == name)
            .unwrap();
        let i95 = p["intervals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| (i["level"].as_f64().unwrap() - 0.95).abs() < 1e-9)
            .unwrap();
        let (lo, hi) = (i95["lo"].as_f64().unwrap(), i95["hi"].as_f64().unwrap());
        assert!(lo <= *k && *k <= hi, "{name}: {k} outside [{lo}, {hi}]");
    }
    let (th0, sd0) = (floats(&runs[0]["theta_val"]), floats(&runs[0]["sd"]));
    assert!(
        truth
            .iter()
            .enumerate()
            .any(|(j, k)| (th0[j] - k).abs() > 1.96 * sd0[j]),
        "the rules' count already held the truth: {th0:?} ± 1.96 × {sd0:?}"
    );

    // A count the user states is kept, unchecked.
    let r = identify(&data, &root.join("stated.json"), &["--substeps", "3"]);
    assert!(r["plan"]["evidence"]["substep_convergence"].is_null());
    assert_eq!(r["plan"]["model"]["substeps"].as_u64(), Some(3));
}
