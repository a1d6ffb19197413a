//! The observer that turns a filter run into the data of a run record (SPEC §7): θ_val over the
//! last `l` steps, decimated traces of posterior means and s.d.s, online state errors against the
//! truth when it is known, and the ESS trace.

use core_filters::model::Layout;
use core_filters::smc::runner::WeightedParticles;
use core_filters::smc::{Observer, Posterior, StepInfo};
use serde::{Deserialize, Serialize};

use crate::metrics::ErrorSums;

/// Decimated per-step traces (step `k` is kept when `k % every == 0` or `k` is the last step).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Trace {
    /// Keep one step in `every` (0: no trace).
    pub every: usize,
    /// Time of each kept step (s).
    pub t: Vec<f64>,
    /// Posterior means of θ at each kept step (one row per kept step).
    pub param_mean: Vec<Vec<f64>>,
    /// Posterior s.d.s of θ at each kept step.
    pub param_sd: Vec<Vec<f64>>,
    /// ESS at each kept step.
    pub ess: Vec<f64>,
}

/// The true state signals, for online errors: `truth[k][j]` is the true value at step `k` of the
/// filter's state `j` (already mapped to the filter's layout order).
pub struct TruthStates<'a> {
    pub rows: &'a [Vec<f64>],
}

/// Records what a run record needs.
pub struct Recorder<'a> {
    total_steps: usize,
    window: usize,
    dt: f64,
    pub trace: Trace,
    window_sum: Vec<f64>,
    window_n: usize,
    pub last: Posterior,
    truth: Option<TruthStates<'a>>,
    pub state_sums: Vec<ErrorSums>,
    /// Optional progress bar advanced every 64 steps (terminal runs of `sysid filter`).
    pub progress: Option<indicatif::ProgressBar>,
    /// Distinct values of each sampled parameter at the end of a completed run (degeneracy).
    pub distinct: Vec<(String, usize)>,
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
        }
    }

    /// θ_val: mean of the posterior means over the last `window` completed steps.
    pub fn theta_val(&self) -> Vec<f64> {
        self.window_sum
            .iter()
            .map(|s| s / self.window_n.max(1) as f64)
            .collect()
    }
}

impl Observer for Recorder<'_> {
    fn on_start(&mut self, layout: &Layout, _particles: usize) {
        self.last = Posterior::for_layout(layout);
    }

    fn on_finish(&mut self, last: &WeightedParticles<'_>) {
        self.distinct = last.distinct_sampled_params();
    }

    fn on_step(&mut self, info: &StepInfo, post: &Posterior) {
        let k = info.k;
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
        if every > 0 && (k % every == 0 || k == self.total_steps) {
            self.trace.t.push(k as f64 * self.dt);
            self.trace.param_mean.push(post.param_mean.clone());
            self.trace.param_sd.push(post.param_sd.clone());
            self.trace.ess.push(info.ess);
        }
        if let Some(bar) = &self.progress {
            if k % 64 == 0 || k == self.total_steps {
                bar.set_position(k as u64);
            }
        }
        // The last completed step's posterior (θ_sd_final; also kept when a run fails early).
        self.last.clone_from(post);
    }
}
