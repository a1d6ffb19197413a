//! The README's walk-through runs as written, from a scratch directory: every `sysid` command of
//! its "A first run" and "Your own recording" blocks, in order, in a fresh temporary directory
//! (so the project's own files are found from elsewhere, and nothing is written into the
//! checkout). The numbers the README states of those runs, of the foreign corpus and of the unseen
//! real structures are the runs' own: each is found, at the README's precision, in what the
//! commands printed and wrote or in the report it cites.

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
    let mut printed = String::new();
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
        printed.push_str(&String::from_utf8_lossy(&out.stdout));
        printed.push_str(&String::from_utf8_lossy(&out.stderr));
        ran += 1;
    }
    assert_eq!(ran, 6);
    // What they wrote is in the scratch directory.
    for p in ["d", "r.json", "r-figures", "frame-northridge", "frame.json"] {
        assert!(scratch.path().join(p).exists(), "{p}");
    }
    // "Measured on this frame": from the frame's commands, their record and the study's report.
    let record = std::fs::read_to_string(scratch.path().join("frame.json")).unwrap();
    let real = std::fs::read_to_string(root().join("results/real/REPORT.md")).unwrap();
    let frame = between(&readme, "Measured on this frame:", "The whole comparison");
    assert_numbers_found(frame, &[&printed, &record, &real], 8);
    // The foreign corpus: from its report.
    let foreign = std::fs::read_to_string(root().join("results/foreign/REPORT.md")).unwrap();
    let corpus = between(
        &readme,
        "On structures nobody tuned it for",
        "results/foreign/REPORT.md",
    );
    assert_numbers_found(corpus, &[&foreign], 2);
    // The real structures it was never developed on: from their study's report.
    let unseen = std::fs::read_to_string(root().join("results/unseen/REPORT.md")).unwrap();
    let structures = between(
        &readme,
        "On six real structures it was never developed on",
        "results/unseen/REPORT.md",
    );
    assert_numbers_found(structures, &[&unseen], 4);
}

fn between<'a>(text: &'a str, start: &str, end: &str) -> &'a str {
    let after = text
        .split_once(start)
        .unwrap_or_else(|| panic!("README has no {start:?}"))
        .1;
    after
        .split_once(end)
        .unwrap_or_else(|| panic!("README has no {end:?} after {start:?}"))
        .0
}

/// The numbers of a text in order: (as written, value, start, end).
fn numbers(text: &str) -> Vec<(String, f64, usize, usize)> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut start = 0;
    for (i, ch) in text
        .char_indices()
        .chain(std::iter::once((text.len(), ' ')))
    {
        if ch.is_ascii_digit() || (ch == '.' && !cur.is_empty() && !cur.contains('.')) {
            if cur.is_empty() {
                start = i;
            }
            cur.push(ch);
            continue;
        }
        let t = cur.trim_end_matches('.').to_string();
        if let Ok(v) = t.parse::<f64>() {
            out.push((t.clone(), v, start, start + t.len()));
        }
        cur.clear();
    }
    out
}

/// The README's claims as groups: numbers written together ("67.7 / 73.7 / 75.4", "0.097 [0.000,
/// 0.612]"), nothing but punctuation between them.
fn groups(text: &str) -> Vec<Vec<String>> {
    let mut out: Vec<Vec<String>> = Vec::new();
    let mut last_end = None;
    for (t, _, start, end) in numbers(text) {
        let joined = last_end
            .is_some_and(|e: usize| text[e..start].chars().all(|c| " /,[]()–-".contains(c)));
        match out.last_mut() {
            Some(g) if joined => g.push(t),
            _ => out.push(vec![t]),
        }
        last_end = Some(end);
    }
    out
}

/// Every group of numbers of `claims` that holds a number with a decimal point or of three digits
/// or more (two-digit whole numbers alone — counts, dates — are not checked) is found in one of
/// `sources` in that order, each within a few numbers of the one before and equal at the
/// README's precision.
fn assert_numbers_found(claims: &str, sources: &[&str], at_least: usize) {
    let streams: Vec<Vec<f64>> = sources
        .iter()
        .map(|s| numbers(s).into_iter().map(|n| n.1).collect())
        .collect();
    let mut checked = 0;
    for g in groups(claims) {
        if !g.iter().any(|t| t.contains('.') || t.len() >= 3) {
            continue;
        }
        checked += 1;
        let found = streams
            .iter()
            .any(|s| (0..s.len()).any(|i| in_order(s, i, &g)));
        assert!(
            found,
            "the README states {g:?}, which no output, record or report it cites holds in that \
             order at that precision"
        );
    }
    assert!(
        checked >= at_least,
        "{checked} groups checked in {claims:?}"
    );
}

/// Whether `stream[i]` shows `group[0]` and each later member of `group` follows within the next
/// `GAP` numbers of the one before (a table row prints a mode's frequency, damping and measured
/// peak before the next mode's), each equal at the README's precision.
fn in_order(stream: &[f64], i: usize, group: &[String]) -> bool {
    const GAP: usize = 8;
    let Some((first, rest)) = group.split_first() else {
        return true;
    };
    let decimals = first.split_once('.').map_or(0, |(_, d)| d.len());
    format!("{:.decimals$}", stream[i]) == *first
        && (rest.is_empty()
            || (i + 1..(i + 1 + GAP).min(stream.len())).any(|j| in_order(stream, j, rest)))
}
