//! SPEC Table I by computation: the moments of `z = xᵀx`,
//! `x ~ N(0, I_nx)`, nx = 1..10, by the exact χ² formulas, linearisation (T1, EKF), second-order
//! expansion (T2, EKF2) and the unscented transform (UT, β = 2, κ = 0), and writes `table1.json`
//! and `table1.md` to the output directory.

use crate::error::Context;
use core_filters::kalman::table1::TABLE1_UT_ALPHA;
use core_filters::kalman::{table1, Table1Row};
use std::fmt::Write as _;
use std::path::Path;

const METHODS: [&str; 4] = ["exact", "T1", "T2", "UT"];

/// The table as Markdown: one row per nx, mean and variance per method.
fn markdown(rows: &[Table1Row]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Table I — moments of z = xᵀx, x ~ N(0, I_nx)\n\n\
         Computed by the filter code: T1 = EKF linearisation at the mean, T2 = EKF2 with the \
         Hessian 2I, UT = scaled unscented transform (α = {TABLE1_UT_ALPHA}, β = 2, κ = 0), \
         exact = χ² moments (nx, 2nx).\n"
    );
    let mut header = String::from("| nx |");
    let mut rule = String::from("|---:|");
    for m in METHODS {
        let _ = write!(header, " {m} mean | {m} var |");
        rule.push_str("---:|---:|");
    }
    let _ = writeln!(s, "{header}\n{rule}");
    let mut nxs: Vec<usize> = rows.iter().map(|r| r.nx).collect();
    nxs.dedup();
    for nx in nxs {
        let mut line = format!("| {nx} |");
        for m in METHODS {
            match rows.iter().find(|r| r.nx == nx && r.method == m) {
                Some(r) => {
                    let _ = write!(line, " {} | {} |", fmt(r.mean), fmt(r.variance));
                }
                None => line.push_str(" – | – |"),
            }
        }
        let _ = writeln!(s, "{line}");
    }
    s
}

/// Compact number format: integers stay integers when they are exact to 1e-9.
fn fmt(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{}", v.round() as i64)
    } else {
        format!("{v:.6}")
    }
}

/// Computes Table I, writes `table1.json` and `table1.md` into `out`, and returns the Markdown.
pub fn write(out: &Path) -> crate::error::Result<String> {
    let rows = table1().context("computing Table I")?;
    let md = markdown(&rows);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let json_path = out.join("table1.json");
    let json = serde_json::json!({
        "table": "SPEC Table I: moments of z = x^T x, x ~ N(0, I_nx)",
        "ut": { "alpha": TABLE1_UT_ALPHA, "beta": 2.0, "kappa": 0.0 },
        "rows": rows,
    });
    // Through the writer of every output (only a new or regular file is replaced), and before
    // the table is printed: a closed standard output ends the process at the print.
    identify::record::atomic::write_bytes_atomic(
        &json_path,
        (serde_json::to_string_pretty(&json)? + "\n").as_bytes(),
    )?;
    let md_path = out.join("table1.md");
    identify::record::atomic::write_bytes_atomic(&md_path, md.as_bytes())?;
    log::info!("wrote {} and {}", json_path.display(), md_path.display());
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_has_one_line_per_dimension_with_paper_values() {
        let rows = table1().unwrap();
        let md = markdown(&rows);
        // Header, rule, and ten data rows.
        let data: Vec<&str> = md
            .lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| nx"))
            .collect();
        assert_eq!(data.len(), 10);
        // nx = 10: exact 10, 20; T1 0, 0; T2 10, 20; UT 10, 200.
        assert_eq!(data[9], "| 10 | 10 | 20 | 0 | 0 | 10 | 20 | 10 | 200 |");
    }
}
