//! Pooled independent filters (the `pool` setting): M filters of Np/M particles each run on the
//! same data from independent streams, and their answers are pooled into one record.
//!
//! One particle filter's posterior does not know its own Monte-Carlo error: after path
//! degeneracy every particle descends from a few ancestors, and the mixture of their Gaussians is
//! much narrower than the scatter of θ_val over repeated runs (`docs/calibration.md`). Independent
//! filters see that scatter. The pooled answer (as in the `particles` library's multiSMC):
//!
//! - posterior: the equal-weight mixture of the filters' final posteriors — the particles of all
//!   filters with weights `w_i^(m) / M` — from which the credible intervals, the final s.d. and
//!   the distinct-value counts are computed as for one filter;
//! - θ_val: the mean of the filters' θ_vals, with Monte-Carlo s.e. `s.d._m(θ_val^(m)) / √M`
//!   recorded per parameter ([`crate::observe::ParamIntervals::mc_se`]);
//! - log-likelihood: `log (1/M) Σ_m p̂_m(y_1:T)`, again an unbiased estimate of the likelihood;
//! - ESS: the smallest over the filters' minima and the mean of their means (each out of Np/M);
//!   repairs and resampling events summed;
//! - trace: the pooled posterior at every kept step ([`pooled_trace`]: the mean of the kept
//!   filters' means, the s.d. of their equal-weight mixture, their mean ESS), so that a figure
//!   drawn from the trace shows the posterior the summary reports;
//! - online state errors: those of the first kept filter (filter 0's stream is the unpooled
//!   run's); prediction errors: filter 0's, none when it was left out.
//!
//! A filter that failed, or that **lost track of the record**, is left out of the pooled answer and
//! listed in the record (`pool_left_out`, with a warning, [`crate::checks`]); the run fails (its
//! record is a failed filter's) only when the kept filters are not a majority of the pool. A
//! completed filter has lost track of the record when, over the record's tail (its last tenth, at
//! least the averaging window, [`crate::observe::tail_steps`]), its one-step predictions of the
//! measurements are worse than the pool's median filter's by more than [`LOST_NATS`] nats per
//! channel and step *and* by more than [`LOST_ROBUST_SDS`] robust s.d.s of the pool's spread
//! (1.4826 × the median absolute deviation). Measured (docs/calibration.md, "Lost filters"):
//! on 3-storey paper data sets no filter of the marginalised algorithms comes near (largest 0.26
//! nats over 1056 filters; one bootstrap PF filter of 320 is left out, at 2.16); at 10 storeys
//! the MLN-RBPF and Storvik have completed filters 10⁴–10⁶ nats per channel and step worse, with
//! k1 at 12–17 % of the truth, which the equal-weight pool averaged in. The rule
//! leaves out at most a minority of the completed filters (their median is the yardstick).
//! The pooled log-likelihood is that of the kept filters.

use core_filters::smc::runner::{slot_moments, WeightedParticles};
use core_filters::smc::{Particles, RunSummary};
use core_filters::Health;

use core_filters::model::Layout;

use crate::metrics::{mean_sd, median, StateErrors};
use crate::observe::final_intervals;
use crate::record::diagnostics::{LeftOutFilter, LeftOutReason};

/// A completed filter of a pool is lost when its tail log-likelihood per channel and step is
/// below the pool median's by more than this many nats… (two nats per channel and step: an
/// innovation χ² larger by 4 on every channel at every step of the tail; on 3-storey paper data
/// sets the marginalised filters stay within 0.26 of their median and the bootstrap PF's,
/// but for one of 320, within 1.01)
pub(crate) const LOST_NATS: f64 = 2.0;
/// …and by more than this many robust s.d.s of the pool's tail log-likelihoods.
pub(crate) const LOST_ROBUST_SDS: f64 = 6.0;

/// What the driver of one filter returns ([`crate::pipeline`]).
pub(crate) struct Driven {
    pub(crate) summary: RunSummary,
    pub(crate) distinct: Vec<(String, usize)>,
    pub(crate) credible: Vec<crate::observe::ParamIntervals>,
    /// The final posterior's correlation matrix of θ (row-major; empty when no step completed).
    pub(crate) correlation: Vec<f64>,
    pub(crate) param_names: Vec<String>,
    pub(crate) theta_val: Vec<f64>,
    pub(crate) theta_sd_final: Vec<f64>,
    pub(crate) trace: crate::observe::Trace,
    pub(crate) online: Option<StateErrors>,
    pub(crate) wall_s: f64,
    /// The final weights and particles, kept for pooling (`s.pool > 1`).
    pub(crate) final_particles: Option<crate::observe::FinalParticles>,
    /// One-step-ahead prediction errors ([`crate::residuals`]), when asked for.
    pub(crate) residuals: Option<crate::checks::Residuals>,
    /// Σ log p̂(y_k | y_1:k−1) over the record's tail and the tail's completed steps
    /// ([`crate::observe::Recorder::tail_loglik`]).
    pub(crate) tail_loglik: f64,
    pub(crate) tail_steps: usize,
    /// The pool's filters left out of this answer (empty for one filter).
    pub(crate) left_out: Vec<LeftOutFilter>,
}

/// Which of a pool's filters to leave out of its answer, and why: every failed filter, and every
/// completed filter whose tail log-likelihood per channel and step falls below the completed
/// filters' median by more than [`LOST_NATS`] and [`LOST_ROBUST_SDS`] robust s.d.s.
pub(crate) fn left_out(members: &[Driven], channels: usize) -> Vec<LeftOutFilter> {
    let per_step = |d: &Driven| d.tail_loglik / (d.tail_steps.max(1) * channels.max(1)) as f64;
    let completed: Vec<f64> = members
        .iter()
        .filter(|d| d.summary.failure.is_none())
        .map(per_step)
        .collect();
    // Median and robust s.d. of the finite tails (a non-finite one is lost by itself, below).
    let centre = median(&completed);
    let spread = centre.map(|m| {
        1.4826 * median(&completed.iter().map(|v| (v - m).abs()).collect::<Vec<_>>()).unwrap_or(0.0)
    });
    let mut out = Vec::new();
    for (i, d) in members.iter().enumerate() {
        if let Some(f) = &d.summary.failure {
            out.push(LeftOutFilter {
                filter: i,
                reason: LeftOutReason::Failed,
                failure_kind: Some(f.kind().to_string()),
                tail_loglik: None,
                median_tail_loglik: centre,
                message: f.to_string(),
            });
            continue;
        }
        let (Some(m), Some(sd)) = (centre, spread) else {
            continue;
        };
        let v = per_step(d);
        let below = m - v;
        // A non-finite tail (an overflowed likelihood) is as lost as a filter can be.
        if !v.is_finite() || (below > LOST_NATS && below > LOST_ROBUST_SDS * sd) {
            out.push(LeftOutFilter {
                filter: i,
                reason: LeftOutReason::Lost,
                failure_kind: None,
                tail_loglik: Some(v),
                median_tail_loglik: Some(m),
                message: format!(
                    "over the last {} steps it predicted the measurements {below:.3e} nats per \
                     channel and step worse than the pool's median filter ({v:.4} against \
                     {m:.4}; robust s.d. of the pool {sd:.3e}): it lost track of the record",
                    d.tail_steps
                ),
            });
        }
    }
    out
}

/// Pools the runs of `members` (all of the same filter, in stream order, on data of `channels`
/// channels) into one, leaving out the filters [`left_out`] names.
pub(crate) fn combine(layout: &Layout, members: Vec<Driven>, channels: usize) -> Driven {
    let wall_s: f64 = members.iter().map(|d| d.wall_s).sum();
    let pool_size = members.len();
    let left = left_out(&members, channels);
    let mut members = members;
    if 2 * (pool_size - left.len()) <= pool_size {
        // No majority kept: the run fails with the first failed filter's failure.
        if let Some(i) = members.iter().position(|d| d.summary.failure.is_some()) {
            let mut failed = members.swap_remove(i);
            failed.wall_s = wall_s;
            failed.credible.clear();
            failed.correlation.clear();
            return failed;
        }
    }
    // Repairs and resampling events of every filter, the left-out ones included.
    let mut health = Health::default();
    for d in &members {
        health.absorb(&d.summary.health);
    }
    let mut members = kept_members(members, &left);
    let m = members.len();
    let finals: Vec<_> = members
        .iter()
        .map(|d| {
            d.final_particles
                .as_ref()
                .expect("a completed run keeps its particles")
        })
        .collect();
    let (particles, w) = pooled_particles(&finals);
    let pooled = WeightedParticles {
        layout,
        w: &w,
        particles: &particles,
        bounds: &finals[0].bounds,
    };
    let n_params = layout.params.len();
    let theta_val: Vec<f64> = (0..n_params)
        .map(|j| members.iter().map(|d| d.theta_val[j]).sum::<f64>() / m as f64)
        .collect();
    let mut credible = final_intervals(&pooled);
    let correlation = pooled.param_correlation();
    for (j, c) in credible.iter_mut().enumerate() {
        let vals: Vec<f64> = members.iter().map(|d| d.theta_val[j]).collect();
        let (_, sd, _) = mean_sd(&vals);
        c.mc_se = sd.is_finite().then(|| sd / (m as f64).sqrt());
    }
    let theta_sd_final = layout
        .params
        .iter()
        .map(|&slot| slot_moments(slot, &w, &particles).1)
        .collect();
    let summary = pooled_summary(&members, health);
    let distinct = pooled.distinct_sampled_params();
    let (tail_loglik, tail_steps) = (members[0].tail_loglik, members[0].tail_steps);
    let trace = pooled_trace(&members);
    let residuals = pooled_residuals(&members);
    let first = members.swap_remove(0);
    Driven {
        summary,
        distinct,
        credible,
        correlation,
        param_names: first.param_names,
        theta_val,
        theta_sd_final,
        trace,
        online: first.online,
        wall_s,
        final_particles: None,
        residuals,
        tail_loglik,
        tail_steps,
        left_out: left,
    }
}

/// The members the pool keeps (those `left` does not name), in stream order.
fn kept_members(members: Vec<Driven>, left: &[LeftOutFilter]) -> Vec<Driven> {
    let mut kept: Vec<Driven> = Vec::with_capacity(members.len());
    for (i, d) in members.into_iter().enumerate() {
        if !left.iter().any(|l| l.filter == i) {
            kept.push(d);
        }
    }
    kept
}

/// The final particles of the kept filters as one weighted cloud: every filter's particles in
/// order, each weight divided by the number of filters.
fn pooled_particles(finals: &[&crate::observe::FinalParticles]) -> (Particles, Vec<f64>) {
    let m = finals.len();
    let shape = finals[0].particles.shape();
    let total: usize = finals.iter().map(|f| f.particles.len()).sum();
    let mut particles = Particles::new(total, shape);
    let mut w = Vec::with_capacity(total);
    for f in finals {
        for i in 0..f.particles.len() {
            particles.copy_from(w.len(), &f.particles, i);
            w.push(f.w[i] / m as f64);
        }
    }
    (particles, w)
}

/// The pool's run summary: the log-likelihood of the mixture of the kept filters, their
/// smallest ESS and mean ESS, and the repairs of every filter (`health`).
fn pooled_summary(members: &[Driven], health: Health) -> RunSummary {
    let m = members.len();
    // log (1/M) Σ exp(ℓ_m), by log-sum-exp.
    let max = members
        .iter()
        .map(|d| d.summary.loglik)
        .fold(f64::NEG_INFINITY, f64::max);
    let loglik = max
        + (members
            .iter()
            .map(|d| (d.summary.loglik - max).exp())
            .sum::<f64>()
            / m as f64)
            .ln();
    let ess_min = members
        .iter()
        .filter_map(|d| d.summary.ess_min)
        .fold(None, |a: Option<f64>, e| Some(a.map_or(e, |a| a.min(e))));
    let ess_means: Vec<f64> = members.iter().filter_map(|d| d.summary.ess_mean).collect();
    RunSummary {
        steps_completed: members[0].summary.steps_completed,
        loglik,
        ess_min,
        ess_mean: (!ess_means.is_empty())
            .then(|| ess_means.iter().sum::<f64>() / ess_means.len() as f64),
        failure: None,
        health,
    }
}

/// The one-step prediction errors of the pooled posterior: at each step the mean of the kept
/// filters' one-step predictions (each filter computes its own), and the errors of that mean
/// divided by the noise s.d. A single filter of 125 particles predicts with its own Monte-Carlo
/// error, which is correlated in time and made the whiteness check flag records of the model's
/// own class (18 % of 150 channels at 500 particles, 4 filters; docs/residuals.md); the mean over
/// the pool carries a fraction of it. The first kept filter's errors when the members' do not
/// line up or hold no noise s.d. (older records).
fn pooled_residuals(members: &[Driven]) -> Option<crate::checks::Residuals> {
    let first = members.first()?.residuals.as_ref()?;
    let all: Vec<&crate::checks::Residuals> = members
        .iter()
        .filter_map(|d| d.residuals.as_ref())
        .collect();
    let lines_up = all.len() == members.len()
        && first.noise_sd.len() == first.channels.len()
        && all.iter().all(|r| {
            r.predicted.len() == first.predicted.len()
                && r.predicted
                    .iter()
                    .all(|row| row.len() == first.channels.len())
        });
    if !lines_up {
        return Some(first.clone());
    }
    let m = all.len() as f64;
    let mut out = first.clone();
    for (k, (row, errors)) in out
        .predicted
        .iter_mut()
        .zip(out.normalised_innovation.iter_mut())
        .enumerate()
    {
        for (j, (v, e)) in row.iter_mut().zip(errors.iter_mut()).enumerate() {
            *v = all.iter().map(|r| r.predicted[k][j]).sum::<f64>() / m;
            *e = (first.measured[k][j] - *v) / first.noise_sd[j];
        }
    }
    Some(out)
}

/// The trace of the pooled posterior: at each kept step the equal-weight mixture of the kept
/// filters' posteriors — the mean of their means, the s.d. from the mixture's second moment
/// (`√(mean(s.d.² + mean²) − pooled mean²)`) — and the filters' mean ESS (each out of its own
/// particles, as the record's ESS). The filters keep the same steps; a shorter trace (none
/// in a completed pool) cuts the pooled one to its length.
fn pooled_trace(members: &[Driven]) -> crate::observe::Trace {
    let first = &members[0].trace;
    let steps = members
        .iter()
        .map(|d| d.trace.t.len().min(d.trace.param_mean.len()))
        .min()
        .unwrap_or(0);
    let m = members.len() as f64;
    let mut trace = crate::observe::Trace {
        every: first.every,
        t: first.t[..steps].to_vec(),
        ..Default::default()
    };
    for k in 0..steps {
        let n = first.param_mean[k].len();
        let mut mean = vec![0.0; n];
        let mut second = vec![0.0; n];
        for d in members {
            for j in 0..n {
                let (mu, sd) = (d.trace.param_mean[k][j], d.trace.param_sd[k][j]);
                mean[j] += mu / m;
                second[j] += (sd * sd + mu * mu) / m;
            }
        }
        let sd = mean
            .iter()
            .zip(&second)
            .map(|(mu, s2)| (s2 - mu * mu).max(0.0).sqrt())
            .collect();
        trace.param_mean.push(mean);
        trace.param_sd.push(sd);
    }
    let ess_steps = members.iter().map(|d| d.trace.ess.len()).min().unwrap_or(0);
    trace.ess = (0..ess_steps)
        .map(|k| members.iter().map(|d| d.trace.ess[k]).sum::<f64>() / m)
        .collect();
    trace
}

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::model::Slot;
    use core_filters::smc::Shape;
    use core_filters::FilterError;

    const STEPS: usize = 100;

    fn layout() -> Layout {
        Layout {
            param_names: vec!["k1".into()],
            params: vec![Slot::Sampled(0)],
            state_names: vec![],
            states: vec![],
        }
    }

    /// A completed filter whose 10 particles all hold θ = `theta`, with tail log-likelihood
    /// `per_step` per channel and step (3 channels, 100 tail steps); `failed` ends it early.
    fn member(theta: f64, per_step: f64, failed: bool) -> Driven {
        let np = 10;
        let mut particles = Particles::new(
            np,
            Shape {
                sampled: 1,
                marginal: 0,
            },
        );
        for i in 0..np {
            particles.particle_mut(i).sampled[0] = theta;
        }
        let health = Health {
            resamples: 1,
            ..Health::default()
        };
        Driven {
            summary: RunSummary {
                steps_completed: if failed { 40 } else { STEPS },
                loglik: per_step * 300.0,
                ess_min: Some(5.0),
                ess_mean: Some(8.0),
                failure: failed.then_some(FilterError::AllWeightsZero { step: 41 }),
                health,
            },
            distinct: vec![],
            credible: vec![],
            correlation: vec![],
            param_names: vec!["k1".into()],
            theta_val: vec![if failed { f64::NAN } else { theta }],
            theta_sd_final: vec![0.0],
            trace: Default::default(),
            online: None,
            wall_s: 1.0,
            final_particles: (!failed).then(|| crate::observe::FinalParticles {
                w: vec![1.0 / np as f64; np],
                particles,
                bounds: Vec::new(),
            }),
            residuals: None,
            tail_loglik: per_step * 300.0,
            tail_steps: STEPS,
            left_out: vec![],
        }
    }

    /// Eight filters spread by ±0.2 nats per channel and step around −1.
    fn pool(theta: f64) -> Vec<Driven> {
        (0..8)
            .map(|i| member(theta + i as f64, -1.0 + 0.05 * (i as f64 - 3.5), false))
            .collect()
    }

    #[test]
    fn a_pool_of_agreeing_filters_keeps_them_all() {
        let d = combine(&layout(), pool(10.0), 3);
        assert!(d.left_out.is_empty());
        assert_eq!(d.theta_val, vec![10.0 + 3.5]);
        assert_eq!(d.summary.health.resamples, 8);
    }

    #[test]
    fn a_filter_that_lost_the_structure_is_left_out_and_named() {
        let mut members = pool(10.0);
        members[5] = member(1000.0, -1.0e6, false);
        let d = combine(&layout(), members, 3);
        assert_eq!(d.left_out.len(), 1);
        assert_eq!(d.left_out[0].filter, 5);
        assert_eq!(d.left_out[0].reason, LeftOutReason::Lost);
        assert_eq!(d.left_out[0].tail_loglik, Some(-1.0e6));
        // The answer is the mean of the other seven; every filter's repairs are counted.
        let kept: f64 = [0, 1, 2, 3, 4, 6, 7].iter().map(|&i| 10.0 + i as f64).sum();
        assert!((d.theta_val[0] - kept / 7.0).abs() < 1e-12);
        assert_eq!(d.summary.health.resamples, 8);
        assert!(d.summary.failure.is_none());
    }

    #[test]
    fn a_worse_filter_within_the_pools_own_spread_or_within_one_nat_is_kept() {
        // 1.9 nats below the median with a tight pool: more than 6 robust s.d.s, less than 2 nats.
        let tight = |i: usize| member(10.0, -1.0 + 0.001 * (i as f64 - 3.5), false);
        let mut members: Vec<Driven> = (0..8).map(tight).collect();
        members[2] = member(10.0, -2.9, false);
        assert!(left_out(&members, 3).is_empty());
        members[2] = member(10.0, -3.1, false);
        assert_eq!(left_out(&members, 3).len(), 1);
        // 3 nats below in a pool spread by ±4 nats: more than 2 nats, within 6 robust s.d.s.
        let wide: Vec<Driven> = (0..8)
            .map(|i| member(10.0, -10.0 + 1.2 * (i as f64 - 3.5), false))
            .collect();
        let mut members = wide;
        members[0] = member(10.0, -13.0, false);
        assert!(left_out(&members, 3).is_empty());
        members[0] = member(10.0, -40.0, false);
        assert_eq!(left_out(&members, 3).len(), 1);
        // A non-finite tail is lost.
        let mut members = pool(10.0);
        members[1] = member(10.0, f64::NEG_INFINITY, false);
        assert_eq!(left_out(&members, 3).len(), 1);
    }

    #[test]
    fn failed_filters_are_left_out_while_a_majority_completes() {
        let mut members = pool(10.0);
        members[0] = member(10.0, -1.0, true);
        members[3] = member(10.0, -1.0, true);
        for (i, m) in members.iter_mut().enumerate() {
            m.residuals = Some(crate::checks::Residuals {
                channels: vec![format!("from {i}")],
                ..Default::default()
            });
        }
        let d = combine(&layout(), members, 3);
        assert!(d.summary.failure.is_none());
        let failed: Vec<usize> = d.left_out.iter().map(|l| l.filter).collect();
        assert_eq!(failed, vec![0, 3]);
        assert!(d.left_out.iter().all(|l| l.reason == LeftOutReason::Failed
            && l.failure_kind.as_deref() == Some("all_weights_zero")));
        // The prediction errors are the first kept filter's (filter 1), not the left-out 0's.
        assert_eq!(
            d.residuals.map(|r| r.channels),
            Some(vec!["from 1".to_string()])
        );
        // Four failed of eight: no majority, the run fails.
        let mut members = pool(10.0);
        for i in [1, 2, 5, 7] {
            members[i] = member(10.0, -1.0, true);
        }
        let d = combine(&layout(), members, 3);
        assert!(d.summary.failure.is_some());
    }
}
