//! `cargo xtask <task>`: project tasks written as plain Rust (the cargo-xtask pattern).
//!
//! - `reproduce-paper [--quick] [--resume] [--threads N] [--shard i/n]`: builds `sysid` in release
//!   (the libraries it builds are the ones `cargo test --release` links) and runs `sysid reproduce` from the workspace root into `results/paper/` (or
//!   `results/paper-quick/`). Every run is computed unless `--resume` is given; then records whose
//!   fingerprint matches are reused.
//! - `reproduce-scaling [--quick] [--resume] [--report-only] [--threads N] [--shard i/n]`: builds `sysid` in
//!   release and runs `sysid scaling` (`experiments/scaling.toml`) into `results/scaling/` (or
//!   `results/scaling-quick/`); sharded and resumed like `reproduce-paper`.
//! - `reproduce-excitations [same options]`: the same for the excitations study
//!   (`experiments/excitations.toml`, `results/excitations/`).
//! - `reproduce-real [--no-baseline] [--report-only]`: builds `sysid` in release, installs the
//!   baseline's Python package (`experiments/real/requirements.txt`, PyPI's `mdof`) into a
//!   virtual environment under `target/`, and runs `sysid field-study` on
//!   `experiments/real/study.toml` into `results/real/` and on
//!   `experiments/real/unseen/study.toml` (structures the defaults never saw) into
//!   `results/unseen/` (REPORT.md each). Without Python or network
//!   the committed baseline numbers are used and the run says so.
//! - `regression [--threads N] [--resume]`: builds `sysid` in release and runs `sysid regression`
//!   on `experiments/regression.toml` (the paper's settings, into `results/regression/`),
//!   `experiments/regression-symplectic.toml` (into `results/regression-symplectic/`) and
//!   `experiments/regression-defaults.toml` (`sysid filter`'s default settings, with bounds on
//!   the 95 % coverage of k and c, into `results/regression-defaults/`) and
//!   `experiments/regression-defaults-n5.toml` (the same on the 5-storey building, where they
//!   sub-step against the velocity lag, into `results/regression-defaults-n5/`) and
//!   `experiments/regression-defaults-n10.toml` (on the 10-storey building, where the
//!   MPF-EKF2's prior is per particle, into `results/regression-defaults-n10/`); fails when a
//!   bound is breached.
//!   Every run is computed unless `--resume` is given.
//! - `docs`: regenerates the README's headline table (from the paper's Fig. 7 records),
//!   `docs/cli.md` (from `sysid`'s own help) and the module layers of `docs/architecture.md`;
//!   tests fail when any has drifted.
//! - `imports [--write-doc]`: fails when a crate has an import cycle between its top-level
//!   modules, else prints each crate's modules in layers (leaves first); `--write-doc` writes
//!   them into `docs/architecture.md` (a test fails when they have drifted).
//! - `fuzz [--seed N] [--probes N] [--timeout S] [--python PATH] [--jobs N] [--only T] [--list]`:
//!   builds `sysid` in release and runs the fuzz driver (`experiments::fuzz`, docs/guarantees.md):
//!   hostile inputs against every subcommand (and the Python package with `--python`); prints a
//!   table per subcommand and fails on a crash, a hang, a write outside a probe's outputs or a
//!   refusal without a message, leaving reproducers in `target/fuzz/failures-seed<N>/`.
//! - `bench [--full]`: runs the criterion benchmarks of `core-filters` (short measurement times
//!   unless `--full`), then appends one dated line per benchmark to `results/perf/history.csv`
//!   and prints the change against the previous line of the same benchmark.

mod foreign;
mod fuzz;
mod imports;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "xtask", about = "Project tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Reproduce the paper: every study, figure, summary.json and REPORT.md under results/paper.
    ReproducePaper {
        /// Few runs, fewer particles (writes results/paper-quick).
        #[arg(long)]
        quick: bool,
        /// Worker threads (0: one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Run part i of n of every sweep (then `sysid merge`, and run again with `--resume`
        /// and without `--shard` to draw).
        #[arg(long)]
        shard: Option<String>,
        /// Reuse the existing records whose fingerprint (configuration, data, seed, numerics
        /// version) matches; without it, every run is computed.
        #[arg(long)]
        resume: bool,
    },
    /// The scaling study (experiments/scaling.toml): records, figures and REPORT.md under
    /// results/scaling.
    ReproduceScaling(StudyArgs),
    /// Regenerate the generated documentation: the README's headline table (from the records in
    /// results/paper/records/fig7), docs/cli.md (from sysid's own help) and the module layers of docs/architecture.md.
    Docs,
    /// Check that no crate has an import cycle between its top-level modules and print each
    /// crate's modules in layers, leaves first.
    Imports {
        /// Rewrite the layers in docs/architecture.md.
        #[arg(long)]
        write_doc: bool,
    },
    /// The excitations study (experiments/excitations.toml): records, figures and REPORT.md
    /// under results/excitations.
    ReproduceExcitations(StudyArgs),
    /// The real-structure case study (experiments/real/study.toml): records, figures and
    /// REPORT.md under results/real.
    ReproduceReal {
        /// Do not recompute the baseline (SRIM, Python); use the committed srim.json.
        #[arg(long)]
        no_baseline: bool,
        /// Compute nothing: write REPORT.md from the records already there.
        #[arg(long)]
        report_only: bool,
        /// Keep the files of an interrupted run instead of recomputing them.
        #[arg(long)]
        resume: bool,
    },
    /// The foreign corpus (experiments::foreign, docs/foreign.md): each case identified with
    /// the minimal flags, validated on a held-out earthquake, beside SRIM; records and
    /// REPORT.md under results/foreign.
    ReproduceForeign {
        /// Do not compute the baseline (SRIM, Python package mdof).
        #[arg(long)]
        no_baseline: bool,
        /// Compute nothing: write REPORT.md from the files already there.
        #[arg(long)]
        report_only: bool,
    },
    /// Identification-accuracy regression checks (experiments/regression.toml,
    /// regression-symplectic.toml, regression-defaults.toml, regression-defaults-n5.toml and
    /// regression-defaults-n10.toml).
    Regression {
        /// Worker threads (0: one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Reuse the records of an interrupted check whose fingerprint matches instead of
        /// computing every run.
        #[arg(long)]
        resume: bool,
    },
    /// Hostile inputs against every sysid subcommand (and the Python package with --python):
    /// fails on a crash, a hang, a write outside a probe's outputs or a refusal without a
    /// message; reproducers in `target/fuzz/failures-seed<N>/`.
    Fuzz(fuzz::FuzzArgs),
    /// Run the criterion benchmarks (release) and append the medians to results/perf/history.csv.
    Bench {
        /// Criterion's own measurement times instead of the short ones.
        #[arg(long)]
        full: bool,
    },
}

/// The workspace root (the parent of this crate's directory). `cargo run` sets
/// `CARGO_MANIFEST_DIR` for the process, and that value wins over the one compiled in: two clones
/// that share a `CARGO_TARGET_DIR` share one `xtask` binary, whose compiled-in directory is the
/// clone that built it last.
fn root() -> PathBuf {
    let manifest_dir = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    manifest_dir
        .parent()
        .expect("xtask lives inside the workspace")
        .to_path_buf()
}

fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|t| if t.is_relative() { root.join(t) } else { t })
        .unwrap_or_else(|| root.join("target"))
}

fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn run(cmd: &mut Command) -> Result<()> {
    let status = cmd.status().with_context(|| format!("starting {cmd:?}"))?;
    if !status.success() {
        bail!("{cmd:?} failed with {status}");
    }
    Ok(())
}

/// Options of a study with a structure axis (`reproduce-scaling`, `reproduce-excitations`).
#[derive(Debug, clap::Args)]
struct StudyArgs {
    /// The study's quick form (writes `results/<study>-quick`).
    #[arg(long)]
    quick: bool,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Run part i of n of the sweep (then `sysid merge`, and run again with `--resume` and
    /// without `--shard` to write the report).
    #[arg(long)]
    shard: Option<String>,
    /// Reuse the existing records whose fingerprint matches; without it, every run is
    /// computed.
    #[arg(long)]
    resume: bool,
    /// Compute nothing: write the report from the records already there.
    #[arg(long)]
    report_only: bool,
}

/// Builds `sysid` and runs `sysid <study>` on `experiments/<study>.toml` into
/// `results/<study>` (or `results/<study>-quick`).
fn reproduce_study(root: &Path, study: &str, a: StudyArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let sysid = build_sysid(root)?;
    let build_s = started.elapsed().as_secs_f64();
    let out = if a.quick {
        format!("results/{study}-quick")
    } else {
        format!("results/{study}")
    };
    let config = format!("experiments/{study}.toml");
    let mut cmd = Command::new(sysid);
    cmd.current_dir(root).args([
        study,
        "--config",
        &config,
        "--out",
        &out,
        "--threads",
        &a.threads.to_string(),
    ]);
    if a.quick {
        cmd.arg("--quick");
    }
    if let Some(s) = &a.shard {
        cmd.args(["--shard", s]);
    }
    if a.resume {
        cmd.arg("--resume");
    }
    if a.report_only {
        cmd.arg("--report-only");
    }
    run(&mut cmd)?;
    eprintln!(
        "reproduce-{study}: {:.0} s in all (build {build_s:.0} s, study {:.0} s)",
        started.elapsed().as_secs_f64(),
        started.elapsed().as_secs_f64() - build_s
    );
    Ok(())
}

/// Builds the release `sysid` (with cargo's own progress: a first build takes minutes) and
/// returns its path.
fn build_sysid(root: &Path) -> Result<PathBuf> {
    eprintln!("building sysid (release; a first build takes a few minutes)");
    run(Command::new(cargo()).current_dir(root).args([
        "build",
        "--release",
        "-p",
        "experiments",
        "--bin",
        "sysid",
    ]))?;
    Ok(target_dir(root).join("release/sysid"))
}

fn main() -> Result<()> {
    identify::logger::install_logger();
    let root = root();
    match Cli::parse().task {
        Task::ReproducePaper {
            quick,
            threads,
            shard,
            resume,
        } => {
            let started = std::time::Instant::now();
            let sysid = build_sysid(&root)?;
            let build_s = started.elapsed().as_secs_f64();
            let out = if quick {
                "results/paper-quick"
            } else {
                "results/paper"
            };
            let mut cmd = Command::new(sysid);
            cmd.current_dir(&root).args([
                "reproduce",
                "--experiments",
                "experiments",
                "--out",
                out,
                "--threads",
                &threads.to_string(),
            ]);
            if quick {
                cmd.arg("--quick");
            }
            if let Some(s) = shard {
                cmd.args(["--shard", &s]);
            }
            if resume {
                cmd.arg("--resume");
            }
            run(&mut cmd)?;
            eprintln!(
                "reproduce-paper: {:.0} s in all (build {build_s:.0} s, reproduction {:.0} s)",
                started.elapsed().as_secs_f64(),
                started.elapsed().as_secs_f64() - build_s
            );
            Ok(())
        }
        Task::ReproduceScaling(a) => reproduce_study(&root, "scaling", a),
        Task::ReproduceExcitations(a) => reproduce_study(&root, "excitations", a),
        Task::Regression { threads, resume } => {
            let sysid = build_sysid(&root)?;
            // The paper's (forward Euler) filters, the symplectic scheme's bounds, then the
            // default settings of `sysid filter` (with coverage bounds) on the paper's structure
            // and on the 5-storey building (its velocity-lag sub-steps) and the 10-storey one (its
            // per-particle prior).
            for (config, out) in [
                ("experiments/regression.toml", "results/regression"),
                (
                    "experiments/regression-symplectic.toml",
                    "results/regression-symplectic",
                ),
                (
                    "experiments/regression-defaults.toml",
                    "results/regression-defaults",
                ),
                (
                    "experiments/regression-defaults-n5.toml",
                    "results/regression-defaults-n5",
                ),
                (
                    "experiments/regression-defaults-n10.toml",
                    "results/regression-defaults-n10",
                ),
            ] {
                let mut cmd = Command::new(&sysid);
                cmd.current_dir(&root).args([
                    "regression",
                    "--config",
                    config,
                    "--out",
                    out,
                    "--threads",
                    &threads.to_string(),
                ]);
                // Every run is computed by the code being checked unless asked to resume (then
                // only records with a matching fingerprint are reused).
                if resume {
                    cmd.arg("--resume");
                }
                run(&mut cmd)?;
            }
            Ok(())
        }
        Task::ReproduceForeign {
            no_baseline,
            report_only,
        } => {
            let started = std::time::Instant::now();
            let sysid = build_sysid(&root)?;
            let python = if no_baseline || report_only {
                None
            } else {
                Some(baseline_python(&root)?)
            };
            foreign::reproduce(&root, &sysid, python, report_only)?;
            eprintln!(
                "reproduce-foreign: {:.0} s in all",
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Task::ReproduceReal {
            no_baseline,
            report_only,
            resume,
        } => reproduce_real(&root, no_baseline, report_only, resume),
        Task::Bench { full } => bench(&root, full),
        Task::Fuzz(a) => {
            let sysid = build_sysid(&root)?;
            fuzz::run(&root, &target_dir(&root), sysid, a)
        }
        Task::Docs => docs(&root),
        Task::Imports { write_doc } => imports::run(&root, write_doc),
    }
}

/// The real-structure case study: `sysid field-study`, with the baseline's Python package
/// installed into `target/real-python` when it can be.
/// The real-structure studies: the structures the defaults were developed on, then those they
/// never saw (`experiments/real/unseen/`).
const REAL_STUDIES: [(&str, &str); 2] = [
    ("experiments/real/study.toml", "results/real"),
    ("experiments/real/unseen/study.toml", "results/unseen"),
];

fn reproduce_real(root: &Path, no_baseline: bool, report_only: bool, resume: bool) -> Result<()> {
    let started = std::time::Instant::now();
    let sysid = build_sysid(root)?;
    let build_s = started.elapsed().as_secs_f64();
    let python = if report_only || no_baseline {
        None
    } else {
        match baseline_python(root) {
            Ok(python) => Some(python),
            Err(e) => {
                eprintln!(
                    "note: the baseline (SRIM, Python package mdof) is not recomputed: {e:#}; the committed srim.json files are used"
                );
                None
            }
        }
    };
    for (config, out) in REAL_STUDIES {
        let mut cmd = Command::new(&sysid);
        cmd.current_dir(root)
            .args(["field-study", "--config", config, "--out", out]);
        if resume {
            cmd.arg("--resume");
        }
        if report_only {
            cmd.arg("--report-only");
        } else if let Some(python) = &python {
            cmd.arg("--python").arg(python);
        }
        run(&mut cmd)?;
    }
    eprintln!(
        "reproduce-real: {:.0} s in all (build {build_s:.0} s, study {:.0} s)",
        started.elapsed().as_secs_f64(),
        started.elapsed().as_secs_f64() - build_s
    );
    Ok(())
}

/// A virtual environment with the baseline's requirements (created once, under `target/`).
fn baseline_python(root: &Path) -> Result<PathBuf> {
    let venv = target_dir(root).join("real-python");
    let python = venv.join("bin/python");
    let stamp = venv.join("requirements.txt");
    let wanted = fs::read_to_string(root.join("experiments/real/requirements.txt"))
        .context("reading experiments/real/requirements.txt")?;
    if python.exists() && fs::read_to_string(&stamp).is_ok_and(|t| t == wanted) {
        return Ok(python);
    }
    eprintln!(
        "installing the baseline's Python packages into {}",
        venv.display()
    );
    run(Command::new("python3").arg("-m").arg("venv").arg(&venv))?;
    run(Command::new(&python)
        .args(["-m", "pip", "install", "--quiet", "-r"])
        .arg(root.join("experiments/real/requirements.txt")))?;
    fs::write(&stamp, wanted)?;
    Ok(python)
}

/// Writes the generated parts of the documentation (tests compare them with their sources).
fn docs(root: &Path) -> Result<()> {
    let sysid = build_sysid(root)?;
    let cli = experiments::cli_reference::render(&sysid)?;
    write_if_changed(&root.join("docs/cli.md"), &cli)?;
    let table = experiments::headline::from_dir(&root.join("results/paper/records/fig7"))?;
    let readme_path = root.join("README.md");
    let readme = fs::read_to_string(&readme_path)
        .with_context(|| format!("reading {}", readme_path.display()))?;
    write_if_changed(
        &readme_path,
        &experiments::headline::splice(&readme, &table)?,
    )?;
    imports::run(root, true)
}

/// Writes `text` to `path` unless it already holds it (says which).
fn write_if_changed(path: &Path, text: &str) -> Result<()> {
    if fs::read_to_string(path).is_ok_and(|old| old == text) {
        eprintln!("{}: up to date", path.display());
        return Ok(());
    }
    fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("{}: written", path.display());
    Ok(())
}

/// Runs the benchmarks, then records the medians of those this run measured.
fn bench(root: &Path, full: bool) -> Result<()> {
    let started = SystemTime::now();
    let mut cmd = Command::new(cargo());
    cmd.current_dir(root)
        // The bench targets only (`--benches` would also run the library's unit tests, whose
        // harness rejects criterion's options).
        .args([
            "bench",
            "-p",
            "core-filters",
            "-p",
            "experiments",
            "--bench",
            "*",
        ])
        // The bench profile keeps debug assertions for `cargo test --release`; the benchmarks
        // measure the code `sysid` runs, without them.
        .args([
            "--config",
            "profile.bench.debug-assertions=false",
            "--config",
            "profile.bench.overflow-checks=false",
        ]);
    if !full {
        // Enough for a few-percent median on steps of 10 µs to 10 ms; trends, not proofs.
        cmd.args([
            "--",
            "--warm-up-time",
            "1",
            "--measurement-time",
            "3",
            "--sample-size",
            "20",
        ]);
    }
    run(&mut cmd)?;
    let mut measured = Vec::new();
    collect_estimates(&target_dir(root).join("criterion"), started, &mut measured)?;
    if measured.is_empty() {
        bail!("no criterion estimates written by this run");
    }
    measured.sort_by(|a, b| a.name.cmp(&b.name));
    let history = root.join("results/perf/history.csv");
    append_history(&history, &date_today(), &git_rev(root), &measured)
}

/// One benchmark measured by this run.
#[derive(Debug, Clone, PartialEq)]
struct Measured {
    name: String,
    median_ns: f64,
    /// Elements (particles) per iteration, when the benchmark declares a throughput.
    elements: Option<f64>,
}

/// Walks `dir` for `new/estimates.json` written after `since`, with the name and throughput
/// from the `new/benchmark.json` beside it.
fn collect_estimates(dir: &Path, since: SystemTime, out: &mut Vec<Measured>) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for entry in entries {
        let path = entry?.path();
        if !path.is_dir() {
            continue;
        }
        let est = path.join("new/estimates.json");
        let fresh = fs::metadata(&est)
            .and_then(|m| m.modified())
            .is_ok_and(|t| t >= since);
        if fresh {
            let e = fs::read_to_string(&est)?;
            let b = fs::read_to_string(path.join("new/benchmark.json"))?;
            let median_ns = json_number_after(&e, "\"median\"", "\"point_estimate\":")
                .with_context(|| format!("no median in {}", est.display()))?;
            let name = json_string(&b, "\"full_id\":")
                .with_context(|| format!("no full_id beside {}", est.display()))?;
            let elements = json_number_after(&b, "\"throughput\"", "\"Elements\":");
            out.push(Measured {
                name,
                median_ns,
                elements,
            });
        } else if path.file_name().is_some_and(|n| n != "report") {
            collect_estimates(&path, since, out)?;
        }
    }
    Ok(())
}

/// The number following `key` after the first `anchor` of a compact JSON text (criterion's own
/// files: a fixed shape, no need for a JSON dependency in this crate).
fn json_number_after(text: &str, anchor: &str, key: &str) -> Option<f64> {
    let rest = &text[text.find(anchor)? + anchor.len()..];
    let rest = &rest[rest.find(key)? + key.len()..];
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    rest[..end].trim().parse().ok()
}

/// The string value of `key` (no escapes expected in criterion ids).
fn json_string(text: &str, key: &str) -> Option<String> {
    let rest = text[text.find(key)? + key.len()..].trim_start();
    let rest = rest.strip_prefix('"')?;
    Some(rest[..rest.find('"')?].to_string())
}

const HISTORY_HEADER: &str = "date,git_rev,benchmark,median_ns,particle_steps_per_s";

/// A CSV field, quoted when it holds a comma or a quote.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Splits one CSV line (quoted fields with doubled quotes).
fn csv_split(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    out.push(cur);
    out
}

/// Appends this run's lines to the history and prints each median against the last line of the
/// same benchmark.
fn append_history(path: &Path, date: &str, rev: &str, measured: &[Measured]) -> Result<()> {
    let old = fs::read_to_string(path).unwrap_or_default();
    let mut previous = std::collections::BTreeMap::new();
    for line in old.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        let f = csv_split(line);
        if let (Some(name), Some(Ok(median))) = (f.get(2), f.get(3).map(|m| m.parse::<f64>())) {
            previous.insert(name.clone(), (f[0].clone(), f[1].clone(), median));
        }
    }
    let mut text = if old.is_empty() {
        format!("{HISTORY_HEADER}\n")
    } else if old.ends_with('\n') {
        old
    } else {
        old + "\n"
    };
    println!(
        "{:<58} {:>13} {:>14} {:>9}  previous",
        "benchmark", "median", "particle-st/s", "change"
    );
    for m in measured {
        let rate = m.elements.map(|n| n / (m.median_ns * 1e-9));
        text.push_str(&format!(
            "{date},{rev},{},{:.1},{}\n",
            csv_field(&m.name),
            m.median_ns,
            rate.map_or(String::new(), |r| format!("{r:.0}"))
        ));
        let (change, prev) = match previous.get(&m.name) {
            Some((d, r, p)) => (
                format!("{:+.1}%", 100.0 * (m.median_ns / p - 1.0)),
                format!("{} ({d}, {r})", human_ns(*p)),
            ),
            None => ("new".into(), String::new()),
        };
        println!(
            "{:<58} {:>13} {:>14} {:>9}  {prev}",
            m.name,
            human_ns(m.median_ns),
            rate.map_or(String::new(), |r| format!("{r:.3e}")),
            change
        );
    }
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    println!("appended {} lines to {}", measured.len(), path.display());
    Ok(())
}

fn human_ns(ns: f64) -> String {
    match ns {
        n if n >= 1e6 => format!("{:.3} ms", n / 1e6),
        n if n >= 1e3 => format!("{:.2} µs", n / 1e3),
        n => format!("{n:.0} ns"),
    }
}

/// The short git revision, with `-dirty` when the benchmarked crate has uncommitted changes.
fn git_rev(root: &Path) -> String {
    let out = Command::new("git")
        .current_dir(root)
        .args(["rev-parse", "--short", "HEAD"])
        .output();
    let Some(out) = out.ok().filter(|o| o.status.success()) else {
        return "unknown".into();
    };
    let rev = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let clean = Command::new("git")
        .current_dir(root)
        .args(["diff", "--quiet", "HEAD", "--", "crates/core-filters"])
        .status()
        .is_ok_and(|s| s.success());
    if clean {
        rev
    } else {
        format!("{rev}-dirty")
    }
}

/// Today's UTC date, YYYY-MM-DD.
fn date_today() -> String {
    let days = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() / 86_400) as i64;
    let (y, m, d) = civil_from_days(days);
    format!("{y:04}-{m:02}-{d:02}")
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

    #[test]
    fn dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
    }

    #[test]
    fn criterion_json() {
        let e = r#"{"mean":{"point_estimate":2.0,"x":1},"median":{"confidence_interval":{"lower_bound":1.0},"point_estimate":38037.5,"standard_error":4.0}}"#;
        assert_eq!(
            json_number_after(e, "\"median\"", "\"point_estimate\":"),
            Some(38037.5)
        );
        let b = r#"{"group_id":"g","throughput":{"Elements":500},"full_id":"particle-step/bootstrap/nx16"}"#;
        assert_eq!(
            json_string(b, "\"full_id\":").as_deref(),
            Some("particle-step/bootstrap/nx16")
        );
        assert_eq!(
            json_number_after(b, "\"throughput\"", "\"Elements\":"),
            Some(500.0)
        );
        let none = r#"{"throughput":null,"full_id":"kf"}"#;
        assert_eq!(
            json_number_after(none, "\"throughput\"", "\"Elements\":"),
            None
        );
    }

    #[test]
    fn csv_round_trip() {
        let name = "second_order_terms 13 states, 5 \"outputs\"";
        let line = format!("2024-01-01,abc,{},1.0,", csv_field(name));
        let f = csv_split(&line);
        assert_eq!(f.len(), 5);
        assert_eq!(f[2], name);
        assert_eq!(f[4], "");
    }

    #[test]
    fn history_appends_and_compares() {
        let dir = tempfile::Builder::new()
            .prefix("xtask-history-")
            .tempdir()
            .unwrap();
        let path = dir.path().join("history.csv");
        let m = |ns| Measured {
            name: "a, b".into(),
            median_ns: ns,
            elements: Some(500.0),
        };
        append_history(&path, "2024-01-01", "r1", &[m(1000.0)]).unwrap();
        append_history(&path, "2024-01-02", "r2", &[m(2000.0)]).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], HISTORY_HEADER);
        assert_eq!(lines[1], "2024-01-01,r1,\"a, b\",1000.0,500000000");
        assert_eq!(lines[2], "2024-01-02,r2,\"a, b\",2000.0,250000000");
    }
}
