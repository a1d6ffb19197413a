//! The one reader of records. Every command that reads a record — a resumed sweep, `merge`,
//! `plot`, `compare-reference`, `reference --start-from` — goes through [`read`] (or
//! [`read_bytes`] and [`parse`] when it also needs the bytes), so the same checks hold
//! everywhere:
//!
//! - the file is at most [`MAX_FILE_BYTES`] long, checked before anything is read (and the read
//!   itself stops there, should the file grow meanwhile);
//! - it is a regular file (a directory named `x.json` is an error, not a silent skip);
//! - the text is complete JSON of the record type, every number a JSON number or one of the
//!   strings `"NaN"`, `"inf"`, `"-inf"` ([`super::number`]);
//! - the record passes its own checks ([`Checked::check`]: schema, lengths, fingerprint).

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use thiserror::Error;

use models::limits::MAX_FILE_BYTES;
use serde::Serialize;

/// A record type that checks itself once read (schema, sizes, fingerprint).
pub trait Checked: DeserializeOwned {
    /// What the record is, for messages ("run record", "reference record").
    const KIND: &'static str;
    /// The checks of a record just parsed; the error says what is wrong.
    fn check(&self) -> Result<(), String>;
}

/// A record a sweep can reuse: it says whether its run failed, what determined it, and checks
/// itself after it is read.
pub trait SweepRecord: Serialize + Checked + Send {
    /// Whether the run failed (for the progress count).
    fn failed(&self) -> bool;
    /// The fingerprint of everything that determined the record (`None`: written by a tool that
    /// did not record one).
    fn fingerprint(&self) -> Option<&str>;
    /// Whether `other` holds the same result, wall-clock timings aside. A sweep keeps the
    /// file of a record it computed again with the same result, so that a reproduction that
    /// agrees leaves the committed records byte for byte as they were.
    fn same_result(&self, other: &Self) -> bool;
}

/// Why a record could not be read (or written); every variant names the file.
#[derive(Debug, Error)]
pub enum ReadError {
    #[error("serialising a record")]
    Serialise(#[source] serde_json::Error),
    #[error("writing {}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("the record was written but does not read back")]
    NoReadBack(#[source] Box<ReadError>),
    #[error("reading {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{} is not a file but {what} (a record is a regular file)", path.display())]
    NotAFile { path: PathBuf, what: &'static str },
    #[error(
        "{}: {bytes} bytes, more than the {max} bytes a record may have; not read",
        path.display(),
        max = MAX_FILE_BYTES
    )]
    TooLarge { path: PathBuf, bytes: u64 },
    #[error("{kind} {} is cut short (an interrupted write?): {source}", path.display())]
    CutShort {
        kind: &'static str,
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{kind} {} is not a valid {kind}: {source}", path.display())]
    Invalid {
        kind: &'static str,
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{kind} {} fails its checks: {reason}", path.display())]
    Check {
        kind: &'static str,
        path: PathBuf,
        reason: String,
    },
}

/// The bytes of the record at `path`, through the one reader of input files
/// ([`models::readers::read_input`]): a regular file of at most [`MAX_FILE_BYTES`] bytes,
/// checked before a byte is read (a named pipe or a link to `/dev/zero` is refused at once).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    use models::readers::ReadError as Input;
    models::readers::read_input(path).map_err(|e| match e {
        Input::NotAFile { what, .. } => ReadError::NotAFile {
            path: path.to_path_buf(),
            what,
        },
        Input::FileTooLarge { bytes, .. } => ReadError::TooLarge {
            path: path.to_path_buf(),
            bytes,
        },
        Input::Io { source, .. } => ReadError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => ReadError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::other(other.to_string()),
        },
    })
}

/// Parses and checks the bytes of one record; `path` names it in errors.
pub fn parse<R: Checked>(bytes: &[u8], path: &Path) -> Result<R, ReadError> {
    let record: R = serde_json::from_slice(bytes).map_err(|source| {
        let path = path.to_path_buf();
        if source.is_eof() {
            ReadError::CutShort {
                kind: R::KIND,
                path,
                source,
            }
        } else {
            ReadError::Invalid {
                kind: R::KIND,
                path,
                source,
            }
        }
    })?;
    record.check().map_err(|reason| ReadError::Check {
        kind: R::KIND,
        path: path.to_path_buf(),
        reason,
    })?;
    Ok(record)
}

/// Reads, parses and checks the record at `path`.
pub fn read<R: Checked>(path: &Path) -> Result<R, ReadError> {
    parse(&read_bytes(path)?, path)
}

/// Writes `record` atomically to `path` ([`super::atomic::write_bytes_atomic`]) and reads the
/// written text back through [`parse`]: a record that would not read back is written (it holds
/// the run's results) but reported as an error, so no command reports success on a record its
/// own readers refuse.
pub fn write<R: Checked + serde::Serialize>(path: &Path, record: &R) -> Result<(), ReadError> {
    let text = serde_json::to_string_pretty(record).map_err(ReadError::Serialise)? + "\n";
    super::atomic::write_bytes_atomic(path, text.as_bytes()).map_err(|source| {
        ReadError::Write {
            path: path.to_path_buf(),
            source,
        }
    })?;
    parse::<R>(text.as_bytes(), path).map_err(|e| ReadError::NoReadBack(Box::new(e)))?;
    Ok(())
}
