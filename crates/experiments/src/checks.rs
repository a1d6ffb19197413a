//! Plausibility checks of a finished run: the warnings a user must see before trusting θ_val.
//!
//! A particle filter always returns numbers; some of them are nonsense. A run record is checked
//! for
//! - a **physically impossible** answer: a stiffness or damping whose posterior mean is ≤ 0
//!   (SPEC §1: k_i > 0, c_i > 0), or a non-finite θ_val; with the storey+mass damping form
//!   (θ has `alpha`) a dashpot or α is impossible only when < 0, since a storey without a
//!   dashpot is still damped by αM;
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

/// Independent filters pooled in the run (`pool` of its settings; 1 when absent).
pub fn pooled_filters(r: &RunRecord) -> usize {
    r.config
        .get("filter")
        .and_then(|f| f.get("pool"))
        .and_then(|p| p.as_u64())
        .map_or(1, |p| p.max(1) as usize)
}

/// Particles of one filter of the run: the ESS is that of one filter.
fn particles_per_filter(r: &RunRecord) -> usize {
    r.particles / pooled_filters(r)
}

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
    matches!(chars.next(), Some('k' | 'c')) && name.len() > 1 && chars.all(|c| c.is_ascii_digit())
}

/// Whether θ entry `name` = `v` is physically impossible: k_j ≤ 0; c_j ≤ 0 with per-storey
/// damping only, c_j < 0 or α < 0 with the storey+mass form (`mass_form`).
fn impossible(name: &str, v: f64, mass_form: bool) -> bool {
    if name == models::structure::ALPHA_NAME {
        return mass_form && v < 0.0;
    }
    if !is_stiffness_or_damping(name) {
        return false;
    }
    if name.starts_with('k') || !mass_form {
        v <= 0.0
    } else {
        v < 0.0
    }
}

/// The warnings of a finished run, most serious first.
pub fn check(r: &RunRecord) -> Vec<Warning> {
    let mut out = Vec::new();
    // A run that failed before its averaging window has no θ_val at all: one warning says so
    // instead of one per parameter.
    let no_estimate = r.failure.is_some() && r.theta_val.iter().all(|v| v.is_nan());
    if let Some(f) = &r.failure {
        let window_done = (r.steps_completed + r.window).saturating_sub(r.steps_total);
        out.push(Warning {
            kind: WarningKind::Failed,
            parameter: None,
            message: if no_estimate {
                format!(
                    "the run failed after {} of {} steps: {f}; it failed before its averaging \
                     window (the last {} steps), so it gives no θ_val",
                    r.steps_completed, r.steps_total, r.window
                )
            } else {
                format!(
                    "the run failed after {} of {} steps: {f}; θ_val averages only the {} \
                     steps of the averaging window completed before the failure",
                    r.steps_completed,
                    r.steps_total,
                    window_done.min(r.window)
                )
            },
        });
    }
    let mass_form = r
        .param_names
        .iter()
        .any(|n| n == models::structure::ALPHA_NAME);
    for (j, (name, v)) in r.param_names.iter().zip(&r.theta_val).enumerate() {
        let sd = r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN);
        if no_estimate {
            break;
        }
        if !v.is_finite() {
            out.push(Warning {
                kind: WarningKind::NonFinite,
                parameter: Some(name.clone()),
                message: format!("{name}: θ_val is {v}: the filter produced no usable estimate"),
            });
        } else if impossible(name, *v, mass_form) {
            out.push(Warning {
                kind: WarningKind::NonPositive,
                parameter: Some(name.clone()),
                message: format!(
                    "{name}: posterior mean {v:.4} (final s.d. {sd:.3}) is {}, physically impossible for a {}: the model or its priors do not fit these data (check the measurement kind, the priors' scale and the masses)",
                    if name.starts_with('k') || !mass_form { "≤ 0" } else { "< 0" },
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
    let tiny = TINY_ESS_ABS.max(TINY_ESS_FRACTION * particles_per_filter(r) as f64);
    if r.ess_min.is_finite() && r.ess_min < tiny && r.steps_completed > 0 {
        out.push(Warning {
            kind: WarningKind::TinyEss,
            parameter: None,
            message: format!(
                "the effective sample size fell to {:.1} of {} particles (mean {:.1}): at that step the estimate rested on a few particles",
                r.ess_min, particles_per_filter(r), r.ess_mean
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
/// `window` steps, SPEC eq. 26), the central 95 % credible interval of the last step's particle
/// posterior from the record (θ_val ± 1.96 final s.d., marked `*`, for a record without one),
/// and the Monte-Carlo
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
        "parameter", "θ_val", "95% credible interval"
    );
    let mut approximated = false;
    let pool = pooled_filters(r);
    for (j, name) in r.param_names.iter().enumerate() {
        let v = r.theta_val.get(j).copied().unwrap_or(f64::NAN);
        if !v.is_finite() {
            // No estimate (a run that failed before its averaging window): no number at all.
            let _ = writeln!(o, "{name:<name_w$}  {:>12}  {:>27}  no estimate", "–", "–");
            continue;
        }
        // The central 95 % interval of the last step's particle posterior; a record without it
        // (written before intervals were recorded, or a failed run) falls back to ±1.96 s.d.,
        // marked with `*`.
        let interval = match r
            .credible
            .iter()
            .find(|p| &p.parameter == name)
            .and_then(|p| p.at(0.95))
        {
            Some(ci) => format!("[{:.4}, {:.4}]", ci.lo, ci.hi),
            None => {
                approximated = true;
                let sd = r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN);
                format!("*[{:.4}, {:.4}]", v - 1.96 * sd, v + 1.96 * sd)
            }
        };
        let mut reliability = match r.distinct_sampled.get(name) {
            Some(&d) if d < FEW_DISTINCT => {
                format!("sampled, {d} distinct value(s): RESTS ON FEW PARTICLES")
            }
            Some(&d) => format!("sampled, {d} distinct values"),
            None => "marginalised (Gaussian per particle)".to_string(),
        };
        // Pooled filters measure the Monte-Carlo error of θ_val.
        if let Some(se) = r
            .credible
            .iter()
            .find(|p| &p.parameter == name)
            .and_then(|p| p.mc_se)
        {
            let _ = write!(reliability, "; θ_val MC s.e. {se:.4}");
        }
        let _ = writeln!(
            o,
            "{name:<name_w$}  {v:>12.4}  {interval:>27}  {reliability}"
        );
    }
    let _ = writeln!(
        o,
        "ESS over the run: min {:.1}, mean {:.1} of {} particles{}{}. Intervals: central 95 % of \
         the last step's particle posterior (Gaussian mixture for marginalised, weighted sample \
         for sampled parameters){}; {} — their coverage is measured in docs/calibration.md.",
        r.ess_min,
        r.ess_mean,
        particles_per_filter(r),
        if pool > 1 {
            format!(" per filter, {pool} filters pooled")
        } else {
            String::new()
        },
        if r.ess_min < TINY_ESS_ABS.max(TINY_ESS_FRACTION * particles_per_filter(r) as f64) {
            " (TINY)"
        } else {
            ""
        },
        if approximated {
            "; * marks θ_val ± 1.96 s.d. where the record holds no interval"
        } else {
            ""
        },
        if pool > 1 {
            "pooled over the filters, so they include the spread between them"
        } else {
            "one filter's posterior does not include its own Monte-Carlo error"
        }
    );
    for line in crate::residuals::describe(&r.innovation_checks) {
        let _ = writeln!(o, "{line}");
    }
    o
}

/// Measured against predicted accelerations and the normalised one-step prediction errors of a
/// run: the only evidence, without truth, that the model fits the data. Written by
/// [`crate::residuals::Predictor`] into the records of `sysid filter`; `sysid plot` draws it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Residuals {
    /// Time of each kept step (s). Keep every step for the whiteness test: a decimated sequence
    /// tests lags that are multiples of the decimation only.
    #[serde(with = "crate::record::number::vec")]
    pub t: Vec<f64>,
    /// Measured channels, e.g. `a1`, `a2`, `a3`.
    pub channels: Vec<String>,
    /// `measured[k][i]`: measurement of channel i at kept step k.
    #[serde(with = "crate::record::number::vec_vec")]
    pub measured: Vec<Vec<f64>>,
    /// One-step-ahead prediction of the measurement from the posterior means of the previous
    /// step ([`crate::residuals`]).
    #[serde(with = "crate::record::number::vec_vec")]
    pub predicted: Vec<Vec<f64>>,
    /// (y_k − ŷ_k) / √R_ii per channel: uncorrelated in time, with a variance of at least 1
    /// (the predictive variance is at least the noise variance), when the model and its noise
    /// levels are right.
    #[serde(with = "crate::record::number::vec_vec")]
    pub normalised_innovation: Vec<Vec<f64>>,
}

/// Whiteness check of one channel's normalised innovations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Whiteness {
    pub n: usize,
    pub mean: f64,
    pub variance: f64,
    /// Sample autocorrelation at lags 1..=L.
    pub autocorrelation: Vec<f64>,
    /// 1.96/√n: the 95% band of one autocorrelation of a white sequence.
    pub bound: f64,
    /// Ljung–Box statistic Q = n(n+2) Σ ρ_k²/(n−k) over lags 1..=L, and its 95% critical value
    /// (χ²_L quantile, Wilson–Hilferty approximation).
    pub ljung_box: f64,
    pub critical: f64,
}

impl Whiteness {
    /// Whether the sequence passes: Q below its 95% critical value.
    pub fn is_white(&self) -> bool {
        self.ljung_box < self.critical
    }
}

/// 95% quantile of χ² with `dof` degrees of freedom (Wilson–Hilferty; relative error below 1%
/// from 3 degrees of freedom up).
fn chi2_95(dof: usize) -> f64 {
    let k = dof as f64;
    let z = 1.644_853_626_951_472_2;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

/// Whiteness check of a sequence (finite values only) up to `max_lag` lags (fewer when the
/// sequence is short: at most n/4). `None` with fewer than 8 finite values.
pub fn whiteness(x: &[f64], max_lag: usize) -> Option<Whiteness> {
    let v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    let n = v.len();
    if n < 8 {
        return None;
    }
    let lags = max_lag.min(n / 4).max(1);
    let mean = v.iter().sum::<f64>() / n as f64;
    let c0 = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n as f64;
    let rho: Vec<f64> = (1..=lags)
        .map(|k| {
            let ck = (0..n - k)
                .map(|i| (v[i] - mean) * (v[i + k] - mean))
                .sum::<f64>()
                / n as f64;
            if c0 > 0.0 {
                ck / c0
            } else {
                0.0
            }
        })
        .collect();
    let nf = n as f64;
    let q = nf
        * (nf + 2.0)
        * rho
            .iter()
            .enumerate()
            .map(|(k, r)| r * r / (nf - (k + 1) as f64))
            .sum::<f64>();
    Some(Whiteness {
        n,
        mean,
        variance: c0 * nf / (nf - 1.0),
        autocorrelation: rho,
        bound: 1.96 / nf.sqrt(),
        ljung_box: q,
        critical: chi2_95(lags),
    })
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
    fn a_zero_dashpot_is_possible_only_beside_mass_damping() {
        // Per-storey form (SPEC §1): c ≤ 0 is impossible.
        assert!(impossible("c2", 0.0, false));
        assert!(impossible("k1", 0.0, true));
        // With αM a storey without a dashpot is still damped; negative values stay impossible.
        assert!(!impossible("c2", 0.0, true));
        assert!(impossible("c2", -1e-3, true));
        assert!(!impossible("alpha", 0.0, true));
        assert!(impossible("alpha", -0.1, true));
        assert!(!impossible("beta", -0.1, true));
    }

    #[test]
    fn chi_square_quantiles() {
        // Tables: χ²_0.95 with 10 and 20 degrees of freedom.
        assert!((chi2_95(10) - 18.307).abs() < 0.05, "{}", chi2_95(10));
        assert!((chi2_95(20) - 31.410).abs() < 0.05, "{}", chi2_95(20));
    }

    #[test]
    fn white_noise_passes_and_a_random_walk_fails() {
        // SplitMix64 uniforms (fixed seed); sums of 12 give mean 0, variance 1, independent.
        let mut state = 7u64;
        let mut uniform = || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let white: Vec<f64> = (0..2000)
            .map(|_| (0..12).map(|_| uniform()).sum::<f64>() - 6.0)
            .collect();
        let w = whiteness(&white, 20).unwrap();
        assert!(w.is_white(), "Q = {} ≥ {}", w.ljung_box, w.critical);
        assert!(w.mean.abs() < 4.0 / 2000f64.sqrt() && (w.variance - 1.0).abs() < 0.15);
        let mut acc = 0.0;
        let walk: Vec<f64> = white
            .iter()
            .map(|e| {
                acc = 0.9 * acc + e;
                acc
            })
            .collect();
        let w = whiteness(&walk, 20).unwrap();
        assert!(!w.is_white());
        assert!(w.autocorrelation[0] > 0.8);
        assert!(whiteness(&[1.0; 5], 20).is_none());
    }

    #[test]
    fn fatal_kinds() {
        assert!(WarningKind::NonPositive.is_fatal());
        assert!(WarningKind::Failed.is_fatal());
        assert!(!WarningKind::FewDistinct.is_fatal());
        assert!(!WarningKind::TinyEss.is_fatal());
    }
}
