//! Mass ratios identified from the data, where the data inform them.
//!
//! Accelerations alone fix a building's stiffness and damping only per unit mass, so the first
//! storey's mass stays the one stated and sets the scale; the ratios of the others to it are
//! fixed by the mode shapes, which a sensor on every storey sees. The masses a user states are
//! approximate (a floor's furniture, an actuator's share of the table), and a wrong ratio moves
//! the upper modes: on the shake-table frame (`docs/real-frame.md`) the stated 1 : 1 : 1.2 gives
//! the EKF2 a log-likelihood of −8718 on the whole record and 1 : 1 : 1.4 gives −7513.
//!
//! So after the held-out choice ([`crate::choice`]) has chosen the noise levels and the damping
//! form, the ratios m_j/m_1 (j ≥ 2) are moved to maximise the chosen filter's log-likelihood of
//! the part of the record it identifies on — a compass search on ln(m_j / stated m_j), from
//! steps of `FIRST_STEP` halved `HALVINGS` times, at most a factor `MAX_FACTOR` from the
//! stated masses — and the held-out part decides: the identified masses are taken only when
//! their free run, with the discrepancy term chosen for it, predicts every channel of it better
//! than the stated ones' with theirs (a better building can leave less for the term to explain;
//! masses that trade one floor for another fit something else). The plan records both, with the
//! evidence ([`MassChoice`]).
//!
//! The search's answer is a maximum-likelihood point, not a posterior: the likelihood's
//! curvature leaves out the model's error (as the modal intervals do), so no interval is claimed
//! for the masses.

use models::dataset::LoadedDataset;

use super::search::Compass;
use super::{score, Scored};
use crate::error::Result;
use crate::field::StructureSettings;
use crate::plan::{MassChoice, RunPlan, Target};
use crate::settings::FilterSettings;

/// First step of the search in ln(m_j / stated m_j): ±22 %.
const FIRST_STEP: f64 = 0.2;

/// Times the step is halved once no move gains (the last step 1.25 %).
const HALVINGS: usize = 4;

/// Farthest the search moves a mass from the stated one, as a factor either way: the stated
/// masses are approximate, not unknown.
const MAX_FACTOR: f64 = 2.0;

/// Most filter runs the search may take (a safeguard; the frame's search takes about 40).
const MAX_EVALUATIONS: usize = 400;

/// Why the masses of `plan` (two storeys or more) cannot be identified from `data`, if they
/// cannot: a storey without a sensor leaves the mode shapes, which fix the ratios, unseen.
pub(crate) fn not_informed(plan: &RunPlan, data: &LoadedDataset) -> Option<String> {
    let unmeasured: Vec<usize> = (1..=plan.building.storeys)
        .filter(|s| !data.sensors.contains(s))
        .collect();
    (!unmeasured.is_empty()).then(|| {
        format!(
            "masses as stated: storeys {unmeasured:?} have no sensor, so the mode shapes that fix the mass ratios are not seen"
        )
    })
}

/// `plan` settled again for `t` with `masses` (its damping form and noise levels kept).
fn with_masses(
    plan: &RunPlan,
    t: &Target,
    settings: &FilterSettings,
    masses: &[f64],
) -> Result<RunPlan> {
    let flags = StructureSettings {
        masses: Some(masses.to_vec()),
        damping: Some(plan.building.damping),
        ..t.flags.clone()
    };
    let target = Target {
        flags: &flags,
        ..*t
    };
    let mut settled = crate::plan::settle(target.request(
        settings.clone(),
        plan.seed,
        plan.run,
        &plan.experiment,
    ))?;
    // What the sub-step check found stays (the rules' count may differ with the masses).
    super::substeps::carry(plan, &mut settled);
    Ok(super::with_noise(
        &settled,
        plan.settings.noise_fraction,
        plan.settings.process_noise_factor,
    ))
}

/// The log-likelihood of `ident` under `plan`'s filter; `None` when the settling or the run
/// failed.
fn loglik(plan: Result<RunPlan>, ident: &LoadedDataset) -> Option<f64> {
    let record = super::run_on(&plan.ok()?, ident).ok()?;
    (record.failure.is_none() && record.loglik.is_finite()).then_some(record.loglik)
}

/// The masses at ln-ratios `u` (of m_2..m_N) from `stated`.
fn masses_at(stated: &[f64], u: &[f64]) -> Vec<f64> {
    std::iter::once(stated[0])
        .chain(stated[1..].iter().zip(u).map(|(m, v)| m * v.exp()))
        .collect()
}

/// The identified masses' plan and free run over the record (none when the run failed).
pub(crate) type Moved = (RunPlan, Option<Vec<Vec<f64>>>);

/// The masses identified for the chosen candidate's `plan` (identified on `ident`, the first
/// samples of `data`) and their held-out score without the discrepancy: the
/// evidence (not yet `kept`: [`crate::choice`] compares the two with their discrepancy terms)
/// and, when the search moved them, their plan and free run over `data`.
pub(crate) fn identify(
    plan: &RunPlan,
    t: &Target,
    settings: &FilterSettings,
    (ident, data): (&LoadedDataset, &LoadedDataset),
) -> Result<(MassChoice, Option<Moved>)> {
    let stated = plan.building.masses.clone();
    log::info!(
        "identifying the mass ratios by the likelihood of the first {} samples…",
        ident.len()
    );
    let eval = |u: &[f64]| {
        let m = masses_at(&stated, u);
        loglik(with_masses(plan, t, settings, &m), ident)
    };
    // The stated masses' log-likelihood is the chosen plan's own.
    let loglik_stated = loglik(Ok(plan.clone()), ident);
    let search = Compass {
        first_step: FIRST_STEP,
        halvings: HALVINGS,
        bound: MAX_FACTOR.ln(),
        max_evaluations: MAX_EVALUATIONS,
    };
    let (u, best, evaluations, failed) = search.maximise(stated.len() - 1, loglik_stated, &eval);
    let identified = masses_at(&stated, &u);
    let mut choice = MassChoice::searched(
        (stated, identified.clone()),
        (loglik_stated, best),
        evaluations,
        failed,
    );
    if u.iter().all(|&v| v == 0.0) {
        choice.note = Some("no move raised the log-likelihood".into());
        return Ok((choice, None));
    }
    let moved = with_masses(plan, t, settings, &identified)?;
    let (c, sim): Scored = score(&moved, ident, data)?;
    choice.held_out_fit = c.held_out_fit;
    choice.score = c.score;
    choice.held_out_error = c.held_out_error;
    choice.note = c.note;
    Ok((choice, Some((moved, sim))))
}
