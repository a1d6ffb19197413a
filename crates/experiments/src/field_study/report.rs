//! `REPORT.md` of a field study, drawn from its records only: the variants identified on the
//! identification record, their predictions of the records kept out of every choice, the
//! selected model on every record and whether their intervals agree — and whether their modes
//! do, and the records' own measured peaks —, the black-box baseline, and the goals decided by
//! stated tests.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use crate::error::{Context, Result};
use serde::Deserialize;

use super::{select, FieldStudy, Part, PartDirs};
use identify::checks::{Warning, WarningKind};
use identify::record::RunRecord;
use identify::validation::cross::CrossValidation;
use identify::validation::shapes::UNLIKE_MAC;
use identify::validation::{ErrorSource, FreeRun, ModalComparison, ModePair};

/// The baseline's result (`experiments/real/srim.py`).
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct Baseline {
    pub method: String,
    pub mdof_version: String,
    pub command: String,
    /// The order of the largest mean fit on the training record; `null` where no order gave a
    /// stable model.
    pub best_order: Option<usize>,
    pub runs: Vec<BaselineRun>,
    /// On a one-storey record: the best linear one-storey model by output error (absent from
    /// baselines written before it, and on structures of more storeys).
    #[serde(default)]
    pub one_storey: Option<OneStorey>,
}

/// The best linear one-storey model by output error (`experiments/real/srim.py`): the yardstick
/// of a one-storey identification.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct OneStorey {
    pub frequency_hz: f64,
    pub damping_ratio: f64,
    /// Fit % of its one channel on each data set (keyed by its directory).
    pub fits: BTreeMap<String, Vec<f64>>,
}

impl OneStorey {
    /// Fits on the record named `record` (the last component of the data directory).
    pub(crate) fn fits_on(&self, record: &str) -> Option<&[f64]> {
        on_record(&self.fits, record).map(Vec::as_slice)
    }
}

/// The entry of a map keyed by data directories whose last component is `record`.
fn on_record<'a, V>(by_dir: &'a BTreeMap<String, V>, record: &str) -> Option<&'a V> {
    by_dir
        .iter()
        .find(|(k, _)| Path::new(k).file_name().is_some_and(|n| n == record))
        .map(|(_, v)| v)
}

/// One model order of the baseline.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct BaselineRun {
    pub order: usize,
    /// Fit % per channel on each data set (keyed by its directory; `null`: unstable model).
    pub fits: BTreeMap<String, Option<Vec<f64>>>,
    pub modes: Vec<BaselineMode>,
    pub seconds: f64,
    /// Why the method failed at this order on these data (a record shorter than its horizon);
    /// absent where it ran.
    #[serde(default)]
    pub error: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
pub(crate) struct BaselineMode {
    pub frequency_hz: f64,
    pub damping_ratio: f64,
}

impl BaselineRun {
    /// Fits on the record named `record` (the last component of the data directory).
    pub(crate) fn fits_on(&self, record: &str) -> Option<&[f64]> {
        on_record(&self.fits, record).and_then(|v| v.as_deref())
    }
}

impl Baseline {
    pub fn load(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text)
            .with_context(|| format!("{}: not a baseline result", path.display()))
    }
    pub fn best(&self) -> Option<&BaselineRun> {
        self.runs.iter().find(|r| Some(r.order) == self.best_order)
    }
    /// The baseline when none of its orders gave a stable model (each free run grows without
    /// bound, or the method failed on the record): a result to state, not a missing one.
    fn without_stable_model(&self) -> Option<&Self> {
        self.best().is_none().then_some(self)
    }
    /// Its orders, as written in the report (`2, 4, 6`).
    fn orders(&self) -> String {
        self.runs
            .iter()
            .map(|r| r.order.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

fn run_record(path: &Path) -> Result<Option<RunRecord>> {
    if !path.exists() {
        return Ok(None);
    }
    Ok(Some(identify::record::read::read::<RunRecord>(path)?))
}

fn cross(path: &Path) -> Result<Option<CrossValidation>> {
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(Some(serde_json::from_str(&text).with_context(|| {
        format!("{}: not a cross-validation result", path.display())
    })?))
}

/// What `sysid validate` said of a free run's discrepancy modes above the record's band
/// (`identify::validation::discrepancy::above_band_note`), from the free run itself: its term
/// and the record's sampling step, `t`'s step over the samples it keeps (`every`; an ulp off the
/// record's own step at 0.1, 0.011 or 0.003 s, which the bound's test allows for).
fn above_band_note(free: &FreeRun) -> Option<String> {
    let d = free.discrepancy.as_ref()?;
    let step = free.t.get(1)? - free.t.first()?;
    let dt = step / free.every.max(1) as f64;
    (dt > 0.0)
        .then(|| identify::validation::discrepancy::above_band_note(d, dt))
        .flatten()
}

/// Is `name` a damping parameter (`c1`…, or the mass-proportional coefficient)?
fn is_damping(name: &str) -> bool {
    let mut ch = name.chars();
    (ch.next() == Some('c') && name.len() > 1 && ch.all(|c| c.is_ascii_digit())) || name == "alpha"
}

fn is_stiffness(name: &str) -> bool {
    let mut ch = name.chars();
    ch.next() == Some('k') && name.len() > 1 && ch.all(|c| c.is_ascii_digit())
}

fn num(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    if a >= 100.0 {
        format!("{x:.0}")
    } else if a >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    }
}

fn fits(f: &FreeRun) -> Vec<f64> {
    f.channels.iter().map(|c| c.fit_percent).collect()
}

fn fit_cell(f: Option<&[f64]>) -> String {
    fit_cell_to(f, 1)
}

/// [`fit_cell`] with `decimals` decimals.
fn fit_cell_to(f: Option<&[f64]>, decimals: usize) -> String {
    cells(f, |x| format!("{x:.decimals$}"))
}

/// The fits of the building alone, where the free run carries a discrepancy term with modes
/// (its fits include the term; `physical_fit_percent` does not).
fn building_alone(f: &FreeRun) -> Option<Vec<f64>> {
    f.discrepancy.as_ref().filter(|d| !d.modes.is_empty())?;
    f.channels.iter().map(|c| c.physical_fit_percent).collect()
}

/// A free run's fits, and beside them the building's alone where a discrepancy term adds to
/// them: a fit that leans on the term says so.
fn fits_cell(f: Option<&FreeRun>) -> String {
    let fit = fit_cell(f.map(fits).as_deref());
    match f.and_then(building_alone) {
        Some(alone) => format!("{fit} (building alone {})", fit_cell(Some(&alone))),
        None => fit,
    }
}

/// The discrepancy term's modes, "discrepancy 3.19 Hz (ζ 2.79 %)"; empty without one.
fn discrepancy_modes(f: Option<&FreeRun>) -> String {
    let Some(d) = f.and_then(|f| f.discrepancy.as_ref()) else {
        return String::new();
    };
    if d.modes.is_empty() {
        return String::new();
    }
    let modes: Vec<String> = d
        .modes
        .iter()
        .map(|m| {
            format!(
                "{:.2} Hz (ζ {:.2} %)",
                m.frequency_hz,
                100.0 * m.damping_ratio
            )
        })
        .collect();
    format!("discrepancy {}", modes.join(", "))
}

/// Values written by `text`, joined by " / " (one per floor); "—" for none.
fn cells(f: Option<&[f64]>, text: impl Fn(f64) -> String) -> String {
    match f {
        Some(v) => v.iter().map(|x| text(*x)).collect::<Vec<_>>().join(" / "),
        None => "—".into(),
    }
}

/// `x` as it reads written with `decimals` decimals.
fn printed(x: f64, decimals: usize) -> f64 {
    format!("{x:.decimals$}").parse().unwrap_or(x)
}

/// The fewest decimals, from one, at which a verdict read off the printed numbers is the one the
/// values give (`tells(d)`); `None` if six do not suffice. A verdict beside its numbers must be
/// readable from them: 47.96 against 47.99 is not "48.0 against 48.0: not met".
fn telling_decimals(tells: impl Fn(usize) -> bool) -> Option<usize> {
    (1..=6).find(|&d| tells(d))
}

/// The share of a held-out record's samples the 95 % band should cover, in per cent.
const BAND_GOAL: std::ops::RangeInclusive<f64> = 90.0..=98.0;

/// Band coverages, each to the decimals that put it on the side of the goal's bounds
/// ([`BAND_GOAL`]) the verdict counts it on ([`telling_decimals`]): 89.96 % is written 89.96.
fn coverage_cell(f: Option<&[f64]>) -> String {
    cells(f, |x| {
        let inside = |v: f64| BAND_GOAL.contains(&v);
        match telling_decimals(|d| inside(printed(x, d)) == inside(x)) {
            Some(d) => format!("{x:.d$}"),
            None => format!("{x}"),
        }
    })
}

/// Whether every floor's fit `mine` is at least `theirs`, and "mine against theirs" written to
/// the decimals that show it ([`telling_decimals`]); not met when either is missing.
fn versus(mine: Option<&[f64]>, theirs: Option<&[f64]>) -> (bool, String) {
    let (Some(m), Some(t)) = (mine, theirs) else {
        return (
            false,
            format!("{} against {}", fit_cell(mine), fit_cell(theirs)),
        );
    };
    let at_least = |read: &dyn Fn(f64) -> f64| m.iter().zip(t).all(|(a, b)| read(*a) >= read(*b));
    let ok = at_least(&|x| x);
    let d = telling_decimals(|d| at_least(&|x| printed(x, d)) == ok).unwrap_or(6);
    (
        ok,
        format!(
            "{} against {}",
            fit_cell_to(mine, d),
            fit_cell_to(theirs, d)
        ),
    )
}

/// What the goals compare with: the baseline's best order, or none of its orders stable.
#[derive(Clone, Copy)]
struct Srim<'a> {
    best: Option<&'a BaselineRun>,
    /// The baseline, where none of its orders gave a stable model (as the part's section holds it).
    unstable: Option<&'a Baseline>,
}

impl Srim<'_> {
    /// [`versus`] the best order's fits on `record`. Against a baseline with no stable model
    /// the goal is not resolved (`None`): its free run grows without bound, so any fit would
    /// "beat" it, and that says nothing of ours.
    fn versus(&self, mine: Option<&[f64]>, record: &str) -> (Option<bool>, String) {
        match (self.best, self.unstable) {
            (None, Some(_)) => (
                None,
                format!(
                    "{} against no stable SRIM model (each order's free run grows without bound)",
                    fit_cell(mine)
                ),
            ),
            (best, _) => {
                let (ok, text) = versus(mine, best.and_then(|b| b.fits_on(record)));
                (Some(ok), text)
            }
        }
    }
}

/// A goal's verdict: met, not met, or not resolved (nothing to decide it against).
fn verdict(ok: Option<bool>) -> &'static str {
    match ok {
        Some(true) => "met",
        Some(false) => "not met",
        None => "not resolved",
    }
}

/// 95 % interval of `name` in the record, if computed.
fn interval(r: &RunRecord, name: &str) -> Option<(f64, f64)> {
    r.credible
        .iter()
        .find(|p| p.parameter == name)
        .and_then(|p| p.intervals.iter().find(|i| (i.level - 0.95).abs() < 1e-9))
        .map(|i| (i.lo, i.hi))
}

/// What stands between the record and a usable identification, or "ok".
/// An identification's whole wall time: its plan settled, the run, its free run and modes.
fn whole_time(r: &RunRecord) -> f64 {
    r.timing.plan_s.unwrap_or(0.0) + r.timing.wall_s + r.timing.validation_s
}

fn outcome(r: &RunRecord) -> String {
    if let Some(f) = &r.failure {
        return format!(
            "failed at step {} of {}: {f}",
            r.steps_completed + 1,
            r.steps_total
        );
    }
    flagged(&r.warnings).unwrap_or_else(|| "ok".into())
}

/// What the warnings of a completed run say against it: a physically impossible value, or a
/// parameter held at its bound 0 — possible by construction, but the data pushed it below zero,
/// which is not an answer to read as "ok" (a stiffness of 0.004 where the prior said 36 is the
/// model not fitting).
fn flagged(warnings: &[Warning]) -> Option<String> {
    let of = |kind: fn(WarningKind) -> bool| -> Vec<&str> {
        warnings
            .iter()
            .filter(|w| kind(w.kind))
            .filter_map(|w| w.parameter.as_deref())
            .collect()
    };
    let fatal = of(WarningKind::is_fatal);
    if !fatal.is_empty() {
        return Some(format!("physically impossible ({})", fatal.join(", ")));
    }
    let at_bound = of(|k| k == WarningKind::AtBound);
    (!at_bound.is_empty()).then(|| format!("held at its bound 0 ({})", at_bound.join(", ")))
}

/// Whether the run completed with a physically possible answer (a parameter held at its bound
/// is possible; the report says so beside it).
fn possible(r: &RunRecord) -> bool {
    r.failure.is_none() && !r.warnings.iter().any(|w| w.kind.is_fatal())
}

fn modes_cell(m: Option<&ModalComparison>) -> String {
    let Some(m) = m else { return "—".into() };
    m.pairs
        .iter()
        .map(|p| match (p.difference_percent, p.mac) {
            (Some(d), Some(mac)) => format!("{:.2} ({:+.1} %, MAC {mac:.3})", p.model_hz, d),
            (Some(d), None) => format!("{:.2} ({:+.1} %)", p.model_hz, d),
            (None, _) => format!("{:.2} (unpaired)", p.model_hz),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn damping_ratios(m: Option<&ModalComparison>) -> String {
    let Some(m) = m else { return "—".into() };
    m.pairs
        .iter()
        .map(|p| format!("{:.2}", 100.0 * p.damping_ratio))
        .collect::<Vec<_>>()
        .join(" / ")
}

fn whiteness(r: &RunRecord) -> String {
    if r.innovation_checks.is_empty() {
        return "—".into();
    }
    r.innovation_checks
        .iter()
        .map(|c| format!("{:.0}", c.ljung_box / c.critical))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// Largest 95 % half-width relative to |θ_val| among the parameters selected by `which`.
fn width(r: &RunRecord, which: fn(&str) -> bool) -> String {
    let w = r
        .param_names
        .iter()
        .zip(&r.theta_val)
        .filter(|(n, _)| which(n))
        .filter_map(|(n, &v)| interval(r, n).map(|(lo, hi)| 50.0 * (hi - lo) / v.abs()))
        .fold(f64::NAN, f64::max);
    if w.is_nan() {
        "—".into()
    } else {
        format!("{w:.2} %")
    }
}

fn params(r: &RunRecord, which: fn(&str) -> bool) -> String {
    r.param_names
        .iter()
        .zip(&r.theta_val)
        .filter(|(n, _)| which(n))
        .map(|(n, &v)| format!("{n} {}", num(v)))
        .collect::<Vec<_>>()
        .join(", ")
}

fn others(n: &str) -> bool {
    !is_stiffness(n) && !is_damping(n)
}

/// Every damping of the record positive (θ_val)?
fn damping_positive(r: &RunRecord) -> bool {
    r.param_names
        .iter()
        .zip(&r.theta_val)
        .filter(|(n, _)| is_damping(n))
        .all(|(_, &v)| v > 0.0)
}

/// Writes the report of the whole study from the records under `out`.
pub(crate) fn render(study: &FieldStudy, out: &Path) -> Result<String> {
    let mut s = String::new();
    writeln!(s, "# {}\n", study.title)?;
    writeln!(
        s,
        "Written by `sysid field-study` from the records under this directory (`cargo xtask \
         reproduce-real` runs it). Every number below is read from a run record of `sysid filter`, a \
         result of `sysid validate` or the baseline's `srim.json`; the commands are in the logs \
         beside them. The records, validations, logs and imported data (about 130 MB) are not \
         committed: the study writes them again. Fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) per measured floor, free run from rest \
         driven by the measured ground motion (docs/validation.md). LB = Ljung–Box Q of each \
         channel's one-step prediction errors over its 95 % critical value (1 = white). ±k, ±c: \
         the largest 95 % half-width relative to θ_val among the stiffnesses / the dampings. MAC: \
         the modal assurance criterion between the model's mode shape and the measured operating \
         shape at the paired peak (1 = the same shape; docs/validation.md, \"Mode shapes\"). \
         Wall s: the identification's whole time — settling its plan (whose held-out choices \
         identify on their own), the run, and the free run with its band and modes (each in the \
         record's `timing`).\n"
    )?;
    for part in &study.part {
        render_part(&mut s, part, out)?;
    }
    Ok(s)
}

fn render_part(s: &mut String, part: &Part, out: &Path) -> Result<()> {
    let dirs = PartDirs::new(out, part);
    let train = &part.identify_record().name;
    let validate: Vec<&str> = part.validate_records().map(|r| r.name.as_str()).collect();
    writeln!(s, "## {}\n\n{}\n", part.title, part.about.trim())?;
    writeln!(
        s,
        "Every choice (variants, selection, priors) was made on `{train}`; {} kept out of every \
         choice.\n",
        if validate.is_empty() {
            "no record was".to_string()
        } else {
            format!(
                "{} {}",
                validate
                    .iter()
                    .map(|v| format!("`{v}`"))
                    .collect::<Vec<_>>()
                    .join(", "),
                if validate.len() == 1 { "was" } else { "were" }
            )
        }
    )?;
    let baseline = match dirs.baseline() {
        p if part.baseline && p.exists() => Some(Baseline::load(&p)?),
        _ => None,
    };
    let best = baseline.as_ref().and_then(|b| b.best());

    let x = Section {
        part,
        dirs: &dirs,
        train,
        validate: &validate,
        best,
        unstable: baseline.as_ref().and_then(Baseline::without_stable_model),
        one_storey: baseline.as_ref().and_then(|b| b.one_storey.as_ref()),
    };
    identified(s, x)?;
    if !validate.is_empty() {
        cross_validation(s, x)?;
    }
    if let Some(b) = &baseline {
        baseline_orders(s, b, train, &validate)?;
    }
    selected_model(s, x)
}

/// What the sections of a part's report read: the part, its directories, the record every
/// choice is made on, those kept out, and the baseline's best order.
#[derive(Clone, Copy)]
struct Section<'a> {
    part: &'a Part,
    dirs: &'a PartDirs,
    train: &'a str,
    validate: &'a [&'a str],
    best: Option<&'a BaselineRun>,
    /// The baseline, where none of its orders gave a stable model.
    unstable: Option<&'a Baseline>,
    /// The best one-storey model by output error, where the baseline has it.
    one_storey: Option<&'a OneStorey>,
}

/// The variants identified on the training record, beside the baseline's best order; the
/// measured peaks; links to the selected model's figures.
fn identified(s: &mut String, x: Section<'_>) -> Result<()> {
    let Section {
        part,
        dirs,
        train,
        best,
        unstable,
        ..
    } = x;
    writeln!(s, "### Identified on `{train}`\n")?;
    writeln!(
        s,
        "| variant | result | stiffness | damping | other | modes Hz (vs measured peak, MAC) | ζ % | fit % | LB | ±k | ±c | log-lik | wall s |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    )?;
    let mut records = BTreeMap::new();
    for v in &part.variant {
        let Some(r) = run_record(&dirs.record(&v.name))? else {
            writeln!(s, "| {} | no record | | | | | | | | | | | |", v.label)?;
            continue;
        };
        writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {:.1} |",
            v.label,
            outcome(&r),
            params(&r, is_stiffness),
            params(&r, is_damping),
            [params(&r, others), discrepancy_modes(r.free_run.as_ref())]
                .into_iter()
                .filter(|x| !x.is_empty())
                .collect::<Vec<_>>()
                .join("; "),
            modes_cell(r.modal.as_ref()),
            damping_ratios(r.modal.as_ref()),
            fits_cell(r.free_run.as_ref()),
            whiteness(&r),
            width(&r, is_stiffness),
            width(&r, is_damping),
            r.loglik,
            whole_time(&r)
        )?;
        records.insert(v.name.clone(), r);
    }
    if let Some(b) = best {
        writeln!(
            s,
            "| SRIM order {} (baseline) | black box | — | — | — | {} | {} | {} | | | | | {:.1} |",
            b.order,
            b.modes
                .iter()
                .map(|m| format!("{:.2}", m.frequency_hz))
                .collect::<Vec<_>>()
                .join(", "),
            b.modes
                .iter()
                .map(|m| format!("{:.2}", 100.0 * m.damping_ratio))
                .collect::<Vec<_>>()
                .join(" / "),
            fit_cell(b.fits_on(train)),
            b.seconds
        )?;
    } else if let Some(b) = unstable {
        writeln!(
            s,
            "| SRIM, orders {} (baseline) | black box: no stable model | — | — | — | — | — | \
             — | | | | | {:.1} |",
            b.orders(),
            b.runs.iter().map(|r| r.seconds).sum::<f64>()
        )?;
    }
    if let Some(first) = records.values().find_map(|r| r.modal.as_ref()) {
        let peaks: Vec<String> = first
            .peaks
            .iter()
            .map(|p| format!("{:.3}", p.frequency_hz))
            .collect();
        writeln!(
            s,
            "\nMeasured transfer-function peaks of `{train}` (Welch H1, docs/validation.md): {} Hz.",
            peaks.join(", ")
        )?;
    }
    if let Some((chosen, _)) = select(part, dirs)? {
        // Only the figures that are there are linked.
        let links: Vec<String> = [
            ("free run against the measured floors", "free_run"),
            ("transfer functions", "transfer"),
        ]
        .iter()
        .filter(|(_, f)| dirs.root.join(format!("selected-{f}.svg")).is_file())
        .map(|(label, f)| format!("[{label}]({}/selected-{f}.svg)", part.name))
        .collect();
        if !links.is_empty() {
            writeln!(
                s,
                "Figures of the selected model ({}): {}; every variant's figures are in `{}/figures/` after a run.",
                chosen.label,
                links.join(", "),
                part.name
            )?;
        }
    }

    writeln!(s)?;

    Ok(())
}

/// Every variant's free-run fit on each record kept out, beside the baseline's.
fn cross_validation(s: &mut String, x: Section<'_>) -> Result<()> {
    let Section {
        part,
        dirs,
        train,
        validate,
        best,
        unstable,
        ..
    } = x;
    if !validate.is_empty() {
        writeln!(s, "### Cross-validation: predicting the records kept out\n")?;
        write!(s, "| identified on `{train}` |")?;
        for v in validate {
            write!(s, " fit % on `{v}` |")?;
        }
        writeln!(s, "\n|---|{}", "---|".repeat(validate.len()))?;
        // What the cells do not say: a discrepancy mode simulated off the record's own grid.
        let mut above_band: Vec<(String, Vec<&str>)> = Vec::new();
        for v in &part.variant {
            write!(s, "| {} |", v.label)?;
            for r in validate {
                let cell = match cross(&dirs.validation(&v.name, r))? {
                    Some(cv) => {
                        if let Some(n) = above_band_note(&cv.free_run) {
                            let n = format!("{} — {n}", v.label);
                            match above_band.iter_mut().find(|(m, _)| *m == n) {
                                Some((_, records)) => records.push(r),
                                None => above_band.push((n, vec![r])),
                            }
                        }
                        fits_cell(Some(&cv.free_run))
                    }
                    None => {
                        let why =
                            super::log_reason(&dirs.log(&format!("validate--{}--{}", v.name, r)));
                        let short = why.rsplit("caused by: ").next().unwrap_or(&why).to_string();
                        format!("not simulated: {short}")
                    }
                };
                write!(s, " {cell} |")?;
            }
            writeln!(s)?;
        }
        if let Some(b) = best {
            write!(s, "| SRIM order {} (baseline) |", b.order)?;
            for r in validate {
                write!(s, " {} |", fit_cell(b.fits_on(r)))?;
            }
            writeln!(s)?;
        } else if let Some(b) = unstable {
            write!(s, "| SRIM, orders {} (baseline) |", b.orders())?;
            writeln!(s, "{}", " no stable model |".repeat(validate.len()))?;
        }
        writeln!(s)?;
        for (note, records) in above_band {
            let on: Vec<String> = records.iter().map(|r| format!("`{r}`")).collect();
            writeln!(s, "On {}: {note}.\n", on.join(", "))?;
        }
    }

    Ok(())
}

/// The baseline's every order: its modes and fits on every record.
fn baseline_orders(s: &mut String, b: &Baseline, train: &str, validate: &[&str]) -> Result<()> {
    writeln!(
        s,
        "### The baseline: {} (mdof {})\n\nTrained on `{train}`; {} Command: `{}`.\n",
        b.method,
        b.mdof_version,
        if b.best().is_some() {
            format!("the best order on `{train}` (largest mean fit) is the one compared above.")
        } else {
            let failed = b.runs.iter().filter(|r| r.error.is_some()).count();
            let why = match failed {
                0 => "each free run grows without bound",
                n if n == b.runs.len() => "the method failed on the record at every order",
                _ => "each free run grows without bound where the method did not fail",
            };
            format!(
                "no order gave a stable model on `{train}` ({why}), so the goals that compare \
                 with it are not resolved."
            )
        },
        b.command
    )?;
    write!(s, "| order | modes Hz (ζ %) |")?;
    let names: Vec<&str> = std::iter::once(train)
        .chain(validate.iter().copied())
        .collect();
    for n in &names {
        write!(s, " fit % `{n}` |")?;
    }
    writeln!(s, " s |\n|---|---|{}---|", "---|".repeat(names.len()))?;
    for r in &b.runs {
        let modes: Vec<String> = r
            .modes
            .iter()
            .map(|m| format!("{:.2} ({:.2})", m.frequency_hz, 100.0 * m.damping_ratio))
            .collect();
        let modes = match &r.error {
            Some(e) => format!("failed: {}", e.replace('|', "/")),
            None => modes.join(", "),
        };
        write!(s, "| {} | {modes} |", r.order)?;
        let missing = if r.error.is_some() {
            "failed"
        } else {
            "unstable"
        };
        for n in &names {
            write!(
                s,
                " {} |",
                r.fits_on(n).map_or(missing.into(), |f| fit_cell(Some(f)))
            )?;
        }
        writeln!(s, " {:.1} |", r.seconds)?;
    }
    writeln!(s)?;
    Ok(())
}

/// The selected variant on every record: its parameters and intervals, whether they agree, its
/// predictive band and the goals.
fn selected_model(s: &mut String, x: Section<'_>) -> Result<()> {
    let Section {
        part,
        dirs,
        train,
        validate,
        best,
        unstable,
        one_storey,
    } = x;
    let selected = select(part, dirs)?;
    if let (Some(sel), None) = (&part.selection, &selected) {
        writeln!(
            s,
            "### Selection\n\nNo variant of the group `{}` completed with a physically possible \
             answer on `{train}`: nothing to select, and the goals are **not met**.\n",
            sel.group
        )?;
    }
    if let Some((chosen, r0)) = &selected {
        let again = if validate.is_empty() {
            String::new()
        } else {
            format!(
                " Identified again on each other record with the same settings and the prior \
                 scaled from `{train}` (`{}/selected-settings.toml`){}.",
                part.name,
                part.selection
                    .as_ref()
                    .filter(|x| !x.other_args.is_empty())
                    .map_or(String::new(), |x| format!(
                        " and `{}`",
                        x.other_args.join(" ")
                    ))
            )
        };
        writeln!(
            s,
            "### The selected model{}\n\nSelected on `{train}` by the filter's log-likelihood \
             among the group `{}`: **{}** (log-lik {:.1}).{again}\n",
            if validate.is_empty() {
                ""
            } else {
                " on every record"
            },
            part.selection.as_ref().map_or("", |x| x.group.as_str()),
            chosen.label,
            r0.loglik,
        )?;
        let mut on: Vec<(String, RunRecord)> = vec![(train.to_string(), r0.clone())];
        for v in validate {
            if let Some(r) = run_record(&dirs.selected_record(v))? {
                on.push((v.to_string(), r));
            }
        }
        write!(s, "| parameter |")?;
        for (n, _) in &on {
            write!(s, " `{n}`: θ_val [95 %] |")?;
        }
        writeln!(s, "\n|---|{}", "---|".repeat(on.len()))?;
        for name in &r0.param_names {
            write!(s, "| {name} |")?;
            for (_, r) in &on {
                let i = r.param_names.iter().position(|n| n == name);
                let cell = match (i, i.and_then(|_| interval(r, name))) {
                    (Some(i), Some((lo, hi))) => {
                        format!("{} [{}, {}]", num(r.theta_val[i]), num(lo), num(hi))
                    }
                    (Some(i), None) => num(r.theta_val[i]),
                    _ => "—".into(),
                };
                write!(s, " {cell} |")?;
            }
            writeln!(s)?;
        }
        write!(s, "| result |")?;
        for (_, r) in &on {
            write!(s, " {} |", outcome(r))?;
        }
        writeln!(s, "\n")?;
        agreement(s, &on)?;
        modes_between_records(s, &on)?;
        band(s, dirs, chosen, r0, train, validate)?;
        // The goals compare with the baseline: only where the part has one.
        if part.baseline {
            let srim = Srim { best, unstable };
            goals(s, part, dirs, chosen, r0, (srim, one_storey), validate)?;
        }
    }
    Ok(())
}

/// Whether the parameters identified on each record lie inside the other records' 95 %
/// intervals, and by how many half-widths they miss.
fn agreement(s: &mut String, on: &[(String, RunRecord)]) -> Result<()> {
    if on.len() < 2 {
        return Ok(());
    }
    writeln!(
        s,
        "**Do the intervals agree?** Test: θ_val of record A lies inside record B's 95 % interval, \
         for every parameter and ordered pair (A, B) of completed runs; a miss is measured in B's \
         half-widths.\n"
    )?;
    let (mut inside, mut total) = (0, 0);
    let mut worst: Vec<(f64, String)> = Vec::new();
    for (a, ra) in on {
        for (b, rb) in on {
            if a == b || ra.failure.is_some() || rb.failure.is_some() {
                continue;
            }
            for (i, name) in ra.param_names.iter().enumerate() {
                let Some((lo, hi)) = interval(rb, name) else {
                    continue;
                };
                total += 1;
                let x = ra.theta_val[i];
                if (lo..=hi).contains(&x) {
                    inside += 1;
                } else {
                    let half = 0.5 * (hi - lo);
                    let miss = if x < lo { lo - x } else { x - hi } / half;
                    worst.push((
                        miss,
                        format!(
                            "{name}: `{a}` {} outside `{b}` [{}, {}] by {miss:.1} half-widths",
                            num(x),
                            num(lo),
                            num(hi)
                        ),
                    ));
                }
            }
        }
    }
    worst.sort_by(|x, y| y.0.total_cmp(&x.0));
    writeln!(
        s,
        "Inside: {inside} of {total} (parameter, pair) cases. Verdict: **{}**.",
        if total == 0 {
            "not resolved (no intervals)"
        } else if inside == total {
            "the intervals agree"
        } else {
            "the intervals do not agree"
        }
    )?;
    for (_, w) in worst.iter().take(6) {
        writeln!(s, "- {w}")?;
    }
    writeln!(s)?;
    Ok(())
}

/// One record's mode `r` for the comparison between records: the model's frequency, its 95 %
/// interval, and the measured peak paired with it unless that peak has another shape.
#[derive(Debug, Clone, Copy)]
struct RecordMode {
    model_hz: f64,
    model_hz_95: Option<[f64; 2]>,
    /// (peak Hz, the record's frequency resolution Hz).
    measured: Option<(f64, f64)>,
}

impl RecordMode {
    fn of(p: &ModePair, resolution_hz: f64) -> Self {
        RecordMode {
            model_hz: p.model_hz,
            model_hz_95: p.model_hz_95,
            // A peak of another shape is not this mode (the modal notes say so): left out.
            measured: p
                .measured_hz
                .filter(|_| p.mac.is_none_or(|mac| mac >= UNLIKE_MAC))
                .map(|f| (f, resolution_hz)),
        }
    }
}

fn record_modes(r: &RunRecord) -> Vec<RecordMode> {
    r.modal.as_ref().map_or(Vec::new(), |m| {
        m.pairs
            .iter()
            .map(|p| RecordMode::of(p, m.resolution_hz))
            .collect()
    })
}

/// Two records' measured peaks of one mode, beyond their resolutions added.
#[derive(Debug, Clone, PartialEq)]
struct PeaksApart {
    mode: usize,
    a: String,
    f_a: f64,
    b: String,
    f_b: f64,
    /// The two records' frequency resolutions added (Hz).
    resolutions: f64,
}

/// The two tests of the modes between records, counted.
#[derive(Debug, Clone, PartialEq, Default)]
struct ModesBetween {
    /// (mode, ordered pair) cases where A's model frequency lies inside B's 95 % interval.
    inside: usize,
    total: usize,
    /// (mode, unordered pair) cases with a measured peak on both records.
    measured_pairs: usize,
    /// Of those, the ones whose peaks differ by more than the resolutions added.
    beyond: usize,
    /// The case furthest beyond (in resolutions).
    furthest: Option<PeaksApart>,
}

/// A peak refined by a parabola through its three bins lies within about a bin of the mode where
/// the record excites it: two records' peaks of the same mode differing by more than their two
/// resolutions added say the structure itself responded at different frequencies. (On the
/// foreign corpus's linear buildings, the same under two earthquakes, 21 such pairs lie at most
/// 0.46 of that apart: `results/foreign/REPORT.md`.)
fn modes_between(records: &[(&str, Vec<RecordMode>)]) -> ModesBetween {
    let mut out = ModesBetween::default();
    let mut furthest = 0.0;
    for (i, (a, ma)) in records.iter().enumerate() {
        for (j, (b, mb)) in records.iter().enumerate() {
            if i == j {
                continue;
            }
            for (r, (xa, xb)) in ma.iter().zip(mb).enumerate() {
                if let Some([lo, hi]) = xb.model_hz_95 {
                    out.total += 1;
                    out.inside += usize::from((lo..=hi).contains(&xa.model_hz));
                }
                let (true, Some(pa), Some(pb)) = (i < j, xa.measured, xb.measured) else {
                    continue;
                };
                let ((f_a, res_a), (f_b, res_b)) = (pa, pb);
                let excess = apart(pa, pb);
                out.measured_pairs += 1;
                if excess > 1.0 {
                    out.beyond += 1;
                    if excess > furthest {
                        furthest = excess;
                        out.furthest = Some(PeaksApart {
                            mode: r + 1,
                            a: a.to_string(),
                            f_a,
                            b: b.to_string(),
                            f_b,
                            resolutions: res_a + res_b,
                        });
                    }
                }
            }
        }
    }
    out
}

/// How far apart two records' measured peaks (Hz, resolution Hz) of one mode lie, in their
/// frequency resolutions added: the data test of [`modes_between`].
fn apart((f_a, res_a): (f64, f64), (f_b, res_b): (f64, f64)) -> f64 {
    (f_a - f_b).abs() / (res_a + res_b)
}

/// Per mode, how far apart two records' measured peaks lie, in their frequency resolutions added
/// — the field study's data test ("Do the modes agree?"), the same on any two
/// records (the foreign corpus's report runs it on its identified and held-out records); none
/// where either has no peak of that mode's shape.
pub fn peaks_apart(a: &ModalComparison, b: &ModalComparison) -> Vec<Option<f64>> {
    let modes = |m: &ModalComparison| -> Vec<RecordMode> {
        m.pairs
            .iter()
            .map(|p| RecordMode::of(p, m.resolution_hz))
            .collect()
    };
    modes(a)
        .iter()
        .zip(&modes(b))
        .map(|(x, y)| Some(apart(x.measured?, y.measured?)))
        .collect()
}

/// Whether the selected model's modes identified on each record lie inside the other records'
/// 95 % modal intervals, and whether the records' own measured peaks (no model) put a mode at
/// different frequencies — the test that tells a structure that differs between records from
/// intervals too narrow for one that does not.
fn modes_between_records(s: &mut String, on: &[(String, RunRecord)]) -> Result<()> {
    let done: Vec<(&str, Vec<RecordMode>)> = on
        .iter()
        .filter(|(_, r)| r.failure.is_none())
        .map(|(n, r)| (n.as_str(), record_modes(r)))
        .filter(|(_, m)| !m.is_empty())
        .collect();
    if done.len() < 2 {
        return Ok(());
    }
    writeln!(
        s,
        "**Do the modes agree?** Test, model: mode r's natural frequency identified on record A \
         lies inside record B's 95 % modal interval (the filter's statistical uncertainty, \
         docs/validation.md), for every mode and ordered pair (A, B). Test, data: the measured \
         transfer-function peaks two records pair with mode r (no model; a peak of another shape, \
         MAC < {UNLIKE_MAC}, left out) differ by more than the two records' frequency resolutions \
         added — then the structure itself responds differently on the two records.\n"
    )?;
    let modes = done.iter().map(|(_, m)| m.len()).max().unwrap_or(0);
    write!(s, "| mode |")?;
    for (n, _) in &done {
        write!(s, " `{n}`: model Hz [95 %]; measured |")?;
    }
    writeln!(s, "\n|---|{}", "---|".repeat(done.len()))?;
    for r in 0..modes {
        write!(s, "| {} |", r + 1)?;
        for (_, m) in &done {
            let cell = m.get(r).map_or("—".to_string(), |x| {
                let model = match x.model_hz_95 {
                    Some([lo, hi]) => format!("{:.3} [{lo:.3}, {hi:.3}]", x.model_hz),
                    None => format!("{:.3}", x.model_hz),
                };
                let measured = x
                    .measured
                    .map_or("—".to_string(), |(f, _)| format!("{f:.3}"));
                format!("{model}; {measured}")
            });
            write!(s, " {cell} |")?;
        }
        writeln!(s)?;
    }
    let m = modes_between(&done);
    let data = match (m.measured_pairs, &m.furthest) {
        (0, _) => "**not resolved** (no two records have a measured peak paired with the same \
                   mode)"
            .to_string(),
        (n, None) => format!(
            "in none of the {n} (mode, pair) cases with two measured peaks do they differ by more \
             than their resolutions added: **the data do not show the structure differs between \
             records**"
        ),
        (n, Some(p)) => format!(
            "{} of the {n} (mode, pair) cases with two measured peaks differ by more than their \
             resolutions added; the furthest, mode {} on `{}` ({:.3} Hz) and `{}` ({:.3} Hz), \
             {:.3} Hz apart ({:.1} %) against {:.3} Hz. **The structure responds differently on \
             different records**: θ identified on one record is not another's, and the \
             intervals' disagreement is at least in part the structure's",
            m.beyond,
            p.mode,
            p.a,
            p.f_a,
            p.b,
            p.f_b,
            (p.f_a - p.f_b).abs(),
            100.0 * (p.f_a - p.f_b).abs() / p.f_a.min(p.f_b),
            p.resolutions,
        ),
    };
    writeln!(
        s,
        "\nModel: inside in {} of {} (mode, pair) cases. Data: {data}.\n",
        m.inside, m.total
    )?;
    Ok(())
}

/// How much of each record the selected model's 95 % predictive band covers: on the record it
/// was identified on (not independent: its model error was learned there) and on each record
/// kept out (independent), with the verdict of the stated test on those.
fn band(
    s: &mut String,
    dirs: &PartDirs,
    chosen: &super::Variant,
    r0: &RunRecord,
    train: &str,
    validate: &[&str],
) -> Result<()> {
    let Some(f0) = r0.free_run.as_ref() else {
        return Ok(());
    };
    let source = match f0.model_error.as_ref().map(|m| m.source) {
        Some(ErrorSource::HeldOut { samples }) => format!(
            "learned on the {samples} samples of `{train}` that the held-out choice's candidate did not fit"
        ),
        Some(ErrorSource::InSample) => format!("learned in-sample on `{train}`"),
        None => "none: the band holds the parameters' spread only".into(),
    };
    writeln!(
        s,
        "**The 95 % predictive band** of the selected model (docs/validation.md): the spread of \
         its posterior draws — on a record kept out, each draw shifted by the spread between \
         `{train}`'s parts where they disagree, as θ of another record — widened by the model's \
         error ({source}). Per cent of each floor's samples inside it:\n"
    )?;
    writeln!(s, "| record | covered % | |\n|---|---|---|")?;
    let cell = |f: &FreeRun| -> Option<Vec<f64>> {
        f.channels.iter().map(|c| c.coverage_percent).collect()
    };
    writeln!(
        s,
        "| `{train}` | {} | identified on it (not independent) |",
        coverage_cell(cell(f0).as_deref())
    )?;
    let mut kept = Vec::new();
    for v in validate {
        let cv = cross(&dirs.validation(&chosen.name, v))?;
        let c = cv.as_ref().and_then(|cv| cell(&cv.free_run));
        let shifted = cv
            .as_ref()
            .and_then(|cv| cv.free_run.band.as_ref())
            .is_some_and(|b| b.shifted);
        writeln!(
            s,
            "| `{v}` | {} | kept out{} |",
            coverage_cell(c.as_deref()),
            if shifted { ", θ shifted" } else { "" }
        )?;
        kept.push((v, c));
    }
    if !kept.is_empty() {
        let inside = kept
            .iter()
            .filter_map(|(_, c)| c.as_ref())
            .flatten()
            .filter(|c| BAND_GOAL.contains(*c))
            .count();
        let total = kept
            .iter()
            .filter_map(|(_, c)| c.as_ref())
            .flatten()
            .count();
        writeln!(
            s,
            "\nTest: the band covers 90–98 % of every floor of every record kept out. {inside} of \
             {total} (record, floor) cases inside: **{}**.",
            if total > 0 && inside == total {
                "met"
            } else {
                "not met"
            }
        )?;
    }
    writeln!(s)?;
    Ok(())
}

/// The issue's goals, each decided by a stated test on the records.
fn goals(
    s: &mut String,
    part: &Part,
    dirs: &PartDirs,
    chosen: &super::Variant,
    r: &RunRecord,
    (srim, one_storey): (Srim<'_>, Option<&OneStorey>),
    validate: &[&str],
) -> Result<()> {
    let train = &part.identify_record().name;
    writeln!(s, "### Goals, decided on the selected model\n")?;
    writeln!(
        s,
        "What stands in the way where a goal is not met is measured in docs/real-frame.md.\n"
    )?;
    // The first three modes, or every mode of a building with fewer.
    let wanted = r.modal.as_ref().map_or(3, |m| m.pairs.len().min(3)).max(1);
    let modes_ok = r.modal.as_ref().is_some_and(|m| {
        m.pairs.len() >= wanted
            && m.pairs
                .iter()
                .take(wanted)
                .all(|p| p.difference_percent.is_some_and(|d| d.abs() <= 1.0))
    });
    let fit = r.free_run.as_ref().map(fits);
    // Where the fit leans on a discrepancy term, the building's alone is stated beside it.
    let alone = |f: Option<&FreeRun>| {
        f.and_then(building_alone).map_or(String::new(), |a| {
            format!(
                "; the model's building alone, without its discrepancy term, {}",
                fit_cell(Some(&a))
            )
        })
    };
    let (fit_ok, fit_text) = srim.versus(fit.as_deref(), train);
    let fit_text = format!("{fit_text}{}", alone(r.free_run.as_ref()));
    let pos = damping_positive(r) && possible(r);
    writeln!(
        s,
        "- On `{train}`: every damping positive ({}), the first {} within 1 % of the \
         measured peaks ({}), every floor's free-run fit at least SRIM's ({fit_text}): **{}**.",
        if pos { "yes" } else { "no" },
        ["mode", "two modes", "three modes"][wanted - 1],
        if modes_ok { "yes" } else { "no" },
        if pos && modes_ok {
            verdict(fit_ok)
        } else {
            "not met"
        }
    )?;
    // A one-storey record: at least the best linear one-storey model's free-run fit.
    if let Some(o) = one_storey {
        let (ok, text) = versus(fit.as_deref(), o.fits_on(train));
        let text = format!("{text}{}", alone(r.free_run.as_ref()));
        writeln!(
            s,
            "- On `{train}`, one storey: free-run fit at least the best linear one-storey \
             model's (output error, {:.3} Hz, ζ {:.2} %: srim.json's `one_storey`): {text}: **{}**.",
            o.frequency_hz,
            100.0 * o.damping_ratio,
            if ok { "met" } else { "not met" }
        )?;
    }
    for v in validate {
        let cv = cross(&dirs.validation(&chosen.name, v))?;
        let (ok, text) = srim.versus(cv.as_ref().map(|c| fits(&c.free_run)).as_deref(), v);
        let text = format!("{text}{}", alone(cv.as_ref().map(|c| &c.free_run)));
        writeln!(
            s,
            "- Cross-validation on `{v}`: fit of the `{train}` model against SRIM's `{train}` model: \
             {text}: **{}**.",
            verdict(ok)
        )?;
    }
    writeln!(s)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const RUNS: &str = r#""method": "SRIM", "mdof_version": "0.0.23", "command": "python srim.py",
        "best_order": 2, "runs": [{"order": 2, "fits": {"d/elcentro-1": [61.4]}, "modes": [],
        "seconds": 0.1}]"#;

    #[test]
    fn a_baseline_reads_with_or_without_its_one_storey_model() {
        let before: Baseline = serde_json::from_str(&format!("{{{RUNS}}}")).unwrap();
        assert!(before.one_storey.is_none());
        let with: Baseline = serde_json::from_str(&format!(
            r#"{{{RUNS}, "one_storey": {{"frequency_hz": 22.03, "damping_ratio": 0.0065,
                "fits": {{"d/elcentro-1": [63.4], "d/sine-1": [-86.5]}}, "seconds": 5.0}}}}"#
        ))
        .unwrap();
        let o = with.one_storey.as_ref().unwrap();
        assert_eq!(o.fits_on("elcentro-1"), Some(&[63.4][..]));
        assert_eq!(o.fits_on("sine-1"), Some(&[-86.5][..]));
        assert_eq!(o.fits_on("elcentro"), None);
        assert_eq!(with.runs[0].fits_on("elcentro-1"), Some(&[61.4][..]));
    }

    #[test]
    fn a_baseline_without_a_stable_order_is_a_result_the_goals_compare_with() {
        let b: Baseline = serde_json::from_str(
            r#"{"method": "SRIM", "mdof_version": "0.0.23", "command": "python srim.py",
            "best_order": null, "runs": [{"order": 2, "fits": {"d/a": null, "d/b": null},
            "modes": [], "seconds": 0.4}, {"order": 4, "fits": {"d/a": null, "d/b": null},
            "modes": [], "seconds": 0.5, "error": "ValueError: negative dimensions"}]}"#,
        )
        .unwrap();
        assert!(b.best().is_none());
        assert_eq!(b.orders(), "2, 4");
        // An order the method failed on says so, and why, in the baseline's table.
        let mut table = String::new();
        baseline_orders(&mut table, &b, "a", &["b"]).unwrap();
        assert!(table.contains("| 2 |  | unstable | unstable |"), "{table}");
        assert!(
            table.contains("| 4 | failed: ValueError: negative dimensions | failed | failed |"),
            "{table}"
        );
        assert!(
            table.contains("(each free run grows without bound where the method did not fail)"),
            "{table}"
        );
        let srim = Srim {
            best: b.best(),
            unstable: b.without_stable_model(),
        };
        // Nothing to decide against: not resolved, and the text says why.
        let (ok, text) = srim.versus(Some(&[7.4]), "a");
        assert_eq!(ok, None);
        assert!(
            text.starts_with("7.4 against no stable SRIM model"),
            "{text}"
        );
        assert_eq!(verdict(ok), "not resolved");
        // A baseline with a stable order is compared as before.
        let stable: Baseline = serde_json::from_str(&format!("{{{RUNS}}}")).unwrap();
        assert!(stable.without_stable_model().is_none());
        let srim = Srim {
            best: stable.best(),
            unstable: None,
        };
        assert_eq!(
            srim.versus(Some(&[63.2]), "elcentro-1"),
            (Some(true), "63.2 against 61.4".into())
        );
        assert_eq!(srim.versus(Some(&[60.0]), "elcentro-1").0, Some(false));
    }

    #[test]
    fn a_parameter_held_at_its_bound_is_said_so_not_ok() {
        let w = |kind, p: &str| Warning {
            kind,
            parameter: Some(p.into()),
            message: String::new(),
        };
        assert_eq!(flagged(&[]), None);
        assert_eq!(flagged(&[w(WarningKind::FewDistinct, "k1")]), None);
        assert_eq!(
            flagged(&[w(WarningKind::AtBound, "k1"), w(WarningKind::AtBound, "c1")]),
            Some("held at its bound 0 (k1, c1)".into())
        );
        // An impossible value says more than a bound, and is what the cell says.
        assert_eq!(
            flagged(&[
                w(WarningKind::AtBound, "k1"),
                w(WarningKind::NonPositive, "c1")
            ]),
            Some("physically impossible (c1)".into())
        );
    }

    #[test]
    fn a_coverage_is_written_on_the_side_of_the_goal_its_verdict_counts() {
        assert_eq!(
            coverage_cell(Some(&[89.96466, 96.94, 98.04, 97.96, 90.0])),
            "89.96 / 96.9 / 98.04 / 98.0 / 90.0"
        );
        assert_eq!(coverage_cell(Some(&[89.99996])), "89.99996");
        assert_eq!(coverage_cell(None), "—");
    }

    #[test]
    fn a_comparison_of_fits_is_written_to_the_decimals_its_verdict_needs() {
        // One decimal where it tells; more only where rounding would hide the verdict.
        assert_eq!(
            versus(Some(&[63.22]), Some(&[63.44])),
            (false, "63.2 against 63.4".into())
        );
        assert_eq!(
            versus(Some(&[47.96]), Some(&[47.99])),
            (false, "47.96 against 47.99".into())
        );
        // Every floor decides: floor 2 at one decimal reads 70.1 ≥ 70.1, at two 70.14 < 70.15.
        assert_eq!(
            versus(Some(&[75.0, 70.14]), Some(&[74.0, 70.149])),
            (false, "75.00 / 70.14 against 74.00 / 70.15".into())
        );
        assert_eq!(
            versus(Some(&[57.6]), Some(&[47.3])),
            (true, "57.6 against 47.3".into())
        );
        assert_eq!(versus(None, Some(&[1.0])), (false, "— against 1.0".into()));
    }

    fn mode(model_hz: f64, interval: [f64; 2], measured: Option<(f64, f64)>) -> RecordMode {
        RecordMode {
            model_hz,
            model_hz_95: Some(interval),
            measured,
        }
    }

    #[test]
    fn measured_peaks_apart_by_more_than_two_resolutions_say_the_structure_differs() {
        // Within the resolutions added (0.2 Hz): no difference shown, whatever the models say.
        let same = [
            ("a", vec![mode(3.00, [2.99, 3.01], Some((3.05, 0.1)))]),
            ("b", vec![mode(3.10, [3.09, 3.11], Some((3.20, 0.1)))]),
        ];
        let m = modes_between(&same);
        assert_eq!((m.inside, m.total), (0, 2));
        assert_eq!((m.measured_pairs, m.beyond, m.furthest), (1, 0, None));
        // a–b 0.3 and a–c 0.45 Hz apart against 0.2: beyond, the furthest named; b–c 0.15: not.
        let apart = [
            ("a", vec![mode(3.0, [2.9, 3.1], Some((3.0, 0.1)))]),
            ("b", vec![mode(3.05, [2.95, 3.15], Some((3.3, 0.1)))]),
            ("c", vec![mode(3.0, [2.99, 3.01], Some((3.45, 0.1)))]),
        ];
        let m = modes_between(&apart);
        assert_eq!((m.inside, m.total), (5, 6));
        assert_eq!((m.measured_pairs, m.beyond), (3, 2));
        let p = m.furthest.unwrap();
        assert_eq!((p.mode, p.a.as_str(), p.b.as_str()), (1, "a", "c"));
        assert!((p.resolutions - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_peak_of_another_shape_is_not_compared() {
        let pair = |mac| ModePair {
            mode: 1,
            model_hz: 3.0,
            damping_ratio: 0.02,
            measured_hz: Some(3.4),
            difference_percent: Some(-11.8),
            excitation_db: None,
            model_hz_95: Some([2.9, 3.1]),
            damping_ratio_95: None,
            model_shape: Vec::new(),
            model_shape_95: Vec::new(),
            operating_shape: Vec::new(),
            mac,
            mac_95: None,
        };
        assert_eq!(RecordMode::of(&pair(Some(0.2)), 0.1).measured, None);
        assert_eq!(
            RecordMode::of(&pair(Some(0.9)), 0.1).measured,
            Some((3.4, 0.1))
        );
        // One storey or one channel: no shape to compare, the peak counts.
        assert_eq!(RecordMode::of(&pair(None), 0.1).measured, Some((3.4, 0.1)));
        let other = [
            ("a", vec![RecordMode::of(&pair(Some(0.2)), 0.1)]),
            ("b", vec![mode(3.0, [2.9, 3.1], Some((3.0, 0.1)))]),
        ];
        assert_eq!(modes_between(&other).measured_pairs, 0);
    }

    fn free_run(discrepancy: &str) -> FreeRun {
        serde_json::from_str(&format!(
            r#"{{"method": "m", "integrator": "exact_linear", "measurement": "absolute",
            "channels": [{{"channel": "a1", "fit_percent": 58.46, "nrmse": 0.4,
            "physical_fit_percent": 47.27}}], {discrepancy} "every": 1, "t": [],
            "measured": [], "simulated": []}}"#
        ))
        .unwrap()
    }

    #[test]
    fn a_fit_that_leans_on_a_discrepancy_term_states_the_buildings_beside_it() {
        let with = free_run(
            r#""discrepancy": {"channels": ["a1"], "modes": [{"frequency_hz": 3.186,
            "damping_ratio": 0.0279}], "coefficients": [[[-0.46, 0.27]]]},"#,
        );
        assert_eq!(fits_cell(Some(&with)), "58.5 (building alone 47.3)");
        assert_eq!(
            discrepancy_modes(Some(&with)),
            "discrepancy 3.19 Hz (ζ 2.79 %)"
        );
        // A term with no mode, or none: the fit alone, nothing listed.
        let empty =
            free_run(r#""discrepancy": {"channels": ["a1"], "modes": [], "coefficients": [[]]},"#);
        for f in [&empty, &free_run("")] {
            assert_eq!(fits_cell(Some(f)), "58.5");
            assert_eq!(discrepancy_modes(Some(f)), "");
        }
        assert_eq!(fits_cell(None), "—");
    }

    /// A free run of a record sampled at `dt` (its series keeping one sample in 3) with a term
    /// of modes at `hz`.
    fn sampled(dt: f64, hz: &[f64]) -> FreeRun {
        let modes: Vec<String> = hz
            .iter()
            .map(|f| format!(r#"{{"frequency_hz": {f}, "damping_ratio": 0.01}}"#))
            .collect();
        let mut f = free_run(&format!(
            r#""discrepancy": {{"channels": ["a1"], "modes": [{}], "coefficients": [[{}]]}},"#,
            modes.join(", "),
            vec!["[0.1, 0.2]"; hz.len()].join(", ")
        ));
        // Set here, not read from the text: a decimal read back can be an ulp off.
        for (m, hz) in f.discrepancy.as_mut().unwrap().modes.iter_mut().zip(hz) {
            m.frequency_hz = *hz;
        }
        f.every = 3;
        f.t = (0..4).map(|k| (k * 3) as f64 * dt).collect();
        f
    }

    #[test]
    fn a_discrepancy_mode_above_a_records_band_is_stated_and_one_at_its_bound_is_not() {
        // Lake Crowley: an 80 Hz mode found at 200 Hz, on a record of 100 Hz.
        let note = above_band_note(&sampled(0.01, &[6.14, 80.0])).unwrap();
        assert!(
            note.contains("80.00 Hz") && !note.contains("6.14"),
            "{note}"
        );
        assert!(note.contains("(40.0 Hz)"), "{note}");
        // At the bound of the record's own rate (0.4/dt: where the search stops): within the
        // band, no note — also where 3·dt/3 is an ulp off dt (0.1, 0.011, 0.003 s).
        for dt in [0.01, 0.005, 1.0 / 120.0, 1.0 / 60.0, 0.1, 0.011, 0.003] {
            assert_eq!(above_band_note(&sampled(dt, &[0.4 / dt])), None, "{dt}");
            assert!(
                above_band_note(&sampled(dt, &[0.41 / dt])).is_some(),
                "{dt}"
            );
        }
        assert_eq!(above_band_note(&free_run("")), None);
    }
}
