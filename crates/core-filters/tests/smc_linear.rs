//! Exactness and statistical tests of the run-time-dimension particle filters (SPEC §5.1–5.4) on
//! linear-Gaussian models whose exact answers the Kalman filter gives, and the batch layer's
//! equality with one particle at a time.
//!
//! Likelihood tests use the unbiasedness of `p̂(y_1:T)`: over `R` independent seeds the mean of
//! `exp(ℓ̂ − ℓ)` has expectation 1; we require it within 4.5 Monte-Carlo standard errors
//! (estimated from the same `R` ratios) of 1.

mod smc_common;

use core_filters::kalman::kalman_filter;
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::stream;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::runner::NoObserver;
use core_filters::smc::{run, Filter, Observer, Posterior, SmcConfig, StepInfo};
use nalgebra::{SVector, Vector1, Vector2};
use smc_common::{ratio_mean_and_se, Linked, StaticOnly};

const Z_LIMIT: f64 = 4.5;

fn config(np: usize) -> SmcConfig {
    SmcConfig {
        particles: np,
        resampling: ResamplePolicy::default(),
    }
}

/// Records `[param means, param sds, state means, loglik increment, ess]` at every step.
#[derive(Default)]
struct Trace(Vec<Vec<f64>>);
impl Observer for Trace {
    fn on_step(&mut self, info: &StepInfo, p: &Posterior) {
        let mut row = p.param_mean.clone();
        row.extend(&p.param_sd);
        row.extend(&p.state_mean);
        row.extend([info.loglik_increment, info.ess]);
        self.0.push(row);
    }
}

fn rows<const N: usize>(flat: &[f64]) -> Vec<SVector<f64, N>> {
    flat.chunks_exact(N)
        .map(SVector::<f64, N>::from_column_slice)
        .collect()
}

#[test]
fn mln_rbpf_is_the_kalman_filter_when_everything_is_linear() {
    let model = StaticOnly::example();
    let ys = model.simulate(Vector2::new(1.5, -1.0), 40, &mut stream(3, 0, "data"));
    let kf = kalman_filter(&model.kalman(), &rows::<2>(&ys)).unwrap();
    for lanes in [false, true] {
        let mut pf = MlnRbpf::with_lanes(model.clone(), lanes);
        let mut trace = Trace::default();
        let s = run(
            &mut pf,
            &config(22),
            &ys,
            2,
            &mut stream(3, 0, "f"),
            &mut trace,
        );
        assert!(s.failure.is_none());
        assert!(
            (s.loglik - kf.loglik).abs() < 1e-9 * kf.loglik.abs().max(1.0),
            "{} vs {}",
            s.loglik,
            kf.loglik
        );
        for (row, (m, c)) in trace.0.iter().zip(kf.means.iter().zip(&kf.covs)) {
            for j in 0..2 {
                assert!((row[j] - m[j]).abs() < 1e-9, "mean {} vs {}", row[j], m[j]);
                assert!((row[2 + j] - c[(j, j)].sqrt()).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn mln_rbpf_likelihood_is_unbiased_when_u_informs_z() {
    let model = Linked::example();
    let ys = model.simulate(1.3, 15, &mut stream(1, 0, "data"));
    let exact = kalman_filter(&model.joint_kalman(), &rows::<1>(&ys))
        .unwrap()
        .loglik;
    let mut pf = MlnRbpf::new(model);
    let ls: Vec<f64> = (0..300)
        .map(|r| {
            let s = run(
                &mut pf,
                &config(100),
                &ys,
                1,
                &mut stream(2024, r, "mln"),
                &mut NoObserver,
            );
            assert!(s.failure.is_none());
            s.loglik
        })
        .collect();
    let (mean, se) = ratio_mean_and_se(&ls, exact);
    eprintln!("mln-rbpf: exact ℓ = {exact:.4}, mean exp(ℓ̂−ℓ) = {mean:.4} ± {se:.4}");
    assert!(se < 0.05, "relative variance too large: se = {se}");
    assert!(
        (mean - 1.0).abs() < Z_LIMIT * se,
        "mean ratio {mean} ± {se}"
    );
}

/// The batch layer gives the same bits as one particle at a time: every step's posterior
/// summary, log-likelihood increment and ESS, for particle counts that fill and do not fill the
/// last group, with resampling at every step and with an ESS threshold.
fn lanes_equal_scalar<F: Filter>(make: impl Fn(bool) -> F, ys: &[f64], ny: usize) {
    for np in [1, 3, 8, 13] {
        for threshold in [None, Some(0.5)] {
            let cfg = SmcConfig {
                particles: np,
                resampling: ResamplePolicy {
                    ess_threshold: threshold,
                    ..ResamplePolicy::default()
                },
            };
            let mut traces = Vec::new();
            for lanes in [false, true] {
                let mut f = make(lanes);
                let mut t = Trace::default();
                let s = run(
                    &mut f,
                    &cfg,
                    ys,
                    ny,
                    &mut stream(9, np as u64, "eq"),
                    &mut t,
                );
                traces.push((s.loglik.to_bits(), t.0, s.health));
            }
            let bits = |t: &Vec<Vec<f64>>| -> Vec<Vec<u64>> {
                t.iter()
                    .map(|r| r.iter().map(|v| v.to_bits()).collect())
                    .collect()
            };
            assert_eq!(traces[0].0, traces[1].0, "np {np}: loglik differs");
            assert_eq!(bits(&traces[0].1), bits(&traces[1].1), "np {np}: trace");
            assert_eq!(traces[0].2, traces[1].2, "np {np}: health");
        }
    }
}

#[test]
fn mln_rbpf_lanes_equal_one_particle_at_a_time() {
    let model = Linked::example();
    let ys = model.simulate(1.3, 25, &mut stream(5, 0, "data"));
    lanes_equal_scalar(|lanes| MlnRbpf::with_lanes(model.clone(), lanes), &ys, 1);
    let st = StaticOnly::example();
    let ys = st.simulate(Vector2::new(0.5, 2.0), 25, &mut stream(6, 0, "data"));
    lanes_equal_scalar(|lanes| MlnRbpf::with_lanes(st.clone(), lanes), &ys, 2);
    let _ = Vector1::new(0.0);
}
