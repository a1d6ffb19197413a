//! `last-run.json`: what the invocation that last wrote a study's results did (wall times, runs
//! executed, threads, revision). It sits beside the results but is not committed, so a
//! reproduction that agrees with the committed records leaves them unchanged.

use std::path::Path;

use crate::error::Result;

use super::write_bytes_atomic;

/// The file, beside a study's results, that holds what the invocation that last wrote them did
/// (timings, runs executed, revision); it is not committed.
pub const FILE: &str = "last-run.json";

/// Writes [`FILE`] into `out`: the toolkit's version, the git revision, the threads and the
/// study's own `facts` (wall times, runs executed).
pub fn write(out: &Path, threads: usize, facts: serde_json::Value) -> Result<()> {
    let threads = if threads == 0 {
        rayon::current_num_threads()
    } else {
        threads
    };
    let value = serde_json::json!({
        "toolkit": env!("CARGO_PKG_VERSION"),
        "git_revision": git_revision(),
        "threads": threads,
        "facts": facts,
    });
    write_bytes_atomic(
        &out.join(FILE),
        (serde_json::to_string_pretty(&value)? + "\n").as_bytes(),
    )
}

/// The git revision of the working tree, when the tool runs inside one ("unknown" otherwise).
fn git_revision() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}
