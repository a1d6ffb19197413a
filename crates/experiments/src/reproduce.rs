//! The paper reproduction (SPEC §8): runs every study of `experiments/`, draws every figure from
//! the records, and writes `summary.json` and `REPORT.md` with the paper's statements beside our
//! measurements.
//!
//! Every run is computed unless the caller asks to resume; then a record is reused only when its
//! fingerprint matches the job's (see [`crate::sweep`]). The output directory is locked for the
//! whole reproduction ([`crate::sweep::lock`]).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use serde::Serialize;

use crate::figures;
use crate::metrics::mean_sd;
use crate::pipeline::Algorithm;
use crate::record::RunRecord;
use crate::study::Study;
use crate::sweep::lock::DirLock;
use crate::sweep::progress::clock;
use crate::sweep::{run_sweep, write_bytes_atomic, Shard, SweepOptions};

/// The studies of the reproduction, in the order they run.
pub const STUDIES: [&str; 5] = ["fig4", "fig5", "fig6", "fig8", "fig7"];

/// The paper's θ_val for its Fig. 8 run (eq. 31).
pub const PAPER_EQ31: [f64; 9] = [
    7.973, 7.912, 7.943, 0.277, 0.342, 0.278, 3.418, 0.960, 2.488,
];

/// Options of a reproduction.
#[derive(Debug, Clone)]
pub struct Options {
    pub experiments: PathBuf,
    pub out: PathBuf,
    pub quick: bool,
    pub threads: usize,
    pub shard: Shard,
    /// Show progress and the summary of each sweep on stderr.
    pub progress: bool,
    /// Reuse records whose fingerprint matches (otherwise every run is computed).
    pub resume: bool,
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

/// Per algorithm and parameter: statistics of θ_val over the runs of a study.
#[derive(Debug, Clone, Serialize)]
pub struct ParamStats {
    pub name: String,
    pub truth: f64,
    /// Mean and s.d. over runs of θ_val / θ_true.
    pub ratio_mean: f64,
    pub ratio_sd: f64,
    /// Mean over runs of the relative error |θ_val − θ_true| / θ_true.
    pub rel_error_mean: f64,
}

/// Per algorithm: statistics over the runs of a study.
#[derive(Debug, Clone, Serialize)]
pub struct AlgorithmStats {
    pub algorithm: String,
    pub runs: usize,
    pub failed: usize,
    pub params: Vec<ParamStats>,
    pub online_nrmse_mean: f64,
    pub validation_nrmse_mean: f64,
    pub distinct_sampled_mean: BTreeMap<String, f64>,
    pub ess_mean: f64,
    pub loglik_mean: f64,
    pub wall_s_mean: f64,
    pub particle_steps_per_s_mean: f64,
}

/// Statistics of one algorithm's records.
pub fn algorithm_stats(algorithm: &str, records: &[&RunRecord]) -> AlgorithmStats {
    let ok: Vec<&&RunRecord> = records.iter().filter(|r| !r.is_failure()).collect();
    let names = records
        .first()
        .map(|r| r.param_names.clone())
        .unwrap_or_default();
    let params = names
        .iter()
        .enumerate()
        .map(|(j, name)| {
            let truth = ok
                .first()
                .and_then(|r| r.theta_true.as_ref())
                .map_or(f64::NAN, |t| t[j]);
            let ratios: Vec<f64> = ok.iter().map(|r| r.theta_val[j] / truth).collect();
            let errs: Vec<f64> = ok
                .iter()
                .filter_map(|r| r.rel_error.as_ref().map(|e| e[j]))
                .collect();
            let (ratio_mean, ratio_sd, _) = mean_sd(&ratios);
            ParamStats {
                name: name.clone(),
                truth,
                ratio_mean,
                ratio_sd,
                rel_error_mean: mean_sd(&errs).0,
            }
        })
        .collect();
    let avg = |f: &dyn Fn(&RunRecord) -> Option<f64>| {
        mean_sd(&ok.iter().filter_map(|r| f(r)).collect::<Vec<_>>()).0
    };
    let mut distinct: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in &ok {
        for (k, v) in &r.distinct_sampled {
            distinct.entry(k.clone()).or_default().push(*v as f64);
        }
    }
    AlgorithmStats {
        algorithm: algorithm.to_string(),
        runs: records.len(),
        failed: records.len() - ok.len(),
        params,
        online_nrmse_mean: avg(&|r| r.online_states.as_ref().map(|s| s.mean_nrmse())),
        validation_nrmse_mean: avg(&|r| {
            r.validation
                .as_ref()
                .filter(|v| v.error.is_none())
                .map(|v| v.states.mean_nrmse())
        }),
        distinct_sampled_mean: distinct
            .into_iter()
            .map(|(k, v)| (k, mean_sd(&v).0))
            .collect(),
        ess_mean: avg(&|r| Some(r.ess_mean)),
        loglik_mean: avg(&|r| Some(r.loglik)),
        wall_s_mean: avg(&|r| Some(r.timing.wall_s)),
        particle_steps_per_s_mean: avg(&|r| Some(r.timing.particle_steps_per_s)),
    }
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

/// Runs the reproduction. With a shard other than `0/1`, only runs this shard's records (no
/// figures, no report): merge the shards' `records/` and run again without `--shard` (with
/// `--resume`) to draw. Returns what was done.
pub fn reproduce(opts: &Options) -> Result<Done> {
    let start = Instant::now();
    let _lock = DirLock::acquire(&opts.out)?;
    let mut studies = BTreeMap::new();
    let mut records = BTreeMap::new();
    let mut done = Done::default();
    for &name in STUDIES.iter().chain(&crate::discretisation::STUDIES) {
        let path = opts.experiments.join(format!("{name}.toml"));
        // The section beyond the paper runs when its studies are configured.
        if crate::discretisation::STUDIES.contains(&name) && !path.exists() {
            continue;
        }
        let mut study = Study::load(&path)?;
        if opts.quick {
            study = study.quick();
        }
        let dir = opts.out.join("records").join(name);
        let sweep = SweepOptions {
            threads: opts.threads,
            shard: opts.shard,
            progress: opts.progress,
            label: name.to_string(),
            resume: opts.resume,
        };
        // The discretisation studies take over the Fig. 7 records that are the same jobs.
        let reuse = match crate::discretisation::STUDIES.contains(&name) {
            true => crate::discretisation::Reuse::new(
                records
                    .get(crate::discretisation::SOURCE)
                    .into_iter()
                    .flatten(),
            ),
            false => crate::discretisation::Reuse::default(),
        };
        let outcome = run_sweep(
            &study.jobs(),
            Study::job_id,
            |job| study.job_fingerprint(job),
            &dir,
            &sweep,
            |job| {
                reuse
                    .run(&study, job)
                    .with_context(|| format!("{name}: {}", Study::job_id(job)))
            },
        )?;
        if opts.progress && reuse.taken() > 0 {
            eprintln!(
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
    let (executed, total_jobs) = (done.executed, done.total);
    if opts.shard != Shard::default() {
        eprintln!(
            "shard {}/{}: {total_jobs} runs, {executed} executed ({} failed), {} reused, {}; \
             merge the shards' records (`sysid merge`) and run `sysid reproduce --resume` to draw",
            opts.shard.index,
            opts.shard.count,
            done.failed,
            done.reused,
            clock(start.elapsed())
        );
        return Ok(done);
    }
    let sweep_s = start.elapsed().as_secs_f64();

    crate::cli::table1::run(crate::cli::table1::Args {
        out: opts.out.join("table1"),
    })?;
    draw(opts, &studies, &records)?;
    crate::discretisation::draw(&opts.out, &records)?;
    let mut summary: BTreeMap<&str, Vec<AlgorithmStats>> = STUDIES
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
        .collect();
    // Coverage of every study with a known truth (SPEC §9), and its figure for the Fig. 7 sweep.
    let mut coverage = BTreeMap::new();
    for name in STUDIES {
        if let Some(c) = crate::coverage::study_coverage(&studies[name], &records[name])? {
            coverage.insert(name, c);
        }
    }
    if let Some(c) = coverage.get("fig7") {
        crate::calibration::coverage_figure(
            &c.calibration,
            &opts.out.join("fig7_coverage.svg"),
            "Fig. 7 sweep — coverage of central credible intervals",
        )?;
    }
    summary.extend(crate::discretisation::summary(&records));
    let total_s = start.elapsed().as_secs_f64();
    let summary_path = opts.out.join("summary.json");
    write_bytes_atomic(
        &summary_path,
        (serde_json::to_string_pretty(&serde_json::json!({
            "quick": opts.quick,
            "studies": summary,
            "coverage": coverage,
        }))? + "\n")
            .as_bytes(),
    )?;
    let report = crate::report::write_report(opts, &studies, &records, &summary, total_jobs)?;
    let path = opts.out.join("REPORT.md");
    write_bytes_atomic(&path, report.as_bytes())?;
    // What this invocation did, beside the committed results but not among them: timings and
    // counts change from run to run even when every record agrees.
    write_last_run(
        &opts.out,
        opts.threads,
        serde_json::json!({
            "wall_s": { "sweeps": sweep_s, "total": total_s },
            "runs": { "executed": executed, "reused": done.reused, "failed": done.failed, "total": total_jobs },
        }),
    )?;
    eprintln!(
        "wrote {}; {total_jobs} runs: {executed} executed ({} failed), {} reused; {}",
        path.display(),
        done.failed,
        done.reused,
        clock(start.elapsed())
    );
    Ok(done)
}

fn draw(
    opts: &Options,
    studies: &BTreeMap<&str, Study>,
    records: &BTreeMap<&str, Vec<RunRecord>>,
) -> Result<()> {
    let fig = |name: &str| opts.out.join(format!("{name}.svg"));
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

/// Writes a Markdown table row.
pub(crate) fn row(out: &mut String, cells: &[String]) {
    let _ = writeln!(out, "| {} |", cells.join(" | "));
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

/// The file, beside a study's results, that holds what the invocation that last wrote them did
/// (timings, runs executed, revision); it is not committed.
pub const LAST_RUN: &str = "last-run.json";

/// Writes [`LAST_RUN`] into `out`: the toolkit's version, the git revision, the threads and the
/// study's own `facts` (wall times, runs executed).
pub fn write_last_run(out: &Path, threads: usize, facts: serde_json::Value) -> Result<()> {
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
        &out.join(LAST_RUN),
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
