//! A fuzz driver for the `sysid` command line and the Python package `sysid_mpf`: hostile
//! inputs against every subcommand that reads a user's file, value or output path, and against
//! the package's readers, writers and runs (`cargo xtask fuzz`, and at a small size the test
//! `crates/experiments/tests/fuzz_cli.rs`).
//!
//! Each probe starts from a valid command on valid inputs that `sysid` itself made (the seeds:
//! small data sets, records, study and filter files, channel maps with excerpts of the real
//! recordings, a cluster submission, a finished field study; 0.5 s of record and 20 particles,
//! so a probe takes milliseconds) and makes one hostile change: a byte-level mutation of an
//! input (cut short, bits flipped, numbers replaced by `1e308`, `NaN`, `-0`, 2⁶⁴…, quotes,
//! NUL, bytes that are not UTF-8, a line of a million bytes, brackets nested 100,000 deep), a
//! special file where an input is expected (a named pipe, a link to `/dev/zero`, a directory, a
//! 3 GiB sparse file, a link to itself or out of the directory), a special output (a link to
//! `/dev/null` or to a file outside, a named pipe, a directory where a file goes, an input as
//! the output, a file of someone else's in the output directory, a newline, `#`, `%` or quotes
//! in the name), a hostile value of a flag, or a damaged command line. A seed reproduces the
//! probes: probe `i` draws from a stream of its own.
//!
//! A probe fails when the program
//! - **crashes**: exits 101 or says `panicked at` (a panic), a `PanicException` in Python, or
//!   is ended by a signal (SIGABRT of a failed allocation, SIGSEGV, …);
//! - **hangs**: still runs at the time limit (killed, with its process group);
//! - **writes outside its output**: the probe's directory (inputs included, hashed), the seeds
//!   and the repository checkout are compared before and after, and every file created,
//!   changed or deleted must lie under one of the probe's declared outputs and be none of its
//!   inputs nor what was there already and is not the program's (a link, a pipe, a user's file);
//! - refuses **without a message** (a non-zero exit with no `Error:` line), or (Python) writes
//!   a data set that does not read back.
//!
//! Each failure leaves a reproducer: the probe's files and a `command.sh` that runs it.

mod exec;
mod hostile;
mod mutate;
mod probe;
mod python;
mod report;
mod seeds;
mod snapshot;
mod targets;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use rand::SeedableRng;

use crate::error::{bail, Context, Result};

use exec::Ended;
use mutate::FuzzRng;
use probe::{Probe, Program};
use snapshot::{Depth, Snapshot};

pub use report::{Failure, FailureKind, Report, Row};

/// What to run.
#[derive(Debug, Clone)]
pub struct Options {
    /// The `sysid` binary under test.
    pub sysid: PathBuf,
    /// A Python interpreter with `sysid_mpf` installed: its probes run too.
    pub python: Option<PathBuf>,
    /// The repository checkout: the seeds are cut from its recordings and channel maps, and no
    /// probe may write into it.
    pub repository: PathBuf,
    /// A directory for the probes (emptied first); the repository guard skips it.
    pub scratch: PathBuf,
    /// Where the reproducers of failures go (emptied first).
    pub failures: PathBuf,
    /// Master seed of the probes.
    pub seed: u64,
    /// Probes in all, spread evenly over the targets.
    pub probes: usize,
    /// Time limit of one probe.
    pub timeout: Duration,
    /// Probes run at once.
    pub jobs: usize,
    /// Only the targets whose name starts with one of these (all when empty): `filter`,
    /// `cluster`, `py` (every Python target), …
    pub only: Vec<String>,
    /// Paths in the repository the guard skips besides `.git`, `target/`, the scratch and the
    /// failures (a build directory, a virtual environment).
    pub unguarded: Vec<PathBuf>,
}

/// The names of every target, the `sysid` subcommands first, then the Python ones.
pub fn target_names() -> Vec<&'static str> {
    targets::TARGETS
        .iter()
        .chain(python::TARGETS)
        .map(|(n, _)| *n)
        .collect()
}

/// Runs the probes and reports what each target did.
pub fn run(opts: &Options) -> Result<Report> {
    let started = Instant::now();
    let chosen = chosen_targets(opts)?;
    if let Some(py) = &opts.python {
        check_python(py)?;
    }
    for dir in [&opts.scratch, &opts.failures] {
        if dir.exists() {
            std::fs::remove_dir_all(dir).with_context(|| format!("emptying {}", dir.display()))?;
        }
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let scratch = std::path::absolute(&opts.scratch)?;
    let seeds_dir = scratch.join("seeds");
    let seeds = seeds::build(&opts.sysid, &opts.repository, &seeds_dir)?;
    log::info!(
        "fuzz: seeds made in {:.1} s; {} probes over {} targets",
        started.elapsed().as_secs_f64(),
        opts.probes,
        chosen.len()
    );
    let guard = Guard::new(opts, &scratch, &seeds_dir)?;
    let runner = Runner {
        opts,
        seeds: &seeds,
        chosen: &chosen,
        guard: &guard,
        scratch: &scratch,
    };
    let results = runner.run_all();
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(report::Report::new(
        opts,
        &chosen.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
        results?,
        started.elapsed(),
    ))
}

/// The probes a run of `opts` makes, one line each (index, target, hostile change, command
/// line) after a line with the digest of the seed files, without running them: what a seed
/// does.
pub fn plan(opts: &Options) -> Result<Vec<String>> {
    let chosen = chosen_targets(opts)?;
    let scratch = std::path::absolute(&opts.scratch)?;
    let seeds = seeds::build(&opts.sysid, &opts.repository, &scratch.join("seeds"))?;
    let guard = Guard::new(opts, &scratch, &scratch.join("seeds"))?;
    let runner = Runner {
        opts,
        seeds: &seeds,
        chosen: &chosen,
        guard: &guard,
        scratch: &scratch,
    };
    let seeds_line = format!("seeds: {}", seeds.digest());
    let lines = std::iter::once(seeds_line)
        .chain((0..opts.probes).map(|i| {
            let p = runner.make(i);
            let argv: Vec<String> = p
                .argv()
                .iter()
                .map(|a| format!("{:?}", a.to_string_lossy()))
                .collect();
            format!(
                "{i} {}: {}: {}",
                p.target,
                p.what.escape_debug(),
                argv.join(" ")
            )
        }))
        .collect();
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(lines)
}

fn chosen_targets(opts: &Options) -> Result<Vec<(&'static str, targets::Make)>> {
    let mut all: Vec<(&'static str, targets::Make)> = targets::TARGETS.to_vec();
    if opts.python.is_some() {
        all.extend_from_slice(python::TARGETS);
    }
    let chosen: Vec<_> = all
        .into_iter()
        .filter(|(n, _)| {
            opts.only.is_empty() || opts.only.iter().any(|o| n.starts_with(o.as_str()))
        })
        .collect();
    if chosen.is_empty() {
        bail!(
            "no fuzz target starts with {:?} (targets: {}; the `py` ones need a Python)",
            opts.only,
            target_names().join(", ")
        );
    }
    Ok(chosen)
}

/// Fails unless `python` imports `sysid_mpf` (else every Python probe would be a refusal).
fn check_python(python: &Path) -> Result<()> {
    let o = std::process::Command::new(python)
        .args(["-c", "import sysid_mpf"])
        .output()
        .with_context(|| format!("starting {}", python.display()))?;
    if !o.status.success() {
        bail!(
            "{} cannot import sysid_mpf (install it: pip install ./python): {}",
            python.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        );
    }
    Ok(())
}

/// The trees outside a probe's own directory that no probe may change: the seeds and the
/// repository checkout. They are compared after each probe with what they were after the
/// previous one (one walk per probe: the checkout has thousands of files); with several probes
/// at once, a change is reported by the probe that saw it first, and its reproducer tells
/// whether it was the one.
struct Guard {
    seeds: PathBuf,
    repository: PathBuf,
    skip: Vec<PathBuf>,
    last: Mutex<(Snapshot, Snapshot)>,
}

impl Guard {
    fn new(opts: &Options, scratch: &Path, seeds: &Path) -> Result<Self> {
        let repository = std::path::absolute(&opts.repository)?;
        let mut skip = vec![
            repository.join(".git"),
            repository.join("target"),
            scratch.to_path_buf(),
            std::path::absolute(&opts.failures)?,
        ];
        for p in &opts.unguarded {
            skip.push(std::path::absolute(p)?);
        }
        let mut guard = Guard {
            seeds: seeds.to_path_buf(),
            repository,
            skip,
            last: Mutex::new((Snapshot::new(), Snapshot::new())),
        };
        guard.last = Mutex::new(guard.take());
        Ok(guard)
    }

    fn take(&self) -> (Snapshot, Snapshot) {
        (
            snapshot::take(&self.seeds, Depth { hash: true }, &[]),
            snapshot::take(&self.repository, Depth { hash: false }, &self.skip),
        )
    }

    /// What changed in the guarded trees since the last look, one line per path.
    fn changed(&self) -> Vec<String> {
        let now = self.take();
        let mut last = self.last.lock().expect("guard");
        let mut out = Vec::new();
        for (was, is) in [(&last.0, &now.0), (&last.1, &now.1)] {
            out.extend(
                snapshot::changes(was, is)
                    .into_iter()
                    .map(|(path, how)| format!("{} {how}", path.display())),
            );
        }
        *last = now;
        out
    }
}

/// What one probe did.
#[derive(Debug, Clone)]
pub(crate) struct Outcome {
    pub(crate) index: usize,
    pub(crate) target: &'static str,
    pub(crate) what: String,
    pub(crate) ended: Verdict,
    /// Paths written outside the outputs, each with what happened to it.
    pub(crate) stray: Vec<String>,
    pub(crate) took: Duration,
    pub(crate) reproducer: Option<PathBuf>,
}

/// How a probe's program ended, judged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Verdict {
    Accepted,
    /// Refused, with its message line.
    Refused(String),
    Crash(String),
    Hang,
    /// Refused without a message, an unexpected exit status, or a broken promise.
    Unclear(String),
}

struct Runner<'a> {
    opts: &'a Options,
    seeds: &'a seeds::Seeds,
    chosen: &'a [(&'static str, targets::Make)],
    guard: &'a Guard,
    scratch: &'a Path,
}

impl Runner<'_> {
    fn run_all(&self) -> Result<Vec<Outcome>> {
        let next = AtomicUsize::new(0);
        let results = Mutex::new(Vec::with_capacity(self.opts.probes));
        let first_error = Mutex::new(None);
        let step = (self.opts.probes / 10).max(1);
        std::thread::scope(|scope| {
            for _ in 0..self.opts.jobs.max(1) {
                scope.spawn(|| loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= self.opts.probes {
                        break;
                    }
                    match self.one(i) {
                        Ok(o) => {
                            let mut r = results.lock().expect("results");
                            r.push(o);
                            if r.len() % step == 0 {
                                log::info!("fuzz: {} of {} probes", r.len(), self.opts.probes);
                            }
                        }
                        Err(e) => {
                            first_error.lock().expect("error").get_or_insert(e);
                            next.store(self.opts.probes, Ordering::Relaxed);
                        }
                    }
                });
            }
        });
        if let Some(e) = first_error.into_inner().expect("error") {
            return Err(e);
        }
        let mut results = results.into_inner().expect("results");
        results.sort_by_key(|o| o.index);
        Ok(results)
    }

    /// Probe `i`: made from its own random stream, so a seed reproduces every probe.
    fn make(&self, i: usize) -> Probe {
        let (_, make) = self.chosen[i % self.chosen.len()];
        let mut rng = FuzzRng::seed_from_u64(
            self.opts
                .seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add(i as u64),
        );
        let mut p = make(self.seeds, &mut rng);
        hostile::harden(&mut p, &mut rng);
        p
    }

    fn one(&self, i: usize) -> Result<Outcome> {
        let p = self.make(i);
        let root = self.scratch.join("probes").join(format!("p{i}"));
        let capture = self.scratch.join("capture").join(format!("p{i}"));
        std::fs::create_dir_all(&capture)?;
        p.materialise(&root)
            .with_context(|| format!("making probe {i} in {}", root.display()))?;
        let before = snapshot::take(&root, Depth { hash: true }, &[]);
        let ran = exec::run(self.command(&p, &root), self.opts.timeout, &capture)
            .with_context(|| format!("running probe {i}"))?;
        let after = snapshot::take(&root, Depth { hash: true }, &[]);
        let mut stray: Vec<String> = snapshot::changes(&before, &after)
            .into_iter()
            .filter(|(path, _)| !p.may_write(path.strip_prefix(&root).unwrap_or(path)))
            .map(|(path, how)| {
                let shown = path.strip_prefix(&root).unwrap_or(&path);
                format!("{} {how}", shown.display())
            })
            .collect();
        stray.extend(self.guard.changed());
        let ended = judge(&p, &ran);
        let mut outcome = Outcome {
            index: i,
            target: p.target,
            what: p.what.clone(),
            ended,
            stray,
            took: ran.took,
            reproducer: None,
        };
        if report::failed(&outcome) {
            outcome.reproducer = Some(self.reproducer(&p, &outcome, &ran.stderr)?);
            log::warn!("fuzz: {}", report::describe(&outcome));
        }
        let _ = std::fs::remove_dir_all(&root);
        let _ = std::fs::remove_dir_all(&capture);
        Ok(outcome)
    }

    fn program(&self, p: &Probe) -> PathBuf {
        match p.program {
            Program::Sysid => self.opts.sysid.clone(),
            Program::Python => self.opts.python.clone().expect("a Python for its probes"),
        }
    }

    fn command(&self, p: &Probe, root: &Path) -> std::process::Command {
        let mut cmd = std::process::Command::new(self.program(p));
        let path = std::env::var_os("PATH").unwrap_or_default();
        let mut paths = vec![self.seeds.bin.clone()];
        paths.extend(std::env::split_paths(&path));
        cmd.args(p.argv())
            .current_dir(root.join("work"))
            .env("PATH", std::env::join_paths(paths).unwrap_or(path))
            .env("RAYON_NUM_THREADS", "1")
            .env("PYTHONDONTWRITEBYTECODE", "1");
        cmd
    }

    /// Writes the probe's files and a script that runs it under the failures directory.
    fn reproducer(&self, p: &Probe, o: &Outcome, stderr: &str) -> Result<PathBuf> {
        let name = format!("{}-{}", o.index, p.target.replace(' ', "-"));
        let dir = std::path::absolute(self.opts.failures.join(name))?;
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        p.materialise(&dir)?;
        copy_dir(&self.seeds.bin, &dir.join("bin"))?;
        let script = report::command_script(self.opts, p, o, &self.program(p));
        std::fs::write(dir.join("command.sh"), script)?;
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(
            dir.join("command.sh"),
            std::fs::Permissions::from_mode(0o755),
        )?;
        std::fs::write(dir.join("stderr.txt"), stderr)?;
        Ok(dir)
    }
}

fn copy_dir(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to)?;
    for e in std::fs::read_dir(from)? {
        let e = e?;
        std::fs::copy(e.path(), to.join(e.file_name()))?;
    }
    Ok(())
}

/// How the program ended, judged.
fn judge(p: &Probe, ran: &exec::Ran) -> Verdict {
    let panic_line = ran
        .stderr
        .lines()
        .position(|l| l.contains("panicked at") || l.starts_with("panicked:"))
        .map(|i| {
            let lines: Vec<&str> = ran.stderr.lines().skip(i).take(2).collect();
            lines.join(" ")
        });
    match &ran.ended {
        Ended::TimedOut => Verdict::Hang,
        Ended::Signal(libc::SIGPIPE) => Verdict::Unclear("ended by SIGPIPE".into()),
        Ended::Signal(s) => Verdict::Crash(format!("killed by {}", exec::signal_name(*s))),
        Ended::Code(101) => Verdict::Crash(panic_line.unwrap_or_else(|| "exit 101".into())),
        Ended::Code(_) if panic_line.is_some() => Verdict::Crash(panic_line.unwrap_or_default()),
        Ended::Code(0) => Verdict::Accepted,
        Ended::Code(code @ (1 | 2)) => match message(&ran.stderr) {
            Some((_, len)) if len > LONGEST_MESSAGE => Verdict::Unclear(format!(
                "an error message of {len} bytes (an input echoed whole?)"
            )),
            Some((m, _)) => Verdict::Refused(m),
            // `cluster compare` exits 1 when the two outputs differ, and says how.
            None if p.target == "cluster compare" && *code == 1 => {
                Verdict::Refused("the outputs differ".into())
            }
            None => Verdict::Unclear(format!("exit {code} without an error message")),
        },
        Ended::Code(3) if p.program == Program::Python => Verdict::Unclear(
            ran.stderr
                .lines()
                .find(|l| l.starts_with("Broken:"))
                .unwrap_or("a promise broken")
                .to_string(),
        ),
        Ended::Code(code) => Verdict::Unclear(format!("exit {code}")),
    }
}

/// The longest error message a refusal may print (its chain of causes, file names included):
/// a message that quotes a mutated input whole (a line of a million bytes) is no message.
const LONGEST_MESSAGE: usize = 4000;

/// The error line of a refusal — `Error: …` (`sysid`, the Python probes) or clap's
/// `error: …` — cut to 300 characters, and the length of the message from that line on.
fn message(stderr: &str) -> Option<(String, usize)> {
    let at = stderr
        .match_indices('\n')
        .map(|(i, _)| i + 1)
        .chain(std::iter::once(0))
        .filter(|&i| stderr[i..].starts_with("Error:") || stderr[i..].starts_with("error:"))
        .min()?;
    let line = stderr[at..].lines().next().unwrap_or("");
    Some((line.chars().take(300).collect(), stderr.len() - at))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ran(ended: Ended, stderr: &str) -> exec::Ran {
        exec::Ran {
            ended,
            stderr: stderr.into(),
            took: Duration::from_millis(5),
        }
    }

    #[test]
    fn crashes_hangs_refusals_and_unclear_ends_are_told_apart() {
        let p = Probe::new("filter", Program::Sysid);
        let judged = |e: Ended, s: &str| judge(&p, &ran(e, s));
        assert_eq!(judged(Ended::Code(0), "done"), Verdict::Accepted);
        assert_eq!(
            judged(
                Ended::Code(1),
                "log line\nError: d/measured.csv:3: field `a1`\n"
            ),
            Verdict::Refused("Error: d/measured.csv:3: field `a1`".into())
        );
        assert_eq!(
            judged(Ended::Code(2), "error: unexpected argument\n"),
            Verdict::Refused("error: unexpected argument".into())
        );
        assert!(matches!(
            judged(Ended::Code(101), "thread 'main' panicked at src/x.rs:1:1:\ncapacity overflow"),
            Verdict::Crash(m) if m.contains("capacity overflow")
        ));
        // A panic caught and turned into an error is a crash still.
        assert!(matches!(
            judged(
                Ended::Code(1),
                "thread 'w' panicked at a.rs:2:3:\nboom\nError: failed"
            ),
            Verdict::Crash(_)
        ));
        assert_eq!(
            judged(Ended::Signal(libc::SIGABRT), "memory allocation failed"),
            Verdict::Crash("killed by SIGABRT".into())
        );
        assert_eq!(judged(Ended::TimedOut, ""), Verdict::Hang);
        assert!(matches!(
            judged(Ended::Code(1), "nothing said"),
            Verdict::Unclear(_)
        ));
        let long = format!("Error: x.csv:2: field `a`: `{}`", "[".repeat(10_000));
        assert!(
            matches!(judged(Ended::Code(1), &long), Verdict::Unclear(m) if m.contains("bytes"))
        );
        // `cluster compare` says that two outputs differ by its exit status.
        let c = Probe::new("cluster compare", Program::Sysid);
        assert!(matches!(
            judge(&c, &ran(Ended::Code(1), "differ: a.json")),
            Verdict::Refused(_)
        ));
        let py = Probe::new("py records", Program::Python);
        assert!(matches!(
            judge(&py, &ran(Ended::Code(3), "Broken: wrote 5 samples, read back 4")),
            Verdict::Unclear(m) if m.starts_with("Broken")
        ));
        assert!(matches!(
            judge(&py, &ran(Ended::Code(101), "panicked: capacity overflow")),
            Verdict::Crash(_)
        ));
    }
}
