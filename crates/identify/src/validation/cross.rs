//! Cross-validation (`sysid validate`): the model identified on one record predicts another
//! record of the same building from its ground motion alone (free run, fit and NRMSE per
//! channel, a band from the first record's posterior, each draw shifted by the spread between
//! that record's parts as θ of another record), and its modes are set beside the other
//! record's transfer-function peaks (docs/validation.md).

use std::path::Path;

use crate::error::{bail, Context, Result};
use models::dataset::{load_dir, MEASURED, META};
use models::description::StructureDescription;
use serde::{Deserialize, Serialize};

use super::{FreeRun, ModalComparison};
use crate::record::{number, RunRecord};

/// The result of a cross-validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossValidation {
    /// The record the model was identified on, and the record it predicts.
    pub record: String,
    pub data: String,
    pub algorithm: String,
    pub seed: u64,
    pub run: u64,
    pub structure: StructureDescription,
    pub param_names: Vec<String>,
    #[serde(with = "number::vec")]
    pub theta_val: Vec<f64>,
    pub free_run: FreeRun,
    pub modal: ModalComparison,
    /// What was assumed about the other record.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// Most draws accepted.
pub(crate) const MAX_DRAWS: usize = 10_000;

/// Reads and checks a run record (the one bounded, checked record reader,
/// `record::read::read`).
pub fn read_record(path: &Path) -> Result<RunRecord> {
    Ok(crate::record::read::read::<RunRecord>(path)?)
}

/// Refuses another record whose building differs from the identified one; returns notes on
/// what is assumed of it.
pub(crate) fn check_same_building(
    d: &StructureDescription,
    data: &models::dataset::LoadedDataset,
    dir: &Path,
) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    match &data.meta {
        Some(meta) => {
            let other = meta
                .structure()
                .with_context(|| format!("{}", dir.join(META).display()))?;
            let mut diffs = Vec::new();
            if other.storeys != d.storeys {
                diffs.push(format!("storeys {} against {}", other.storeys, d.storeys));
            }
            if other.masses != d.masses {
                diffs.push(format!("masses {:?} against {:?}", other.masses, d.masses));
            }
            if other.hysteretic != d.hysteretic {
                diffs.push(format!(
                    "hysteretic storeys {:?} against {:?}",
                    other.hysteretic, d.hysteretic
                ));
            }
            if other.measurement != d.measurement {
                diffs.push(format!(
                    "measurement {} against {}",
                    other.measurement, d.measurement
                ));
            }
            if !diffs.is_empty() {
                bail!(
                    "{} describes another building than the record's: {} — cross-validation \
                     predicts a record of the same building",
                    dir.join(META).display(),
                    diffs.join(", ")
                );
            }
        }
        None => notes.push(format!(
            "{} has no {META}: taken to be a record of the identified building ({} storeys, \
             {} accelerations)",
            dir.display(),
            d.storeys,
            d.measurement
        )),
    }
    if let Some(&s) = data.sensors.iter().find(|&&s| s > d.storeys) {
        bail!(
            "{}: column a{s}: the identified building has only {} storeys",
            dir.join(MEASURED).display(),
            d.storeys
        );
    }
    if data.sensors != d.sensors {
        notes.push(format!(
            "measured storeys {:?} (the identification used {:?})",
            data.sensors, d.sensors
        ));
    }
    Ok(notes)
}

/// A cross-validation with the record it started from.
#[derive(Debug, Clone)]
pub struct CrossValidated {
    /// The run record of the identification.
    pub record: RunRecord,
    pub result: CrossValidation,
}

/// Cross-validates the identification of the run record at `record_path` on the data set at
/// `data_dir`, with a band of `draws` posterior draws (0: no band; else 2 to `MAX_DRAWS`).
/// `note` hears what is assumed of the other record and why there is no band, in order.
pub fn cross_validate(
    record_path: &Path,
    data_dir: &Path,
    draws: usize,
    note: &mut dyn FnMut(&str),
) -> Result<CrossValidated> {
    if draws > MAX_DRAWS || draws == 1 {
        bail!("--draws {draws}: give 0 (no band) or 2 to {MAX_DRAWS}");
    }
    let record = read_record(record_path)?;
    super::check_identified(&record).with_context(|| format!("{}", record_path.display()))?;
    let d = super::description_of(&record).with_context(|| format!("{}", record_path.display()))?;
    let data =
        load_dir(data_dir).with_context(|| format!("loading data set {}", data_dir.display()))?;
    let notes = check_same_building(&d, &data, data_dir)?;
    for n in &notes {
        note(n);
    }
    // The record's own posterior: the modes' intervals (its statistical uncertainty, as on the
    // record itself); the band draws it shifted to another record's θ.
    let own = if draws == 0 {
        None
    } else {
        match super::posterior_of(&record) {
            Ok(q) => Some(q),
            Err(e) => {
                note(&format!("no band: {e}"));
                None
            }
        }
    };
    let posterior = own.clone().map(|q| super::shifted_to_another(&record, q));
    let q = posterior.as_ref().map(|q| (q, record.seed, record.run));
    // The model error learned with the identification (none in records older than it).
    let error = match record
        .free_run
        .as_ref()
        .and_then(|f| f.model_error.as_ref())
    {
        Some(m) => super::prediction::ErrorBand::Given(m),
        None => {
            note("the record holds no model error: the band holds the parameters' spread only");
            super::prediction::ErrorBand::Without
        }
    };
    let disc = match record
        .free_run
        .as_ref()
        .and_then(|f| f.discrepancy.as_ref())
    {
        Some(dd) => {
            // Said where the user reads it, not only in the result's method: the prediction is
            // then the building's alone.
            let names: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
            if !dd.modes.is_empty() && dd.channels != names {
                note(&format!(
                    "the record's discrepancy term was fitted to channels {} and {} has {}: \
                     the building alone predicts it",
                    dd.channels.join(", "),
                    data_dir.display(),
                    names.join(", ")
                ));
            } else if let Some(n) = super::discrepancy::above_band_note(dd, data.dt) {
                note(&n);
            }
            super::DiscrepancyUse::Given(dd)
        }
        None => super::DiscrepancyUse::Without,
    };
    let free = super::free_run(&d, &data, &record.theta_val, q, draws, error, disc)
        .with_context(|| format!("the free run on {}", data_dir.display()))?;
    let modal = super::modal_with_intervals(
        &d,
        &data,
        &record.theta_val,
        own.as_ref().map(|q| (q, record.seed, record.run)),
    );
    let result = CrossValidation {
        record: record_path.display().to_string(),
        data: data_dir.display().to_string(),
        algorithm: record.algorithm.clone(),
        seed: record.seed,
        run: record.run,
        structure: d,
        param_names: record.param_names.clone(),
        theta_val: record.theta_val.clone(),
        free_run: free,
        modal,
        notes,
    };
    Ok(CrossValidated { record, result })
}
