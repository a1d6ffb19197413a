//! The paper reproduction (SPEC §8): runs every study of `experiments/`, draws every figure from
//! the records, and writes `summary.json` and `REPORT.md` with the paper's statements beside our
//! measurements.
//!
//! Every run is computed unless the caller asks to resume; then a record is reused only when its
//! fingerprint matches the job's (see [`crate::sweep`]). The output directory is locked for the
//! whole reproduction ([`crate::sweep::lock`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{bail, Result};

use crate::engine::{load, write_json, Engine, Reuse, RunMode};
use crate::run_dir::open;
use crate::study::Study;
use crate::sweep::progress::clock;
use crate::sweep::write_bytes_atomic;
use identify::figures;
use identify::pipeline::Algorithm;
use identify::record::RunRecord;

pub(crate) use crate::stats::algorithm_stats;
pub use crate::stats::{AlgorithmStats, ParamStats, STUDIES};

/// Options of a reproduction.
#[derive(Debug, Clone)]
pub struct Options {
    /// Directory of the study configs.
    pub experiments: PathBuf,
    pub out: PathBuf,
    pub mode: RunMode,
}

/// What a reproduction did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Done {
    /// Runs of this shard.
    pub total: usize,
    /// Runs computed by this invocation.
    pub executed: usize,
    /// Records reused (resume with a matching fingerprint).
    pub reused: usize,
    /// Computed runs that failed.
    pub failed: usize,
}

/// Records of a study grouped by algorithm, in the study's algorithm order.
fn by_algorithm<'a>(
    study: &Study,
    records: &'a [RunRecord],
) -> Vec<(Algorithm, Vec<&'a RunRecord>)> {
    study
        .sweep
        .algorithms
        .iter()
        .map(|a| {
            (
                *a,
                records.iter().filter(|r| r.algorithm == a.name()).collect(),
            )
        })
        .collect()
}

/// The studies of a reproduction by name, and their records.
type StudiesAndRecords = (
    BTreeMap<&'static str, Study>,
    BTreeMap<&'static str, Vec<RunRecord>>,
);

/// Runs the reproduction. With a shard other than `0/1`, only runs this shard's records (no
/// figures, no report): merge the shards' `records/` and run again without `--shard` (with
/// `--resume`) to draw. Returns what was done.
pub fn reproduce(opts: &Options) -> Result<Done> {
    let start = Instant::now();
    let (_lock, engine) = open(&opts.out, opts.mode)?;
    let mut done = Done::default();
    let (studies, records) = run_studies(opts, &engine, &mut done)?;
    let (executed, total_jobs) = (done.executed, done.total);
    if engine.sharded() {
        engine.shard_note(&format!(
            "{total_jobs} runs, {executed} executed ({} failed), {} reused, {}",
            done.failed,
            done.reused,
            clock(start.elapsed())
        ));
        return Ok(done);
    }
    let sweep_s = start.elapsed().as_secs_f64();

    crate::table1::write(&opts.out.join("table1"))?;
    let mut summary = paper_summary(&studies, &records);
    let coverage = draw_figures(opts, &studies, &records)?;
    summary.extend(crate::discretisation::summary(&records));
    let total_s = start.elapsed().as_secs_f64();
    write_json(
        &opts.out.join("summary.json"),
        &serde_json::json!({
            "quick": opts.mode.quick,
            "studies": summary,
            "coverage": coverage,
        }),
    )?;
    let report = crate::report::write_report(
        &crate::report::Target {
            out: &opts.out,
            quick: opts.mode.quick,
        },
        &studies,
        &records,
        &summary,
        total_jobs,
    )?;
    let path = opts.out.join("REPORT.md");
    write_bytes_atomic(&path, report.as_bytes())?;
    // What this invocation did, beside the committed results but not among them: timings and
    // counts change from run to run even when every record agrees.
    engine.last_run(serde_json::json!({
            "wall_s": { "sweeps": sweep_s, "total": total_s },
        "runs": { "executed": executed, "reused": done.reused, "failed": done.failed, "total": total_jobs },
    }))?;
    log::info!(
        "wrote {}; {total_jobs} runs: {executed} executed ({} failed), {} reused; {}",
        path.display(),
        done.failed,
        done.reused,
        clock(start.elapsed())
    );
    Ok(done)
}

/// Runs (or reuses the records of) every study of `opts.experiments`: the paper's, then the
/// discretisation studies when they are configured. Adds each sweep's counts to `done`.
fn run_studies(opts: &Options, engine: &Engine<'_>, done: &mut Done) -> Result<StudiesAndRecords> {
    let mut studies = BTreeMap::new();
    let mut records = BTreeMap::new();
    for &name in STUDIES.iter().chain(&crate::discretisation::STUDIES) {
        let path = opts.experiments.join(format!("{name}.toml"));
        // The section beyond the paper runs when its studies are configured.
        if crate::discretisation::STUDIES.contains(&name) && !path.exists() {
            continue;
        }
        let study = load(&path, opts.mode.quick)?;
        let decided = name == "fig7" || crate::discretisation::STUDIES.contains(&name);
        if !decided && !study.verdicts.is_empty() {
            bail!(
                "{}: the reproduction decides the `[[verdicts]]` of fig7.toml and of the \
                 discretisation studies only; declare the statement there",
                path.display()
            );
        }
        // The discretisation studies take over the Fig. 7 records that are the same jobs.
        let reuse = match crate::discretisation::STUDIES.contains(&name) {
            true => Reuse::new(
                records
                    .get(crate::discretisation::SOURCE)
                    .into_iter()
                    .flatten(),
            ),
            false => Reuse::default(),
        };
        let outcome = engine.sweep(
            &study,
            &study.jobs(),
            &opts.out.join("records").join(name),
            Study::job_id,
            |job| reuse.run(&study, job),
        )?;
        if opts.mode.progress && reuse.taken() > 0 {
            log::info!(
                "{name}: {} records taken over from {} (same fingerprint)",
                reuse.taken(),
                crate::discretisation::SOURCE
            );
        }
        done.total += outcome.records.len();
        done.executed += outcome.executed;
        done.reused += outcome.reused;
        done.failed += outcome.failed;
        records.insert(name, outcome.records);
        studies.insert(name, study);
    }
    Ok((studies, records))
}

/// The statistics of each algorithm in each of the paper's studies, by study.
fn paper_summary<'a>(
    studies: &BTreeMap<&str, Study>,
    records: &BTreeMap<&str, Vec<RunRecord>>,
) -> BTreeMap<&'a str, Vec<AlgorithmStats>> {
    STUDIES
        .iter()
        .map(|name| {
            let groups = by_algorithm(&studies[name], &records[name]);
            (
                *name,
                groups
                    .iter()
                    .map(|(a, r)| algorithm_stats(a.name(), r))
                    .collect(),
            )
        })
        .collect()
}

/// The coverage of every study with a known truth (SPEC §9), returned, and every figure drawn
/// from the records, its figure for the Fig. 7 sweep among them.
fn draw_figures(
    opts: &Options,
    studies: &BTreeMap<&'static str, Study>,
    records: &BTreeMap<&'static str, Vec<RunRecord>>,
) -> Result<BTreeMap<&'static str, crate::coverage::SweepCoverage>> {
    let mut coverage = BTreeMap::new();
    for name in STUDIES {
        if let Some(c) = crate::coverage::study_coverage(&studies[name], &records[name])? {
            coverage.insert(name, c);
        }
    }
    // Every figure is drawn aside and put in place whole (an interrupted reproduction leaves
    // each figure as it was or complete; a resumed one draws them all again from the records).
    identify::plot::figures_in_place(&opts.out, |dir| {
        draw(dir, studies, records)?;
        crate::discretisation::draw(dir, records)?;
        if let Some(c) = coverage.get("fig7") {
            crate::calibration::coverage_figure(
                &c.calibration,
                &dir.join("fig7_coverage.svg"),
                "Fig. 7 sweep — coverage of central credible intervals",
            )?;
        }
        Ok(())
    })?;
    Ok(coverage)
}

/// Draws the paper's figures from the records into `dir`.
fn draw(
    dir: &Path,
    studies: &BTreeMap<&str, Study>,
    records: &BTreeMap<&str, Vec<RunRecord>>,
) -> Result<()> {
    let fig = |name: &str| dir.join(format!("{name}.svg"));
    let first = |study: &str, alg: Algorithm| -> Option<&RunRecord> {
        records[study]
            .iter()
            .find(|r| r.algorithm == alg.name() && r.run == 0)
    };
    if let Some(r) = first("fig4", Algorithm::Bootstrap) {
        figures::convergence(
            &[("Bootstrap PF", r)],
            &fig("fig4a_bootstrap_convergence"),
            "Fig. 4(a) — bootstrap PF, 500 particles: parameter estimates",
        )?;
        figures::hysteresis(
            r,
            &fig("fig4b_bootstrap_loop"),
            "Fig. 4(b) — bootstrap PF: validation hysteresis loop",
        )?;
    }
    let pair = |study: &str, a: Algorithm, b: Algorithm, file: &str, title: &str| -> Result<()> {
        if let (Some(ra), Some(rb)) = (first(study, a), first(study, b)) {
            figures::convergence(&[(a.label(), ra), (b.label(), rb)], &fig(file), title)?;
        }
        Ok(())
    };
    pair(
        "fig5",
        Algorithm::MlnRbpf,
        Algorithm::Storvik,
        "fig5_mlnrbpf_vs_storvik",
        "Fig. 5 — MLN-RBPF vs Storvik, 500 particles",
    )?;
    pair(
        "fig6",
        Algorithm::MlnRbpf,
        Algorithm::MpfEkf2,
        "fig6a_mlnrbpf_vs_mpfekf2",
        "Fig. 6(a) — MLN-RBPF vs MPF-EKF2, 500 particles",
    )?;
    // Fig. 6(b): the paper's pair (MLN-RBPF, MPF-EKF2) over the runs of the Fig. 7 sweep, so that
    // the figure shows distributions rather than one run each; the Fig. 6 study's own runs when
    // the sweep has no completed run of the pair.
    let pair_of = |study: &str| -> Vec<(&str, Vec<&RunRecord>)> {
        by_algorithm(&studies[study], &records[study])
            .into_iter()
            .filter(|(a, _)| matches!(a, Algorithm::MlnRbpf | Algorithm::MpfEkf2))
            .map(|(a, r)| (a.label(), r))
            .collect()
    };
    let has_states = |g: &[(&str, Vec<&RunRecord>)]| {
        g.iter().any(|(_, rs)| {
            rs.iter()
                .any(|r| r.online_states.is_some() && !r.is_failure())
        })
    };
    let (groups6, source) = match pair_of("fig7") {
        g if has_states(&g) => (g, "the runs of the Fig. 7 sweep"),
        _ => (pair_of("fig6"), "the Fig. 6 study"),
    };
    figures::state_errors(
        &groups6,
        &fig("fig6b_state_nrmse"),
        &format!("Fig. 6(b) — online state NRMSE over {source}"),
    )?;
    let groups7: Vec<(&str, Vec<&RunRecord>)> = by_algorithm(&studies["fig7"], &records["fig7"])
        .into_iter()
        .map(|(a, r)| (a.label(), r))
        .collect();
    figures::crosses(
        &groups7,
        &fig("fig7_theta_val_crosses"),
        "Fig. 7 — θ_val / θ_true: mean ± s.d. over runs",
    )?;
    if let Some(r) = first("fig8", Algorithm::MpfEkf2) {
        figures::convergence(
            &[("MPF-EKF2", r)],
            &fig("fig8a_mpfekf2_convergence"),
            "Fig. 8(a) — MPF-EKF2, 500 particles: parameter estimates",
        )?;
        figures::hysteresis(
            r,
            &fig("fig8b_mpfekf2_loop"),
            "Fig. 8(b) — MPF-EKF2: validation hysteresis loop",
        )?;
    }
    Ok(())
}

/// The figure files a full reproduction draws.
pub fn figure_files(out: &Path) -> Vec<PathBuf> {
    [
        "fig4a_bootstrap_convergence",
        "fig4b_bootstrap_loop",
        "fig5_mlnrbpf_vs_storvik",
        "fig6a_mlnrbpf_vs_mpfekf2",
        "fig6b_state_nrmse",
        "fig7_theta_val_crosses",
        "fig8a_mpfekf2_convergence",
        "fig8b_mpfekf2_loop",
        "fig7_coverage",
    ]
    .iter()
    .map(|n| out.join(format!("{n}.svg")))
    .collect()
}
