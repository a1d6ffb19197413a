//! Pooled independent filters (`pool`): the pooled θ_val is the mean of the filters' θ_vals and
//! its Monte-Carlo s.e. their s.d. over √M; the first filter draws from the unpooled run's
//! stream; the intervals are those of the pooled posterior; a pool larger than the particles is
//! a named error; an unpooled run's settings are written without the field.

use identify::pipeline::{identify, Algorithm, FilterSettings, RunInput};
use models::dataset::{generate, DatasetConfig};

/// A 2 s `paper-3dof` data set (its structure kept for the run input).
fn paper_data() -> (models::dataset::Dataset, models::dataset::LoadedDataset) {
    let mut config = DatasetConfig::from_preset("paper-3dof", 3).unwrap();
    config.duration = Some(2.0);
    let data = generate(&config).unwrap();
    let loaded = data.to_loaded();
    (data, loaded)
}

fn input<'a>(
    data: &'a models::dataset::Dataset,
    loaded: &'a models::dataset::LoadedDataset,
    seed: u64,
) -> RunInput<'a> {
    RunInput {
        data: loaded,
        chain: Some(&data.chain),
        experiment: "pool",
        seed,
        run: 0,
        progress: None,
        residuals: false,
    }
}

#[test]
fn two_pooled_filters_average_and_measure_their_spread() {
    let (data, loaded) = paper_data();
    let input = input(&data, &loaded, 3);
    let single = FilterSettings {
        particles: 40,
        validate: false,
        ..FilterSettings::default()
    };
    let pooled = FilterSettings {
        particles: 80,
        pool: 2,
        ..single.clone()
    };
    for alg in [Algorithm::MpfEkf2, Algorithm::MlnRbpf] {
        let first = identify(&input, alg, &single).unwrap();
        let r = identify(&input, alg, &pooled).unwrap();
        assert!(r.failure.is_none() && first.failure.is_none());
        assert_eq!(r.credible.len(), r.param_names.len());
        assert!(first.credible.iter().all(|c| c.mc_se.is_none()));
        for (j, name) in r.param_names.iter().enumerate() {
            // With two filters θ_val = (θ0 + θ1)/2 and s.e. = |θ0 − θ1|/√2/√2 = |θ_val − θ0|.
            let c = &r.credible[j];
            assert_eq!(&c.parameter, name);
            let se = c
                .mc_se
                .expect("a pooled run measures its Monte-Carlo error");
            let want = (r.theta_val[j] - first.theta_val[j]).abs();
            assert!(
                (se - want).abs() <= 1e-12 * (1.0 + want),
                "{} {name}: s.e. {se} vs |θ_val − θ0| = {want}",
                alg.name()
            );
            assert_eq!(c.intervals.len(), 3);
            assert!(c
                .intervals
                .windows(2)
                .all(|w| w[0].lo >= w[1].lo && w[0].hi <= w[1].hi));
            assert!(r.theta_sd_final[j] >= 0.0);
        }
        // The two filters' particles together: the exponent n keeps at least the first's values.
        assert!(r.distinct_sampled["n"] >= first.distinct_sampled["n"]);
    }
    // Fewer particles than filters, or no filter, is an error naming the field.
    for (particles, pool) in [(1, 2), (40, 0)] {
        let bad = FilterSettings {
            particles,
            pool,
            ..single.clone()
        };
        let err = identify(&input, Algorithm::MpfEkf2, &bad).unwrap_err();
        assert!(format!("{err:#}").contains("`pool`"), "{err:#}");
    }
    // Particles that do not split evenly: the first filters take one more.
    let uneven = FilterSettings {
        particles: 41,
        pool: 2,
        ..single.clone()
    };
    let r = identify(&input, Algorithm::MpfEkf2, &uneven).unwrap();
    assert!(r.failure.is_none() && r.credible.iter().all(|c| c.mc_se.is_some()));
    // Unpooled settings are written as before (records and fingerprints unchanged).
    let v = serde_json::to_value(&single).unwrap();
    assert!(v.get("pool").is_none(), "{v}");
    assert_eq!(serde_json::to_value(&pooled).unwrap()["pool"], 2);
}

/// The trace of a pooled run is the pooled posterior the summary reports, not its first filter:
/// averaged over the last `window` steps its means are θ_val (the mean of the filters' θ_vals);
/// its last s.d. is the pooled posterior's final s.d.; and it differs from the first filter's.
#[test]
fn a_pooled_trace_shows_the_pooled_posterior() {
    let (data, loaded) = paper_data();
    let input = input(&data, &loaded, 5);
    let pooled = FilterSettings {
        particles: 160,
        pool: 4,
        trace_every: 1,
        validate: false,
        ..FilterSettings::default()
    };
    let first = FilterSettings {
        particles: 40,
        pool: 1,
        ..pooled.clone()
    };
    for alg in [Algorithm::MpfEkf2, Algorithm::Storvik] {
        let r = identify(&input, alg, &pooled).unwrap();
        let f = identify(&input, alg, &first).unwrap();
        assert!(r.failure.is_none());
        let (t, w) = (&r.trace, r.window);
        assert_eq!(t.param_mean.len(), r.steps_total);
        for (j, name) in r.param_names.iter().enumerate() {
            let tail = &t.param_mean[t.param_mean.len() - w..];
            let avg = tail.iter().map(|row| row[j]).sum::<f64>() / w as f64;
            let want = r.theta_val[j];
            assert!(
                (avg - want).abs() <= 1e-9 * want.abs().max(1e-9),
                "{} {name}: trace {avg} against θ_val {want}",
                alg.name()
            );
            let sd = t.param_sd.last().unwrap()[j];
            let final_sd = r.theta_sd_final[j];
            assert!(
                (sd - final_sd).abs() <= 1e-6 * final_sd.max(1e-12),
                "{} {name}: last trace s.d. {sd} against the pooled final s.d. {final_sd}",
                alg.name()
            );
        }
        assert_ne!(r.trace.param_mean, f.trace.param_mean, "{}", alg.name());
    }
}
