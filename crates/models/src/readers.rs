//! Readers of user ground-motion records (SPEC §2): CSV `t,acc` and PEER NGA `.AT2`.
//!
//! Every error names the file, the 1-based line number and the field, and no input makes a
//! reader panic or allocate beyond the [`crate::limits`]: the file size, the number of
//! samples (and an AT2 header's `NPTS`) are checked before anything is allocated from them, the
//! time step must lie in `[MIN_DT, MAX_DT]` and every value within `±MAX_ABS_VALUE`. A UTF-8
//! byte-order mark at the start of a file is skipped. Records are returned as a
//! [`GroundMotion`] in m/s² whose time origin is the first sample.

use crate::excitation::{GroundMotion, G};
use crate::limits::{self, LimitError};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Characters of a value, field name or line of an input that an error message quotes.
const QUOTED_CHARS: usize = 60;
/// Characters of a reader's message (which may quote a value) that an error shows.
const MESSAGE_CHARS: usize = 400;

/// `text` from an input (a value, a field name, a line) as an error message quotes it: whole
/// up to 60 characters, else its start and its length. A line of a million bytes, or brackets
/// nested 100,000 deep, is not echoed whole (the TOML readers cut their messages too).
pub fn quoted(text: &str) -> std::borrow::Cow<'_, str> {
    cut(text, QUOTED_CHARS)
}

/// A reader's message about an input, cut to 400 characters when longer (with its length).
pub fn clipped(text: &str) -> std::borrow::Cow<'_, str> {
    cut(text, MESSAGE_CHARS)
}

fn cut(text: &str, max: usize) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(max) {
        None => std::borrow::Cow::Borrowed(text),
        Some((at, _)) => std::borrow::Cow::Owned(format!(
            "{}… ({} characters)",
            &text[..at],
            text.chars().count()
        )),
    }
}

/// Units of the acceleration column of a CSV record (declared by the caller).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Units {
    /// Multiples of g = 9.81 m/s².
    #[serde(rename = "g")]
    G,
    /// m/s².
    #[serde(rename = "m/s2")]
    MetersPerSecond2,
}

impl Units {
    /// Factor converting to m/s².
    pub(crate) fn to_si(self) -> f64 {
        match self {
            Units::G => G,
            Units::MetersPerSecond2 => 1.0,
        }
    }
}

/// Why a record could not be read. `line` is 1-based.
#[derive(Debug, Error)]
pub enum ReadError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: expected {expected} columns, found {found}")]
    ColumnCount {
        file: PathBuf,
        line: usize,
        expected: usize,
        found: usize,
    },
    #[error("{file}:{line}: field `{}`: `{}` is not a number", quoted(.field), quoted(.value))]
    NotNumeric {
        file: PathBuf,
        line: usize,
        field: String,
        value: String,
    },
    #[error("{file}:{line}: field `{}`: non-finite value `{}`", quoted(.field), quoted(.value))]
    NonFinite {
        file: PathBuf,
        line: usize,
        field: String,
        value: String,
    },
    #[error("{file}:{line}: field `t`: time {t} does not increase (previous {previous})")]
    NonMonotonicTime {
        file: PathBuf,
        line: usize,
        previous: f64,
        t: f64,
    },
    #[error("{file}:{line}: field `t`: time {t} is off the uniform grid (expected {expected}, dt = {dt})")]
    NonUniformTime {
        file: PathBuf,
        line: usize,
        t: f64,
        expected: f64,
        dt: f64,
    },
    #[error(
        "{file}:{line}: field `NPTS`: header declares {declared} points, the file holds {found}"
    )]
    NptsMismatch {
        file: PathBuf,
        line: usize,
        declared: usize,
        found: usize,
    },
    #[error("{file}:{line}: field `{}`: {}", quoted(.field), clipped(.message))]
    Header {
        file: PathBuf,
        line: usize,
        field: String,
        message: String,
    },
    #[error("{file}:{line}: field `{}`: {source}", quoted(.field))]
    Limit {
        file: PathBuf,
        line: usize,
        field: String,
        #[source]
        source: LimitError,
    },
    #[error("{file}: {bytes} bytes, more than the {max} bytes an input file may have")]
    FileTooLarge { file: PathBuf, bytes: u64, max: u64 },
    /// An input that is not a regular file: a device (`/dev/zero`, also through a symbolic
    /// link), a named pipe (whose read would wait for a writer), a socket or a directory.
    #[error("{file}: is {what}, not a regular file; an input is read only from a regular file")]
    NotAFile { file: PathBuf, what: &'static str },
    #[error("{file}:{line}: not UTF-8 text (byte {byte} of the file)")]
    NotUtf8 {
        file: PathBuf,
        line: usize,
        byte: usize,
    },
    #[error("{file}: empty record ({found} samples, at least {needed} needed)")]
    Empty {
        file: PathBuf,
        found: usize,
        needed: usize,
    },
}

/// A [`ReadError::Limit`] at `file:line`, field `field`.
pub(crate) fn limit_error(file: &Path, line: usize, field: &str, source: LimitError) -> ReadError {
    ReadError::Limit {
        file: file.to_path_buf(),
        line,
        field: field.to_string(),
        source,
    }
}

/// Parses one data value (Fortran `D` exponents accepted), rejecting NaN, infinities and
/// values beyond `±MAX_ABS_VALUE`.
pub(crate) fn parse_field(
    file: &Path,
    line: usize,
    field: &str,
    raw: &str,
) -> Result<f64, ReadError> {
    parse_within(file, line, field, raw, limits::check_value)
}

/// Parses one time stamp, rejecting NaN, infinities and values beyond `±MAX_ABS_TIME`.
pub(crate) fn parse_time(
    file: &Path,
    line: usize,
    field: &str,
    raw: &str,
) -> Result<f64, ReadError> {
    parse_within(file, line, field, raw, limits::check_time)
}

/// Parses one number ([`parse_number`]) and checks it against its limit (`check`).
fn parse_within(
    file: &Path,
    line: usize,
    field: &str,
    raw: &str,
    check: fn(f64) -> Result<f64, LimitError>,
) -> Result<f64, ReadError> {
    let v = parse_number(file, line, field, raw)?;
    check(v).map_err(|e| limit_error(file, line, field, e))
}

/// Parses one number (Fortran `D` exponents accepted), rejecting NaN and infinities.
pub(crate) fn parse_number(
    file: &Path,
    line: usize,
    field: &str,
    raw: &str,
) -> Result<f64, ReadError> {
    let s = raw.trim();
    let v: f64 = s
        .parse()
        .or_else(|_| s.replace(['D', 'd'], "E").parse())
        .map_err(|_| ReadError::NotNumeric {
            file: file.to_path_buf(),
            line,
            field: field.to_string(),
            value: s.to_string(),
        })?;
    if !v.is_finite() {
        return Err(ReadError::NonFinite {
            file: file.to_path_buf(),
            line,
            field: field.to_string(),
            value: s.to_string(),
        });
    }
    Ok(v)
}

/// Checks that `times` (with their 1-based line numbers; at least two) increase strictly and lie
/// on a uniform grid whose step is within `[MIN_DT, MAX_DT]`; returns the step. Rounding of
/// printed times is tolerated up to 1% of a step, far below any real gap or jitter.
pub(crate) fn uniform_step(file: &Path, times: &[(usize, f64)]) -> Result<f64, ReadError> {
    if times.len() < 2 {
        return Err(ReadError::Empty {
            file: file.to_path_buf(),
            found: times.len(),
            needed: 2,
        });
    }
    for w in times.windows(2) {
        if w[1].1 <= w[0].1 {
            return Err(ReadError::NonMonotonicTime {
                file: file.to_path_buf(),
                line: w[1].0,
                previous: w[0].1,
                t: w[1].1,
            });
        }
    }
    // Local check first, so that a gap is reported where it occurs: every step within 5 % of
    // the first one (printed times rounded to a few digits stay well inside).
    let dt1 = times[1].1 - times[0].1;
    limits::check_dt(dt1).map_err(|e| step_error(file, times[1].0, e))?;
    for w in times.windows(2) {
        if ((w[1].1 - w[0].1) - dt1).abs() > 0.05 * dt1 {
            return Err(ReadError::NonUniformTime {
                file: file.to_path_buf(),
                line: w[1].0,
                t: w[1].1,
                expected: w[0].1 + dt1,
                dt: dt1,
            });
        }
    }
    // Global check: no drift away from the uniform grid.
    let n = times.len();
    let t0 = times[0].1;
    let dt = (times[n - 1].1 - t0) / (n - 1) as f64;
    limits::check_dt(dt).map_err(|e| step_error(file, times[n - 1].0, e))?;
    for (k, &(line, t)) in times.iter().enumerate() {
        let expected = t0 + k as f64 * dt;
        if (t - expected).abs() > 0.01 * dt {
            return Err(ReadError::NonUniformTime {
                file: file.to_path_buf(),
                line,
                t,
                expected,
                dt,
            });
        }
    }
    Ok(dt)
}

fn step_error(file: &Path, line: usize, e: LimitError) -> ReadError {
    let message = format!("time step: {e} (s)");
    ReadError::Header {
        file: file.to_path_buf(),
        line,
        field: "t".to_string(),
        message,
    }
}

/// What a file that is not a regular file is, for messages (also for the output checks, which
/// look at a path without following a link).
pub fn file_kind(t: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_block_device() || t.is_char_device() {
            return "a device";
        }
        if t.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Checks that `meta` (of `path`) is a regular file of at most [`limits::MAX_FILE_BYTES`].
fn check_input(path: &Path, meta: &std::fs::Metadata) -> Result<(), ReadError> {
    if !meta.is_file() {
        return Err(ReadError::NotAFile {
            file: path.to_path_buf(),
            what: file_kind(meta.file_type()),
        });
    }
    if meta.len() > limits::MAX_FILE_BYTES {
        return Err(ReadError::FileTooLarge {
            file: path.to_path_buf(),
            bytes: meta.len(),
            max: limits::MAX_FILE_BYTES,
        });
    }
    Ok(())
}

/// Checks, without opening it, that `path` is an input [`read_input`] reads: a regular file
/// (through any symbolic link) of at most [`limits::MAX_FILE_BYTES`] bytes. For a command that
/// hands the path on (resolved, to a script) before reading it.
pub fn check_input_file(path: &Path) -> Result<(), ReadError> {
    let meta = std::fs::metadata(path).map_err(|source| ReadError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    check_input(path, &meta)
}

/// Reads the input file `path` whole: the one reader of every file a user gives (records, data
/// files, channel maps, configs, study and cluster files, excitations).
///
/// Before a byte is read (before the file is even opened, so that a named pipe cannot make
/// the call wait for a writer), `path` must be a regular file (a symbolic link is followed: a
/// link to `/dev/zero` is a device and refused) of at most [`limits::MAX_FILE_BYTES`] bytes (a
/// sparse file of 3 GiB is refused at once). The opened file is checked again, and no more than
/// the limit is ever read, so a file that grows meanwhile cannot make the read unbounded.
pub fn read_input(path: &Path) -> Result<Vec<u8>, ReadError> {
    use std::io::Read;
    let io = |source| ReadError::Io {
        file: path.to_path_buf(),
        source,
    };
    check_input_file(path)?;
    let file = std::fs::File::open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    check_input(path, &meta)?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limits::MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > limits::MAX_FILE_BYTES {
        return Err(ReadError::FileTooLarge {
            file: path.to_path_buf(),
            bytes: bytes.len() as u64,
            max: limits::MAX_FILE_BYTES,
        });
    }
    Ok(bytes)
}

/// `bytes` of `path` as UTF-8 text; a byte that is not UTF-8 is refused naming its line.
pub(crate) fn utf8_text(path: &Path, bytes: Vec<u8>) -> Result<String, ReadError> {
    String::from_utf8(bytes).map_err(|e| {
        let byte = e.utf8_error().valid_up_to();
        let line = e.as_bytes()[..byte].iter().filter(|&&b| b == b'\n').count() + 1;
        ReadError::NotUtf8 {
            file: path.to_path_buf(),
            line,
            byte: byte + 1,
        }
    })
}

/// Reads the input text file `path` whole ([`read_input`], then `utf8_text`).
pub fn read_input_text(path: &Path) -> Result<String, ReadError> {
    utf8_text(path, read_input(path)?)
}

/// Reads a whole text file ([`read_input_text`]).
pub(crate) fn read_text(path: &Path) -> Result<String, ReadError> {
    read_input_text(path)
}

/// `text` without a leading UTF-8 byte-order mark (which some spreadsheet programs write and
/// no editor shows).
pub(crate) fn strip_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// Error for the sample beyond `MAX_SAMPLES` at `line`.
pub(crate) fn too_many_samples(file: &Path, line: usize, field: &str) -> ReadError {
    limit_error(
        file,
        line,
        field,
        LimitError::CountTooLarge {
            value: limits::MAX_SAMPLES as u128 + 1,
            max: limits::MAX_SAMPLES as u128,
        },
    )
}

/// Reads a CSV record `t,acc` (one header line optional; blank lines and lines starting with
/// `#` are skipped) with the acceleration in `units`.
pub fn read_csv(path: &Path, units: Units) -> Result<GroundMotion, ReadError> {
    let text = read_text(path)?;
    parse_csv(path, &text, units)
}

/// Parses CSV text as [`read_csv`] does; `file` is used in error messages only.
pub(crate) fn parse_csv(file: &Path, text: &str, units: Units) -> Result<GroundMotion, ReadError> {
    let mut times = Vec::new();
    let mut acc = Vec::new();
    let mut seen_first = false;
    for (i, raw) in strip_bom(text).lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = l.split(',').collect();
        // The first non-blank line is a header when none of its fields is a number.
        if !seen_first {
            seen_first = true;
            if fields.iter().all(|f| f.trim().parse::<f64>().is_err()) {
                continue;
            }
        }
        if fields.len() != 2 {
            return Err(ReadError::ColumnCount {
                file: file.to_path_buf(),
                line,
                expected: 2,
                found: fields.len(),
            });
        }
        if acc.len() == limits::MAX_SAMPLES {
            return Err(too_many_samples(file, line, "t"));
        }
        let t = parse_time(file, line, "t", fields[0])?;
        let a = parse_field(file, line, "acc", fields[1])?;
        times.push((line, t));
        acc.push(a * units.to_si());
    }
    if acc.len() < 2 {
        return Err(ReadError::Empty {
            file: file.to_path_buf(),
            found: acc.len(),
            needed: 2,
        });
    }
    let dt = uniform_step(file, &times)?;
    Ok(GroundMotion { dt, acc })
}

/// Reads a PEER NGA `.AT2` record (values in g, converted to m/s²).
pub fn read_at2(path: &Path) -> Result<GroundMotion, ReadError> {
    let text = read_text(path)?;
    parse_at2(path, &text)
}

/// `(NPTS, DT)` from line 4 of an AT2 file, in either the NGA-West2 form
/// `NPTS=  4000, DT= .0050 SEC` or the older `4000   .0050   NPTS, DT`.
fn parse_at2_header(file: &Path, line: &str) -> Result<(usize, f64), ReadError> {
    let up = line.to_ascii_uppercase();
    let header_err = |field: &str, message: String| ReadError::Header {
        file: file.to_path_buf(),
        line: 4,
        field: field.to_string(),
        message,
    };
    // Value following `key` and `=`, up to the next comma or whitespace-separated token.
    let keyed = |key: &str| -> Option<String> {
        let pos = up.find(key)?;
        let rest = up[pos + key.len()..].trim_start();
        let rest = rest.strip_prefix('=')?.trim_start();
        let end = rest
            .find(|c: char| c == ',' || c.is_whitespace())
            .unwrap_or(rest.len());
        Some(rest[..end].to_string())
    };
    let (npts_raw, dt_raw) = match (keyed("NPTS"), keyed("DT")) {
        (Some(n), Some(d)) => (n, d),
        _ => {
            let toks: Vec<&str> = up
                .split([' ', '\t', ','])
                .filter(|t| !t.is_empty())
                .collect();
            if toks.len() < 2 {
                return Err(header_err(
                    "NPTS",
                    format!("cannot find NPTS and DT in `{}`", line.trim()),
                ));
            }
            (toks[0].to_string(), toks[1].to_string())
        }
    };
    // NPTS is bounded before it becomes a size: `NPTS= 1e30` once overflowed a capacity.
    let npts_f = parse_number(file, 4, "NPTS", &npts_raw)?;
    if npts_f < 1.0 || npts_f.fract() != 0.0 {
        return Err(header_err(
            "NPTS",
            format!("`{npts_raw}` is not a positive integer"),
        ));
    }
    if npts_f > limits::MAX_SAMPLES as f64 {
        return Err(limit_error(
            file,
            4,
            "NPTS",
            LimitError::TooLarge {
                value: npts_f,
                max: limits::MAX_SAMPLES as f64,
            },
        ));
    }
    let dt = parse_number(file, 4, "DT", &dt_raw)?;
    if dt <= 0.0 {
        return Err(header_err("DT", format!("`{dt_raw}` is not positive")));
    }
    let dt = limits::check_dt(dt).map_err(|e| limit_error(file, 4, "DT", e))?;
    Ok((npts_f as usize, dt))
}

/// Parses AT2 text as [`read_at2`] does; `file` is used in error messages only.
pub(crate) fn parse_at2(file: &Path, text: &str) -> Result<GroundMotion, ReadError> {
    let lines: Vec<&str> = strip_bom(text).lines().collect();
    if lines.len() < 4 {
        return Err(ReadError::Header {
            file: file.to_path_buf(),
            line: lines.len() + 1,
            field: "header".to_string(),
            message: format!(
                "an AT2 file has 4 header lines, found {} lines in all",
                lines.len()
            ),
        });
    }
    let (npts, dt) = parse_at2_header(file, lines[3])?;
    let mut acc = Vec::with_capacity(npts);
    // Values beyond NPTS are counted, not kept.
    let mut extra = 0usize;
    for (i, l) in lines.iter().enumerate().skip(4) {
        for tok in l.split_whitespace() {
            if acc.len() == npts {
                extra += 1;
                continue;
            }
            let field = format!("value {}", acc.len() + 1);
            acc.push(parse_field(file, i + 1, &field, tok)? * G);
        }
    }
    if acc.len() != npts || extra > 0 {
        return Err(ReadError::NptsMismatch {
            file: file.to_path_buf(),
            line: 4,
            declared: npts,
            found: acc.len() + extra,
        });
    }
    if acc.len() < 2 {
        return Err(ReadError::Empty {
            file: file.to_path_buf(),
            found: acc.len(),
            needed: 2,
        });
    }
    Ok(GroundMotion { dt, acc })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value of 100,000 characters (brackets a fuzz run inserted into a CSV cell, a header
    /// line of a million digits) is quoted by its start and length, not echoed whole.
    #[test]
    fn long_values_are_quoted_by_their_start_and_length() {
        let f = Path::new("exc.csv");
        let long = format!("-0.03{}", "{".repeat(100_000));
        let text = format!("t,acc\n0,0.1\n0.01,{long}\n");
        let e = parse_csv(f, &text, Units::G).unwrap_err().to_string();
        assert!(e.starts_with("exc.csv:3: field `acc`: `-0.03{{{{"), "{e}");
        assert!(e.contains("… (100005 characters)") && e.len() < 200, "{e}");
        let header = format!("head\nline 2\nline 3\n{}\n0.1\n", "9".repeat(1_000_000));
        let e = parse_at2(Path::new("rec.AT2"), &header)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("rec.AT2:4: field `NPTS`"), "{e}");
        assert!(e.len() < 600, "{} characters: {}", e.len(), &e[..200]);
        // Short values are quoted whole.
        assert_eq!(quoted("1e400"), "1e400");
    }

    #[test]
    fn csv_with_and_without_header() {
        let f = Path::new("mem.csv");
        let a = parse_csv(f, "t,acc\n0,0.1\n0.01,-0.2\n0.02,0.3\n", Units::G).unwrap();
        let b = parse_csv(f, "0,0.1\n0.01,-0.2\n\n0.02,0.3\n", Units::G).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.acc.len(), 3);
        assert!((a.dt - 0.01).abs() < 1e-15);
        assert!((a.acc[1] + 0.2 * G).abs() < 1e-12);
        let c = parse_csv(f, "0,0.1\n0.01,-0.2\n", Units::MetersPerSecond2).unwrap();
        assert_eq!(c.acc, vec![0.1, -0.2]);
    }

    /// A data value and a time stamp are each held to their own limit: 10¹¹ is a value but not
    /// a time; beyond 10¹² neither.
    #[test]
    fn values_and_times_have_their_own_limits() {
        let f = Path::new("mem.csv");
        assert_eq!(parse_field(f, 3, "acc", " 1e11 ").unwrap(), 1e11);
        assert_eq!(parse_field(f, 3, "acc", "-2.5D3").unwrap(), -2500.0);
        assert_eq!(parse_time(f, 3, "t", "1e9").unwrap(), 1e9);
        let limit = |r: Result<f64, ReadError>| match r {
            Err(ReadError::Limit { line, field, .. }) => (line, field),
            other => panic!("{other:?}"),
        };
        assert_eq!(limit(parse_time(f, 3, "t", "1e11")), (3, "t".into()));
        assert_eq!(limit(parse_time(f, 4, "t", "2e12")), (4, "t".into()));
        assert_eq!(limit(parse_field(f, 5, "acc", "2e12")), (5, "acc".into()));
    }

    #[test]
    fn at2_header_formats() {
        let f = Path::new("mem.AT2");
        let new = "PEER\nEVENT\nACCELERATION TIME SERIES IN UNITS OF G\nNPTS=    5, DT=   .0050 SEC\n  .1E-02  -.2E-02  .3E-02\n  .4E-02  .5E-02\n";
        let old = "PEER\nEVENT\nACCELERATION TIME SERIES IN UNITS OF G\n     5   .0050   NPTS, DT\n  .1E-02  -.2E-02  .3E-02\n  .4E-02  .5E-02\n";
        let a = parse_at2(f, new).unwrap();
        let b = parse_at2(f, old).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.dt, 0.005);
        assert_eq!(a.acc.len(), 5);
        assert!((a.acc[1] + 0.002 * G).abs() < 1e-15);
    }
}
