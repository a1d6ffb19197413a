//! Storvik's filter (SPEC §5.3) and the MLN-RBPF (§5.2) on the paper's chain run their Gaussian
//! updates for four particles at once in SIMD lanes; this checks, step by step, that they give
//! exactly the results of the scalar updates particle by particle (`without_lanes`): the same
//! bits in every sampled block, mean, covariance and weight, the same step reports and the same
//! repair and failure counts. The cases cover both of Storvik's treatments of `y_k`, fixed
//! parameters (zero-variance directions), particle counts that leave the last group of four
//! partly empty, resampling with an ESS threshold, and a measurement that fails.

use core_filters::particle::mlnrbpf::MlnRbpf;
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

/// The filters compared: Storvik with either update, or the MLN-RBPF.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Storvik(StorvikUpdate),
    Mln,
}

/// A filter's sampled blocks, means, covariances and weights.
type Parts<'a> = (
    &'a [SVector<f64, 8>],
    &'a [SVector<f64, 8>],
    &'a [nalgebra::SMatrix<f64, 8, 8>],
    &'a [f64],
);

/// What the comparison reads of a filter.
trait Inspect: ParticleFilter<3> {
    fn parts(&self) -> Parts<'_>;
}

macro_rules! inspect {
    ($($filter:ty),*) => {$(
        impl Inspect for $filter {
            fn parts(&self) -> Parts<'_> {
                (self.sampled(), self.means(), self.covariances(), self.weights())
            }
        }
    )*};
}

inspect!(Storvik<PaperMln, 8, 8, 4, 3>, MlnRbpf<PaperMln, 8, 8, 4, 3>);

fn config(np: usize) -> ParticleConfig {
    ParticleConfig {
        particles: np,
        resampling: ResamplePolicy {
            scheme: Scheme::Systematic,
            ess_threshold: Some(0.5),
        },
    }
}

fn check(spec: &FilterSpec, ys: &[SVector<f64, 3>], kind: Kind, np: usize) {
    let model = || PaperMln::new(spec.clone()).unwrap();
    match kind {
        Kind::Storvik(update) => compare(
            Storvik::with_update(model(), config(np), update),
            Storvik::with_update(model(), config(np), update).without_lanes(),
            ys,
        ),
        Kind::Mln => compare(
            MlnRbpf::new(model(), config(np)),
            MlnRbpf::new(model(), config(np)).without_lanes(),
            ys,
        ),
    }
}

/// Runs the lanes and the scalar reference side by side on the same draws.
fn compare<F: Inspect>(mut lanes: F, mut scalar: F, ys: &[SVector<f64, 3>]) {
    let np = lanes.particles();
    let (mut rng_l, mut rng_s) = (stream(5, np as u64, "lanes"), stream(5, np as u64, "lanes"));
    lanes.initialise(&mut rng_l);
    scalar.initialise(&mut rng_s);
    for (k, y) in ys.iter().enumerate().map(|(k, y)| (k + 1, y)) {
        let (info_l, info_s) = (lanes.step(k, y, &mut rng_l), scalar.step(k, y, &mut rng_s));
        assert_eq!(format!("{info_l:?}"), format!("{info_s:?}"), "step {k}");
        let (l, s) = (lanes.parts(), scalar.parts());
        same_bits(l.3, s.3, "weights", k);
        for i in 0..np {
            same_bits(l.0[i].as_slice(), s.0[i].as_slice(), "sampled", k);
            same_bits(l.1[i].as_slice(), s.1[i].as_slice(), "means", k);
            same_bits(l.2[i].as_slice(), s.2[i].as_slice(), "covariances", k);
        }
        assert_eq!(lanes.health(), scalar.health(), "step {k}");
        if info_l.is_err() {
            return;
        }
    }
}

const KINDS: [Kind; 3] = [
    Kind::Storvik(StorvikUpdate::Linearised),
    Kind::Storvik(StorvikUpdate::Exact),
    Kind::Mln,
];

#[test]
fn lanes_give_the_scalar_results_bit_for_bit() {
    let (ys, spec) = data_and_spec();
    for kind in KINDS {
        for np in [1, 3, 8, 50] {
            check(&spec, &ys, kind, np);
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
    for kind in KINDS {
        check(&fixed, &ys, kind, 13);
    }
    // A NaN measurement: every particle fails at that step, through the scalar path.
    ys[40][1] = f64::NAN;
    for kind in KINDS {
        check(&spec, &ys, kind, 10);
    }
}
