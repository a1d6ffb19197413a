//! `substeps = "auto"` (the default of `sysid filter`): sub-steps where the prior's building is
//! stiff relative to the sampling rate, one where it is not, and one for the filters that do not
//! sub-step (`models::filtering::substeps`).

use std::fmt::Write as _;

use experiments::field::StructureSettings;
use experiments::pipeline::{chain_spec, identify, resolve_substeps, Algorithm, RunInput};
use experiments::settings::{FilterSettings, Substeps};
use models::dataset::{generate, load_dir, DatasetConfig, MeasurementKind};
use models::integrate::simulate_rk4;
use models::structure::ShearChain;

/// A linear three-storey building like the shake-table frame (k ≈ 2700 per unit mass, modes up
/// to about 16 Hz) sampled at 120 Hz, 3 s of a chirp-like table motion, no noise.
fn write_frame_like(dir: &std::path::Path) {
    let chain = ShearChain::new(vec![1.0; 3], vec![2700.0; 3], vec![1.0; 3], vec![]).unwrap();
    let dt = 1.0 / 120.0;
    let ug: Vec<f64> = (0..360)
        .map(|i| {
            let t = i as f64 * dt;
            (std::f64::consts::TAU * (2.0 + 6.0 * t) * t).sin()
        })
        .collect();
    let truth = simulate_rk4(&chain, &ug, dt);
    let mut text = String::from("t,ug,a1,a2,a3\n");
    let mut row = [0.0; 3];
    for (i, g) in ug.iter().enumerate() {
        chain.relative_accelerations(truth.state(i), *g, &mut row);
        write!(text, "{},{g}", i as f64 * dt).unwrap();
        for a in row {
            write!(text, ",{}", a + g).unwrap();
        }
        text.push('\n');
    }
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("measured.csv"), text).unwrap();
}

fn frame_settings() -> FilterSettings {
    FilterSettings {
        particles: 40,
        trace_every: 0,
        structure: StructureSettings {
            storeys: Some(3),
            hysteretic: Some(vec![]),
            masses: Some(vec![1.0]),
            measurement: Some(MeasurementKind::Absolute),
            damping: None,
        },
        ..FilterSettings::recommended()
    }
}

#[test]
fn a_stiff_record_is_sub_stepped_until_its_highest_mode_is_represented() {
    let dir = std::env::temp_dir().join(format!("sysid-auto-substeps-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    write_frame_like(&dir);
    let data = load_dir(&dir).unwrap();
    let s = frame_settings();
    assert_eq!(s.substeps, Substeps::Auto);
    let mut spec = chain_spec(&data, None, &s).unwrap();
    let a = resolve_substeps(Algorithm::MpfEkf2, &mut spec, &s, None)
        .linear
        .unwrap();
    // One step per sample would shift the highest mode by several per cent; the choice keeps
    // it under the rule's 0.5 % with the fewest sub-steps.
    assert!(a.substeps >= 2, "{a:?}");
    assert!(a.error_one > 0.02 && a.error_chosen <= 0.005, "{a:?}");
    let fewer = models::filtering::substeps::frequency_error(
        a.omega_max * spec.dt / (a.substeps - 1) as f64,
    );
    assert!(
        fewer > 0.005,
        "{a:?}: {} sub-steps were enough",
        a.substeps - 1
    );
    assert_eq!(spec.substeps, a.substeps);
    // Filters that do not sub-step keep one transition (and say what it costs).
    let mut spec1 = chain_spec(&data, None, &s).unwrap();
    let b = resolve_substeps(Algorithm::MlnRbpf, &mut spec1, &s, None)
        .linear
        .unwrap();
    assert_eq!((b.substeps, spec1.substeps), (1, 1));
    assert_eq!(b.error_chosen, b.error_one);
    // A fixed number is kept as given.
    let fixed = FilterSettings {
        substeps: Substeps::Fixed(2),
        ..s.clone()
    };
    let mut spec2 = chain_spec(&data, None, &fixed).unwrap();
    assert!(
        resolve_substeps(Algorithm::MpfEkf2, &mut spec2, &fixed, None)
            .linear
            .is_none()
    );
    assert_eq!(spec2.substeps, 2);
    // The run records the choice.
    let input = RunInput {
        data: &data,
        chain: None,
        experiment: "auto",
        seed: 1,
        run: 0,
        progress: false,
        residuals: false,
    };
    let r = identify(&input, Algorithm::MpfEkf2, &s).unwrap();
    assert_eq!(r.config["filter"]["substeps"], "auto");
    assert_eq!(r.config["spec"]["substeps"], a.substeps);
    assert_eq!(r.config["substeps_auto"]["substeps"], a.substeps);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_papers_data_need_no_sub_step() {
    let data = generate(&DatasetConfig::from_preset("paper-3dof", 1).unwrap())
        .unwrap()
        .to_loaded();
    let chain = data.true_chain().unwrap();
    let s = FilterSettings::recommended();
    let mut spec = chain_spec(&data, chain.as_ref(), &s).unwrap();
    let a = resolve_substeps(Algorithm::MpfEkf2, &mut spec, &s, None)
        .linear
        .unwrap();
    assert_eq!(a.substeps, 1, "{a:?}");
}
