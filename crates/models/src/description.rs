//! The description of a building as a user states it (SPEC §1–2, §9 "any building"): storey
//! count, masses, the storeys with a hysteretic (Bouc–Wen) element, the measured storeys and what
//! the accelerometers measure.
//!
//! It is what `dataset.json` records under `structure`, and what field data must be given (flags
//! or the `[structure]` table of a filter config): everything the filters need besides the data.
//! Storeys are 1-based here, as users write them (`hysteretic = [1, 6]`: an element between the
//! ground and storey 1 and one between storeys 5 and 6); code converts them to 0-based.

use crate::limits;
use crate::sensors::{MeasurementKind, SensorLayout};
use crate::structure::Damping;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A malformed description; `field` is the key a user wrote (`storeys`, `masses`, `hysteretic`,
/// `sensors`).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("field `{field}`: {message}")]
pub struct DescriptionError {
    pub field: &'static str,
    pub message: String,
}

fn error(field: &'static str, message: impl Into<String>) -> DescriptionError {
    DescriptionError {
        field,
        message: message.into(),
    }
}

/// A complete, validated building description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StructureDescription {
    /// Number of storeys N.
    pub storeys: usize,
    /// Storey masses m_1..m_N.
    pub masses: Vec<f64>,
    /// 1-based storeys with a Bouc–Wen element, increasing (may be empty: a linear chain).
    pub hysteretic: Vec<usize>,
    /// 1-based measured storeys, increasing, at least one.
    pub sensors: Vec<usize>,
    /// What the accelerometers measure.
    pub measurement: MeasurementKind,
    /// The damping form of the model identified for it ([`Damping`]); the default (per-storey
    /// dashpots) is not written.
    #[serde(default, skip_serializing_if = "Damping::is_default")]
    pub damping: Damping,
}

impl StructureDescription {
    /// Checks every field against the others and the [`limits`].
    pub fn validate(&self) -> Result<(), DescriptionError> {
        limits::check_storeys(self.storeys).map_err(|e| error("storeys", e.to_string()))?;
        check_masses(&self.masses, self.storeys)?;
        check_storey_list("hysteretic", &self.hysteretic, self.storeys, true)?;
        check_storey_list("sensors", &self.sensors, self.storeys, false)?;
        Ok(())
    }

    /// 0-based storeys of the hysteretic elements (as `structure::BoucWen::storey`).
    pub fn hysteretic_zero_based(&self) -> Vec<usize> {
        self.hysteretic.iter().map(|s| s - 1).collect()
    }

    /// The sensor layout (validated).
    pub fn sensor_layout(&self) -> Result<SensorLayout, DescriptionError> {
        SensorLayout::new(self.storeys, &self.sensors, self.measurement)
            .map_err(|e| error("sensors", strip_field(&e.to_string(), "sensors")))
    }
}

/// `message` without a leading `"<field>: "` (the sensor layout's errors name their field
/// themselves).
fn strip_field(message: &str, field: &str) -> String {
    message
        .strip_prefix(&format!("{field}: "))
        .unwrap_or(message)
        .to_string()
}

/// Checks a list of 1-based storeys of a building of `storeys` storeys: no storey 0, none above
/// N, none twice, increasing; empty only when `allow_empty`.
pub fn check_storey_list(
    field: &'static str,
    list: &[usize],
    storeys: usize,
    allow_empty: bool,
) -> Result<(), DescriptionError> {
    if list.is_empty() && !allow_empty {
        return Err(error(field, "at least one storey is required"));
    }
    for (i, &s) in list.iter().enumerate() {
        if s == 0 {
            return Err(error(
                field,
                "storey 0 does not exist (storeys are numbered from 1, the ground is not a storey)",
            ));
        }
        if s > storeys {
            return Err(error(
                field,
                format!("storey {s} is above the top of the building of {storeys} storeys"),
            ));
        }
        if list[..i].contains(&s) {
            return Err(error(field, format!("storey {s} is listed twice")));
        }
        if i > 0 && s < list[i - 1] {
            return Err(error(
                field,
                format!(
                    "storeys must be listed in increasing order ({s} after {})",
                    list[i - 1]
                ),
            ));
        }
    }
    Ok(())
}

/// Checks N storey masses: exactly `storeys` of them, each positive and finite.
pub fn check_masses(masses: &[f64], storeys: usize) -> Result<(), DescriptionError> {
    if masses.len() != storeys {
        return Err(error(
            "masses",
            format!(
                "{} masses for a building of {storeys} storeys (one per storey, ground excluded)",
                masses.len()
            ),
        ));
    }
    if let Some(j) = masses.iter().position(|m| !(m.is_finite() && *m > 0.0)) {
        return Err(error(
            "masses",
            format!("mass of storey {} is {}, not positive", j + 1, masses[j]),
        ));
    }
    for &m in masses {
        limits::check_range(m, 0.0, limits::MAX_ABS_VALUE)
            .map_err(|e| error("masses", e.to_string()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ten() -> StructureDescription {
        StructureDescription {
            storeys: 10,
            masses: vec![1.0; 10],
            hysteretic: vec![1, 6],
            damping: Damping::Storey,
            sensors: vec![1, 3, 6, 10],
            measurement: MeasurementKind::Absolute,
        }
    }

    #[test]
    fn a_valid_description_converts_to_zero_based_storeys() {
        let d = ten();
        d.validate().unwrap();
        assert_eq!(d.hysteretic_zero_based(), [0, 5]);
        let s = d.sensor_layout().unwrap();
        assert_eq!(s.storeys(), [0, 2, 5, 9]);
        assert_eq!(s.kind(), MeasurementKind::Absolute);
    }

    #[test]
    fn every_malformed_field_is_named() {
        type Edit = fn(&mut StructureDescription);
        let cases: [(Edit, &str, &str); 8] = [
            (
                |d| d.hysteretic = vec![1, 11],
                "hysteretic",
                "storey 11 is above",
            ),
            (|d| d.hysteretic = vec![0], "hysteretic", "storey 0"),
            (|d| d.sensors = vec![0, 3], "sensors", "storey 0"),
            (|d| d.sensors = vec![3, 3], "sensors", "listed twice"),
            (|d| d.sensors = vec![], "sensors", "at least one"),
            (|d| d.sensors = vec![3, 1], "sensors", "increasing"),
            (|d| d.masses = vec![1.0; 9], "masses", "9 masses"),
            (|d| d.masses[4] = -1.0, "masses", "storey 5"),
        ];
        for (edit, field, words) in cases {
            let mut d = ten();
            edit(&mut d);
            let e = d.validate().unwrap_err();
            assert_eq!(e.field, field, "{e}");
            assert!(e.to_string().contains(words), "{e}");
            assert!(
                e.to_string().starts_with(&format!("field `{field}`")),
                "{e}"
            );
        }
        let mut linear = ten();
        linear.hysteretic.clear();
        linear.validate().unwrap();
    }
}
