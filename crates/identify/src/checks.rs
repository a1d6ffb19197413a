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
//! - a **failed** run (the filter stopped early), or filters of a pool **left out** of its
//!   answer because they failed or lost track of the record (module `pool`);
//! - a parameter **held at its physical bound**: with the physical support on, a stiffness,
//!   damping or α whose Gaussian the data pushed below zero is truncated there, and its answer
//!   sits at a small fraction (`AT_BOUND_FRACTION`) of its prior mean — physical, but the
//!   model (masses, damping form, storeys) likely does not fit these data.
//!
//! `sysid filter` prints every warning on stderr, writes them into the record's `warnings`, and
//! exits non-zero when the answer is impossible or the run failed.

use std::fmt::Write as _;

pub use crate::record::diagnostics::{Residuals, Warning, WarningKind};
use crate::record::RunRecord;

/// A truncated parameter whose θ_val is below this fraction of its prior mean is flagged as held
/// at its bound.
pub(crate) const AT_BOUND_FRACTION: f64 = 0.01;

/// The prior means of θ from the record's `config.spec.prior` (none for a record without one).
fn prior_means(r: &RunRecord) -> Option<Vec<f64>> {
    let prior = r.config.get("spec")?.get("prior")?.clone();
    let prior: models::filtering::ChainPrior = serde_json::from_value(prior).ok()?;
    Some(prior.moments().0)
}

/// A sampled static parameter represented by fewer distinct particle values than this at the
/// end is flagged: its posterior rests on a handful of particles.
pub(crate) const FEW_DISTINCT: usize = 10;

/// The ESS is tiny when its minimum over the run falls below this many particles…
pub(crate) const TINY_ESS_ABS: f64 = 10.0;
/// …or below this fraction of the particles, whichever is larger.
pub(crate) const TINY_ESS_FRACTION: f64 = 0.02;

/// Independent filters pooled in the run (`pool` of its settings; 1 when absent).
pub(crate) fn pooled_filters(r: &RunRecord) -> usize {
    r.config
        .get("filter")
        .and_then(|f| f.get("pool"))
        .and_then(|p| p.as_u64())
        .map_or(1, |p| p.max(1) as usize)
}

/// Whether θ entry `name` was fixed by the run's settings (`[fix]`, `--fix`): a point-mass prior,
/// whose single particle value is the user's choice, not a collapse of the filter.
fn is_fixed(r: &RunRecord, name: &str) -> bool {
    r.config
        .get("filter")
        .and_then(|f| f.get("fix"))
        .and_then(|f| f.get(name))
        .is_some()
}

/// Particles of one filter of the run: the ESS is that of one filter.
fn particles_per_filter(r: &RunRecord) -> usize {
    r.particles / pooled_filters(r)
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
        out.push(failure_warning(r, f, no_estimate));
    }
    left_out_warnings(r, &mut out);
    impossible_value_warnings(r, no_estimate, &mut out);
    if r.health.truncated > 0 && !no_estimate {
        at_bound_warnings(r, &mut out);
    }
    few_distinct_warnings(r, &mut out);
    let tiny = TINY_ESS_ABS.max(TINY_ESS_FRACTION * particles_per_filter(r) as f64);
    // One Gaussian filter has one particle, whose ESS of 1 says nothing.
    if r.ess_min.is_finite() && r.ess_min < tiny && r.steps_completed > 0 && !r.one_gaussian_filter
    {
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

/// The warning of a failed run (failure `f`): how far it came, and how much of the averaging
/// window θ_val rests on (none: `no_estimate`).
fn failure_warning(r: &RunRecord, f: &str, no_estimate: bool) -> Warning {
    let window_done = (r.steps_completed + r.window).saturating_sub(r.steps_total);
    Warning {
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
    }
}

/// One warning per filter of the pool left out of the answer, with why and how many filters
/// the answer rests on.
fn left_out_warnings(r: &RunRecord, out: &mut Vec<Warning>) {
    let pool = pooled_filters(r);
    for l in &r.pool_left_out {
        out.push(Warning {
            kind: WarningKind::LeftOut,
            parameter: None,
            message: format!(
                "filter {} of the pool's {pool} was left out of the answer ({}): {}; the answer \
                 rests on {} filters",
                l.filter,
                match l.reason {
                    crate::record::diagnostics::LeftOutReason::Failed => "it failed",
                    crate::record::diagnostics::LeftOutReason::Lost =>
                        "it lost track of the record",
                },
                l.message,
                pool.saturating_sub(r.pool_left_out.len())
            ),
        });
    }
}

/// The parameters whose θ_val is not finite or physically impossible (none when the run gave
/// `no_estimate`).
fn impossible_value_warnings(r: &RunRecord, no_estimate: bool, out: &mut Vec<Warning>) {
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
}

/// The bounded parameters (stiffness, damping, α) of a run whose values were truncated at 0
/// that θ_val holds at the bound: far below their prior mean.
fn at_bound_warnings(r: &RunRecord, out: &mut Vec<Warning>) {
    let means = prior_means(r).unwrap_or_default();
    for (j, (name, v)) in r.param_names.iter().zip(&r.theta_val).enumerate() {
        let bounded = is_stiffness_or_damping(name) || name == models::structure::ALPHA_NAME;
        let Some(&m) = means.get(j) else { continue };
        if bounded && v.is_finite() && *v >= 0.0 && m > 0.0 && *v < AT_BOUND_FRACTION * m {
            out.push(Warning {
                kind: WarningKind::AtBound,
                parameter: Some(name.clone()),
                message: format!(
                    "{name}: θ_val {v:.4} is held at its physical bound 0 ({:.2} % of its prior mean {m:.4}): the data pushed it below zero, so the model (masses, damping form, storeys) likely does not fit these data",
                    100.0 * v / m
                ),
            });
        }
    }
}

/// The sampled parameters (not fixed) whose posterior rests on few distinct particle values.
fn few_distinct_warnings(r: &RunRecord, out: &mut Vec<Warning>) {
    for (name, &d) in &r.distinct_sampled {
        if d < FEW_DISTINCT && !is_fixed(r, name) {
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
/// (flagged below `FEW_DISTINCT`), the ESS for the others.
pub fn summary_table(r: &RunRecord) -> String {
    let mut o = String::new();
    let name_w = r
        .param_names
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(0)
        .max("parameter".len());
    // Simulated data: the true values beside the answer, and whether the interval holds them.
    let truth = r
        .theta_true
        .as_ref()
        .filter(|t| t.len() == r.param_names.len());
    let _ = writeln!(
        o,
        "{:<name_w$}  {:>12}  {:>27}  {}Monte-Carlo reliability",
        "parameter",
        "θ_val",
        "95% credible interval",
        if truth.is_some() {
            format!("{:>12}  ", "true θ")
        } else {
            String::new()
        }
    );
    let mut approximated = false;
    let pool = pooled_filters(r);
    for (j, name) in r.param_names.iter().enumerate() {
        approximated |= write_parameter_row(&mut o, r, j, name, name_w, truth.map(Vec::as_slice));
    }
    let reliability = if r.one_gaussian_filter {
        "One Gaussian filter (EKF2): the building has no hysteretic element and the prior is one \
         Gaussian, so nothing is sampled and there is no Monte-Carlo error. Intervals: central \
         95 % of the last step's Gaussian posterior."
            .to_string()
    } else {
        ess_line(r, pool, approximated)
    };
    let _ = writeln!(o, "{reliability}");
    if truth.is_some() {
        let _ = writeln!(
            o,
            "true θ: the values the data were simulated with (✗: outside the 95 % interval)."
        );
    }
    if let Some(s) = &r.segment_spread {
        let _ = writeln!(o, "{}", crate::spread::describe(s));
    }
    for line in crate::residuals::describe(&r.innovation_checks) {
        let _ = writeln!(o, "{line}");
    }
    o
}

/// The summary's row of parameter `j` (`name`, its column `name_w` wide): θ_val, its 95 %
/// interval, the true value when the data know it (`truth`) and its Monte-Carlo reliability.
/// Returns whether the interval is the ±1.96 s.d. stand-in for one the record lacks.
fn write_parameter_row(
    o: &mut String,
    r: &RunRecord,
    j: usize,
    name: &str,
    name_w: usize,
    truth: Option<&[f64]>,
) -> bool {
    let v = r.theta_val.get(j).copied().unwrap_or(f64::NAN);
    if !v.is_finite() {
        // No estimate (a run that failed before its averaging window): no number at all.
        let _ = writeln!(o, "{name:<name_w$}  {:>12}  {:>27}  no estimate", "–", "–");
        return false;
    }
    // The central 95 % interval of the last step's particle posterior; a record without it
    // (written before intervals were recorded, or a failed run) falls back to ±1.96 s.d.,
    // marked with `*`.
    let mut approximated = false;
    let interval = match r
        .credible
        .iter()
        .find(|p| p.parameter == name)
        .and_then(|p| p.at(0.95))
    {
        Some(ci) => format!("[{:.4}, {:.4}]", ci.lo, ci.hi),
        None => {
            approximated = true;
            let sd = r.theta_sd_final.get(j).copied().unwrap_or(f64::NAN);
            format!("*[{:.4}, {:.4}]", v - 1.96 * sd, v + 1.96 * sd)
        }
    };
    if is_fixed(r, name) {
        let _ = writeln!(
            o,
            "{name:<name_w$}  {v:>12.4}  {:>27}  fixed (point-mass prior)",
            "–"
        );
        return approximated;
    }
    let reliability = reliability_cell(r, name);
    let true_cell = match truth {
        Some(t) => {
            let inside = r
                .credible
                .iter()
                .find(|p| p.parameter == name)
                .and_then(|p| p.at(0.95))
                .map(|ci| ci.lo <= t[j] && t[j] <= ci.hi);
            format!(
                "{:>12}  ",
                format!(
                    "{:.4}{}",
                    t[j],
                    if inside == Some(false) { " ✗" } else { "" }
                )
            )
        }
        None => String::new(),
    };
    let _ = writeln!(
        o,
        "{name:<name_w$}  {v:>12.4}  {interval:>27}  {true_cell}{reliability}"
    );
    approximated
}

/// How reliable parameter `name`'s estimate is as Monte-Carlo: its distinct particle values
/// when sampled (flagged when few), or how it is carried, and the pool's Monte-Carlo s.e.
fn reliability_cell(r: &RunRecord, name: &str) -> String {
    let mut reliability = match r.distinct_sampled.get(name) {
        Some(&d) if d < FEW_DISTINCT => {
            format!("sampled, {d} distinct value(s): RESTS ON FEW PARTICLES")
        }
        Some(&d) => format!("sampled, {d} distinct values"),
        None if r.one_gaussian_filter => "Gaussian (one EKF2: nothing sampled)".to_string(),
        None => "marginalised (Gaussian per particle)".to_string(),
    };
    // Pooled filters measure the Monte-Carlo error of θ_val.
    if let Some(se) = r
        .credible
        .iter()
        .find(|p| p.parameter == name)
        .and_then(|p| p.mc_se)
    {
        let _ = write!(reliability, "; θ_val MC s.e. {se:.4}");
    }
    reliability
}

/// The line on the particles behind the answer: the ESS over the run (per filter of a pool),
/// flagged when tiny, and what the intervals are.
fn ess_line(r: &RunRecord, pool: usize, approximated: bool) -> String {
    format!(
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
    )
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
    fn fatal_kinds() {
        assert!(WarningKind::NonPositive.is_fatal());
        assert!(WarningKind::Failed.is_fatal());
        assert!(!WarningKind::FewDistinct.is_fatal());
        assert!(!WarningKind::TinyEss.is_fatal());
    }
}
