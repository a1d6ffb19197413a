//! The SVG figures of one run, drawn from its record only (`sysid plot RUN.json --out DIR`).
//!
//! - `convergence.svg`: posterior mean of every parameter against time with its ±2 s.d. band
//!   (and the true value when the record knows it), from the record's trace;
//! - `ess.svg`: the effective sample size against time, from the trace;
//! - `hysteresis.svg`: the validation hysteresis loop, with the true loop when known;
//! - `accelerations.svg`, `innovations.svg`, `innovation_acf.svg`: measured against predicted
//!   accelerations, the normalised innovations and their autocorrelation with a whiteness check
//!   (Ljung–Box), when the record carries `residuals` ([`crate::checks::Residuals`]).
//!
//! A figure whose data the record lacks is skipped with a note saying what is missing.

use std::path::{Path, PathBuf};

use crate::error::{Context, Result};

use crate::figures::{self, Panel, Series};
use crate::record::RunRecord;
use crate::residuals::{whiteness, Residuals, Whiteness};

/// What `plot` drew and what it skipped (and why).
#[derive(Debug, Default)]
pub struct Plotted {
    pub written: Vec<PathBuf>,
    pub skipped: Vec<String>,
}

/// Lags of the whiteness check.
const MAX_LAG: usize = 20;

/// Reads a record (through [`crate::record::read::read`], with every reader's checks) and draws
/// its figures into `out`.
///
/// Each figure is put in place whole or not at all: every figure is drawn into a hidden
/// directory `out/.figures.tmp<pid>`, checked to be a complete SVG document
/// ([`figures::validate_svg`]) and then renamed over `out/<name>.svg` (the same file system, so
/// the rename is atomic), as records are written. An interruption leaves each figure either as
/// it was or complete; a figure of `out` that exists and is not a regular file (a link, a
/// directory) is refused, not replaced. The hidden directory of a process that has ended is
/// removed by the next `plot` into `out`.
pub fn plot(record_path: &Path, out: &Path) -> Result<Plotted> {
    let record: RunRecord = crate::record::read::read(record_path)?;
    draw_in_place(out, |staging| {
        draw(&record, record.residuals.as_ref(), staging)
    })
}

/// Runs `draw` on a fresh hidden directory of `out` and puts every figure it reports written
/// in place in `out`, as [`plot`] does (each checked and renamed whole); the figures of
/// `sysid validate --plot` go through here too.
pub fn draw_in_place(out: &Path, draw: impl FnOnce(&Path) -> Result<Plotted>) -> Result<Plotted> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    remove_stale_staging(out);
    let staging = out.join(format!("{STAGING}{}", std::process::id()));
    if staging.exists() {
        std::fs::remove_dir_all(&staging)
            .with_context(|| format!("removing {}", staging.display()))?;
    }
    std::fs::create_dir(&staging).with_context(|| format!("creating {}", staging.display()))?;
    let placed = draw(&staging).and_then(|drawn| put_in_place(drawn, &staging, out));
    // The staging directory holds only what was not put in place (nothing, on success).
    let _ = std::fs::remove_dir_all(&staging);
    placed
}

/// Runs `draw` on a fresh hidden directory of `out` and puts every file it drew there in place
/// in `out`, each checked to be a complete SVG document and renamed whole, as [`plot`] does:
/// the one way the figures of the studies (`sysid reproduce`, `scaling`, `excitations`,
/// `study`) reach their directory. Returns the figures put in place.
pub fn figures_in_place(
    out: &Path,
    draw: impl FnOnce(&Path) -> Result<()>,
) -> Result<Vec<PathBuf>> {
    let placed = draw_in_place(out, |staging| {
        draw(staging)?;
        Ok(Plotted {
            written: files_under(staging)?,
            skipped: Vec::new(),
        })
    })?;
    Ok(placed.written)
}

/// The files under `dir`, recursively, in name order.
fn files_under(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("listing {}", d.display()))? {
            let p = e
                .with_context(|| format!("listing {}", d.display()))?
                .path();
            if p.is_dir() {
                stack.push(p);
            } else {
                files.push(p);
            }
        }
    }
    files.sort();
    Ok(files)
}

/// Prefix of the directory figures are drawn in before they are put in place.
const STAGING: &str = ".figures.tmp";

/// Checks every figure drawn into `staging` and renames it into `out`.
fn put_in_place(drawn: Plotted, staging: &Path, out: &Path) -> Result<Plotted> {
    let mut placed = Plotted {
        written: Vec::with_capacity(drawn.written.len()),
        skipped: drawn.skipped,
    };
    for from in drawn.written {
        let name = from
            .strip_prefix(staging)
            .map_err(|_| crate::error::invalid!("figure {} outside its directory", from.display()))?
            .to_path_buf();
        figures::validate_svg(&from)?;
        let to = out.join(&name);
        crate::record::atomic::check_replaceable(&to, "figure")?;
        if let Some(dir) = to.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        std::fs::rename(&from, &to)
            .with_context(|| format!("renaming {} into {}", from.display(), to.display()))?;
        placed.written.push(to);
    }
    Ok(placed)
}

/// Removes the staging directories of `plot` runs into `out` whose process has ended (Linux:
/// no `/proc/<pid>`); elsewhere they are left.
fn remove_stale_staging(out: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(out) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(STAGING))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Draws every figure the record has data for.
pub fn draw(r: &RunRecord, residuals: Option<&Residuals>, out: &Path) -> Result<Plotted> {
    let mut p = Plotted::default();
    let who = format!("{} (seed {}, run {})", r.algorithm, r.seed, r.run);

    if r.trace.t.is_empty() {
        p.skipped.push(
            "convergence.svg and ess.svg: the record has no trace (run `sysid filter` with a config `trace_every` > 0)".into(),
        );
    } else {
        let path = out.join("convergence.svg");
        figures::convergence(
            &[(r.algorithm.as_str(), r)],
            &path,
            &format!("{who}: posterior mean ± 2 s.d."),
        )?;
        p.written.push(path);
        let path = out.join("ess.svg");
        figures::time_series(
            &[Panel {
                caption: format!("effective sample size of {} particles", r.particles),
                y_desc: "ESS [-]".into(),
                series: vec![Series {
                    label: "ESS".into(),
                    t: &r.trace.t,
                    y: &r.trace.ess,
                    colour: Some(0),
                }],
                reference: vec![0.0, r.particles as f64],
            }],
            &path,
            &format!("{who}: effective sample size"),
        )?;
        p.written.push(path);
    }

    let has_loop = r
        .validation
        .as_ref()
        .is_some_and(|v| v.loop_validation.is_some());
    if has_loop {
        let path = out.join("hysteresis.svg");
        figures::hysteresis(r, &path, &format!("{who}: validation hysteresis loop"))?;
        p.written.push(path);
    } else {
        p.skipped.push(match &r.validation {
            None => "hysteresis.svg: the record has no validation run (it needs a known structure: a data set with dataset.json)".into(),
            Some(v) => match &v.error {
                Some(e) => format!("hysteresis.svg: the validation run failed: {e}"),
                None => "hysteresis.svg: the record keeps no loops (config `loop_every` = 0)".into(),
            },
        });
    }

    match residuals {
        None => p.skipped.push(
            "accelerations.svg, innovations.svg, innovation_acf.svg: the record has no `residuals` (measured and predicted accelerations, normalised innovations)".into(),
        ),
        Some(res) => draw_residuals(res, &who, out, &mut p)?,
    }
    let (free, modal) = (r.free_run.as_ref(), r.modal.as_ref());
    crate::validation::figures::draw(free, modal, out, &who, &mut p.written, &mut p.skipped)?;
    Ok(p)
}

/// Column `i` of row-major rows.
fn column(rows: &[Vec<f64>], i: usize) -> Vec<f64> {
    rows.iter()
        .map(|row| row.get(i).copied().unwrap_or(f64::NAN))
        .collect()
}

/// The residual figures of a record's one-step prediction errors `res`: the measured and
/// predicted accelerations, the normalised innovations, and their autocorrelation with a
/// whiteness check per channel.
fn draw_residuals(res: &Residuals, who: &str, out: &Path, p: &mut Plotted) -> Result<()> {
    let channels = &res.channels;
    let measured: Vec<Vec<f64>> = (0..channels.len())
        .map(|i| column(&res.measured, i))
        .collect();
    let predicted: Vec<Vec<f64>> = (0..channels.len())
        .map(|i| column(&res.predicted, i))
        .collect();
    let innov: Vec<Vec<f64>> = (0..channels.len())
        .map(|i| column(&res.normalised_innovation, i))
        .collect();
    draw_accelerations(res, &measured, &predicted, who, out, p)?;
    let checks: Vec<_> = innov.iter().map(|x| whiteness(x, MAX_LAG)).collect();
    draw_innovations(res, &innov, &checks, who, out, p)?;
    draw_innovation_acf(channels, &checks, who, out, p)
}

/// `accelerations.svg`: each channel's measured acceleration beside its one-step-ahead
/// prediction.
fn draw_accelerations(
    res: &Residuals,
    measured: &[Vec<f64>],
    predicted: &[Vec<f64>],
    who: &str,
    out: &Path,
    p: &mut Plotted,
) -> Result<()> {
    let panels: Vec<Panel<'_>> = res
        .channels
        .iter()
        .enumerate()
        .map(|(i, name)| Panel {
            caption: name.clone(),
            y_desc: format!("{name} [m/s²]"),
            series: vec![
                Series {
                    label: "measured".into(),
                    t: &res.t,
                    y: &measured[i],
                    colour: None,
                },
                Series {
                    label: "predicted (one step ahead)".into(),
                    t: &res.t,
                    y: &predicted[i],
                    colour: Some(1),
                },
            ],
            reference: Vec::new(),
        })
        .collect();
    let path = out.join("accelerations.svg");
    figures::time_series(
        &panels,
        &path,
        &format!("{who}: measured and predicted accelerations"),
    )?;
    p.written.push(path);
    Ok(())
}

/// `innovations.svg`: each channel's normalised innovations with the ±2 lines, captioned with
/// their mean and variance (`checks`).
fn draw_innovations(
    res: &Residuals,
    innov: &[Vec<f64>],
    checks: &[Option<Whiteness>],
    who: &str,
    out: &Path,
    p: &mut Plotted,
) -> Result<()> {
    let panels: Vec<Panel<'_>> = res
        .channels
        .iter()
        .enumerate()
        .map(|(i, name)| Panel {
            caption: match &checks[i] {
                Some(w) => format!(
                    "{name}: mean {:.2}, variance {:.2} (white: 0, 1)",
                    w.mean, w.variance
                ),
                None => format!("{name}: too few values for a whiteness check"),
            },
            y_desc: "normalised innovation [-]".into(),
            series: vec![Series {
                label: "normalised innovation".into(),
                t: &res.t,
                y: &innov[i],
                colour: Some(0),
            }],
            reference: vec![-2.0, 2.0],
        })
        .collect();
    let path = out.join("innovations.svg");
    figures::time_series(&panels, &path, &format!("{who}: normalised innovations"))?;
    p.written.push(path);
    Ok(())
}

/// `innovation_acf.svg`: the autocorrelation of each channel's innovations with its Ljung–Box
/// verdict (`checks`), or why it is skipped.
fn draw_innovation_acf(
    channels: &[String],
    checks: &[Option<Whiteness>],
    who: &str,
    out: &Path,
    p: &mut Plotted,
) -> Result<()> {
    let acf: Vec<(String, Vec<f64>)> = channels
        .iter()
        .zip(checks)
        .filter_map(|(name, w)| {
            w.as_ref().map(|w| {
                (
                    format!(
                        "{name}: Ljung–Box Q = {:.1} vs {:.1} (95%): {}",
                        w.ljung_box,
                        w.critical,
                        if w.is_white() {
                            "consistent with white"
                        } else {
                            "NOT white: the model leaves structure in the residuals"
                        }
                    ),
                    w.autocorrelation.clone(),
                )
            })
        })
        .collect();
    if acf.is_empty() {
        p.skipped
            .push("innovation_acf.svg: too few innovations for a whiteness check".into());
    } else {
        let bound = checks.iter().flatten().map(|w| w.bound).fold(0.0, f64::max);
        let path = out.join("innovation_acf.svg");
        figures::autocorrelation(
            &acf,
            bound,
            &path,
            &format!("{who}: whiteness of the normalised innovations"),
        )?;
        p.written.push(path);
    }
    Ok(())
}
