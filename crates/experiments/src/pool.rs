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
//! - traces and online state errors: those of the first filter (its stream is the unpooled run's).
//!
//! A failure of any filter is the failure of the run: its record is the failed filter's.

use core_filters::smc::runner::{slot_moments, WeightedParticles};
use core_filters::smc::{Particles, RunSummary};
use core_filters::Health;

use core_filters::model::Layout;

use crate::metrics::{mean_sd, StateErrors};
use crate::observe::final_intervals;

/// What the driver of one filter returns ([`crate::pipeline`]).
pub(crate) struct Driven {
    pub(crate) summary: RunSummary,
    pub(crate) distinct: Vec<(String, usize)>,
    pub(crate) credible: Vec<crate::observe::ParamIntervals>,
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
}

/// Pools the runs of `members` (all of the same filter, in stream order) into one.
pub(crate) fn combine(layout: &Layout, members: Vec<Driven>) -> Driven {
    let wall_s: f64 = members.iter().map(|d| d.wall_s).sum();
    let m = members.len();
    let mut members = members;
    if let Some(i) = members.iter().position(|d| d.summary.failure.is_some()) {
        let mut failed = members.swap_remove(i);
        failed.wall_s = wall_s;
        failed.credible.clear();
        return failed;
    }
    let finals: Vec<_> = members
        .iter()
        .map(|d| {
            d.final_particles
                .as_ref()
                .expect("a completed run keeps its particles")
        })
        .collect();
    let shape = finals[0].particles.shape();
    let total: usize = finals.iter().map(|f| f.particles.len()).sum();
    let mut particles = Particles::new(total, shape);
    let mut w = Vec::with_capacity(total);
    for f in &finals {
        for i in 0..f.particles.len() {
            particles.copy_from(w.len(), &f.particles, i);
            w.push(f.w[i] / m as f64);
        }
    }
    let pooled = WeightedParticles {
        layout,
        w: &w,
        particles: &particles,
    };
    let n_params = layout.params.len();
    let theta_val: Vec<f64> = (0..n_params)
        .map(|j| members.iter().map(|d| d.theta_val[j]).sum::<f64>() / m as f64)
        .collect();
    let mut credible = final_intervals(&pooled);
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
    let mut health = Health::default();
    for d in &members {
        health.absorb(&d.summary.health);
    }
    let ess_min = members
        .iter()
        .filter_map(|d| d.summary.ess_min)
        .fold(None, |a: Option<f64>, e| Some(a.map_or(e, |a| a.min(e))));
    let ess_means: Vec<f64> = members.iter().filter_map(|d| d.summary.ess_mean).collect();
    let summary = RunSummary {
        steps_completed: members[0].summary.steps_completed,
        loglik,
        ess_min,
        ess_mean: (!ess_means.is_empty())
            .then(|| ess_means.iter().sum::<f64>() / ess_means.len() as f64),
        failure: None,
        health,
    };
    let distinct = pooled.distinct_sampled_params();
    let first = members.swap_remove(0);
    Driven {
        summary,
        distinct,
        credible,
        param_names: first.param_names,
        theta_val,
        theta_sd_final,
        trace: first.trace,
        online: first.online,
        wall_s,
        final_particles: None,
        residuals: first.residuals,
    }
}
