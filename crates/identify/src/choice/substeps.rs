//! Sub-steps checked by doubling: the filter's own time step must not move θ by more than a
//! small part of its posterior s.d. (docs/validation.md, "Sub-steps checked by doubling").
//!
//! The filter integrates the building with a semi-implicit step M times per sample, and θ
//! absorbs what that step gets wrong: the stiffnesses its frequency shift, the dampings and
//! stiffnesses its velocity lag (first order in the step). The sub-step rules
//! ([`crate::rules::FIELD_FREQUENCY_ERROR`] and the others) bound the shift of the highest mode
//! of the *prior's* building; they cannot say how that compares with the posterior's width,
//! which shrinks with the record's length and falls with its noise. Measured on the foreign
//! corpus's `in-class` record (the filter's own class, 31 s at 200 Hz, 5 % noise): with the 3
//! sub-steps of the rule k3 = 798.04 with 95 % interval [797.27, 798.81] against the true 800 —
//! the interval misses the truth by 3 of its half-widths —, 799.31 with 6, 799.82 with 12, 800.04
//! with 24, 800.14 with 48; the differences halve with each doubling, as a first-order error's.
//!
//! So on field data of a linear building run as one Gaussian filter (where a run costs little:
//! [`crate::rules::samples_nothing`]), with the sub-steps left to `auto`, a record is identified
//! with the rules' M, then with 2M, 4M, … until a doubling moves every stiffness by at most
//! [`TOLERANCE`] of its posterior s.d. (the run's reported 95 % half-width over 1.96, model error
//! included), or the count reaches [`models::filtering::MAX_SUBSTEPS`]. With a first-order error
//! the bias left at the last count is about the last move, so a 95 % interval keeps at least
//! 94.6 % coverage (Φ(1.96 − 0.25) − Φ(−1.96 − 0.25)). A check that did not converge says so, as
//! a warning. It runs twice: on the part of the record the held-out choice identifies on, with
//! the default candidate, so that every candidate is scored at a count its own step does not
//! bias (`converge_on`, called by the choice), and on the whole record from that count, whose
//! last count the run takes ([`converge`]).
//!
//! The stiffnesses decide; the other parameters' largest move is recorded beside. On the
//! shake-table frame (dashpots + αM: four damping parameters for three modes) c2 sits near its
//! bound and moves by about one s.d. at every doubling up to 64 without settling, while the
//! stiffnesses move by 0.18 s.d. from 8 to 16: a check on c2 would cost the largest count on
//! every run of such a building and converge nowhere.

use models::dataset::LoadedDataset;

use super::run_on;
use crate::error::Result;
use crate::plan::{Decision, Level, Moved, RunPlan, SubstepConvergence, SubstepRun, Target};
use crate::record::RunRecord;
use crate::settings::Substeps;

/// Largest move of a stiffness in one doubling, in posterior s.d., that counts as converged.
pub use crate::rules::SUBSTEP_CHECK_TOLERANCE as TOLERANCE;

/// The 95 % normal quantile: a reported 95 % half-width over it is the s.d.
const Z95: f64 = 1.959963984540054;

/// Whether the check applies to `plan` for `t`: field data (no data set description), sub-steps
/// left to `auto` (by no flag and no config), and a run that samples nothing (one Gaussian
/// filter).
pub(crate) fn applies(plan: &RunPlan, t: &Target) -> Result<bool> {
    Ok(t.data.meta.is_none()
        && plan.settings.substeps == Substeps::Auto
        && crate::rules::samples_nothing(plan.algorithm, &plan.spec(t.data)?))
}

/// θ_val and the s.d. of each parameter as the run reports it (its 95 % interval over 2·1.96,
/// after the spread between the record's parts: [`crate::spread::reported`]).
fn point(plan: &RunPlan, record: &RunRecord) -> (Vec<f64>, Vec<f64>) {
    let credible = crate::spread::reported(
        &record.param_names,
        &record.credible,
        &record.trace,
        plan.holds_bounds(),
    )
    .0;
    let sd = record
        .param_names
        .iter()
        .map(|name| {
            credible
                .iter()
                .find(|p| &p.parameter == name)
                .and_then(|p| p.intervals.iter().find(|i| (i.level - 0.95).abs() < 1e-9))
                .map_or(f64::NAN, |i| (i.hi - i.lo) / (2.0 * Z95))
        })
        .collect();
    (record.theta_val.clone(), sd)
}

/// Whether parameter `name` is a storey stiffness (k1, k2, …): what decides the check.
fn is_stiffness(name: &str) -> bool {
    name.strip_prefix('k')
        .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
}

/// The largest |Δθ_j| / s.d._j of `now` against `before` among the parameters `which` takes,
/// with the parameter (a parameter without a positive finite s.d. or a finite move is left
/// out; none when nothing is left).
fn largest_move(
    names: &[String],
    (before, now): (&[f64], &[f64]),
    sd: &[f64],
    which: &dyn Fn(&str) -> bool,
) -> Option<(f64, String)> {
    let mut best: Option<(f64, String)> = None;
    for ((name, (a, b)), s) in names.iter().zip(before.iter().zip(now)).zip(sd) {
        let moved = (b - a).abs() / s;
        if which(name) && *s > 0.0 && moved.is_finite() && best.as_ref().is_none_or(|b| moved > b.0)
        {
            best = Some((moved, name.clone()));
        }
    }
    best
}

/// `plan` (for `t`, where the check applies) with the sub-steps doubled from its count until
/// θ identified on the whole record no longer moves with them (see the module documentation),
/// with the evidence and a decision; a plan the check does not apply to, or whose count is
/// already the largest, comes back unchanged.
pub fn converge(plan: RunPlan, t: &Target) -> Result<RunPlan> {
    if !applies(&plan, t)? || plan.model.substeps >= models::filtering::MAX_SUBSTEPS {
        return Ok(plan);
    }
    converge_on(plan, t.data, true)
}

/// The check of [`converge`] on `data` — the whole record (`whole`) or the part the held-out
/// choice identifies on, whose candidates then run at the count it found.
pub(crate) fn converge_on(plan: RunPlan, data: &LoadedDataset, whole: bool) -> Result<RunPlan> {
    let max = models::filtering::MAX_SUBSTEPS;
    log::info!(
        "checking the sub-steps on {}: {} per sample, doubled until the stiffnesses stop moving…",
        if whole {
            "the whole record".to_string()
        } else {
            format!("the first {} samples", data.len())
        },
        plan.model.substeps
    );
    let mut check = SubstepConvergence {
        samples: data.len(),
        whole,
        tolerance: TOLERANCE,
        runs: Vec::new(),
        converged: false,
        note: None,
    };
    let mut current = plan.clone();
    loop {
        let record = run_on(&current, data)?;
        if let Some(f) = &record.failure {
            check.note = Some(format!(
                "the run with {} sub-steps failed: {f}",
                current.model.substeps
            ));
            break;
        }
        let (theta, sd) = point(&current, &record);
        let names = &record.param_names;
        let prev = check.runs.last().map(|p| &p.theta_val[..]);
        let moved = prev.and_then(|p| largest_move(names, (p, &theta), &sd, &is_stiffness));
        let other = prev.and_then(|p| largest_move(names, (p, &theta), &sd, &|n| !is_stiffness(n)));
        check.converged = moved.as_ref().is_some_and(|(m, _)| *m <= TOLERANCE);
        check.runs.push(SubstepRun {
            substeps: current.model.substeps,
            theta_val: theta,
            sd,
            moved: moved.map(|(sd, parameter)| Moved { sd, parameter }),
            others_moved: other.map(|(sd, parameter)| Moved { sd, parameter }),
        });
        if check.converged || current.model.substeps >= max {
            break;
        }
        current.model.substeps = (2 * current.model.substeps).min(max);
    }
    let mut out = plan;
    // A failed doubling leaves the last count that ran.
    if let Some(m) = check.substeps() {
        out.model.substeps = m;
    }
    out.decisions.push(Decision {
        rule: "choice::substeps::converge".into(),
        set: format!("substeps = {}", out.model.substeps),
        level: if check.converged {
            Level::Note
        } else {
            Level::Warning
        },
        why: check.describe(),
    });
    out.evidence.substep_checks.push(check);
    Ok(out)
}

/// `to` (the same run settled again: the other damping form, other masses) with what the
/// checks of `from` found: at least its count, and its checks' evidence and decisions.
pub(crate) fn carry(from: &RunPlan, to: &mut RunPlan) {
    to.model.substeps = to.model.substeps.max(from.model.substeps);
    if to.evidence.substep_checks.is_empty() {
        to.evidence.substep_checks = from.evidence.substep_checks.clone();
        to.decisions.extend(
            from.decisions
                .iter()
                .filter(|d| d.rule == "choice::substeps::converge")
                .cloned(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::{is_stiffness, largest_move};

    #[test]
    fn the_largest_move_is_in_posterior_sds_among_the_parameters_asked_for() {
        let names: Vec<String> = ["k1", "k2", "c1"].iter().map(|s| s.to_string()).collect();
        let before = [100.0, 50.0, 1.0];
        let all = |_: &str| true;
        let m = largest_move(
            &names,
            (&before, &[101.0, 50.5, 1.0]),
            &[2.0, 0.25, 0.1],
            &all,
        );
        assert_eq!(m, Some((2.0, "k2".to_string())));
        // A parameter without a positive s.d. does not count.
        let m = largest_move(
            &names,
            (&before, &[101.0, 50.0, 9.0]),
            &[2.0, 0.25, 0.0],
            &all,
        );
        assert_eq!(m, Some((0.5, "k1".to_string())));
        // Only the stiffnesses: c1's larger move is not theirs.
        let now = [100.5, 50.0, 2.0];
        let m = largest_move(&names, (&before, &now), &[1.0, 1.0, 0.1], &is_stiffness);
        assert_eq!(m, Some((0.5, "k1".to_string())));
        let m = largest_move(&names, (&before, &now), &[1.0, 1.0, 0.1], &|n| {
            !is_stiffness(n)
        });
        assert_eq!(m, Some((10.0, "c1".to_string())));
        assert!(largest_move(&names, (&before, &now), &[1.0; 3], &|_| false).is_none());
    }

    #[test]
    fn stiffnesses_are_k_and_a_storey_number() {
        assert!(is_stiffness("k1") && is_stiffness("k12"));
        assert!(!is_stiffness("k") && !is_stiffness("c1") && !is_stiffness("kappa"));
    }
}
