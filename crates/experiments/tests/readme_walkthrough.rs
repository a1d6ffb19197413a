//! The README's walk-through runs as written, from a scratch directory: every `sysid` command of
//! its "A first run" and "Your own recording" blocks, in order, in a fresh temporary directory
//! (so the project's own files are found from elsewhere, and nothing is written into the
//! checkout).

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The shell lines of the first ```sh block after the heading `heading`, continuations joined.
fn block(readme: &str, heading: &str) -> Vec<String> {
    let after = readme
        .split_once(heading)
        .unwrap_or_else(|| panic!("README has no heading {heading}"))
        .1;
    let body = after
        .split_once("```sh\n")
        .expect("a sh block")
        .1
        .split_once("```")
        .expect("closed")
        .0;
    body.replace("\\\n", " ")
        .lines()
        .map(|l| l.split(" #").next().unwrap().trim().to_string())
        .filter(|l| !l.is_empty())
        .collect()
}

#[test]
fn the_readme_walkthrough_runs_from_a_scratch_directory() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let first = block(&readme, "## A first run");
    assert!(first[0].starts_with("cargo install"), "{first:?}");
    assert_eq!(first[1], "cd \"$(mktemp -d)\"");
    let own = block(&readme, "## Your own recording");
    let scratch = tempfile::Builder::new()
        .prefix("sysid-readme-")
        .tempdir()
        .unwrap();
    let mut ran = 0;
    for line in first[2..].iter().chain(&own) {
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(
            words[0], "sysid",
            "a README line that is not a sysid command: {line}"
        );
        let out = Command::new(env!("CARGO_BIN_EXE_sysid"))
            .current_dir(scratch.path())
            .args(&words[1..])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{line}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        ran += 1;
    }
    assert_eq!(ran, 6);
    // What they wrote is in the scratch directory.
    for p in ["d", "r.json", "r-figures", "frame-northridge", "frame.json"] {
        assert!(scratch.path().join(p).exists(), "{p}");
    }
}
