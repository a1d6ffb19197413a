//! The foreign corpus at small size (`experiments::foreign`, docs/foreign.md): every case's
//! identification record, identified by `sysid filter` with only what a user knows (storeys,
//! masses, measurement kind, no hysteresis) — the data `cargo xtask reproduce-foreign` writes,
//! without its held-out record and SRIM. Every answer must be physical (exit 0, every k, c, α
//! > 0) and predict the floors better than saying they move with the ground.

use crate::common;

use std::process::Command;

use experiments::foreign;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

#[test]
fn foreign_structures_get_physical_answers_that_predict_better_than_the_ground() {
    let (_tmp, root) = common::temp_dir("sysid-foreign-");
    let (ug, dt) = common::foreign_ground(&root.join("ground"), &[]);
    for (ci, mut case) in foreign::cases().into_iter().enumerate() {
        foreign::calibrate_joint(&mut case, &ug, dt);
        let clean = foreign::respond(&case.structure, &ug, dt);
        let mut rng = core_filters::rng::stream(foreign::SEED, ci as u64, "foreign identify");
        let record = foreign::measure(&case.sensing, &ug, clean, &mut rng);
        let dir = root.join(case.name);
        foreign::write(&record, dt, &dir).unwrap();
        let out = dir.join("r.json");
        let o = sysid()
            .arg("filter")
            .args(foreign::MINIMAL_FLAGS)
            .args(["--seed", &foreign::SEED.to_string(), "--data"])
            .arg(&dir)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{}: {text}", case.name);
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let names = r["param_names"].as_array().unwrap();
        for (name, v) in names.iter().zip(r["theta_val"].as_array().unwrap()) {
            let v = v.as_f64().unwrap();
            assert!(v > 0.0, "{}: {name} = {v}", case.name);
        }
        // The free run predicts every floor better than "the floor moves with the ground".
        for (j, ch) in r["free_run"]["channels"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let model = ch["fit_percent"].as_f64().unwrap();
            let ground = foreign::fit(&record.measured[j], &record.ug);
            assert!(
                model > ground,
                "{}: a{}: fit {model:.1} % against the ground's {ground:.1} %",
                case.name,
                j + 1
            );
            let truth = foreign::fit(&record.measured[j], &record.clean[j]);
            eprintln!(
                "{}: a{}: fit {model:.1} % (the true structure's {truth:.1} %, the ground's {ground:.1} %)",
                case.name,
                j + 1
            );
        }
    }
}
