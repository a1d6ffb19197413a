//! Where the accelerometers are and what they measure (SPEC §2, §9 "any building").
//!
//! A [`SensorLayout`] is a non-empty, strictly increasing list of storeys. Storeys are given and
//! named 1-based (`a1` is the first storey's channel, as in `measured.csv`), and stored 0-based
//! like every storey index in code ([`crate::structure`]). The channel of storey `s` measures
//!
//! - [`MeasurementKind::Relative`]: `y = ẍ_s = −ü_g + (F_{s+1} − F_s)/m_s` (SPEC eq. 29b, `h = −ü_g`);
//! - [`MeasurementKind::Absolute`]: `y = ẍ_s + ü_g = (F_{s+1} − F_s)/m_s` (no `ü_g` term).

/// What the accelerometers measure (SPEC §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeasurementKind {
    /// Relative accelerations ẍ_j (eq. 29b: h = −ü_g).
    #[default]
    Relative,
    /// Absolute accelerations ẍ_j + ü_g (h has no ü_g term).
    Absolute,
}

impl MeasurementKind {
    /// The name users write (`relative`, `absolute`).
    pub fn name(self) -> &'static str {
        match self {
            MeasurementKind::Relative => "relative",
            MeasurementKind::Absolute => "absolute",
        }
    }
}

impl std::fmt::Display for MeasurementKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MeasurementKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "relative" => Ok(MeasurementKind::Relative),
            "absolute" => Ok(MeasurementKind::Absolute),
            _ => Err(format!(
                "unknown measurement kind `{s}` (expected absolute or relative)"
            )),
        }
    }
}

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Invalid sensor layouts; every message names the field `sensors`.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum SensorError {
    #[error("sensors: at least one measured storey is required")]
    Empty,
    #[error("sensors: storey 0 does not exist (storeys are numbered from 1)")]
    StoreyZero,
    #[error("sensors: storey {storey} is outside the chain of {storeys} storeys")]
    OutOfRange { storey: usize, storeys: usize },
    #[error("sensors: storey {storey} is listed twice")]
    Duplicate { storey: usize },
    #[error("sensors: storeys must be listed in increasing order ({after} after {before})")]
    Unsorted { before: usize, after: usize },
}

/// The measured storeys and the measurement kind.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "SensorLayoutRaw", into = "SensorLayoutRaw")]
pub struct SensorLayout {
    /// 0-based storeys, strictly increasing.
    storeys: Vec<usize>,
    /// Storeys of the chain the layout was validated for.
    n_storeys: usize,
    kind: MeasurementKind,
}

/// The serialised form: 1-based storeys, as users write them.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorLayoutRaw {
    storeys: Vec<usize>,
    n_storeys: usize,
    #[serde(default)]
    kind: MeasurementKind,
}

impl TryFrom<SensorLayoutRaw> for SensorLayout {
    type Error = SensorError;
    fn try_from(raw: SensorLayoutRaw) -> Result<Self, SensorError> {
        SensorLayout::new(raw.n_storeys, &raw.storeys, raw.kind)
    }
}

impl From<SensorLayout> for SensorLayoutRaw {
    fn from(s: SensorLayout) -> Self {
        SensorLayoutRaw {
            n_storeys: s.n_storeys,
            storeys: s.one_based(),
            kind: s.kind,
        }
    }
}

impl SensorLayout {
    /// A validated layout for a chain of `n_storeys` storeys from 1-based storey numbers.
    pub fn new(
        n_storeys: usize,
        storeys_one_based: &[usize],
        kind: MeasurementKind,
    ) -> Result<Self, SensorError> {
        if storeys_one_based.is_empty() {
            return Err(SensorError::Empty);
        }
        for (i, &s) in storeys_one_based.iter().enumerate() {
            if s == 0 {
                return Err(SensorError::StoreyZero);
            }
            if s > n_storeys {
                return Err(SensorError::OutOfRange {
                    storey: s,
                    storeys: n_storeys,
                });
            }
            if i > 0 {
                let before = storeys_one_based[i - 1];
                if s == before || storeys_one_based[..i].contains(&s) {
                    return Err(SensorError::Duplicate { storey: s });
                }
                if s < before {
                    return Err(SensorError::Unsorted { before, after: s });
                }
            }
        }
        Ok(Self {
            storeys: storeys_one_based.iter().map(|s| s - 1).collect(),
            n_storeys,
            kind,
        })
    }

    /// Every storey measured (the paper's layout).
    pub fn all(n_storeys: usize, kind: MeasurementKind) -> Result<Self, SensorError> {
        let all: Vec<usize> = (1..=n_storeys).collect();
        Self::new(n_storeys, &all, kind)
    }

    /// 0-based measured storeys, increasing.
    pub fn storeys(&self) -> &[usize] {
        &self.storeys
    }

    /// 1-based measured storeys.
    pub fn one_based(&self) -> Vec<usize> {
        self.storeys.iter().map(|s| s + 1).collect()
    }

    /// Number of storeys of the chain the layout was validated for.
    pub fn n_storeys(&self) -> usize {
        self.n_storeys
    }

    pub fn kind(&self) -> MeasurementKind {
        self.kind
    }

    /// Number of channels.
    pub fn len(&self) -> usize {
        self.storeys.len()
    }

    /// Always false: a layout has at least one sensor.
    pub fn is_empty(&self) -> bool {
        self.storeys.is_empty()
    }

    /// Channel names `a<s>` (1-based storey), as in the header of `measured.csv`.
    pub fn channel_names(&self) -> Vec<String> {
        self.storeys.iter().map(|s| format!("a{}", s + 1)).collect()
    }

    /// The ground term of a channel at a step with measured excitation `ug`: `−ü_g` for
    /// relative accelerations, 0 for absolute ones.
    #[inline]
    pub fn ground(&self, ug: f64) -> f64 {
        match self.kind {
            MeasurementKind::Relative => -ug,
            MeasurementKind::Absolute => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_are_validated_and_named() {
        let s = SensorLayout::new(7, &[2, 4, 7], MeasurementKind::Relative).unwrap();
        assert_eq!(s.storeys(), [1, 3, 6]);
        assert_eq!(s.channel_names(), ["a2", "a4", "a7"]);
        assert_eq!(s.one_based(), [2, 4, 7]);
        assert_eq!(s.ground(1.5), -1.5);
        let a = SensorLayout::new(7, &[2], MeasurementKind::Absolute).unwrap();
        assert_eq!(a.ground(1.5), 0.0);
        let k = MeasurementKind::Relative;
        assert_eq!(SensorLayout::new(3, &[], k), Err(SensorError::Empty));
        assert_eq!(
            SensorLayout::new(3, &[0, 1], k),
            Err(SensorError::StoreyZero)
        );
        assert_eq!(
            SensorLayout::new(3, &[1, 4], k),
            Err(SensorError::OutOfRange {
                storey: 4,
                storeys: 3
            })
        );
        assert_eq!(
            SensorLayout::new(3, &[2, 2], k),
            Err(SensorError::Duplicate { storey: 2 })
        );
        assert_eq!(
            SensorLayout::new(3, &[3, 1], k),
            Err(SensorError::Unsorted {
                before: 3,
                after: 1
            })
        );
        for e in [SensorError::Empty, SensorError::StoreyZero] {
            assert!(e.to_string().starts_with("sensors:"));
        }
    }

    #[test]
    fn serde_form_is_one_based_and_validated() {
        let s = SensorLayout::new(5, &[1, 3, 5], MeasurementKind::Absolute).unwrap();
        let json = serde_json::to_string(&s).unwrap();
        assert!(json.contains(r#""storeys":[1,3,5]"#), "{json}");
        let back: SensorLayout = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
        let bad = r#"{"storeys":[0],"n_storeys":5}"#;
        assert!(serde_json::from_str::<SensorLayout>(bad).is_err());
    }
}
