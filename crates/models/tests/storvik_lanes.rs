//! Storvik's filter on the paper's chain (SPEC §5.3) runs step (iii) for four particles at once
//! in SIMD lanes; this checks, step by step, that it gives exactly the results of the scalar
//! updates particle by particle ([`Storvik::without_lanes`]): the same bits in every mean,
//! covariance and weight, the same step reports and the same repair and failure counts. The
//! cases cover both treatments of `y_k`, fixed parameters (zero-variance directions), particle
//! counts that leave the last group of four partly empty, and a measurement that fails.

use core_filters::particle::storvik::{Storvik, StorvikUpdate};
use core_filters::particle::{ParticleConfig, ParticleFilter};
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::stream;
use models::dataset::{generate, DatasetConfig};
use models::partition::{FilterSpec, PaperMln};
use nalgebra::SVector;

/// The paper-3dof data set, first two seconds, and a filter specification for it.
fn data_and_spec() -> (Vec<SVector<f64, 3>>, FilterSpec) {
    let mut config = DatasetConfig::from_preset("paper-3dof", 11).unwrap();
    config.duration = Some(2.0);
    let data = generate(&config).unwrap();
    let ys = (1..data.len())
        .map(|k| SVector::from_column_slice(data.y(k)))
        .collect();
    let spec = FilterSpec::from_rms(
        data.dt,
        data.chain.masses().to_vec(),
        data.ug_meas.clone(),
        &[3.0, 3.0, 3.0],
        3.0,
        0.3,
        0.1,
    )
    .unwrap();
    (ys, spec)
}

fn same_bits(a: &[f64], b: &[f64], what: &str, k: usize) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert_eq!(
            x.to_bits(),
            y.to_bits(),
            "{what} at step {k}: {x} against {y}"
        );
    }
}

/// Runs the lanes and the scalar reference side by side on the same draws.
fn check(spec: &FilterSpec, ys: &[SVector<f64, 3>], update: StorvikUpdate, np: usize) {
    let config = ParticleConfig {
        particles: np,
        resampling: ResamplePolicy {
            scheme: Scheme::Systematic,
            ess_threshold: Some(0.5),
        },
    };
    let mut lanes = Storvik::with_update(PaperMln::new(spec.clone()).unwrap(), config, update);
    let mut scalar =
        Storvik::with_update(PaperMln::new(spec.clone()).unwrap(), config, update).without_lanes();
    let (mut rng_l, mut rng_s) = (stream(5, np as u64, "lanes"), stream(5, np as u64, "lanes"));
    lanes.initialise(&mut rng_l);
    scalar.initialise(&mut rng_s);
    for (k, y) in ys.iter().enumerate().map(|(k, y)| (k + 1, y)) {
        let (info_l, info_s) = (lanes.step(k, y, &mut rng_l), scalar.step(k, y, &mut rng_s));
        assert_eq!(format!("{info_l:?}"), format!("{info_s:?}"), "step {k}");
        same_bits(lanes.weights(), scalar.weights(), "weights", k);
        for i in 0..np {
            same_bits(
                lanes.means()[i].as_slice(),
                scalar.means()[i].as_slice(),
                "means",
                k,
            );
            same_bits(
                lanes.covariances()[i].as_slice(),
                scalar.covariances()[i].as_slice(),
                "covariances",
                k,
            );
            same_bits(
                lanes.sampled()[i].as_slice(),
                scalar.sampled()[i].as_slice(),
                "sampled",
                k,
            );
        }
        assert_eq!(lanes.health(), scalar.health(), "step {k}");
        if info_l.is_err() {
            return;
        }
    }
}

#[test]
fn lanes_give_the_scalar_results_bit_for_bit() {
    let (ys, spec) = data_and_spec();
    for update in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
        for np in [1, 3, 8, 50] {
            check(&spec, &ys, update, np);
        }
    }
}

#[test]
fn lanes_give_the_scalar_results_with_fixed_parameters_and_failures() {
    let (mut ys, spec) = data_and_spec();
    // Fixed parameters: zero-variance directions of C, and a prior far from the data.
    let mut fixed = spec.clone();
    fixed.prior.fix("k1", 80.0).unwrap();
    fixed.prior.fix("c2", 0.5).unwrap();
    fixed.prior.fix("beta", 2.0).unwrap();
    for update in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
        check(&fixed, &ys, update, 13);
    }
    // A NaN measurement: every particle fails at that step, through the scalar path.
    ys[40][1] = f64::NAN;
    for update in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
        check(&spec, &ys, update, 10);
    }
}
