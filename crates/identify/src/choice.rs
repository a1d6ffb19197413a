//! Model choice on held-out evidence: the noise level and the damping form of an identification
//! on field data, chosen by how well each candidate predicts the part of the record it did not
//! see.
//!
//! The noise levels of a run are a fraction `nf` of each signal's RMS (SPEC §3): `R_ii =
//! (nf·RMS a_i)²`, and the velocities' process noise `dt·nf·RMS ü_g`. On a structure the model
//! cannot represent exactly, that guess decides where model error goes: on the Painter Street
//! Overpass (Ferndale 2015) the one-step log-likelihood prefers `nf = 0.3`, whose identified
//! damping makes the free run ring past the record (fit −73.4 %, `results/real/REPORT.md`), while
//! the candidate this choice takes (storey+mass, `nf = 3`) predicts it at +24.1 %.
//! A user judges an identification by what it predicts, so the plan chooses by prediction:
//! every candidate (each noise fraction of [`NOISE_FRACTIONS`] × each process-noise factor of
//! [`PROCESS_NOISE_FACTORS`] × each damping form the user left open) is identified on the first
//! part of the record, its θ_val run freely from rest over the whole record, and scored by the
//! fit of the part it never saw (the record's second half by energy, `HELD_OUT_ENERGY`); the best
//! mean fit over the channels wins, the first listed (less noise, fewer parameters) on a tie. The plan records every candidate's score ([`HeldOutChoice`]).
//!
//! Only where a candidate is cheap: the run is one Gaussian filter (a linear building under the
//! MPF-EKF2, [`crate::rules::samples_nothing`]) on field data, asked for without a config. A
//! particle run would cost one full run per candidate (24 with both damping forms open); its plan
//! says so and keeps the default.

pub mod channel_noise;
mod linear;
pub mod masses;
pub mod search;
pub mod substeps;

use models::dataset::LoadedDataset;
use models::structure::Damping;
use rayon::prelude::*;

use crate::error::Result;
use crate::field::StructureSettings;
use crate::plan::{
    Candidate, Decision, HeldOutChoice, JointDiscrepancy, Level, MassChoice, RunPlan, Target,
};
use crate::settings::FilterSettings;
use crate::validation::free_run::{
    chain_of, fit_percent, free_run_integrator, simulate_channels_between,
};
use crate::validation::{discrepancy, prediction};

/// The noise fractions tried, in order of preference on a tie (SPEC §3's 0.1 first).
pub const NOISE_FRACTIONS: [f64; 4] = [0.1, 0.3, 1.0, 3.0];

/// The process-noise factors tried with each (SPEC §3's 1 first).
pub const PROCESS_NOISE_FACTORS: [f64; 3] = [1.0, 0.1, 0.01];

/// The part of the record held out: what follows the sample by which the measured channels
/// have delivered this share of their energy (Σ y², mean removed) — the record's second half by
/// energy, so that the held-out part holds strong shaking, not only a quiet tail (on the
/// shake-table frame's `northridge` the last third by time is free decay at a tenth of the
/// shaking's amplitude, where every candidate's fit was negative).
pub(crate) const HELD_OUT_ENERGY: f64 = 0.5;

/// Each part keeps at least this share of the samples.
pub(crate) const MIN_PART: f64 = 0.2;

/// Fewest samples a record needs for the choice (below it the held-out part is too short to
/// tell candidates apart and the default stays).
pub(crate) const MIN_SAMPLES: usize = 600;

/// Why one storey has one damping form: storey 1's dashpot force −c₁v₁ and the mass term
/// −α m₁ v₁ act on the same velocity, so the data fix c₁/m₁ + α and nothing else; the two forms
/// are one model under two priors. Offered both, the choice chose between priors (on the
/// Painter Street bent, Ferndale 2015: storey+mass at ζ 2.2 %, whole-record fit 24.5 %; the
/// storey form alone, ζ 7.7 %, 38.2 % — the best one-storey output-error model's 38.4 %).
const ONE_STOREY_DAMPING: &str = "damping form: one storey's dashpot (−c1·v1) and the mass term \
     (−alpha·m1·v1) act on the same velocity, so the data fix only c1/m1 + alpha: storey+mass is \
     the same model with one more parameter, not a second candidate (docs/validation.md)";

/// The warning of a one-storey run that states `storey+mass`.
const ONE_STOREY_DAMPING_STATED: &str = "storey+mass on one storey: the dashpot (−c1·v1) and the \
     mass term (−alpha·m1·v1) act on the same velocity, so the data fix only c1/m1 + alpha; c1 and \
     alpha alone are not identified (each interval is mostly its prior's) — `--damping storey` \
     identifies their sum as c1 (docs/validation.md)";

/// Which of the settings the choice would choose the run stated itself (`--noise-fraction`,
/// `--process-noise-factor`): those are kept.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stated {
    pub noise_fraction: bool,
    pub process_noise_factor: bool,
}

/// Whether `plan` (settled for `t` from `asked`-less defaults) is one the choice applies to.
fn applies(plan: &RunPlan, t: &Target, data: &LoadedDataset) -> Result<Option<String>> {
    if t.config.is_some() {
        return Ok(Some(
            "the run has a config, whose noise fraction and damping form it keeps".into(),
        ));
    }
    if data.meta.is_some() {
        return Ok(Some(
            "the data were simulated: their noise levels are the SPEC's".into(),
        ));
    }
    if !crate::rules::samples_nothing(plan.algorithm, &plan.spec(data)?) {
        return Ok(Some(format!(
            "noise fraction {} kept (SPEC §3): choosing it on held-out data would cost one full particle run per candidate (up to {})",
            plan.settings.noise_fraction,
            NOISE_FRACTIONS.len() * PROCESS_NOISE_FACTORS.len() * 2
        )));
    }
    if data.len() < MIN_SAMPLES {
        return Ok(Some(format!(
            "noise fraction {} kept: {} samples are too few to hold a part out (at least {MIN_SAMPLES})",
            plan.settings.noise_fraction,
            data.len()
        )));
    }
    Ok(None)
}

/// `plan` (of field data) with its noise fraction changed to `nf` and its process-noise factor
/// to `pf` — the plan [`crate::plan::settle`] settles with them. On field data the clean RMS of a
/// channel is its measured RMS over √(1 + nf²) (the noise is nf × the clean RMS), so a noise
/// s.d. nf·RMS(clean) scales with g(nf) = nf/√(1 + nf²): `R` ∝ g², the velocities' process
/// noise ∝ g·pf; the hysteretic variables' and the displacements' do not depend on nf (the plan
/// settles them from the measured response alone; tested against `settle`).
pub fn with_noise(plan: &RunPlan, nf: f64, pf: f64) -> RunPlan {
    let g = |f: f64| f / (1.0 + f * f).sqrt();
    let (nf0, pf0) = (
        plan.settings.noise_fraction,
        plan.settings.process_noise_factor,
    );
    let ratio = g(nf) / g(nf0);
    let mut p = plan.clone();
    p.settings.noise_fraction = nf;
    p.settings.process_noise_factor = pf;
    for r in &mut p.model.r_diag {
        *r *= ratio * ratio;
    }
    p.model.q_vel *= ratio * pf / pf0;
    p
}

/// Records in `plan` that the choice kept its settings, and why.
fn kept(plan: &mut RunPlan, level: Level, why: String) {
    plan.decisions.push(Decision {
        rule: "choice::choose".into(),
        set: String::new(),
        level,
        why,
    });
}

/// Samples identified on: up to the sample by which the channels hold `HELD_OUT_ENERGY` of
/// their energy, each part keeping at least `MIN_PART` of the samples.
pub fn split_point(data: &LoadedDataset) -> usize {
    let (n, c) = (data.len(), data.channels);
    let mean: Vec<f64> = (0..c)
        .map(|j| (0..n).map(|k| data.y(k)[j]).sum::<f64>() / n as f64)
        .collect();
    let energy: Vec<f64> = (0..n)
        .map(|k| (0..c).map(|j| (data.y(k)[j] - mean[j]).powi(2)).sum())
        .collect();
    let total: f64 = energy.iter().sum();
    let mut cum = 0.0;
    let mut at = n;
    for (k, e) in energy.iter().enumerate() {
        cum += e;
        if cum >= HELD_OUT_ENERGY * total {
            at = k + 1;
            break;
        }
    }
    let lo = (MIN_PART * n as f64).ceil() as usize;
    at.clamp(lo, n - lo)
}

/// The first `len` samples of `data`.
fn head(data: &LoadedDataset, len: usize) -> LoadedDataset {
    LoadedDataset {
        dt: data.dt,
        t: data.t[..len].to_vec(),
        ug_meas: data.ug_meas[..len].to_vec(),
        y_meas: data.y_meas[..len * data.channels].to_vec(),
        channels: data.channels,
        sensors: data.sensors.clone(),
        truth: None,
        meta: None,
    }
}

/// A candidate with its free run over the whole record (per channel), when it has one.
pub(crate) type Scored = (Candidate, Option<Vec<Vec<f64>>>);

/// `plan` run on the identified part `ident` (no progress, no residuals kept).
pub(crate) fn run_on(plan: &RunPlan, ident: &LoadedDataset) -> Result<crate::record::RunRecord> {
    let input = crate::pipeline::RunInput {
        data: ident,
        chain: None,
        experiment: &plan.experiment,
        seed: plan.seed,
        run: plan.run,
        progress: None,
        residuals: false,
    };
    crate::pipeline::execute(plan, &input, &|| false)
}

/// Scores `plan` on the held-out part: identified on `ident` (the first samples of `data`), its
/// θ_val run freely over all of `data`, fit over the samples from `ident.len()` on.
pub(crate) fn score(plan: &RunPlan, ident: &LoadedDataset, data: &LoadedDataset) -> Result<Scored> {
    let mut c = Candidate {
        damping: plan.building.damping,
        noise_fraction: plan.settings.noise_fraction,
        process_noise_factor: plan.settings.process_noise_factor,
        held_out_fit: Vec::new(),
        score: None,
        held_out_error: None,
        note: None,
    };
    let record = run_on(plan, ident)?;
    if let Some(f) = &record.failure {
        c.note = Some(format!("the run failed: {f}"));
        return Ok((c, None));
    }
    let chain = match chain_of(&plan.building, &record.theta_val) {
        Ok(chain) => chain,
        Err(e) => {
            c.note = Some(format!("no building to simulate: {e}"));
            return Ok((c, None));
        }
    };
    let sim = match simulate_channels_between(
        &chain,
        &data.ug_meas,
        data.dt,
        &data.sensors,
        plan.building.measurement,
        free_run_integrator(&chain),
        plan.building.ground_between,
    ) {
        Ok(sim) => sim,
        Err(e) => {
            c.note = Some(format!("the free run failed: {e}"));
            return Ok((c, None));
        }
    };
    let from = ident.len();
    let measured = crate::validation::measured_channels(data);
    for (y, s) in measured.iter().zip(&sim) {
        let fit = if s.len() == data.len() {
            fit_percent(&y[from..], &s[from..])
        } else {
            f64::NAN
        };
        c.held_out_fit.push(fit);
    }
    let names: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
    if sim.iter().all(|s| s.len() == data.len()) {
        c.held_out_error = prediction::learn(
            &names,
            &measured,
            &sim,
            data.dt,
            prediction::window_seconds(&plan.building, &record.theta_val),
            from,
            prediction::ErrorSource::HeldOut {
                samples: data.len() - from,
            },
        );
    }
    let fits = &c.held_out_fit;
    if fits.iter().all(|f| f.is_finite()) {
        c.score = Some(fits.iter().sum::<f64>() / fits.len() as f64);
        Ok((c, Some(sim)))
    } else {
        c.note = Some("the free run left the record (non-finite fit)".into());
        Ok((c, None))
    }
}

/// Chooses the noise fraction (and, where the user left it open, the damping form) of `plan` —
/// settled for `t` from `settings` — by held-out prediction, and returns the plan of the chosen
/// candidate with the evidence and a decision; a plan the choice does not apply to comes back
/// with a decision saying why. Then, on the plan chosen, the sub-steps are doubled until θ no
/// longer moves with them ([`substeps::converge`], where that applies); a one-storey plan with
/// `storey+mass` damping (stated: the choice keeps `storey` on one storey) is warned that c1 and
/// alpha are one damping.
pub fn choose(
    plan: RunPlan,
    t: &Target,
    settings: &FilterSettings,
    stated: Stated,
) -> Result<RunPlan> {
    let plan = choose_noise(plan, t, settings, stated)?;
    let mut plan = substeps::converge(plan, t)?;
    if plan.building.storeys == 1 && plan.building.damping == Damping::StoreyMass {
        plan.decisions.push(Decision {
            rule: "choice::one_storey_damping".into(),
            set: String::new(),
            level: Level::Warning,
            why: ONE_STOREY_DAMPING_STATED.into(),
        });
    }
    Ok(plan)
}

/// [`choose`] without the sub-step check.
fn choose_noise(
    plan: RunPlan,
    t: &Target,
    settings: &FilterSettings,
    stated: Stated,
) -> Result<RunPlan> {
    let data = t.data;
    let mut plan = plan;
    let one_storey = plan.building.storeys == 1;
    if let Some(why) = applies(&plan, t, data)? {
        if t.config.is_none() && data.meta.is_none() {
            // A particle run: its noise chosen on its linear counterpart, where that runs.
            let applies_to = |p: &RunPlan, t: &Target| applies(p, t, data);
            if let Some(p) = linear::choose(&plan, t, settings, stated, applies_to)? {
                return Ok(p);
            }
            kept(&mut plan, Level::Info, why);
        }
        return Ok(plan);
    }
    // The damping forms: the user's, or both when the flags and table leave it open; the noise
    // levels: the stated ones, or the grids.
    let left_open = t.flags.damping.is_none() && settings.structure.damping.is_none();
    let open = left_open && !one_storey;
    if left_open && one_storey {
        plan.decisions.push(Decision {
            rule: "choice::one_storey_damping".into(),
            set: format!("damping = {}", plan.building.damping),
            level: Level::Note,
            why: ONE_STOREY_DAMPING.into(),
        });
    }
    let (fractions, factors) = noise_grids(settings, stated);
    if !open && fractions.len() * factors.len() == 1 {
        kept(
            &mut plan,
            Level::Info,
            "noise fraction, process noise and damping form as stated: nothing to choose on held-out data".into(),
        );
        return Ok(plan);
    }
    let ident = head(data, split_point(data));
    // The candidates run at a count their own step does not bias: the default candidate's
    // sub-steps checked on the part they identify on (docs/validation.md, "Sub-steps checked by
    // doubling").
    if substeps::applies(&plan, t)? {
        plan = substeps::converge_on(plan, &ident, false)?;
    }
    let mut bases = vec![plan.clone()];
    if open {
        let mut other = with_other_damping(&plan, t, settings)?;
        substeps::carry(&plan, &mut other);
        bases.push(other);
    }
    let held_out = data.len() - ident.len();
    log::info!(
        "choosing the noise levels{} on held-out data: {} candidates identified on the first {} of {} samples, each run freely over the rest…",
        if open { " and the damping form" } else { "" },
        bases.len() * fractions.len() * factors.len(),
        ident.len(),
        data.len()
    );
    let factors = &factors;
    let mut plans: Vec<RunPlan> = bases
        .iter()
        .flat_map(|b| {
            fractions
                .iter()
                .flat_map(move |&nf| factors.iter().map(move |&pf| with_noise(b, nf, pf)))
        })
        .collect();
    // The candidates are independent Gaussian filters that draw nothing: scored side by side on
    // every core, collected in the order above, so the choice is the same for any thread count.
    let (mut candidates, mut sims): (Vec<Candidate>, Vec<_>) = plans
        .par_iter()
        .map(|p| score(p, &ident, data))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .unzip();
    let Some(chosen) = best_scored(&candidates) else {
        let why = format!(
            "no candidate of the held-out choice predicted the record (noise fraction {} kept): {}",
            plan.settings.noise_fraction,
            candidates
                .iter()
                .filter_map(|c| c.note.clone())
                .collect::<Vec<_>>()
                .join("; ")
        );
        kept(&mut plan, Level::Warning, why);
        return Ok(plan);
    };
    // The discrepancy on the chosen candidate's free run; then the masses, where the data
    // inform them, each with its own discrepancy term: the run takes the better on the
    // held-out part.
    let mut out = plans.swap_remove(chosen);
    let mut error = candidates[chosen].held_out_error.clone();
    let mut discrepancy = sims[chosen]
        .take()
        .and_then(|sim| with_discrepancy(&mut error, &sim, data, ident.len()));
    candidates[chosen].held_out_error = error;
    // One storey has no mass ratio: its mass only scales the answer.
    let masses = if out.building.storeys < 2 {
        None
    } else if let Some(why) = masses::not_informed(&out, data) {
        kept(&mut out, Level::Info, why);
        None
    } else {
        let c = &candidates[chosen];
        let m;
        (out, m) = identify_masses(out, t, settings, (&ident, data), c, &mut discrepancy)?;
        Some(m)
    };
    let (out, joint) = joint_discrepancy(out, discrepancy.as_ref(), (&ident, data))?;
    let choice = HeldOutChoice {
        identified_samples: ident.len(),
        held_out_samples: held_out,
        candidates,
        chosen,
    };
    let mut out = with_evidence(with_choice(out, choice, open), masses, discrepancy);
    if let Some(j) = joint {
        out.decisions.push(Decision {
            rule: "choice::joint_discrepancy".into(),
            set: if j.kept {
                format!("discrepancy_modes = {}", out.model.discrepancy_modes.len())
            } else {
                String::new()
            },
            level: Level::Note,
            why: j.describe(),
        });
        out.evidence.joint_discrepancy = Some(j);
    }
    Ok(out)
}

/// The discrepancy inside the filter: `out` identified on the first part again with the chosen
/// modes' responses as regressors whose coefficients its Gaussian part carries beside θ
/// ([`crate::plan::Model::discrepancy_modes`]), θ's free run with the term fitted after it as
/// before, scored on the held-out part; the run takes it when its mean held-out fit is at least
/// that of θ identified alone with the term fitted after it. Model error then has the modes to
/// go into instead of θ, and θ's intervals carry what the data cannot tell apart between the
/// building and the modes.
fn joint_discrepancy(
    out: RunPlan,
    discrepancy: Option<&discrepancy::DiscrepancyChoice>,
    (ident, data): (&LoadedDataset, &LoadedDataset),
) -> Result<(RunPlan, Option<JointDiscrepancy>)> {
    let Some(d) = discrepancy.filter(|d| !d.modes().is_empty()) else {
        return Ok((out, None));
    };
    let modes = d.modes();
    let mut joint = out.clone();
    joint.model.discrepancy_modes = modes.to_vec();
    let mut j = JointDiscrepancy {
        after_fit: d.candidates[d.chosen].held_out_fit.clone(),
        joint_fit: Vec::new(),
        joint_building_fit: Vec::new(),
        kept: false,
        held_out_error: None,
        note: None,
    };
    let (c, sim) = score(&joint, ident, data)?;
    let Some(sim) = sim else {
        j.note = Some(c.note.unwrap_or_else(|| "no free run".into()));
        return Ok((out, Some(j)));
    };
    j.joint_building_fit = c.held_out_fit;
    let names: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
    let measured = crate::validation::measured_channels(data);
    let from = ident.len();
    let ground = (&data.ug_meas[..], data.dt);
    let term = discrepancy::refit(modes, &names, &measured, &sim, ground, from);
    j.joint_fit = discrepancy::held_out_fits(Some(&term), &measured, &sim, ground, from);
    let add = discrepancy::contribution(&term, &data.ug_meas, data.dt);
    let with: Vec<Vec<f64>> = sim
        .iter()
        .zip(&add)
        .map(|(s, a)| s.iter().zip(a).map(|(x, y)| x + y).collect())
        .collect();
    j.held_out_error = c.held_out_error.and_then(|e| {
        prediction::learn(
            &names,
            &measured,
            &with,
            data.dt,
            e.window_s,
            from,
            prediction::ErrorSource::HeldOut {
                samples: data.len() - from,
            },
        )
    });
    let mean = |f: &[f64]| f.iter().sum::<f64>() / f.len() as f64;
    let (mj, ma) = (mean(&j.joint_fit), mean(&j.after_fit));
    j.kept = mj.is_finite() && (mj >= ma || !ma.is_finite());
    Ok((if j.kept { joint } else { out }, Some(j)))
}

/// The masses of the chosen candidate's plan `out` identified ([`masses::identify`]) and, when
/// their free run with its own discrepancy term predicts every channel of the held-out part
/// better than `chosen`'s with `discrepancy`, taken: then the plan and the discrepancy are
/// theirs.
fn identify_masses(
    out: RunPlan,
    t: &Target,
    settings: &FilterSettings,
    (ident, data): (&LoadedDataset, &LoadedDataset),
    chosen: &Candidate,
    discrepancy: &mut Option<discrepancy::DiscrepancyChoice>,
) -> Result<(RunPlan, MassChoice)> {
    let (mut m, moved) = masses::identify(&out, t, settings, (ident, data))?;
    let Some((plan_m, sim_m)) = moved else {
        return Ok((out, m));
    };
    let mut error_m = m.held_out_error.take();
    let disc_m = sim_m.and_then(|sim| with_discrepancy(&mut error_m, &sim, data, ident.len()));
    m.held_out_error = error_m;
    let stated_fits = final_fits(discrepancy.as_ref(), &chosen.held_out_fit);
    let fits = final_fits(disc_m.as_ref(), &m.held_out_fit);
    m.stated_final_fit = stated_fits.to_vec();
    m.final_fit = fits.to_vec();
    m.kept = better_everywhere(fits, stated_fits);
    Ok(if m.kept {
        *discrepancy = disc_m;
        (plan_m, m)
    } else {
        (out, m)
    })
}

/// `out` with the masses' and the discrepancy's evidence and decisions, in that order.
fn with_evidence(
    mut out: RunPlan,
    masses: Option<MassChoice>,
    discrepancy: Option<discrepancy::DiscrepancyChoice>,
) -> RunPlan {
    if let Some(m) = masses {
        out.decisions.push(Decision {
            rule: "masses::identify".into(),
            set: if m.kept {
                format!("masses = {:?}", m.identified)
            } else {
                String::new()
            },
            level: Level::Note,
            why: m.describe(),
        });
        out.evidence.masses = Some(m);
    }
    if let Some(d) = discrepancy {
        out.decisions.push(Decision {
            rule: "discrepancy::choose".into(),
            set: format!(
                "discrepancy = {}",
                d.candidates[d.chosen].discrepancy.describe_modes()
            ),
            level: Level::Note,
            why: d.describe(),
        });
        out.evidence.discrepancy = Some(d);
    }
    out
}

/// The discrepancy modes of the free run `sim` over `data` the run takes (identified on the
/// samples `..from`), chosen on the held-out part ([`discrepancy::choose`]); with modes, its
/// model `error` is learned again on the held-out part with the discrepancy added, since the
/// band is drawn around the prediction that includes it.
fn with_discrepancy(
    error: &mut Option<crate::record::validation::ModelError>,
    sim: &[Vec<f64>],
    data: &LoadedDataset,
    from: usize,
) -> Option<discrepancy::DiscrepancyChoice> {
    let names: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
    let measured = crate::validation::measured_channels(data);
    let choice = discrepancy::choose(
        &discrepancy::SEARCH,
        &names,
        &measured,
        sim,
        &data.ug_meas,
        data.dt,
        from,
    )?;
    let chosen = &choice.candidates[choice.chosen].discrepancy;
    if !chosen.modes.is_empty() {
        let add = discrepancy::contribution(chosen, &data.ug_meas, data.dt);
        let with: Vec<Vec<f64>> = sim
            .iter()
            .zip(&add)
            .map(|(s, a)| s.iter().zip(a).map(|(x, y)| x + y).collect())
            .collect();
        if let Some(window_s) = error.as_ref().map(|e| e.window_s) {
            *error = prediction::learn(
                &names,
                &measured,
                &with,
                data.dt,
                window_s,
                from,
                prediction::ErrorSource::HeldOut {
                    samples: data.len() - from,
                },
            );
        }
    }
    Some(choice)
}

/// The held-out fits (per channel) of a free run with its chosen discrepancy term, or (no term
/// searched) its own `fits`.
fn final_fits<'a>(d: Option<&'a discrepancy::DiscrepancyChoice>, fits: &'a [f64]) -> &'a [f64] {
    match d {
        Some(d) => &d.candidates[d.chosen].held_out_fit,
        None => fits,
    }
}

/// Whether `fits` beat `than` on every channel (a channel without a finite fit beats nothing).
/// Masses that trade one floor's fit for another's are fitting something else: on the foreign
/// corpus's hardening joint (`docs/foreign.md`) the identified masses 1 : 0.75 : 0.94 raised the
/// held-out part's mean fit by 2.1 points, floor 1 by 6.5 and floor 3 down by 1.2, and predicted
/// the case's other earthquake 15 points worse on floor 1.
fn better_everywhere(fits: &[f64], than: &[f64]) -> bool {
    !fits.is_empty()
        && fits.len() == than.len()
        && fits
            .iter()
            .zip(than)
            .all(|(f, t)| f.is_finite() && (!t.is_finite() || f > t))
}

/// The noise fractions and process-noise factors to choose among: each the stated value, or
/// its grid.
fn noise_grids(settings: &FilterSettings, stated: Stated) -> (Vec<f64>, Vec<f64>) {
    let fractions: Vec<f64> = if stated.noise_fraction {
        vec![settings.noise_fraction]
    } else {
        NOISE_FRACTIONS.to_vec()
    };
    let factors: Vec<f64> = if stated.process_noise_factor {
        vec![settings.process_noise_factor]
    } else {
        PROCESS_NOISE_FACTORS.to_vec()
    };
    (fractions, factors)
}

/// `plan` settled again for `t` with the other damping form (storey ↔ storey+mass): the second
/// base of the candidates when the damping form is left open.
fn with_other_damping(plan: &RunPlan, t: &Target, settings: &FilterSettings) -> Result<RunPlan> {
    let other = match plan.building.damping {
        Damping::Storey => Damping::StoreyMass,
        Damping::StoreyMass => Damping::Storey,
    };
    let flags = StructureSettings {
        damping: Some(other),
        ..t.flags.clone()
    };
    let target = t.with_flags(t.algorithm, &flags);
    crate::plan::settle(target.request(settings.clone(), plan.seed, plan.run, &plan.experiment))
}

/// The candidate with the highest held-out score (the first of equals), if any was scored.
fn best_scored(candidates: &[Candidate]) -> Option<usize> {
    let best = candidates
        .iter()
        .enumerate()
        .filter_map(|(i, c)| c.score.map(|s| (i, s)))
        .fold(None, |acc: Option<(usize, f64)>, (i, s)| match acc {
            Some((_, b)) if b >= s => acc,
            _ => Some((i, s)),
        });
    best.map(|(chosen, _)| chosen)
}

/// The chosen candidate's plan `out` with the choice's decision (the damping form named when it
/// was `open`) and the choice as its evidence.
fn with_choice(mut out: RunPlan, choice: HeldOutChoice, open: bool) -> RunPlan {
    let c = &choice.candidates[choice.chosen];
    out.decisions.push(Decision {
        rule: "choice::choose".into(),
        set: format!(
            "noise_fraction = {}, process_noise_factor = {}{}",
            c.noise_fraction,
            c.process_noise_factor,
            if open {
                format!(", damping = {}", c.damping)
            } else {
                String::new()
            }
        ),
        level: Level::Note,
        why: choice.describe(),
    });
    out.evidence.held_out = Some(choice);
    out
}

#[cfg(test)]
mod tests {
    use super::better_everywhere;

    #[test]
    fn identified_masses_must_predict_every_channel_better() {
        assert!(better_everywhere(&[72.0, 80.0], &[71.9, 79.0]));
        // The joint's case: a better mean from one floor at another's cost.
        assert!(!better_everywhere(&[31.7, 27.8, 26.1], &[25.2, 26.9, 27.3]));
        // Equal is not better; a non-finite fit beats nothing; a non-finite rival is beaten.
        assert!(!better_everywhere(&[72.0], &[72.0]));
        assert!(!better_everywhere(&[f64::NAN, 90.0], &[10.0, 10.0]));
        assert!(better_everywhere(&[20.0, 90.0], &[f64::NAN, 10.0]));
        // Nothing to compare, or channels that do not match.
        assert!(!better_everywhere(&[], &[]));
        assert!(!better_everywhere(&[90.0], &[10.0, 10.0]));
    }
}
