//! The structure a run identifies (SPEC §1–2, §9 "any building"): recorded in `dataset.json` for
//! simulated data; stated by the user for field data (only `measured.csv`), through the flags of
//! `sysid filter` or the `[structure]` table of its config.
//!
//! Nothing is guessed: when the data carry no `dataset.json` and a key is missing, the run is
//! refused with a message that names every missing key and how to give it. The measured storeys
//! are always the header of `measured.csv` (`t,ug,a1,a3,a5`); a header that does not fit the
//! stated structure is an error naming the file and the column. A stated key that contradicts
//! `dataset.json` is an error naming both.

use std::path::Path;

use crate::error::{bail, Result};
use models::building::BuildingError;
use models::dataset::{LoadedDataset, MEASURED, META};
use models::description::StructureDescription;
use models::ground_between::GroundBetween;
use models::sensors::MeasurementKind;
use models::structure::{Damping, ShearChain};
use serde::{Deserialize, Serialize};

/// The `[structure]` table of a filter config, and the structure flags of `sysid filter`
/// (`--storeys`, `--hysteretic`, `--masses`, `--measurement`, `--damping`): what a user states
/// about the building of field data. Every key is optional here; [`resolve`] says which are
/// required (all but `damping`, whose default is the per-storey dashpots).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StructureSettings {
    /// Number of storeys N.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub storeys: Option<usize>,
    /// 1-based storeys with a Bouc–Wen element (empty: a linear building).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hysteretic: Option<Vec<usize>>,
    /// Storey masses m_1..m_N, or one value for every storey.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub masses: Option<Vec<f64>>,
    /// What the accelerometers record: `absolute` (ẍ + ü_g, what real accelerometers give) or
    /// `relative` (ẍ).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measurement: Option<MeasurementKind>,
    /// Damping form of the model: `storey` (per-storey dashpots c_j, the default) or
    /// `storey+mass` (also mass-proportional damping αM; θ gains `alpha` after c1..cN).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping: Option<Damping>,
}

impl StructureSettings {
    /// No key given.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Sets every key `over` gives (flags over the config table).
    pub(crate) fn overlay(&mut self, over: &StructureSettings) {
        if over.storeys.is_some() {
            self.storeys = over.storeys;
        }
        if over.hysteretic.is_some() {
            self.hysteretic.clone_from(&over.hysteretic);
        }
        if over.masses.is_some() {
            self.masses.clone_from(&over.masses);
        }
        if over.measurement.is_some() {
            self.measurement = over.measurement;
        }
        if over.damping.is_some() {
            self.damping = over.damping;
        }
    }
}

/// How a key is named in messages: a flag (`--storeys`) or a config key
/// (`[structure] storeys in field.toml`).
pub(crate) type KeyName<'a> = &'a dyn Fn(&str) -> String;

/// The name of a key in the `[structure]` table of a config (the form used by the library).
pub(crate) fn table_key(key: &str) -> String {
    format!("[structure] `{key}`")
}

/// Masses as stated: one value means that mass for every storey.
fn expand_masses(masses: &[f64], storeys: usize) -> Vec<f64> {
    if masses.len() == 1 {
        vec![masses[0]; storeys]
    } else {
        masses.to_vec()
    }
}

/// Errors when a stated key differs from the structure `dataset.json` records; each names the
/// key (through `name`) and `dataset.json`.
pub(crate) fn check_agrees(
    recorded: &StructureDescription,
    given: &StructureSettings,
    name: KeyName,
    meta_file: &Path,
) -> Result<()> {
    let conflict = |key: &str, stated: String, has: String| -> Result<()> {
        bail!(
            "{} = {stated} contradicts {} ({key} = {has}); the data set's structure is used: drop \
             the setting, or remove {META} to treat the data as field data",
            name(key),
            meta_file.display()
        )
    };
    if let Some(n) = given.storeys {
        if n != recorded.storeys {
            conflict("storeys", n.to_string(), recorded.storeys.to_string())?;
        }
    }
    if let Some(h) = &given.hysteretic {
        if *h != recorded.hysteretic {
            conflict("hysteretic", list(h), list(&recorded.hysteretic))?;
        }
    }
    if let Some(m) = &given.masses {
        if expand_masses(m, recorded.storeys) != recorded.masses {
            conflict("masses", list(m), list(&recorded.masses))?;
        }
    }
    if let Some(k) = given.measurement {
        if k != recorded.measurement {
            conflict(
                "measurement",
                k.to_string(),
                recorded.measurement.to_string(),
            )?;
        }
    }
    // The data's true θ (compared with the estimate) has the recorded form's parameters.
    if let Some(d) = given.damping {
        if d != recorded.damping {
            conflict("damping", d.to_string(), recorded.damping.to_string())?;
        }
    }
    Ok(())
}

fn list<T: std::fmt::Display>(v: &[T]) -> String {
    let items: Vec<String> = v.iter().map(|x| x.to_string()).collect();
    format!("[{}]", items.join(","))
}

/// The structure of a run's data.
///
/// - With `dataset.json`: the structure it records (`given` must agree, see `check_agrees`).
/// - Without, but with the true `chain` (data generated in memory): its storeys, masses and
///   hysteretic storeys where `given` is silent.
/// - Field data: every key from `given`; a missing key is refused by name.
///
/// The measured storeys are the header of `measured.csv`. `measured_file` names that file in
/// messages (the directory's file when known); `name` names the keys (flags or config keys).
pub fn resolve(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    given: &StructureSettings,
    measured_file: &Path,
    name: KeyName,
) -> Result<StructureDescription> {
    RESOLUTIONS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    if let Some(meta) = &data.meta {
        let recorded = meta.structure()?;
        let meta_file = measured_file.with_file_name(META);
        check_agrees(&recorded, given, name, &meta_file)?;
        return Ok(recorded);
    }
    let mut given = given.clone();
    if let Some(c) = chain {
        given.storeys.get_or_insert(c.storeys());
        given.masses.get_or_insert_with(|| c.masses().to_vec());
        given
            .hysteretic
            .get_or_insert_with(|| c.bouc_wen().iter().map(|b| b.storey + 1).collect());
        given.damping.get_or_insert(c.damping_form());
    }
    let mut missing = Vec::new();
    if given.storeys.is_none() {
        missing.push(format!("{} (the number of storeys, N)", name("storeys")));
    }
    if given.hysteretic.is_none() {
        missing.push(format!(
            "{} (1-based storeys with a hysteretic element, e.g. 1,4; `none` for a linear \
             building)",
            name("hysteretic")
        ));
    }
    if given.masses.is_none() {
        missing.push(format!(
            "{} (storey masses m1,...,mN, or one value for every storey; with masses 1 the \
             stiffnesses and dampings are identified per unit mass)",
            name("masses")
        ));
    }
    if given.measurement.is_none() {
        missing.push(format!(
            "{} (absolute|relative: what the accelerometers record; real accelerometers record \
             absolute accelerations)",
            name("measurement")
        ));
    }
    if !missing.is_empty() {
        bail!(
            "{}: field data (no {META} beside it): the structure is not known; add {}",
            measured_file.display(),
            missing.join(", ")
        );
    }
    let n = given.storeys.expect("checked");
    // Bounded before anything is sized from it: one mass for every storey of 2⁶³ storeys was
    // a capacity-overflow panic.
    models::limits::check_storeys(n)
        .map_err(|e| crate::error::invalid!("{}: {e} storeys", name("storeys")))?;
    let d = StructureDescription {
        storeys: n,
        masses: expand_masses(&given.masses.expect("checked"), n),
        hysteretic: given.hysteretic.expect("checked"),
        sensors: data.sensors.clone(),
        measurement: given.measurement.expect("checked"),
        damping: given.damping.unwrap_or_default(),
        // A recorded ground motion is the sampling of a band-limited signal; linear
        // interpolation would take up to a quarter of its amplitude near a stiff building's
        // modes (models::ground_between).
        ground_between: GroundBetween::BandLimited,
    };
    d.building()
        .map_err(|e: BuildingError| crate::error::invalid!("{}: {}", name(e.field), e.message))?;
    // The header against the stated structure: every measured storey must exist.
    if let Some(&s) = data.sensors.iter().find(|&&s| s > n) {
        bail!(
            "{}: column `a{s}`: storey {s} is above the top of the building ({} = {n}); \
             the header names the measured storeys",
            measured_file.display(),
            name("storeys")
        );
    }
    d.sensor_layout()
        .map_err(|e| crate::error::invalid!("{}: {}", measured_file.display(), e))?;
    Ok(d)
}

/// How many times this process has resolved a building ([`resolve`]; the plan of a run
/// resolves it once: tested).
pub fn resolutions() -> usize {
    RESOLUTIONS.load(std::sync::atomic::Ordering::Relaxed)
}

static RESOLUTIONS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// [`resolve`] as the library uses it (keys named as in the `[structure]` table).
pub fn resolve_for_run(
    data: &LoadedDataset,
    chain: Option<&ShearChain>,
    given: &StructureSettings,
) -> Result<StructureDescription> {
    resolve(data, chain, given, Path::new(MEASURED), &table_key)
}
