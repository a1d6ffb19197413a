//! Atomic writes: a file is replaced whole or not at all (records, and every file a sweep or
//! merge writes), and only a regular file is ever replaced.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Why an output path is refused; every variant names the path and the option that gave it.
#[derive(Debug, Error)]
pub enum OutputError {
    /// The path exists and is not a regular file. The rename that puts a new file in place
    /// would replace it: a symbolic link would become a file (its target left stale), a device
    /// such as `/dev/null` (as root) a file in `/dev`.
    #[error(
        "{flag} {}: exists and is {what}, not a regular file; an output is written only as a \
         new file or over a regular file",
        path.display()
    )]
    NotAFile {
        flag: String,
        path: PathBuf,
        what: &'static str,
    },
    /// The path is a file the command reads.
    #[error(
        "{flag} {}: is {input_flag} {}, which this command reads; choose another {flag}",
        path.display(),
        input.display()
    )]
    IsAnInput {
        flag: String,
        path: PathBuf,
        input_flag: String,
        input: PathBuf,
    },
    /// The path could not be examined.
    #[error("{flag} {}: {source}", path.display())]
    Io {
        flag: String,
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// Checks that `path` (given as `flag`) may be replaced: it does not exist, or it is a regular
/// file (not followed through a symbolic link: a link is refused, not its target written).
pub(crate) fn check_replaceable(path: &Path, flag: &str) -> Result<(), OutputError> {
    match fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_file() => Ok(()),
        Ok(m) => Err(OutputError::NotAFile {
            flag: flag.to_string(),
            path: path.to_path_buf(),
            what: models::readers::file_kind(m.file_type()),
        }),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(OutputError::Io {
            flag: flag.to_string(),
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// Whether `a` and `b` are the same existing file (also through another name: a hard link or a
/// path that differs in spelling).
fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (fs::metadata(a), fs::metadata(b)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        ma.dev() == mb.dev() && ma.ino() == mb.ino()
    }
    #[cfg(not(unix))]
    {
        let _ = (ma, mb);
        matches!((fs::canonicalize(a), fs::canonicalize(b)), (Ok(x), Ok(y)) if x == y)
    }
}

/// Checks an output path before a command's work: replaceable (`check_replaceable`) and none
/// of the command's `inputs` (option, path). An input that is a directory stands for the
/// data-set files in it (`measured.csv`, ...), which is what the commands read from one.
pub fn check_output(out: &Path, flag: &str, inputs: &[(&str, &Path)]) -> Result<(), OutputError> {
    check_replaceable(out, flag)?;
    for &(input_flag, input) in inputs {
        let files: Vec<PathBuf> = if input.is_dir() {
            models::dataset::replace::DATASET_FILES
                .iter()
                .map(|f| input.join(f))
                .collect()
        } else {
            vec![input.to_path_buf()]
        };
        if let Some(hit) = files.into_iter().find(|f| same_file(out, f)) {
            return Err(OutputError::IsAnInput {
                flag: flag.to_string(),
                path: out.to_path_buf(),
                input_flag: input_flag.to_string(),
                input: hit,
            });
        }
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically: a temporary file `<name>.tmp<pid>` in the same
/// directory, then a rename over `path`. An interruption leaves either the old file or the new
/// one, never a part of either (and possibly the temporary file, removed by the next sweep or
/// merge of the directory). A `path` that exists and is not a regular file is refused
/// (`check_replaceable`): every file the tool writes goes through here, so none replaces a
/// device, a pipe or a symbolic link.
/// The error names the file and what was being done.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} names no file", path.display()),
        )
    })?;
    // The option that named the path is the caller's to add; here it is the path that is
    // refused.
    check_replaceable(path, "output")
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
    let mut tmp_name = name.to_os_string();
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    write_and_rename(&tmp, path, bytes)
}

/// Writes `bytes` to `tmp` and renames it over `path`. When either fails, `tmp` is removed: a
/// failed write leaves nothing behind (a failed rename used to leave the whole temporary file).
/// The error names the file and what was being done; a missing directory is said as such.
fn write_and_rename(tmp: &Path, path: &Path, bytes: &[u8]) -> io::Result<()> {
    // The message carries the path: an `io::Error` has no other place for it.
    let named = |what: String| move |e: io::Error| io::Error::new(e.kind(), format!("{what}: {e}"));
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!(
                    "writing {}: the directory {} does not exist",
                    path.display(),
                    dir.display()
                ),
            ));
        }
    }
    let done = fs::write(tmp, bytes)
        .map_err(named(format!("writing {}", path.display())))
        .and_then(|()| {
            fs::rename(tmp, path).map_err(named(format!("renaming into {}", path.display())))
        });
    if done.is_err() {
        let _ = fs::remove_file(tmp);
    }
    done
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn links_directories_and_inputs_are_refused_and_files_replaced() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("a.json");
        write_bytes_atomic(&file, b"one").unwrap();
        write_bytes_atomic(&file, b"two").unwrap();
        assert_eq!(fs::read(&file).unwrap(), b"two");
        let link = tmp.path().join("link.json");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        let e = write_bytes_atomic(&link, b"three").unwrap_err();
        assert!(e.to_string().contains("a symbolic link"), "{e}");
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read(&file).unwrap(), b"two");
        // A rename that fails (over a directory that appeared after the check) leaves no
        // temporary file; a missing directory is named as such, not by a temporary file.
        let dir = tmp.path().join("d.json");
        fs::create_dir(&dir).unwrap();
        fs::write(dir.join("keep"), b"keep").unwrap();
        let t = tmp.path().join("d.json.tmp1");
        assert!(write_and_rename(&t, &dir, b"new").is_err());
        assert!(!t.exists());
        assert_eq!(fs::read(dir.join("keep")).unwrap(), b"keep");
        let e = write_bytes_atomic(&tmp.path().join("no/such/r.json"), b"x").unwrap_err();
        assert!(
            e.to_string().contains("the directory") && !e.to_string().contains("r.json.tmp"),
            "{e}"
        );
        let e = write_bytes_atomic(tmp.path(), b"x").unwrap_err();
        assert!(e.to_string().contains("names no file") || e.to_string().contains("directory"));
        let e = check_output(&file, "--out", &[("--record", &file)]).unwrap_err();
        assert!(e.to_string().contains("--out") && e.to_string().contains("--record"));
        let hard = tmp.path().join("hard.json");
        fs::hard_link(&file, &hard).unwrap();
        assert!(check_output(&hard, "--out", &[("--record", &file)]).is_err());
        assert!(check_output(
            &tmp.path().join("new.json"),
            "--out",
            &[("--record", &file)]
        )
        .is_ok());
    }
}
