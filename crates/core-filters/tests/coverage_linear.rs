//! Coverage of the particle filters' credible intervals on a model whose exact posterior is known
//! (SPEC §9 "Calibration"): the linear-Gaussian model with a static parameter of the Storvik grid
//! test ([`Linked`]: `u_k = a u_{k−1} + b z + v`, `y_k = c u_k + d z + η`).
//!
//! Each replicate draws θ_true = z **from its prior** N(1, 0.5²) and simulates 40 measurements;
//! then, whatever the data, the exact posterior's central q-interval contains z with probability
//! exactly q, so over R independent replicates the number of intervals that cover is
//! Binomial(R, q) for an exact posterior. The exact posterior of z is Gaussian, from the Kalman
//! filter on the joint state [u, z].
//!
//! Tolerance: coverage within 3 binomial standard errors √(q(1 − q)/R) of q (a false alarm in
//! about 0.3 % of seeds per level for an exact posterior). A particle filter's posterior is not
//! exact: with 500 particles its interval ends carry a Monte-Carlo error, which here is small
//! against the posterior width (the marginalised filters hold z in closed form per particle), so
//! the test uses the binomial band unwidened. R = 300 keeps it under a few seconds while the band
//! (±0.052 at 90 %) still rejects the over-confidence of a posterior only 25 % too narrow
//! (coverage 0.82 instead of 0.9), as the control at the end shows.

use crate::smc_common;

use core_filters::credible::{normal_cdf, CredibleInterval, STANDARD_LEVELS};
use core_filters::kalman::kalman_filter;
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::stream;
use core_filters::smc::bootstrap::BootstrapPf;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::runner::WeightedParticles;
use core_filters::smc::storvik::{Storvik, StorvikUpdate};
use core_filters::smc::{run, Filter, Observer, SmcConfig};
use nalgebra::Vector1;
use smc_common::{normal, Linked};

const REPLICATES: u64 = 300;
const STEPS: usize = 40;
const PARTICLES: usize = 500;
const BAND_SE: f64 = 3.0;

/// Standard normal quantiles Φ⁻¹((1 + q)/2) for q = 0.5, 0.9, 0.95.
const Z: [f64; 3] = [
    0.674_489_750_196_081_7,
    1.644_853_626_951_472_7,
    1.959_963_984_540_054_2,
];

/// Keeps the intervals of the parameter at the end of the run.
#[derive(Default)]
struct Final(Vec<CredibleInterval>);
impl Observer for Final {
    fn wants_posterior(&self, _k: usize) -> bool {
        false
    }
    fn on_finish(&mut self, last: &WeightedParticles<'_>) {
        self.0 = last
            .central_intervals(last.layout.params[0], &STANDARD_LEVELS)
            .expect("finite particles");
    }
}

/// One replicate: z drawn from the prior, data, the exact posterior N(m, s²) of z.
fn replicate(model: &Linked, r: u64) -> (f64, Vec<f64>, (f64, f64)) {
    let mut rng = stream(16, r, "data");
    let z = model.z_mean + model.z_sd * normal(&mut rng);
    let ys = model.simulate(z, STEPS, &mut rng);
    let rows: Vec<Vector1<f64>> = ys.iter().map(|&y| Vector1::new(y)).collect();
    let kf = kalman_filter(&model.joint_kalman(), &rows).expect("the KF runs");
    let (m, p) = (kf.means[STEPS - 1][1], kf.covs[STEPS - 1][(1, 1)]);
    (z, ys, (m, p.sqrt()))
}

/// Covered counts at the standard levels over the replicates, for `filter`'s intervals and for
/// the exact posterior's.
fn coverage(model: &Linked, filter: &mut dyn Filter, name: &str) -> ([usize; 3], [usize; 3]) {
    let (mut got, mut exact) = ([0; 3], [0; 3]);
    let config = SmcConfig {
        particles: PARTICLES,
        resampling: ResamplePolicy::default(),
        rejuvenation: None,
    };
    for r in 0..REPLICATES {
        let (z, ys, (m, s)) = replicate(model, r);
        let mut fin = Final::default();
        let summary = run(filter, &config, &ys, 1, &mut stream(16, r, name), &mut fin);
        assert!(summary.failure.is_none(), "{:?}", summary.failure);
        for l in 0..3 {
            if fin.0[l].contains(z) {
                got[l] += 1;
            }
            if (z - m).abs() <= Z[l] * s {
                exact[l] += 1;
            }
        }
    }
    eprintln!(
        "{name}: covered {got:?} of {REPLICATES} at {STANDARD_LEVELS:?} (exact posterior {exact:?})"
    );
    (got, exact)
}

fn assert_nominal(what: &str, covered: [usize; 3]) {
    for (&q, c) in STANDARD_LEVELS.iter().zip(covered) {
        let n = REPLICATES as f64;
        let (cov, se) = (c as f64 / n, (q * (1.0 - q) / n).sqrt());
        assert!(
            (cov - q).abs() <= BAND_SE * se,
            "{what}: coverage {cov:.3} at level {q} is outside {q} ± {BAND_SE}·{se:.4}"
        );
    }
}

#[test]
fn exact_posterior_covers_at_the_nominal_rate() {
    // The set-up itself: z from the prior and the Kalman posterior give nominal coverage.
    let model = Linked::example();
    let mut exact = [0; 3];
    for r in 0..REPLICATES {
        let (z, _, (m, s)) = replicate(&model, r);
        for l in 0..3 {
            if (z - m).abs() <= Z[l] * s {
                exact[l] += 1;
            }
        }
    }
    assert_nominal("Kalman posterior", exact);
}

#[test]
fn mln_rbpf_intervals_cover_at_the_nominal_rate() {
    let model = Linked::example();
    let (got, _) = coverage(&model, &mut MlnRbpf::new(model.clone()), "mln-rbpf");
    assert_nominal("MLN-RBPF", got);
}

#[test]
fn storvik_exact_intervals_cover_at_the_nominal_rate() {
    let model = Linked::example();
    let (got, _) = coverage(
        &model,
        &mut Storvik::new(model.clone(), StorvikUpdate::Exact),
        "storvik",
    );
    assert_nominal("Storvik (exact update)", got);
}

/// The bootstrap PF samples z and never moves it (SPEC §5.1: no artificial parameter noise):
/// resampling leaves copies of fewer and fewer values, and its intervals are too narrow already
/// on 40 steps — one source of the over-confidence measured on the paper's data. Measured with
/// the seeds here: 232 of 300 at 90 % when resampling every step (0.77, 4.4 s.e. below
/// nominal), 245 of 300 when resampling only below ESS = Np/2 (0.82, still 2.9 s.e. below).
/// The test pins the defect at the paper's setting; a rejuvenation move for sampled static
/// parameters has to turn it into a nominal-coverage test.
#[test]
fn bootstrap_intervals_are_over_confident_without_rejuvenation() {
    let model = Linked::example();
    let (got, exact) = coverage(
        &model,
        &mut BootstrapPf::new(model.augmented()),
        "bootstrap",
    );
    assert_nominal("Kalman posterior, same replicates", exact);
    let n = REPLICATES as f64;
    let q = STANDARD_LEVELS[1];
    let at90 = got[1] as f64 / n;
    assert!(
        at90 < q - BAND_SE * (q * (1.0 - q) / n).sqrt(),
        "the bootstrap PF's 90 % intervals cover at {at90:.3}: no longer over-confident"
    );
}

/// The band has power: the exact posterior with its s.d. shrunk by 25 % covers the truth at
/// 2Φ(0.75 · 1.645) − 1 ≈ 0.78 at nominal 90 %, outside the band.
#[test]
fn a_posterior_25_percent_too_narrow_is_rejected() {
    let model = Linked::example();
    let mut narrow = [0; 3];
    for r in 0..REPLICATES {
        let (z, _, (m, s)) = replicate(&model, r);
        for l in 0..3 {
            if (z - m).abs() <= Z[l] * 0.75 * s {
                narrow[l] += 1;
            }
        }
    }
    let expected = 2.0 * normal_cdf(0.75 * Z[1]) - 1.0;
    let at90 = narrow[1] as f64 / REPLICATES as f64;
    assert!((at90 - expected).abs() < 0.08, "{at90} vs {expected}");
    let result = std::panic::catch_unwind(|| assert_nominal("narrow", narrow));
    assert!(
        result.is_err(),
        "a 25 % too narrow posterior passed: {narrow:?}"
    );
}
