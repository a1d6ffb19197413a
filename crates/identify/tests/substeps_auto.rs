//! `substeps = "auto"` (the default of `sysid filter`): sub-steps where the prior's building is
//! stiff relative to the sampling rate, one where it is not, and one for the filters that do not
//! sub-step (`models::filtering::substeps`).

use std::fmt::Write as _;

use identify::field::StructureSettings;
use identify::pipeline::{chain_spec, identify, resolve_substeps, Algorithm, RunInput};
use identify::settings::{FilterSettings, Substeps};
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
    let tmp = tempfile::Builder::new()
        .prefix("sysid-auto-substeps-")
        .tempdir()
        .unwrap();
    let dir = tmp.path().join("data");
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
        progress: None,
        residuals: false,
    };
    let r = identify(&input, Algorithm::MpfEkf2, &s).unwrap();
    assert_eq!(r.config["filter"]["substeps"], "auto");
    assert_eq!(r.config["substeps_auto"]["substeps"], a.substeps);
    // Field data of a linear building under the MPF-EKF2 (one Gaussian filter): the field
    // rule takes the highest mode's shift under 0.05 %, more sub-steps than the linear rule's.
    let f = &r.config["substeps_field"];
    let m = f["substeps"].as_u64().unwrap() as usize;
    assert!(m > a.substeps, "{f}");
    assert!(f["error_chosen"].as_f64().unwrap() <= identify::rules::FIELD_FREQUENCY_ERROR);
    let fewer =
        models::filtering::substeps::frequency_error(a.omega_max * spec.dt / (m - 1) as f64);
    assert!(fewer > identify::rules::FIELD_FREQUENCY_ERROR, "{f}");
    assert_eq!(r.config["spec"]["substeps"], m);
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

/// The velocity-lag rule (`pipeline::LAG_SUBSTEPS`): four sub-steps for the MPF-EKF2 with one
/// shared prior Gaussian on the scaling study's 5-storey building (lag 9.3 % with one step),
/// and nothing where it was not measured to pay: per-particle prior means, another filter, a
/// linear building, ten storeys, a fixed number of sub-steps, the paper's building.
#[test]
fn the_shared_prior_gaussian_below_ten_storeys_is_sub_stepped_against_the_velocity_lag() {
    use identify::pipeline::LAG_SUBSTEPS;
    use models::filtering::MarginalPrior;
    let building = |storeys: usize, hysteretic: bool| {
        let mut c = DatasetConfig::from_preset("building-chain", 1).unwrap();
        c.storeys = Some(storeys);
        c.duration = Some(0.5);
        if !hysteretic {
            c.hysteretic = Some(vec![]);
        }
        generate(&c).unwrap().to_loaded()
    };
    let choose = |data: &models::dataset::LoadedDataset, alg: Algorithm, s: &FilterSettings| {
        let chain = data.true_chain().unwrap();
        let mut spec = chain_spec(data, chain.as_ref(), s).unwrap();
        let auto = resolve_substeps(alg, &mut spec, s, None);
        (auto, spec.substeps)
    };
    let shared = FilterSettings::recommended();
    assert_eq!(shared.marginal_prior, MarginalPrior::MomentMatched);
    let five = building(5, true);
    let (auto, m) = choose(&five, Algorithm::MpfEkf2, &shared);
    let lag = auto.lag.expect("the rule applies");
    assert_eq!((m, lag.substeps), (LAG_SUBSTEPS, 4));
    assert!((lag.lag_one - 0.0926).abs() < 0.001, "{lag:?}");
    assert_eq!(lag.lag_one, auto.linear.unwrap().lag_one);
    // Not where it did not pay or was not measured.
    let per_particle = FilterSettings {
        marginal_prior: MarginalPrior::PerParticle { rel_sd: 0.1 },
        ..shared.clone()
    };
    let (auto, m) = choose(&five, Algorithm::MpfEkf2, &per_particle);
    assert_eq!((auto.lag.is_none(), m), (true, 1));
    for alg in [Algorithm::Bootstrap, Algorithm::MlnRbpf, Algorithm::Storvik] {
        let (auto, m) = choose(&five, alg, &shared);
        assert_eq!((auto.lag.is_none(), m), (true, 1), "{alg:?}");
    }
    let (auto, m) = choose(&building(5, false), Algorithm::MpfEkf2, &shared);
    assert_eq!((auto.lag.is_none(), m), (true, 1), "linear building");
    let (auto, _) = choose(&building(10, true), Algorithm::MpfEkf2, &shared);
    assert!(auto.lag.is_none(), "ten storeys");
    let one = FilterSettings {
        substeps: Substeps::Fixed(1),
        ..shared.clone()
    };
    let (auto, m) = choose(&five, Algorithm::MpfEkf2, &one);
    assert_eq!((auto.lag.is_none(), m), (true, 1), "--substeps 1");
    let paper = generate(&DatasetConfig::from_preset("paper-3dof", 1).unwrap())
        .unwrap()
        .to_loaded();
    let (auto, m) = choose(&paper, Algorithm::MpfEkf2, &shared);
    assert_eq!((auto.lag.is_none(), m), (true, 1), "the paper's building");
    // The run records the choice.
    let truth = five.true_chain().unwrap();
    let input = RunInput {
        data: &five,
        chain: truth.as_ref(),
        experiment: "lag",
        seed: 1,
        run: 0,
        progress: None,
        residuals: false,
    };
    let s = FilterSettings {
        particles: 16,
        pool: 1,
        trace_every: 0,
        loop_every: 0,
        validate: false,
        ..shared
    };
    let r = identify(&input, Algorithm::MpfEkf2, &s).unwrap();
    assert_eq!(r.config["spec"]["substeps"], 4);
    assert_eq!(r.config["substeps_lag"]["substeps"], 4);
}
