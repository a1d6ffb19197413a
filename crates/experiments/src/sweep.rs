//! The sweep runner: many independent runs in parallel, each record written as soon as it is done.
//!
//! - Parallel over runs with rayon, **ordered collect**: results come back in job order whatever
//!   the thread count, and every run draws only from its own seeded streams, so records are the
//!   same byte for byte with 1 or N threads (timings aside).
//! - Each record is written atomically (temporary file, then rename) into `dir/<id>.json` the
//!   moment its run finishes; a sweep started again skips the jobs whose record exists, so an
//!   interrupted sweep resumes without losing or duplicating anything.
//! - `--shard i/n` runs the jobs whose index is `i` modulo `n` (e.g. one Slurm array task each);
//!   [`merge`] gathers the shard directories into one.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{de::DeserializeOwned, Serialize};

/// A record that can say whether its run failed (for the progress bar's failure count).
pub trait SweepRecord: Serialize + DeserializeOwned + Send {
    fn failed(&self) -> bool;
}

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
    /// Draw a progress bar on stderr (only when it is a terminal).
    pub progress: bool,
    /// Label of the progress bar.
    pub label: String,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self {
            threads: 0,
            shard: Shard::default(),
            progress: true,
            label: "runs".into(),
        }
    }
}

/// Runs `run` on every job of this shard whose record is not yet in `dir`, writing each record to
/// `dir/<id(job)>.json` as soon as it is done. An `Err` from `run` is a configuration error and
/// stops the sweep (records already written stay); numerical failures belong inside records.
/// Returns the records of this shard, in job order
/// (finished earlier or now).
pub fn run_sweep<J, R>(
    jobs: &[J],
    id: impl Fn(&J) -> String + Sync,
    dir: &Path,
    opts: &SweepOptions,
    run: impl Fn(&J) -> Result<R> + Sync,
) -> Result<Vec<R>>
where
    J: Sync,
    R: SweepRecord,
{
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mine: Vec<(usize, &J)> = jobs
        .iter()
        .enumerate()
        .filter(|(i, _)| opts.shard.contains(*i))
        .collect();
    let pending = mine
        .iter()
        .filter(|(_, j)| !record_path(dir, &id(j)).exists())
        .count();
    let bar = progress_bar(opts, mine.len() as u64, (mine.len() - pending) as u64);
    let failures = AtomicU64::new(0);
    let work = || -> Result<Vec<R>> {
        mine.par_iter()
            .map(|(_, job)| {
                let path = record_path(dir, &id(job));
                let record = if path.exists() {
                    read_record(&path)?
                } else {
                    let r = run(job)?;
                    write_atomic(&path, &r)?;
                    bar.inc(1);
                    r
                };
                if record.failed() {
                    let f = failures.fetch_add(1, Ordering::Relaxed) + 1;
                    bar.set_message(format!("{f} failed"));
                }
                Ok(record)
            })
            .collect()
    };
    let out = if opts.threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(opts.threads)
            .build()
            .context("building the thread pool")?
            .install(work)
    } else {
        work()
    }?;
    bar.finish_and_clear();
    Ok(out)
}

fn progress_bar(opts: &SweepOptions, len: u64, done: u64) -> ProgressBar {
    use std::io::IsTerminal;
    if !opts.progress || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{prefix:>12} [{bar:30}] {pos}/{len} runs, ETA {eta} {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_prefix(opts.label.clone());
    bar.set_position(done);
    bar
}

/// Where the record of job `id` lives.
pub fn record_path(dir: &Path, id: &str) -> PathBuf {
    dir.join(format!("{id}.json"))
}

/// Reads one record, naming the file in the error.
pub fn read_record<R: DeserializeOwned>(path: &Path) -> Result<R> {
    let text = fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing record {}", path.display()))
}

/// Writes `value` as pretty JSON to `path` atomically (temporary file in the same directory, then
/// rename), so that an interrupted sweep never leaves a half-written record behind.
pub fn write_atomic<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).context("serialising a record")?;
    let tmp = path.with_extension(format!("json.tmp{}", std::process::id()));
    fs::write(&tmp, text + "\n").with_context(|| format!("writing {}", tmp.display()))?;
    fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))?;
    Ok(())
}

/// Copies every record of the shard directories `parts` into `into`. A record present in two
/// parts must be identical (same job run twice); otherwise merging fails.
pub fn merge(parts: &[PathBuf], into: &Path) -> Result<usize> {
    fs::create_dir_all(into).with_context(|| format!("creating {}", into.display()))?;
    let mut copied = 0;
    for part in parts {
        let entries = fs::read_dir(part).with_context(|| format!("reading {}", part.display()))?;
        let mut names: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            .collect();
        names.sort();
        for src in names {
            let dst = into.join(src.file_name().expect("file name"));
            let text = fs::read(&src).with_context(|| format!("reading {}", src.display()))?;
            if dst.exists() {
                let old = fs::read(&dst).with_context(|| format!("reading {}", dst.display()))?;
                if old != text && !same_but_timing(&old, &text) {
                    bail!(
                        "{} and {} hold different records for the same run",
                        src.display(),
                        dst.display()
                    );
                }
                continue;
            }
            fs::write(&dst, &text).with_context(|| format!("writing {}", dst.display()))?;
            copied += 1;
        }
    }
    Ok(copied)
}

/// Two JSON records equal once their `timing` objects are removed.
fn same_but_timing(a: &[u8], b: &[u8]) -> bool {
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
