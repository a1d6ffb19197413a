//! A study of one real structure from its recordings (`experiments/real/study.toml`,
//! `results/real/REPORT.md`): import every record, identify model variants on the record every
//! choice is made on, predict the records kept out of every choice (cross-validation), select a
//! variant by its likelihood, identify the selected model on every record to see whether their
//! intervals agree, and set the toolkit beside a black-box baseline (SRIM, by the PyPI package
//! `mdof`).
//!
//! The study is a description (this module's `FieldStudy`, a TOML file) turned into the
//! `sysid` commands a user would type (`plan_identify`, `plan_validate`); `run` executes them in
//! this process through the entry it is given (`StepRunner`: the command line's own), so every
//! number of the report comes from the same commands as a user's and from their records, and
//! every step's text is in its log. The report is drawn from those records only
//! ([`report`]).

pub mod report;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::console::Console;

use crate::error::{bail, Context, Result};
use identify::record::fingerprint::hex;
use serde::Deserialize;
use sha2::{Digest, Sha256};

use identify::pipeline::Algorithm;
use identify::record::RunRecord;

/// The whole study: its parts (one structure each).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FieldStudy {
    pub title: String,
    pub part: Vec<Part>,
}

/// One structure and its records.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Part {
    /// Directory name under the output (`results/real/<name>`).
    pub name: String,
    pub title: String,
    /// Prose for the report: the structure, the model and what is asked of it.
    pub about: String,
    pub record: Vec<RecordSpec>,
    /// Arguments of every `sysid filter` of this part (the structure, the measurement).
    #[serde(default)]
    pub common: Vec<String>,
    pub variant: Vec<Variant>,
    #[serde(default)]
    pub selection: Option<Selection>,
    /// Whether the part has the black-box baseline (`<out>/<part>/srim.json`, written by
    /// `experiments/real/srim.py`).
    #[serde(default)]
    pub baseline: bool,
    /// The baseline's model orders (`--orders` of the script; absent: its default, 6–16, for
    /// three storeys — a one-storey structure wants 2–8).
    #[serde(default)]
    pub baseline_orders: Option<Vec<usize>>,
    /// The baseline's horizon (`--horizon` of the script; absent: mdof's default, 300, which
    /// finds no stable model of a record sampled far above its modes, e.g. a 3 Hz bent at 200 Hz).
    #[serde(default)]
    pub baseline_horizon: Option<usize>,
}

/// A recording of the structure, imported by `sysid import --map`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RecordSpec {
    pub name: String,
    /// Channel map, relative to the study file.
    pub map: PathBuf,
    pub role: Role,
}

/// What a record is used for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum Role {
    /// Every choice of the study (variants, selection, priors) is made on this record.
    Identify,
    /// Kept out of every choice: predicted only (cross-validation) and identified again with
    /// the selected model to compare intervals.
    Validate,
}

/// One model and algorithm identified on the identification record.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Variant {
    /// File stem of its record (`records/<name>.json`).
    pub name: String,
    pub label: String,
    pub algorithm: Algorithm,
    /// Arguments of `sysid filter` after the part's `common` ones; a flag given here replaces the
    /// same flag of `common`.
    #[serde(default)]
    pub args: Vec<String>,
    /// Variants of one group are candidates of the [`Selection`].
    #[serde(default)]
    pub group: Option<String>,
}

/// Selection of a variant by the filter's log-likelihood of the identification record (a
/// profile likelihood over what the filter does not identify itself, e.g. mass ratios); the
/// selected variant is then identified on every other record.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Selection {
    pub group: String,
    /// Extra arguments for the identifications on the other records (e.g. the prior scaled from
    /// the identification record, written out in a config file).
    #[serde(default)]
    pub other_args: Vec<String>,
}

impl FieldStudy {
    /// Reads and checks a study file; paths in it are made relative to its directory.
    pub fn load(path: &Path) -> Result<Self> {
        let text = identify::limits::read_text_file(path, "study")?;
        let mut s: FieldStudy = identify::limits::parse_toml(&text, path, "field study")?;
        let base = path.parent().unwrap_or(Path::new("."));
        for p in &mut s.part {
            for r in &mut p.record {
                r.map = base.join(&r.map);
            }
            // A config file named in the arguments is relative to the study file too.
            for args in std::iter::once(&mut p.common)
                .chain(p.variant.iter_mut().map(|v| &mut v.args))
                .chain(p.selection.iter_mut().map(|s| &mut s.other_args))
            {
                for i in 1..args.len() {
                    if args[i - 1] == "--config" {
                        args[i] = base.join(&args[i]).display().to_string();
                    }
                }
            }
        }
        s.check()
            .map_err(|e| crate::error::invalid!("{}: {e}", path.display()))?;
        Ok(s)
    }

    fn check(&self) -> std::result::Result<(), String> {
        let mut parts = BTreeSet::new();
        for p in &self.part {
            if !is_stem(&p.name) || !parts.insert(&p.name) {
                return Err(format!(
                    "part `{}`: a unique name of [a-z0-9-] is needed",
                    p.name
                ));
            }
            let mut names = BTreeSet::new();
            for r in &p.record {
                if !is_stem(&r.name) || !names.insert(r.name.as_str()) {
                    return Err(format!(
                        "part `{}`, record `{}`: a unique name of [a-z0-9.-] is needed",
                        p.name, r.name
                    ));
                }
            }
            let identify: Vec<_> = p
                .record
                .iter()
                .filter(|r| r.role == Role::Identify)
                .collect();
            if identify.len() != 1 {
                return Err(format!(
                    "part `{}`: exactly one record has role = \"identify\" ({} found)",
                    p.name,
                    identify.len()
                ));
            }
            let mut variants = BTreeSet::new();
            for v in &p.variant {
                if !is_stem(&v.name) || !variants.insert(v.name.as_str()) || v.name.contains("--") {
                    return Err(format!(
                        "part `{}`, variant `{}`: a unique name of [a-z0-9.-] (no `--`) is needed",
                        p.name, v.name
                    ));
                }
                for flag in ["--algorithm", "--data", "--out"] {
                    if v.args.iter().chain(&p.common).any(|a| a == flag) {
                        return Err(format!(
                            "part `{}`, variant `{}`: {flag} is set by the study, not in args",
                            p.name, v.name
                        ));
                    }
                }
            }
            if let Some(s) = &p.selection {
                if !p
                    .variant
                    .iter()
                    .any(|v| v.group.as_deref() == Some(s.group.as_str()))
                {
                    return Err(format!(
                        "part `{}`: selection group `{}` has no variant",
                        p.name, s.group
                    ));
                }
            }
        }
        Ok(())
    }
}

fn is_stem(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '.')
        && !s.starts_with('.')
}

impl Part {
    /// The identification record.
    pub(crate) fn identify_record(&self) -> &RecordSpec {
        self.record
            .iter()
            .find(|r| r.role == Role::Identify)
            .expect("checked on load")
    }

    /// The records kept out of every choice.
    pub(crate) fn validate_records(&self) -> impl Iterator<Item = &RecordSpec> {
        self.record.iter().filter(|r| r.role == Role::Validate)
    }
}

/// Where a part's files go.
#[derive(Debug, Clone)]
pub(crate) struct PartDirs {
    pub root: PathBuf,
}

impl PartDirs {
    pub fn new(out: &Path, part: &Part) -> Self {
        Self {
            root: out.join(&part.name),
        }
    }
    /// Imported data sets (regenerated from the maps; not tracked).
    pub fn data(&self, record: &str) -> PathBuf {
        self.root.join("data").join(record)
    }
    pub fn record(&self, variant: &str) -> PathBuf {
        self.root.join("records").join(format!("{variant}.json"))
    }
    /// The selected model identified on `record`.
    pub(crate) fn selected_record(&self, record: &str) -> PathBuf {
        self.root
            .join("records")
            .join(format!("selected--{record}.json"))
    }
    pub fn validation(&self, variant: &str, record: &str) -> PathBuf {
        self.root
            .join("validation")
            .join(format!("{variant}--{record}.json"))
    }
    pub fn figures(&self, variant: &str) -> PathBuf {
        self.root.join("figures").join(variant)
    }
    /// Settings and prior of the selected run, for the other records.
    pub(crate) fn selected_settings(&self) -> PathBuf {
        self.root.join("selected-settings.toml")
    }
    /// The baseline's result.
    pub fn baseline(&self) -> PathBuf {
        self.root.join("srim.json")
    }
    pub fn log(&self, name: &str) -> PathBuf {
        self.root.join("logs").join(format!("{name}.txt"))
    }
}

/// One `sysid` command of the study and the file it writes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Step {
    pub args: Vec<String>,
    pub writes: PathBuf,
    /// Log of the command's output (stdout and stderr), kept beside the records.
    pub log: PathBuf,
    /// A step whose file is missing stops the study (an import); otherwise the report says why
    /// the file is missing (a cross-validation of a physically impossible model is refused).
    pub required: bool,
    /// The directory of the figures drawn from the record the step writes (`sysid filter
    /// --plot`); on resume they are drawn again from the kept record.
    pub figures: Option<PathBuf>,
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// The imports and the identifications on the identification record (every variant).
pub(crate) fn plan_identify(part: &Part, dirs: &PartDirs) -> Vec<Step> {
    let mut steps: Vec<Step> = part
        .record
        .iter()
        .map(|r| Step {
            args: vec![
                "import".into(),
                "--map".into(),
                s(&r.map),
                "--out".into(),
                s(&dirs.data(&r.name)),
            ],
            writes: dirs.data(&r.name).join(models::dataset::MEASURED),
            log: dirs.log(&format!("import--{}", r.name)),
            required: true,
            figures: None,
        })
        .collect();
    let train = part.identify_record();
    for v in &part.variant {
        steps.push(filter_step(
            part,
            dirs,
            FilterCall {
                algorithm: v.algorithm,
                args: &v.args,
                record: &train.name,
                out: &dirs.record(&v.name),
                plot: Some(&dirs.figures(&v.name)),
                log: &v.name,
            },
        ));
    }
    steps
}

/// The part's `common` flags followed by a variant's `args`, a flag of `args` replacing the
/// same flag of `common` with its values (`--particles 2000` in a variant overrides the part's
/// `--particles 500`: `sysid filter` takes each flag once).
fn with_overrides(common: &[String], args: &[String]) -> Vec<String> {
    // Groups of a flag and the values after it, up to the next flag.
    fn groups(a: &[String]) -> Vec<&[String]> {
        let mut out = Vec::new();
        let mut start = 0;
        for i in 1..=a.len() {
            if i == a.len() || a[i].starts_with("--") {
                out.push(&a[start..i]);
                start = i;
            }
        }
        out.retain(|g| !g.is_empty());
        out
    }
    let overridden: Vec<&String> = groups(args).iter().map(|g| &g[0]).collect();
    groups(common)
        .into_iter()
        .filter(|g| !overridden.contains(&&g[0]))
        .flatten()
        .chain(args)
        .cloned()
        .collect()
}

/// One `sysid filter` call of a part: the algorithm and its flags (laid over the part's
/// `common` ones), the record it identifies, where its run record (and figures) go, its log.
struct FilterCall<'a> {
    algorithm: Algorithm,
    args: &'a [String],
    record: &'a str,
    out: &'a Path,
    plot: Option<&'a Path>,
    log: &'a str,
}

fn filter_step(part: &Part, dirs: &PartDirs, call: FilterCall) -> Step {
    let FilterCall {
        algorithm,
        args,
        record,
        out,
        plot,
        log,
    } = call;
    let mut a: Vec<String> = vec![
        "filter".into(),
        "--algorithm".into(),
        algorithm.name().into(),
        "--data".into(),
        s(&dirs.data(record)),
    ];
    a.extend(with_overrides(&part.common, args));
    a.extend(["--out".into(), s(out)]);
    if let Some(p) = plot {
        a.extend(["--plot".into(), s(p)]);
    }
    Step {
        args: a,
        writes: out.to_path_buf(),
        log: dirs.log(log),
        required: true,
        figures: plot.map(Path::to_path_buf),
    }
}

/// Cross-validation of every variant on every record kept out of the choices.
pub(crate) fn plan_validate(part: &Part, dirs: &PartDirs) -> Vec<Step> {
    let mut steps = Vec::new();
    for v in &part.variant {
        for r in part.validate_records() {
            let out = dirs.validation(&v.name, &r.name);
            steps.push(Step {
                args: vec![
                    "validate".into(),
                    "--record".into(),
                    s(&dirs.record(&v.name)),
                    "--data".into(),
                    s(&dirs.data(&r.name)),
                    "--out".into(),
                    s(&out),
                ],
                writes: out,
                log: dirs.log(&format!("validate--{}--{}", v.name, r.name)),
                required: false,
                figures: None,
            });
        }
    }
    steps
}

/// The selected variant (largest log-likelihood among the group's completed, physically
/// possible runs) and why; `None` when no candidate qualifies.
pub(crate) fn select<'a>(
    part: &'a Part,
    dirs: &PartDirs,
) -> Result<Option<(&'a Variant, RunRecord)>> {
    let Some(sel) = &part.selection else {
        return Ok(None);
    };
    let mut best: Option<(&Variant, RunRecord)> = None;
    for v in part
        .variant
        .iter()
        .filter(|v| v.group.as_deref() == Some(sel.group.as_str()))
    {
        let path = dirs.record(&v.name);
        if !path.exists() {
            continue;
        }
        let r: RunRecord = identify::record::read::read(&path)?;
        if r.failure.is_some() || identify::checks::is_fatal(&r.warnings) {
            continue;
        }
        if best.as_ref().is_none_or(|(_, b)| r.loglik > b.loglik) {
            best = Some((v, r));
        }
    }
    Ok(best)
}

/// The settings of the selected run with its prior (the one scaled from the identification
/// record) written out, so that the other records are identified from the same prior rather
/// than one scaled from each of them (`--config` of [`plan_selected`]).
pub(crate) fn write_selected_settings(dirs: &PartDirs, selected: &RunRecord) -> Result<PathBuf> {
    let mut settings: identify::settings::FilterSettings =
        serde_json::from_value(selected.config["filter"].clone())
            .context("the selected record's filter settings")?;
    settings.prior = Some(
        serde_json::from_value(selected.config["spec"]["prior"].clone())
            .context("the selected record's prior")?,
    );
    let text = toml::to_string(&settings).context("writing the settings as TOML")?;
    let path = dirs.selected_settings();
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d)?;
    }
    identify::record::atomic::write_bytes_atomic(
        &path,
        format!(
            "# The settings and prior of the selected run on the identification record (written by\n\
             # sysid field-study): the other records are identified from this prior.\n{text}"
        )
        .as_bytes(),
    )?;
    Ok(path)
}

/// The selected variant identified on every other record, with the identification record's
/// settings and prior ([`write_selected_settings`]).
pub(crate) fn plan_selected(part: &Part, dirs: &PartDirs, chosen: &Variant) -> Vec<Step> {
    let mut extra: Vec<String> = vec!["--config".into(), s(&dirs.selected_settings())];
    extra.extend(
        part.selection
            .as_ref()
            .map(|s| s.other_args.clone())
            .unwrap_or_default(),
    );
    part.validate_records()
        .map(|r| {
            let mut args = chosen.args.clone();
            args.extend(extra.iter().cloned());
            let out = dirs.selected_record(&r.name);
            filter_step(
                part,
                dirs,
                FilterCall {
                    algorithm: chosen.algorithm,
                    args: &args,
                    record: &r.name,
                    out: &out,
                    plot: None,
                    log: &format!("selected--{}", r.name),
                },
            )
        })
        .collect()
}

/// How a step ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Ended {
    /// Exit 0.
    Ok,
    /// Non-zero exit, file written (a run whose answer is physically impossible writes its
    /// record and exits 1): the report shows why.
    Flagged,
    /// No file (allowed for a step that is not required): the log's last error line.
    Refused(String),
}

/// The error a log ends with (from its last line starting with `Error`, causes joined), or its
/// last line.
pub(crate) fn log_reason(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    match lines.iter().rposition(|l| l.starts_with("Error")) {
        Some(i) => lines[i..]
            .iter()
            .map(|l| l.trim())
            .filter(|l| !l.is_empty() && *l != "Caused by:")
            .map(|l| l.trim_start_matches("Error: "))
            .map(|l| {
                l.trim_start_matches(|c: char| c.is_ascii_digit() || c == ':')
                    .trim()
            })
            .collect::<Vec<_>>()
            .join(": "),
        None => lines.last().unwrap_or(&"no output").trim().to_string(),
    }
}

/// Runs one step's command in this process: `args` as a user types them after `sysid`
/// (`import …`, `filter …`, `validate …`), the command's text to the console. The command-line
/// layer gives it (`sysid field-study` passes the entry its own subcommands run through), so a
/// step runs the very code a user's command runs, with no second process.
pub(crate) type StepRunner = fn(&[String], &mut Console) -> Result<()>;

/// Runs `step` through `run_step`; the command's text, the library's log lines while it runs
/// and the error it ends with (as `sysid` prints it) go to the step's log. A required step that
/// wrote nothing is an error. A panic of the command is caught and ends the step like an
/// error, so that one step cannot take the study down without a word in its log.
pub(crate) fn execute(run_step: StepRunner, step: &Step) -> Result<Ended> {
    for p in [&step.writes, &step.log] {
        if let Some(d) = p.parent() {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
    }
    if step.writes.exists() {
        std::fs::remove_file(&step.writes)
            .with_context(|| format!("removing the old {}", step.writes.display()))?;
    }
    let log = std::fs::File::create(&step.log)
        .with_context(|| format!("creating {}", step.log.display()))?;
    let mut con = Console::log_file(log.try_clone()?)?;
    writeln!(con.err(), "sysid {}", step.args.join(" "))?;
    let outcome = {
        let _diverted = identify::logger::divert(Box::new(log));
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_step(&step.args, &mut con)
        }))
    };
    let failure = match outcome {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(e),
        Err(panic) => Some(crate::error::invalid!(
            "internal error (a bug, please report it): {}",
            panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("a panic without a message")
        )),
    };
    if let Some(e) = &failure {
        con.error(e)?;
    }
    drop(con);
    if !step.writes.exists() && !step.required {
        return Ok(Ended::Refused(log_reason(&step.log)));
    }
    if !step.writes.exists() {
        bail!(
            "`sysid {}` wrote no {} ({}); its output is in {}",
            step.args.join(" "),
            step.writes.display(),
            failure.map_or("no error".into(), |e| format!("{e:#}")),
            step.log.display()
        );
    }
    Ok(if failure.is_none() {
        Ended::Ok
    } else {
        Ended::Flagged
    })
}

/// The part's black-box baseline: computed by the baseline script where a Python with `mdof` is
/// given, else the committed file used (or none); the note the study ends with says which (none
/// for a part without a baseline).
fn baseline(part: &Part, dirs: &PartDirs, opts: &RunOptions) -> Result<Option<String>> {
    let baseline = dirs.baseline();
    if let (true, Some(python), Some(script)) = (part.baseline, &opts.python, &opts.baseline_script)
    {
        let train = dirs.data(&part.identify_record().name);
        let mut cmd = Command::new(python);
        cmd.arg(script).arg("--train").arg(&train);
        // A structure of one record has none to validate on (and the command says none).
        if part.validate_records().next().is_some() {
            cmd.arg("--validate");
            for r in part.validate_records() {
                cmd.arg(dirs.data(&r.name));
            }
        }
        cmd.arg("--out").arg(&baseline);
        if let Some(orders) = &part.baseline_orders {
            let list: Vec<String> = orders.iter().map(usize::to_string).collect();
            cmd.arg("--orders").arg(list.join(","));
        }
        if let Some(h) = part.baseline_horizon {
            cmd.arg("--horizon").arg(h.to_string());
        }
        let status = cmd
            .status()
            .with_context(|| format!("starting {}", python.display()))?;
        if !status.success() {
            bail!("the baseline script failed ({status}): {cmd:?}");
        }
        Ok(Some(format!(
            "{}: baseline recomputed ({})",
            part.name,
            baseline.display()
        )))
    } else if part.baseline && baseline.exists() {
        Ok(Some(format!(
            "{}: baseline as committed in {} (not recomputed: no Python with mdof given)",
            part.name,
            baseline.display()
        )))
    } else if part.baseline {
        Ok(Some(format!(
            "{}: no baseline: {} is absent and no Python with mdof was given (--python), so \
             the report compares with none (copy a computed srim.json there, or pass --python)",
            part.name,
            baseline.display()
        )))
    } else {
        Ok(None)
    }
}

/// On resume, a step whose record is kept has its figures drawn again from that record
/// (`identify::plot::plot`, which puts each figure in place atomically): a figure cut short, a
/// missing one or a lost figure directory of an interrupted study is not carried on. `false`
/// when the kept record does not read back or cannot be drawn: the step is then run again.
fn kept_figures_redrawn(step: &Step) -> bool {
    let Some(dir) = &step.figures else {
        return true;
    };
    match identify::plot::plot(&step.writes, dir) {
        Ok(_) => true,
        Err(e) => {
            log::info!(
                "{}: not kept ({e:#}); computing it again",
                step.writes.display()
            );
            false
        }
    }
}

/// SHA-256 of the running program's file: a step's output kept on resume was computed by this
/// very build ([`inputs_digest`]). A program file that cannot be read gives a digest no earlier
/// one matches, so nothing is kept rather than something of another build.
fn this_binary() -> String {
    match std::env::current_exe().and_then(std::fs::read) {
        Ok(bytes) => hex(&Sha256::digest(&bytes)),
        Err(e) => {
            log::info!("the program's own file cannot be read ({e}): --resume keeps nothing");
            format!("unreadable-{}", std::process::id())
        }
    }
}

/// The files a step's command reads, from its arguments: every file of a `--data` directory,
/// the `--record`, `--config` and `--map` files, and the files a map names — the bytes its
/// output is computed from.
fn inputs_of(step: &Step) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for pair in step.args.windows(2) {
        let path = Path::new(&pair[1]);
        match pair[0].as_str() {
            "--data" if path.is_dir() => {
                let mut in_dir: Vec<PathBuf> = std::fs::read_dir(path)
                    .with_context(|| format!("reading {}", path.display()))?
                    .flatten()
                    .map(|e| e.path())
                    .filter(|p| p.is_file())
                    .collect();
                in_dir.sort();
                files.extend(in_dir);
            }
            "--record" | "--config" | "--data" => files.push(path.to_path_buf()),
            "--map" => {
                files.push(path.to_path_buf());
                files.extend(files_named_by_map(path));
            }
            _ => {}
        }
    }
    Ok(files)
}

/// The files a map names, resolved as the import resolves them (`ChannelMap::load`, the
/// import's own reader of maps); none when the map does not load (the import then says why).
fn files_named_by_map(map: &Path) -> Vec<PathBuf> {
    models::import::channel_map::ChannelMap::load(map).map_or_else(
        |_| Vec::new(),
        |m| {
            std::iter::once(m.ground.path)
                .chain(m.storeys.into_iter().map(|c| c.path))
                .collect()
        },
    )
}

/// What a step's output is computed from, as one SHA-256: the program (`binary`, from
/// [`this_binary`]), the command's arguments and the bytes of every file it reads
/// ([`inputs_of`]), each read as the step reads it (`models::readers::read_input`: a regular file
/// within the size limit — a device, a named pipe or an absent file enters as the reader's error,
/// which the step itself then reports, and is never read forever). A step whose input was computed again in this run
/// (a new record: its timings alone change its bytes) therefore has a new digest, and so has
/// every step after an import of changed data or a rebuilt program: on resume those are computed
/// again, never kept beside inputs they were not computed from.
fn inputs_digest(step: &Step, binary: &str) -> Result<String> {
    let mut h = Sha256::new();
    h.update(binary.as_bytes());
    for a in &step.args {
        h.update((a.len() as u64).to_le_bytes());
        h.update(a.as_bytes());
    }
    for f in inputs_of(step)? {
        h.update(f.to_string_lossy().as_bytes());
        match models::readers::read_input(&f) {
            Ok(bytes) => {
                h.update((bytes.len() as u64).to_le_bytes());
                h.update(&bytes);
            }
            Err(e) => h.update(format!("unread: {e}").as_bytes()),
        }
    }
    Ok(hex(&h.finalize()))
}

/// Where the digest of what a step's output was computed from is kept: beside its log.
fn inputs_file(step: &Step) -> PathBuf {
    step.log.with_extension("inputs")
}

/// Whether a step's output is kept on resume: it exists and was computed from `inputs` (the
/// digest recorded when it was written equals the step's digest now). An output without a
/// recorded digest — cut off between the two, or written before digests were kept — is
/// computed again.
fn kept(step: &Step, inputs: &str) -> bool {
    let same = step.writes.exists()
        && std::fs::read_to_string(inputs_file(step)).is_ok_and(|d| d.trim() == inputs);
    if step.writes.exists() && !same {
        log::info!(
            "{}: computed from other inputs or by another build; computing it again",
            step.writes.display()
        );
    }
    same
}

/// Records the digest of what `step`'s output was just computed from (after the output itself:
/// an interruption between the two leaves an output that is computed again).
fn record_inputs(step: &Step, inputs: &str) -> Result<()> {
    let path = inputs_file(step);
    if step.writes.exists() {
        identify::record::atomic::write_bytes_atomic(&path, format!("{inputs}\n").as_bytes())
            .with_context(|| format!("writing {}", path.display()))
    } else if path.exists() {
        std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))
    } else {
        Ok(())
    }
}

/// Copies the figure `from` to `to` atomically when it is a complete SVG document; otherwise
/// removes `to`, so that no figure of an earlier run stands in for a missing one.
fn copy_figure(from: &Path, to: &Path) -> Result<()> {
    if from.is_file() && identify::figures::validate_svg(from).is_ok() {
        let bytes = std::fs::read(from).with_context(|| format!("reading {}", from.display()))?;
        identify::record::atomic::write_bytes_atomic(to, &bytes)
            .with_context(|| format!("copying {} to {}", from.display(), to.display()))?;
    } else if to.is_file() {
        std::fs::remove_file(to).with_context(|| format!("removing {}", to.display()))?;
    }
    Ok(())
}

/// Options of [`run`].
#[derive(Debug, Clone)]
pub(crate) struct RunOptions {
    /// Runs each step's command ([`StepRunner`]).
    pub run_step: StepRunner,
    pub out: PathBuf,
    /// A Python interpreter with `mdof` (and numpy) to recompute the baseline; without it the
    /// baseline file of the study is used as committed.
    pub python: Option<PathBuf>,
    /// The baseline script (`experiments/real/srim.py`).
    pub baseline_script: Option<PathBuf>,
    /// Keep the files already written (an interrupted study; every file is written atomically,
    /// so one that exists is complete) instead of recomputing them — each only where what it
    /// was computed from is unchanged ([`inputs_digest`]).
    pub resume: bool,
}

/// Runs every part of the study and writes `REPORT.md` into `out`.
pub(crate) fn run(study: &FieldStudy, opts: &RunOptions) -> Result<()> {
    let started = std::time::Instant::now();
    let binary = this_binary();
    let mut notes = Vec::new();
    for part in &study.part {
        let dirs = PartDirs::new(&opts.out, part);
        let mut steps = plan_identify(part, &dirs);
        steps.extend(plan_validate(part, &dirs));
        let total = steps.len();
        for (i, step) in steps.iter().enumerate() {
            let inputs = inputs_digest(step, &binary)?;
            if opts.resume && kept(step, &inputs) && kept_figures_redrawn(step) {
                log::info!(
                    "[{}/{total}] {}: kept {}",
                    i + 1,
                    part.name,
                    step.writes.display()
                );
                continue;
            }
            let t = std::time::Instant::now();
            let ended = execute(opts.run_step, step)?;
            record_inputs(step, &inputs)?;
            log::info!(
                "[{}/{total}] {}: sysid {} → {} ({:.1} s){}",
                i + 1,
                part.name,
                step.args[0],
                step.writes.display(),
                t.elapsed().as_secs_f64(),
                match ended {
                    Ended::Ok => String::new(),
                    Ended::Flagged => ": non-zero exit, see the report".into(),
                    Ended::Refused(why) => format!(": refused: {why}"),
                }
            );
        }
        if let Some((chosen, record)) = select(part, &dirs)? {
            log::info!(
                "{}: selected `{}` (largest log-likelihood of its group)",
                part.name,
                chosen.name
            );
            write_selected_settings(&dirs, &record)?;
            // The selected model's validation figures are kept beside the report (the records
            // and the other figures are large and regenerated by the study).
            for fig in ["free_run.svg", "transfer.svg"] {
                copy_figure(
                    &dirs.figures(&chosen.name).join(fig),
                    &dirs.root.join(format!("selected-{fig}")),
                )?;
            }
            for step in plan_selected(part, &dirs, chosen) {
                let inputs = inputs_digest(&step, &binary)?;
                if opts.resume && kept(&step, &inputs) {
                    continue;
                }
                let ended = execute(opts.run_step, &step)?;
                record_inputs(&step, &inputs)?;
                log::info!(
                    "{}: sysid filter → {} ({ended:?})",
                    part.name,
                    step.writes.display()
                );
            }
        }
        notes.extend(baseline(part, &dirs, opts)?);
    }
    let text = report::render(study, &opts.out)?;
    let path = opts.out.join("REPORT.md");
    identify::record::atomic::write_bytes_atomic(&path, text.as_bytes())?;
    for n in notes {
        log::info!("{n}");
    }
    log::info!(
        "field study: {:.0} s; report {}",
        started.elapsed().as_secs_f64(),
        path.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const STUDY: &str = r#"
title = "t"
[[part]]
name = "frame"
title = "f"
about = "a"
common = ["--storeys", "3", "--config", "prior.toml"]
[[part.record]]
name = "northridge"
map = "m1.toml"
role = "identify"
[[part.record]]
name = "sine-2.0"
map = "m2.toml"
role = "validate"
[[part.variant]]
name = "mpf"
label = "MPF-EKF2"
algorithm = "mpf-ekf2"
args = ["--masses", "1"]
group = "g"
[part.selection]
group = "g"
"#;

    fn load(text: &str) -> Result<FieldStudy> {
        // One directory per call (the tests run in parallel threads of one process), removed
        // when the study is loaded: loading reads no other file.
        let dir = tempfile::Builder::new().prefix("field-study-").tempdir()?;
        let path = dir.path().join("study.toml");
        std::fs::write(&path, text)?;
        FieldStudy::load(&path)
    }

    #[test]
    fn a_maps_inputs_are_its_files_as_the_import_reads_them() {
        let map = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../experiments/real/frame-bonus-event.toml");
        let files = files_named_by_map(&map);
        let names: Vec<String> = files
            .iter()
            .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        // The ground, then storeys 1–3 (floor-2.csv is storey 1 on this day: the map says why).
        assert_eq!(
            names,
            ["ground.csv", "floor-2.csv", "floor-1.csv", "floor-3.csv"]
        );
        assert!(files.iter().all(|f| f.is_file()), "{files:?}");
        assert!(files_named_by_map(Path::new("no-such-map.toml")).is_empty());
    }

    #[test]
    fn plans_the_commands_a_user_would_type() {
        let s = load(STUDY).unwrap();
        let part = &s.part[0];
        let dirs = PartDirs::new(Path::new("out"), part);
        let steps = plan_identify(part, &dirs);
        assert_eq!(steps.len(), 3);
        assert_eq!(steps[0].args[0], "import");
        assert!(steps[0].args[2].ends_with("m1.toml"));
        let f = &steps[2].args;
        assert_eq!(
            &f[..5],
            [
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--data",
                "out/frame/data/northridge"
            ]
        );
        // The config of `common` is taken from the study file's directory.
        let c = f.iter().position(|a| a == "--config").unwrap();
        assert!(Path::new(&f[c + 1]).is_absolute() || f[c + 1].contains("field-study-"));
        assert!(f
            .windows(2)
            .any(|w| w == ["--out", "out/frame/records/mpf.json"]));
        let v = plan_validate(part, &dirs);
        assert_eq!(v.len(), 1);
        assert_eq!(
            v[0].writes,
            Path::new("out/frame/validation/mpf--sine-2.0.json")
        );
        let sel = plan_selected(part, &dirs, &part.variant[0]);
        assert_eq!(
            sel[0].writes,
            Path::new("out/frame/records/selected--sine-2.0.json")
        );
    }

    #[test]
    fn a_variants_flag_replaces_the_parts_common_one() {
        let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let common = v(&[
            "--storeys",
            "3",
            "--particles",
            "500",
            "--masses",
            "1",
            "2",
            "3",
        ]);
        assert_eq!(
            with_overrides(&common, &v(&["--particles", "2000", "--substeps", "1"])),
            v(&[
                "--storeys",
                "3",
                "--masses",
                "1",
                "2",
                "3",
                "--particles",
                "2000",
                "--substeps",
                "1"
            ])
        );
        assert_eq!(with_overrides(&common, &[]), common);
        let s = load(&STUDY.replacen(
            "args = [\"--masses\", \"1\"]",
            "args = [\"--storeys\", \"4\"]",
            1,
        ))
        .unwrap();
        let f = &plan_identify(&s.part[0], &PartDirs::new(Path::new("out"), &s.part[0]))[2].args;
        assert_eq!(f.iter().filter(|a| *a == "--storeys").count(), 1);
        assert!(f.windows(2).any(|w| w == ["--storeys", "4"]));
    }

    #[test]
    fn refuses_a_study_it_cannot_run() {
        for (from, to, why) in [
            (
                "role = \"identify\"",
                "role = \"validate\"",
                "exactly one record",
            ),
            (
                "args = [\"--masses\", \"1\"]",
                "args = [\"--out\", \"x\"]",
                "--out is set by the study",
            ),
            (
                "[part.selection]\ngroup = \"g\"",
                "[part.selection]\ngroup = \"h\"",
                "selection group `h`",
            ),
            ("name = \"mpf\"", "name = \"a--b\"", "variant `a--b`"),
            (
                "algorithm = \"mpf-ekf2\"",
                "algorithm = \"kalman\"",
                "unknown variant",
            ),
            (
                "title = \"f\"",
                "title = \"f\"\ncolour = 1",
                "unknown field",
            ),
        ] {
            let e = load(&STUDY.replacen(from, to, 1)).unwrap_err();
            let msg = format!("{e:#}");
            assert!(msg.contains(why), "{msg}");
        }
    }

    fn step(dir: &Path, required: bool) -> Step {
        Step {
            args: vec!["filter".into(), "--data".into(), "d".into()],
            writes: dir.join("records/r.json"),
            log: dir.join("logs/r.txt"),
            required,
            figures: None,
        }
    }

    fn writes_and_says(args: &[String], con: &mut Console) -> Result<()> {
        writeln!(con.out(), "summary of {}", args[0])?;
        log::info!("a line of the library's log");
        std::fs::write(
            Path::new(&args[2]).parent().unwrap().join("records/r.json"),
            "{}",
        )?;
        Ok(())
    }

    fn refuses(_: &[String], con: &mut Console) -> Result<()> {
        writeln!(con.err(), "note: looked at it")?;
        Err(crate::error::Error::from(std::io::Error::other("the disk")))
            .context("reading the data set d")
    }

    fn panics(_: &[String], _: &mut Console) -> Result<()> {
        panic!("an index out of bounds")
    }

    #[test]
    fn a_step_runs_in_this_process_with_its_text_its_log_lines_and_its_error_in_its_log() {
        identify::logger::install_logger();
        let dir = tempfile::tempdir().unwrap();
        let mut ok = step(dir.path(), true);
        ok.args[2] = dir.path().join("d").display().to_string();
        assert_eq!(execute(writes_and_says, &ok).unwrap(), Ended::Ok);
        let log = std::fs::read_to_string(&ok.log).unwrap();
        assert!(log.starts_with("sysid filter --data "), "{log}");
        assert!(log.contains("summary of filter\n"), "{log}");
        assert!(log.contains("a line of the library's log\n"), "{log}");

        // Refused, not required: the reason is the error as `sysid` prints it, causes joined.
        let no = step(dir.path(), false);
        std::fs::remove_file(&no.writes).unwrap();
        match execute(refuses, &no).unwrap() {
            Ended::Refused(why) => {
                assert!(why.contains("reading the data set d"), "{why}");
                assert!(why.contains("the disk"), "{why}");
            }
            e => panic!("{e:?}"),
        }
        // A required step that wrote nothing stops the study, naming its log.
        let e = execute(refuses, &step(dir.path(), true)).unwrap_err();
        assert!(format!("{e:#}").contains("logs/r.txt"), "{e:#}");
        // A panic is caught: an error in the log, the study told.
        match execute(panics, &step(dir.path(), false)).unwrap() {
            Ended::Refused(why) => assert!(why.contains("an index out of bounds"), "{why}"),
            e => panic!("{e:?}"),
        }
    }
}
