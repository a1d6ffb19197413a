//! Reader of generic sensor CSV exports: a few lines of device information, a line of column
//! names, then one row per sample with a time stamp column and value columns (the Xsens DOT
//! export is one: seven header lines, `PacketCounter,SampleTimeFine,…,Acc_X,…`, the time stamp
//! in µs of the sensor's own clock).
//!
//! The columns are chosen by name, never by position, so that an export with other or more
//! columns reads the same. Every error names the file, the 1-based line and the column; the
//! input limits are those of every other reader ([`crate::limits`]).

use crate::limits;
use crate::readers::{
    parse_field, parse_number, read_text, strip_bom, too_many_samples, ReadError,
};
use std::path::Path;

/// How far into a file the line of column names is looked for when the map does not say.
pub(crate) const HEADER_SEARCH_LINES: usize = 100;

/// Units of a time stamp column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum TimeUnits {
    #[serde(rename = "s")]
    Seconds,
    #[serde(rename = "ms")]
    Milliseconds,
    #[serde(rename = "us")]
    Microseconds,
    #[serde(rename = "ns")]
    Nanoseconds,
}

impl TimeUnits {
    /// Factor converting to seconds.
    pub(crate) fn to_seconds(self) -> f64 {
        match self {
            TimeUnits::Seconds => 1.0,
            TimeUnits::Milliseconds => 1e-3,
            TimeUnits::Microseconds => 1e-6,
            TimeUnits::Nanoseconds => 1e-9,
        }
    }
}

/// What to read from a sensor CSV file.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvColumns {
    /// Name of the time stamp column.
    pub time: String,
    pub time_units: TimeUnits,
    /// Name of the value column.
    pub column: String,
    /// Lines before the line of column names; `None`: the first line (among the first
    /// `HEADER_SEARCH_LINES`, 100) that names both columns.
    pub header_lines: Option<usize>,
    /// Drop a row whose value is `nan` or `inf` (its line goes to [`SensorColumn::dropped`])
    /// instead of refusing the file.
    pub drop_non_finite: bool,
}

/// One column of a sensor file, as recorded: time stamps in seconds of the sensor's clock and
/// the values in the file's units, with the 1-based line of every row.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorColumn {
    pub times: Vec<f64>,
    pub values: Vec<f64>,
    pub lines: Vec<usize>,
    /// Lines of the rows dropped for a non-finite value ([`CsvColumns::drop_non_finite`]).
    pub dropped: Vec<usize>,
}

/// Reads `columns` of the sensor CSV file `path`.
pub fn read_sensor_csv(path: &Path, columns: &CsvColumns) -> Result<SensorColumn, ReadError> {
    let text = read_text(path)?;
    parse_sensor_csv(path, &text, columns)
}

fn header_error(file: &Path, line: usize, field: &str, message: String) -> ReadError {
    ReadError::Header {
        file: file.to_path_buf(),
        line,
        field: field.to_string(),
        message,
    }
}

/// Parses sensor CSV text as [`read_sensor_csv`] does; `file` is used in messages only.
pub(crate) fn parse_sensor_csv(
    file: &Path,
    text: &str,
    columns: &CsvColumns,
) -> Result<SensorColumn, ReadError> {
    let lines: Vec<&str> = strip_bom(text).lines().collect();
    let sep = separator(&lines);
    // The 0-based index of the line of column names.
    let header = header_index(file, &lines, sep, columns)?;
    let names = split_names(lines[header], sep);
    let jt = column_index(file, header, &names, &columns.time)?;
    let jv = column_index(file, header, &names, &columns.column)?;
    let out = read_rows(file, &lines, header, names.len(), sep, (jt, jv), columns)?;
    check_time_series(file, &out)?;
    Ok(out)
}

/// The field separator: `,` unless a first line `sep=X` announces another (as spreadsheet
/// exports do).
fn separator(lines: &[&str]) -> char {
    lines
        .first()
        .and_then(|l| l.trim().strip_prefix("sep="))
        .and_then(|s| s.chars().next())
        .unwrap_or(',')
}

/// The fields of a line of column names, trimmed.
fn split_names(l: &str, sep: char) -> Vec<String> {
    l.split(sep).map(|f| f.trim().to_string()).collect()
}

/// The 0-based index of the line of column names: the one the map gives, or the first (among
/// the first [`HEADER_SEARCH_LINES`]) that names both columns.
fn header_index(
    file: &Path,
    lines: &[&str],
    sep: char,
    columns: &CsvColumns,
) -> Result<usize, ReadError> {
    let names_both =
        |names: &[String]| names.contains(&columns.time) && names.contains(&columns.column);
    match columns.header_lines {
        Some(h) => {
            if h >= lines.len() {
                return Err(header_error(
                    file,
                    lines.len().max(1),
                    "header_lines",
                    format!(
                        "the map says {h} lines come before the column names, the file has {} \
                         lines",
                        lines.len()
                    ),
                ));
            }
            Ok(h)
        }
        None => lines
            .iter()
            .take(HEADER_SEARCH_LINES)
            .position(|l| names_both(&split_names(l, sep)))
            .ok_or_else(|| {
                header_error(
                    file,
                    1,
                    &columns.column,
                    format!(
                        "no line among the first {HEADER_SEARCH_LINES} names both columns `{}` \
                         and `{}`",
                        columns.time, columns.column
                    ),
                )
            }),
    }
}

/// The index of the column `name` among `names` (the line of column names, 0-based index
/// `header`), refused when absent or named twice.
fn column_index(
    file: &Path,
    header: usize,
    names: &[String],
    name: &str,
) -> Result<usize, ReadError> {
    let mut at = names.iter().enumerate().filter(|(_, n)| *n == name);
    let first = at.next().map(|(j, _)| j).ok_or_else(|| {
        header_error(
            file,
            header + 1,
            name,
            format!("no such column (columns: {})", names.join(",")),
        )
    })?;
    if at.next().is_some() {
        return Err(header_error(
            file,
            header + 1,
            name,
            "the column name appears twice".to_string(),
        ));
    }
    Ok(first)
}

/// The rows after the line of column names (`header`; `width` columns): the time stamps (s,
/// column `jt`) and values (column `jv`) with their lines; blank lines skipped, a non-finite
/// value dropped or refused as the map says.
fn read_rows(
    file: &Path,
    lines: &[&str],
    header: usize,
    width: usize,
    sep: char,
    (jt, jv): (usize, usize),
    columns: &CsvColumns,
) -> Result<SensorColumn, ReadError> {
    let to_s = columns.time_units.to_seconds();
    let mut out = SensorColumn {
        times: Vec::new(),
        values: Vec::new(),
        lines: Vec::new(),
        dropped: Vec::new(),
    };
    for (i, l) in lines.iter().enumerate().skip(header + 1) {
        let line = i + 1;
        if l.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = l.split(sep).collect();
        if fields.len() != width {
            return Err(ReadError::ColumnCount {
                file: file.to_path_buf(),
                line,
                expected: width,
                found: fields.len(),
            });
        }
        if out.values.len() == limits::MAX_SAMPLES {
            return Err(too_many_samples(file, line, &columns.time));
        }
        // A time stamp is bounded in seconds, whatever unit it is written in.
        let t = parse_number(file, line, &columns.time, fields[jt])? * to_s;
        let t = limits::check_time(t)
            .map_err(|e| crate::readers::limit_error(file, line, &columns.time, e))?;
        let raw = fields[jv].trim();
        if raw.parse::<f64>().is_ok_and(|v| !v.is_finite()) {
            if columns.drop_non_finite {
                out.dropped.push(line);
                continue;
            }
            return Err(ReadError::Header {
                file: file.to_path_buf(),
                line,
                field: columns.column.clone(),
                message: format!(
                    "non-finite value `{raw}` (how some loggers write a lost packet; \
                     `[options] non_finite = \"drop\"` in the map drops such rows and fills \
                     their samples as gaps under max_gap)"
                ),
            });
        }
        let v = parse_field(file, line, &columns.column, fields[jv])?;
        out.times.push(t);
        out.values.push(v);
        out.lines.push(line);
    }
    Ok(out)
}

/// At least two samples, with increasing time stamps.
fn check_time_series(file: &Path, out: &SensorColumn) -> Result<(), ReadError> {
    if out.values.len() < 2 {
        return Err(ReadError::Empty {
            file: file.to_path_buf(),
            found: out.values.len(),
            needed: 2,
        });
    }
    for k in 1..out.times.len() {
        if out.times[k] <= out.times[k - 1] {
            return Err(ReadError::NonMonotonicTime {
                file: file.to_path_buf(),
                line: out.lines[k],
                previous: out.times[k - 1],
                t: out.times[k],
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cols(header_lines: Option<usize>) -> CsvColumns {
        CsvColumns {
            time: "SampleTimeFine".into(),
            time_units: TimeUnits::Microseconds,
            column: "Acc_X".into(),
            header_lines,
            drop_non_finite: false,
        }
    }

    #[test]
    fn columns_by_name_and_header_found() {
        let text = "sep=,\nDeviceTag:,X\n\nPacketCounter,SampleTimeFine,Acc_X\n0,1000,0.5\n\
                    1,9333,-0.25\n";
        let f = Path::new("mem.csv");
        let a = parse_sensor_csv(f, text, &cols(None)).unwrap();
        let b = parse_sensor_csv(f, text, &cols(Some(3))).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.values, vec![0.5, -0.25]);
        assert_eq!(a.lines, vec![5, 6]);
        assert!((a.times[1] - 9333e-6).abs() < 1e-15);
        let e = parse_sensor_csv(f, text, &cols(Some(2)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("mem.csv:3") && e.contains("SampleTimeFine"),
            "{e}"
        );
    }

    #[test]
    fn decreasing_clock_is_refused_with_its_line() {
        let text = "t,a\n0,1\n2,1\n1,1\n";
        let c = CsvColumns {
            time: "t".into(),
            time_units: TimeUnits::Seconds,
            column: "a".into(),
            header_lines: None,
            drop_non_finite: false,
        };
        let e = parse_sensor_csv(Path::new("m.csv"), text, &c)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("m.csv:4:"), "{e}");
    }
}
