//! Statistics of one algorithm's run records over a study (θ_val / θ_true, errors, ESS, cost),
//! and the paper's published values they are set against.

use std::collections::BTreeMap;

use serde::Serialize;

use identify::metrics::mean_sd;
use identify::record::RunRecord;

/// The studies of the reproduction, in the order they run.
pub const STUDIES: [&str; 5] = ["fig4", "fig5", "fig6", "fig8", "fig7"];

/// The paper's θ_val for its Fig. 8 run (eq. 31).
pub(crate) const PAPER_EQ31: [f64; 9] = [
    7.973, 7.912, 7.943, 0.277, 0.342, 0.278, 3.418, 0.960, 2.488,
];

/// Per algorithm and parameter: statistics of θ_val over the runs of a study.
#[derive(Debug, Clone, Serialize)]
pub struct ParamStats {
    pub name: String,
    pub truth: f64,
    /// Mean and s.d. over runs of θ_val / θ_true.
    pub ratio_mean: f64,
    pub ratio_sd: f64,
    /// Mean over runs of the relative error |θ_val − θ_true| / θ_true.
    pub rel_error_mean: f64,
}

/// Per algorithm: statistics over the runs of a study.
#[derive(Debug, Clone, Serialize)]
pub struct AlgorithmStats {
    pub algorithm: String,
    pub runs: usize,
    pub failed: usize,
    pub params: Vec<ParamStats>,
    pub online_nrmse_mean: f64,
    pub validation_nrmse_mean: f64,
    pub distinct_sampled_mean: BTreeMap<String, f64>,
    pub ess_mean: f64,
    pub loglik_mean: f64,
    pub wall_s_mean: f64,
    pub particle_steps_per_s_mean: f64,
}

/// The completed runs among one algorithm's `records`, and the parameter names (those of the
/// first record).
pub(crate) fn completed<'a>(records: &[&'a RunRecord]) -> (Vec<&'a RunRecord>, Vec<String>) {
    let ok = records
        .iter()
        .copied()
        .filter(|r| !r.is_failure())
        .collect();
    let names = records
        .first()
        .map(|r| r.param_names.clone())
        .unwrap_or_default();
    (ok, names)
}

/// The true value of parameter `j` as the first completed run knows it.
pub(crate) fn truth(ok: &[&RunRecord], j: usize) -> Option<f64> {
    ok.first()
        .and_then(|r| r.theta_true.as_ref())
        .and_then(|t| t.get(j).copied())
}

/// Statistics of one algorithm's records.
pub(crate) fn algorithm_stats(algorithm: &str, records: &[&RunRecord]) -> AlgorithmStats {
    let (ok, names) = completed(records);
    let params = names
        .iter()
        .enumerate()
        .map(|(j, name)| {
            let truth = truth(&ok, j).unwrap_or(f64::NAN);
            let ratios: Vec<f64> = ok.iter().map(|r| r.theta_val[j] / truth).collect();
            let errs: Vec<f64> = ok
                .iter()
                .filter_map(|r| r.rel_error.as_ref().map(|e| e[j]))
                .collect();
            let (ratio_mean, ratio_sd, _) = mean_sd(&ratios);
            ParamStats {
                name: name.clone(),
                truth,
                ratio_mean,
                ratio_sd,
                rel_error_mean: mean_sd(&errs).0,
            }
        })
        .collect();
    let avg = |f: &dyn Fn(&RunRecord) -> Option<f64>| {
        mean_sd(&ok.iter().filter_map(|r| f(r)).collect::<Vec<_>>()).0
    };
    let mut distinct: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in &ok {
        for (k, v) in &r.distinct_sampled {
            distinct.entry(k.clone()).or_default().push(*v as f64);
        }
    }
    AlgorithmStats {
        algorithm: algorithm.to_string(),
        runs: records.len(),
        failed: records.len() - ok.len(),
        params,
        online_nrmse_mean: avg(&|r| r.online_states.as_ref().map(|s| s.mean_nrmse())),
        validation_nrmse_mean: avg(&|r| {
            r.validation
                .as_ref()
                .filter(|v| v.error.is_none())
                .map(|v| v.states.mean_nrmse())
        }),
        distinct_sampled_mean: distinct
            .into_iter()
            .map(|(k, v)| (k, mean_sd(&v).0))
            .collect(),
        ess_mean: avg(&|r| Some(r.ess_mean)),
        loglik_mean: avg(&|r| Some(r.loglik)),
        wall_s_mean: avg(&|r| Some(r.timing.wall_s)),
        particle_steps_per_s_mean: avg(&|r| Some(r.timing.particle_steps_per_s)),
    }
}
