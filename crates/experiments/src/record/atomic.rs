//! Atomic writes: a file is replaced whole or not at all (records, and every file a sweep or
//! merge writes).

use std::fs;
use std::io;
use std::path::Path;

/// Writes `bytes` to `path` atomically: a temporary file `<name>.tmp<pid>` in the same
/// directory, then a rename over `path`. An interruption leaves either the old file or the new
/// one, never a part of either (and possibly the temporary file, removed by the next sweep or
/// merge of the directory).
/// The error names the file and what was being done.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    // The message carries the path: an `io::Error` has no other place for it.
    let named = |what: String| move |e: io::Error| io::Error::new(e.kind(), format!("{what}: {e}"));
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} names no file", path.display()),
        )
    })?;
    let mut tmp_name = name.to_os_string();
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    fs::write(&tmp, bytes).map_err(named(format!("writing {}", tmp.display())))?;
    fs::rename(&tmp, path).map_err(named(format!("renaming into {}", path.display())))?;
    Ok(())
}
