//! The record `sysid reference` writes ([`ReferenceRecord`]) and the warnings that say when its
//! chain is not a trustworthy posterior ([`chain_warnings`]).

use serde::{Deserialize, Serialize};

use super::ParamSummary;

/// What `sysid reference` writes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceRecord {
    pub data: String,
    /// SHA-256 of the data set as the estimator saw it (`data.sha256` of a run record's
    /// fingerprint), so that online records are compared with the reference of their own data
    /// set; absent in records written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_sha256: Option<String>,
    pub steps: usize,
    #[serde(with = "identify::record::number::scalar")]
    pub dt: f64,
    pub estimator: String,
    pub particles: usize,
    pub iterations: usize,
    pub burn_in: usize,
    pub seed: u64,
    #[serde(with = "identify::record::number::vec")]
    pub start: Vec<f64>,
    /// Mean and s.d. of `probe` likelihood estimates at the start point.
    #[serde(with = "identify::record::number::scalar")]
    pub loglik_at_start_mean: f64,
    #[serde(with = "identify::record::number::scalar")]
    pub loglik_at_start_sd: f64,
    #[serde(with = "identify::record::number::scalar")]
    pub acceptance: f64,
    #[serde(with = "identify::record::number::scalar")]
    pub acceptance_burn_in: f64,
    pub evaluations: u64,
    pub failed_estimates: u64,
    #[serde(with = "identify::record::number::scalar")]
    pub wall_s: f64,
    pub params: Vec<ParamSummary>,
    /// Why this reference should not be trusted as it is ([`chain_warnings`]).
    #[serde(default)]
    pub warnings: Vec<String>,
}

impl identify::record::read::Checked for ReferenceRecord {
    const KIND: &'static str = "reference record";
    /// One summary per free parameter with distinct names, quantiles in order where they are
    /// numbers, and counts that agree (failed estimates within the evaluations).
    fn check(&self) -> Result<(), String> {
        if self.iterations == 0 {
            return Err("`iterations` is 0: a chain of no kept iteration is no posterior".into());
        }
        if self.failed_estimates > self.evaluations {
            return Err(format!(
                "`failed_estimates` {} exceeds `evaluations` {}",
                self.failed_estimates, self.evaluations
            ));
        }
        let mut names: Vec<&str> = self.params.iter().map(|p| p.name.as_str()).collect();
        names.sort_unstable();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("parameter `{}` is summarised twice", w[0]));
        }
        if let Some(p) = self
            .params
            .iter()
            .find(|p| p.quantiles.windows(2).any(|q| q[0] > q[1]))
        {
            return Err(format!("the quantiles of `{}` are not in order", p.name));
        }
        Ok(())
    }
}

/// Chain ESS below which a reference mean is flagged: its Monte-Carlo s.e. is then more than a
/// tenth of the posterior s.d.
pub(crate) const MIN_CHAIN_ESS: f64 = 100.0;

/// Acceptance rate below which the chain is flagged as (nearly) stuck.
pub(crate) const MIN_ACCEPTANCE: f64 = 0.02;

/// The reasons a chain's summary is not a trustworthy posterior: a chain that did not move
/// after its burn-in (one point, not a distribution), a nearly stuck one, too few effective
/// samples, failed likelihood estimates.
pub fn chain_warnings(
    acceptance: f64,
    params: &[ParamSummary],
    failed: u64,
    evaluations: u64,
) -> Vec<String> {
    let mut w = Vec::new();
    if acceptance == 0.0 {
        w.push(
            "the chain did not move after the burn-in: its summary is one point, not a posterior \
             (start it elsewhere, e.g. --start-from an online run, or use more particles)"
                .to_string(),
        );
    } else if acceptance < MIN_ACCEPTANCE {
        w.push(format!(
            "acceptance {acceptance:.3} < {MIN_ACCEPTANCE}: the chain is nearly stuck"
        ));
    }
    for p in params
        .iter()
        .filter(|p| p.ess.is_nan() || p.ess < MIN_CHAIN_ESS)
    {
        w.push(format!(
            "{}: chain ESS {:.0} < {MIN_CHAIN_ESS}: the mean carries a Monte-Carlo s.e. of about \
             {:.3} (s.d./√ESS)",
            p.name,
            p.ess,
            p.sd / p.ess.max(1.0).sqrt()
        ));
    }
    if failed > 0 {
        w.push(format!(
            "{failed} of {evaluations} likelihood estimates failed (rejected proposals)"
        ));
    }
    w
}
