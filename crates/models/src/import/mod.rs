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
pub mod delay;
mod mode_shape;
pub mod sensor_csv;

use crate::dataset::{self, DatasetError, FileDigest, MEASURED};
use crate::readers::ReadError;
use crate::sensors::MeasurementKind;
use align::{Recorded, Repair};
use channel_map::{Channel, ChannelMap, ClockDelay, Format, NonFinite, Options, Role};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The record of an import, written beside `measured.csv`.
pub(crate) use crate::dataset::replace::IMPORT;

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
    /// Each sensor-CSV storey's delay against the ground where one was measured (storey,
    /// delay), removed or not ([`delay`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clock_delays: Vec<(usize, delay::Delay)>,
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
/// `non_finite` says what a sensor-CSV row with a `nan`/`inf` value does; the lines of the rows
/// it drops are returned with the channel.
fn read_channel(
    c: &Channel,
    non_finite: NonFinite,
) -> Result<(Recorded, Source, Vec<usize>), ImportError> {
    let mut dropped = Vec::new();
    let (times, values, lines, recorded_as) = match c.spec.format {
        Format::SensorCsv => {
            let mut cols = c.csv_columns().expect("checked by the map");
            cols.drop_non_finite = non_finite == NonFinite::Drop;
            let col = sensor_csv::read_sensor_csv(&c.path, &cols)?;
            dropped = col.dropped;
            (col.times, col.values, col.lines, None)
        }
        Format::CsmipV2 => {
            let r = csmip::read_v2(&c.path)?;
            if let Some(want) = &c.spec.direction {
                if !csmip::direction_matches(want, r.orientation) {
                    let want = want.trim().to_ascii_lowercase();
                    // The record gives an azimuth (older records do, and some later ones)
                    // where the map names an axis: which azimuth is the structure's transverse
                    // one only its user knows.
                    let hint = if csmip::code_azimuth(r.orientation).is_some()
                        && csmip::azimuth(&want).is_none()
                    {
                        format!(
                            "; the record gives its sensor's azimuth, {}°, not an axis: \
                             write direction = \"{}\" if that is the axis meant",
                            r.orientation, r.orientation
                        )
                    } else {
                        String::new()
                    };
                    return Err(ImportError::Map {
                        file: c.path.clone(),
                        line: 1,
                        key: "direction".into(),
                        message: format!(
                            "the map expects {want} for {}, the record is channel {} `{}` \
                             (orientation code {}): wrong file or swapped channels{hint}",
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
    Ok((rec, src, dropped))
}

/// The log entry of the rows a channel lost to `non_finite = "drop"`.
fn dropped_rows(channel: &Recorded, lines: &[usize]) -> Repair {
    let shown: Vec<String> = lines.iter().take(10).map(usize::to_string).collect();
    let more = if lines.len() > 10 { ", …" } else { "" };
    Repair {
        channel: channel.name(),
        action: format!(
            "dropped {} row{} with a non-finite value (line{} {}{more}; non_finite = \"drop\"): \
             their samples are gaps in the time stamps, filled under max_gap",
            lines.len(),
            if lines.len() == 1 { "" } else { "s" },
            if lines.len() == 1 { "" } else { "s" },
            shown.join(", ")
        ),
    }
}

/// Measures each sensor-CSV storey's clock delay against the ground ([`delay::measure`]) and,
/// under `rule`, advances the storeys whose delay is unambiguous, dropping from every channel
/// the samples at the ends the shifts leave without data. Logged as repairs.
fn remove_clock_delays(
    a: &mut align::Aligned,
    channels: &[Channel],
    names: &[String],
    clocks_differ: impl Fn(&Channel) -> bool,
    rule: ClockDelay,
) -> Vec<(usize, delay::Delay)> {
    let mut found = Vec::new();
    let (mut head, mut tail) = (0usize, 0usize);
    // The first mode from the highest storey measured, as the swapped-storeys check finds it.
    let Some(f1) = a
        .storeys
        .last()
        .and_then(|top| delay::first_mode(a.dt, &a.ug, top))
    else {
        return found;
    };
    for (j, c) in channels.iter().enumerate() {
        let Role::Storey(storey) = c.role else {
            continue;
        };
        if !clocks_differ(c) {
            continue;
        }
        let Some(mut d) = delay::measure(a.dt, &a.ug, &a.storeys[j], f1) else {
            continue;
        };
        // A shift of a tenth of the record would be no clock offset but a misread time unit.
        d.removed &= rule == ClockDelay::Remove && d.seconds.abs() < 0.1 * a.ug.len() as f64 * a.dt;
        if d.removed {
            let shift = d.seconds / a.dt;
            a.storeys[j] = delay::advance(&a.storeys[j], shift);
            if shift > 0.0 {
                tail = tail.max(shift.ceil() as usize);
            } else {
                head = head.max((-shift).ceil() as usize);
            }
        }
        // Logged where it was removed, or measured on request; a delay within the rule's
        // margins is only recorded (`clock_delays`).
        if d.removed || rule == ClockDelay::Measure {
            let how = if d.removed {
                "advanced by it (a band-limited shift; clock_delay = \"measure\" keeps it)"
            } else {
                "kept (clock_delay = \"measure\")"
            };
            a.repairs.push(Repair {
                channel: names[j].clone(),
                action: format!(
                    "its clock {} the ground's by {:.2} ms ({:.2} samples, s.e. {:.2} ms), \
                     measured from the phase of its transfer function over the whole record, \
                     {} blocks of {} frequencies at {:.2}–{:.2} Hz, below half its first mode \
                     ({:.2} Hz): {how}",
                    if d.seconds >= 0.0 { "lags" } else { "leads" },
                    1e3 * d.seconds.abs(),
                    d.seconds.abs() / a.dt,
                    1e3 * d.standard_error,
                    d.bins,
                    delay::BLOCK,
                    d.band_hz.0,
                    d.band_hz.1,
                    d.first_mode_hz
                ),
            });
        }
        found.push((storey, d));
    }
    if head + tail > 0 {
        let n = a.ug.len();
        a.ug = a.ug[head..n - tail].to_vec();
        for v in &mut a.storeys {
            *v = v[head..n - tail].to_vec();
        }
        a.t0 += head as f64 * a.dt;
        a.repairs.push(Repair {
            channel: "all".into(),
            action: format!(
                "dropped {head} sample{} at the start and {tail} at the end of every channel: \
                 the clock-delay shifts leave them without data",
                if head == 1 { "" } else { "s" }
            ),
        });
    }
    found
}

/// Reads every channel of `map`, aligns and repairs them (see [`align`]).
pub fn import(map: &ChannelMap) -> Result<Imported, ImportError> {
    let non_finite = map.options.non_finite;
    let (ground, gsrc, gdropped) = read_channel(&map.ground, non_finite)?;
    let mut dropped = Vec::new();
    if !gdropped.is_empty() {
        dropped.push(dropped_rows(&ground, &gdropped));
    }
    let mut storeys = Vec::with_capacity(map.storeys.len());
    let mut sources = vec![gsrc];
    for c in &map.storeys {
        let (r, s, d) = read_channel(c, non_finite)?;
        if !d.is_empty() {
            dropped.push(dropped_rows(&r, &d));
        }
        storeys.push(r);
        sources.push(s);
    }
    let names: Vec<String> = storeys.iter().map(Recorded::name).collect();
    let mut a = align::align(ground, storeys, &map.options)?;
    // Dropped rows are the first thing done to a channel: logged before the gaps they left.
    a.repairs.splice(0..0, dropped);
    let clocks_differ = |c: &Channel| {
        map.ground.spec.format == Format::SensorCsv && c.spec.format == Format::SensorCsv
    };
    let clock_delays = remove_clock_delays(
        &mut a,
        &map.storeys,
        &names,
        clocks_differ,
        map.options.clock_delay,
    );
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
            clock_delays,
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
