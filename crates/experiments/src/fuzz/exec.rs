//! Runs one probe's program with a time limit and says how it ended.
//!
//! The program runs in a process group of its own, so that a hang is ended with everything it
//! started; its standard output and error go to files (a pipe that nobody reads would block a
//! chatty program, and a closed one is not what is being tested).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How a program ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Ended {
    /// It exited with this code.
    Code(i32),
    /// A signal ended it (not the driver's kill).
    Signal(i32),
    /// It was still running at the time limit and was killed.
    TimedOut,
}

/// What a run left.
#[derive(Debug, Clone)]
pub(crate) struct Ran {
    pub(crate) ended: Ended,
    /// Its standard error, lossily decoded: whole up to [`WHOLE`] bytes, else its first and
    /// last [`KEPT`] bytes.
    pub(crate) stderr: String,
    pub(crate) took: Duration,
}

/// Standard error up to this size is kept whole (a long error message is measured).
const WHOLE: u64 = 4 << 20;
/// Of a longer one (a flood of log lines), this much of each end.
const KEPT: u64 = 16 << 10;

/// Runs `cmd` (its arguments, directory and environment set) with `timeout`; `capture` is a
/// directory for its output files, outside every tree that is compared.
pub(crate) fn run(mut cmd: Command, timeout: Duration, capture: &Path) -> std::io::Result<Ran> {
    use std::os::unix::process::CommandExt;
    let out = std::fs::File::create(capture.join("stdout"))?;
    let err = std::fs::File::create(capture.join("stderr"))?;
    cmd.stdin(Stdio::null())
        .stdout(Stdio::from(out))
        .stderr(Stdio::from(err))
        .process_group(0);
    let started = Instant::now();
    let mut child = cmd.spawn()?;
    let group = child.id() as i32;
    let ended = loop {
        if let Some(status) = child.try_wait()? {
            break ended(status);
        }
        if started.elapsed() > timeout {
            kill_group(group);
            child.wait()?;
            break Ended::TimedOut;
        }
        std::thread::sleep(poll(started.elapsed()));
    };
    // Whatever the program left running ends with it.
    kill_group(group);
    Ok(Ran {
        ended,
        stderr: tail(&capture.join("stderr")),
        took: started.elapsed(),
    })
}

/// Short waits first: most probes end within milliseconds.
fn poll(elapsed: Duration) -> Duration {
    if elapsed < Duration::from_millis(50) {
        Duration::from_millis(1)
    } else {
        Duration::from_millis(10)
    }
}

fn ended(status: std::process::ExitStatus) -> Ended {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => Ended::Code(code),
        (None, Some(signal)) => Ended::Signal(signal),
        (None, None) => Ended::Code(-1),
    }
}

fn kill_group(group: i32) {
    // SAFETY: `kill` with a negative id signals the process group the child leads (made by
    // `process_group(0)`); it touches no memory of this process. A group that is gone gives
    // ESRCH, which is what is wanted.
    unsafe {
        libc::kill(-group, libc::SIGKILL);
    }
}

/// A file whole up to [`WHOLE`] bytes, else its first and last [`KEPT`] bytes, lossily
/// decoded.
fn tail(path: &Path) -> String {
    use std::io::{Read, Seek, SeekFrom};
    let Ok(mut f) = std::fs::File::open(path) else {
        return String::new();
    };
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let mut head = Vec::new();
    let _ = (&mut f)
        .take(WHOLE.min(len).max(KEPT))
        .read_to_end(&mut head);
    if len <= WHOLE {
        return String::from_utf8_lossy(&head).into_owned();
    }
    head.truncate(KEPT as usize);
    let _ = f.seek(SeekFrom::Start(len - KEPT));
    let mut end = Vec::new();
    let _ = f.take(KEPT).read_to_end(&mut end);
    format!(
        "{}\n[… {} bytes …]\n{}",
        String::from_utf8_lossy(&head),
        len - 2 * KEPT,
        String::from_utf8_lossy(&end)
    )
}

/// The name of a signal that ends a process.
pub(crate) fn signal_name(signal: i32) -> String {
    match signal {
        libc::SIGABRT => "SIGABRT".into(),
        libc::SIGSEGV => "SIGSEGV".into(),
        libc::SIGBUS => "SIGBUS".into(),
        libc::SIGILL => "SIGILL".into(),
        libc::SIGFPE => "SIGFPE".into(),
        libc::SIGKILL => "SIGKILL".into(),
        libc::SIGPIPE => "SIGPIPE".into(),
        libc::SIGTERM => "SIGTERM".into(),
        s => format!("signal {s}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exits_signals_and_hangs_are_told_apart() {
        let tmp = tempfile::tempdir().unwrap();
        let sh = |script: &str| {
            let mut c = Command::new("sh");
            c.args(["-c", script]);
            c
        };
        let long = Duration::from_secs(20);
        let r = run(sh("echo oops >&2; exit 3"), long, tmp.path()).unwrap();
        assert_eq!((r.ended, r.stderr.trim()), (Ended::Code(3), "oops"));
        let r = run(sh("kill -ABRT $$"), long, tmp.path()).unwrap();
        assert_eq!(r.ended, Ended::Signal(libc::SIGABRT));
        // A hang, with a child of its own that ends with it.
        let r = run(
            sh("sleep 30 & sleep 30"),
            Duration::from_millis(200),
            tmp.path(),
        )
        .unwrap();
        assert_eq!(r.ended, Ended::TimedOut);
        assert!(r.took < Duration::from_secs(10), "{:?}", r.took);
    }
}
