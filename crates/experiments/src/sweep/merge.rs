//! Merging the record directories of sharded sweeps.
//!
//! In two phases, so that a bad part writes nothing: first every source record is read, parsed
//! and checked (fingerprint included), records with the same name in two parts are compared, and
//! every record already in a destination is read and classified; any problem stops the merge
//! with the list of files and reasons. Then each record is copied byte for byte with an atomic write (temporary
//! file and rename in the destination), so a merge killed at any point leaves only complete
//! records, and running it again finishes the job.
//!
//! A record's sidecar files (`<id>.cpu`: the CPU seconds of a structure study's run, see
//! [`crate::scaling`]) travel with it: copied after the record, and copied into a destination
//! that holds the record but not the sidecar (a merge killed between the two writes).

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use crate::error::{bail, Context, Result};

use super::{clean_stale_temporaries, same_but_timing, write_bytes_atomic, SweepRecord};
use identify::record::read::{parse, read_bytes};

/// What a merge did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MergeReport {
    /// Records copied into a destination that had none.
    pub copied: usize,
    /// Records the destination already held (same fingerprint, same results).
    pub present: usize,
    /// Destination records replaced, with the reason (unreadable, or computed from other inputs).
    pub replaced: Vec<(PathBuf, String)>,
    /// Stale temporary files removed from the destinations.
    pub cleaned: usize,
}

/// Extensions of the files written beside a record `<id>.json` that belong to it.
const SIDECARS: [&str; 1] = ["cpu"];

struct Planned {
    src: PathBuf,
    dst: PathBuf,
    bytes: Vec<u8>,
    fingerprint: Option<String>,
    replaces: Option<String>,
}

/// Merges records: each pair is (source directory, destination directory); every `*.json` of a
/// source goes to the destination under the same name. A record in two sources must be the same
/// run (same fingerprint, same results but timings). A destination record that does not read
/// back, or that was computed from other inputs, is replaced (and reported); one with the same
/// fingerprint but other results is a conflict. Any unreadable source record or conflict stops
/// the merge before anything is written.
pub fn merge<R: SweepRecord>(pairs: &[(PathBuf, PathBuf)]) -> Result<MergeReport> {
    let mut problems: Vec<String> = Vec::new();
    let mut plan = plan_sources::<R>(pairs, &mut problems)?;
    classify_destinations::<R>(&mut plan, &mut problems);
    if !problems.is_empty() {
        bail!(
            "{} problem(s) found; nothing was written:\n  {}",
            problems.len(),
            problems.join("\n  ")
        );
    }
    write_plan(pairs, plan)
}

/// The first phase's first half: every `*.json` of every source read, parsed and planned for
/// its destination, by destination path. A record that does not read, has no fingerprint, or
/// differs from another source's record of the same name is a problem, not planned.
fn plan_sources<R: SweepRecord>(
    pairs: &[(PathBuf, PathBuf)],
    problems: &mut Vec<String>,
) -> Result<BTreeMap<PathBuf, Planned>> {
    let mut plan: BTreeMap<PathBuf, Planned> = BTreeMap::new();
    for (src_dir, dst_dir) in pairs {
        let mut names: Vec<PathBuf> = fs::read_dir(src_dir)
            .with_context(|| format!("reading {}", src_dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            .collect();
        names.sort();
        for src in names {
            let dst = dst_dir.join(src.file_name().expect("a file name"));
            // A directory named `x.json` is reported by the reader, not skipped.
            let record: Result<(R, Vec<u8>), _> =
                read_bytes(&src).and_then(|b| Ok((parse(&b, &src)?, b)));
            let (record, bytes) = match record {
                Ok(r) => r,
                Err(e) => {
                    problems.push(format!("{e:#}"));
                    continue;
                }
            };
            let Some(fingerprint) = record.fingerprint().map(str::to_string) else {
                problems.push(format!(
                    "{}: has no fingerprint (written by an older sysid); compute this part again",
                    src.display()
                ));
                continue;
            };
            if let Some(other) = plan.get(&dst) {
                if other.fingerprint.as_deref() != Some(&fingerprint)
                    || !same_but_timing(&other.bytes, &bytes)
                {
                    problems.push(format!(
                        "{} and {} hold different runs under one name",
                        other.src.display(),
                        src.display()
                    ));
                }
                continue;
            }
            plan.insert(
                dst.clone(),
                Planned {
                    src,
                    dst,
                    bytes,
                    fingerprint: Some(fingerprint),
                    replaces: None,
                },
            );
        }
    }
    Ok(plan)
}

/// The first phase's second half: each planned record whose destination already holds one is
/// marked as present (same run), or to replace (unreadable, or from other inputs, with the
/// reason); a destination that cannot be read, or holds the same fingerprint with other
/// results, is a problem.
fn classify_destinations<R: SweepRecord>(
    plan: &mut BTreeMap<PathBuf, Planned>,
    problems: &mut Vec<String>,
) {
    for p in plan.values_mut() {
        if !p.dst.exists() {
            continue;
        }
        let old = match read_bytes(&p.dst) {
            Ok(b) => b,
            Err(e @ identify::record::read::ReadError::TooLarge { .. }) => {
                p.replaces = Some(format!("unreadable: {e}"));
                continue;
            }
            Err(e) => {
                problems.push(e.to_string());
                continue;
            }
        };
        match parse::<R>(&old, &p.dst) {
            Err(e) => p.replaces = Some(format!("unreadable: {e:#}")),
            Ok(r) if r.fingerprint() != p.fingerprint.as_deref() => {
                p.replaces = Some(match r.fingerprint() {
                    None => "written by an older sysid (no fingerprint)".into(),
                    Some(f) => format!(
                        "computed from other inputs (fingerprint {} instead of {})",
                        short(f),
                        short(p.fingerprint.as_deref().unwrap_or(""))
                    ),
                })
            }
            Ok(_) if same_but_timing(&old, &p.bytes) => {
                p.replaces = Some(String::new());
            }
            Ok(_) => problems.push(format!(
                "{} and {} have the same fingerprint but different results",
                p.src.display(),
                p.dst.display()
            )),
        }
    }
}

/// The second phase: the destinations created and cleaned of stale temporaries, then each
/// planned record written (unless already present) with its sidecars. Returns what was done.
fn write_plan(
    pairs: &[(PathBuf, PathBuf)],
    plan: BTreeMap<PathBuf, Planned>,
) -> Result<MergeReport> {
    let mut report = MergeReport::default();
    let mut dst_dirs: Vec<&PathBuf> = pairs.iter().map(|(_, d)| d).collect();
    dst_dirs.sort();
    dst_dirs.dedup();
    for d in dst_dirs {
        fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        report.cleaned += clean_stale_temporaries(d)?;
    }
    for p in plan.into_values() {
        let present = match p.replaces {
            Some(why) if why.is_empty() => {
                report.present += 1;
                true
            }
            Some(why) => {
                report.replaced.push((p.dst.clone(), why));
                false
            }
            None => {
                report.copied += 1;
                false
            }
        };
        if !present {
            write_bytes_atomic(&p.dst, &p.bytes)?;
        }
        copy_sidecars(&p.src, &p.dst, present)?;
    }
    Ok(report)
}

/// Copies the sidecars of record `src` beside record `dst` (atomically); with `only_missing`,
/// only those `dst` lacks.
fn copy_sidecars(src: &Path, dst: &Path, only_missing: bool) -> Result<()> {
    for ext in SIDECARS {
        let (from, to) = (src.with_extension(ext), dst.with_extension(ext));
        if !from.is_file() || (only_missing && to.exists()) {
            continue;
        }
        let bytes = fs::read(&from).with_context(|| format!("reading {}", from.display()))?;
        write_bytes_atomic(&to, &bytes)?;
    }
    Ok(())
}

/// The first 12 hex digits of a fingerprint, for messages.
fn short(f: &str) -> &str {
    &f[..f.len().min(12)]
}

/// The record directories of a shard's output paired with their destination under `into`:
/// `PART/records/<study>/` of a reproduction (one directory per study), and `PART/records/`
/// itself when it holds records (a structure study or a study file writes its records there).
pub fn study_pairs(parts: &[PathBuf], into: &Path) -> Result<Vec<(PathBuf, PathBuf)>> {
    let mut pairs = Vec::new();
    for part in parts {
        let records = part.join("records");
        let studies = fs::read_dir(&records).with_context(|| {
            format!(
                "reading {} (a part is the output directory of a sharded sweep, `--shard i/n`)",
                records.display()
            )
        })?;
        let entries: Vec<PathBuf> = studies.filter_map(|e| e.ok().map(|e| e.path())).collect();
        if entries
            .iter()
            .any(|p| p.is_file() && p.extension().is_some_and(|x| x == "json"))
        {
            pairs.push((records.clone(), into.join("records")));
        }
        let mut dirs: Vec<PathBuf> = entries.into_iter().filter(|p| p.is_dir()).collect();
        dirs.sort();
        for dir in dirs {
            let name = dir.file_name().expect("a directory name").to_owned();
            pairs.push((dir, into.join("records").join(name)));
        }
    }
    Ok(pairs)
}
