//! Importing real recordings: per-channel files (sensor CSV exports, CSMIP V2 records) named
//! by a channel map become one field-data set (`measured.csv`, the format `sysid filter`
//! reads) with `import.json` beside it, which records where every channel came from and every
//! repair the import made.
//!
//! The import never guesses what the recordings cannot say: the masses, the storey count and
//! the hysteretic storeys are stated to `sysid filter`, not written here; the measured storeys
//! and what the sensors record (the map's `measurement`, absolute by default) are recorded.
//! What would take a guess to repair — clocks that do not overlap, a gap longer than
//! `max_gap`, irregular sampling, a channel that reads the same signal as another — is refused
//! by name.

pub mod align;
pub mod channel_map;
pub mod csmip;
pub mod mode_shape;
pub mod sensor_csv;

use crate::dataset::{self, DatasetError, FileDigest, MEASURED};
use crate::readers::ReadError;
use crate::sensors::MeasurementKind;
use align::{Recorded, Repair};
use channel_map::{Channel, ChannelMap, Format, Options, Role};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The record of an import, written beside `measured.csv`.
pub use crate::dataset::replace::IMPORT;

/// Why an import could not be made.
#[derive(Debug, Error)]
pub enum ImportError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(
        "{file}:{line}: key `{}`: {}",
        crate::readers::quoted(.key),
        crate::readers::clipped(.message)
    )]
    Map {
        file: PathBuf,
        line: usize,
        key: String,
        message: String,
    },
    #[error("{file}:{line}: {channel}: {}", crate::readers::clipped(.message))]
    Refused {
        file: PathBuf,
        line: usize,
        channel: String,
        message: String,
    },
    #[error("{channel}: {}", crate::readers::clipped(.message))]
    Value { channel: String, message: String },
    #[error("no span of time is covered by every channel ({channels}): nothing to import")]
    NoCommonSpan { channels: String },
    #[error(transparent)]
    Write(#[from] DatasetError),
}

/// Where one channel came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Source {
    /// `ground` or `storey <s>`.
    pub channel: String,
    /// The file as the map names it, and as opened.
    pub file: PathBuf,
    pub sha256: String,
    pub bytes: u64,
    pub spec: channel_map::ChannelSpec,
    /// Rows (samples) read.
    pub samples: usize,
    /// For a V2 record: the channel and direction its header names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recorded_as: Option<String>,
}

/// The content of `import.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImportRecord {
    /// The channel map, as given, and its SHA-256.
    pub map: PathBuf,
    pub map_sha256: String,
    pub options: Options,
    pub dt: f64,
    pub samples: usize,
    /// `t = 0` of `measured.csv` on the ground file's clock (s).
    pub t0_ground_clock: f64,
    pub sensors: Vec<usize>,
    pub measurement: MeasurementKind,
    /// What the import does not know and `sysid filter` must be told.
    pub not_recorded: String,
    pub channels: Vec<Source>,
    pub repairs: Vec<Repair>,
    pub warnings: Vec<String>,
    /// Size and SHA-256 of the `measured.csv` written with this record.
    pub files: BTreeMap<String, FileDigest>,
}

/// An imported data set, ready to be written.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub dt: f64,
    pub ug: Vec<f64>,
    /// Row-major `K × sensors`.
    pub y: Vec<f64>,
    pub record: ImportRecord,
}

fn digest_of(path: &Path) -> Result<FileDigest, ReadError> {
    let bytes = crate::readers::read_input(path)?;
    Ok(FileDigest::of(&bytes))
}

/// Reads one channel, converted to m/s² with the map's units, scale and sign and its clock
/// moved by the map's `offset`.
fn read_channel(c: &Channel) -> Result<(Recorded, Source), ImportError> {
    let (times, values, lines, recorded_as) = match c.spec.format {
        Format::SensorCsv => {
            let cols = c.csv_columns().expect("checked by the map");
            let col = sensor_csv::read_sensor_csv(&c.path, &cols)?;
            (col.times, col.values, col.lines, None)
        }
        Format::CsmipV2 => {
            let r = csmip::read_v2(&c.path)?;
            if let Some(want) = &c.spec.direction {
                let want = want.to_ascii_lowercase();
                let has = csmip::orientation_name(r.orientation);
                if has != Some(want.as_str()) {
                    return Err(ImportError::Map {
                        file: c.path.clone(),
                        line: 1,
                        key: "direction".into(),
                        message: format!(
                            "the map expects {want} for {}, the record is channel {} `{}` \
                             (orientation code {}): wrong file or swapped channels",
                            c.role, r.channel, r.direction, r.orientation
                        ),
                    });
                }
            }
            // One recorder: every channel's first sample is at the record's start.
            let times = (0..r.acc.len()).map(|k| k as f64 * r.dt).collect();
            let lines = (0..r.acc.len()).map(|k| r.first_line + k / 8).collect();
            let as_ = format!("channel {} {}", r.channel, r.direction);
            (times, r.acc, lines, Some(as_))
        }
    };
    // The limit on data values applies in SI units, after the map's units, scale and sign.
    let f = c.factor();
    let field = c.spec.column.as_deref().unwrap_or("accel");
    for (v, &line) in values.iter().zip(&lines) {
        crate::limits::check_value(v * f)
            .map_err(|e| crate::readers::limit_error(&c.path, line, field, e))?;
    }
    let d = digest_of(&c.path)?;
    let samples = values.len();
    let rec = Recorded {
        role: c.role,
        file: c.path.clone(),
        times: times.into_iter().map(|t| t + c.spec.offset).collect(),
        values: values.into_iter().map(|v| v * f).collect(),
        lines,
    };
    let src = Source {
        channel: c.role.to_string(),
        file: c.path.clone(),
        sha256: d.sha256,
        bytes: d.bytes,
        spec: c.spec.clone(),
        samples,
        recorded_as,
    };
    Ok((rec, src))
}

/// Reads every channel of `map`, aligns and repairs them (see [`align`]).
pub fn import(map: &ChannelMap) -> Result<Imported, ImportError> {
    let (ground, gsrc) = read_channel(&map.ground)?;
    let mut storeys = Vec::with_capacity(map.storeys.len());
    let mut sources = vec![gsrc];
    for c in &map.storeys {
        let (r, s) = read_channel(c)?;
        storeys.push(r);
        sources.push(s);
    }
    let a = align::align(ground, storeys, &map.options)?;
    let k = a.ug.len();
    let m = a.storeys.len();
    let mut y = vec![0.0; k * m];
    for (j, col) in a.storeys.iter().enumerate() {
        for (i, v) in col.iter().enumerate() {
            y[i * m + j] = *v;
        }
    }
    let map_digest = digest_of(&map.path)?;
    let sensors: Vec<usize> = map
        .storeys
        .iter()
        .map(|c| match c.role {
            Role::Storey(s) => s,
            Role::Ground => unreachable!("storeys only"),
        })
        .collect();
    let mut warnings = a.warnings;
    warnings.extend(mode_shape::swapped_storeys_warning(
        a.dt, &a.ug, &sensors, &a.storeys,
    ));
    Ok(Imported {
        dt: a.dt,
        ug: a.ug,
        y,
        record: ImportRecord {
            map: map.path.clone(),
            map_sha256: map_digest.sha256,
            options: map.options.clone(),
            dt: a.dt,
            samples: k,
            t0_ground_clock: a.t0,
            sensors,
            measurement: map.options.measurement,
            not_recorded: "the storey count, the masses and the hysteretic storeys are not \
                           known from the recordings: state them to `sysid filter` (--storeys, \
                           --masses, --hysteretic)"
                .into(),
            channels: sources,
            repairs: a.repairs,
            warnings,
            files: BTreeMap::new(),
        },
    })
}

impl Imported {
    /// The measured storeys.
    pub fn sensors(&self) -> &[usize] {
        &self.record.sensors
    }

    /// Writes `measured.csv` and `import.json` as the directory `dir`, staged and renamed into
    /// place as every data set is (`dataset::write_staged`): an interruption leaves the old
    /// directory or the new one.
    pub fn write_dir(&self, dir: &Path) -> Result<ImportRecord, DatasetError> {
        let k = self.ug.len();
        let t: Vec<f64> = (0..k).map(|i| i as f64 * self.dt).collect();
        let names: Vec<String> = self.sensors().iter().map(|s| format!("a{s}")).collect();
        let csv = dataset::measured_csv_text(&t, &self.ug, &self.y, &names);
        let mut record = self.record.clone();
        record
            .files
            .insert(MEASURED.to_string(), FileDigest::of(csv.as_bytes()));
        let json = serde_json::to_string_pretty(&record).expect("the record is serialisable");
        dataset::write_staged(
            dir,
            &[(MEASURED, csv.as_bytes()), (IMPORT, json.as_bytes())],
        )?;
        Ok(record)
    }
}
