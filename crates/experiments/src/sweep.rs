//! The sweep runner: many independent runs in parallel, each record written as soon as it is done.
//!
//! - Parallel over runs with rayon, **ordered collect**: results come back in job order whatever
//!   the thread count, and every run draws only from its own seeded streams, so records are the
//!   same byte for byte with 1 or N threads (timings aside).
//! - Each record is written atomically (temporary file `<id>.json.tmp<pid>` in the same
//!   directory, then rename) into `dir/<id>.json` the moment its run finishes, so an interrupted
//!   sweep never leaves a half-written record; temporary files of processes that have ended are
//!   removed by the next sweep or merge of the directory.
//! - A sweep computes every run unless asked to **resume**; then it reuses an existing record
//!   only when it reads back, passes its checks and its fingerprint equals the job's (the hash of
//!   everything that determines the result, see [`identify::record::fingerprint`]), and says how
//!   many it reused and recomputed, and why.
//! - `--shard i/n` runs the jobs whose index is `i` modulo `n` (e.g. one Slurm array task each);
//!   [`merge`] gathers the shard directories into one, checking every record.
//! - [`lock::DirLock`] keeps a second writer out of an output directory.

pub mod last_run;
pub mod lock;
mod merge;
pub mod progress;

pub use merge::{merge, study_pairs, MergeReport};

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Context, Result};
use rayon::prelude::*;
use serde::Serialize;

use progress::{clock, Progress};

/// [`identify::record::atomic::write_bytes_atomic`], as this crate's error.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(identify::record::atomic::write_bytes_atomic(path, bytes)?)
}
pub use identify::record::read::SweepRecord;

/// Part `index` of `count` of a sweep (`0 ≤ index < count`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Self { index: 0, count: 1 }
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("shard `{s}` is not of the form i/n"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| format!("shard index `{i}` is not a number"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| format!("shard count `{n}` is not a number"))?;
        if count == 0 || index >= count {
            return Err(format!("shard `{s}`: need 0 ≤ i < n"));
        }
        Ok(Shard { index, count })
    }
}

impl Shard {
    pub fn contains(&self, job_index: usize) -> bool {
        job_index % self.count == self.index
    }
}

/// Options of a sweep.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// Worker threads (0: rayon's default, one per core).
    pub threads: usize,
    pub shard: Shard,
    /// Show progress on stderr (a bar in a terminal, plain lines elsewhere) and a summary.
    pub progress: bool,
    /// Name of the sweep in progress lines.
    pub label: String,
    /// Reuse existing records whose fingerprint matches the job's (otherwise every run of the
    /// shard is computed).
    pub resume: bool,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self {
            threads: 0,
            shard: Shard::default(),
            progress: true,
            label: "runs".into(),
            resume: false,
        }
    }
}

/// Why a run was computed rather than reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Recompute {
    /// No record in the directory.
    Missing,
    /// A record exists, but the sweep was not asked to resume.
    NotResuming,
    /// The record does not parse or fails its checks.
    Unreadable,
    /// The record carries no fingerprint (written by an older version).
    NoFingerprint,
    /// The record was computed from other inputs (configuration, data, seed or numerics).
    FingerprintChanged,
}

impl Recompute {
    pub fn describe(self) -> &'static str {
        match self {
            Recompute::Missing => "without a record",
            Recompute::NotResuming => "with a record, not resuming (no --resume)",
            Recompute::Unreadable => "with an unreadable record",
            Recompute::NoFingerprint => "with a record without fingerprint (older version)",
            Recompute::FingerprintChanged => "with a record of another fingerprint",
        }
    }
}

/// What a sweep did.
#[derive(Debug, Clone)]
pub struct SweepOutcome<R> {
    /// The records of this shard, in job order.
    pub records: Vec<R>,
    /// Runs computed by this sweep.
    pub executed: usize,
    /// Records reused (resume with a matching fingerprint).
    pub reused: usize,
    /// Runs computed, by reason.
    pub recomputed: BTreeMap<Recompute, usize>,
    /// Executed runs that failed.
    pub failed: usize,
    pub wall_s: f64,
}

impl<R> SweepOutcome<R> {
    /// `12 runs: 10 executed (1 failed), 2 reused; recomputed: 10 no record — 3.4 s`.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{} runs: {} executed ({} failed), {} reused",
            self.records.len(),
            self.executed,
            self.failed,
            self.reused
        );
        if !self.recomputed.is_empty() {
            let why: Vec<String> = self
                .recomputed
                .iter()
                .map(|(r, n)| format!("{n} {}", r.describe()))
                .collect();
            s.push_str(&format!("; computed because: {}", why.join(", ")));
        }
        s.push_str(&format!(
            " — {}",
            clock(std::time::Duration::from_secs_f64(self.wall_s))
        ));
        s
    }
}

enum Decision<R> {
    Reuse(R),
    Run(Recompute),
}

/// Runs the jobs of this shard into `dir/<id(job)>.json`. Without `opts.resume` every job is
/// computed (an existing record is replaced when its run finishes); with it, a job whose record
/// reads back and carries the fingerprint `fingerprint(job)` is reused. An `Err` from `run` or
/// `fingerprint` is a configuration error and stops the sweep (records already written stay);
/// numerical failures belong inside records.
pub fn run_sweep<J, R>(
    jobs: &[J],
    id: impl Fn(&J) -> String + Sync,
    fingerprint: impl Fn(&J) -> Result<String> + Sync,
    dir: &Path,
    opts: &SweepOptions,
    run: impl Fn(&J) -> Result<R> + Sync,
) -> Result<SweepOutcome<R>>
where
    J: Sync,
    R: SweepRecord,
{
    let start = Instant::now();
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    clean_stale_temporaries(dir)?;
    let mine: Vec<&J> = jobs
        .iter()
        .enumerate()
        .filter(|(i, _)| opts.shard.contains(*i))
        .map(|(_, j)| j)
        .collect();
    let work = || -> Result<SweepOutcome<R>> {
        let decisions: Vec<Decision<R>> = mine
            .par_iter()
            .map(|job| decide(dir, &id(job), opts.resume, || fingerprint(job)))
            .collect::<Result<_>>()?;
        let pending = decisions
            .iter()
            .filter(|d| matches!(d, Decision::Run(_)))
            .count();
        let replaced = decisions
            .iter()
            .filter(|d| matches!(d, Decision::Run(Recompute::NotResuming)))
            .count();
        if opts.progress && replaced > 0 {
            log::info!(
                "{}: computing all {pending} runs; the {replaced} records already in {} are \
                 replaced as runs finish (--resume reuses those whose fingerprint matches)",
                opts.label,
                dir.display()
            );
        }
        let progress = Progress::new(&opts.label, pending, opts.progress);
        let records: Vec<(R, Option<Recompute>)> = mine
            .par_iter()
            .zip(decisions)
            .map(|(job, decision)| match decision {
                Decision::Reuse(r) => Ok((r, None)),
                Decision::Run(why) => {
                    let r = keep_if_same(&record_path(dir, &id(job)), run(job)?)?;
                    progress.inc(r.failed());
                    Ok((r, Some(why)))
                }
            })
            .collect::<Result<_>>()?;
        progress.finish();
        let mut out = SweepOutcome {
            records: Vec::with_capacity(records.len()),
            executed: 0,
            reused: 0,
            recomputed: BTreeMap::new(),
            failed: 0,
            wall_s: 0.0,
        };
        for (r, why) in records {
            match why {
                Some(why) => {
                    out.executed += 1;
                    out.failed += usize::from(r.failed());
                    *out.recomputed.entry(why).or_default() += 1;
                }
                None => out.reused += 1,
            }
            out.records.push(r);
        }
        Ok(out)
    };
    identify::limits::check_count(opts.threads, 0, identify::limits::MAX_THREADS)
        .context("--threads")?;
    let mut out = if opts.threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(opts.threads)
            .build()
            .context("building the thread pool")?
            .install(work)
    } else {
        work()
    }?;
    out.wall_s = start.elapsed().as_secs_f64();
    if opts.progress {
        log::info!("{}: {}", opts.label, out.summary());
    }
    Ok(out)
}

/// Whether the record of one job can be reused.
fn decide<R: SweepRecord>(
    dir: &Path,
    id: &str,
    resume: bool,
    expected: impl FnOnce() -> Result<String>,
) -> Result<Decision<R>> {
    let path = record_path(dir, id);
    if !path.exists() {
        return Ok(Decision::Run(Recompute::Missing));
    }
    if !resume {
        return Ok(Decision::Run(Recompute::NotResuming));
    }
    let record: R = match read_record(&path) {
        Ok(r) => r,
        Err(e) => {
            log::warn!("{e:#}: computing it again");
            return Ok(Decision::Run(Recompute::Unreadable));
        }
    };
    Ok(match record.fingerprint() {
        None => Decision::Run(Recompute::NoFingerprint),
        Some(f) if f == expected()? => Decision::Reuse(record),
        Some(_) => Decision::Run(Recompute::FingerprintChanged),
    })
}

/// Writes a freshly computed record, unless the file already holds a readable record with the
/// same result (timings aside): then that file is left untouched and its record returned, so
/// the record in memory is the one on disk.
fn keep_if_same<R: SweepRecord>(path: &Path, fresh: R) -> Result<R> {
    if path.exists() {
        if let Ok(old) = read_record::<R>(path) {
            if old.same_result(&fresh) {
                return Ok(old);
            }
        }
    }
    write_atomic(path, &fresh)?;
    Ok(fresh)
}

/// Where the record of job `id` lives.
pub fn record_path(dir: &Path, id: &str) -> PathBuf {
    dir.join(format!("{id}.json"))
}

/// Reads one record and checks it ([`identify::record::read::read`], the one reader of records);
/// errors name the file and say what is wrong (a record cut short, a value that is not a number,
/// a fingerprint that does not match, …).
pub fn read_record<R: SweepRecord>(path: &Path) -> Result<R> {
    Ok(identify::record::read::read(path)?)
}

/// Writes `value` as pretty JSON to `path` atomically (see [`write_bytes_atomic`]).
pub fn write_atomic<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).context("serialising a record")?;
    write_bytes_atomic(path, (text + "\n").as_bytes())
}

/// Removes the temporary files `*.json.tmp<pid>` that processes which have ended left in `dir`
/// (a sweep or merge killed between writing a record and renaming it); returns how many.
pub(crate) fn clean_stale_temporaries(dir: &Path) -> Result<usize> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(0);
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.rsplit_once(".json.tmp"))
            .and_then(|(_, pid)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !lock::is_running(pid, None) {
            fs::remove_file(entry.path())
                .with_context(|| format!("removing {}", entry.path().display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Two JSON records equal once their `timing` objects are removed.
pub(crate) fn same_but_timing(a: &[u8], b: &[u8]) -> bool {
    let strip = |x: &[u8]| -> Option<serde_json::Value> {
        let mut v: serde_json::Value = serde_json::from_slice(x).ok()?;
        v.as_object_mut()?.remove("timing");
        Some(v)
    };
    matches!((strip(a), strip(b)), (Some(x), Some(y)) if x == y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parsing() {
        assert_eq!(
            "1/3".parse::<Shard>().unwrap(),
            Shard { index: 1, count: 3 }
        );
        assert!("3/3".parse::<Shard>().is_err());
        assert!("x".parse::<Shard>().is_err());
        let s = Shard { index: 1, count: 3 };
        assert_eq!(
            (0..7).filter(|&i| s.contains(i)).collect::<Vec<_>>(),
            vec![1, 4]
        );
    }
}
