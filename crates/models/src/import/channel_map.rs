//! The channel map (`channels.toml`): which file and column holds the ground motion and which
//! holds each storey's sensor, in which units, scale and sign, and how the import may repair
//! what a real record brings.
//!
//! ```toml
//! [options]                  # every key optional, defaults shown
//! remove_mean = true         # subtract each channel's mean (gravity or an offset in the axis)
//! detrend = false            # also remove a least-squares straight line (drift)
//! drop_leading_zeros = true  # drop the rows of exact zeros a logger writes before its first sample
//! max_gap = 0.05             # s: a gap in the time stamps up to this long is interpolated, longer is refused
//! clock_delay = "remove"    # or "measure": a sensor-csv storey whose clock lags the ground's (phase below the first mode) is advanced, or only logged
//! non_finite = "refuse"      # or "drop": a sensor-csv row whose value is nan/inf is dropped (a lost packet) and its sample filled as a gap
//! align = "timestamps"       # or "start": the files' first rows are simultaneous (clocks not shared)
//! max_clock_offset = 1.0     # s: channels whose clocks start further apart than this are refused
//! clock_tolerance = 0.05     # samples: clocks closer than this to whole samples apart are shifted, not resampled
//! measurement = "absolute"   # what the accelerometers record
//!
//! [ground]
//! file = "ground.csv"        # relative to this file
//! format = "sensor-csv"      # or "csmip-v2"
//! time = "SampleTimeFine"    # sensor-csv: the time stamp column, its units (s, ms, us, ns),
//! time_units = "us"
//! column = "Acc_X"           # the value column and its units (m/s2, cm/s2, mm/s2, g)
//! units = "m/s2"
//! header_lines = 7           # optional: lines before the column names (found when absent)
//! scale = 1.0                # optional factor, and sign (+1 or −1)
//! sign = 1
//! offset = 0.0               # optional: seconds added to this file's time stamps
//! direction = "X"            # optional label; for csmip-v2 checked against the record
//!                            # (long, tran, up, or the record's azimuth, e.g. "270")
//!
//! [[storey]]
//! storey = 1
//! file = "floor-1.csv"
//! # … the same keys as [ground]
//! ```
//!
//! Every key is checked before a file is opened; a malformed map is refused with the map's
//! file, the line and the key.

use super::sensor_csv::{CsvColumns, TimeUnits};
use super::ImportError;
use crate::excitation::G;
use crate::limits;
use crate::sensors::MeasurementKind;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format of a channel's file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Format {
    /// A sensor's CSV export, read by column names ([`super::sensor_csv`]).
    SensorCsv,
    /// A CSMIP/COSMOS V2 processed record, one channel a file ([`super::csmip`]).
    CsmipV2,
}

/// Units of an acceleration column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AccUnits {
    #[serde(rename = "m/s2")]
    MetersPerSecond2,
    #[serde(rename = "cm/s2")]
    CentimetersPerSecond2,
    #[serde(rename = "mm/s2")]
    MillimetersPerSecond2,
    #[serde(rename = "g")]
    G,
}

impl AccUnits {
    /// Factor converting to m/s².
    pub(crate) fn to_si(self) -> f64 {
        match self {
            AccUnits::MetersPerSecond2 => 1.0,
            AccUnits::CentimetersPerSecond2 => 0.01,
            AccUnits::MillimetersPerSecond2 => 0.001,
            AccUnits::G => G,
        }
    }
}

/// How the files' clocks relate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Align {
    /// The time stamps of every file are of one clock (or of synchronised clocks): rows are
    /// matched by time, never by row number.
    Timestamps,
    /// Each file has its own clock; the first rows of the files are simultaneous. An assumption
    /// the import states, for sensors whose clocks were never synchronised.
    Start,
}

/// What the import does with a sensor-CSV row whose value is not a finite number (`nan`, `inf`:
/// how some loggers write a lost packet).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NonFinite {
    /// The import stops, naming the file, the line and the column (the default: a value the
    /// logger could not write is not guessed without being asked).
    #[default]
    Refuse,
    /// The row is dropped and logged; the sample it should have held becomes a gap in the time
    /// stamps, filled by interpolation under `max_gap` like any other (or refused beyond it).
    Drop,
}

/// What the import does with a storey sensor whose clock is offset from the ground sensor's
/// ([`super::delay`]); only between sensor-CSV files (a V2 record's channels are taken as
/// simultaneous: one recorder, or recorders the agency started together).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ClockDelay {
    /// Measure it and, where the rule finds it unambiguous, advance the storey by it (logged).
    #[default]
    Remove,
    /// Measure and log it only.
    Measure,
}

fn yes() -> bool {
    true
}
fn default_max_gap() -> f64 {
    0.05
}
fn default_max_clock_offset() -> f64 {
    1.0
}
fn default_clock_tolerance() -> f64 {
    0.05
}
fn default_align() -> Align {
    Align::Timestamps
}
fn default_measurement() -> MeasurementKind {
    MeasurementKind::Absolute
}
fn one() -> f64 {
    1.0
}
fn plus() -> i64 {
    1
}

/// The `[options]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Options {
    #[serde(default = "yes")]
    pub remove_mean: bool,
    #[serde(default)]
    pub detrend: bool,
    #[serde(default = "yes")]
    pub drop_leading_zeros: bool,
    #[serde(default = "default_max_gap")]
    pub max_gap: f64,
    #[serde(default)]
    pub non_finite: NonFinite,
    #[serde(default)]
    pub clock_delay: ClockDelay,
    #[serde(default = "default_align")]
    pub align: Align,
    #[serde(default = "default_max_clock_offset")]
    pub max_clock_offset: f64,
    /// Fraction of a sample within which two clocks count as whole samples apart (rows are
    /// then paired without interpolation).
    #[serde(default = "default_clock_tolerance")]
    pub clock_tolerance: f64,
    #[serde(default = "default_measurement")]
    pub measurement: MeasurementKind,
}

impl Default for Options {
    fn default() -> Self {
        toml::from_str("").expect("every option has a default")
    }
}

/// One channel as the map states it (`[ground]` or one `[[storey]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub storey: Option<usize>,
    pub file: PathBuf,
    pub format: Format,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_units: Option<TimeUnits>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub column: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<AccUnits>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub header_lines: Option<usize>,
    #[serde(default = "one")]
    pub scale: f64,
    #[serde(default = "plus")]
    pub sign: i64,
    #[serde(default)]
    pub offset: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    #[serde(default)]
    options: Option<toml::Spanned<Options>>,
    ground: toml::Spanned<ChannelSpec>,
    #[serde(default)]
    storey: Vec<toml::Spanned<ChannelSpec>>,
}

/// Which signal a channel is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Role {
    Ground,
    /// 1-based storey.
    Storey(usize),
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Role::Ground => f.write_str("ground"),
            Role::Storey(s) => write!(f, "storey {s}"),
        }
    }
}

/// A checked channel: its role, the spec, and the file resolved against the map's directory.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub role: Role,
    pub spec: ChannelSpec,
    pub path: PathBuf,
    /// Line of the channel's table in the map.
    pub line: usize,
}

impl Channel {
    /// The columns to read from a sensor CSV file (checked present by [`ChannelMap::parse`]).
    pub(crate) fn csv_columns(&self) -> Option<CsvColumns> {
        Some(CsvColumns {
            time: self.spec.time.clone()?,
            time_units: self.spec.time_units?,
            column: self.spec.column.clone()?,
            header_lines: self.spec.header_lines,
            drop_non_finite: false,
        })
    }

    /// Factor from the file's values to m/s² with the map's scale and sign (a V2 reader already
    /// returns m/s²).
    pub fn factor(&self) -> f64 {
        let units = match self.spec.format {
            Format::SensorCsv => self.spec.units.map_or(1.0, AccUnits::to_si),
            Format::CsmipV2 => 1.0,
        };
        units * self.spec.scale * self.spec.sign as f64
    }
}

/// A checked channel map.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelMap {
    pub path: PathBuf,
    pub options: Options,
    pub ground: Channel,
    /// In increasing storey order.
    pub storeys: Vec<Channel>,
}

/// Whether `a` and `b` are one file: the same path, or (both existing) the same device and
/// inode, so that a link to a file already mapped is seen as that file.
fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        #[cfg(unix)]
        (Ok(ma), Ok(mb)) => {
            use std::os::unix::fs::MetadataExt;
            ma.dev() == mb.dev() && ma.ino() == mb.ino()
        }
        _ => matches!(
            (std::fs::canonicalize(a), std::fs::canonicalize(b)),
            (Ok(x), Ok(y)) if x == y
        ),
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset)
        .map_or(1, |s| s.bytes().filter(|&b| b == b'\n').count() + 1)
}

/// The key written on the line of byte `offset` (`name = value`), with the table it is in
/// (`storey.storey`, `ground.units`); the table alone on a table's header line; `None` when
/// the line holds neither.
fn key_at(text: &str, offset: usize) -> Option<String> {
    let start = text.get(..offset)?.rfind('\n').map_or(0, |i| i + 1);
    let table = text[..start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    let line = text[start..].lines().next().unwrap_or("").trim();
    if line.starts_with('[') {
        return Some(
            line.trim_matches(|c| c == '[' || c == ']')
                .trim()
                .to_string(),
        );
    }
    let key = line.split_once('=')?.0.trim().trim_matches('"');
    if key.is_empty() || key.chars().count() > 64 {
        return None;
    }
    Some(match table {
        Some(t) => format!("{t}.{key}"),
        None => key.to_string(),
    })
}

impl ChannelMap {
    /// Reads and checks the map at `path`.
    pub fn load(path: &Path) -> Result<Self, ImportError> {
        let text = crate::readers::read_text(path)?;
        Self::parse(path, &text)
    }

    /// Parses and checks map text; files are resolved against `path`'s directory.
    pub fn parse(path: &Path, text: &str) -> Result<Self, ImportError> {
        let text = crate::readers::strip_bom(text);
        let raw = map_file(path, text)?;
        let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let options = checked_options(path, text, raw.options)?;
        let ground = check_channel(path, text, &dir, Role::Ground, raw.ground)?;
        let storeys = storey_channels(path, text, &dir, raw.storey)?;
        check_distinct_signals(path, &ground, &storeys)?;
        Ok(ChannelMap {
            path: path.to_path_buf(),
            options,
            ground,
            storeys,
        })
    }
}

/// An error of the map `path` at `line`, naming `key`.
fn map_error(path: &Path, line: usize, key: &str, message: String) -> ImportError {
    ImportError::Map {
        file: path.to_path_buf(),
        line,
        key: key.to_string(),
        message,
    }
}

/// The map's TOML as read, its syntax and key errors naming the line and key.
fn map_file(path: &Path, text: &str) -> Result<MapFile, ImportError> {
    toml::from_str(text).map_err(|e| {
        let line = e.span().map_or(1, |s| line_of(text, s.start));
        let msg = e.message().trim().to_string();
        // A missing or unknown key is named by toml in backquotes; otherwise the key is
        // the one written on the line of the error (toml quotes the value there, not the
        // key), within its table.
        let named = msg.starts_with("missing field") || msg.starts_with("unknown field");
        let key = match (named, e.span()) {
            (true, _) | (false, None) => msg.split('`').nth(1).map(str::to_string),
            (false, Some(s)) => key_at(text, s.start),
        };
        map_error(
            path,
            line,
            key.as_deref().unwrap_or("(the map's top level)"),
            msg,
        )
    })
}

/// The `[options]` table, its gap, clock offset and clock tolerance within limits; the
/// defaults when there is none.
fn checked_options(
    path: &Path,
    text: &str,
    options: Option<toml::Spanned<Options>>,
) -> Result<Options, ImportError> {
    let Some(o) = options else {
        return Ok(Options::default());
    };
    let line = line_of(text, o.span().start);
    let o = o.into_inner();
    let check = |key: &str, v: f64, max: f64| {
        limits::check_range(v, 0.0, max)
            .map(|_| ())
            .map_err(|e| map_error(path, line, &format!("options.{key}"), format!("{e} (s)")))
    };
    check("max_gap", o.max_gap, 3600.0)?;
    check("max_clock_offset", o.max_clock_offset, limits::MAX_ABS_TIME)?;
    limits::check_range(o.clock_tolerance, 0.0, 0.5).map_err(|e| {
        map_error(
            path,
            line,
            "options.clock_tolerance",
            format!("{e} (samples)"),
        )
    })?;
    Ok(o)
}

/// The `[[storey]]` tables as channels, sorted by storey: at least one, each naming a storey
/// within limits, no storey twice.
fn storey_channels(
    path: &Path,
    text: &str,
    dir: &Path,
    tables: Vec<toml::Spanned<ChannelSpec>>,
) -> Result<Vec<Channel>, ImportError> {
    let err = |line: usize, key: &str, message: String| map_error(path, line, key, message);
    if tables.is_empty() {
        return Err(err(
            line_of(text, text.len()),
            "storey",
            "no [[storey]] table: at least one storey's sensor is needed".to_string(),
        ));
    }
    let mut storeys = Vec::with_capacity(tables.len());
    for s in tables {
        let line = line_of(text, s.span().start);
        let Some(n) = s.get_ref().storey else {
            return Err(err(
                line,
                "storey.storey",
                "missing: which storey (1-based) this sensor is on".to_string(),
            ));
        };
        if n == 0 || n > limits::MAX_STOREYS {
            return Err(err(
                line,
                "storey.storey",
                format!(
                    "{n} is not a storey (storeys are numbered 1 to {})",
                    limits::MAX_STOREYS
                ),
            ));
        }
        storeys.push(check_channel(path, text, dir, Role::Storey(n), s)?);
    }
    storeys.sort_by_key(|c| c.role);
    for w in storeys.windows(2) {
        if w[0].role == w[1].role {
            return Err(err(
                w[1].line.max(w[0].line),
                "storey.storey",
                format!(
                    "{} is mapped twice (lines {} and {})",
                    w[0].role, w[0].line, w[1].line
                ),
            ));
        }
    }
    Ok(storeys)
}

/// One recorded signal cannot be two channels: a copy-paste slip, or swapped files. Refuses
/// two channels reading the same column of the same file (also through another name: a
/// symbolic or hard link).
fn check_distinct_signals(
    path: &Path,
    ground: &Channel,
    storeys: &[Channel],
) -> Result<(), ImportError> {
    let all: Vec<&Channel> = std::iter::once(ground).chain(storeys).collect();
    for (i, a) in all.iter().enumerate() {
        for b in &all[..i] {
            if same_file(&a.path, &b.path) && a.spec.column == b.spec.column {
                return Err(map_error(
                    path,
                    a.line,
                    "file",
                    format!(
                        "{} reads the same signal as {} ({}{}): each channel needs its own",
                        a.role,
                        b.role,
                        a.path.display(),
                        a.spec
                            .column
                            .as_ref()
                            .map_or(String::new(), |c| format!(", column {c}"))
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks one channel table; errors name the key as `ground.<key>` or `storey.<key>`.
fn check_channel(
    path: &Path,
    text: &str,
    dir: &Path,
    role: Role,
    spanned: toml::Spanned<ChannelSpec>,
) -> Result<Channel, ImportError> {
    let line = line_of(text, spanned.span().start);
    let spec = spanned.into_inner();
    let at = ChannelErrors {
        path,
        line,
        table: match role {
            Role::Ground => "ground",
            Role::Storey(_) => "storey",
        },
        what: match role {
            Role::Ground => String::new(),
            Role::Storey(s) => format!(" (storey {s})"),
        },
    };
    if role == Role::Ground && spec.storey.is_some() {
        return Err(at.err(
            "storey",
            "the ground is not a storey; remove the key".to_string(),
        ));
    }
    if spec.file.as_os_str().is_empty() {
        return Err(at.err("file", "empty file name".to_string()));
    }
    match spec.format {
        Format::SensorCsv => check_sensor_csv_keys(&spec, &at)?,
        Format::CsmipV2 => check_csmip_v2_keys(&spec, &at)?,
    }
    check_conversion(&spec, &at)?;
    Ok(Channel {
        role,
        path: normalise(&dir.join(&spec.file)),
        spec,
        line,
    })
}

/// Where an error of a channel table points: the map `path`, the table's `line`, the table
/// (`ground` or `storey`) and what follows the message (which storey).
struct ChannelErrors<'a> {
    path: &'a Path,
    line: usize,
    table: &'static str,
    what: String,
}

impl ChannelErrors<'_> {
    /// An error of the table's `key`.
    fn err(&self, key: &str, message: String) -> ImportError {
        ImportError::Map {
            file: self.path.to_path_buf(),
            line: self.line,
            key: format!("{}.{key}", self.table),
            message: format!("{message}{}", self.what),
        }
    }
}

/// A sensor-csv channel names its time and value columns (not blank), their units, and at
/// most [`super::sensor_csv::HEADER_SEARCH_LINES`] lines before the column names.
fn check_sensor_csv_keys(spec: &ChannelSpec, at: &ChannelErrors) -> Result<(), ImportError> {
    for (key, present) in [
        ("time", spec.time.is_some()),
        ("time_units", spec.time_units.is_some()),
        ("column", spec.column.is_some()),
        ("units", spec.units.is_some()),
    ] {
        if !present {
            return Err(at.err(key, format!("missing: a sensor-csv channel needs `{key}`")));
        }
    }
    for (key, v) in [("time", &spec.time), ("column", &spec.column)] {
        if v.as_deref().is_some_and(|s| s.trim().is_empty()) {
            return Err(at.err(key, "empty column name".to_string()));
        }
    }
    if spec
        .header_lines
        .is_some_and(|h| h > super::sensor_csv::HEADER_SEARCH_LINES)
    {
        return Err(at.err(
            "header_lines",
            format!(
                "at most {} lines before the column names",
                super::sensor_csv::HEADER_SEARCH_LINES
            ),
        ));
    }
    Ok(())
}

/// A csmip-v2 channel has no column keys (one channel on a uniform step), no units but
/// cm/s², and a direction V2 knows (an axis word, or an azimuth in degrees).
fn check_csmip_v2_keys(spec: &ChannelSpec, at: &ChannelErrors) -> Result<(), ImportError> {
    for (key, present) in [
        ("time", spec.time.is_some()),
        ("time_units", spec.time_units.is_some()),
        ("column", spec.column.is_some()),
        ("header_lines", spec.header_lines.is_some()),
    ] {
        if present {
            return Err(at.err(
                key,
                "a csmip-v2 file holds one channel on a uniform step; remove the key".to_string(),
            ));
        }
    }
    if spec
        .units
        .is_some_and(|u| u != AccUnits::CentimetersPerSecond2)
    {
        return Err(at.err(
            "units",
            "a V2 record is in cm/s2, as its header says; remove the key".to_string(),
        ));
    }
    if let Some(d) = &spec.direction {
        let d = d.to_ascii_lowercase();
        if !["long", "tran", "up"].contains(&d.as_str()) && super::csmip::azimuth(&d).is_none() {
            return Err(at.err(
                "direction",
                format!(
                    "`{d}`: a V2 direction is long, tran or up, or an azimuth in degrees, 0 \
                     to 360 (where the record gives one, as records before about 1993 do)"
                ),
            ));
        }
    }
    Ok(())
}

/// The conversion of the channel's values and clock: a non-zero scale within limits, a sign
/// of ±1, a clock offset within limits.
fn check_conversion(spec: &ChannelSpec, at: &ChannelErrors) -> Result<(), ImportError> {
    limits::check_scale(spec.scale).map_err(|e| at.err("scale", e.to_string()))?;
    if spec.scale == 0.0 {
        return Err(at.err("scale", "0 would erase the channel".to_string()));
    }
    if spec.sign != 1 && spec.sign != -1 {
        return Err(at.err("sign", format!("{} is not +1 or -1", spec.sign)));
    }
    limits::check_time(spec.offset).map_err(|e| at.err("offset", format!("{e} (s)")))?;
    Ok(())
}

/// `a/b/../c` as `a/c`, so that messages name a file as a person would (lexical only: a
/// symbolic link is not resolved).
fn normalise(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir
                if matches!(out.components().next_back(), Some(Component::Normal(_))) =>
            {
                out.pop();
            }
            other => out.push(other),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}
