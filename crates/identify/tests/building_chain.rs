//! The `building-chain` structures of the scaling study (docs/scaling.md) through the pipeline:
//! their default prior is SPEC §3's carried to the building's values, and at their stiffness
//! (ω_N·dt ≈ 0.45) the symplectic discretisation identifies them while forward Euler's damping
//! bias (dt·k/c, docs/discretisation.md) becomes a factor of several.

use identify::pipeline::{chain_spec, identify, Algorithm, FilterSettings, RunInput};
use models::dataset::{generate, DatasetConfig};
use models::filtering::{ChainPrior, Discretisation};
use models::priors::Prior;

#[test]
fn default_prior_follows_the_structure() {
    let mut config = DatasetConfig::from_preset("building-chain", 3).unwrap();
    config.storeys = Some(5);
    config.duration = Some(0.5);
    let set = generate(&config).unwrap();
    let data = set.to_loaded();
    let spec = chain_spec(&data, Some(&set.chain), &FilterSettings::default()).unwrap();
    let (k, c) = (set.chain.stiffness(), set.chain.damping());
    for j in 0..5 {
        assert_eq!(
            spec.prior.k[j],
            Prior::LogNormal {
                median: 1.25 * k[j],
                log_sd: 0.3
            }
        );
        assert_eq!(
            spec.prior.c[j],
            Prior::LogNormal {
                median: 1.6 * c[j],
                log_sd: 0.5
            }
        );
    }
    // The paper's presets keep SPEC §3's prior exactly.
    let mut paper = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    paper.duration = Some(0.5);
    let set = generate(&paper).unwrap();
    let spec = chain_spec(
        &set.to_loaded(),
        Some(&set.chain),
        &FilterSettings::default(),
    )
    .unwrap();
    assert_eq!(spec.prior, ChainPrior::paper(3, &[0]));
}

#[test]
fn symplectic_identifies_a_stiff_building_where_euler_biases_damping() {
    // Three storeys, T₁ = 0.32 s, the whole record; MPF-EKF2 with 200 particles, one seed.
    let config = DatasetConfig::from_preset("building-chain", 11).unwrap();
    let set = generate(&config).unwrap();
    let data = set.to_loaded();
    let input = RunInput {
        data: &data,
        chain: Some(&set.chain),
        experiment: "building-chain",
        seed: 11,
        run: 0,
        progress: None,
        residuals: false,
    };
    let run = |d: Discretisation| {
        let s = FilterSettings {
            particles: 200,
            discretisation: d,
            trace_every: 0,
            loop_every: 0,
            validate: false,
            ..FilterSettings::default()
        };
        identify(&input, Algorithm::MpfEkf2, &s).unwrap()
    };
    let sym = run(Discretisation::Symplectic);
    let eul = run(Discretisation::Euler);
    assert!(sym.failure.is_none(), "{:?}", sym.failure);
    let ratio = |r: &identify::record::RunRecord, name: &str| {
        let j = r.param_names.iter().position(|n| n == name).unwrap();
        r.theta_val[j] / r.theta_true.as_ref().unwrap()[j]
    };
    for j in 1..=3 {
        let k = ratio(&sym, &format!("k{j}"));
        assert!((0.85..1.15).contains(&k), "symplectic k{j}/true = {k}");
    }
    // Euler's damping bias at this stiffness: dt·k/c = 0.005·2000/4.02 ≈ 2.5, i.e. c about
    // 3.5 times too large; symplectic within a factor 2 of the truth.
    let (ce, cs) = (ratio(&eul, "c1"), ratio(&sym, "c1"));
    assert!(ce > 2.0, "Euler c1/true = {ce}");
    assert!((0.5..2.0).contains(&cs), "symplectic c1/true = {cs}");
}
