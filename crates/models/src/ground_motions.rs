//! Named real ground motions (SPEC §2: user records): the PEER NGA `.AT2` records vendored in
//! `data/ground_motions/peer/` (provenance, licence and SHA-256 of each file in
//! `data/ground_motions/PROVENANCE.md`), embedded in the binary and parsed by
//! the PEER `.AT2` reader of [`crate::readers`].
//!
//! The paper identifies its structure under one record only and remarks that the results "would
//! most likely vary with the excitation"; these records let a study try other ones. Each name
//! without a suffix is the record's first horizontal component (`hor1` in the source package);
//! the `-hor2` names are the orthogonal horizontal component.

use std::path::Path;

use crate::excitation::{GroundMotion, DEFAULT_DT, EL_CENTRO_SCALE};
use crate::readers::{parse_at2, parse_csv, ReadError, Units};

const EL_CENTRO_CSV: &str = include_str!("../../../data/ground_motions/elcentro_1940_ns.csv");

/// The vendored El Centro 1940 N-S record (data/ground_motions/elcentro_1940_ns.csv, in g,
/// dt = 0.02 s, 1560 samples), in m/s².
pub fn el_centro() -> GroundMotion {
    parse_csv(
        Path::new("data/ground_motions/elcentro_1940_ns.csv"),
        EL_CENTRO_CSV,
        Units::G,
    )
    .expect("the vendored El Centro record is valid (tested)")
}

/// SPEC §2 default excitation: El Centro × 3.0 interpolated to dt = 0.005 s (6237 samples,
/// 31.18 s).
pub fn paper_default() -> GroundMotion {
    el_centro()
        .scaled(EL_CENTRO_SCALE)
        .resample_linear(DEFAULT_DT)
}

/// A vendored record: where it comes from and its text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NamedRecord {
    /// Name used on the command line and in study configs, e.g. `el-centro-1940`.
    pub name: &'static str,
    /// Event, date, station and component as written in line 2 of the AT2 header.
    pub description: &'static str,
    /// PEER NGA record sequence number.
    pub rsn: u32,
    /// Path of the vendored file, relative to the repository root.
    pub file: &'static str,
    /// The file's text (values in g).
    text: &'static str,
}

macro_rules! record {
    ($name:literal, $description:literal, $rsn:literal, $file:literal) => {
        NamedRecord {
            name: $name,
            description: $description,
            rsn: $rsn,
            file: concat!("data/ground_motions/peer/", $file),
            text: include_str!(concat!("../../../data/ground_motions/peer/", $file)),
        }
    };
}

/// Every vendored record, in chronological order of the events.
pub const RECORDS: [NamedRecord; 8] = [
    record!(
        "el-centro-1940",
        "Imperial Valley-02, 5/19/1940, El Centro Array #9, 180",
        6,
        "RSN6_IMPVALL.I_I-ELC180-hor1.AT2"
    ),
    record!(
        "el-centro-1940-hor2",
        "Imperial Valley-02, 5/19/1940, El Centro Array #9, 270",
        6,
        "RSN6_IMPVALL.I_I-ELC270-hor2.AT2"
    ),
    record!(
        "san-fernando-1971",
        "San Fernando, 2/9/1971, Pacoima Dam (upper left abut), 164",
        77,
        "RSN77_SFERN_PUL164-hor1.AT2"
    ),
    record!(
        "san-fernando-1971-hor2",
        "San Fernando, 2/9/1971, Pacoima Dam (upper left abut), 254",
        77,
        "RSN77_SFERN_PUL254-hor2.AT2"
    ),
    record!(
        "loma-prieta-1989",
        "Loma Prieta, 10/18/1989, Corralitos, 0",
        753,
        "RSN753_LOMAP_CLS000-hor1.AT2"
    ),
    record!(
        "loma-prieta-1989-hor2",
        "Loma Prieta, 10/18/1989, Corralitos, 90",
        753,
        "RSN753_LOMAP_CLS090-hor2.AT2"
    ),
    record!(
        "northridge-1994",
        "Northridge-05, 1/18/1994, Sylmar - County Hospital Grounds, 90",
        1690,
        "RSN1690_NORTH151_SYL090-hor1.AT2"
    ),
    record!(
        "northridge-1994-hor2",
        "Northridge-05, 1/18/1994, Sylmar - County Hospital Grounds, 360",
        1690,
        "RSN1690_NORTH151_SYL360-hor2.AT2"
    ),
];

impl NamedRecord {
    /// The record in m/s² (the AT2 values are in g).
    pub fn ground_motion(&self) -> Result<GroundMotion, ReadError> {
        parse_at2(Path::new(self.file), self.text)
    }
}

/// The vendored record called `name`, if there is one.
pub fn by_name(name: &str) -> Option<&'static NamedRecord> {
    RECORDS.iter().find(|r| r.name == name)
}

/// The names of all vendored records (for error messages and `--help`).
pub fn names() -> Vec<&'static str> {
    RECORDS.iter().map(|r| r.name).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::G;

    #[test]
    fn el_centro_default_has_6237_samples() {
        let raw = el_centro();
        assert_eq!(raw.len(), 1560);
        assert!((raw.dt - 0.02).abs() < 1e-12);
        // Provenance: peak −0.31882 g at t = 2.04 s.
        assert!((raw.pga() - 0.31882 * G).abs() < 1e-12);
        assert!((raw.acc[102] + 0.31882 * G).abs() < 1e-12);
        let d = paper_default();
        assert_eq!(d.len(), 6237);
        assert_eq!(d.dt, 0.005);
        assert!((d.duration() - 31.18).abs() < 1e-9);
        // Every 4th sample is an original sample, scaled by 3; in between is the linear midpoint.
        assert!((d.acc[408] - 3.0 * raw.acc[102]).abs() < 1e-12);
        assert!((d.acc[2] - 1.5 * (raw.acc[0] + raw.acc[1])).abs() < 1e-12);
        assert!((d.pga() - 3.0 * 0.31882 * G).abs() < 1e-9);
    }

    /// (name, NPTS, DT [s], peak [g] signed, time of the peak [s]) as documented in
    /// `data/ground_motions/PROVENANCE.md` (read off the files independently of this parser).
    const DOCUMENTED: [(&str, usize, f64, f64, f64); 8] = [
        ("el-centro-1940", 5372, 0.01, -0.2807955, 2.18),
        ("el-centro-1940-hor2", 5346, 0.01, -0.210743, 11.51),
        ("san-fernando-1971", 4172, 0.01, 1.219037, 7.75),
        ("san-fernando-1971-hor2", 4172, 0.01, -1.238319, 8.52),
        ("loma-prieta-1989", 7997, 0.005, 0.6447264, 2.625),
        ("loma-prieta-1989-hor2", 7999, 0.005, 0.482787, 4.055),
        ("northridge-1994", 1000, 0.02, -0.08578056, 4.42),
        ("northridge-1994-hor2", 1000, 0.02, -0.06190701, 4.66),
    ];

    #[test]
    fn every_record_parses_with_its_documented_header_and_peak() {
        assert_eq!(DOCUMENTED.len(), RECORDS.len());
        for (name, npts, dt, peak_g, t_peak) in DOCUMENTED {
            let rec = by_name(name).unwrap_or_else(|| panic!("{name} is vendored"));
            let gm = rec
                .ground_motion()
                .unwrap_or_else(|e| panic!("{name} parses: {e}"));
            assert_eq!(gm.len(), npts, "{name}: NPTS");
            assert_eq!(gm.dt, dt, "{name}: DT");
            let (k, peak) = gm
                .acc
                .iter()
                .copied()
                .enumerate()
                .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                .expect("non-empty");
            // The files give 7 significant digits; the peak is the printed value times g.
            assert!(
                (peak - peak_g * G).abs() < 1e-12,
                "{name}: peak {} g, documented {peak_g} g",
                peak / G
            );
            assert!(
                (k as f64 * dt - t_peak).abs() < 1e-9,
                "{name}: peak at {} s, documented {t_peak} s",
                k as f64 * dt
            );
        }
    }

    #[test]
    fn names_are_unique_and_unknown_names_are_none() {
        let mut n = names();
        n.sort_unstable();
        n.dedup();
        assert_eq!(n.len(), RECORDS.len());
        assert!(by_name("el-centro").is_none());
        assert_eq!(by_name("northridge-1994").map(|r| r.rsn), Some(1690));
    }
}
