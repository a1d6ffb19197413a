//! Model error in the intervals: the spread of θ between the parts of the record (issue
//! "unseen structures": model error must widen the intervals, not bend the parameters;
//! docs/validation.md, "Intervals that include model error").
//!
//! A filter's posterior is conditional on its model. Where the model is wrong, every sample
//! still counts as independent evidence, and the intervals shrink as if it were right: on the
//! shake-table frame the stiffnesses' 95 % intervals are ±0.2 % wide, while the same model
//! identified on another record of the frame lands 3–14 % away (`results/real/REPORT.md`: 8 of
//! 84 (parameter, pair) cases inside each other's intervals).
//!
//! What each part of the record says of θ on its own is read off the run's trace, without
//! running again: for a Gaussian posterior, information adds, so the part between trace points a
//! and b alone has precision λ = 1/v_b − 1/v_a and mean (m_b/v_b − m_a/v_a)/λ — per parameter,
//! because the trace keeps no correlations (exact for uncorrelated parameters, an approximation
//! otherwise). The run is cut into `SEGMENTS` parts of equal duration; a part that added no
//! information (λ ≤ 0) is left out. Where the model fits the record the parts agree within their
//! own s.d.s; where it does not they scatter. The test: Cochran's Q = Σ w_s (m_s − m̄)², w = 1/v_s,
//! above the 95 % quantile of χ²_{S−1} (agreeing parts exceed it 5 % of the time). Where it
//! says the parts disagree, their between-part variance τ² is the variance model error adds —
//! the Paule–Mandel estimate, the τ² at which the parts' random-effects Q, Σ (m_s − μ̂)²/(v_s + τ²),
//! equals its expectation S − 1. What the interval is asked to hold is θ where the record's
//! conditions differ, as on another record: the prediction interval of a new part (Higgins,
//! Thompson & Spiegelhalter 2009), whose model-error term is t_{S−2}·τ — Student's t with S − 2
//! degrees of freedom, since τ itself rests on S parts. Every credible interval of the parameter
//! is widened in quadrature by that term on each side (t at the level's quantile), and held at 0
//! for a parameter held to k, c, α ≥ 0. The filter's own intervals stay in the record beside
//! them.
//!
//! Why these two and not DerSimonian–Laird's moment estimate with the normal quantile (the first
//! version): with parts of very unequal precision — the strong shaking informs one or two parts
//! far more than the rest — DL's τ² is weighted by the parts' own precision and follows the
//! precise ones, and with 3–8 parts the normal quantile ignores that τ is itself a rough
//! estimate; both are the meta-analysis literature's known faults of DL (Veroniki et al. 2016
//! recommend Paule–Mandel). Chosen on the shake-table frame's four records (the selected model's
//! θ_val of one record inside another's 95 % interval: 29 → 46 of 84 (parameter, pair) cases),
//! judged on the unseen structures' (stiff one-storey frame 38 → 41 of 60, Meloland 5 → 7 of
//! 12, Capistrano 8 → 8 of 24) — docs/validation.md.
//!
//! Only for a marginalised parameter (a Gaussian or a mixture of Gaussians per particle): a
//! sampled one (Bouc–Wen's n) keeps its intervals.

use core_filters::credible::CredibleInterval;
use statrs::distribution::{ContinuousCDF, StudentsT};

use crate::observe::{ParamIntervals, PosteriorShape, Trace};
pub use crate::record::diagnostics::{ParamSpread, SegmentSpread};

/// Parts of the record.
pub(crate) const SEGMENTS: usize = 8;

/// Fewest parts with information a parameter needs for τ² (below: not widened).
pub(crate) const MIN_PARTS: usize = 3;

/// Whether parameter `name` is one the physical support holds ≥ 0 (k_j, c_j, α).
pub(crate) fn physically_bounded(name: &str) -> bool {
    let indexed = |p: &str| {
        name.strip_prefix(p)
            .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
    };
    indexed("k") || indexed("c") || name == "alpha"
}

/// The intervals a run on field data reports: the filter's own `credible`, widened by the spread
/// of θ between the record's parts where they disagree ([`spread`]; held at 0 for a parameter
/// the physical support holds ≥ 0 when `held`), with that spread (none where the trace is too
/// short to cut into parts).
pub(crate) fn reported(
    names: &[String],
    credible: &[ParamIntervals],
    trace: &Trace,
    held: bool,
) -> (Vec<ParamIntervals>, Option<SegmentSpread>) {
    let bounded = |name: &str| held && physically_bounded(name);
    match spread(names, credible, trace, &bounded) {
        Some((s, widened)) => (widened, Some(s)),
        None => (credible.to_vec(), None),
    }
}

/// What each part of the trace says of parameter `j` alone: (mean, variance) per part with
/// information.
pub(crate) fn parts(trace: &Trace, j: usize, segments: usize) -> Vec<(f64, f64)> {
    let n = trace.param_mean.len();
    if n < 2 || segments == 0 {
        return Vec::new();
    }
    let at = |i: usize| {
        let m = trace.param_mean[i].get(j).copied().unwrap_or(f64::NAN);
        let s = trace.param_sd[i].get(j).copied().unwrap_or(f64::NAN);
        (m, s * s)
    };
    let bounds: Vec<usize> = (0..=segments)
        .map(|s| ((s * (n - 1)) as f64 / segments as f64).round() as usize)
        .collect();
    bounds
        .windows(2)
        .filter(|w| w[1] > w[0])
        .filter_map(|w| {
            let ((ma, va), (mb, vb)) = (at(w[0]), at(w[1]));
            if !(va > 0.0 && vb > 0.0 && ma.is_finite() && mb.is_finite()) {
                return None;
            }
            let lambda = 1.0 / vb - 1.0 / va;
            // A part that added (almost) nothing: its own estimate is undefined.
            if lambda.is_nan() || lambda <= 1e-12 / vb {
                return None;
            }
            let mean = (mb / vb - ma / va) / lambda;
            mean.is_finite().then_some((mean, 1.0 / lambda))
        })
        .collect()
}

/// Cochran's Q = Σ w_s (m_s − m̄)² of estimates (mean, variance) with a between-part variance
/// `tau2` added to each, w = 1/(variance + τ²), m̄ their w-weighted mean (τ² = 0: the test's Q).
fn cochran_q(parts: &[(f64, f64)], tau2: f64) -> f64 {
    let w = |p: &(f64, f64)| 1.0 / (p.1 + tau2);
    let sw: f64 = parts.iter().map(w).sum();
    let mean = parts.iter().map(|p| w(p) * p.0).sum::<f64>() / sw;
    parts.iter().map(|p| w(p) * (p.0 - mean).powi(2)).sum()
}

/// The test that decides whether the parts disagree: Cochran's Q above the 95 % quantile of
/// χ² with S − 1 degrees of freedom (what agreeing parts give 5 % of the time).
pub(crate) fn heterogeneous(parts: &[(f64, f64)]) -> bool {
    parts.len() >= 2 && cochran_q(parts, 0.0) > crate::residuals::chi2_95(parts.len() - 1)
}

/// The Paule–Mandel between-part variance τ² of estimates (mean, variance): the root of
/// Q(τ²) = S − 1, 0 where Q(0) ≤ S − 1. Q(τ²) falls monotonically from Q(0) to 0, so the root
/// is bracketed by doubling and found by bisection — to a relative 1e-12 in at most about 100
/// halvings (a dozen lines; no root finder of the workspace's dependencies).
pub(crate) fn between_variance(parts: &[(f64, f64)]) -> f64 {
    let s = parts.len();
    let target = s.saturating_sub(1) as f64;
    if s < 2 || cochran_q(parts, 0.0) <= target {
        return 0.0;
    }
    let excess = |t2: f64| cochran_q(parts, t2) - target;
    // Start the bracket at the parts' own scale: the spread of their means.
    let (lo_m, hi_m) = parts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
    let (mut lo, mut hi) = (0.0, (hi_m - lo_m).powi(2).max(f64::MIN_POSITIVE));
    while excess(hi) > 0.0 {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return f64::NAN;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if excess(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// The quantile that multiplies τ in a central `level` interval of a new part among `parts`
/// informative ones: Student's t with `parts − 2` degrees of freedom (Higgins, Thompson &
/// Spiegelhalter 2009); NaN below 3 parts.
pub(crate) fn t_of(level: f64, parts: usize) -> f64 {
    if parts < 3 {
        return f64::NAN;
    }
    StudentsT::new(0.0, 1.0, (parts - 2) as f64)
        .map_or(f64::NAN, |t| t.inverse_cdf(0.5 * (1.0 + level)))
}

/// `p` widened by τ of `parts` informative parts: each level's interval about `centre` (the
/// last step's posterior mean), each side in quadrature with t·τ ([`t_of`]), held at 0 when
/// `bounded`.
pub(crate) fn widen(
    p: &ParamIntervals,
    centre: f64,
    tau: f64,
    parts: usize,
    bounded: bool,
) -> ParamIntervals {
    let mut out = p.clone();
    out.intervals = p
        .intervals
        .iter()
        .map(|ci| {
            let term = t_of(ci.level, parts) * tau;
            let mut lo = centre - (centre - ci.lo).max(0.0).hypot(term);
            let hi = centre + (ci.hi - centre).max(0.0).hypot(term);
            if bounded {
                lo = lo.max(0.0);
            }
            CredibleInterval {
                level: ci.level,
                lo: lo.min(ci.lo),
                hi: hi.max(ci.hi),
            }
        })
        .collect();
    out
}

/// The spread of every marginalised parameter between the parts of the run's `trace`, and its
/// credible intervals widened by it; `bounded(name)` says whether a parameter is held ≥ 0.
/// `None` when the trace is too short to cut.
pub(crate) fn spread(
    names: &[String],
    credible: &[ParamIntervals],
    trace: &Trace,
    bounded: &dyn Fn(&str) -> bool,
) -> Option<(SegmentSpread, Vec<ParamIntervals>)> {
    if trace.param_mean.len() < 2 * SEGMENTS {
        return None;
    }
    let last = trace.param_mean.last()?;
    let mut parameters = Vec::new();
    let mut widened = Vec::with_capacity(credible.len());
    for p in credible {
        let Some(j) = names.iter().position(|n| n == &p.parameter) else {
            widened.push(p.clone());
            continue;
        };
        if p.shape != PosteriorShape::GaussianMixture || p.error.is_some() {
            widened.push(p.clone());
            continue;
        }
        let parts = parts(trace, j, SEGMENTS);
        let tau = (parts.len() >= MIN_PARTS).then(|| {
            if heterogeneous(&parts) {
                between_variance(&parts).sqrt()
            } else {
                0.0
            }
        });
        widened.push(match tau {
            Some(t) if t > 0.0 => widen(p, last[j], t, parts.len(), bounded(&p.parameter)),
            _ => p.clone(),
        });
        parameters.push(ParamSpread {
            parameter: p.parameter.clone(),
            part_mean: parts.iter().map(|x| x.0).collect(),
            part_sd: parts.iter().map(|x| x.1.sqrt()).collect(),
            tau,
        });
    }
    Some((
        SegmentSpread {
            segments: SEGMENTS,
            parameters,
            filter_credible: credible.to_vec(),
        },
        widened,
    ))
}

/// The summary's line on the spread.
pub(crate) fn describe(s: &SegmentSpread) -> String {
    let widened: Vec<String> = s
        .parameters
        .iter()
        .filter(|p| p.tau.is_some_and(|t| t > 0.0))
        .map(|p| p.parameter.clone())
        .collect();
    let untested = s.parameters.iter().filter(|p| p.tau.is_none()).count();
    let mut line = if widened.is_empty() {
        format!(
            "Model error: the record's {} parts agree on every parameter tested (Cochran's Q, 5 %): \
             the intervals are the filter's own",
            s.segments
        )
    } else {
        format!(
            "Model error: the record's {} parts disagree on {} (Cochran's Q, 5 %), so their \
             intervals include the spread between the parts (Paule–Mandel's τ, times Student's \
             t as for a part not seen) and a band on another record draws θ shifted by it; the \
             filter's own intervals are in the record (segment_spread) — docs/validation.md",
            s.segments,
            widened.join(", ")
        )
    };
    if untested > 0 {
        line.push_str(&format!(
            "; {untested} parameter(s) gained information in fewer than {MIN_PARTS} parts and were not tested"
        ));
    }
    line.push('.');
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trace of one parameter whose parts say `means` with precision `info` each, starting
    /// from a prior N(0, 100²) (each part two trace points).
    fn trace_of(means: &[f64], info: f64) -> Trace {
        let (mut prec, mut eta) = (1e-4, 0.0);
        let mut t = Trace {
            every: 1,
            t: vec![0.0],
            param_mean: vec![vec![0.0]],
            param_sd: vec![vec![100.0]],
            ess: vec![1.0],
        };
        for (i, m) in means.iter().enumerate() {
            for half in 0..2 {
                prec += info / 2.0;
                eta += info / 2.0 * m;
                t.t.push((2 * i + half + 1) as f64);
                t.param_mean.push(vec![eta / prec]);
                t.param_sd.push(vec![prec.sqrt().recip()]);
                t.ess.push(1.0);
            }
        }
        t
    }

    #[test]
    fn each_part_is_read_back_from_the_accumulated_posterior() {
        let means = [1.0, 2.0, -1.0, 4.0, 0.5, 3.0, 2.0, 1.5];
        let t = trace_of(&means, 25.0);
        let p = parts(&t, 0, 8);
        assert_eq!(p.len(), 8);
        // The first part includes the prior's tiny information: its mean is pulled by 1e-4/25.
        for (k, ((m, v), want)) in p.iter().zip(means).enumerate() {
            let tol = if k == 0 { 1e-4 } else { 1e-9 };
            assert!((m - want).abs() < tol, "part {k}: {m} vs {want}");
            assert!((v - 1.0 / 25.0).abs() < 1e-9 * (k + 1) as f64, "{v}");
        }
    }

    #[test]
    fn agreeing_parts_add_nothing_and_scattered_ones_their_spread() {
        // Parts within their own s.d. (0.2): Q below its degrees of freedom, τ² = 0.
        let agree: Vec<(f64, f64)> = [0.1, -0.1, 0.05, -0.05]
            .iter()
            .map(|m| (*m, 0.04))
            .collect();
        assert_eq!(between_variance(&agree), 0.0);
        assert!(!heterogeneous(&agree));
        // Q = 9 on 3 degrees of freedom: above 7.81, the 95 % quantile.
        let apart: Vec<(f64, f64)> = [0.3, -0.3, 0.3, -0.3].iter().map(|m| (*m, 0.04)).collect();
        assert!(heterogeneous(&apart));
        assert!((between_variance(&apart) - (9.0 - 3.0) / (100.0 - 2500.0 / 100.0)).abs() < 1e-12);
        // Means 0, 2, 0, 2 with a negligible own variance: τ² → their variance, 4/3 (unbiased).
        let scatter: Vec<(f64, f64)> = [0.0, 2.0, 0.0, 2.0].iter().map(|m| (*m, 1e-8)).collect();
        assert!((between_variance(&scatter) - 4.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn the_between_part_variance_makes_the_random_effects_q_its_expectation() {
        // Unequal precision: one precise part among three vague ones that scatter. Paule–Mandel's
        // τ² solves Σ (m − μ̂)²/(v + τ²) = S − 1 exactly (9.9199, by an independent root
        // finder); DerSimonian–Laird's moment estimate, (Q − (S − 1))/(Σw − Σw²/Σw) =
        // (12.0263 − 3)/(4.75 − 16.1875/4.75) = 6.73, follows the precise part's weight.
        let parts = [(0.0, 0.25), (4.0, 4.0), (-3.0, 4.0), (5.0, 4.0)];
        assert!((cochran_q(&parts, 0.0) - 12.026_315_789_473_685).abs() < 1e-12);
        let t2 = between_variance(&parts);
        assert!((cochran_q(&parts, t2) - 3.0).abs() < 1e-9, "τ² = {t2}");
        assert!((t2 - 9.919_876_768_266_546).abs() < 1e-8, "τ² = {t2}");
        assert!(heterogeneous(&parts));
    }

    #[test]
    fn a_new_parts_quantile_is_students_t_on_two_fewer_degrees_of_freedom() {
        // Tables: t_{0.975} on 1, 4 and 6 degrees of freedom; t_{0.95} on 6.
        assert!((t_of(0.95, 3) - 12.706_204_736).abs() < 1e-6);
        assert!((t_of(0.95, 6) - 2.776_445_105).abs() < 1e-6);
        assert!((t_of(0.95, 8) - 2.446_911_851).abs() < 1e-6);
        assert!((t_of(0.9, 8) - 1.943_180_281).abs() < 1e-6);
        assert!(t_of(0.95, 2).is_nan());
    }

    #[test]
    fn widening_is_in_quadrature_and_held_at_the_bound() {
        let p = ParamIntervals {
            parameter: "c1".into(),
            shape: PosteriorShape::GaussianMixture,
            intervals: vec![CredibleInterval {
                level: 0.95,
                lo: 0.9,
                hi: 1.2,
            }],
            error: None,
            mc_se: None,
        };
        // Eight parts: τ enters with Student's t on 6 degrees of freedom (2.447 at 97.5 %).
        let w = widen(&p, 1.0, 1.0, 8, true);
        let t6 = 2.446_911_851_144_965;
        assert!((w.intervals[0].hi - (1.0 + 0.2f64.hypot(t6))).abs() < 1e-9);
        assert_eq!(w.intervals[0].lo, 0.0);
        let u = widen(&p, 1.0, 1.0, 8, false);
        assert!((u.intervals[0].lo - (1.0 - 0.1f64.hypot(t6))).abs() < 1e-9);
        assert_eq!(widen(&p, 1.0, 0.0, 8, true).intervals, p.intervals);
    }
}
