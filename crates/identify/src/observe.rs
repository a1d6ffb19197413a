//! The observer that turns a filter run into the data of a run record (SPEC §7): θ_val over the
//! last `l` steps, decimated traces of posterior means and s.d.s, online state errors against the
//! truth when it is known, the ESS trace, and the central credible intervals of θ at the end.

use core_filters::credible::STANDARD_LEVELS;
use core_filters::model::{Layout, Slot};
use core_filters::smc::runner::WeightedParticles;
use core_filters::smc::{Observer, Particles, Posterior, StepInfo};

use crate::metrics::ErrorSums;
pub use crate::record::trace::{ParamIntervals, PosteriorShape, Trace};

/// The intervals of every parameter of the layout from the weighted particles of the last step.
pub(crate) fn final_intervals(last: &WeightedParticles<'_>) -> Vec<ParamIntervals> {
    last.layout
        .param_names
        .iter()
        .zip(&last.layout.params)
        .map(|(name, &slot)| {
            let shape = match slot {
                Slot::Sampled(_) => PosteriorShape::WeightedSample,
                Slot::Marginal(_) => PosteriorShape::GaussianMixture,
            };
            let (intervals, error) = match last.central_intervals(slot, &STANDARD_LEVELS) {
                Ok(v) => (v, None),
                Err(e) => (Vec::new(), Some(e.to_string())),
            };
            ParamIntervals {
                parameter: name.clone(),
                shape,
                intervals,
                error,
                mc_se: None,
            }
        })
        .collect()
}

/// The normalised weights and the particles of a run's last step, kept for pooling.
#[derive(Debug, Clone)]
pub(crate) struct FinalParticles {
    pub w: Vec<f64>,
    pub particles: Particles,
    /// The filter's physical support (its intervals are truncated to it).
    pub bounds: Vec<core_filters::linalg::LowerBound>,
}

/// The true state signals, for online errors: `truth[k][j]` is the true value at step `k` of the
/// filter's state `j` (already mapped to the filter's layout order).
pub(crate) struct TruthStates<'a> {
    pub rows: &'a [Vec<f64>],
}

/// How far a run is, told to its caller: `tell(steps done, steps in all)` with the steps of the
/// earlier filters of a pool (`before`) counted in, so that a pooled run counts one way from 0
/// to `total`.
#[derive(Clone, Copy)]
pub struct Progress<'a> {
    pub tell: &'a (dyn Fn(usize, usize) + Sync),
    pub before: usize,
    pub total: usize,
}

/// Records what a run record needs.
pub(crate) struct Recorder<'a> {
    total_steps: usize,
    window: usize,
    dt: f64,
    pub trace: Trace,
    window_sum: Vec<f64>,
    window_n: usize,
    pub last: Posterior,
    truth: Option<TruthStates<'a>>,
    pub state_sums: Vec<ErrorSums>,
    /// Who is told how far the run is ([`Progress`]).
    pub progress: Option<Progress<'a>>,
    /// Distinct values of each sampled parameter at the end of a completed run (degeneracy).
    pub distinct: Vec<(String, usize)>,
    /// Central credible intervals of θ at the end of a completed run ([`ParamIntervals`]).
    pub credible: Vec<ParamIntervals>,
    /// The final posterior's correlation matrix of θ (row-major; empty before the end).
    pub correlation: Vec<f64>,
    /// Keep a copy of the final weighted particles (for pooling several filters).
    pub keep_final: bool,
    pub final_particles: Option<FinalParticles>,
    /// One-step-ahead prediction errors, when asked for ([`crate::residuals`]).
    pub predictor: Option<crate::residuals::Predictor>,
    /// Asked before every step whether to stop the run (a user's interruption); `None`: never.
    pub stop: Option<&'a (dyn Fn() -> bool + Sync)>,
    /// Σ log p̂(y_k | y_1:k−1) over the record's tail (the steps after `tail_from`): how well the
    /// filter predicts the measurements once it has settled (module `pool` compares it
    /// between pooled filters).
    pub tail_loglik: f64,
    pub tail_steps: usize,
    tail_from: usize,
}

/// The steps of a run's tail: the last tenth of the record, and at least the averaging window.
pub(crate) fn tail_steps(total_steps: usize, window: usize) -> usize {
    (total_steps / 10).max(window).min(total_steps)
}

impl<'a> Recorder<'a> {
    /// A recorder for a run of `total_steps` steps of length `dt`, averaging θ over the last
    /// `window` steps (SPEC eq. 26: l = 80), keeping one trace step in `trace_every`.
    pub fn new(
        total_steps: usize,
        window: usize,
        trace_every: usize,
        dt: f64,
        n_params: usize,
        n_states: usize,
        truth: Option<TruthStates<'a>>,
    ) -> Self {
        Self {
            total_steps,
            window,
            dt,
            trace: Trace {
                every: trace_every,
                ..Trace::default()
            },
            window_sum: vec![0.0; n_params],
            window_n: 0,
            last: Posterior::default(),
            truth,
            state_sums: vec![ErrorSums::default(); n_states],
            progress: None,
            distinct: Vec::new(),
            credible: Vec::new(),
            correlation: Vec::new(),
            keep_final: false,
            final_particles: None,
            predictor: None,
            stop: None,
            tail_loglik: 0.0,
            tail_steps: 0,
            tail_from: total_steps.saturating_sub(tail_steps(total_steps, window)),
        }
    }

    /// θ_val: mean of the posterior means over the steps of the averaging window (the last
    /// `window` steps of the run) that completed. NaN for every parameter when none did (a run
    /// that failed before its window): a failed run has no θ_val rather than a zero one.
    pub fn theta_val(&self) -> Vec<f64> {
        if self.window_n == 0 {
            return vec![f64::NAN; self.window_sum.len()];
        }
        self.window_sum
            .iter()
            .map(|s| s / self.window_n as f64)
            .collect()
    }
}

impl Observer for Recorder<'_> {
    fn should_stop(&mut self, _k: usize) -> bool {
        self.stop.is_some_and(|stop| stop())
    }

    fn on_start(&mut self, layout: &Layout, _particles: usize) {
        self.last = Posterior::for_layout(layout);
        if let Some(p) = &mut self.predictor {
            p.start(layout);
        }
    }

    fn on_finish(&mut self, last: &WeightedParticles<'_>) {
        self.distinct = last.distinct_sampled_params();
        self.credible = final_intervals(last);
        if self.keep_final {
            // A pool's member: pooled before its answer is read, the pool's correlation is the
            // pooled particles' (`pool::combine`), so the member computes none of its own.
            self.final_particles = Some(FinalParticles {
                w: last.w.to_vec(),
                particles: last.particles.clone(),
                bounds: last.bounds.to_vec(),
            });
        } else {
            self.correlation = last.param_correlation();
        }
    }

    fn on_step(&mut self, info: &StepInfo, post: &Posterior) {
        let k = info.k;
        if k > self.tail_from {
            self.tail_loglik += info.loglik_increment;
            self.tail_steps += 1;
        }
        if k + self.window > self.total_steps {
            for (s, m) in self.window_sum.iter_mut().zip(&post.param_mean) {
                *s += m;
            }
            self.window_n += 1;
        }
        if let Some(truth) = &self.truth {
            if let Some(row) = truth.rows.get(k) {
                for ((s, est), tr) in self.state_sums.iter_mut().zip(&post.state_mean).zip(row) {
                    s.add(*est, *tr);
                }
            }
        }
        let every = self.trace.every;
        if every > 0 && (k.is_multiple_of(every) || k == self.total_steps) {
            self.trace.t.push(k as f64 * self.dt);
            self.trace.param_mean.push(post.param_mean.clone());
            self.trace.param_sd.push(post.param_sd.clone());
            self.trace.ess.push(info.ess);
        }
        if let Some(p) = &self.progress {
            if k.is_multiple_of(64) || k == self.total_steps {
                (p.tell)(p.before + k, p.total);
            }
        }
        if let Some(p) = &mut self.predictor {
            p.step(k, post);
        }
        // The last completed step's posterior (θ_sd_final; also kept when a run fails early).
        self.last.clone_from(post);
    }
}
