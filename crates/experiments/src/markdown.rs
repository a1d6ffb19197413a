//! Markdown helpers shared by the reports.

use std::fmt::Write as _;

/// Writes a Markdown table row.
pub(crate) fn row(out: &mut String, cells: &[String]) {
    let _ = writeln!(out, "| {} |", cells.join(" | "));
}
