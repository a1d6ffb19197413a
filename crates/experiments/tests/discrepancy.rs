//! The discrepancy term end to end (`identify::validation::discrepancy`, docs/validation.md): on
//! records of the filter's own class `sysid filter` with the minimal flags keeps no discrepancy
//! mode (a mode fitted to the noise gains nothing on the held-out part), and on a structure with
//! an unmeasured fourth mode it keeps at least one, which improves the held-out fit. The
//! structures are our own, not the foreign corpus's.

use crate::common;

use std::path::Path;
use std::process::Command;

use experiments::foreign::{self, Sensing, Structure};
use nalgebra::{DMatrix, DVector};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

/// A shear chain of storey stiffnesses `k` (unit masses) with Rayleigh damping of 3 % in its
/// first and last modes, floors measured; with `appendage`, a mass of that share on floor 3
/// tuned 10 % above the first mode (a fourth, unmeasured degree of freedom).
fn building(k: &[f64], appendage: Option<f64>) -> Structure {
    let base = foreign::chain(k);
    let band = foreign::band(&base);
    let (m, kk) = match appendage {
        None => (DMatrix::identity(3, 3), base),
        Some(ma) => foreign::with_mass_on(&base, 2, ma, 1.1 * band.0),
    };
    let n = m.nrows();
    Structure {
        c: foreign::rayleigh(&m, &kk, 0.03, band),
        m,
        k: kk,
        joint: None,
        r: DVector::from_element(n, 1.0),
        sensors: DMatrix::identity(3, n),
    }
}

/// `sysid filter` with the minimal flags on the record of `s` under `ug`: the number of
/// discrepancy modes its plan chose, and the held-out mean fit without and with them.
fn chosen_modes(s: &Structure, ug: &[f64], dt: f64, i: u64, dir: &Path) -> (usize, f64, f64) {
    let clean = foreign::respond(s, ug, dt);
    let mut rng = core_filters::rng::stream(11, i, "discrepancy test");
    let rec = foreign::measure(&Sensing::default(), ug, clean, &mut rng);
    foreign::write(&rec, dt, dir).unwrap();
    let out = dir.join("r.json");
    let o = sysid()
        .arg("filter")
        .args(foreign::MINIMAL_FLAGS)
        .args(["--seed", "11", "--data"])
        .arg(dir)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let choice = &r["plan"]["evidence"]["discrepancy"];
    assert!(
        choice.is_object(),
        "the plan records the discrepancy's choice"
    );
    let chosen = choice["chosen"].as_u64().unwrap() as usize;
    let score = |m: usize| choice["candidates"][m]["score"].as_f64().unwrap();
    // The record holds the term exactly when modes were chosen.
    let term = &r["free_run"]["discrepancy"];
    assert_eq!(term.is_object(), chosen > 0, "{term}");
    // With modes, θ was also identified with them inside the filter and scored on the held-out
    // part; the run takes that where its mean held-out fit is at least the term-after-θ's, and
    // then the plan and the record's spec carry the modes.
    let joint = &r["plan"]["evidence"]["joint_discrepancy"];
    assert_eq!(joint.is_object(), chosen > 0, "{joint}");
    let in_filter = &r["plan"]["model"]["discrepancy_modes"];
    if chosen > 0 {
        let mean = |k: &str| {
            let f = joint[k].as_array().unwrap();
            f.iter().map(|v| v.as_f64().unwrap()).sum::<f64>() / f.len() as f64
        };
        assert_eq!(
            joint["after_fit"],
            choice["candidates"][chosen]["held_out_fit"]
        );
        let kept = joint["kept"].as_bool().unwrap();
        assert_eq!(kept, mean("joint_fit") >= mean("after_fit"), "{joint}");
        if kept {
            assert_eq!(in_filter, &term["modes"]);
            assert_eq!(&r["config"]["spec"]["discrepancy_modes"], in_filter);
        }
        assert_eq!(in_filter.is_array(), kept, "{in_filter}");
    } else {
        assert!(in_filter.is_null());
    }
    (chosen, score(0), score(chosen))
}

#[test]
fn no_discrepancy_mode_on_the_filters_own_class_and_one_for_an_unmeasured_mode() {
    let (_tmp, root) = common::temp_dir("sysid-discrepancy-");
    let (ug, dt) = common::foreign_ground(
        &root.join("ground"),
        &["--excitation", "san-fernando-1971", "--duration", "20"],
    );
    for (i, k) in [[1500.0, 1100.0, 900.0], [800.0, 800.0, 600.0]]
        .iter()
        .enumerate()
    {
        let (m, without, with) = chosen_modes(
            &building(k, None),
            &ug,
            dt,
            i as u64,
            &root.join(format!("in-class-{i}")),
        );
        assert_eq!(m, 0, "in-class {k:?}: {m} modes ({without} → {with})");
    }
    let (m, without, with) = chosen_modes(
        &building(&[1500.0, 1100.0, 900.0], Some(0.08)),
        &ug,
        dt,
        9,
        &root.join("appendage"),
    );
    assert!(m >= 1, "appendage: no mode chosen ({without})");
    assert!(with > without + 0.5 * m as f64, "{without} → {with}");
}
