//! The lock of an output directory: one writer at a time (`reproduce`, `merge`, `regression`).
//!
//! The lock is the file `DIR/.sysid.lock`, created only if absent (published by a hard link of a
//! complete temporary file, so a reader never sees a half-written lock) and holding its holder:
//! process id, host, command line and start time. A second writer finds it and stops with a
//! message naming the holder. A lock whose holder is gone — same host, and no process with its
//! id is running (or the id now belongs to a process started at another time) — is stale: it is
//! taken over with a message. A lock from another host is never taken over (its process cannot
//! be checked from here): the message says which file to remove once that process is known to
//! have ended. The holder removes the file when it finishes; a killed holder leaves it behind,
//! stale.

use std::fs;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::error::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// File name of the lock inside the directory it guards.
pub const LOCK_FILE: &str = ".sysid.lock";

/// Who holds a lock.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Holder {
    pub pid: u32,
    pub host: String,
    /// The holder's command line.
    pub command: String,
    /// Start time, UTC (RFC 3339).
    pub started: String,
    /// The kernel's start time of the process (Linux `/proc/PID/stat`, clock ticks since boot),
    /// to tell the holder from a later process that reuses its id.
    #[serde(default)]
    pub process_start: Option<u64>,
}

impl Holder {
    /// This process.
    pub fn me() -> Self {
        let pid = std::process::id();
        Self {
            pid,
            host: host_name(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            started: utc_now(),
            process_start: process_start(pid),
        }
    }

    fn describe(&self) -> String {
        format!(
            "pid {} on {} (`{}`, started {})",
            self.pid, self.host, self.command, self.started
        )
    }
}

/// A held lock; dropping it releases the directory.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
    holder: Holder,
}

impl DirLock {
    /// Takes the lock of `dir` (created if needed) or fails naming its holder.
    pub fn acquire(dir: &Path) -> Result<Self> {
        fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join(LOCK_FILE);
        let me = Holder::me();
        let text = serde_json::to_string_pretty(&me)? + "\n";
        for _ in 0..5 {
            match publish(&path, &text) {
                Ok(()) => {
                    clean_leftovers(dir);
                    return Ok(Self { path, holder: me });
                }
                Err(e) if e.kind() == ErrorKind::AlreadyExists => {}
                Err(e) => return Err(e).with_context(|| format!("creating {}", path.display())),
            }
            let Some(found) = read_lock(&path, dir)? else {
                continue;
            };
            let Ok(holder) = serde_json::from_str::<Holder>(&found) else {
                bail!(
                    "{} exists but does not name a holder; if no sysid is writing to {}, remove it",
                    path.display(),
                    dir.display()
                );
            };
            if holder.host != me.host {
                bail!(
                    "{} is in use by {} (lock {}); wait for it to finish, or remove the lock \
                     once that process is known to have ended",
                    dir.display(),
                    holder.describe(),
                    path.display()
                );
            }
            if is_running(holder.pid, holder.process_start) {
                bail!(
                    "{} is in use by {}; wait for it to finish (lock {})",
                    dir.display(),
                    holder.describe(),
                    path.display()
                );
            }
            log::warn!(
                "taking over the lock of {} left by {}, which is no longer running",
                dir.display(),
                holder.describe()
            );
            take_over(&path, &found)?;
        }
        bail!(
            "could not take the lock {} (other writers kept taking it)",
            path.display()
        )
    }

    /// Who holds this lock (this process).
    #[cfg(test)]
    pub(crate) fn holder(&self) -> &Holder {
        &self.holder
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        let ours = fs::read_to_string(&self.path)
            .ok()
            .and_then(|t| serde_json::from_str::<Holder>(&t).ok())
            .is_some_and(|h| h == self.holder);
        if ours {
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// The text of the lock `path` of `dir`, or `None` when it has gone meanwhile. A lock that is
/// not a regular file (a named pipe, whose read would wait for a writer; a link; a directory)
/// was not written by `sysid` and is refused, naming it; a regular one is read within the
/// input limits.
fn read_lock(path: &Path, dir: &Path) -> Result<Option<String>> {
    match fs::symlink_metadata(path) {
        Ok(m) if !m.file_type().is_file() => bail!(
            "{} is {}, not a lock written by sysid; if no sysid is writing to {}, remove it",
            path.display(),
            models::readers::file_kind(m.file_type()),
            dir.display()
        ),
        Err(e) if e.kind() == ErrorKind::NotFound => return Ok(None),
        _ => {}
    }
    match models::readers::read_input_text(path) {
        Ok(t) => Ok(Some(t)),
        Err(models::readers::ReadError::Io { source, .. })
            if source.kind() == ErrorKind::NotFound =>
        {
            Ok(None)
        }
        Err(e) => Err(e).with_context(|| format!("reading the lock of {}", dir.display())),
    }
}

/// Creates `path` with `text` only if it does not exist: a complete temporary file, hard-linked
/// to `path` (fails with `AlreadyExists` when the lock is held). Where hard links are not
/// supported, an exclusive create.
fn publish(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension(format!("lock.tmp{}", std::process::id()));
    fs::write(&tmp, text)?;
    let linked = fs::hard_link(&tmp, path);
    let _ = fs::remove_file(&tmp);
    match linked {
        Err(e) if e.kind() != ErrorKind::AlreadyExists => {
            use std::io::Write as _;
            let mut f = fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(path)?;
            f.write_all(text.as_bytes())
        }
        other => other,
    }
}

/// Removes a stale lock whose text was `stale`, without removing a lock another process took
/// meanwhile: the lock is first renamed to a name of this process; if what was renamed is not the
/// stale lock, it is put back.
fn take_over(path: &Path, stale: &str) -> Result<()> {
    let aside = path.with_extension(format!("lock.stale{}", std::process::id()));
    match fs::rename(path, &aside) {
        Ok(()) => {}
        Err(e) if e.kind() == ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e).with_context(|| format!("removing the stale {}", path.display())),
    }
    if fs::read_to_string(&aside).ok().as_deref() != Some(stale) {
        // Another writer's fresh lock: restore it (unless yet another one exists).
        let _ = fs::hard_link(&aside, path);
    }
    let _ = fs::remove_file(&aside);
    Ok(())
}

/// Removes the temporary and set-aside lock files (`.sysid.lock.tmp<pid>`,
/// `.sysid.lock.stale<pid>`) of processes that have ended.
fn clean_leftovers(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let pid = name.to_str().and_then(|n| {
            let rest = n.strip_prefix(LOCK_FILE)?;
            let digits = rest
                .strip_prefix(".tmp")
                .or_else(|| rest.strip_prefix(".stale"))?;
            digits.parse::<u32>().ok()
        });
        if let Some(pid) = pid {
            if pid != std::process::id() && !is_running(pid, None) {
                let _ = fs::remove_file(entry.path());
            }
        }
    }
}

/// Whether a process with id `pid` (and, when known, kernel start time `start`) is running on
/// this host. On Linux from `/proc` (a zombie counts as ended); elsewhere `kill -0`.
pub(crate) fn is_running(pid: u32, start: Option<u64>) -> bool {
    if Path::new("/proc/self/stat").exists() {
        let Ok(stat) = fs::read_to_string(format!("/proc/{pid}/stat")) else {
            return false;
        };
        let Some(fields) = stat_fields(&stat) else {
            return true;
        };
        if fields.first() == Some(&"Z") || fields.first() == Some(&"X") {
            return false;
        }
        match (start, fields.get(19).and_then(|s| s.parse::<u64>().ok())) {
            (Some(want), Some(got)) => want == got,
            _ => true,
        }
    } else {
        std::process::Command::new("kill")
            .args(["-0", &pid.to_string()])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    }
}

/// Fields of `/proc/PID/stat` after the command name: state is field 0, start time field 19.
fn stat_fields(stat: &str) -> Option<Vec<&str>> {
    let rest = &stat[stat.rfind(')')? + 1..];
    Some(rest.split_whitespace().collect())
}

fn process_start(pid: u32) -> Option<u64> {
    let stat = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat_fields(&stat)?.get(19)?.parse().ok()
}

fn host_name() -> String {
    ["/proc/sys/kernel/hostname", "/etc/hostname"]
        .iter()
        .find_map(|p| fs::read_to_string(p).ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown-host".into())
}

/// The current time, UTC, as `YYYY-MM-DDTHH:MM:SSZ`.
pub(crate) fn utc_now() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A directory, not yet created, inside a fresh directory under the system temp dir, and
    /// the guard that removes them when dropped (also when the test panics).
    fn temp(tag: &str) -> (tempfile::TempDir, PathBuf) {
        let tmp = tempfile::Builder::new()
            .prefix(&format!("sysid-lock-{tag}-"))
            .tempdir()
            .unwrap();
        let d = tmp.path().join("out");
        (tmp, d)
    }

    #[test]
    fn a_second_writer_is_refused_with_the_holder_named() {
        let (_tmp, dir) = temp("held");
        let lock = DirLock::acquire(&dir).unwrap();
        let e = DirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains(&format!("pid {}", std::process::id())), "{e}");
        assert!(e.contains("in use by"), "{e}");
        drop(lock);
        assert!(!dir.join(LOCK_FILE).exists(), "released lock left behind");
        DirLock::acquire(&dir).unwrap();
    }

    /// A lock that is a named pipe, a link to nothing or a directory is refused by name at
    /// once (a named pipe made `merge` wait for a writer forever); it is left as it was.
    #[test]
    #[cfg(unix)]
    fn a_lock_that_is_not_a_regular_file_is_refused_at_once() {
        let (_tmp, dir) = temp("special");
        fs::create_dir_all(&dir).unwrap();
        let lock = dir.join(LOCK_FILE);
        let fifo = std::ffi::CString::new(lock.to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path that outlives the call.
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o644) }, 0);
        let e = DirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains("named pipe") && e.contains(LOCK_FILE), "{e}");
        fs::remove_file(&lock).unwrap();
        std::os::unix::fs::symlink("nowhere", &lock).unwrap();
        let e = DirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
        assert!(fs::symlink_metadata(&lock)
            .unwrap()
            .file_type()
            .is_symlink());
        fs::remove_file(&lock).unwrap();
        fs::create_dir(&lock).unwrap();
        let e = DirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains("a directory"), "{e}");
    }

    #[test]
    fn a_stale_lock_is_taken_over() {
        let (_tmp, dir) = temp("stale");
        fs::create_dir_all(&dir).unwrap();
        // A holder on this host whose process has ended: this process's id with another start
        // time.
        let mut dead = Holder::me();
        dead.process_start = dead.process_start.map(|s| s + 1).or(Some(0));
        dead.pid = if Path::new("/proc/self/stat").exists() {
            dead.pid
        } else {
            u32::MAX - 1
        };
        fs::write(dir.join(LOCK_FILE), serde_json::to_string(&dead).unwrap()).unwrap();
        let leftover = dir.join(format!("{LOCK_FILE}.tmp4294967"));
        fs::write(&leftover, "{").unwrap();
        let lock = DirLock::acquire(&dir).unwrap();
        assert_eq!(lock.holder().pid, std::process::id());
        assert!(
            !leftover.exists(),
            "a dead writer's temporary lock file was kept"
        );
        drop(lock);
    }

    #[test]
    fn a_lock_from_another_host_is_kept() {
        let (_tmp, dir) = temp("host");
        fs::create_dir_all(&dir).unwrap();
        let mut other = Holder::me();
        other.host = "some-other-host".into();
        fs::write(dir.join(LOCK_FILE), serde_json::to_string(&other).unwrap()).unwrap();
        let e = DirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains("some-other-host"), "{e}");
        assert!(dir.join(LOCK_FILE).exists());
    }

    #[test]
    fn utc_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        assert_eq!(utc_now().len(), 20);
    }
}
