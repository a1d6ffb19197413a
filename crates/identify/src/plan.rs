//! The plan of one run ([`RunPlan`]): settled once, before anything runs, from the data, what
//! the user stated of the building, the settings (a config's or the recommended ones) and the
//! command line — the building, the prior, the noise levels, the sub-steps, the particles and
//! pooling, the rejuvenation and the seeds — with every choice a default rule made and why
//! ([`Decision`]). A run executes its plan and nothing else (`pipeline::execute`); `sysid
//! filter --plan-only` prints it, `--print-plan` writes it as TOML and `--plan FILE` runs
//! exactly that plan.
//!
//! [`settle`] is the one place where a run's defaults are decided: the building is resolved
//! once, the data-scaled prior scanned at most once, and the rules of [`crate::rules`] applied
//! in a fixed order.

use std::fmt;
use std::path::Path;

use crate::error::{bail, invalid, Context, Result};
use models::dataset::{LoadedDataset, META};
use models::description::StructureDescription;
use models::filtering::{ChainPrior, ChainSpec, MarginalPrior, RmsLevels};
use models::sensors::MeasurementKind;
use models::structure::{Damping, ShearChain};
use serde::{Deserialize, Serialize};

use crate::algorithm::Algorithm;
use crate::field::{self, resolve_for_run, StructureSettings};
use crate::rules::{
    per_particle_reason, unmeasured_storeys, LagSubsteps, HYSTERETIC_PARTICLES, LAG_SUBSTEPS,
    PER_PARTICLE_MIN_STOREYS, SPARSE_REL_SD,
};
use crate::scaled_prior::{HystereticSubsteps, ScaledPrior};
use crate::settings::{recommended_pool, FilterSettings, Substeps, RECOMMENDED_PARTICLES};

/// The version of the plan's layout, written into every plan (a plan file of another version
/// is refused by name).
pub(crate) const PLAN_VERSION: u32 = 1;

/// Everything one run does, settled before it starts ([`settle`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunPlan {
    /// `PLAN_VERSION`.
    pub plan_version: u32,
    pub algorithm: Algorithm,
    /// Master seed and run index: the filter's random streams are derived from them.
    pub seed: u64,
    pub run: u64,
    /// Experiment name written into the record.
    pub experiment: String,
    /// SHA-256 of the data the plan was settled on (`record::fingerprint::data_identity`); a
    /// plan is refused on other data.
    pub data_sha256: String,
    /// The filter settings after the default rules (`particles`, `pool`, `rejuvenation`,
    /// `marginal_prior` as the rules set them; `substeps` as asked, the number run in
    /// [`Model::substeps`]).
    pub settings: FilterSettings,
    /// The building identified: storeys, masses, hysteretic storeys, sensors, measurement kind
    /// and damping form.
    pub building: StructureDescription,
    /// The model the filter runs: prior, noise levels, sub-steps.
    pub model: Model,
    /// What the automatic choices rest on (recorded, not needed to run).
    #[serde(default)]
    pub evidence: Evidence,
    /// Every choice a default rule made, in the order made.
    #[serde(default)]
    pub decisions: Vec<Decision>,
}

/// The model a plan runs: the prior of θ (with its fixed parameters), the noise levels and the
/// transitions per sample interval.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    pub prior: ChainPrior,
    /// Measurement-noise variances, one per channel (m²/s⁴).
    pub r_diag: Vec<f64>,
    /// Process-noise s.d. of the displacements, of the velocities and of each hysteretic
    /// variable, per step.
    pub q_disp: f64,
    pub q_vel: f64,
    pub q_r: Vec<f64>,
    /// Transitions inside the filter per sample interval.
    pub substeps: usize,
    /// The coloured part of the measurement noise, if any (settings' `coloured_noise`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coloured_noise: Option<models::filtering::ColouredNoise>,
    /// Discrepancy modes identified with θ: their responses to the ground motion are regressors
    /// of every channel whose coefficients the filter's Gaussian part carries beside θ
    /// ([`crate::choice`], "the discrepancy inside the filter"); none: θ alone.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub discrepancy_modes: Vec<crate::record::validation::DiscrepancyMode>,
}

/// What the automatic choices of a plan rest on.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Evidence {
    /// Field data with the default prior: what the prior was scaled from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_from_data: Option<ScaledPrior>,
    /// `substeps = "auto"`: what each sub-step rule found.
    #[serde(default)]
    pub substeps: AutoChoice,
    /// The noise fraction (and damping form) chosen by held-out prediction: every candidate's
    /// score ([`crate::choice`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOutChoice>,
    /// The discrepancy modes chosen by held-out prediction on the chosen candidate's free run
    /// ([`crate::validation::discrepancy`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrepancy: Option<DiscrepancyChoice>,
    /// The mass ratios identified after the held-out choice, and whether the run takes them
    /// ([`crate::choice::masses`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub masses: Option<MassChoice>,
    /// Each channel's measurement noise learned by maximum likelihood after the masses, and
    /// whether the run takes it ([`crate::choice::channel_noise`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channel_noise: Option<ChannelNoise>,
    /// The chosen discrepancy modes identified with θ inside the filter, and whether the run
    /// does so ([`crate::choice`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_discrepancy: Option<JointDiscrepancy>,
    /// The sub-steps doubled until θ no longer moved with them ([`crate::choice::substeps`]):
    /// on the part the held-out choice identifies on (its candidates run at that count), then
    /// on the whole record.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub substep_checks: Vec<SubstepConvergence>,
}

/// One run of the sub-step check: the count, θ_val and each parameter's posterior s.d. as the
/// run reports it (its 95 % half-width over 1.96, model error included).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubstepRun {
    pub substeps: usize,
    pub theta_val: Vec<f64>,
    pub sd: Vec<f64>,
    /// The stiffnesses' largest |Δθ_j| / s.d._j against the run before (none for the first):
    /// what decides.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moved: Option<Moved>,
    /// The other parameters' largest, reported beside.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub others_moved: Option<Moved>,
}

/// How far a parameter moved between two runs, in its posterior s.d.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Moved {
    pub parameter: String,
    pub sd: f64,
}

/// The evidence of the sub-step check ([`crate::choice::substeps`]): the whole record identified
/// with the sub-steps of the rules, then with twice as many, and so on, until θ_val moved by at
/// most `tolerance` posterior s.d. in a doubling or the count reached its largest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubstepConvergence {
    /// Samples identified on: the whole record, or the first part of it (the held-out
    /// choice's).
    pub samples: usize,
    pub whole: bool,
    pub tolerance: f64,
    pub runs: Vec<SubstepRun>,
    /// Whether the last doubling moved θ by at most `tolerance` s.d.
    pub converged: bool,
    /// Why the check stopped early (a run that failed), if it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl SubstepConvergence {
    /// The count the run takes: the last run's.
    pub fn substeps(&self) -> Option<usize> {
        self.runs.last().map(|r| r.substeps)
    }

    /// The line `sysid filter` prints.
    pub fn describe(&self) -> String {
        let counts: Vec<String> = self.runs.iter().map(|r| r.substeps.to_string()).collect();
        let list = |pick: &dyn Fn(&SubstepRun) -> Option<&Moved>| {
            let moves: Vec<String> = self
                .runs
                .iter()
                .filter_map(|r| pick(r).map(|m| format!("{:.2} ({})", m.sd, m.parameter)))
                .collect();
            if moves.is_empty() {
                "—".to_string()
            } else {
                moves.join(", ")
            }
        };
        let verdict = if let Some(n) = &self.note {
            format!("stopped: {n}")
        } else if self.converged {
            format!(
                "converged: the last doubling moved the stiffnesses by at most {} s.d., so the step's own bias is about that or less",
                self.tolerance
            )
        } else {
            format!(
                "not converged: the largest count still moved a stiffness by more than {} s.d.; its interval does not include the step's bias",
                self.tolerance
            )
        };
        format!(
            "sub-steps checked on {}: {} per sample; each step up moved the stiffnesses by at most {} of their posterior s.d. (the others by at most {}); {verdict} (docs/validation.md, \"Sub-steps checked by doubling\")",
            if self.whole {
                "the whole record".to_string()
            } else {
                format!(
                    "the first {} samples (the part the held-out choice identifies on; its candidates run at the count found)",
                    self.samples
                )
            },
            counts.join(" → "),
            list(&|r| r.moved.as_ref()),
            list(&|r| r.others_moved.as_ref()),
        )
    }
}

/// The evidence of identifying θ with the discrepancy modes inside the filter: the held-out
/// part's free-run fit with the term, each way, the term's coefficients fitted on the
/// identified part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointDiscrepancy {
    /// θ identified alone, the term fitted after it (the discrepancy choice's chosen fits).
    pub after_fit: Vec<f64>,
    /// θ identified with the modes' coefficients in the filter, the term fitted after it.
    pub joint_fit: Vec<f64>,
    /// The held-out part's fit of the building alone, identified jointly.
    pub joint_building_fit: Vec<f64>,
    /// Whether the run identifies θ with the modes: its mean held-out fit is at least the
    /// other's.
    pub kept: bool,
    /// The joint model's error learned on the held-out part (the band's, when kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_error: Option<crate::record::validation::ModelError>,
    /// Why it could not be scored, if so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl JointDiscrepancy {
    /// One line: both ways' held-out fits and which the run takes.
    pub fn describe(&self) -> String {
        let mean = |f: &[f64]| f.iter().sum::<f64>() / f.len().max(1) as f64;
        match &self.note {
            Some(n) => format!("θ identified without the discrepancy modes: {n}"),
            None => format!(
                "θ identified {} the discrepancy modes inside the filter: identified with them, \
                 {} with the term (the building alone {} %), against {} identified alone with \
                 the term fitted after it",
                if self.kept { "with" } else { "without" },
                held_out_fit(mean(&self.joint_fit), &self.joint_fit),
                fits_list(&self.joint_building_fit),
                held_out_fit(mean(&self.after_fit), &self.after_fit),
            ),
        }
    }
}

impl Evidence {
    /// The model error the run's predictive band takes: learned on the held-out part with the
    /// masses and discrepancy the run takes (the identified masses' when kept, else the chosen
    /// candidate's); `None` when the held-out choice did not run.
    pub(crate) fn held_out_error(&self) -> Option<&crate::record::validation::ModelError> {
        if let Some(j) = self.joint_discrepancy.as_ref().filter(|j| j.kept) {
            return j.held_out_error.as_ref();
        }
        match &self.masses {
            Some(m) if m.kept => m.held_out_error.as_ref(),
            _ => self
                .held_out
                .as_ref()
                .and_then(|h| h.candidates.get(h.chosen))
                .and_then(|c| c.held_out_error.as_ref()),
        }
    }
}

/// "68.0 / 72.1 / 72.6": channels' fits.
fn fits_list(fits: &[f64]) -> String {
    fits.iter()
        .map(|f| format!("{f:.1}"))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// "held-out fit 70.9 % (68.0 / 72.1 / 72.6)": a candidate's score and its channels' fits.
fn held_out_fit(score: f64, fits: &[f64]) -> String {
    format!("held-out fit {score:.1} % ({})", fits_list(fits))
}

/// A number of discrepancy modes and how well it predicted the held-out part
/// ([`crate::validation::discrepancy`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscrepancyCandidate {
    /// Its modes, with the coefficients fitted on the identified part.
    pub discrepancy: crate::record::validation::Discrepancy,
    /// Free-run fit (%) of each channel over the held-out samples, the discrepancy added.
    pub held_out_fit: Vec<f64>,
    /// Their mean (absent when a fit is not finite).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    /// Whether every mode's frequency and damping were searched again with the new one (else
    /// the new one's alone): the one of the two that predicted the held-out part better.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub every_mode_refined: bool,
}

impl DiscrepancyCandidate {
    /// The candidate `discrepancy` with its held-out fits.
    pub fn new(
        discrepancy: crate::record::validation::Discrepancy,
        held_out_fit: Vec<f64>,
    ) -> Self {
        let score = held_out_fit
            .iter()
            .all(|f| f.is_finite())
            .then(|| held_out_fit.iter().sum::<f64>() / held_out_fit.len().max(1) as f64);
        DiscrepancyCandidate {
            discrepancy,
            held_out_fit,
            score,
            every_mode_refined: false,
        }
    }
}

/// The evidence of the discrepancy's choice: the chosen noise candidate's free run, 0 to
/// `max_modes` discrepancy modes found on the identified part, scored on the held-out part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscrepancyChoice {
    pub identified_samples: usize,
    pub held_out_samples: usize,
    /// Held-out fit (points) each mode must gain to be kept.
    pub mode_cost: f64,
    /// Candidate `m` has `m` modes.
    pub candidates: Vec<DiscrepancyCandidate>,
    pub chosen: usize,
}

impl DiscrepancyChoice {
    /// The chosen modes.
    pub fn modes(&self) -> &[crate::record::validation::DiscrepancyMode] {
        &self.candidates[self.chosen].discrepancy.modes
    }

    /// One line per candidate, the chosen one marked.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "discrepancy modes chosen by the free-run fit of the held-out {} samples (each mode \
             must gain {} points), found and fitted on the first {}:",
            self.held_out_samples, self.mode_cost, self.identified_samples
        );
        for (m, c) in self.candidates.iter().enumerate() {
            let mark = if m == self.chosen { " ← chosen" } else { "" };
            let fit = match c.score {
                Some(v) => held_out_fit(v, &c.held_out_fit),
                None => "no score".into(),
            };
            s.push_str(&format!(
                "\n  {m} mode(s){}: {}: {fit}{mark}",
                if c.every_mode_refined {
                    " (all searched again)"
                } else {
                    ""
                },
                c.discrepancy.describe_modes()
            ));
        }
        s
    }
}

/// The evidence of the masses' identification ([`crate::choice::masses`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MassChoice {
    /// The masses stated, and those that maximise the log-likelihood (m_1 kept).
    pub stated: Vec<f64>,
    pub identified: Vec<f64>,
    /// The chosen filter's log-likelihood of the identified part under each (none where that
    /// run failed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loglik_stated: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loglik_identified: Option<f64>,
    /// Filter runs the search took, and how many of them failed (scored −∞).
    pub evaluations: usize,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub failed_evaluations: usize,
    /// The held-out part's free-run fit with the identified masses, building alone (the stated
    /// masses' is the chosen candidate's, `HeldOutChoice`), with its channels' fits.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_out_fit: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    /// The held-out fits (per channel) of each with its own discrepancy term (the fits again
    /// when no term was searched): what decides.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stated_final_fit: Vec<f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub final_fit: Vec<f64>,
    /// Whether the run takes the identified masses: their free run, with its discrepancy term,
    /// predicts every channel of the held-out part better than the stated masses' with theirs.
    pub kept: bool,
    /// The identified masses' model error learned on the held-out part (the band's, when kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_error: Option<crate::record::validation::ModelError>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// "1 : 1.02 : 1.38".
fn ratios(m: &[f64]) -> String {
    m.iter()
        .map(|x| format!("{:.3}", x / m[0]))
        .collect::<Vec<_>>()
        .join(" : ")
}

impl MassChoice {
    /// The evidence of a search that found `identified` from `stated` in `evaluations` runs
    /// (`failed` of them failed), before any held-out score: not taken.
    pub(crate) fn searched(
        (stated, identified): (Vec<f64>, Vec<f64>),
        (loglik_stated, loglik_identified): (Option<f64>, Option<f64>),
        evaluations: usize,
        failed: usize,
    ) -> Self {
        Self {
            stated,
            identified,
            loglik_stated,
            loglik_identified,
            evaluations,
            failed_evaluations: failed,
            held_out_fit: Vec::new(),
            score: None,
            stated_final_fit: Vec::new(),
            final_fit: Vec::new(),
            kept: false,
            held_out_error: None,
            note: None,
        }
    }

    /// What was found and what the run takes.
    pub fn describe(&self) -> String {
        let ll = |l: Option<f64>| l.map_or("run failed".into(), |l| format!("{l:.1}"));
        let held = match self.score {
            Some(s) if !self.final_fit.is_empty() => format!(
                "held-out fit {s:.1} % (building alone); per channel, each with its discrepancy \
                 term, {} % against the stated masses' {} %",
                fits_list(&self.final_fit),
                fits_list(&self.stated_final_fit)
            ),
            Some(s) => format!("held-out fit {s:.1} % (building alone)"),
            None => format!(
                "no held-out fit ({})",
                self.note.as_deref().unwrap_or("no free run")
            ),
        };
        let failed = if self.failed_evaluations > 0 {
            format!(", {} of them failed", self.failed_evaluations)
        } else {
            String::new()
        };
        format!(
            "mass ratios identified by the chosen filter's log-likelihood of the first part of the record \
             ({} runs{failed}): {} (log-likelihood {}) against the stated {} ({}); {held}: {}",
            self.evaluations,
            ratios(&self.identified),
            ll(self.loglik_identified),
            ratios(&self.stated),
            ll(self.loglik_stated),
            if self.kept {
                "the identified masses are taken"
            } else {
                "the stated masses are kept (the identified ones do not predict every channel of the held-out part better)"
            }
        )
    }
}

/// The evidence of each channel's noise learned by maximum likelihood
/// ([`crate::choice::channel_noise`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelNoise {
    /// Each channel's noise s.d. as settled before (the noise fraction's), and as learned.
    pub settled_sd: Vec<f64>,
    pub learned_sd: Vec<f64>,
    /// The learned levels' 95 % intervals (Laplace, per channel); a channel is left out where
    /// the curvature there was not negative or a neighbour's run failed.
    pub learned_sd_95: Vec<LevelInterval>,
    /// The filter's log-likelihood of the record under each (none where that run failed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loglik_settled: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loglik_learned: Option<f64>,
    /// Filter runs the search took, and how many of them failed (scored −∞).
    pub evaluations: usize,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub failed_evaluations: usize,
    /// The channels, in order (`a1`, …).
    pub channels: Vec<String>,
    /// Channels whose learned level is at the search's bound (`MAX_FACTOR` from the settled
    /// one): the likelihood wants more, so the level is a bound, not an estimate.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub at_bound: Vec<String>,
}

/// A channel's learned noise s.d.'s 95 % interval.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelInterval {
    pub channel: String,
    pub lo: f64,
    pub hi: f64,
}

impl ChannelNoise {
    /// What was learned.
    pub fn describe(&self) -> String {
        let ll = |l: Option<f64>| l.map_or("run failed".into(), |l| format!("{l:.1}"));
        let sds = |s: &[f64]| {
            s.iter()
                .map(|x| format!("{x:.3e}"))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        let learned = self
            .learned_sd
            .iter()
            .zip(&self.channels)
            .map(
                |(x, c)| match self.learned_sd_95.iter().find(|i| &i.channel == c) {
                    Some(i) => format!("{x:.3e} [{:.3e}, {:.3e}]", i.lo, i.hi),
                    None => format!("{x:.3e} [no interval]"),
                },
            )
            .collect::<Vec<_>>()
            .join(" / ");
        let failed = if self.failed_evaluations > 0 {
            format!(", {} of them failed", self.failed_evaluations)
        } else {
            String::new()
        };
        let bound = if self.at_bound.is_empty() {
            String::new()
        } else {
            format!(
                "; {} at the search's bound (a bound, not an estimate)",
                self.at_bound.join(", ")
            )
        };
        format!(
            "each channel's measurement noise s.d. learned by the filter's log-likelihood of the record, \
             the settled level its prior's median ({} runs{failed}): {learned} m/s² [95 %] \
             (log-likelihood {}) against the settled {} ({}){bound}; the process noise as settled \
             (docs/validation.md, \"Noise learned by maximum likelihood\")",
            self.evaluations,
            ll(self.loglik_learned),
            sds(&self.settled_sd),
            ll(self.loglik_settled),
        )
    }
}

/// One candidate and how well it predicted the held-out part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Candidate {
    pub damping: Damping,
    pub noise_fraction: f64,
    pub process_noise_factor: f64,
    /// Free-run fit (%) of each channel over the held-out samples; empty when the candidate
    /// has no free run (`note` says why).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_out_fit: Vec<f64>,
    /// Their mean: the score.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    /// The model error of its free run learned on the held-out samples
    /// (`crate::validation::prediction`): the chosen candidate's widens the run's predictive band.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_error: Option<crate::record::validation::ModelError>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The evidence of the choice: the split and every candidate's score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeldOutChoice {
    /// Samples identified on (the first ones) and held out (the rest).
    pub identified_samples: usize,
    pub held_out_samples: usize,
    pub candidates: Vec<Candidate>,
    /// Index of the chosen candidate.
    pub chosen: usize,
}

impl HeldOutChoice {
    /// One line per candidate, the chosen one marked.
    pub fn describe(&self) -> String {
        let forms = self
            .candidates
            .iter()
            .any(|c| c.damping != self.candidates[0].damping);
        let mut s = format!(
            "noise levels{} chosen by the free-run fit of the last {} of {} samples (the record's second half by energy), identified on the first {}:",
            if forms { " and damping form" } else { "" },
            self.held_out_samples,
            self.identified_samples + self.held_out_samples,
            self.identified_samples
        );
        for (i, c) in self.candidates.iter().enumerate() {
            let mark = if i == self.chosen { " ← chosen" } else { "" };
            let what = match (&c.score, &c.note) {
                (Some(v), _) => held_out_fit(*v, &c.held_out_fit),
                (None, Some(n)) => n.clone(),
                (None, None) => "no score".into(),
            };
            s.push_str(&format!(
                "\n  damping {}, noise fraction {}, process noise ×{}: {what}{mark}",
                c.damping, c.noise_fraction, c.process_noise_factor
            ));
        }
        s
    }
}

/// A run to settle ([`settle`]): its algorithm, its data set (and `measured.csv` path), the
/// true structure when the data set says what it is, the structure flags, and where the settings
/// came from.
pub struct Target<'a> {
    pub algorithm: Algorithm,
    pub data: &'a LoadedDataset,
    pub chain: Option<&'a models::structure::ShearChain>,
    pub measured: &'a Path,
    pub flags: &'a StructureSettings,
    /// The config's name (a file, or how else it was given); `None` when the run has no config
    /// and takes the recommended settings.
    pub config: Option<&'a str>,
    /// Whether the run asked for its particle count (`--particles`); if not, and without a
    /// config, the plan may choose it ([`crate::rules::HYSTERETIC_PARTICLES`]).
    pub particles_asked: bool,
}

impl Target<'_> {
    /// The same run with another `algorithm` and structure `flags`: the target of a candidate
    /// settled on another building (the other damping form, the linear counterpart).
    pub fn with_flags<'b>(
        &'b self,
        algorithm: Algorithm,
        flags: &'b StructureSettings,
    ) -> Target<'b> {
        Target {
            algorithm,
            data: self.data,
            chain: self.chain,
            measured: self.measured,
            flags,
            config: self.config,
            particles_asked: self.particles_asked,
        }
    }

    /// The plan request of this target with `settings`, seed, run and experiment.
    pub fn request<'a>(
        &'a self,
        settings: FilterSettings,
        seed: u64,
        run: u64,
        experiment: &'a str,
    ) -> PlanRequest<'a> {
        PlanRequest {
            algorithm: self.algorithm,
            data: self.data,
            chain: self.chain,
            settings,
            seed,
            run,
            experiment,
            asked: Some(Asked {
                measured: self.measured,
                flags: self.flags,
                config: self.config,
                particles_asked: self.particles_asked,
            }),
        }
    }
}

/// How much a decision asks of the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Level {
    /// What was found or resolved (the building of field data, the data-scaled prior).
    Info,
    /// A default a rule chose.
    Note,
    /// A setting kept against a rule's advice, or a bias the run cannot remove.
    Warning,
}

/// One choice of [`settle`]: which rule, what it set, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Decision {
    /// The rule: a function or constant of [`crate::rules`], [`crate::scaled_prior`],
    /// [`crate::field`] or `models::filtering::substeps`.
    pub rule: String,
    /// What it set (`key = value`), or empty when it only informs.
    pub set: String,
    pub level: Level,
    /// Why, with the measurement behind it.
    pub why: String,
}

impl fmt::Display for Decision {
    /// The line `sysid filter` prints.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.level {
            Level::Info => f.write_str(&self.why),
            Level::Note => write!(f, "note: {}", self.why),
            Level::Warning => write!(f, "warning: {}", self.why),
        }
    }
}

/// How a person asked for a run (`sysid filter`, the Python `identify`, `loglik`): the
/// structure flags, whether a config was given, whether a particle count was asked for. A
/// study's job has none: its settings are final but for the prior and `substeps = "auto"`.
#[derive(Clone, Copy)]
pub struct Asked<'a> {
    /// `measured.csv` of the data set (named in messages).
    pub measured: &'a Path,
    /// The structure flags (`--storeys`, …), over the config's `[structure]` table.
    pub flags: &'a StructureSettings,
    /// The config's name (a file, or how else it was given); `None`: no config, the
    /// recommended settings and the default rules.
    pub config: Option<&'a str>,
    /// Whether the run asked for its particle count; if not, and without a config, the
    /// particle rule ([`HYSTERETIC_PARTICLES`]) may choose it.
    pub particles_asked: bool,
}

/// What [`settle`] settles.
pub struct PlanRequest<'a> {
    pub algorithm: Algorithm,
    pub data: &'a LoadedDataset,
    /// The true structure, when the data set says what it is.
    pub chain: Option<&'a ShearChain>,
    /// The settings the run starts from (a config's or the recommended ones, under the command
    /// line's overrides).
    pub settings: FilterSettings,
    pub seed: u64,
    pub run: u64,
    pub experiment: &'a str,
    pub asked: Option<Asked<'a>>,
}

/// A flag's name for a key of the `[structure]` table.
fn flag_name(key: &str) -> String {
    format!("--{key}")
}

/// Settles the plan of a run. In order: the building — simulated data carry theirs and a
/// stated key (flag or the config's `[structure]` table) must agree with it; field data take
/// the flags over the table and are refused by name when incomplete — the settings' limits, the
/// prior (given, the preset's, or scaled from the data) and the noise levels; for the MPF-EKF2
/// asked for without a config the rules of [`crate::rules`] (per-particle prior, rejuvenation,
/// particle count); then `substeps = "auto"`.
pub fn settle(req: PlanRequest) -> Result<RunPlan> {
    let PlanRequest {
        algorithm,
        data,
        chain,
        settings: mut s,
        seed,
        run,
        experiment,
        asked,
    } = req;
    if data.len() < 2 {
        bail!(
            "the data set has {} samples; at least 2 are needed",
            data.len()
        );
    }
    let mut decisions = Vec::new();
    let structure = settle_building(data, chain, &mut s, asked, &mut decisions)?;
    crate::limits::check_filter_settings(&s)?;
    let mut scan = None;
    let mut spec = assemble_spec(data, chain, &structure, &s, &mut scan)?;
    // The data-scaled prior the run uses (none when a prior is given or the data are
    // simulated).
    let scaled = (s.prior.is_none() && is_field_data(data, chain))
        .then_some(scan)
        .flatten();
    if let Some(p) = &scaled {
        decisions.push(Decision {
            rule: "scaled_prior::scaled_prior".into(),
            set: "prior".into(),
            level: Level::Info,
            why: p.describe(),
        });
    }
    if let (Algorithm::MpfEkf2, Some(asked)) = (algorithm, asked) {
        mpf_rules(&spec, &mut s, asked, scaled.as_ref(), &mut decisions);
        spec.marginal_prior = s.marginal_prior;
    }
    if asked.is_some() && crate::rules::samples_nothing(algorithm, &spec) {
        one_gaussian_filter(&mut s, &mut decisions);
    }
    let auto = resolve_substeps(algorithm, &mut spec, &s, scaled.as_ref());
    decisions.extend(substep_decisions(&auto, algorithm, &spec));
    s.liu_west()?;
    spec.validate()?;
    Ok(RunPlan {
        plan_version: PLAN_VERSION,
        algorithm,
        seed,
        run,
        experiment: experiment.to_string(),
        data_sha256: data_sha256(data),
        settings: s,
        building: structure,
        model: Model {
            prior: spec.prior,
            r_diag: spec.r_diag,
            q_disp: spec.q_disp,
            q_vel: spec.q_vel,
            q_r: spec.q_r,
            substeps: spec.substeps,
            coloured_noise: spec.coloured_noise,
            discrepancy_modes: Vec::new(),
        },
        evidence: Evidence {
            prior_from_data: scaled,
            substeps: auto,
            held_out: None,
            discrepancy: None,
            masses: None,
            channel_noise: None,
            joint_discrepancy: None,
            substep_checks: Vec::new(),
        },
        decisions,
    })
}

/// The SHA-256 of a data set as run records identify it.
pub fn data_sha256(data: &LoadedDataset) -> String {
    crate::record::fingerprint::data_identity(data)["sha256"]
        .as_str()
        .unwrap_or_default()
        .to_string()
}

/// The building of a run, resolved once (`field::resolve`): `dataset.json`'s, checked against
/// the flags and the config's table; field data's from the flags over the table (recorded in
/// `s.structure`); an in-memory simulation's from its chain.
fn settle_building(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    s: &mut FilterSettings,
    asked: Option<Asked>,
    decisions: &mut Vec<Decision>,
) -> Result<StructureDescription> {
    let Some(asked) = asked else {
        return resolve_for_run(data, chain, &s.structure);
    };
    let config_name = asked.config.unwrap_or_default();
    let table_name = |key: &str| format!("[structure] `{key}` in {config_name}");
    let both_name = |key: &str| format!("{} (or {})", flag_name(key), field::table_key(key));
    if let Some(meta) = &data.meta {
        let recorded = meta.structure()?;
        let meta_file = asked.measured.with_file_name(META);
        field::check_agrees(&recorded, asked.flags, &flag_name, &meta_file)?;
        field::check_agrees(&recorded, &s.structure, &table_name, &meta_file)?;
        s.structure = StructureSettings::default();
        return Ok(recorded);
    }
    if chain.is_some() {
        return resolve_for_run(data, chain, &s.structure);
    }
    s.structure.overlay(asked.flags);
    let d = field::resolve(data, None, &s.structure, asked.measured, &both_name)?;
    decisions.push(Decision {
        rule: "field::resolve".into(),
        set: "building".into(),
        level: Level::Info,
        why: format!(
            "field data: {} storeys, masses {:?}, hysteretic storeys {:?}, {} accelerations at \
             storeys {:?}, {} damping, the ground motion {} between its samples (no {META})",
            d.storeys,
            d.masses,
            d.hysteretic,
            d.measurement,
            d.sensors,
            d.damping,
            d.ground_between.name()
        ),
    });
    Ok(d)
}

/// The MPF-EKF2's rules for a run asked for by a person: without a config, the rejuvenation of
/// the exponents ([`crate::rules::MPF_REJUVENATION`]), the particle count of coarsely sampled
/// hysteretic field data ([`HYSTERETIC_PARTICLES`]) and the per-particle prior
/// ([`per_particle_reason`]); with a config that keeps the shared prior where that rule would
/// not, a warning.
fn mpf_rules(
    spec: &ChainSpec,
    s: &mut FilterSettings,
    asked: Asked,
    scaled: Option<&ScaledPrior>,
    decisions: &mut Vec<Decision>,
) {
    let algorithm = Algorithm::MpfEkf2;
    let (storeys, unmeasured) = (spec.n_storeys(), unmeasured_storeys(spec));
    let recommended = FilterSettings::recommended_for(algorithm, storeys, &unmeasured);
    let no_config = asked.config.is_none();
    // A linear building has no exponents to move, and its settings do not claim a move.
    let has_exponents = !spec.building.hysteretic().is_empty();
    if no_config && s.rejuvenation.is_none() && has_exponents {
        s.rejuvenation = recommended.rejuvenation;
        if let Some(d) = s.rejuvenation {
            decisions.push(Decision {
                rule: "rules::MPF_REJUVENATION".into(),
                set: format!("rejuvenation = {d}"),
                level: Level::Note,
                why: format!(
                    "the MPF-EKF2 with one shared prior Gaussian moves its sampled exponents n \
                     after every resampling (Liu–West, δ = {d}; measured to lower the damping \
                     error on the paper's structure, docs/calibration.md); --rejuvenation 1 \
                     keeps them still"
                ),
            });
        }
    }
    let per_particle = per_particle_reason(storeys, &unmeasured);
    let rule_may_apply = no_config
        && !asked.particles_asked
        && has_exponents
        && per_particle.is_none()
        && s.substeps == Substeps::Auto;
    let coarse = scaled
        .map(|p| HystereticSubsteps::new(p.omega1, spec.dt))
        .filter(|h| h.substeps > 1);
    if let (true, Some(h)) = (rule_may_apply, coarse) {
        s.particles = HYSTERETIC_PARTICLES;
        s.pool = recommended_pool(HYSTERETIC_PARTICLES);
        decisions.push(Decision {
            rule: "rules::HYSTERETIC_PARTICLES".into(),
            set: format!("particles = {}, pool = {}", s.particles, s.pool),
            level: Level::Note,
            why: format!(
                "Bouc–Wen elements sampled at ω₁·dt = {:.4} of the data-scaled ω₁ (above {}): \
                 the MPF-EKF2 takes {} particles as {} filters of {} (with {} k1 came out up to \
                 7.7 % low on a stiff building, with these at most 4.1 %; about 4 times the \
                 cost; docs/structures.md, \"Stiff buildings\"); --particles {} keeps the usual \
                 count",
                h.omega1_dt,
                h.above,
                s.particles,
                s.pool,
                s.particles / s.pool,
                RECOMMENDED_PARTICLES,
                RECOMMENDED_PARTICLES,
            ),
        });
    }
    if let Some(reason) = per_particle {
        if no_config {
            s.marginal_prior = recommended.marginal_prior;
            decisions.push(Decision {
                rule: "rules::per_particle_reason".into(),
                set: format!("marginal_prior = per_particle (rel_sd {SPARSE_REL_SD})"),
                level: Level::Note,
                why: format!(
                    "{reason}: the MPF-EKF2 starts every particle from its own prior mean \
                     (marginal_prior = {{ kind = \"per_particle\", rel_sd = {SPARSE_REL_SD} }}; \
                     with one shared prior Gaussian it loses its particles where storeys carry \
                     no sensor, docs/scaling.md, and is less accurate from \
                     {PER_PARTICLE_MIN_STOREYS} storeys on, docs/calibration.md)"
                ),
            });
        } else if s.marginal_prior == MarginalPrior::MomentMatched {
            decisions.push(Decision {
                rule: "rules::per_particle_reason".into(),
                set: String::new(),
                level: Level::Warning,
                why: format!(
                    "{reason} and the MPF-EKF2 starts from one moment-matched prior Gaussian \
                     (marginal_prior = {{ kind = \"moment_matched\" }}): where storeys carry no \
                     sensor it drives their stiffnesses below zero and loses all its particles \
                     in most runs at 20 and 40 storeys (docs/scaling.md), and at 10 storeys its \
                     mean stiffness error was 16 % against 4 % (docs/calibration.md); set \
                     marginal_prior = {{ kind = \"per_particle\", rel_sd = {SPARSE_REL_SD} }}"
                ),
            });
        }
    }
}

/// A run that samples nothing ([`crate::rules::samples_nothing`]) is one Gaussian filter: one
/// particle, no pool.
fn one_gaussian_filter(s: &mut FilterSettings, decisions: &mut Vec<Decision>) {
    let asked = (s.particles, s.pool);
    s.particles = 1;
    s.pool = 1;
    decisions.push(Decision {
        rule: "rules::samples_nothing".into(),
        set: "particles = 1, pool = 1".into(),
        level: Level::Note,
        why: format!(
            "the building has no hysteretic element and the MPF-EKF2 starts from one shared \
             prior Gaussian: it samples nothing, so each of {} particles ({} filter(s)) would \
             carry the same Gaussian; the run is that one Gaussian filter (EKF2), whose \
             intervals have no Monte-Carlo error",
            asked.0, asked.1
        ),
    });
}

/// What `substeps = "auto"` chose, as decisions (the lines `sysid filter` prints).
fn substep_decisions(auto: &AutoChoice, algorithm: Algorithm, spec: &ChainSpec) -> Vec<Decision> {
    let mut out = Vec::new();
    if let Some(h) = auto.hysteretic.filter(|h| h.substeps > 1) {
        out.push(hysteretic_substeps_decision(&h, spec));
    }
    if let Some(l) = auto.lag {
        out.push(lag_substeps_decision(&l, spec));
    }
    if let Some(f) = auto.field {
        out.push(field_substeps_decision(&f, spec));
    }
    if let Some(a) = auto.linear {
        linear_substep_decisions(&a, auto.field.is_some(), algorithm, spec, &mut out);
    }
    out
}

/// The Bouc–Wen rule's sub-steps: ω₁·dt above its limit, and whether the count it took
/// brought it under.
fn hysteretic_substeps_decision(h: &HystereticSubsteps, spec: &ChainSpec) -> Decision {
    Decision {
        rule: "scaled_prior::hysteretic_substeps".into(),
        set: format!("substeps = {}", spec.substeps),
        level: Level::Info,
        why: {
            let per = h.omega1_dt / h.substeps as f64;
            let reached = if per <= h.max_omega1_h {
                format!("ω₁·dt/{} = {per:.4} ≤ {}", h.substeps, h.max_omega1_h)
            } else {
                format!(
                    "ω₁·dt/{} = {per:.4}, still above {}: {} is the most this rule takes \
                     (sample faster, or give --substeps)",
                    h.substeps,
                    h.max_omega1_h,
                    crate::scaled_prior::HYSTERETIC_MAX_SUBSTEPS
                )
            };
            format!(
                "sub-steps: {} per sample (auto: Bouc–Wen elements and ω₁·dt = {:.4} above \
                 {}; {reached})",
                spec.substeps, h.omega1_dt, h.above
            )
        },
    }
}

/// The velocity-lag rule's sub-steps (MPF-EKF2, one shared prior Gaussian, a small
/// hysteretic building).
fn lag_substeps_decision(l: &LagSubsteps, spec: &ChainSpec) -> Decision {
    Decision {
        rule: "rules::LAG_SUBSTEPS".into(),
        set: format!("substeps = {}", spec.substeps),
        level: Level::Info,
        why: format!(
            "sub-steps: {} per sample (auto: the MPF-EKF2 with one shared prior Gaussian on a \
             hysteretic building below {PER_PARTICLE_MIN_STOREYS} storeys, whose velocity \
             lag with one step, {:.1} %, is above {:.0} %; measured to lower the stiffness \
             error at 5 storeys at about 3 times the cost: docs/calibration.md, \"The prior \
             or the size?\"; --substeps 1 to keep one step)",
            spec.substeps,
            100.0 * l.lag_one,
            100.0 * l.above
        ),
    }
}

/// A mode's frequency shift with one step per sample, `error` (a fraction), as a percentage of
/// `digits` decimals — or, past the semi-implicit Euler step's stability limit (ω·dt ≥ 2, where
/// [`models::filtering::substeps::frequency_error`] is infinite), says that one step does not
/// oscillate at that frequency at all.
fn one_step_shift(error: f64, digits: usize) -> String {
    if error.is_finite() {
        format!("{:.digits$} %", 100.0 * error)
    } else {
        "∞ (one step is unstable there: ω·dt ≥ 2, the step's stability limit)".into()
    }
}

/// The field-data rule's sub-steps (a linear building run as one Gaussian filter): the highest
/// mode's frequency shift with one step and with the count taken.
fn field_substeps_decision(f: &crate::rules::FieldSubsteps, spec: &ChainSpec) -> Decision {
    Decision {
        rule: "rules::FIELD_FREQUENCY_ERROR".into(),
        set: format!("substeps = {}", spec.substeps),
        level: Level::Info,
        why: format!(
            "sub-steps: {} per sample (auto, field data of a linear building, one Gaussian \
             filter: the highest mode's frequency shift {} with one step, {:.3} % with \
             {}, at most {:.2} %, because the free run's phase over a lightly damped mode's \
             many cycles is that shift over ζ: docs/real-frame.md)",
            spec.substeps,
            one_step_shift(f.error_one, 2),
            100.0 * f.error_chosen,
            f.substeps,
            100.0 * crate::rules::FIELD_FREQUENCY_ERROR
        ),
    }
}

/// The linear rule's decisions: a warning when an algorithm that cannot sub-step keeps a
/// biasing single step, the count it raised (unless the field rule says so: `field_raised`),
/// and a note of the stiffness bias left by the run's step's velocity lag.
fn linear_substep_decisions(
    a: &models::filtering::substeps::AutoSubsteps,
    field_raised: bool,
    algorithm: Algorithm,
    spec: &ChainSpec,
    out: &mut Vec<Decision>,
) {
    use models::filtering::substeps::{LAG_NOTED_ABOVE, SUBSTEP_ABOVE};
    if a.substeps == 1 && a.error_one > SUBSTEP_ABOVE {
        out.push(Decision {
            rule: "models::filtering::substeps::auto_substeps".into(),
            set: String::new(),
            level: Level::Warning,
            why: format!(
                "the prior's building has modes up to {:.2} Hz (ω·dt = {:.2}): one step per \
                 sample shifts that mode by {}, and {} cannot sub-step; its \
                 frequencies and stiffnesses carry that bias (MPF-EKF2 and the bootstrap \
                 PF sub-step)",
                a.omega_max / std::f64::consts::TAU,
                a.omega_max * spec.dt,
                one_step_shift(a.error_one, 1),
                algorithm.label()
            ),
        });
    }
    // The field rule's message says what the run takes when it raised the count.
    if a.substeps > 1 && !field_raised {
        out.push(Decision {
            rule: "models::filtering::substeps::auto_substeps".into(),
            set: format!("substeps = {}", spec.substeps),
            level: Level::Info,
            why: format!(
                "sub-steps: {} per sample (auto: the prior's building has modes up to {:.2} \
                 Hz, ω·dt = {:.2}; one step per sample would shift that mode by {}, {} \
                 by {:.2} %)",
                a.substeps,
                a.omega_max / std::f64::consts::TAU,
                a.omega_max * spec.dt,
                one_step_shift(a.error_one, 1),
                a.substeps,
                100.0 * a.error_chosen
            ),
        });
    }
    // The lag of the run's step (proportional to it): the Bouc–Wen rule may have raised
    // the sub-steps beyond the linear rule's.
    let lag = a.lag_one / spec.substeps as f64;
    if lag > LAG_NOTED_ABOVE {
        out.push(Decision {
            rule: "models::filtering::substeps::damping_lag_error".into(),
            set: String::new(),
            level: Level::Note,
            why: format!(
                "with {} step(s) per sample the model favours stiffnesses up to {:.1} % low \
                 (with the prior's central dashpots and springs), most at the top storeys \
                 (the semi-implicit step's velocity lag; docs/calibration.md, \"The top \
                 storeys' bias\"). --substeps M divides it by M; on the scaling study's \
                 buildings 4 took the MPF-EKF2's mean stiffness error from 3.5 to 2.0 % at \
                 5 storeys with one shared prior Gaussian (which is why `auto` takes them \
                 there) and did not pay with per-particle prior means (5 and 10 storeys; \
                 worse at 20), at about 3 times the cost (docs/calibration.md, \"The prior \
                 or the size?\")",
                spec.substeps,
                100.0 * lag
            ),
        });
    }
}

/// The responses of the discrepancy `modes` to the ground motion of `data` as regressors of the
/// filter ([`models::filtering::Regressors`]): each mode's `ω² q` and `ω q̇`
/// ([`models::integrate::oscillator_basis`], the discrepancy term's own columns), and for the
/// coefficient of column c in channel i a prior s.d. of RMS(y_i)/RMS(column c) — wide enough for
/// one column alone to carry the whole channel.
fn discrepancy_regressors(
    modes: &[crate::record::validation::DiscrepancyMode],
    data: &LoadedDataset,
) -> models::filtering::Regressors {
    let columns: Vec<Vec<f64>> = modes
        .iter()
        .flat_map(|m| {
            models::integrate::oscillator_basis(
                m.frequency_hz,
                m.damping_ratio,
                &data.ug_meas,
                data.dt,
            )
        })
        .collect();
    let rms = |xs: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = xs.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
        (sum / n.max(1) as f64).sqrt()
    };
    let ny = data.channels;
    let mut prior_sd = Vec::with_capacity(ny * columns.len());
    for i in 0..ny {
        let ry = rms(&mut data.y_meas.iter().skip(i).step_by(ny).copied());
        for c in &columns {
            let rc = rms(&mut c.iter().copied());
            // A column the record does not excite: any positive s.d. (it is never informed).
            prior_sd.push(if rc > 0.0 && ry > 0.0 { ry / rc } else { 1.0 });
        }
    }
    models::filtering::Regressors { columns, prior_sd }
}

impl RunPlan {
    /// Whether the run holds k, c and α at ≥ 0 (its physical support; Storvik's sampler does
    /// not), so that a widened interval is held at 0 too.
    pub fn holds_bounds(&self) -> bool {
        self.settings.physical_support && self.algorithm != Algorithm::Storvik
    }

    /// The filter partitions' specification of this plan on `data` (the data the plan was
    /// settled on): the building, the prior and noise levels of [`Model`], the settings'
    /// discretisation and marginal prior, the measured ground acceleration, and the regressors
    /// of [`Model::discrepancy_modes`] on it.
    pub fn spec(&self, data: &LoadedDataset) -> Result<ChainSpec> {
        let spec = ChainSpec {
            dt: data.dt,
            building: self.building.building()?,
            sensors: self.building.sensor_layout()?,
            ug: data.ug_meas.clone(),
            q_disp: self.model.q_disp,
            q_vel: self.model.q_vel,
            q_r: self.model.q_r.clone(),
            r_diag: self.model.r_diag.clone(),
            prior: self.model.prior.clone(),
            marginal_prior: self.settings.marginal_prior,
            discretisation: self.settings.discretisation,
            substeps: self.model.substeps,
            physical_support: self.settings.physical_support,
            coloured_noise: self.model.coloured_noise,
            ground_between: self.building.ground_between,
            regressors: (!self.model.discrepancy_modes.is_empty())
                .then(|| discrepancy_regressors(&self.model.discrepancy_modes, data)),
        };
        if spec.sensors.len() != data.channels {
            bail!(
                "{} sensors in the plan's building, {} channels in the data",
                spec.sensors.len(),
                data.channels
            );
        }
        spec.validate()?;
        Ok(spec)
    }

    /// The plan as a TOML file (`sysid filter --print-plan`), read back by [`RunPlan::from_toml`]
    /// to the same plan.
    pub fn to_toml(&self) -> Result<String> {
        let body = toml::to_string(self).context("writing the plan as TOML")?;
        Ok(format!(
            "# The plan of one `sysid filter` run: `sysid filter --plan FILE --data DIR --out R` \
             runs exactly it.\n# Every key may be edited; `decisions` and `evidence` are the \
             record of how it was settled.\n{body}"
        ))
    }

    /// A plan read from TOML text; `name` names the file in errors.
    pub fn from_toml(text: &str, name: &str) -> Result<Self> {
        let plan: RunPlan =
            toml::from_str(text).map_err(|e| invalid!("{name}: not a run plan: {e}"))?;
        if plan.plan_version != PLAN_VERSION {
            bail!(
                "{name}: field `plan_version`: {} (this build reads plans of version \
                 {PLAN_VERSION})",
                plan.plan_version
            );
        }
        crate::limits::check_filter_settings(&plan.settings)
            .with_context(|| format!("{name}: field `settings`"))?;
        Ok(plan)
    }

    /// Refuses `data` when it is not the data the plan was settled on.
    pub fn check_data(&self, data: &LoadedDataset, name: &str) -> Result<()> {
        let sha = data_sha256(data);
        if sha != self.data_sha256 {
            bail!(
                "{name}: field `data_sha256`: the plan was settled on other data ({}…, these \
                 are {}…); settle a plan on these data with --print-plan",
                &self.data_sha256.get(..12).unwrap_or(&self.data_sha256),
                &sha.get(..12).unwrap_or(&sha)
            );
        }
        Ok(())
    }

    /// The plan a record was run with (records of `sysid filter` and the Python `identify`
    /// carry it); `None` for a record without one.
    pub fn of_record(record: &crate::record::RunRecord) -> Result<Option<Self>> {
        record
            .plan
            .as_ref()
            .map(|v| {
                serde_json::from_value(v.clone())
                    .map_err(|e| invalid!("field `plan` of the record: {e}"))
            })
            .transpose()
    }

    /// What a person reads before the run: the algorithm, the building, particles and pooling,
    /// sub-steps, prior, noise levels, and every decision.
    pub fn describe(&self) -> String {
        let s = &self.settings;
        let b = &self.building;
        let mut out = format!(
            "plan: {} on {} storeys (masses {:?}, hysteretic storeys {:?}, {} damping), {} \
             accelerations at storeys {:?}\n",
            self.algorithm.label(),
            b.storeys,
            b.masses,
            b.hysteretic,
            b.damping,
            b.measurement,
            b.sensors,
        );
        out += &format!(
            "  particles {} as {} filter(s), {} resampling{}, {} discretisation, {} \
             transition(s) per sample, rejuvenation {}\n",
            s.particles,
            s.pool,
            s.resampling.name(),
            s.ess_threshold
                .map(|t| format!(" when ESS < {t} × particles"))
                .unwrap_or_else(|| " at every step".into()),
            s.discretisation.name(),
            self.model.substeps,
            s.rejuvenation
                .map(|d| format!("δ = {d}"))
                .unwrap_or_else(|| "none".into()),
        );
        let names = self.model.prior.names();
        let fixed: Vec<String> = s.fix.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        out += &format!(
            "  θ: {} ({} parameters{}); seed {}, run {}\n",
            names.join(", "),
            names.len(),
            if fixed.is_empty() {
                String::new()
            } else {
                format!("; fixed {}", fixed.join(", "))
            },
            self.seed,
            self.run
        );
        out += &format!(
            "  noise: measurement s.d. [{}] m/s², process s.d. x {:.3e}, v {:.3e}, r [{}]\n",
            self.model
                .r_diag
                .iter()
                .map(|r| format!("{:.3e}", r.sqrt()))
                .collect::<Vec<_>>()
                .join(", "),
            self.model.q_disp,
            self.model.q_vel,
            self.model
                .q_r
                .iter()
                .map(|q| format!("{q:.3e}"))
                .collect::<Vec<_>>()
                .join(", "),
        );
        for d in &self.decisions {
            out += &format!("  [{}] {d}\n", d.rule);
        }
        out
    }
}

/// Root mean square of a signal.
fn rms_of(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (s / n.max(1) as f64).sqrt()
}

/// RMS values that set Q and R (SPEC §3): from the data set's metadata and truth (clean signals)
/// when present, otherwise estimated from the measured signals. `storeys` is N, `sensors` the
/// 0-based storey of each channel, `hysteretic` the 0-based storeys of the hysteretic elements
/// (one drift-velocity RMS each).
fn rms_levels(
    data: &LoadedDataset,
    storeys: usize,
    sensors: &[usize],
    kind: MeasurementKind,
    hysteretic: &[usize],
    nf: f64,
) -> RmsLevels {
    let k = data.len();
    let n = storeys;
    if let Some(meta) = &data.meta {
        // The drift velocity of element j is v_j − v_{j−1}: from the true states when present.
        let drift = hysteretic
            .iter()
            .map(|&j| match &data.truth {
                Some(t) => rms_of((0..t.states.len()).map(|i| {
                    let st = t.states.state(i);
                    st[n + j] - if j == 0 { 0.0 } else { st[n + j - 1] }
                })),
                None => meta.rms.vel[j],
            })
            .collect();
        return RmsLevels {
            acc: meta.rms.acc.clone(),
            ug: meta.rms.ug,
            drift_velocity: drift,
        };
    }
    // Field data: a measured channel holds the clean signal plus noise of s.d. nf·RMS(clean),
    // so RMS(measured) = RMS(clean)·√(1 + nf²).
    let clean = (1.0 + nf * nf).sqrt();
    let m = sensors.len();
    let acc: Vec<f64> = (0..m)
        .map(|c| rms_of((0..k).map(|i| data.y(i)[c])) / clean)
        .collect();
    let ug = rms_of(data.ug_meas.iter().copied()) / clean;
    // Relative velocity of channel c: the trapezoidal integral of its relative acceleration
    // (absolute minus ü_g for absolute data) with its linear trend removed (the drift of
    // integrated noise).
    let relative = |i: usize, c: usize| -> f64 {
        let y = data.y(i)[c];
        match kind {
            MeasurementKind::Relative => y,
            MeasurementKind::Absolute => y - data.ug_meas[i],
        }
    };
    let velocity = |c: usize| -> Vec<f64> {
        let mut v = vec![0.0; k];
        for i in 1..k {
            v[i] = v[i - 1] + 0.5 * data.dt * (relative(i - 1, c) + relative(i, c));
        }
        let slope = v[k - 1] / (k.max(2) - 1) as f64;
        v.iter()
            .enumerate()
            .map(|(i, x)| x - slope * i as f64)
            .collect()
    };
    let channel = |storey: usize| sensors.iter().position(|&s| s == storey);
    let drift = hysteretic
        .iter()
        .map(|&j| {
            match (channel(j), j.checked_sub(1).map(channel)) {
                // The element's storey and the one below (or the ground) are measured.
                (Some(c), None) => rms_of(velocity(c).into_iter()),
                (Some(c), Some(Some(b))) => {
                    let (vj, vb) = (velocity(c), velocity(b));
                    rms_of(vj.iter().zip(&vb).map(|(a, b)| a - b))
                }
                // Otherwise the mean drift per storey below the nearest measured storey s
                // (above j when there is one): RMS v_s / (s + 1). A scale only, for the
                // hysteretic variable's process noise (q_r = 0.05·dt·RMS δv, SPEC §3).
                _ => {
                    let c = sensors.iter().position(|&s| s >= j).unwrap_or(m - 1);
                    rms_of(velocity(c).into_iter()) / (sensors[c] + 1) as f64
                }
            }
        })
        .collect();
    RmsLevels {
        acc,
        ug,
        drift_velocity: drift,
    }
}

/// Builds the specification of a run's filter partitions: the structure of the data
/// ([`resolve_for_run`]: `dataset.json`, else the true chain, else the settings' `[structure]`
/// for field data — refused when incomplete), the measured storeys of the header, noise levels
/// from RMS values (SPEC §3), the prior and the discretisation.
pub fn chain_spec(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    s: &FilterSettings,
) -> Result<ChainSpec> {
    let structure = resolve_for_run(data, chain, &s.structure)?;
    assemble_spec(data, chain, &structure, s, &mut None)
}

/// [`chain_spec`] on a building already resolved; `scan` holds the data-scaled prior once it
/// has been computed (it is computed at most once, and only where the prior needs it).
fn assemble_spec(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    structure: &StructureDescription,
    s: &FilterSettings,
    scan: &mut Option<ScaledPrior>,
) -> Result<ChainSpec> {
    let n = structure.storeys;
    let building = structure.building()?;
    let hysteretic = building.hysteretic().to_vec();
    let sensors = structure.sensor_layout()?;
    if sensors.len() != data.channels {
        bail!(
            "{} sensors in the structure, {} channels in the data",
            sensors.len(),
            data.channels
        );
    }
    let rms = rms_levels(
        data,
        n,
        sensors.storeys(),
        sensors.kind(),
        &hysteretic,
        s.noise_fraction,
    );
    let mut spec = ChainSpec::from_rms(
        data.dt,
        building.clone().with_damping(Damping::Storey),
        sensors,
        data.ug_meas.clone(),
        &rms,
        s.noise_fraction,
    )?;
    spec.marginal_prior = s.marginal_prior;
    spec.set_r_noise_fraction(s.r_noise_fraction)?;
    spec.discretisation = s.discretisation;
    spec.physical_support = s.physical_support;
    spec.q_vel *= s.process_noise_factor;
    spec.coloured_noise = s.coloured_noise;
    spec.substeps = match s.substeps {
        Substeps::Fixed(m) => m,
        // Chosen per algorithm once the prior is known (`resolve_substeps`).
        Substeps::Auto => 1,
    };
    // The building's damping form, whose α gets its prior below.
    spec.building = building;
    // Default priors: SPEC §3's for simulated data (the paper's scale); for field data scaled
    // from the measured response (`scaled_prior`).
    let mut prior = match (&s.prior, is_field_data(data, chain)) {
        (Some(p), _) => p.clone(),
        (None, true) => scanned(scan, data, structure)?.prior.clone(),
        // Simulated data: the preset's (SPEC §3's, carried to the structure's values for a
        // preset whose storeys are not the paper's).
        (None, false) => match (data.meta.as_ref(), chain) {
            (Some(meta), Some(chain)) if chain.storeys() == n => {
                models::preset::Preset::default_prior(&meta.config.preset, chain, &hysteretic)
            }
            _ => ChainPrior::paper(n, &hysteretic),
        },
    };
    // The storey+mass form's α: a default prior centred from the structure's first mode
    // (`models::filtering::prior::alpha_prior`) unless the prior states one. A given `[prior]`
    // without `alpha` is refused by the spec's validation, naming `prior.alpha`.
    if structure.damping.has_mass_term() && prior.alpha.is_none() && s.prior.is_none() {
        prior.alpha = Some(match (is_field_data(data, chain), chain) {
            (false, Some(chain)) => {
                let w1 = models::modal::modes(chain)
                    .ok()
                    .and_then(|m| m.modes.first().map(|m| m.frequency_hz))
                    .context(
                        "the true structure has no under-damped mode to centre α's prior on",
                    )?
                    * std::f64::consts::TAU;
                models::filtering::prior::alpha_prior(w1)
            }
            _ => scanned(scan, data, structure)?
                .prior
                .alpha
                .context("the scaled prior of the storey+mass form has α")?,
        });
    }
    for (name, value) in &s.fix {
        prior
            .fix(name, *value)
            .with_context(|| format!("fixing {name} = {value}"))?;
    }
    spec.prior = prior;
    spec.validate()?;
    Ok(spec)
}

/// Field data: neither `dataset.json` nor a known true structure.
pub(crate) fn is_field_data(data: &LoadedDataset, chain: Option<&ShearChain>) -> bool {
    data.meta.is_none() && chain.is_none()
}

/// The data-scaled default prior of a field-data run (printed by `sysid filter` and recorded
/// under `config.prior_from_data`), `None` when the run uses another prior.
pub fn prior_from_data(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    s: &FilterSettings,
) -> Result<Option<crate::scaled_prior::ScaledPrior>> {
    if s.prior.is_some() || !is_field_data(data, chain) {
        return Ok(None);
    }
    let structure = resolve_for_run(data, chain, &s.structure)?;
    Ok(Some(crate::scaled_prior::scaled_prior(data, &structure)?))
}

/// The data-scaled prior of `structure`, scanned from the data the first time it is asked for.
fn scanned<'a>(
    scan: &'a mut Option<ScaledPrior>,
    data: &LoadedDataset,
    structure: &StructureDescription,
) -> Result<&'a ScaledPrior> {
    if scan.is_none() {
        *scan = Some(crate::scaled_prior::scaled_prior(data, structure)?);
    }
    Ok(scan.as_ref().expect("just scanned"))
}

/// What `substeps = "auto"` chose for a run: by the linear modes of the prior's building
/// ([`models::filtering::substeps`]), on field data with Bouc–Wen elements by the data-scaled
/// ω₁·dt (`crate::scaled_prior::hysteretic_substeps`) and, for the MPF-EKF2 with one shared
/// prior Gaussian below [`PER_PARTICLE_MIN_STOREYS`] storeys, by the velocity lag
/// ([`LagSubsteps`]); the run takes the largest.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct AutoChoice {
    pub linear: Option<models::filtering::substeps::AutoSubsteps>,
    pub hysteretic: Option<crate::scaled_prior::HystereticSubsteps>,
    pub lag: Option<LagSubsteps>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<crate::rules::FieldSubsteps>,
}

/// Resolves `substeps = "auto"` for the algorithms that sub-step (MPF-EKF2, bootstrap PF);
/// MLN-RBPF and Storvik keep one transition per sample. `scaled` is the run's data-scaled
/// prior ([`prior_from_data`]), if it has one. Returns what was chosen automatically (nothing
/// for a fixed number).
pub fn resolve_substeps(
    algorithm: Algorithm,
    spec: &mut ChainSpec,
    s: &FilterSettings,
    scaled: Option<&crate::scaled_prior::ScaledPrior>,
) -> AutoChoice {
    if s.substeps != Substeps::Auto {
        return AutoChoice::default();
    }
    let sub_steps = !matches!(algorithm, Algorithm::MlnRbpf | Algorithm::Storvik);
    let mut a = models::filtering::substeps::auto_substeps(spec);
    if !sub_steps {
        a.substeps = 1;
        a.error_chosen = a.error_one;
    }
    spec.substeps = a.substeps;
    let hysteretic = match scaled {
        Some(p) if sub_steps && !spec.building.hysteretic().is_empty() => {
            let h = crate::scaled_prior::HystereticSubsteps::new(p.omega1, spec.dt);
            spec.substeps = spec.substeps.max(h.substeps);
            Some(h)
        }
        _ => None,
    };
    let above = models::filtering::substeps::LAG_NOTED_ABOVE;
    let lag = (algorithm == Algorithm::MpfEkf2
        && s.marginal_prior == models::filtering::MarginalPrior::MomentMatched
        && !spec.building.hysteretic().is_empty()
        && spec.building.storeys() < PER_PARTICLE_MIN_STOREYS
        && a.lag_one / spec.substeps as f64 > above)
        .then(|| {
            spec.substeps = spec.substeps.max(LAG_SUBSTEPS);
            LagSubsteps {
                lag_one: a.lag_one,
                above,
                substeps: LAG_SUBSTEPS,
            }
        });
    let field = (scaled.is_some() && crate::rules::samples_nothing(algorithm, spec))
        .then(|| crate::rules::FieldSubsteps::new(a.omega_max * spec.dt))
        .flatten()
        .inspect(|f| spec.substeps = spec.substeps.max(f.substeps));
    AutoChoice {
        linear: Some(a),
        hysteretic,
        lag,
        field,
    }
}

#[cfg(test)]
mod tests {
    use super::{
        one_step_shift, JointDiscrepancy, MassChoice, Moved, SubstepConvergence, SubstepRun,
    };

    /// Past ω·dt = 2 one step has no frequency to shift: said, not printed as "inf %".
    #[test]
    fn one_step_past_its_stability_limit_is_said_unstable() {
        use models::filtering::substeps::frequency_error;
        assert_eq!(one_step_shift(frequency_error(0.5), 2), "1.07 %");
        // The shake-table frame decimated to 40 Hz: its third mode at ω·dt ≈ 2.6.
        let past = one_step_shift(frequency_error(2.6), 1);
        assert!(!past.contains("inf") && past.contains("unstable"), "{past}");
    }

    /// The sub-step check's decision lists the counts and moves and says whether it converged,
    /// ran out of counts, or stopped at a failed run; the run takes the last count that ran.
    #[test]
    fn the_substep_check_says_how_it_ended() {
        let run = |substeps: usize, moved: Option<f64>| SubstepRun {
            substeps,
            theta_val: vec![1.0],
            sd: vec![0.1],
            moved: moved.map(|sd| Moved {
                parameter: "k3".into(),
                sd,
            }),
            others_moved: moved.map(|sd| Moved {
                parameter: "c2".into(),
                sd: 2.0 * sd,
            }),
        };
        let mut c = SubstepConvergence {
            samples: 1000,
            whole: true,
            tolerance: 0.25,
            runs: vec![run(8, None), run(16, Some(0.9)), run(32, Some(0.2))],
            converged: true,
            note: None,
        };
        assert_eq!(c.substeps(), Some(32));
        let d = c.describe();
        assert!(d.contains("8 → 16 → 32 per sample"), "{d}");
        assert!(d.contains("0.90 (k3), 0.20 (k3)"), "{d}");
        assert!(
            d.contains("the others by at most 1.80 (c2), 0.40 (c2)"),
            "{d}"
        );
        assert!(d.contains("converged"), "{d}");
        assert!(
            d.starts_with("sub-steps checked on the whole record"),
            "{d}"
        );
        c.whole = false;
        let d = c.describe();
        assert!(
            d.starts_with("sub-steps checked on the first 1000 samples"),
            "{d}"
        );
        c.converged = false;
        assert!(c.describe().contains("not converged"), "{}", c.describe());
        c.note = Some("the run with 64 sub-steps failed: NaN".into());
        assert!(
            c.describe().contains("stopped: the run with 64"),
            "{}",
            c.describe()
        );
        let back: SubstepConvergence =
            serde_json::from_value(serde_json::to_value(&c).unwrap()).unwrap();
        assert_eq!(back, c);
        c.runs.clear();
        assert_eq!(c.substeps(), None);
        assert!(c
            .describe()
            .contains("each step up moved the stiffnesses by at most — "));
    }

    /// The joint identification's decision says which way the run went, with both held-out fits,
    /// or why it could not be scored; it reads back from a record's JSON.
    #[test]
    fn the_joint_discrepancy_says_which_way_and_why() {
        let mut j = JointDiscrepancy {
            after_fit: vec![80.0, 70.0],
            joint_fit: vec![60.0, 50.0],
            joint_building_fit: vec![10.0, 20.0],
            kept: false,
            held_out_error: None,
            note: None,
        };
        let text = j.describe();
        assert!(
            text.starts_with("θ identified without the discrepancy modes"),
            "{text}"
        );
        assert!(text.contains("held-out fit 55.0 % (60.0 / 50.0)"), "{text}");
        assert!(text.contains("the building alone 10.0 / 20.0 %"), "{text}");
        assert!(text.contains("held-out fit 75.0 % (80.0 / 70.0)"), "{text}");
        j.kept = true;
        assert!(j
            .describe()
            .starts_with("θ identified with the discrepancy modes"));
        let back: JointDiscrepancy =
            serde_json::from_str(&serde_json::to_string(&j).unwrap()).unwrap();
        assert_eq!(back, j);
        j.note = Some("the run failed: x".into());
        assert!(
            j.describe().ends_with(": the run failed: x"),
            "{}",
            j.describe()
        );
    }

    /// A search whose every run failed has no log-likelihood: the evidence says so and reads back
    /// from a record's JSON (a −∞ would be written as `null` and not read back).
    #[test]
    fn a_failed_masses_search_reads_back_from_json() {
        let mut m = MassChoice::searched((vec![1.0, 1.0], vec![1.0, 1.0]), (None, None), 5, 5);
        m.note = Some("no move raised the log-likelihood".into());
        let text = serde_json::to_string(&m).unwrap();
        assert_eq!(serde_json::from_str::<MassChoice>(&text).unwrap(), m);
        let d = m.describe();
        assert!(
            d.contains("(log-likelihood run failed)") && d.contains("5 of them failed"),
            "{d}"
        );
        assert!(d.contains("the stated masses are kept"), "{d}");
    }

    /// A learned level without an interval (a flat or failed neighbourhood) and one at the
    /// search's bound read back from a record's JSON and a plan's TOML, and say so.
    #[test]
    fn learned_noise_without_an_interval_reads_back_and_says_so() {
        let n = super::ChannelNoise {
            settled_sd: vec![0.1, 0.2],
            learned_sd: vec![0.05, 2.0],
            learned_sd_95: vec![super::LevelInterval {
                channel: "a1".into(),
                lo: 0.04,
                hi: 0.06,
            }],
            channels: vec!["a1".into(), "a2".into()],
            loglik_settled: Some(-10.0),
            loglik_learned: None,
            evaluations: 9,
            failed_evaluations: 2,
            at_bound: vec!["a2".into()],
        };
        let json = serde_json::to_string(&n).unwrap();
        assert_eq!(
            serde_json::from_str::<super::ChannelNoise>(&json).unwrap(),
            n
        );
        let toml = toml::to_string(&n).unwrap();
        assert_eq!(toml::from_str::<super::ChannelNoise>(&toml).unwrap(), n);
        let d = n.describe();
        assert!(d.contains("5.000e-2 [4.000e-2, 6.000e-2]"), "{d}");
        assert!(d.contains("2.000e0 [no interval]"), "{d}");
        assert!(d.contains("a2 at the search's bound"), "{d}");
        assert!(
            d.contains("(log-likelihood run failed)") && d.contains("2 of them failed"),
            "{d}"
        );
    }
}
