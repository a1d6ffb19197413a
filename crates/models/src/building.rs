//! The building (SPEC §1, §9 "any building"): what is known about the structure and not
//! identified — the storey masses, the storeys with a hysteretic (Bouc–Wen) element and the
//! damping form of the model.
//!
//! Users state a building 1-based (`dataset.json`'s `structure`, the `[structure]` table of a
//! filter config, the flags of `sysid filter`); those forms convert into a [`Building`] at the
//! boundary, and [`Building::new`] is the one place that validates it. Inside, storeys are
//! 0-based, and the truth simulator (`crate::structure::ShearChain`), the filter partitions
//! (`crate::filtering::ChainSpec`) and the force kernel they share all hold a `Building`, so an
//! unvalidated one cannot reach them.

use crate::limits;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The damping form of the model (`crate::structure` documents the forces).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Damping {
    /// Per-storey (inter-storey) dashpots `c_j` only (SPEC §1).
    #[default]
    #[serde(rename = "storey")]
    Storey,
    /// Per-storey dashpots plus mass-proportional damping `α M` (θ gains `alpha`).
    #[serde(rename = "storey+mass")]
    StoreyMass,
}

impl Damping {
    /// Every form, in the order of [`Damping::NAMES`].
    pub const ALL: [Damping; 2] = [Damping::Storey, Damping::StoreyMass];
    /// The names users write (`--damping`, `damping = "…"`).
    pub const NAMES: [&'static str; 2] = ["storey", "storey+mass"];

    pub fn name(self) -> &'static str {
        match self {
            Damping::Storey => Self::NAMES[0],
            Damping::StoreyMass => Self::NAMES[1],
        }
    }

    /// Whether the form has the mass-proportional term (and θ its `alpha`).
    pub fn has_mass_term(self) -> bool {
        self == Damping::StoreyMass
    }

    /// Number of θ entries the form adds after `c_1..c_N` (0 or 1).
    pub fn extra_parameters(self) -> usize {
        usize::from(self.has_mass_term())
    }

    /// Whether this is the default form (skipped when serialising, so that what records the
    /// default form is unchanged).
    pub fn is_default(&self) -> bool {
        *self == Damping::Storey
    }
}

impl std::fmt::Display for Damping {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown damping form name.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("unknown damping form `{0}` (expected storey or storey+mass)")]
pub struct UnknownDamping(pub String);

impl std::str::FromStr for Damping {
    type Err = UnknownDamping;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "storey" => Ok(Damping::Storey),
            "storey+mass" => Ok(Damping::StoreyMass),
            other => Err(UnknownDamping(other.to_string())),
        }
    }
}

/// An impossible building; `field` is the key a user wrote (`storeys`, `masses`, `hysteretic`,
/// `sensors`), so that each boundary can name it as its user wrote it (a flag, a config key, a
/// field of `dataset.json`).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("field `{field}`: {message}")]
pub struct BuildingError {
    pub field: &'static str,
    pub message: String,
}

pub(crate) fn error(field: &'static str, message: impl Into<String>) -> BuildingError {
    BuildingError {
        field,
        message: message.into(),
    }
}

/// A validated building. Storey `j` (0-based) has mass `masses()[j]`; element `j` links storey
/// `j−1` to storey `j` (storey `−1` being the ground).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Stated", into = "Stated")]
pub struct Building {
    masses: Vec<f64>,
    /// 0-based storeys of the hysteretic elements, strictly increasing (the order of their `r`
    /// in the state).
    hysteretic: Vec<usize>,
    /// `element[j] = Some(e)` when element `j` is hysteretic element `e` (the force kernel's
    /// lookup, built once here).
    element: Vec<Option<usize>>,
    damping: Damping,
}

/// A building as it is serialised (0-based storeys); deserialising validates it.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Stated {
    masses: Vec<f64>,
    hysteretic: Vec<usize>,
    #[serde(default, skip_serializing_if = "Damping::is_default")]
    damping: Damping,
}

impl TryFrom<Stated> for Building {
    type Error = BuildingError;
    fn try_from(s: Stated) -> Result<Self, BuildingError> {
        Building::new(s.masses, s.hysteretic, s.damping)
    }
}

impl From<Building> for Stated {
    fn from(b: Building) -> Self {
        Stated {
            masses: b.masses,
            hysteretic: b.hysteretic,
            damping: b.damping,
        }
    }
}

impl Building {
    /// The building of `masses` (one per storey, N = `masses.len()` within
    /// [`limits::MAX_STOREYS`]) with hysteretic elements at the 0-based storeys `hysteretic`
    /// (strictly increasing, below N).
    pub fn new(
        masses: Vec<f64>,
        hysteretic: Vec<usize>,
        damping: Damping,
    ) -> Result<Self, BuildingError> {
        let n = masses.len();
        limits::check_storeys(n).map_err(|e| error("masses", format!("{n} storeys: {e}")))?;
        check_masses(&masses)?;
        let mut element = vec![None; n];
        for (e, &j) in hysteretic.iter().enumerate() {
            let s = j + 1;
            if j >= n {
                return Err(error(
                    "hysteretic",
                    format!("storey {s} is above the top of the building of {n} storeys"),
                ));
            }
            if element[j].is_some() {
                return Err(error("hysteretic", format!("storey {s} is listed twice")));
            }
            if e > 0 && j < hysteretic[e - 1] {
                return Err(error(
                    "hysteretic",
                    format!(
                        "storeys must be listed in increasing order ({s} after {})",
                        hysteretic[e - 1] + 1
                    ),
                ));
            }
            element[j] = Some(e);
        }
        Ok(Self {
            masses,
            hysteretic,
            element,
            damping,
        })
    }

    /// [`Building::new`] with the hysteretic storeys 1-based, as users write them
    /// (`[1, 6]`: an element between the ground and storey 1 and one between storeys 5 and 6).
    pub(crate) fn from_one_based(
        masses: Vec<f64>,
        hysteretic: &[usize],
        damping: Damping,
    ) -> Result<Self, BuildingError> {
        if hysteretic.contains(&0) {
            return Err(error(
                "hysteretic",
                "storey 0 does not exist (storeys are numbered from 1, the ground is not a storey)",
            ));
        }
        Self::new(masses, hysteretic.iter().map(|s| s - 1).collect(), damping)
    }

    /// The same building with damping form `damping`.
    pub fn with_damping(mut self, damping: Damping) -> Self {
        self.damping = damping;
        self
    }

    /// Number of storeys N.
    #[inline]
    pub fn storeys(&self) -> usize {
        self.masses.len()
    }

    #[inline]
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }

    /// 0-based storeys of the hysteretic elements, in element order.
    #[inline]
    pub fn hysteretic(&self) -> &[usize] {
        &self.hysteretic
    }

    /// 1-based storeys of the hysteretic elements, as users write them.
    pub(crate) fn hysteretic_one_based(&self) -> Vec<usize> {
        self.hysteretic.iter().map(|j| j + 1).collect()
    }

    /// The hysteretic element at storey `j`, if any.
    #[inline]
    pub(crate) fn element_at(&self, j: usize) -> Option<usize> {
        self.element[j]
    }

    #[inline]
    pub fn damping(&self) -> Damping {
        self.damping
    }
}

/// Checks storey masses as a user states them: each positive, finite and within
/// `limits::MAX_ABS_VALUE` (10¹²; 1-based storeys in the message). [`Building::new`] checks every
/// building's masses here; a config's `[structure] masses` is checked here when it is read.
pub fn check_masses(masses: &[f64]) -> Result<(), BuildingError> {
    for (j, &m) in masses.iter().enumerate() {
        let s = j + 1;
        if !(m.is_finite() && m > 0.0) {
            return Err(error(
                "masses",
                format!("mass of storey {s} is {m}, not positive"),
            ));
        }
        limits::check_range(m, 0.0, limits::MAX_ABS_VALUE)
            .map_err(|e| error("masses", format!("mass of storey {s}: {e}")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_impossible_building_is_refused_naming_its_field() {
        let b = |m: Vec<f64>, h: &[usize]| Building::from_one_based(m, h, Damping::Storey);
        let cases: [(Result<Building, BuildingError>, &str, &str); 8] = [
            (b(vec![], &[]), "masses", "0 storeys"),
            (b(vec![1.0; 201], &[]), "masses", "201 storeys"),
            (b(vec![1.0, -1.0], &[]), "masses", "mass of storey 2 is -1"),
            (b(vec![1.0, f64::NAN], &[]), "masses", "storey 2 is NaN"),
            (b(vec![1e300], &[]), "masses", "mass of storey 1"),
            (b(vec![1.0; 2], &[3]), "hysteretic", "storey 3 is above"),
            (b(vec![1.0; 2], &[0]), "hysteretic", "storey 0"),
            (b(vec![1.0; 3], &[2, 1]), "hysteretic", "increasing order"),
        ];
        for (result, field, words) in cases {
            let e = result.unwrap_err();
            assert_eq!(e.field, field, "{e}");
            assert!(e.to_string().contains(words), "{e}");
        }
        let e = b(vec![1.0; 3], &[2, 2]).unwrap_err();
        assert!(e.to_string().contains("storey 2 is listed twice"), "{e}");
    }

    #[test]
    fn a_building_is_zero_based_inside_and_validated_when_read() {
        let b =
            Building::from_one_based(vec![1.0, 2.0, 3.0], &[1, 3], Damping::StoreyMass).unwrap();
        assert_eq!(b.hysteretic(), [0, 2]);
        assert_eq!(b.hysteretic_one_based(), [1, 3]);
        assert_eq!(
            (b.element_at(0), b.element_at(1), b.element_at(2)),
            (Some(0), None, Some(1))
        );
        let json = serde_json::to_string(&b).unwrap();
        assert_eq!(
            json,
            r#"{"masses":[1.0,2.0,3.0],"hysteretic":[0,2],"damping":"storey+mass"}"#
        );
        assert_eq!(serde_json::from_str::<Building>(&json).unwrap(), b);
        let bad = json.replace("2.0", "-2.0");
        let e = serde_json::from_str::<Building>(&bad).unwrap_err();
        assert!(e.to_string().contains("mass of storey 2"), "{e}");
    }
}
