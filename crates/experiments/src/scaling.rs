//! The scaling study (`experiments/scaling.toml`, `sysid scaling`, `cargo xtask
//! reproduce-scaling`): the identification of shear chains of 3 to 40 storeys by every
//! algorithm, to test the paper's closing claim that the MPF-EKF2's sampled dimension "does no
//! longer scale with the dimension of the problem" (SPEC §5.4, §9).
//!
//! The study is an ordinary [`Study`] with a structure axis; this module runs its sweep
//! (resumable and shardable like every sweep, [`crate::sweep`]), then reduces the records to one
//! [`Cell`] per structure and algorithm (accuracy, ESS, failures, cost per particle-step), fits
//! the growth of the cost with the marginalised dimension, draws two figures and writes
//! `cells.csv`, `summary.json` and `REPORT.md`.
//!
//! Costs are measured twice: the records' wall times, and the CPU time of the thread that ran
//! each job (written beside its record as `<id>.cpu`, see `thread_cpu_s`). On a machine shared
//! with other work the wall time of a run grows with the load while its CPU time does not, so
//! the cost figure and fits use CPU time when every run of a cell has it.
//!
//! Runs a sweep has not computed yet are listed in the report as not run (as would a structure a
//! build could not generate: `crate::study::Structure::unsupported`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{bail, Context, Result};
use serde::Serialize;

use crate::engine::{load, write_json, Engine, RunMode};
use crate::run_dir::open;
use crate::study::{Job, Study};
use crate::sweep::progress::clock;
use crate::sweep::{read_record, record_path, write_bytes_atomic};
use crate::verdict::group_mean_error;
use identify::metrics::{mean_sd, mean_spread, median};
use identify::pipeline::Algorithm;
use identify::record::RunRecord;

mod figures;
mod report;
pub mod structures;

/// Options of a scaling study run.
#[derive(Debug, Clone)]
pub struct Options {
    /// The study file (`experiments/scaling.toml`).
    pub config: PathBuf,
    pub out: PathBuf,
    pub mode: RunMode,
    /// Compute nothing: write the report from the records already in `out/records` whose
    /// fingerprint matches their job (the runs without one are reported as not run).
    pub report_only: bool,
}

/// Sampled and marginalised dimensions of one algorithm on one chain (SPEC §5, §9;
/// `docs/partitions.md`). `storeys` N, `hysteretic` the 1-based storeys of the Bouc–Wen
/// elements (E of them).
///
/// - bootstrap PF: everything sampled, `2N + E` states and `2N + 3E` parameters;
/// - MLN-RBPF and Storvik: sampled `[x, v, r, n]` (2N + 2E), marginalised `[k, c, β, γ]`
///   (2N + 2E);
/// - MPF-EKF2: sampled the velocities the hysteresis laws read (`v_j`, and `v_{j−1}` above the
///   first storey), `r` and `n` of each element; marginalised the rest: 4N + 2E minus the
///   sampled velocities.
pub(crate) fn dimensions(
    algorithm: Algorithm,
    storeys: usize,
    hysteretic: &[usize],
) -> (usize, usize) {
    let (n, e) = (storeys, hysteretic.len());
    match algorithm {
        Algorithm::Bootstrap => (4 * n + 4 * e, 0),
        Algorithm::MlnRbpf | Algorithm::Storvik => (2 * n + 2 * e, 2 * n + 2 * e),
        Algorithm::MpfEkf2 => {
            let mut velocities: Vec<usize> = hysteretic
                .iter()
                .flat_map(|&s| if s > 1 { vec![s, s - 1] } else { vec![s] })
                .collect();
            velocities.sort_unstable();
            velocities.dedup();
            let sv = velocities.len();
            (sv + 2 * e, 4 * n + 2 * e - sv)
        }
    }
}

/// Statistics over the runs of one algorithm on one structure.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    pub structure: String,
    pub storeys: usize,
    /// 1-based hysteretic storeys and measured storeys.
    pub hysteretic: Vec<usize>,
    pub sensors: Vec<usize>,
    /// Filter steps per run (the record length over dt).
    pub steps: usize,
    pub algorithm: String,
    pub sampled_dim: usize,
    pub marginalised_dim: usize,
    pub particles: usize,
    /// Runs planned, runs with a record, runs that failed.
    pub runs_planned: usize,
    pub runs: usize,
    pub failed: usize,
    /// Mean over completed runs of the storey-averaged relative error of k (and c), and the
    /// run-to-run s.d. of that average.
    pub k_error_mean: f64,
    pub k_error_sd: f64,
    /// The storey whose k has the largest mean relative error, and that error.
    pub k_error_worst: f64,
    pub c_error_mean: f64,
    pub c_error_sd: f64,
    /// Mean over runs of the mean online-state NRMSE.
    pub state_nrmse: f64,
    /// Mean over runs of the mean ESS, as a fraction of the particles.
    pub ess_fraction: f64,
    /// Fraction of (completed run, k_j or c_j) pairs whose central 95 % interval holds the
    /// truth, and the number of pairs ([`crate::coverage::stiffness_damping_coverage`]).
    pub coverage95_kc: f64,
    pub coverage_pairs: usize,
    /// Median over runs of the wall time per particle-step (µs) and the mean wall time per run.
    pub us_per_particle_step: f64,
    pub wall_s_mean: f64,
    /// Median over runs of the thread CPU time per particle-step (µs), data generation
    /// included; NaN unless every run has its `.cpu` file.
    pub cpu_us_per_particle_step: f64,
}

/// CPU time (s) consumed so far by the calling thread (NaN where the clock is unavailable).
pub(crate) fn thread_cpu_s() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec; the call writes only into it.
        let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        if rc == 0 {
            return ts.tv_sec as f64 + 1e-9 * ts.tv_nsec as f64;
        }
    }
    f64::NAN
}

/// Path of the CPU-time file of record `id`.
pub(crate) fn cpu_path(records: &Path, id: &str) -> PathBuf {
    records.join(format!("{id}.cpu"))
}

/// Bytes of a CPU-time file read at most: one number.
const CPU_FILE_BYTES: u64 = 64;

/// The CPU seconds of record `id`, if its file is a regular file that holds a positive
/// number. Anything else counts as no CPU time and is not waited on or read far: a named pipe
/// there made a report wait forever.
pub(crate) fn read_cpu(records: &Path, id: &str) -> Option<f64> {
    use std::io::Read;
    let path = cpu_path(records, id);
    let meta = std::fs::metadata(&path).ok()?;
    if !meta.is_file() || meta.len() > CPU_FILE_BYTES {
        return None;
    }
    let mut text = String::new();
    std::fs::File::open(&path)
        .ok()?
        .take(CPU_FILE_BYTES)
        .read_to_string(&mut text)
        .ok()?;
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
}

/// What a cell is of: one algorithm on one structure of the study's axis, as planned.
pub(crate) struct CellOf<'a> {
    pub structure: &'a str,
    pub storeys: usize,
    /// 1-based hysteretic storeys and measured storeys.
    pub hysteretic: &'a [usize],
    pub sensors: &'a [usize],
    /// Filter steps per run.
    pub steps: usize,
    pub algorithm: Algorithm,
    pub particles: usize,
    pub runs_planned: usize,
}

/// The statistics of `records` (the runs of one algorithm on one structure) and their CPU
/// times.
pub(crate) fn cell(of: &CellOf, records: &[&RunRecord], cpu_s: &[Option<f64>]) -> Cell {
    let &CellOf {
        structure,
        storeys,
        hysteretic,
        sensors,
        steps,
        algorithm,
        particles,
        runs_planned,
    } = of;
    let ok: Vec<&RunRecord> = records
        .iter()
        .copied()
        .filter(|r| !r.is_failure())
        .collect();
    // A run-to-run s.d. needs two runs: NaN (written "–") with one.
    let spread = |prefix| {
        mean_spread(
            &ok.iter()
                .filter_map(|r| group_mean_error(r, prefix))
                .collect::<Vec<_>>(),
        )
    };
    let ((k_mean, k_sd), (c_mean, c_sd)) = (spread('k'), spread('c'));
    let k_worst = (1..=storeys)
        .map(|j| {
            let name = format!("k{j}");
            mean_sd(
                &ok.iter()
                    .filter_map(|r| {
                        let i = r.param_names.iter().position(|n| *n == name)?;
                        r.rel_error.as_ref().map(|e| e[i])
                    })
                    .collect::<Vec<_>>(),
            )
            .0
        })
        .filter(|e| e.is_finite())
        .fold(f64::NAN, f64::max);
    let (sampled_dim, marginalised_dim) = dimensions(algorithm, storeys, hysteretic);
    let avg = |f: &dyn Fn(&RunRecord) -> Option<f64>| {
        mean_sd(&ok.iter().filter_map(|r| f(r)).collect::<Vec<_>>()).0
    };
    let (coverage95_kc, coverage_pairs) = crate::coverage::stiffness_damping_coverage(&ok, 0.95);
    Cell {
        coverage95_kc,
        coverage_pairs,
        structure: structure.to_string(),
        storeys,
        hysteretic: hysteretic.to_vec(),
        sensors: sensors.to_vec(),
        steps,
        algorithm: algorithm.name().to_string(),
        sampled_dim,
        marginalised_dim,
        particles,
        runs_planned,
        runs: records.len(),
        failed: records.len() - ok.len(),
        k_error_mean: k_mean,
        k_error_sd: k_sd,
        k_error_worst: k_worst,
        c_error_mean: c_mean,
        c_error_sd: c_sd,
        state_nrmse: avg(&|r| r.online_states.as_ref().map(|s| s.mean_nrmse())),
        ess_fraction: avg(&|r| Some(r.ess_mean / r.particles as f64)),
        // Every run's cost, failed or not, up to where it stopped: timings of all records.
        us_per_particle_step: median(
            &records
                .iter()
                .map(|r| 1e6 / r.timing.particle_steps_per_s)
                .collect::<Vec<_>>(),
        )
        .unwrap_or(f64::NAN),
        wall_s_mean: mean_sd(&records.iter().map(|r| r.timing.wall_s).collect::<Vec<_>>()).0,
        cpu_us_per_particle_step: if !records.is_empty() && cpu_s.iter().all(Option::is_some) {
            median(
                &records
                    .iter()
                    .zip(cpu_s)
                    .map(|(r, c)| {
                        1e6 * c.unwrap_or(f64::NAN)
                            / (r.particles * r.steps_completed.max(1)) as f64
                    })
                    .collect::<Vec<_>>(),
            )
            .unwrap_or(f64::NAN)
        } else {
            f64::NAN
        },
    }
}

/// Least-squares slope and intercept of `ln y` against `ln x` over the finite positive pairs
/// (`None` with fewer than two distinct x).
pub(crate) fn log_log_fit(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let p: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = p.len() as f64;
    let mx = p.iter().map(|q| q.0).sum::<f64>() / n;
    let my = p.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = p.iter().map(|q| (q.0 - mx).powi(2)).sum();
    if p.len() < 2 || sxx <= 1e-12 {
        return None;
    }
    let sxy: f64 = p.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    let slope = sxy / sxx;
    Some((slope, my - slope * mx))
}

/// The jobs of a structure study's sweep, in sweep order (the order `--shard i/n` deals them
/// out in): every job of a structure this build can generate.
pub(crate) fn sweep_jobs(study: &Study) -> Vec<Job> {
    study
        .jobs()
        .into_iter()
        .filter(|j| {
            j.structure
                .is_none_or(|i| study.sweep.structures[i].unsupported().is_none())
        })
        .collect()
}

/// Runs the study's sweep (the structures this build can generate), then, unless sharded,
/// writes the cells, figures and report. Returns the cells.
pub fn run(opts: &Options) -> Result<Vec<Cell>> {
    if !load(&opts.config, opts.mode.quick)?.verdicts.is_empty() {
        bail!(
            "{}: the scaling study does not decide `[[verdicts]]`; `sysid study` does",
            opts.config.display()
        );
    }
    run_with(opts, &|opts, study, cells, _jobs, _records| {
        write_outputs(opts, study, cells)
    })
}

/// What writes a structure study's outputs from its cells and records.
/// Its arguments: the options, the study, the cells, the jobs with a record and those records
/// (in the same order); `cells.csv` and `last-run.json` are written before it is called.
pub(crate) type Writer<'a> =
    dyn Fn(&Options, &Study, &[Cell], &[Job], &[RunRecord]) -> Result<()> + 'a;

/// [`run`] with another writer of the outputs: the sweep over a study's structure axis,
/// resumable, shardable, with CPU times, shared by the studies that have one (the scaling and
/// the excitations studies).
pub(crate) fn run_with(opts: &Options, write: &Writer<'_>) -> Result<Vec<Cell>> {
    let start = Instant::now();
    let (_lock, engine) = open(&opts.out, opts.mode)?;
    let study = load(&opts.config, opts.mode.quick)?;
    let jobs = sweep_jobs(&study);
    let records_dir = opts.out.join("records");
    let cpu_of = |jobs: &[Job]| -> Vec<Option<f64>> {
        jobs.iter()
            .map(|j| read_cpu(&records_dir, &study.record_id(j)))
            .collect()
    };
    if opts.report_only {
        let asked = jobs.len();
        let (jobs, records) = existing(&study, &jobs, &records_dir)?;
        if records.is_empty() {
            bail!(
                "{}: none of the {asked} runs of {} has a record computed from its present \
                 inputs (a record from another configuration or numerics version is left out, \
                 the log above names each): nothing to report; run the study without \
                 --report-only",
                opts.out.display(),
                opts.config.display()
            );
        }
        let cells = cells(&study, &jobs, &records, &cpu_of(&jobs))?;
        write_cells(&engine, &cells, f64::NAN)?;
        write(opts, &study, &cells, &jobs, &records)?;
        log::info!(
            "wrote {} from {} existing records",
            opts.out.join("REPORT.md").display(),
            records.len()
        );
        return Ok(cells);
    }
    let outcome = engine.sweep(
        &study,
        &jobs,
        &records_dir,
        |j| study.record_id(j),
        |j| {
            let cpu0 = thread_cpu_s();
            let record = study.run_job(j)?;
            let cpu = thread_cpu_s() - cpu0;
            let path = cpu_path(&records_dir, &study.record_id(j));
            if cpu.is_finite() {
                write_bytes_atomic(&path, format!("{cpu}\n").as_bytes())?;
            } else if path.exists() {
                std::fs::remove_file(&path)
                    .with_context(|| format!("removing {}", path.display()))?;
            }
            Ok(record)
        },
    )?;
    if engine.sharded() {
        engine.shard_note(&outcome.summary());
        return Ok(Vec::new());
    }
    let sweep_s = start.elapsed().as_secs_f64();
    let cells = cells(&study, &jobs, &outcome.records, &cpu_of(&jobs))?;
    write_cells(&engine, &cells, sweep_s)?;
    write(opts, &study, &cells, &jobs, &outcome.records)?;
    log::info!(
        "wrote {}; {}",
        opts.out.join("REPORT.md").display(),
        clock(start.elapsed())
    );
    Ok(cells)
}

/// Writes `cells.csv` and `last-run.json` (with the sweep's wall time, NaN when nothing was
/// computed): the outputs every structure study has.
fn write_cells(engine: &Engine<'_>, cells: &[Cell], sweep_s: f64) -> Result<()> {
    write_bytes_atomic(&engine.out.join("cells.csv"), csv(cells).as_bytes())?;
    engine.last_run(serde_json::json!({ "sweep_wall_s": sweep_s }))
}

/// Writes a structure study's `summary.json`: its name, form and structures, and the fields of
/// `results`.
pub(crate) fn write_summary(
    opts: &Options,
    study: &Study,
    values: &[structures::StructureValues],
    results: serde_json::Value,
) -> Result<()> {
    let mut summary = serde_json::json!({
        "study": study.name,
        "quick": opts.mode.quick,
        "structures": values,
    });
    if let (Some(s), serde_json::Value::Object(r)) = (summary.as_object_mut(), results) {
        s.extend(r);
    }
    write_json(&opts.out.join("summary.json"), &summary)
}

/// The jobs whose record exists, reads back and carries the job's fingerprint, with their
/// records.
fn existing(study: &Study, jobs: &[Job], dir: &Path) -> Result<(Vec<Job>, Vec<RunRecord>)> {
    let mut kept = (Vec::new(), Vec::new());
    for job in jobs {
        let path = record_path(dir, &study.record_id(job));
        if !path.exists() {
            continue;
        }
        let record: RunRecord = match read_record(&path) {
            Ok(r) => r,
            Err(e) => {
                log::warn!("{e:#}: left out of the report");
                continue;
            }
        };
        if record.fingerprint.as_ref().map(|f| f.sha256.as_str())
            == Some(study.job_fingerprint(job)?.as_str())
        {
            kept.0.push(job.clone());
            kept.1.push(record);
        } else {
            log::info!(
                "{}: computed from other inputs, left out of the report",
                path.display()
            );
        }
    }
    Ok(kept)
}

/// One cell per structure and algorithm, in the study's order, from the records of `jobs`.
/// `cpu_s[i]` is the CPU time of `records[i]`, when known.
pub fn cells(
    study: &Study,
    jobs: &[Job],
    records: &[RunRecord],
    cpu_s: &[Option<f64>],
) -> Result<Vec<Cell>> {
    type Runs<'a> = (Vec<&'a RunRecord>, Vec<Option<f64>>);
    let mut by_key: BTreeMap<(usize, Algorithm), Runs> = BTreeMap::new();
    for ((job, rec), cpu) in jobs.iter().zip(records).zip(cpu_s) {
        if let Some(i) = job.structure {
            let e = by_key.entry((i, job.algorithm)).or_default();
            e.0.push(rec);
            e.1.push(*cpu);
        }
    }
    let particles = study.sweep.particles.first().copied().unwrap_or(0);
    let mut out = Vec::new();
    for (i, st) in study.sweep.structures.iter().enumerate() {
        let hysteretic = st.hysteretic.clone().unwrap_or_else(|| vec![1]);
        let sensors = st
            .sensors
            .clone()
            .unwrap_or_else(|| (1..=st.storeys).collect());
        let algorithms = st.algorithms.as_ref().unwrap_or(&study.sweep.algorithms);
        let runs_planned = st.runs.unwrap_or(study.sweep.runs) as usize;
        let steps = if st.unsupported().is_none() {
            let c = study.structure_config(Some(i), 0)?;
            models::dataset::ground_motion(&c)?.len().saturating_sub(1)
        } else {
            0
        };
        for &a in algorithms {
            let (recs, cpu) = by_key.get(&(i, a)).cloned().unwrap_or_default();
            let of = CellOf {
                structure: &st.label,
                storeys: st.storeys,
                hysteretic: &hysteretic,
                sensors: &sensors,
                steps,
                algorithm: a,
                particles,
                runs_planned,
            };
            out.push(cell(&of, &recs, &cpu));
        }
    }
    Ok(out)
}

/// Header of `cells.csv`.
pub const CSV_HEADER: &str = "structure,storeys,hysteretic,sensors,steps,algorithm,\
sampled_dim,marginalised_dim,particles,runs_planned,runs,failed,k_error_mean,k_error_sd,\
k_error_worst,c_error_mean,c_error_sd,state_nrmse,ess_fraction,us_per_particle_step,wall_s_mean,\
cpu_us_per_particle_step,coverage95_kc,coverage_pairs";

/// `cells.csv`: one line per cell (lists joined by `;`).
pub fn csv(cells: &[Cell]) -> String {
    let join = |v: &[usize]| {
        v.iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(";")
    };
    let mut out = format!("{CSV_HEADER}\n");
    for c in cells {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            c.structure,
            c.storeys,
            join(&c.hysteretic),
            join(&c.sensors),
            c.steps,
            c.algorithm,
            c.sampled_dim,
            c.marginalised_dim,
            c.particles,
            c.runs_planned,
            c.runs,
            c.failed,
            c.k_error_mean,
            c.k_error_sd,
            c.k_error_worst,
            c.c_error_mean,
            c.c_error_sd,
            c.state_nrmse,
            c.ess_fraction,
            c.us_per_particle_step,
            c.wall_s_mean,
            c.cpu_us_per_particle_step,
            c.coverage95_kc,
            c.coverage_pairs
        );
    }
    out
}

/// The cost fit of one algorithm: µs per particle-step against the marginalised dimension over
/// the structures of one family (the base-hysteresis, all-sensor chains).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct CostFit {
    pub algorithm: String,
    /// Whether the points are CPU times (every cell of the algorithm has them) or wall times.
    pub cpu: bool,
    /// Points (marginalised dimension, or the sampled one for the bootstrap PF; µs).
    pub points: Vec<(f64, f64)>,
    pub slope: Option<f64>,
    pub intercept: Option<f64>,
}

/// Whether a cell belongs to the reference family: Bouc–Wen at storey 1 only, every storey
/// measured.
pub(crate) fn is_reference(c: &Cell) -> bool {
    c.hysteretic == [1] && c.sensors.len() == c.storeys
}

/// The cost fits of the reference family, one per algorithm with runs.
pub(crate) fn cost_fits(cells: &[Cell]) -> Vec<CostFit> {
    let mut algs: Vec<&str> = Vec::new();
    for c in cells {
        if !algs.contains(&c.algorithm.as_str()) {
            algs.push(&c.algorithm);
        }
    }
    algs.into_iter()
        .map(|a| {
            let mine: Vec<&Cell> = cells
                .iter()
                .filter(|c| c.algorithm == a && is_reference(c) && c.runs > 0)
                .collect();
            let cpu =
                !mine.is_empty() && mine.iter().all(|c| c.cpu_us_per_particle_step.is_finite());
            let points: Vec<(f64, f64)> = mine
                .iter()
                .map(|c| {
                    let us = if cpu {
                        c.cpu_us_per_particle_step
                    } else {
                        c.us_per_particle_step
                    };
                    (cost_dimension(c) as f64, us)
                })
                .collect();
            let fit = log_log_fit(&points);
            CostFit {
                algorithm: a.to_string(),
                cpu,
                points,
                slope: fit.map(|f| f.0),
                intercept: fit.map(|f| f.1),
            }
        })
        .filter(|f| !f.points.is_empty())
        .collect()
}

/// The dimension the cost is plotted against: the marginalised one, or for the bootstrap PF
/// (which marginalises nothing) its sampled dimension.
pub(crate) fn cost_dimension(c: &Cell) -> usize {
    if c.marginalised_dim > 0 {
        c.marginalised_dim
    } else {
        c.sampled_dim
    }
}

fn write_outputs(opts: &Options, study: &Study, cells: &[Cell]) -> Result<()> {
    let out = &opts.out;
    let fits = cost_fits(cells);
    identify::plot::figures_in_place(out, |dir| {
        figures::cost(&fits, &dir.join("cost_vs_dimension.svg"))?;
        figures::accuracy(cells, &dir.join("accuracy_vs_storeys.svg"))
    })?;
    let unsupported: Vec<String> = study
        .sweep
        .structures
        .iter()
        .filter_map(|s| s.unsupported())
        .collect();
    let values = structures::structure_values(study)?;
    write_summary(
        opts,
        study,
        &values,
        serde_json::json!({
            "cells": cells,
            "cost_fits": fits,
            "not_run": unsupported,
        }),
    )?;
    let text = report::write(study, &values, cells, &fits, &unsupported, opts.mode.quick);
    write_bytes_atomic(&out.join("REPORT.md"), text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CPU-time file that is a named pipe, a directory, a 3 GiB sparse file or not a number
    /// counts as none, at once (a named pipe made `scaling --report-only` wait forever).
    #[test]
    #[cfg(unix)]
    fn cpu_files_that_are_not_a_number_count_as_none_at_once() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        std::fs::write(cpu_path(d, "ok"), "0.5\n").unwrap();
        assert_eq!(read_cpu(d, "ok"), Some(0.5));
        std::fs::write(cpu_path(d, "text"), "fast").unwrap();
        std::fs::create_dir(cpu_path(d, "dir")).unwrap();
        std::fs::File::create(cpu_path(d, "huge"))
            .unwrap()
            .set_len(3 << 30)
            .unwrap();
        let fifo = std::ffi::CString::new(cpu_path(d, "fifo").to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path that outlives the call.
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o644) }, 0);
        let started = std::time::Instant::now();
        for id in ["text", "dir", "huge", "fifo", "missing"] {
            assert_eq!(read_cpu(d, id), None, "{id}");
        }
        assert!(started.elapsed() < std::time::Duration::from_secs(5));
    }

    #[test]
    fn dimensions_of_the_paper_chain() {
        // SPEC §6: the MPF-EKF2 samples [ẋ1, r1, n] and marginalises 13 values at N = 3.
        assert_eq!(dimensions(Algorithm::MpfEkf2, 3, &[1]), (3, 13));
        assert_eq!(dimensions(Algorithm::MpfEkf2, 40, &[1]), (3, 161));
        assert_eq!(dimensions(Algorithm::MlnRbpf, 3, &[1]), (8, 8));
        assert_eq!(dimensions(Algorithm::Bootstrap, 3, &[1]), (16, 0));
        // Elements at storeys 1, 2 and 6 read v1, v2 and v5, v6: four sampled velocities.
        assert_eq!(dimensions(Algorithm::MpfEkf2, 10, &[1, 2, 6]), (10, 42));
    }

    #[test]
    fn log_log_slope() {
        let pts: Vec<(f64, f64)> = [10.0, 20.0, 40.0]
            .iter()
            .map(|&x| (x, 3.0 * x * x))
            .collect();
        let (s, b) = log_log_fit(&pts).unwrap();
        assert!((s - 2.0).abs() < 1e-12 && (b - 3f64.ln()).abs() < 1e-12);
        assert!(log_log_fit(&[(10.0, 1.0)]).is_none());
        assert!(log_log_fit(&[(10.0, 1.0), (10.0, 2.0)]).is_none());
    }
}
