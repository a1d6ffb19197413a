//! Plausibility checks of a finished run: the warnings a user must see before trusting θ_val.
//!
//! A particle filter always returns numbers; some of them are nonsense. A run record is checked
//! for
//! - a **physically impossible** answer: a stiffness or damping whose posterior mean is ≤ 0
//!   (SPEC §1: k_i > 0, c_i > 0), or a non-finite θ_val;
//! - a posterior that **rests on a handful of particles**: a sampled static parameter with few
//!   distinct particle values at the end (resampling a static, noise-free parameter at every step
//!   leaves copies of a few values; its posterior s.d. then says nothing about the real
//!   uncertainty), or a tiny effective sample size;
//! - a **failed** run (the filter stopped early).
//!
//! `sysid filter` prints every warning on stderr, writes them into the record's `warnings`, and
//! exits non-zero when the answer is impossible or the run failed.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::record::RunRecord;

/// A sampled static parameter represented by fewer distinct particle values than this at the
/// end is flagged: its posterior rests on a handful of particles.
pub const FEW_DISTINCT: usize = 10;

/// The ESS is tiny when its minimum over the run falls below this many particles…
pub const TINY_ESS_ABS: f64 = 10.0;
/// …or below this fraction of the particles, whichever is larger.
pub const TINY_ESS_FRACTION: f64 = 0.02;

/// What a warning is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// The run ended early with a numerical failure.
    Failed,
    /// A stiffness or damping with posterior mean ≤ 0.
    NonPositive,
    /// A non-finite θ_val.
    NonFinite,
    /// A sampled static parameter with few distinct values at the end.
    FewDistinct,
    /// A tiny effective sample size.
    TinyEss,
}

impl WarningKind {
    /// Whether the answer is unusable: the command must not exit successfully.
    pub fn is_fatal(self) -> bool {
        matches!(
            self,
            WarningKind::Failed | WarningKind::NonPositive | WarningKind::NonFinite
        )
    }
}

/// One warning, with the parameter it concerns (if any) and the reason in words.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warning {
    pub kind: WarningKind,
    pub parameter: Option<String>,
    pub message: String,
}

/// Whether `name` is a stiffness (`k1`, …) or a damping (`c1`, …) of the shear chain.
fn is_stiffness_or_damping(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some('k' | 'c'))
        && name.len() > 1
        && chars.all(|c| c.is_ascii_digit())
}

/// The warnings of a finished run, most serious first.
pub fn check(r: &RunRecord) -> Vec<Warning> {
    let mut out = Vec::new();
    if let Some(f) = &r.failure {
        out.push(Warning {
            kind: WarningKind::Failed,
            parameter: None,
            message: format!(
                "the run failed after {} of {} steps: {f}; θ_val is the average of the steps before the failure",
                r.steps_completed, r.steps_total
            ),
        });
    }
    for (j, (name, v)) in r.param_names.iter().zip(&r.theta_val).enumerate() {
        let sd = r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN);
        if !v.is_finite() {
            out.push(Warning {
                kind: WarningKind::NonFinite,
                parameter: Some(name.clone()),
                message: format!("{name}: θ_val is {v}: the filter produced no usable estimate"),
            });
        } else if is_stiffness_or_damping(name) && *v <= 0.0 {
            out.push(Warning {
                kind: WarningKind::NonPositive,
                parameter: Some(name.clone()),
                message: format!(
                    "{name}: posterior mean {v:.4} (final s.d. {sd:.3}) is ≤ 0, physically impossible for a {}: the model or its priors do not fit these data (check the measurement kind, the priors' scale and the masses)",
                    if name.starts_with('k') { "stiffness" } else { "damping" }
                ),
            });
        }
    }
    for (name, &d) in &r.distinct_sampled {
        if d < FEW_DISTINCT {
            out.push(Warning {
                kind: WarningKind::FewDistinct,
                parameter: Some(name.clone()),
                message: format!(
                    "{name}: only {d} distinct particle value(s) of {} at the end: its posterior rests on a handful of particles, and its s.d. does not measure its uncertainty",
                    r.particles
                ),
            });
        }
    }
    let tiny = TINY_ESS_ABS.max(TINY_ESS_FRACTION * r.particles as f64);
    if r.ess_min.is_finite() && r.ess_min < tiny && r.steps_completed > 0 {
        out.push(Warning {
            kind: WarningKind::TinyEss,
            parameter: None,
            message: format!(
                "the effective sample size fell to {:.1} of {} particles (mean {:.1}): at that step the estimate rested on a few particles",
                r.ess_min, r.particles, r.ess_mean
            ),
        });
    }
    out
}

/// Whether any warning makes the answer unusable.
pub fn is_fatal(warnings: &[Warning]) -> bool {
    warnings.iter().any(|w| w.kind.is_fatal())
}

/// The terminal summary of a run: per parameter θ_val (posterior mean averaged over the last
/// `window` steps, SPEC eq. 26), an approximate 95% interval θ_val ± 1.96 × the final posterior
/// s.d. (Gaussian approximation, not a calibrated credible interval), and the Monte-Carlo
/// reliability of the estimate: the number of distinct particle values of a sampled parameter
/// (flagged below [`FEW_DISTINCT`]), the ESS for the others.
pub fn summary_table(r: &RunRecord) -> String {
    let mut o = String::new();
    let name_w = r
        .param_names
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(0)
        .max("parameter".len());
    let _ = writeln!(
        o,
        "{:<name_w$}  {:>12}  {:>27}  Monte-Carlo reliability",
        "parameter", "θ_val", "≈95% interval (±1.96 s.d.)"
    );
    for (j, name) in r.param_names.iter().enumerate() {
        let v = r.theta_val.get(j).copied().unwrap_or(f64::NAN);
        let sd = r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN);
        let interval = format!("[{:.4}, {:.4}]", v - 1.96 * sd, v + 1.96 * sd);
        let reliability = match r.distinct_sampled.get(name) {
            Some(&d) if d < FEW_DISTINCT => {
                format!("sampled, {d} distinct value(s): RESTS ON FEW PARTICLES")
            }
            Some(&d) => format!("sampled, {d} distinct values"),
            None => "marginalised (Gaussian per particle)".to_string(),
        };
        let _ = writeln!(
            o,
            "{name:<name_w$}  {v:>12.4}  {interval:>27}  {reliability}"
        );
    }
    let _ = writeln!(
        o,
        "ESS over the run: min {:.1}, mean {:.1} of {} particles{}. Intervals: Gaussian approximation from the final posterior s.d., not checked for calibration.",
        r.ess_min,
        r.ess_mean,
        r.particles,
        if r.ess_min < TINY_ESS_ABS.max(TINY_ESS_FRACTION * r.particles as f64) {
            " (TINY)"
        } else {
            ""
        }
    );
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stiffness_and_damping_names() {
        assert!(is_stiffness_or_damping("k1"));
        assert!(is_stiffness_or_damping("c12"));
        assert!(!is_stiffness_or_damping("c"));
        assert!(!is_stiffness_or_damping("cx"));
        assert!(!is_stiffness_or_damping("beta"));
    }

    #[test]
    fn fatal_kinds() {
        assert!(WarningKind::NonPositive.is_fatal());
        assert!(WarningKind::Failed.is_fatal());
        assert!(!WarningKind::FewDistinct.is_fatal());
        assert!(!WarningKind::TinyEss.is_fatal());
    }
}
