//! Mutations of valid input files for the property-based reader tests: truncation, byte
//! flips, inserted and replaced tokens (huge numbers, NaN/∞, separators, a byte-order mark),
//! extra and missing columns and lines, CRLF line ends. Positions are fractions of the length,
//! so one mutation applies to any file. Shared by the fuzz tests of `models` and
//! `experiments`.
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestError, TestRng, TestRunner};
use std::path::{Path, PathBuf};

/// Tokens that broke or could break a reader.
pub const TOKENS: &[&str] = &[
    "1e308",
    "-1e308",
    "1e309",
    "NaN",
    "inf",
    "-inf",
    "1e30",
    "1e12",
    "1e7",
    "1e6",
    "1e300",
    "1e-300",
    "0",
    "-0",
    "-1",
    "",
    ",",
    "\n",
    "\r\n",
    "\u{feff}",
    "\"",
    "[]",
    "{}",
    "null",
    "18446744073709551616",
    "4294967296",
    "9e18",
    "1D3",
    "abc",
    " ",
    "#",
    "=",
    "NPTS= 1e30",
    "DT= 1e6",
    ",,",
    "[1e308]",
    "true",
    "\u{0}",
    "é",
];

#[derive(Debug, Clone)]
pub enum Mutation {
    Truncate(f64),
    Delete { at: f64, len: usize },
    Insert { at: f64, token: usize },
    ReplaceNumber { nth: usize, token: usize },
    SetByte { at: f64, byte: u8 },
    DropField { line: usize },
    AddField { line: usize, token: usize },
    DuplicateLine { line: usize },
    DeleteLine { line: usize },
    Crlf,
    Bom,
}

pub fn mutation() -> impl Strategy<Value = Mutation> {
    let tok = 0..TOKENS.len();
    prop_oneof![
        (0.0..1.0f64).prop_map(Mutation::Truncate),
        (0.0..1.0f64, 1..40usize).prop_map(|(at, len)| Mutation::Delete { at, len }),
        (0.0..1.0f64, tok.clone()).prop_map(|(at, token)| Mutation::Insert { at, token }),
        (0..400usize, tok.clone()).prop_map(|(nth, token)| Mutation::ReplaceNumber { nth, token }),
        (0.0..1.0f64, any::<u8>()).prop_map(|(at, byte)| Mutation::SetByte { at, byte }),
        (0..60usize).prop_map(|line| Mutation::DropField { line }),
        (0..60usize, tok).prop_map(|(line, token)| Mutation::AddField { line, token }),
        (0..60usize).prop_map(|line| Mutation::DuplicateLine { line }),
        (0..60usize).prop_map(|line| Mutation::DeleteLine { line }),
        Just(Mutation::Crlf),
        Just(Mutation::Bom),
    ]
}

/// One to four mutations.
pub fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    prop::collection::vec(mutation(), 1..5)
}

fn pos(len: usize, at: f64) -> usize {
    ((len as f64 * at) as usize).min(len)
}

/// Byte ranges of the number-like tokens (runs of digits, `.`, `e`, `E`, `+`, `-`).
fn numbers(b: &[u8]) -> Vec<(usize, usize)> {
    let is = |c: u8| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'+' | b'-');
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() || (b[i] == b'.' && i + 1 < b.len() && b[i + 1].is_ascii_digit()) {
            let mut j = i;
            // Include a sign just before.
            let start = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
            while j < b.len() && is(b[j]) {
                j += 1;
            }
            out.push((start, j));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

fn lines(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push((start, i));
            start = i + 1;
        }
    }
    if start < b.len() {
        out.push((start, b.len()));
    }
    out
}

fn apply_one(b: &mut Vec<u8>, m: &Mutation) {
    match *m {
        Mutation::Truncate(at) => b.truncate(pos(b.len(), at)),
        Mutation::Delete { at, len } => {
            let s = pos(b.len(), at);
            let e = (s + len).min(b.len());
            b.drain(s..e);
        }
        Mutation::Insert { at, token } => {
            let s = pos(b.len(), at);
            b.splice(s..s, TOKENS[token].bytes());
        }
        Mutation::ReplaceNumber { nth, token } => {
            let nums = numbers(b);
            if !nums.is_empty() {
                let (s, e) = nums[nth % nums.len()];
                b.splice(s..e, TOKENS[token].bytes());
            }
        }
        Mutation::SetByte { at, byte } => {
            if !b.is_empty() {
                let s = pos(b.len() - 1, at);
                b[s] = byte;
            }
        }
        Mutation::DropField { line } => {
            let ls = lines(b);
            if !ls.is_empty() {
                let (s, e) = ls[line % ls.len()];
                if let Some(c) = b[s..e].iter().rposition(|&c| c == b',') {
                    b.drain(s + c..e);
                }
            }
        }
        Mutation::AddField { line, token } => {
            let ls = lines(b);
            if !ls.is_empty() {
                let (_, e) = ls[line % ls.len()];
                let mut add = b",".to_vec();
                add.extend_from_slice(TOKENS[token].as_bytes());
                b.splice(e..e, add);
            }
        }
        Mutation::DuplicateLine { line } => {
            let ls = lines(b);
            if !ls.is_empty() {
                let (s, e) = ls[line % ls.len()];
                let mut copy = b[s..e].to_vec();
                copy.push(b'\n');
                b.splice(s..s, copy);
            }
        }
        Mutation::DeleteLine { line } => {
            let ls = lines(b);
            if !ls.is_empty() {
                let (s, e) = ls[line % ls.len()];
                let e = (e + 1).min(b.len());
                b.drain(s..e);
            }
        }
        Mutation::Crlf => {
            let mut out = Vec::with_capacity(b.len() + 64);
            for &c in b.iter() {
                if c == b'\n' {
                    out.push(b'\r');
                }
                out.push(c);
            }
            *b = out;
        }
        Mutation::Bom => {
            b.splice(0..0, "\u{feff}".bytes());
        }
    }
}

/// `seed` with the mutations applied in order.
pub fn apply(seed: &[u8], muts: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in muts {
        apply_one(&mut b, m);
    }
    b
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
pub fn scratch(name: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("fuzz-{name}-"))
        .tempdir()
        .unwrap();
    let dir = tmp.path().to_path_buf();
    (tmp, dir)
}

/// Runs `cases` cases of `test` on inputs from `strategy` with a fixed seed. A failure is
/// shrunk to a minimal input, written to `<temp>/fuzz-crash-<target>` for the corpus, and
/// reported.
pub fn run<S: Strategy>(
    target: &str,
    seed: u8,
    cases: u32,
    strategy: S,
    input_bytes: impl Fn(&S::Value) -> Vec<u8>,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
) where
    S::Value: std::fmt::Debug,
{
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 2_000,
        ..Config::default()
    };
    let mut runner = TestRunner::new_with_rng(
        config,
        TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32]),
    );
    let start = std::time::Instant::now();
    let result = runner.run(&strategy, test);
    eprintln!(
        "fuzz {target}: {cases} cases in {:.2} s",
        start.elapsed().as_secs_f64()
    );
    match result {
        Ok(()) => {}
        Err(TestError::Fail(reason, value)) => {
            let crash = std::env::temp_dir().join(format!("fuzz-crash-{target}"));
            std::fs::write(&crash, input_bytes(&value)).unwrap();
            panic!(
                "fuzz {target}: {reason}\ninput written to {} (add it to the corpus)\n{value:?}",
                crash.display()
            );
        }
        Err(e) => panic!("fuzz {target}: {e}"),
    }
}

/// Files of the corpus directory `dir` (sorted), for the regression tests.
pub fn corpus(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    out.retain(|p| p.is_file());
    out.sort();
    out
}
