//! The command reference (`docs/cli.md`), generated from `sysid`'s own help so that it cannot
//! drift from it: `cargo xtask docs` writes it, a test fails when the file and the help disagree.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use crate::error::{bail, Context, Result};

/// The subcommands listed under "Commands:" in a clap help text (without `help`).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| l.trim() != "Commands:")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter(|l| !l.starts_with("   ")) // continuation lines of a long description
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_string)
        .collect()
}

/// The help text of `sysid ARGS --help`.
fn help(sysid: &Path, args: &[&str]) -> Result<String> {
    let out = Command::new(sysid)
        .args(args)
        .arg("--help")
        .env("COLUMNS", "100")
        .output()
        .with_context(|| format!("running {}", sysid.display()))?;
    if !out.status.success() {
        bail!(
            "`sysid {} --help` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    String::from_utf8(out.stdout).context("help text is not UTF-8")
}

/// The whole reference as Markdown: `sysid --help`, then every subcommand's help in the order
/// `sysid --help` lists them.
pub fn render(sysid: &Path) -> Result<String> {
    let top = help(sysid, &[])?;
    let mut o = String::new();
    let _ = writeln!(o, "# Command reference: `sysid`\n");
    let _ = writeln!(
        o,
        "Generated from the tool's own help by `cargo xtask docs` (a test fails when this file \
         and the help disagree). A walk-through is in [the user guide](user-guide.md).\n"
    );
    let _ = writeln!(o, "```text\n{}```\n", top);
    for sub in subcommands(&top) {
        let text = help(sysid, &[&sub])?;
        let _ = writeln!(o, "## `sysid {sub}`\n\n```text\n{}```\n", text);
    }
    Ok(o.trim_end().to_string() + "\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_command_list_of_a_clap_help() {
        let help =
            "About\n\nUsage: sysid <COMMAND>\n\nCommands:\n  simulate  Simulate a structure\n  \
                    filter    Run one filter\n            on a data set\n  help      Print this\n\n\
                    Options:\n  -h, --help  Print help\n";
        assert_eq!(subcommands(help), vec!["simulate", "filter"]);
    }
}
