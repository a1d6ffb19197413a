//! Writing a data-set directory so that an interruption never destroys one.
//!
//! The files are written into a temporary sibling `.<name>.tmp-<pid>-<nanos>` (same parent, so
//! the same file system), flushed to disk, and the directory is then put into place:
//! - when `<name>` does not exist, by one `rename` (atomic);
//! - when it exists, on Linux by `renameat2(RENAME_EXCHANGE)`, which swaps the two directories
//!   atomically; the old data set, now under the temporary name, is removed afterwards.
//!   At every instant `<name>` is either the complete old data set or the complete new one.
//! - Where the exchange is not available (another OS, or a file system without it), the old
//!   directory is renamed aside to `.<name>.old-<pid>-<nanos>`, the new one renamed in, and the
//!   old one removed. **Crash window:** between those two renames (two system calls, no I/O
//!   between them) `<name>` does not exist; the old data set is then complete under the
//!   `.old-` name and the new one under the `.tmp-` name. [`super::load_dir`] names the aside
//!   copy in its error, and the next write into `<name>` removes it once the new set is in
//!   place.
//!
//! Leftovers of killed writers (`.tmp-`/`.old-` siblings whose process is gone) are removed by
//! the next write into the same `<name>`; an `.old-` copy is kept while `<name>` is absent,
//! since it may then be the only copy.
//!
//! An existing `<name>` is replaced only when it is a directory holding nothing but data-set
//! files, each a regular file: `--out .`, a directory with other files in it, or one where a
//! data-set file name is a directory, a link or a device is refused, never deleted.

use super::{DatasetError, MEASURED, META, TRUTH};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The import log `sysid import` writes beside `measured.csv` (see `crate::import`).
pub(crate) const IMPORT: &str = "import.json";

/// The files a data-set directory may hold (`import.json`: the record of `sysid import`).
pub const DATASET_FILES: [&str; 4] = [MEASURED, TRUTH, META, IMPORT];

/// A temporary directory that will replace `target`.
pub(crate) struct Staging {
    pub(crate) dir: PathBuf,
    target: PathBuf,
}

fn io_error(file: &Path, source: std::io::Error) -> DatasetError {
    DatasetError::Io {
        file: file.to_path_buf(),
        source,
    }
}

fn not_a_dataset(dir: &Path, message: String) -> DatasetError {
    DatasetError::NotADataset {
        dir: dir.to_path_buf(),
        message,
    }
}

/// Parent directory and file name of `target` (`.` for a bare name).
fn split(target: &Path) -> Result<(PathBuf, OsString), DatasetError> {
    let name = target.file_name().ok_or_else(|| {
        not_a_dataset(
            target,
            "has no directory name to write a data set under".to_string(),
        )
    })?;
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name.to_os_string()))
}

/// Is process `pid` still running? Unknown (`true`, keep its files) off Linux.
fn alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// Leftovers `.<name>.tmp-<pid>-…` / `.<name>.old-<pid>-…` of processes that are gone.
/// `.old-` copies are listed only when `keep_old` is false.
fn stale_siblings(parent: &Path, name: &str, keep_old: bool) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    let tmp = format!(".{name}.tmp-");
    let old = format!(".{name}.old-");
    entries
        .flatten()
        .filter_map(|e| {
            let file = e.file_name().to_string_lossy().into_owned();
            let rest = if let Some(r) = file.strip_prefix(&tmp) {
                r
            } else if let Some(r) = file.strip_prefix(&old) {
                if keep_old {
                    return None;
                }
                r
            } else {
                return None;
            };
            let pid: u32 = rest.split('-').next()?.parse().ok()?;
            (pid != std::process::id() && !alive(pid)).then(|| e.path())
        })
        .collect()
}

/// `.<name>.old-…` copies left beside `target` by an interrupted replacement.
pub(crate) fn aside_copies(target: &Path) -> Vec<PathBuf> {
    let Ok((parent, name)) = split(target) else {
        return Vec::new();
    };
    let prefix = format!(".{}.old-", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(&parent) else {
        return Vec::new();
    };
    let mut out: Vec<PathBuf> = entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .collect();
    out.sort();
    out
}

/// Checks that `target` may be replaced, removes leftovers of killed writers and creates the
/// temporary sibling directory.
pub(crate) fn stage(target: &Path) -> Result<Staging, DatasetError> {
    // A symbolic link is followed: the data set it points to is replaced, the link kept.
    let target = match std::fs::symlink_metadata(target) {
        Ok(m) if m.file_type().is_symlink() => {
            std::fs::canonicalize(target).map_err(|e| io_error(target, e))?
        }
        _ => target.to_path_buf(),
    };
    match std::fs::metadata(&target) {
        Ok(m) if m.is_dir() => {
            let entries = std::fs::read_dir(&target).map_err(|e| io_error(&target, e))?;
            for e in entries {
                let e = e.map_err(|e| io_error(&target, e))?;
                let file = e.file_name();
                if !DATASET_FILES.iter().any(|f| file == *f) {
                    return Err(not_a_dataset(
                        &target,
                        format!(
                            "exists and holds `{}`, which is not a data-set file ({}); \
                             a data set is written only into a new directory or over an \
                             existing data set",
                            file.to_string_lossy(),
                            DATASET_FILES.join(", ")
                        ),
                    ));
                }
                // The old set is removed whole once the new one is in place: a directory
                // named `measured.csv` would go with everything in it, and a link or a device
                // is not a data-set file the guarantee lets the writer replace.
                let kind = e.file_type().map_err(|err| io_error(&e.path(), err))?;
                if !kind.is_file() {
                    return Err(not_a_dataset(
                        &target,
                        format!(
                            "holds `{}`, which is not a regular file ({}); a data set is \
                             written only over data-set files, never over a directory, link \
                             or device of that name",
                            file.to_string_lossy(),
                            if kind.is_dir() {
                                "a directory"
                            } else if kind.is_symlink() {
                                "a symbolic link"
                            } else {
                                "a device, pipe or socket"
                            }
                        ),
                    ));
                }
            }
        }
        Ok(_) => {
            return Err(not_a_dataset(
                &target,
                "exists and is not a directory".to_string(),
            ))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(io_error(&target, e)),
    }
    let (parent, name) = split(&target)?;
    std::fs::create_dir_all(&parent).map_err(|e| io_error(&parent, e))?;
    let name_s = name.to_string_lossy().into_owned();
    for stale in stale_siblings(&parent, &name_s, !target.exists()) {
        let _ = std::fs::remove_dir_all(stale);
    }
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let dir = parent.join(format!(".{name_s}.tmp-{}-{nanos}", std::process::id()));
    std::fs::create_dir(&dir).map_err(|e| io_error(&dir, e))?;
    Ok(Staging { dir, target })
}

/// Flushes a directory's entries to disk (best effort off Unix).
fn sync_dir(dir: &Path) -> Result<(), DatasetError> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)
            .and_then(|f| f.sync_all())
            .map_err(|e| io_error(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// Atomically swaps two directories (Linux `renameat2(RENAME_EXCHANGE)`). `Ok(false)` when the
/// kernel or file system does not offer the exchange.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    };
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: both paths are valid NUL-terminated strings that outlive the call.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        return Ok(true);
    }
    let err = std::io::Error::last_os_error();
    match err.raw_os_error() {
        Some(libc::EINVAL) | Some(libc::ENOSYS) | Some(libc::EOPNOTSUPP) => Ok(false),
        _ => Err(err),
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_a: &Path, _b: &Path) -> std::io::Result<bool> {
    Ok(false)
}

impl Staging {
    /// The real path a staged file stands for, for error messages.
    pub(crate) fn real(&self, name: &str) -> PathBuf {
        self.target.join(name)
    }

    /// Puts the staged directory in place of the target (see the module doc).
    pub(crate) fn commit(self) -> Result<(), DatasetError> {
        self.commit_using(true)
    }

    /// [`Staging::commit`], with the atomic exchange or (`try_exchange = false`, for the tests
    /// of the fallback) without it.
    fn commit_using(self, try_exchange: bool) -> Result<(), DatasetError> {
        sync_dir(&self.dir)?;
        let (parent, name) = split(&self.target)?;
        let rename = |from: &Path, to: &Path| {
            std::fs::rename(from, to).map_err(|e| io_error(&self.target, e))
        };
        if !self.target.exists() {
            if let Err(e) = rename(&self.dir, &self.target) {
                // E.g. another writer created the target meanwhile: leave it, drop ours.
                let _ = std::fs::remove_dir_all(&self.dir);
                return Err(e);
            }
        } else if try_exchange
            && exchange(&self.dir, &self.target).map_err(|e| {
                let _ = std::fs::remove_dir_all(&self.dir);
                io_error(&self.target, e)
            })?
        {
            // `self.dir` now holds the old data set.
            std::fs::remove_dir_all(&self.dir).map_err(|e| io_error(&self.dir, e))?;
        } else {
            let aside = parent.join(format!(
                ".{}.old-{}",
                name.to_string_lossy(),
                self.dir
                    .file_name()
                    .map(|f| f.to_string_lossy().into_owned())
                    .unwrap_or_default()
                    .rsplit(".tmp-")
                    .next()
                    .unwrap_or_default()
            ));
            if let Err(e) = rename(&self.target, &aside) {
                let _ = std::fs::remove_dir_all(&self.dir);
                return Err(e);
            }
            if let Err(e) = rename(&self.dir, &self.target) {
                // Put the old data set back; ours is dropped.
                let _ = std::fs::rename(&aside, &self.target);
                let _ = std::fs::remove_dir_all(&self.dir);
                return Err(e);
            }
            std::fs::remove_dir_all(&aside).map_err(|e| io_error(&aside, e))?;
        }
        sync_dir(&parent)?;
        // The new set is in place: copies left aside by killed writers are no longer needed.
        for stale in stale_siblings(&parent, &name.to_string_lossy(), false) {
            let _ = std::fs::remove_dir_all(stale);
        }
        Ok(())
    }

    /// Removes the staged directory after a failure.
    pub(crate) fn abandon(self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh directory under the system temp dir, unique per test, and the guard that removes
    /// it when dropped (also when the test panics).
    fn scratch(name: &str) -> (tempfile::TempDir, PathBuf) {
        let tmp = tempfile::Builder::new()
            .prefix(&format!("replace-{name}-"))
            .tempdir()
            .unwrap();
        let d = tmp.path().to_path_buf();
        (tmp, d)
    }

    fn write_set(target: &Path, content: &str, try_exchange: bool) {
        let s = stage(target).unwrap();
        std::fs::write(s.dir.join(MEASURED), content).unwrap();
        s.commit_using(try_exchange).unwrap();
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn both_paths_replace_the_set_and_leave_nothing_beside_it() {
        for try_exchange in [true, false] {
            let (_tmp, d) = scratch(&format!("paths-{try_exchange}"));
            let target = d.join("ds");
            write_set(&target, "one", try_exchange);
            write_set(&target, "two", try_exchange);
            assert_eq!(
                std::fs::read_to_string(target.join(MEASURED)).unwrap(),
                "two"
            );
            assert_eq!(entries(&d), vec!["ds".to_string()]);
            assert_eq!(entries(&target), vec![MEASURED.to_string()]);
        }
    }

    #[test]
    fn an_abandoned_staging_leaves_the_old_set() {
        let (_tmp, d) = scratch("abandon");
        let target = d.join("ds");
        write_set(&target, "one", true);
        let s = stage(&target).unwrap();
        std::fs::write(s.dir.join(MEASURED), "partial").unwrap();
        s.abandon();
        assert_eq!(
            std::fs::read_to_string(target.join(MEASURED)).unwrap(),
            "one"
        );
        assert_eq!(entries(&d), vec!["ds".to_string()]);
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_is_kept_and_its_target_replaced() {
        let (_tmp, d) = scratch("link");
        let real = d.join("real");
        write_set(&real, "one", true);
        let link = d.join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_set(&link, "two", true);
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(real.join(MEASURED)).unwrap(), "two");
    }
}
