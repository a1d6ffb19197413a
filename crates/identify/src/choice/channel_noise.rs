//! Each channel's measurement noise learned from the data by maximum likelihood (type II):
//! `sysid filter --learn-noise`.
//!
//! The noise levels a run settles are a fraction `nf` of each signal's RMS (SPEC §3), the same
//! fraction on every channel, chosen on field data by held-out prediction ([`crate::choice`]).
//! Asked to learn them, the run treats each channel's noise s.d. as an unknown: scaled by
//! `exp(u_i)`, the settled level its prior's median (`u_i ~ N(0, PRIOR_LOG_SD²)`), with the
//! `u_i` moved to maximise the posterior — the filter's log-likelihood of the record,
//! `log p(y_1:T | R) = Σ_k log N(y_k; ŷ_k|k−1, S_k(R))`, θ integrated out by the filter (the
//! marginal likelihood of the noise levels), plus the prior's log-density. A compass search on
//! `u`, from steps of `FIRST_STEP` halved `HALVINGS` times, each `u_i` at most `ln MAX_FACTOR`
//! from the settled level; the neighbours of a step are run side by side and the best (the first
//! of equals) taken, so the answer is the same for any thread count. Each level's 95 % interval
//! is the Laplace approximation's, `exp(u_i ± 1.96/√−∂²/∂u_i²)` with the curvature from the
//! neighbours one last step away (per channel: the levels' correlations are left out). The
//! process noise stays as settled.
//!
//! Only for a run that is one Gaussian filter, whose log-likelihood is exact for a linear
//! building: on data of the filter's own class it recovers a known noise level per channel
//! (tested against the exact Kalman likelihood). It is not the default because on every real
//! record measured it predicts worse: the likelihood scores one-step predictions, which a filter
//! tracking the response makes well with little noise, and the levels it learns (0.10–0.75 of the
//! held-out choice's on five real records) let θ fit what the model cannot represent; the held-out choice scores the
//! free run a user judges (docs/validation.md, "Noise learned by maximum likelihood").

use models::dataset::LoadedDataset;
use rayon::prelude::*;

use super::search::Compass;

use crate::error::Result;
use crate::plan::{ChannelNoise, Decision, Level, LevelInterval, RunPlan};

/// First step of the search in `u_i = ln(σ_i / σ_i settled)`: ±65 %.
pub const FIRST_STEP: f64 = 0.5;

/// Times the step is halved once no move gains (the last step 1.6 %).
pub const HALVINGS: usize = 5;

/// Farthest the search moves a channel's noise s.d. from the settled one, as a factor either
/// way (the grid of noise fractions spans 30), and its logarithm (the bound of `u_i`).
pub const MAX_FACTOR: f64 = 10.0;
const MAX_FACTOR_LN: f64 = std::f64::consts::LN_10;

/// Most filter runs the search may take (a safeguard; a three-channel search takes 100–130).
const MAX_EVALUATIONS: usize = 400;

/// `plan` with channel `i`'s noise s.d. scaled by `exp(u[i])` (its variance by `exp(2 u[i])`).
pub fn with_channel_noise(plan: &RunPlan, u: &[f64]) -> RunPlan {
    let mut p = plan.clone();
    for (r, v) in p.model.r_diag.iter_mut().zip(u) {
        *r *= (2.0 * v).exp();
    }
    p
}

/// The log-likelihood of `data` under `plan`'s filter; `None` when the run failed.
fn loglik(plan: &RunPlan, data: &LoadedDataset) -> Option<f64> {
    let record = super::run_on(plan, data).ok()?;
    (record.failure.is_none() && record.loglik.is_finite()).then_some(record.loglik)
}

/// The prior of each `u_i`: N(0, `PRIOR_LOG_SD`²) — the settled level (the noise fraction's)
/// as the median, a factor 10 either way two s.d. out. The fixed noise fraction becomes the
/// prior of what is learned; a record of a few hundred samples moves it, a short one less.
pub const PRIOR_LOG_SD: f64 = std::f64::consts::LN_10 / 2.0;

/// The normal quantile of a central 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// The prior's log-density of `u` (up to its constant).
fn log_prior(u: &[f64]) -> f64 {
    -u.iter().map(|v| v * v).sum::<f64>() / (2.0 * PRIOR_LOG_SD * PRIOR_LOG_SD)
}

/// The search of the module documentation.
pub const SEARCH: Compass = Compass {
    first_step: FIRST_STEP,
    halvings: HALVINGS,
    bound: MAX_FACTOR_LN,
    max_evaluations: MAX_EVALUATIONS,
};

/// Why `--learn-noise` cannot serve `plan` on `data`, if it cannot: the search compares
/// log-likelihoods, which only a run that is one Gaussian filter gives exactly (a particle run's
/// is an estimate whose noise would steer the search).
pub fn refused(plan: &RunPlan, data: &LoadedDataset) -> Result<Option<String>> {
    Ok((!crate::rules::samples_nothing(plan.algorithm, &plan.spec(data)?)).then(|| {
        format!(
            "--learn-noise needs a run that is one Gaussian filter (the MPF-EKF2 on a linear building); \
             this {} run samples, and its log-likelihood is an estimate whose Monte-Carlo noise would \
             steer the search",
            plan.algorithm.label()
        )
    }))
}

/// `plan` with each channel's measurement noise learned on `data` (the whole record) — the
/// posterior's mode, the settled level its prior's median (the likelihood dominates on any
/// record long enough to identify on) — with the evidence and a decision; refused by name
/// where [`refused`] says so.
pub fn learn(plan: RunPlan, data: &LoadedDataset) -> Result<RunPlan> {
    if let Some(why) = refused(&plan, data)? {
        return Err(crate::error::Error::Invalid(why));
    }
    log::info!(
        "learning each of the {} channels' measurement noise by maximum likelihood…",
        plan.model.r_diag.len()
    );
    let sd = |p: &RunPlan| p.model.r_diag.iter().map(|r| r.sqrt()).collect::<Vec<_>>();
    let dims = plan.model.r_diag.len();
    // The log-posterior of u: the filter's log-likelihood and the prior's log-density.
    let eval = |u: &[f64]| loglik(&with_channel_noise(&plan, u), data).map(|l| l + log_prior(u));
    let at_settled = loglik(&plan, data);
    let ((u, best, mut evaluations, mut failed), last) =
        SEARCH.maximise_keeping_last(dims, at_settled, &eval);
    // Each u_i's curvature at the answer, from its neighbours one last step away: those the
    // search's last round ran, the others (beyond its bound) run here, side by side.
    let h = SEARCH.last_step();
    let around: Vec<Vec<f64>> = (0..dims)
        .flat_map(|j| [h, -h].map(|d| (j, d)))
        .map(|(j, d)| {
            let mut v = u.clone();
            v[j] += d;
            v
        })
        .collect();
    let known = |v: &Vec<f64>| last.iter().find(|(w, _)| w == v).map(|(_, l)| *l);
    let values: Vec<Option<f64>> = around
        .par_iter()
        .map(|v| known(v).unwrap_or_else(|| eval(v)))
        .collect();
    let ran = around.iter().filter(|v| known(v).is_none()).count();
    evaluations += ran;
    failed += around
        .iter()
        .zip(&values)
        .filter(|(v, l)| known(v).is_none() && l.is_none())
        .count();
    let mut out = with_channel_noise(&plan, &u);
    let learned = sd(&out);
    let channels: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
    let interval: Vec<LevelInterval> = (0..dims)
        .filter_map(|j| {
            let (up, down, at) = (values[2 * j]?, values[2 * j + 1]?, best?);
            let curvature = (up - 2.0 * at + down) / (h * h);
            (curvature < 0.0).then(|| {
                let half = Z95 / (-curvature).sqrt();
                LevelInterval {
                    channel: channels[j].clone(),
                    lo: learned[j] * (-half).exp(),
                    hi: learned[j] * half.exp(),
                }
            })
        })
        .collect();
    let at_bound = channels
        .iter()
        .zip(&u)
        .filter(|(_, v)| v.abs() >= MAX_FACTOR_LN - 1e-9)
        .map(|(c, _)| c.clone())
        .collect();
    let evidence = ChannelNoise {
        settled_sd: sd(&plan),
        learned_sd: learned,
        learned_sd_95: interval,
        channels,
        loglik_settled: at_settled,
        loglik_learned: best.map(|b| b - log_prior(&u)),
        evaluations,
        failed_evaluations: failed,
        at_bound,
    };
    let sds: Vec<String> = evidence
        .learned_sd
        .iter()
        .map(|s| format!("{s:.3e}"))
        .collect();
    out.decisions.push(Decision {
        rule: "choice::channel_noise::learn".into(),
        set: format!("measurement noise s.d. = [{}]", sds.join(", ")),
        level: if evidence.at_bound.is_empty() {
            Level::Note
        } else {
            Level::Warning
        },
        why: evidence.describe(),
    });
    out.evidence.channel_noise = Some(evidence);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::{MAX_FACTOR_LN, SEARCH};
    use core_filters::kalman::linear::{kalman_filter, LinearGaussian};
    use nalgebra::{SMatrix, SVector};
    use rand::Rng;

    /// A lightly damped 1.5 Hz oscillator sampled at 50 Hz, driven by process noise, seen by two
    /// channels (its displacement, and a mix of displacement and velocity) with different noise.
    fn model(r: [f64; 2]) -> LinearGaussian<2, 2> {
        let (dt, w, z) = (0.02, 2.0 * std::f64::consts::PI * 1.5, 0.03);
        LinearGaussian {
            // Semi-implicit Euler (velocity first): stable, det G = 1 − 2ζω·dt.
            g_mat: SMatrix::<f64, 2, 2>::new(
                1.0 - w * w * dt * dt,
                dt * (1.0 - 2.0 * z * w * dt),
                -w * w * dt,
                1.0 - 2.0 * z * w * dt,
            ),
            g_off: SVector::zeros(),
            h_mat: SMatrix::<f64, 2, 2>::new(1.0, 0.0, 0.5, 0.2),
            h_off: SVector::zeros(),
            q: SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from([1e-6, 4e-3])),
            r: SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from(r)),
            m0: SVector::zeros(),
            p0: SMatrix::<f64, 2, 2>::identity() * 0.01,
        }
    }

    #[test]
    fn the_search_finds_the_exact_kalman_likelihoods_noise_levels() {
        let truth = [0.02, 0.05];
        let m = model([truth[0] * truth[0], truth[1] * truth[1]]);
        let mut rng = core_filters::rng::stream(7, 0, "channel-noise-test");
        let normal = |rng: &mut core_filters::rng::StreamRng| {
            rng.sample::<f64, _>(rand_distr::StandardNormal)
        };
        let samples = 4000;
        let mut x = SVector::<f64, 2>::zeros();
        let ys: Vec<SVector<f64, 2>> = (0..samples)
            .map(|_| {
                x = m.g_mat * x
                    + SVector::from([m.q[(0, 0)].sqrt() * normal(&mut rng), {
                        m.q[(1, 1)].sqrt() * normal(&mut rng)
                    }]);
                m.h_mat * x
                    + SVector::from([truth[0] * normal(&mut rng), truth[1] * normal(&mut rng)])
            })
            .collect();
        // Started 3× and 1/2× off; the search moves the s.d. by exp(u).
        let start = [3.0 * truth[0], 0.5 * truth[1]];
        let ll = |u: &[f64]| {
            let r = [
                (start[0] * u[0].exp()).powi(2),
                (start[1] * u[1].exp()).powi(2),
            ];
            kalman_filter(&model(r), &ys).ok().map(|k| k.loglik)
        };
        let (u, best, evaluations, failed) = SEARCH.maximise(2, ll(&[0.0, 0.0]), &ll);
        assert_eq!(failed, 0);
        assert!(evaluations < 200, "{evaluations}");
        let learned = [start[0] * u[0].exp(), start[1] * u[1].exp()];
        // A local maximum of the exact likelihood to the search's last step: every neighbour
        // one step away along each channel is lower.
        let last = SEARCH.last_step();
        let best = best.unwrap();
        for j in 0..2 {
            for d in [last, -last] {
                let mut v = u.clone();
                v[j] += d;
                assert!(ll(&v).unwrap() <= best, "channel {j}, step {d}");
            }
        }
        // The ML estimate of ln σ_j over T samples has s.e. about (S_jj/R_jj)/√(2T), S the
        // steady innovation covariance of the true model (1.1 and 1.3 here); 4 s.e. and the
        // last step.
        let k = kalman_filter(&m, &ys).unwrap();
        let p_pred = m.g_mat * k.covs[samples - 1] * m.g_mat.transpose() + m.q;
        let s = m.h_mat * p_pred * m.h_mat.transpose() + m.r;
        for j in 0..2 {
            let se = s[(j, j)] / m.r[(j, j)] / (2.0 * samples as f64).sqrt();
            let tol = 4.0 * se + last;
            assert!(
                (learned[j] / truth[j]).ln().abs() <= tol,
                "channel {j}: learned {} against {} (tolerance {tol:.3} in ln)",
                learned[j],
                truth[j]
            );
        }
        assert!(u.iter().all(|v| v.abs() < MAX_FACTOR_LN));
    }
}
