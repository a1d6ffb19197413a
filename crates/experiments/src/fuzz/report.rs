//! What a fuzz run found: a table per target and the failures with their reproducers.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::probe::{Probe, Program};
use super::{Options, Outcome, Verdict};

/// Counts of one target.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Row {
    pub target: String,
    pub probes: usize,
    /// Refused with an error message.
    pub refused: usize,
    pub accepted: usize,
    pub crashes: usize,
    pub hangs: usize,
    /// Probes that wrote outside their outputs (whatever their exit).
    pub stray: usize,
    /// Refused without a message, an unexpected exit status, or a broken promise.
    pub unclear: usize,
    /// The longest probe.
    pub slowest: Duration,
}

/// What kind of failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureKind {
    Crash,
    Hang,
    StrayWrite,
    Unclear,
}

/// One failed probe.
#[derive(Debug, Clone)]
pub struct Failure {
    pub index: usize,
    pub target: String,
    /// The hostile change.
    pub what: String,
    pub kinds: Vec<FailureKind>,
    /// What happened: the crash, or the paths written outside the outputs.
    pub detail: String,
    /// The probe's files and `command.sh`.
    pub reproducer: Option<PathBuf>,
}

/// The result of a fuzz run.
#[derive(Debug, Clone)]
pub struct Report {
    pub seed: u64,
    pub rows: Vec<Row>,
    pub failures: Vec<Failure>,
    /// Where the reproducers are.
    pub failures_dir: PathBuf,
    pub took: Duration,
}

impl Report {
    pub(crate) fn new(
        opts: &Options,
        targets: &[&str],
        outcomes: Vec<Outcome>,
        took: Duration,
    ) -> Self {
        let mut rows: Vec<Row> = targets
            .iter()
            .map(|t| Row {
                target: t.to_string(),
                ..Row::default()
            })
            .collect();
        let mut failures = Vec::new();
        for o in &outcomes {
            let Some(row) = rows.iter_mut().find(|r| r.target == o.target) else {
                continue;
            };
            row.probes += 1;
            row.slowest = row.slowest.max(o.took);
            match &o.ended {
                Verdict::Accepted => row.accepted += 1,
                Verdict::Refused(_) => row.refused += 1,
                Verdict::Crash(_) => row.crashes += 1,
                Verdict::Hang => row.hangs += 1,
                Verdict::Unclear(_) => row.unclear += 1,
            }
            if !o.stray.is_empty() {
                row.stray += 1;
            }
            if failed(o) {
                failures.push(failure(o));
            }
        }
        Report {
            seed: opts.seed,
            rows,
            failures,
            failures_dir: opts.failures.clone(),
            took,
        }
    }

    /// No crash, hang, stray write or unclear refusal.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }

    /// The table of counts per target, a total, and each failure with its reproducer.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<19} {:>6} {:>8} {:>8} {:>7} {:>5} {:>12} {:>7} {:>9}",
            "target",
            "probes",
            "refused",
            "accepted",
            "crashes",
            "hangs",
            "stray writes",
            "unclear",
            "slowest"
        );
        let mut total = Row {
            target: "all".into(),
            ..Row::default()
        };
        for r in &self.rows {
            row_line(&mut s, r);
            total.probes += r.probes;
            total.refused += r.refused;
            total.accepted += r.accepted;
            total.crashes += r.crashes;
            total.hangs += r.hangs;
            total.stray += r.stray;
            total.unclear += r.unclear;
            total.slowest = total.slowest.max(r.slowest);
        }
        row_line(&mut s, &total);
        let _ = writeln!(
            s,
            "seed {}, {:.1} s; refused: with an error message; stray writes: probes that changed a \
             file outside their outputs",
            self.seed,
            self.took.as_secs_f64()
        );
        for f in &self.failures {
            let _ = writeln!(
                s,
                "FAILED probe {} ({}): {}\n  {}\n  reproducer: {}",
                f.index,
                f.target,
                f.what.escape_debug(),
                f.detail.escape_debug(),
                f.reproducer
                    .as_ref()
                    .map_or_else(|| "none".into(), |p| p.display().to_string())
            );
        }
        if !self.failures.is_empty() {
            let _ = writeln!(
                s,
                "{} failed probe(s); reproducers (files and command.sh) in {}",
                self.failures.len(),
                self.failures_dir.display()
            );
        }
        s
    }
}

fn row_line(s: &mut String, r: &Row) {
    let _ = writeln!(
        s,
        "{:<19} {:>6} {:>8} {:>8} {:>7} {:>5} {:>12} {:>7} {:>7.2} s",
        r.target,
        r.probes,
        r.refused,
        r.accepted,
        r.crashes,
        r.hangs,
        r.stray,
        r.unclear,
        r.slowest.as_secs_f64()
    );
}

/// Did the probe fail?
pub(crate) fn failed(o: &Outcome) -> bool {
    !o.stray.is_empty()
        || matches!(
            o.ended,
            Verdict::Crash(_) | Verdict::Hang | Verdict::Unclear(_)
        )
}

fn failure(o: &Outcome) -> Failure {
    let mut kinds = Vec::new();
    match &o.ended {
        Verdict::Crash(_) => kinds.push(FailureKind::Crash),
        Verdict::Hang => kinds.push(FailureKind::Hang),
        Verdict::Unclear(_) => kinds.push(FailureKind::Unclear),
        _ => {}
    }
    if !o.stray.is_empty() {
        kinds.push(FailureKind::StrayWrite);
    }
    Failure {
        index: o.index,
        target: o.target.to_string(),
        what: o.what.clone(),
        kinds,
        detail: detail(o),
        reproducer: o.reproducer.clone(),
    }
}

fn detail(o: &Outcome) -> String {
    let mut parts = Vec::new();
    match &o.ended {
        Verdict::Crash(m) => parts.push(format!("crash: {m}")),
        Verdict::Hang => parts.push(format!(
            "hang: still running after {:.0} s",
            o.took.as_secs_f64()
        )),
        Verdict::Unclear(m) => parts.push(format!("unclear: {m}")),
        Verdict::Refused(m) => parts.push(format!("refused: {m}")),
        Verdict::Accepted => parts.push("accepted".into()),
    }
    if !o.stray.is_empty() {
        parts.push(format!("wrote outside its outputs: {}", o.stray.join(", ")));
    }
    parts.join("; ")
}

/// One line about a failed probe.
pub(crate) fn describe(o: &Outcome) -> String {
    format!(
        "probe {} ({}) FAILED: {}: {}",
        o.index,
        o.target,
        o.what.escape_debug(),
        detail(o).escape_debug()
    )
}

/// `s` quoted for a POSIX shell.
fn quoted(s: &[u8]) -> String {
    let text = String::from_utf8_lossy(s);
    format!("'{}'", text.replace('\'', "'\\''"))
}

/// The script of a reproducer: it runs the probe from its own `work/` directory, with the
/// stand-ins for Slurm first on PATH, as the driver ran it.
pub(crate) fn command_script(opts: &Options, p: &Probe, o: &Outcome, program: &Path) -> String {
    let mut s = String::from("#!/bin/sh\n");
    let _ = writeln!(
        s,
        "# Probe {} (target `{}`) of `cargo xtask fuzz --seed {}`.",
        o.index, p.target, opts.seed
    );
    for line in format!("Hostile change: {}", o.what.escape_debug())
        .lines()
        .chain(detail(o).escape_debug().to_string().lines())
    {
        let _ = writeln!(s, "# {line}");
    }
    s.push_str("here=$(cd \"$(dirname \"$0\")\" && pwd)\ncd \"$here/work\" || exit 1\n");
    s.push_str("PATH=\"$here/bin:$PATH\" RAYON_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE=1 exec ");
    let mut words = vec![quoted(program.as_os_str().as_encoded_bytes())];
    words.extend(p.argv().iter().map(|a| quoted(a.as_encoded_bytes())));
    s.push_str(&words.join(" "));
    s.push('\n');
    if p.program == Program::Python {
        s.push_str("# The Python script prints a refusal as `Error: …` and exits 1.\n");
    }
    s
}
