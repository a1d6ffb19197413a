//! The fuzz driver (`experiments::fuzz`, run longer by `cargo xtask fuzz`) at a small size:
//! hostile inputs made from valid ones against every `sysid` subcommand that reads a user's
//! file, value or output path — and, when `SYSID_PYTHON` names a Python with `sysid_mpf`
//! installed, against the Python package — with no crash, no hang, no write outside a probe's
//! outputs and no refusal without a message. A failure prints the table and the directory of
//! its reproducers (`command.sh` and the probe's files).
#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use experiments::fuzz::{self, Options};

/// Probes of this test: about 30 per `sysid` target, a fixed seed.
const PROBES: usize = 660;

fn options(scratch: &Path, seed: u64, probes: usize) -> Options {
    Options {
        sysid: PathBuf::from(env!("CARGO_BIN_EXE_sysid")),
        python: std::env::var_os("SYSID_PYTHON").map(PathBuf::from),
        repository: Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."),
        scratch: scratch.join("scratch"),
        failures: Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-failures"),
        seed,
        probes,
        timeout: Duration::from_secs(30),
        jobs: 2,
        only: Vec::new(),
        unguarded: Vec::new(),
    }
}

#[test]
fn hostile_inputs_neither_crash_hang_nor_write_outside_their_outputs() {
    let tmp = tempfile::Builder::new()
        .prefix("sysid-fuzz-")
        .tempdir()
        .unwrap();
    let opts = options(tmp.path(), 1, PROBES);
    let started = std::time::Instant::now();
    let report = fuzz::run(&opts).unwrap();
    let table = report.table();
    eprintln!("{table}");
    eprintln!("fuzz run: {:.1} s", started.elapsed().as_secs_f64());
    assert!(report.passed(), "{table}");
    // Every target was probed, and each both refused and accepted something: the probes reach
    // past the first check and are not all valid.
    for row in &report.rows {
        assert!(row.probes > 0, "{} not probed:\n{table}", row.target);
        assert!(row.refused > 0, "{} refused nothing:\n{table}", row.target);
    }
    let accepted: usize = report.rows.iter().map(|r| r.accepted).sum();
    assert!(accepted > PROBES / 10, "{accepted} accepted:\n{table}");
}

/// A seed reproduces its probes byte for byte: the seed files made again are the same (their
/// first line is their digest), and so is every probe; another seed makes other probes.
#[test]
fn a_seed_reproduces_its_probes() {
    let tmp = tempfile::Builder::new()
        .prefix("sysid-fuzz-plan-")
        .tempdir()
        .unwrap();
    let plan = |seed| fuzz::plan(&options(tmp.path(), seed, 200)).unwrap();
    let (a, b, c) = (plan(7), plan(7), plan(8));
    assert!(a[0].starts_with("seeds: "), "{}", a[0]);
    assert_eq!(a, b);
    assert_eq!(a[0], c[0]);
    assert_ne!(a, c);
    // Every `sysid` target is among them.
    for name in fuzz::target_names()
        .iter()
        .filter(|n| !n.starts_with("py "))
    {
        assert!(
            a.iter().any(|l| l.contains(&format!(" {name}: "))),
            "{name} not in the plan"
        );
    }
}
