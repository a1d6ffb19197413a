//! Two output directories of the same study compared with the timings set aside: the check that
//! a study run on a cluster gives what the same study gives on one machine.
//!
//! Compared: every record (`records/**/*.json`) as JSON without its `timing` object;
//! `summary.json` without the keys that hold times, costs or the invocation's run counts;
//! `cells.csv` (a structure study's cells) without its cost columns; the report (`REPORT.md`)
//! without the lines that describe the invocation (threads, runs executed by it, wall times) and
//! without its "Performance" section; every other file byte for byte. Not compared: the files
//! that hold only measured costs (`*.cpu`, the cost figure), what one invocation did
//! (`last-run.json`), the files of the submission itself
//! (`cluster/`), and the report of a structure study (a directory with `cells.csv`), whose costs
//! are woven into its tables and sentences — its accuracy figures come from the cells and the
//! summary, which are compared.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::ClusterError;
use crate::sweep::same_but_timing;

/// Files that hold measured costs only, by name.
const COST_FILES: [&str; 1] = ["cost_vs_dimension.svg"];

/// Keys of `summary.json` (at any depth) and columns of `cells.csv` that hold times, rates or
/// cost fits.
const TIMING_KEYS: [&str; 7] = [
    "wall_s",
    "wall_s_mean",
    "sweep_wall_s",
    "particle_steps_per_s_mean",
    "us_per_particle_step",
    "cpu_us_per_particle_step",
    "cost_fits",
];

/// Top-level key of `summary.json` that counts what one invocation executed and reused.
const INVOCATION_KEY: &str = "runs";

/// Report lines that describe the invocation, by their first cell.
const INVOCATION_ROWS: [&str; 4] = [
    "| threads |",
    "| runs executed by this invocation |",
    "| wall time, sweeps (s) |",
    "| wall time, total incl. figures (s) |",
];

fn files(root: &Path) -> Result<BTreeSet<PathBuf>, ClusterError> {
    let structure_study = root.join("cells.csv").is_file();
    let mut out = BTreeSet::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries = std::fs::read_dir(&dir).map_err(|e| ClusterError::file(&dir, e))?;
        for e in entries {
            let e = e.map_err(|e| ClusterError::file(&dir, e))?;
            let p = e.path();
            let rel = p.strip_prefix(root).expect("under root").to_path_buf();
            let name = e.file_name().to_string_lossy().into_owned();
            if rel == Path::new("cluster") || name.starts_with('.') {
                continue;
            }
            // `last-run.json` describes the invocation (wall times, runs executed, threads).
            let costs_only = name.ends_with(".cpu")
                || name == crate::sweep::last_run::FILE
                || COST_FILES.contains(&name.as_str())
                || (structure_study && rel == Path::new("REPORT.md"));
            if p.is_dir() {
                stack.push(p);
            } else if !costs_only {
                out.insert(rel);
            }
        }
    }
    Ok(out)
}

/// The report without its invocation rows and its "Performance" section.
fn report_without_timings(text: &str) -> String {
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        if line.starts_with("## ") {
            skipping = line.starts_with("## Performance");
        }
        if skipping || INVOCATION_ROWS.iter().any(|r| line.starts_with(r)) {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

fn strip_keys(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(m) => {
            for k in TIMING_KEYS {
                m.remove(k);
            }
            m.values_mut().for_each(strip_keys);
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(strip_keys),
        _ => {}
    }
}

/// A CSV text without the columns named in [`TIMING_KEYS`].
fn csv_without_timings(text: &str) -> String {
    let mut lines = text.lines();
    let Some(header) = lines.next() else {
        return String::new();
    };
    let keep: Vec<bool> = header
        .split(',')
        .map(|h| !TIMING_KEYS.contains(&h.trim()))
        .collect();
    let pick = |line: &str| -> String {
        line.split(',')
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(c, _)| c)
            .collect::<Vec<_>>()
            .join(",")
    };
    std::iter::once(header)
        .chain(lines)
        .map(|l| pick(l) + "\n")
        .collect()
}

fn same_file(rel: &Path, a: &[u8], b: &[u8]) -> bool {
    let name = rel.file_name().map(|n| n.to_string_lossy().into_owned());
    if rel.starts_with("records") && rel.extension().is_some_and(|x| x == "json") {
        return same_but_timing(a, b);
    }
    match name.as_deref() {
        Some("REPORT.md") => {
            report_without_timings(&String::from_utf8_lossy(a))
                == report_without_timings(&String::from_utf8_lossy(b))
        }
        Some("cells.csv") => {
            csv_without_timings(&String::from_utf8_lossy(a))
                == csv_without_timings(&String::from_utf8_lossy(b))
        }
        Some("summary.json") => {
            let parse = |x: &[u8]| {
                serde_json::from_slice::<serde_json::Value>(x)
                    .ok()
                    .map(|mut v| {
                        if let Some(m) = v.as_object_mut() {
                            m.remove(INVOCATION_KEY);
                        }
                        strip_keys(&mut v);
                        v
                    })
            };
            matches!((parse(a), parse(b)), (Some(x), Some(y)) if x == y)
        }
        _ => a == b,
    }
}

/// The differences between two output directories, timings aside (empty: the same result).
pub fn compare(a: &Path, b: &Path) -> Result<Vec<String>, ClusterError> {
    let (fa, fb) = (files(a)?, files(b)?);
    let mut diffs = Vec::new();
    for rel in fa.symmetric_difference(&fb) {
        let (has, lacks) = if fa.contains(rel) { (a, b) } else { (b, a) };
        diffs.push(format!(
            "{} is in {} but not in {}",
            rel.display(),
            has.display(),
            lacks.display()
        ));
    }
    for rel in fa.intersection(&fb) {
        let read = |root: &Path| {
            let p = root.join(rel);
            models::readers::read_input(&p).map_err(|e| ClusterError::file(&p, e))
        };
        if !same_file(rel, &read(a)?, &read(b)?) {
            diffs.push(format!("{} differs", rel.display()));
        }
    }
    Ok(diffs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_is_compared_without_its_invocation_and_performance() {
        let a = "# R\n| threads | 2 |\n| seed | 1 |\n## Performance\n| x | 0.1 |\n## Next\nok\n";
        let b = "# R\n| threads | 8 |\n| seed | 1 |\n## Performance\n| x | 0.3 |\n## Next\nok\n";
        assert!(same_file(
            Path::new("REPORT.md"),
            a.as_bytes(),
            b.as_bytes()
        ));
        let c = b.replace("| seed | 1 |", "| seed | 2 |");
        assert!(!same_file(
            Path::new("REPORT.md"),
            a.as_bytes(),
            c.as_bytes()
        ));
        let c = b.replace("ok", "not ok");
        assert!(!same_file(
            Path::new("REPORT.md"),
            a.as_bytes(),
            c.as_bytes()
        ));
    }

    #[test]
    fn the_summary_is_compared_without_times() {
        let a = br#"{"wall_s": 1.0, "runs": {"executed": 4}, "s": [{"wall_s_mean": 2, "ratio": 1.5, "runs": 4}]}"#;
        let b = br#"{"wall_s": 9.0, "runs": {"executed": 0}, "s": [{"wall_s_mean": 3, "ratio": 1.5, "runs": 4}]}"#;
        let c = br#"{"wall_s": 9.0, "s": [{"wall_s_mean": 3, "ratio": 1.6, "runs": 4}]}"#;
        let d = br#"{"wall_s": 9.0, "s": [{"wall_s_mean": 3, "ratio": 1.5, "runs": 3}]}"#;
        let p = Path::new("summary.json");
        assert!(same_file(p, a, b));
        assert!(!same_file(p, a, c));
        assert!(
            !same_file(p, a, d),
            "a count of runs inside the results is a result"
        );
    }

    #[test]
    fn cells_are_compared_without_their_cost_columns() {
        let a = "structure,k_error_mean,us_per_particle_step\nn2,0.1,1.9\n";
        let b = "structure,k_error_mean,us_per_particle_step\nn2,0.1,2.3\n";
        let c = "structure,k_error_mean,us_per_particle_step\nn2,0.2,1.9\n";
        let p = Path::new("cells.csv");
        assert!(same_file(p, a.as_bytes(), b.as_bytes()));
        assert!(!same_file(p, a.as_bytes(), c.as_bytes()));
    }
}
