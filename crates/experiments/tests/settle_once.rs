//! A run settles its plan once: one `sysid filter` identification on field data with a Bouc–Wen
//! element (the data-scaled prior, the MPF-EKF2's rules, `substeps = "auto"`) resolves its
//! building once and scans the data's spectra for the prior once. Alone in its test binary: the
//! counters are the process's.

use identify::identification::{identify_request, FilterRequest};
use identify::pipeline::Algorithm;
use models::sensors::MeasurementKind;

#[test]
fn one_identification_resolves_its_building_and_scans_its_prior_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("d");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args([
            "simulate",
            "--preset",
            "paper-3dof",
            "--duration",
            "2",
            "--seed",
            "4",
        ])
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for f in ["dataset.json", "truth.csv"] {
        std::fs::remove_file(dir.join(f)).unwrap();
    }
    let req = FilterRequest {
        algorithm: Algorithm::MpfEkf2,
        data: dir,
        config: None,
        particles: None,
        resampling: None,
        ess_threshold: None,
        storvik_update: None,
        discretisation: None,
        substeps: None,
        coloured_noise: None,
        learn_noise: false,
        rejuvenation: None,
        fix: None,
        noise_fraction: None,
        process_noise_factor: None,
        experiment: "once".into(),
        seed: 1,
        run: 0,
        storeys: Some(3),
        hysteretic: Some("1".into()),
        masses: Some("1".into()),
        measurement: Some(MeasurementKind::Relative),
        damping: None,
    };
    let (resolved, scanned) = (
        identify::field::resolutions(),
        identify::scaled_prior::scans(),
    );
    let mut notes = 0;
    let identified = identify_request(&req, &mut |_| notes += 1).unwrap();
    assert!(identified.record.failure.is_none());
    assert!(notes >= 3, "building, prior and rules are said");
    // The time of settling the plan is recorded beside the run's, and on field data the free
    // run's: the run alone is not what the identification cost.
    let t = &identified.record.timing;
    assert!(t.plan_s.is_some_and(|p| p > 0.0), "{t:?}");
    assert!(
        identified.record.free_run.is_some() && t.validation_s > 0.0,
        "{t:?}"
    );
    assert_eq!(
        identify::field::resolutions() - resolved,
        1,
        "building resolutions"
    );
    assert_eq!(identify::scaled_prior::scans() - scanned, 1, "prior scans");
}
