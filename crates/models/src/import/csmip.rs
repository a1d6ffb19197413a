//! Reader of CSMIP/COSMOS V2 processed strong-motion records (`CHANnnn.V2`: corrected
//! acceleration, velocity and displacement of one channel), in both layouts the California
//! Strong Motion Instrumentation Program has distributed them in: the mixed-case one of records
//! since about 1993 and the upper-case one of older records (film digitised, e.g. the Meloland
//! overpass under the 1979 Imperial Valley and 1987 Superstition Hills earthquakes).
//!
//! The layout, as found in the records this reader was written for (lines 1-based; the
//! phrases matched without regard to case):
//! - lines 1–22 a text header: line 1 `Corrected accelerogram … Chan  7:  Tran …` (older:
//!   `CORRECTED ACCELEROGRAM … CHAN  7: 270 DEG …`), line 16
//!   `  8511 points of instrument- and baseline-corrected accel, veloc and displ data`, line 17
//!   `At equally-spaced intervals of    .010  sec.`;
//! - line 23 blank, lines 24–25 a title;
//! - lines 26–32: 100 integers in 5-character fields (16 a line); integer 27 is the sensor's
//!   orientation: 800 longitudinal, 900 transverse, 500 up, or (older records) the azimuth of
//!   its horizontal axis in degrees (270, 360);
//! - lines 33–45: 100 reals in 10-character fields;
//! - line 46 `  8511 points of accel data equally spaced at  .010 sec, in cm/sec2. (8f10.5)`
//!   (older: `… SPACED AT  .020 SEC.  (UNITS: CM/SEC/SEC)`), then the acceleration, 8 values a
//!   line in 10-character fields. Values may touch (`-12.34567-123.45678`), so they are read by
//!   column, never split at white space.
//!
//! Only the acceleration block is read; the velocity and displacement blocks after it are not
//! needed to import a record. Any other layout (another line 1, 16 or 46) is refused by name
//! rather than read by guesswork.

use crate::limits;
use crate::readers::{limit_error, parse_field, parse_number, read_text, strip_bom, ReadError};
use std::path::Path;

/// Line (1-based) of the count of corrected samples in the text header.
const NPTS_LINE: usize = 16;
/// Line of the time step.
const DT_LINE: usize = 17;
/// First line of the 100 integers (5-character fields, 16 a line).
const INT_LINE: usize = 26;
/// Line of the acceleration block's own header.
const ACC_LINE: usize = 46;
/// 1-based index of the orientation code among the integers.
const ORIENTATION_INT: usize = 27;

/// One V2 channel: the acceleration in m/s² at a uniform step from the record's first sample.
#[derive(Debug, Clone, PartialEq)]
pub struct V2Record {
    /// The channel named on line 1 (`Chan  7:  Tran`): its number and direction word.
    pub channel: String,
    pub direction: String,
    /// Orientation code (integer 27): 800 longitudinal, 900 transverse, 500 up, or an azimuth
    /// in degrees (0–360; older records give one for every horizontal sensor).
    pub orientation: i64,
    pub dt: f64,
    /// Acceleration, m/s² (the file's cm/s² × 0.01).
    pub acc: Vec<f64>,
    /// 1-based line of the first acceleration value.
    pub first_line: usize,
}

/// Reads a V2 file.
pub fn read_v2(path: &Path) -> Result<V2Record, ReadError> {
    let text = read_text(path)?;
    parse_v2(path, &text)
}

fn header_error(file: &Path, line: usize, field: &str, message: impl Into<String>) -> ReadError {
    ReadError::Header {
        file: file.to_path_buf(),
        line,
        field: field.to_string(),
        message: message.into(),
    }
}

/// The sample count at the start of `line` (`  8511 points of …`), bounded before it is used
/// as a size.
fn leading_count(file: &Path, line_no: usize, line: &str) -> Result<usize, ReadError> {
    let tok = line.split_whitespace().next().unwrap_or("");
    let n = parse_number(file, line_no, "NPTS", tok)?;
    if n < 2.0 || n.fract() != 0.0 {
        return Err(header_error(
            file,
            line_no,
            "NPTS",
            format!("`{tok}` is not a sample count of at least 2"),
        ));
    }
    if n > limits::MAX_SAMPLES as f64 {
        return Err(limit_error(
            file,
            line_no,
            "NPTS",
            limits::LimitError::TooLarge {
                value: n,
                max: limits::MAX_SAMPLES as f64,
            },
        ));
    }
    Ok(n as usize)
}

/// The number that follows `key` in `line` (`… intervals of    .010  sec.`).
/// `key` is matched without regard to case.
fn number_after(file: &Path, line_no: usize, line: &str, key: &str) -> Result<f64, ReadError> {
    // ASCII lower-casing keeps every byte where it was: the position found indexes `line`.
    let rest = line
        .to_ascii_lowercase()
        .find(key)
        .map(|p| &line[p + key.len()..])
        .ok_or_else(|| {
            header_error(
                file,
                line_no,
                "DT",
                format!("`{key}` not found in `{}`", line.trim()),
            )
        })?;
    let tok = rest.split_whitespace().next().unwrap_or("");
    parse_number(file, line_no, "DT", tok.trim_end_matches(','))
}

/// Parses V2 text as [`read_v2`] does; `file` is used in messages only.
pub fn parse_v2(file: &Path, text: &str) -> Result<V2Record, ReadError> {
    let lines: Vec<&str> = strip_bom(text)
        .lines()
        .map(|l| l.trim_end_matches('\r'))
        .collect();
    let line = |n: usize| header_line(file, &lines, n);
    let first = line(1)?;
    if !first
        .trim_start()
        .to_ascii_lowercase()
        .starts_with("corrected accelerogram")
    {
        return Err(header_error(
            file,
            1,
            "header",
            "not a CSMIP V2 corrected accelerogram (line 1 does not start with `Corrected \
             accelerogram`)",
        ));
    }
    let npts = sample_count(file, line(NPTS_LINE)?)?;
    let dt_text = line(DT_LINE)?;
    let dt = number_after(file, DT_LINE, dt_text, "intervals of")?;
    let dt = limits::check_dt(dt).map_err(|e| limit_error(file, DT_LINE, "DT", e))?;

    let (channel, direction) = channel_name(first);
    let orientation = orientation(file, &lines)?;

    check_acc_header(file, line(ACC_LINE)?, npts, dt)?;
    let acc = acc_values(file, &lines, npts)?;
    Ok(V2Record {
        channel,
        direction,
        orientation,
        dt,
        acc,
        first_line: ACC_LINE + 1,
    })
}

/// Line `n` (1-based) of the header, refused as a file that ends before the header does.
fn header_line<'a>(file: &Path, lines: &[&'a str], n: usize) -> Result<&'a str, ReadError> {
    lines.get(n - 1).copied().ok_or_else(|| {
        header_error(
            file,
            lines.len() + 1,
            "header",
            format!(
                "the file ends at line {}, a V2 header has {ACC_LINE} lines",
                lines.len()
            ),
        )
    })
}

/// The sample count NPTS from its line `npts_text`, refused when that line is not the one of
/// the V2 layouts read here (another layout or format).
fn sample_count(file: &Path, npts_text: &str) -> Result<usize, ReadError> {
    if !npts_text
        .to_ascii_lowercase()
        .contains("points of instrument- and baseline-corrected")
    {
        return Err(header_error(
            file,
            NPTS_LINE,
            "NPTS",
            format!(
                "`{}` is not the sample count of the V2 layouts read here (`N points of \
                 instrument- and baseline-corrected accel, veloc and displ data`): another \
                 layout or format, which is not read",
                npts_text.trim()
            ),
        ));
    }
    leading_count(file, NPTS_LINE, npts_text)
}

/// The orientation of the sensor: integer [`ORIENTATION_INT`] of the header's integer block.
fn orientation(file: &Path, lines: &[&str]) -> Result<i64, ReadError> {
    // Integer k (1-based) sits on line INT_LINE + (k−1)/16, columns 5·((k−1)%16) ..+5.
    let k = ORIENTATION_INT - 1;
    let int_line = INT_LINE + k / 16;
    let col = 5 * (k % 16);
    let raw = header_line(file, lines, int_line)?
        .get(col..col + 5)
        .unwrap_or("");
    let field = format!("integer {ORIENTATION_INT} (orientation)");
    raw.trim()
        .parse::<i64>()
        .map_err(|_| ReadError::NotNumeric {
            file: file.to_path_buf(),
            line: int_line,
            field,
            value: raw.trim().to_string(),
        })
}

/// The acceleration block's header line `acc_text`: its sample count that of NPTS (`npts`),
/// its step that of line [`DT_LINE`] (`dt`), its unit cm/s² (`cm/sec2` or `CM/SEC/SEC`).
fn check_acc_header(file: &Path, acc_text: &str, npts: usize, dt: f64) -> Result<(), ReadError> {
    let lower = acc_text.to_ascii_lowercase();
    if !lower.contains("points of accel data") {
        return Err(header_error(
            file,
            ACC_LINE,
            "accel",
            format!(
                "expected the acceleration block's header (`N points of accel data equally \
                 spaced at DT sec, in cm/sec2.`), found `{}`",
                acc_text.trim()
            ),
        ));
    }
    let acc_n = leading_count(file, ACC_LINE, acc_text)?;
    if acc_n != npts {
        return Err(ReadError::NptsMismatch {
            file: file.to_path_buf(),
            line: ACC_LINE,
            declared: npts,
            found: acc_n,
        });
    }
    let acc_dt = number_after(file, ACC_LINE, acc_text, "spaced at")?;
    if (acc_dt - dt).abs() > 1e-9 * dt {
        return Err(header_error(
            file,
            ACC_LINE,
            "DT",
            format!("{acc_dt} s, but line {DT_LINE} says {dt} s"),
        ));
    }
    // `in cm/sec2.` since about 1993, `(UNITS: CM/SEC/SEC)` before.
    if !(lower.contains("cm/sec2") || lower.contains("cm/sec/sec")) {
        return Err(header_error(
            file,
            ACC_LINE,
            "units",
            format!("the acceleration is not in cm/sec2: `{}`", acc_text.trim()),
        ));
    }
    Ok(())
}

/// The `npts` accelerations (m/s²) of the block after line [`ACC_LINE`]: 8 fields of 10
/// characters a line, in cm/s², and nothing else on a line.
fn acc_values(file: &Path, lines: &[&str], npts: usize) -> Result<Vec<f64>, ReadError> {
    let mut acc = Vec::with_capacity(npts);
    let mut n = ACC_LINE;
    while acc.len() < npts {
        n += 1;
        let l = lines.get(n - 1).copied().ok_or(ReadError::NptsMismatch {
            file: file.to_path_buf(),
            line: ACC_LINE,
            declared: npts,
            found: acc.len(),
        })?;
        let on_line = (npts - acc.len()).min(8);
        for j in 0..on_line {
            let field = format!("accel value {}", acc.len() + 1);
            // A short line or a multi-byte character inside a field is a malformed value.
            let raw = l
                .get(10 * j..10 * (j + 1))
                .ok_or_else(|| ReadError::ColumnCount {
                    file: file.to_path_buf(),
                    line: n,
                    expected: on_line,
                    found: j,
                })?;
            // cm/s² to m/s²; the limit applies to the value in SI units.
            let v = parse_field(file, n, &field, raw)? * 0.01;
            acc.push(v);
        }
        let rest = if l.len() > 10 * on_line {
            l.get(10 * on_line..)
        } else {
            Some("")
        };
        if rest.is_none_or(|r| !r.trim().is_empty()) {
            return Err(ReadError::ColumnCount {
                file: file.to_path_buf(),
                line: n,
                expected: on_line,
                found: on_line + 1,
            });
        }
    }
    Ok(acc)
}

/// `("7", "Tran")` from line 1's `… Chan  7:  Tran  …`, `("7", "270 DEG")` from an older
/// record's `… CHAN  7: 270 DEG …` (empty when absent).
fn channel_name(first: &str) -> (String, String) {
    let Some(p) = first.to_ascii_lowercase().find("chan") else {
        return (String::new(), String::new());
    };
    let mut rest = first[p + 4..].split_whitespace();
    let number = rest.next().unwrap_or("").trim_end_matches(':').to_string();
    let word = rest.next().unwrap_or("");
    let direction = match rest.next() {
        Some(unit) if unit.eq_ignore_ascii_case("deg") => format!("{word} {unit}"),
        _ => word.to_string(),
    };
    (number, direction)
}

/// The direction word a map may expect of an orientation code.
pub(crate) fn orientation_name(code: i64) -> Option<&'static str> {
    match code {
        800 => Some("long"),
        900 => Some("tran"),
        500 => Some("up"),
        _ => None,
    }
}

/// An azimuth in degrees (0–360) as a map may write a direction (`"270"`).
pub(crate) fn azimuth(direction: &str) -> Option<i64> {
    direction
        .trim()
        .parse::<i64>()
        .ok()
        .filter(|d| (0..=360).contains(d))
}

/// The azimuth (0–359°) an orientation `code` gives, if it gives one rather than an axis code.
pub(crate) fn code_azimuth(code: i64) -> Option<i64> {
    (0..=360).contains(&code).then_some(code % 360)
}

/// Whether a map's `direction` (long, tran, up, or an azimuth in degrees) is the record's
/// orientation `code`; 0° and 360° are one azimuth.
pub(crate) fn direction_matches(direction: &str, code: i64) -> bool {
    let want = direction.trim().to_ascii_lowercase();
    match azimuth(&want) {
        Some(d) => code_azimuth(code) == Some(d % 360),
        None => orientation_name(code) == Some(want.as_str()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_layouts_name_their_channel() {
        assert_eq!(
            channel_name(
                "Corrected accelerogram   01336-E0785-08325.04       Chan  3:  Tran    from"
            ),
            ("3".into(), "Tran".into())
        );
        assert_eq!(
            channel_name(
                "CORRECTED ACCELEROGRAM   01336-C0164-79290.04       CHAN  7: 270 DEG     FROM"
            ),
            ("7".into(), "270 DEG".into())
        );
    }

    #[test]
    fn a_direction_is_a_word_or_an_azimuth() {
        assert!(direction_matches("tran", 900) && direction_matches("Long", 800));
        assert!(direction_matches("up", 500) && !direction_matches("up", 900));
        assert!(direction_matches("270", 270) && direction_matches(" 360", 0));
        assert!(direction_matches("0", 360) && !direction_matches("90", 270));
        // An azimuth never matches a code that is not one, nor a word an azimuth.
        assert!(!direction_matches("500", 500) && !direction_matches("tran", 270));
        assert_eq!(azimuth("361"), None);
        assert_eq!(azimuth("-90"), None);
    }
}
