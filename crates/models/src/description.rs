//! The description of a building as a user states it (SPEC §1–2, §9 "any building"): storey
//! count, masses, the storeys with a hysteretic (Bouc–Wen) element, the measured storeys and what
//! the accelerometers measure.
//!
//! It is what `dataset.json` records under `structure`, and what field data must be given (flags
//! or the `[structure]` table of a filter config): everything the filters need besides the data.
//! Storeys are 1-based here, as users write them (`hysteretic = [1, 6]`: an element between the
//! ground and storey 1 and one between storeys 5 and 6); [`StructureDescription::building`]
//! converts them into the 0-based [`Building`].

use crate::building::{error, Building, BuildingError, Damping};
use crate::ground_between::GroundBetween;
use crate::limits;
use crate::sensors::{MeasurementKind, SensorLayout};
use serde::{Deserialize, Serialize};

/// A building and its sensors as a user describes them (1-based storeys).
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
    /// The measured ground acceleration between its samples, in the filter's sub-steps and the
    /// free run ([`GroundBetween`]): linear (SPEC §2, the default, not written) or band-limited
    /// (a recorded ground motion: field data).
    #[serde(default, skip_serializing_if = "GroundBetween::is_linear")]
    pub ground_between: GroundBetween,
}

impl StructureDescription {
    /// The description of `building` with accelerometers of kind `measurement` at the 1-based
    /// storeys `sensors` (what `dataset.json` records).
    pub fn of(building: &Building, sensors: Vec<usize>, measurement: MeasurementKind) -> Self {
        Self {
            storeys: building.storeys(),
            masses: building.masses().to_vec(),
            hysteretic: building.hysteretic_one_based(),
            sensors,
            measurement,
            damping: building.damping(),
            ground_between: GroundBetween::Linear,
        }
    }

    /// The building described, validated against the stated storey count.
    pub fn building(&self) -> Result<Building, BuildingError> {
        let n = self.storeys;
        limits::check_storeys(n).map_err(|e| error("storeys", e.to_string()))?;
        if self.masses.len() != n {
            return Err(error(
                "masses",
                format!(
                    "{} masses for a building of {n} storeys (one per storey, ground excluded)",
                    self.masses.len()
                ),
            ));
        }
        Building::from_one_based(self.masses.clone(), &self.hysteretic, self.damping)
    }

    /// The sensor layout (validated).
    pub fn sensor_layout(&self) -> Result<SensorLayout, BuildingError> {
        SensorLayout::new(self.storeys, &self.sensors, self.measurement)
            .map_err(|e| error("sensors", strip_field(&e.to_string(), "sensors")))
    }

    /// Checks every field against the others and the [`limits`].
    pub fn validate(&self) -> Result<(), BuildingError> {
        self.building()?;
        self.sensor_layout()?;
        Ok(())
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
            ground_between: Default::default(),
        }
    }

    #[test]
    fn a_valid_description_converts_to_zero_based_storeys() {
        let d = ten();
        let b = d.building().unwrap();
        assert_eq!(
            StructureDescription::of(&b, d.sensors.clone(), d.measurement),
            d
        );
        d.validate().unwrap();
        assert_eq!(d.building().unwrap().hysteretic(), [0, 5]);
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
            (
                |d| d.masses[4] = -1.0,
                "masses",
                "mass of storey 5 is -1, not positive",
            ),
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
