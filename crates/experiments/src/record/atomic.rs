//! Atomic writes: a file is replaced whole or not at all (records, and every file a sweep or
//! merge writes).

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};

/// Writes `bytes` to `path` atomically: a temporary file `<name>.tmp<pid>` in the same
/// directory, then a rename over `path`. An interruption leaves either the old file or the new
/// one, never a part of either (and possibly the temporary file, removed by the next sweep or
/// merge of the directory).
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{} names no file", path.display()))?;
    let mut tmp_name = name.to_os_string();
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))?;
    Ok(())
}
