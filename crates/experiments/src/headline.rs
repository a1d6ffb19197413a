//! The README's headline table: θ_val / θ_true, mean ± s.d. over the paper's Fig. 7 runs, per
//! algorithm and stiffness/damping parameter, computed from the committed run records (never
//! typed, so it cannot drift from them: a test compares the README with this function's output).
//!
//! Each cell is rounded once, from the records' full-precision statistics. The lowest
//! run-to-run s.d. of each column is bold, and so is an algorithm's name when it has the lowest
//! s.d. in every column.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{bail, Context, Result};

use crate::reproduce::{algorithm_stats, AlgorithmStats};
use identify::record::RunRecord;

/// The line before the generated table in the README.
pub(crate) const BEGIN: &str = "<!-- headline table: generated from results/paper/records/fig7 by `cargo xtask docs`; do not edit by hand -->";
/// The line after it.
pub(crate) const END: &str = "<!-- end of the generated headline table -->";

/// Rows in this order (the paper's order of presentation, then the baseline).
const ALGORITHMS: [(&str, &str); 4] = [
    ("mln-rbpf", "MLN-RBPF"),
    ("storvik", "Storvik"),
    ("mpf-ekf2", "MPF-EKF2"),
    ("bootstrap", "bootstrap PF"),
];

/// Columns: the parameters of the table, and the decimals each is given with (the stiffnesses
/// move in the third decimal, the dampings in the second).
const COLUMNS: [(&str, usize); 6] = [
    ("k1", 3),
    ("k2", 3),
    ("k3", 3),
    ("c1", 2),
    ("c2", 2),
    ("c3", 2),
];

/// The table from the records of one sweep (every algorithm's runs together).
pub fn table(records: &[RunRecord]) -> Result<String> {
    let stats: Vec<(&str, AlgorithmStats)> = ALGORITHMS
        .iter()
        .map(|(name, label)| {
            let runs: Vec<&RunRecord> = records.iter().filter(|r| r.algorithm == *name).collect();
            (*label, algorithm_stats(name, &runs))
        })
        .collect();
    let runs = stats.iter().map(|(_, s)| s.runs).max().unwrap_or(0);
    if runs == 0 {
        bail!("no records of the paper's algorithms to draw the headline table from");
    }
    // (mean, s.d.) of every cell, [algorithm][column].
    let cells: Vec<Vec<(f64, f64)>> = stats
        .iter()
        .map(|(label, s)| {
            COLUMNS
                .iter()
                .map(|(p, _)| {
                    s.params
                        .iter()
                        .find(|q| q.name == *p)
                        .map(|q| (q.ratio_mean, q.ratio_sd))
                        .with_context(|| format!("{label}: no parameter {p} in the records"))
                })
                .collect::<Result<Vec<_>>>()
        })
        .collect::<Result<_>>()?;
    let lowest_sd: Vec<f64> = (0..COLUMNS.len())
        .map(|j| {
            cells
                .iter()
                .map(|row| row[j].1)
                .fold(f64::INFINITY, f64::min)
        })
        .collect();

    let mut o = String::new();
    let head: Vec<&str> = COLUMNS.iter().map(|(p, _)| *p).collect();
    let _ = writeln!(
        o,
        "| θ_val / θ_true, mean ± s.d. over {runs} runs | {} |",
        head.join(" | ")
    );
    let _ = writeln!(o, "|---|{}", "---|".repeat(COLUMNS.len()));
    for ((label, s), row) in stats.iter().zip(&cells) {
        let best_everywhere = row.iter().zip(&lowest_sd).all(|(c, l)| c.1 == *l);
        let name = if best_everywhere {
            format!("**{label}**")
        } else {
            label.to_string()
        };
        let failed = if s.failed > 0 {
            format!(" ({} of {} runs failed, left out)", s.failed, s.runs)
        } else {
            String::new()
        };
        let cols: Vec<String> = row
            .iter()
            .zip(&COLUMNS)
            .zip(&lowest_sd)
            .map(|(((m, sd), (_, d)), l)| {
                let sd_text = format!("{sd:.d$}", d = *d);
                let sd_text = if sd == l {
                    format!("**{sd_text}**")
                } else {
                    sd_text
                };
                format!("{m:.d$} ± {sd_text}", d = *d)
            })
            .collect();
        let _ = writeln!(o, "| {name}{failed} | {} |", cols.join(" | "));
    }
    Ok(o)
}

/// The table from a directory of run records (`results/paper/records/fig7`).
pub fn from_dir(dir: &Path) -> Result<String> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("reading the records in {}", dir.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()
        .with_context(|| format!("listing {}", dir.display()))?;
    paths.retain(|p| p.extension().is_some_and(|e| e == "json"));
    paths.sort();
    let records: Vec<RunRecord> = paths
        .iter()
        .map(|p| crate::sweep::read_record(p))
        .collect::<Result<_>>()?;
    table(&records)
}

/// `readme` with the text between `BEGIN` and `END` replaced by `table`.
pub fn splice(readme: &str, table: &str) -> Result<String> {
    let (Some(b), Some(e)) = (readme.find(BEGIN), readme.find(END)) else {
        bail!("the README has no generated headline table (the lines `{BEGIN}` and `{END}`)");
    };
    if e < b {
        bail!("the README's headline table markers are out of order");
    }
    let start = b + BEGIN.len();
    Ok(format!("{}\n{}{}", &readme[..start], table, &readme[e..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splice_replaces_only_the_generated_part() {
        let readme = format!("intro\n{BEGIN}\nold\n{END}\nrest\n");
        let out = splice(&readme, "| new |\n").unwrap();
        assert_eq!(out, format!("intro\n{BEGIN}\n| new |\n{END}\nrest\n"));
        assert!(splice("no markers", "x").is_err());
    }
}
