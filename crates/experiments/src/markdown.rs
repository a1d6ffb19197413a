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

/// Writes a table's header row and its rule in the compact form `|---|---:|`: one character of
/// `align` per column, `l` for a left-aligned column and `r` for a right-aligned one.
pub(crate) fn compact_header(out: &mut String, cells: &[&str], align: &str) {
    debug_assert_eq!(
        cells.len(),
        align.chars().count(),
        "one alignment per column"
    );
    let cells: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
    row(out, &cells);
    let rule: Vec<&str> = align
        .chars()
        .map(|a| if a == 'r' { "---:" } else { "---" })
        .collect();
    let _ = writeln!(out, "|{}|", rule.join("|"));
}

/// The items written one after the other, separated by `sep`.
pub(crate) fn joined<T: std::fmt::Display>(
    items: impl IntoIterator<Item = T>,
    sep: &str,
) -> String {
    items
        .into_iter()
        .map(|item| item.to_string())
        .collect::<Vec<_>>()
        .join(sep)
}

/// A number with `digits` decimals, or "–" for a missing (non-finite) one.
pub(crate) fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

/// "0.93 of 150": a fraction of `of` cases, or "–" when there was none to count.
pub(crate) fn share(fraction: f64, of: usize) -> String {
    if of > 0 && fraction.is_finite() {
        format!("{fraction:.2} of {of}")
    } else {
        "–".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compact_headers_align_each_column() {
        let mut out = String::new();
        compact_header(&mut out, &["name", "x \\| y", "n"], "lrr");
        assert_eq!(out, "| name | x \\| y | n |\n|---|---:|---:|\n");
    }

    #[test]
    fn missing_numbers_are_dashes() {
        assert_eq!(num(1.23456, 2), "1.23");
        assert_eq!(num(f64::NAN, 2), "–");
        assert_eq!(num(f64::INFINITY, 0), "–");
        assert_eq!(share(0.5, 10), "0.50 of 10");
        assert_eq!(share(f64::NAN, 0), "–");
        assert_eq!(share(0.0, 0), "–");
        assert_eq!(joined([1, 2, 3], ", "), "1, 2, 3");
        assert_eq!(joined(Vec::<usize>::new(), ", "), "");
    }
}
