//! Markdown helpers shared by the reports.

use std::fmt::Write as _;

/// Writes a Markdown table row.
pub(crate) fn row(out: &mut String, cells: &[String]) {
    let _ = writeln!(out, "| {} |", cells.join(" | "));
}

/// Writes a table's header row and the `---` rule below it.
pub(crate) fn header<S: AsRef<str>>(out: &mut String, cells: &[S]) {
    let cells: Vec<String> = cells.iter().map(|c| c.as_ref().to_string()).collect();
    row(out, &cells);
    row(out, &vec!["---".to_string(); cells.len()]);
}

/// Text for a table cell: a `|` inside it (as in |ratio − 1|) would end the cell.
pub(crate) fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}
