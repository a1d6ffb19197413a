//! SVG figures of the paper reproduction (SPEC §8), drawn from run records only (STYLE lesson 10).
//!
//! - [`convergence`]: posterior mean of each parameter against time with a ±2 s.d. band, one
//!   colour per run, the true value dashed (Figs. 4, 5, 6, 8);
//! - [`hysteresis`]: restoring force k1·r1 against x1, true loop and validation loop
//!   (Figs. 4 (b), 8);
//! - [`crosses`]: θ_val / θ_true over many runs, a cross at the mean with arms of ± one s.d.
//!   per algorithm, one panel (and scale) per parameter group (Fig. 7);
//! - [`state_errors`]: distribution over runs of the online-state NRMSE per state and algorithm
//!   (Fig. 6 (b));
//! - [`validate_svg`]: a cheap well-formedness check of a written figure.
//!
//! Every function writes one SVG file, creating its parent directories. Non-finite values in a
//! record (a diverged run, a failure mid-trace) leave gaps in the curves instead of corrupting
//! the axes; every drawn mean, cross and run lies inside its axes (only a convergence figure's
//! ±2 s.d. bands may be clipped, and the panel says so).

use std::path::Path;

use crate::error::{bail, Context, Result};
use plotters::chart::MeshStyle;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub mod style;

use crate::metrics::mean_sd;
use crate::record::RunRecord;
use style::SeriesStyle;

/// Font family of all text (the SVG backend writes `<text>` elements; the viewer lays them out).
pub const FONT: &str = "sans-serif";
/// Font sizes in plotters units; the SVG backend writes `size / 1.24` px, so these give ≥ 16 px
/// tick labels, ≥ 17 px axis descriptions and ≥ 20 px titles.
pub const TITLE_SIZE: f64 = 32.0;
pub const CAPTION_SIZE: f64 = 26.0;
pub const DESC_SIZE: f64 = 21.0;
pub const LABEL_SIZE: f64 = 20.0;
pub const WIDTH: u32 = 1200;

/// Average advance of one character of the figures' text, in em: about DejaVu Sans's (among the
/// widest sans-serif fonts; a narrower one only leaves more room). The SVG backend writes no
/// text metrics and the viewer lays the text out, so its width is estimated from its length.
pub(crate) const EM_PER_CHAR: f64 = 0.6;

/// Estimated width in px of `text` at plotters font size `size` (the SVG backend writes
/// `size / 1.24` px).
pub(crate) fn text_width(text: &str, size: f64) -> f64 {
    text.chars().count() as f64 * EM_PER_CHAR * size / 1.24
}

/// The font size, at most `size`, at which `text` fits in `avail` px (`text_width`): a
/// caption longer than its panel is drawn smaller instead of running past the panel's edge
/// (or the figure's, where the viewer cuts it).
pub(crate) fn fitted_size(text: &str, size: f64, avail: f64) -> f64 {
    let w = text_width(text, size);
    if w > avail && avail > 0.0 {
        size * avail / w
    } else {
        size
    }
}

/// Colour-blind-safe palette (Okabe–Ito), one colour per run or algorithm, cycled.
pub(crate) const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 120, 120),
];

pub(crate) fn colour(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Units of a parameter of the Bouc–Wen chain with unit masses (SPEC §2): stiffnesses k [1/s²],
/// dampings c [1/s], β and γ [1/mⁿ] (β|r|ⁿ has units of 1/m), the exponent n dimensionless.
pub(crate) fn param_unit(name: &str) -> &'static str {
    let digits_after = |prefix: &str| {
        name.strip_prefix(prefix)
            .is_some_and(|rest| rest.chars().all(|c| c.is_ascii_digit()))
    };
    if name.starts_with("beta") || name.starts_with("gamma") {
        "[1/m^n]"
    } else if digits_after("k") {
        "[1/s²]"
    } else if digits_after("c") {
        "[1/s]"
    } else {
        "[-]"
    }
}

/// Grid of panels for `n` panels: as square as possible, columns first (9 → 3×3, 4 → 2×2,
/// 2 → 1×2, 5 → 2×3).
pub fn grid_dims(n: usize) -> (usize, usize) {
    let n = n.max(1);
    let mut cols = 1;
    while cols * cols < n {
        cols += 1;
    }
    let rows = n.div_ceil(cols);
    (rows, cols)
}

fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("creating directory {}", dir.display()))?;
        }
    }
    Ok(())
}

/// Smallest and largest finite values, if any.
pub(crate) fn finite_range(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// A non-degenerate range with 5 % padding on both sides (plotters needs lo < hi).
pub(crate) fn padded((lo, hi): (f64, f64)) -> (f64, f64) {
    if hi > lo {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    } else {
        let half = if lo.abs() > 0.0 { 0.1 * lo.abs() } else { 1.0 };
        (lo - half, lo + half)
    }
}

/// Tick label with as many decimals as the tick spacing of a range of width `span` needs.
pub(crate) fn tick(v: f64, span: f64) -> String {
    // Plotters picks at most ~10 ticks at 1, 2 or 5 × 10^k, so span/10 bounds the spacing.
    let step = span / 10.0;
    let decimals = if step > 0.0 && step.is_finite() {
        (-step.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        2
    };
    let s = format!("{v:.decimals$}");
    // "-0.00" reads badly on an axis.
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_string()
    } else {
        s
    }
}

/// Maximal runs of consecutive indices where `ok` holds (gaps at non-finite data).
pub(crate) fn segments(n: usize, ok: impl Fn(usize) -> bool) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    for k in 0..n {
        match (ok(k), start) {
            (true, None) => start = Some(k),
            (false, Some(s)) => {
                out.push(s..k);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(s..n);
    }
    out
}

/// A drawing area of an SVG figure.
pub(crate) type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// Opens the SVG figure `path`, [`WIDTH`] × `height` px: creates its parent directory, fills the
/// background white, draws the title and splits a legend strip `legend_h` px high off the
/// bottom. Returns the root (for [`present`]), the area below the title and the legend strip.
pub fn open_figure<'a>(
    path: &'a Path,
    height: u32,
    title: &str,
    legend_h: u32,
) -> Result<(Area<'a>, Area<'a>, Area<'a>)> {
    create_parent(path)?;
    let root = SVGBackend::new(path, (WIDTH, height)).into_drawing_area();
    root.fill(&WHITE)?;
    let size = fitted_size(title, TITLE_SIZE, WIDTH as f64 - 20.0);
    let body = root.titled(title, (FONT, size))?;
    let (body, legend) = body.split_vertically(body.dim_in_pixel().1 - legend_h);
    Ok((root, body, legend))
}

/// Writes the figure drawn on `root` to its file, `path`.
pub fn present(root: &Area<'_>, path: &Path) -> Result<()> {
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// A chart of the figures' axes.
type Chart<'a> = ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The chart of one panel of a figure of several: its caption above (sized to fit the panel's
/// width, `fitted_size`), an 8 px margin, an x label area 48 px high and a y label area
/// `y_label_area` px wide.
pub(crate) fn panel_chart<'a>(
    area: &Area<'a>,
    caption: &str,
    y_label_area: u32,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<Chart<'a>> {
    panel_chart_right(area, caption, y_label_area, 8, x, y)
}

/// [`panel_chart`] with a right margin of `right` px: room for half of a tick label at the x
/// axis's right end (a tick can fall on it, as on a window of whole seconds).
pub(crate) fn panel_chart_right<'a>(
    area: &Area<'a>,
    caption: &str,
    y_label_area: u32,
    right: u32,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<Chart<'a>> {
    let avail = area.dim_in_pixel().0 as f64 - 2.0 * 8.0;
    Ok(ChartBuilder::on(area)
        .caption(caption, (FONT, fitted_size(caption, CAPTION_SIZE, avail)))
        .margin(8)
        .margin_right(right)
        .x_label_area_size(48)
        .y_label_area_size(y_label_area)
        .build_cartesian_2d(x, y)?)
}

/// Draws a mesh configured by the caller in the figures' fonts, without light grid lines.
pub fn draw_mesh(
    mesh: &mut MeshStyle<'_, '_, RangedCoordf64, RangedCoordf64, SVGBackend<'_>>,
) -> Result<()> {
    mesh.label_style((FONT, LABEL_SIZE))
        .axis_desc_style((FONT, DESC_SIZE))
        .light_line_style(WHITE)
        .draw()?;
    Ok(())
}

/// One legend entry of a manually drawn legend strip.
pub(crate) enum Swatch {
    Line(RGBColor),
    Dashed(RGBColor),
    /// A shaded area of this colour and opacity.
    Band(RGBColor, f64),
    Bar(RGBColor),
    /// A filled dot (a marked point, e.g. a peak).
    Dot(RGBColor),
    /// A cross with the marker and line style of a series (see [`marker`]).
    Marker(SeriesStyle),
}

/// Height of one legend row (px).
const LEGEND_ROW: u32 = 34;

/// Columns and height (px) of the legend strip of `entries` on a figure `WIDTH` px wide: as
/// many columns as the longest label allows, so that labels never overlap.
pub(crate) fn legend_layout(entries: &[(Swatch, String)]) -> (usize, u32) {
    if entries.is_empty() {
        return (1, 0);
    }
    // Swatch, gap and the label at its estimated width (the SVG viewer lays text out).
    let longest = entries
        .iter()
        .map(|(_, l)| text_width(l, DESC_SIZE))
        .fold(0.0, f64::max);
    let slot = 70.0 + longest;
    let cols = (((WIDTH - 40) as f64 / slot).floor() as usize).clamp(1, entries.len());
    let rows = entries.len().div_ceil(cols) as u32;
    (cols, rows * LEGEND_ROW + 16)
}

/// The marker of a series centred at pixel `(x, y)`: circle, triangle, square, diamond; filled
/// for solid series (forward Euler or no scheme), hollow for dashed ones.
pub fn marker<DB: DrawingBackend>(
    st: SeriesStyle,
    (x, y): (i32, i32),
) -> DynElement<'static, DB, (i32, i32)> {
    let style = if st.dashed {
        st.colour.stroke_width(3)
    } else {
        st.colour.filled()
    };
    match st.marker % 4 {
        0 => Circle::new((x, y), 7, style).into_dyn(),
        1 => TriangleMarker::new((x, y), 9, style).into_dyn(),
        2 => Rectangle::new([(x - 6, y - 6), (x + 6, y + 6)], style).into_dyn(),
        _ => Polygon::new(vec![(x, y - 8), (x + 8, y), (x, y + 8), (x - 8, y)], style).into_dyn(),
    }
}

/// A line between two pixels, whole for a solid series, in dashes for a dashed one.
fn arm_segments(
    ((x0, y0), (x1, y1)): ((i32, i32), (i32, i32)),
    dashed: bool,
) -> Vec<Vec<(i32, i32)>> {
    if !dashed {
        return vec![vec![(x0, y0), (x1, y1)]];
    }
    let len = (((x1 - x0) as f64).hypot((y1 - y0) as f64)).max(1.0);
    let (dash, gap) = (6.0, 4.0);
    let mut out = Vec::new();
    let mut s = 0.0;
    while s < len {
        let e = (s + dash).min(len);
        let at = |t: f64| {
            (
                x0 + ((x1 - x0) as f64 * t / len).round() as i32,
                y0 + ((y1 - y0) as f64 * t / len).round() as i32,
            )
        };
        out.push(vec![at(s), at(e)]);
        s = e + gap;
    }
    out
}

/// Draws legend entries in the grid given by [`legend_layout`].
fn legend_strip(area: &Area<'_>, entries: &[(Swatch, String)]) -> Result<()> {
    if entries.is_empty() {
        return Ok(());
    }
    let (cols, _) = legend_layout(entries);
    let (w, _) = area.dim_in_pixel();
    let slot = (w as i32 - 40) / cols as i32;
    let text =
        TextStyle::from((FONT, DESC_SIZE).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for (i, (swatch, label)) in entries.iter().enumerate() {
        let x = 20 + (i % cols) as i32 * slot;
        let y = 8 + (i / cols) as i32 * LEGEND_ROW as i32 + LEGEND_ROW as i32 / 2;
        match swatch {
            Swatch::Line(c) => area.draw(&PathElement::new(
                vec![(x, y), (x + 40, y)],
                c.stroke_width(3),
            ))?,
            Swatch::Dashed(c) => {
                for dx in [0, 16, 32] {
                    area.draw(&PathElement::new(
                        vec![(x + dx, y), (x + dx + 9, y)],
                        c.stroke_width(2),
                    ))?;
                }
            }
            Swatch::Band(c, alpha) => area.draw(&Rectangle::new(
                [(x, y - 8), (x + 40, y + 8)],
                c.mix(*alpha).filled(),
            ))?,
            Swatch::Dot(c) => area.draw(&Circle::new((x + 20, y), 6, c.filled()))?,
            Swatch::Bar(c) => area.draw(&Rectangle::new(
                [(x + 8, y - 9), (x + 32, y + 9)],
                c.mix(0.85).filled(),
            ))?,
            Swatch::Marker(st) => {
                for seg in arm_segments(((x + 20, y - 12), (x + 20, y + 12)), st.dashed) {
                    area.draw(&PathElement::new(seg, st.colour.stroke_width(3)))?;
                }
                for seg in arm_segments(((x + 10, y), (x + 30, y)), st.dashed) {
                    area.draw(&PathElement::new(seg, st.colour.stroke_width(3)))?;
                }
                area.draw(&marker(*st, (x + 20, y)))?;
            }
        }
        area.draw(&Text::new(label.clone(), (x + 48, y), text.clone()))?;
    }
    Ok(())
}

/// Draws the legend strip of `entries` and writes the figure ([`present`]).
pub(crate) fn finish(
    root: &Area<'_>,
    legend: &Area<'_>,
    entries: &[(Swatch, String)],
    path: &Path,
) -> Result<()> {
    legend_strip(legend, entries)?;
    present(root, path)
}

/// Value of parameter `j` in trace row `k` (NaN when the row is short).
fn at(rows: &[Vec<f64>], k: usize, j: usize) -> f64 {
    rows.get(k)
        .and_then(|r| r.get(j))
        .copied()
        .unwrap_or(f64::NAN)
}

/// Y range of one convergence panel and whether the ±2 s.d. bands were clipped. The range always
/// contains every posterior mean and the true value (a mean of γ at −2.6 is drawn at −2.6, not on
/// an edge); the bands widen it on each side by at most the larger of the core range's width and
/// its largest |value|, so that one diverging band does not flatten the panel. Band
/// parts beyond are drawn on the edge and the panel says so.
pub fn convergence_y_range(
    runs: &[(&str, &RunRecord)],
    j: usize,
    truth: Option<f64>,
) -> ((f64, f64), bool) {
    let mut means = Vec::new();
    let mut bands = Vec::new();
    for (_, r) in runs {
        let tr = &r.trace;
        for k in 0..tr.t.len() {
            let m = at(&tr.param_mean, k, j);
            if !m.is_finite() {
                continue;
            }
            means.push(m);
            let sd = at(&tr.param_sd, k, j);
            if sd.is_finite() {
                bands.push(m - 2.0 * sd);
                bands.push(m + 2.0 * sd);
            }
        }
    }
    means.extend(truth);
    let Some((core_lo, core_hi)) = finite_range(means) else {
        return ((0.0, 1.0), false);
    };
    let (band_lo, band_hi) = finite_range(bands).unwrap_or((core_lo, core_hi));
    let reach = (core_hi - core_lo).max(core_lo.abs().max(core_hi.abs()));
    let lo = band_lo.max(core_lo - reach).min(core_lo);
    let hi = band_hi.min(core_hi + reach).max(core_hi);
    (padded((lo, hi)), lo > band_lo || hi < band_hi)
}

/// Convergence figure (SPEC §8, Figs. 4, 5, 6, 8): one panel per parameter (3×3 for the nine
/// parameters of SPEC §2), posterior mean against time with a shaded ±2 s.d. band per run, in
/// distinct colours, and the true value as a black dashed line when the records know it.
///
/// All runs must share the parameter names of the first. Failed runs are drawn up to where
/// their trace stops.
pub fn convergence(runs: &[(&str, &RunRecord)], path: &Path, title: &str) -> Result<()> {
    let Some((_, first)) = runs.first() else {
        bail!("convergence figure {}: no runs to draw", path.display());
    };
    let names = &first.param_names;
    if names.is_empty() {
        bail!(
            "convergence figure {}: the record has no parameters",
            path.display()
        );
    }
    if let Some((label, _)) = runs.iter().find(|(_, r)| &r.param_names != names) {
        bail!(
            "convergence figure {}: run '{label}' has parameters different from the first run",
            path.display()
        );
    }
    let (t0, t1) = padded(
        finite_range(runs.iter().flat_map(|(_, r)| r.trace.t.iter().copied()))
            .unwrap_or((0.0, 1.0)),
    );
    let t0 = if t0 < 0.0 && t1 > 0.0 { 0.0 } else { t0 };

    let mut entries: Vec<(Swatch, String)> = runs
        .iter()
        .enumerate()
        .map(|(i, (label, _))| {
            (
                Swatch::Line(style::for_label(label, i).colour),
                label.to_string(),
            )
        })
        .collect();
    entries.push((Swatch::Band(colour(6), 0.25), "mean ± 2 s.d.".to_string()));
    if (0..names.len()).any(|j| known_truth(runs, j).is_some()) {
        entries.push((Swatch::Dashed(BLACK), "true value".to_string()));
    }
    let (_, legend_h) = legend_layout(&entries);

    let (rows, cols) = grid_dims(names.len());
    let height = 60 + legend_h + 265 * rows as u32;
    let (root, grid, legend) = open_figure(path, height, title, legend_h)?;
    let panels = grid.split_evenly((rows, cols));

    for (j, (name, area)) in names.iter().zip(&panels).enumerate() {
        draw_convergence_panel(area, runs, j, name, (t0, t1))?;
    }

    finish(&root, &legend, &entries, path)
}

/// The true value of parameter `j`, drawn when some record knows it (they come from the same
/// data).
fn known_truth(runs: &[(&str, &RunRecord)], j: usize) -> Option<f64> {
    runs.iter()
        .find_map(|(_, r)| r.theta_true.as_ref().and_then(|t| t.get(j).copied()))
        .filter(|t| t.is_finite())
}

/// The convergence panel of parameter `j` (`name`) over the time axis `t0..t1`: every run's
/// ±2 s.d. band and mean, and the true value where it is known and inside the axis.
fn draw_convergence_panel(
    area: &Area<'_>,
    runs: &[(&str, &RunRecord)],
    j: usize,
    name: &str,
    (t0, t1): (f64, f64),
) -> Result<()> {
    let truth_j = known_truth(runs, j);
    let ((lo, hi), clipped) = convergence_y_range(runs, j, truth_j);
    let caption = if clipped {
        format!("{name} {} (bands clipped)", param_unit(name))
    } else {
        format!("{name} {}", param_unit(name))
    };
    let mut chart = panel_chart(area, &caption, 70, t0..t1, lo..hi)?;
    let (tspan, yspan) = (t1 - t0, hi - lo);
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .x_labels(6)
            .y_labels(5)
            .x_label_formatter(&|v| tick(*v, tspan))
            .y_label_formatter(&|v| tick(*v, yspan)),
    )?;
    // Bands first so that no mean line is hidden under another run's band.
    draw_sd_bands(&mut chart, runs, j, (lo, hi))?;
    draw_mean_lines(&mut chart, runs, j, (lo, hi))?;
    if let Some(t) = truth_j.filter(|t| *t >= lo && *t <= hi) {
        chart.draw_series(DashedLineSeries::new(
            vec![(t0, t), (t1, t)],
            10,
            6,
            BLACK.stroke_width(2),
        ))?;
    }
    Ok(())
}

/// Every run's shaded band of mean ± 2 s.d. of parameter `j`, clamped to the axis `lo..hi`, one
/// polygon per stretch of finite values.
fn draw_sd_bands(
    chart: &mut Chart<'_>,
    runs: &[(&str, &RunRecord)],
    j: usize,
    (lo, hi): (f64, f64),
) -> Result<()> {
    let clamp = |v: f64| v.clamp(lo, hi);
    for (i, (_, r)) in runs.iter().enumerate() {
        let tr = &r.trace;
        let ok = |k: usize| {
            tr.t[k].is_finite()
                && at(&tr.param_mean, k, j).is_finite()
                && at(&tr.param_sd, k, j).is_finite()
        };
        for seg in segments(tr.t.len(), ok) {
            let upper = seg.clone().map(|k| {
                (
                    tr.t[k],
                    clamp(at(&tr.param_mean, k, j) + 2.0 * at(&tr.param_sd, k, j)),
                )
            });
            let lower = seg.clone().rev().map(|k| {
                (
                    tr.t[k],
                    clamp(at(&tr.param_mean, k, j) - 2.0 * at(&tr.param_sd, k, j)),
                )
            });
            let outline: Vec<(f64, f64)> = upper.chain(lower).collect();
            chart.draw_series(std::iter::once(Polygon::new(
                outline,
                style::for_label(runs[i].0, i).colour.mix(0.18).filled(),
            )))?;
        }
    }
    Ok(())
}

/// Every run's posterior mean of parameter `j` against time, clamped to the axis `lo..hi`, one
/// line per stretch of finite values.
fn draw_mean_lines(
    chart: &mut Chart<'_>,
    runs: &[(&str, &RunRecord)],
    j: usize,
    (lo, hi): (f64, f64),
) -> Result<()> {
    let clamp = |v: f64| v.clamp(lo, hi);
    for (i, (_, r)) in runs.iter().enumerate() {
        let tr = &r.trace;
        let ok = |k: usize| tr.t[k].is_finite() && at(&tr.param_mean, k, j).is_finite();
        for seg in segments(tr.t.len(), ok) {
            let points: Vec<(f64, f64)> = seg
                .map(|k| (tr.t[k], clamp(at(&tr.param_mean, k, j))))
                .collect();
            chart.draw_series(LineSeries::new(
                points,
                style::for_label(runs[i].0, i).colour.stroke_width(2),
            ))?;
        }
    }
    Ok(())
}

/// Hysteresis figure (SPEC §7 validation, Figs. 4 (b) and 8): restoring force k1·r1 against the
/// drift x1, the true loop in black and the loop of the validation run (integrated with θ_val)
/// in colour. A record without loops gives a figure that says why.
pub fn hysteresis(run: &RunRecord, path: &Path, title: &str) -> Result<()> {
    let validation = run.validation.as_ref();
    let loop_val = validation.and_then(|v| v.loop_validation.as_ref());
    let loop_true = validation.and_then(|v| v.loop_true.as_ref());
    let loops: Vec<(&crate::record::Loop, RGBColor, String)> = [
        loop_true.map(|l| (l, BLACK, "true loop".to_string())),
        loop_val.map(|l| {
            (
                l,
                style::for_label(&run.algorithm, 0).colour,
                format!("validation loop ({}, θ_val)", run.algorithm),
            )
        }),
    ]
    .into_iter()
    .flatten()
    .collect();

    let pairs = |l: &crate::record::Loop| -> Vec<(f64, f64)> {
        l.x.iter().copied().zip(l.force.iter().copied()).collect()
    };
    // The axes hold every point drawn: those with both coordinates finite.
    let drawn: Vec<(f64, f64)> = loops
        .iter()
        .flat_map(|(l, ..)| pairs(l))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let axis = |coordinate: fn(&(f64, f64)) -> f64| {
        padded(finite_range(drawn.iter().map(coordinate)).unwrap_or((-1.0, 1.0)))
    };
    let ((x0, x1), (f0, f1)) = (axis(|p| p.0), axis(|p| p.1));

    let entries: Vec<(Swatch, String)> = loops
        .iter()
        .map(|(_, c, label)| (Swatch::Line(*c), label.clone()))
        .collect();
    let (_, legend_h) = legend_layout(&entries);
    let (root, body, legend) = open_figure(path, 900, title, legend_h)?;
    let mut chart = ChartBuilder::on(&body)
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(100)
        .build_cartesian_2d(x0..x1, f0..f1)?;
    let (xspan, fspan) = (x1 - x0, f1 - f0);
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("x1 [m]")
            .y_desc("k1·r1 [m/s²]")
            .x_label_formatter(&|v| tick(*v, xspan))
            .y_label_formatter(&|v| tick(*v, fspan)),
    )?;

    for (l, c, _) in &loops {
        let xy = pairs(l);
        let ok = |k: usize| xy[k].0.is_finite() && xy[k].1.is_finite();
        for seg in segments(xy.len(), ok) {
            chart.draw_series(LineSeries::new(xy[seg].to_vec(), c.stroke_width(2)))?;
        }
    }
    if loops.is_empty() {
        let why = match validation {
            None => "no validation run in this record".to_string(),
            Some(v) => match &v.error {
                Some(e) => format!("validation failed: {e}"),
                None => "the record keeps no hysteresis loops".to_string(),
            },
        };
        let (w, h) = body.dim_in_pixel();
        let style = TextStyle::from((FONT, CAPTION_SIZE).into_font())
            .pos(Pos::new(HPos::Center, VPos::Center));
        body.draw(&Text::new(why, (w as i32 / 2, h as i32 / 2), style))?;
    }
    finish(&root, &legend, &entries, path)
}

/// Category labels under the x axis: name `j` centred at x = j (plotters' automatic ticks of
/// a float axis need not fall on the integers).
fn category_labels(
    root: &Area<'_>,
    chart: &ChartContext<'_, SVGBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    names: &[String],
    y_axis: f64,
) -> Result<()> {
    let style =
        TextStyle::from((FONT, LABEL_SIZE).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
    for (j, name) in names.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(j as f64, y_axis));
        root.draw(&PathElement::new(vec![(x, y), (x, y + 5)], BLACK))?;
        root.draw(&Text::new(name.clone(), (x, y + 8), style.clone()))?;
    }
    Ok(())
}

/// Cross figure (SPEC §8, Fig. 7): for each parameter and algorithm, a cross at the mean over
/// runs of θ_val / θ_true with a vertical arm of ± one s.d. over runs and a short horizontal arm,
/// algorithms side by side; the truth is the line at 1. Failed runs and runs without a true θ
/// are skipped and counted in the legend.
pub fn crosses(groups: &[(&str, Vec<&RunRecord>)], path: &Path, title: &str) -> Result<()> {
    let Some(names) = groups
        .iter()
        .flat_map(|(_, runs)| runs.iter())
        .map(|r| &r.param_names)
        .next()
    else {
        bail!("cross figure {}: no runs to draw", path.display());
    };
    if names.is_empty() {
        bail!(
            "cross figure {}: the records have no parameters",
            path.display()
        );
    }
    let summaries = groups
        .iter()
        .map(|(label, runs)| ratio_summary(label, runs, names, path))
        .collect::<Result<Vec<_>>>()?;
    let entries = cross_legend(groups, &summaries);
    let (_, legend_h) = legend_layout(&entries);

    // One panel per parameter group, each on its own scale, so that the stiffnesses' small
    // differences are not flattened by the hysteresis parameters' large ones.
    let panels = parameter_groups(names);
    let (root, body, legend) = open_figure(path, 760 + legend_h, title, legend_h)?;
    let areas = panel_areas(&body, &panels);
    for ((group, idx), area) in panels.iter().zip(&areas) {
        let labels: Vec<&str> = groups.iter().map(|(label, _)| *label).collect();
        let sub: Vec<String> = idx.iter().map(|&j| names[j].clone()).collect();
        draw_cross_panel(&root, area, group, idx, &sub, &labels, &summaries)?;
    }
    finish(&root, &legend, &entries, path)
}

/// θ_val / θ_true over the usable runs of one algorithm: mean and s.d. per parameter, and how
/// many runs were used, failed or had no true θ.
struct RatioSummary {
    mean: Vec<f64>,
    sd: Vec<f64>,
    used: usize,
    failed: usize,
    no_truth: usize,
}

/// The [`RatioSummary`] of the runs of algorithm `label`, which must all have the parameters
/// `names`.
fn ratio_summary(
    label: &str,
    runs: &[&RunRecord],
    names: &[String],
    path: &Path,
) -> Result<RatioSummary> {
    if let Some(r) = runs.iter().find(|r| r.param_names != names) {
        bail!(
            "cross figure {}: a run of '{label}' (seed {}, run {}) has different parameters",
            path.display(),
            r.seed,
            r.run
        );
    }
    let failed = runs.iter().filter(|r| r.is_failure()).count();
    let ratios: Vec<Vec<f64>> = runs
        .iter()
        .filter(|r| !r.is_failure())
        .filter_map(|r| r.normalised_theta_val())
        .collect();
    let no_truth = runs.len() - failed - ratios.len();
    let (mut mean, mut sd) = (Vec::new(), Vec::new());
    for j in 0..names.len() {
        let column: Vec<f64> = ratios
            .iter()
            .map(|r| r.get(j).copied().unwrap_or(f64::NAN))
            .collect();
        let (m, s, _) = mean_sd(&column);
        mean.push(m);
        sd.push(s);
    }
    Ok(RatioSummary {
        mean,
        sd,
        used: ratios.len(),
        failed,
        no_truth,
    })
}

/// The cross figure's legend: each algorithm with the runs it used and skipped, and the truth.
fn cross_legend(
    groups: &[(&str, Vec<&RunRecord>)],
    summaries: &[RatioSummary],
) -> Vec<(Swatch, String)> {
    let mut entries: Vec<(Swatch, String)> = groups
        .iter()
        .zip(summaries)
        .enumerate()
        .map(|(i, ((label, _), s))| {
            let mut text = format!("{label} (n = {}", s.used);
            if s.failed > 0 {
                text.push_str(&format!(", {} failed run(s) skipped", s.failed));
            }
            if s.no_truth > 0 {
                text.push_str(&format!(", {} without truth skipped", s.no_truth));
            }
            text.push_str("): mean ± 1 s.d. over runs");
            (Swatch::Marker(style::for_label(label, i)), text)
        })
        .collect();
    entries.push((Swatch::Dashed(BLACK), "truth".to_string()));
    entries
}

/// The body split side by side into one area per parameter group, widths in proportion to the
/// parameters shown plus room for each panel's y labels.
fn panel_areas<'a>(body: &Area<'a>, panels: &[(String, Vec<usize>)]) -> Vec<Area<'a>> {
    let (body_w, _) = body.dim_in_pixel();
    let weight = |p: &(String, Vec<usize>)| p.1.len() as f64 + 1.2;
    let total: f64 = panels.iter().map(weight).sum();
    let mut cuts = Vec::new();
    let mut acc = 0.0;
    for p in &panels[..panels.len() - 1] {
        acc += weight(p);
        cuts.push((acc / total * body_w as f64).round() as i32);
    }
    body.split_by_breakpoints(cuts, Vec::<i32>::new())
}

/// Where the `i`-th of `g` algorithms sits beside a category's centre, slots `width` apart.
fn slot_offset(i: usize, g: usize, width: f64) -> f64 {
    (i as f64 - (g as f64 - 1.0) / 2.0) * width
}

/// One panel of the cross figure: the parameters `idx` (named `sub`) of group `group` on their
/// own scale, the truth at 1 and every algorithm's crosses.
fn draw_cross_panel(
    root: &Area<'_>,
    area: &Area<'_>,
    group: &str,
    idx: &[usize],
    sub: &[String],
    labels: &[&str],
    summaries: &[RatioSummary],
) -> Result<()> {
    // Every drawn value is inside the axis: mean ± s.d. of every algorithm, and 1.
    let values = summaries.iter().flat_map(|s| {
        idx.iter()
            .flat_map(|&j| {
                let sd = if s.sd[j].is_finite() { s.sd[j] } else { 0.0 };
                [s.mean[j] - sd, s.mean[j] + sd]
            })
            .collect::<Vec<_>>()
    });
    let (lo, hi) = padded(finite_range(values.chain([1.0])).unwrap_or((0.0, 2.0)));
    let k = idx.len();
    let mut chart = ChartBuilder::on(area)
        .caption(group, (FONT, CAPTION_SIZE))
        .margin(14)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(-0.5..(k as f64 - 0.5), lo..hi)?;
    let yspan = hi - lo;
    draw_mesh(
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .y_labels(8)
            .y_label_formatter(&|v| tick(*v, yspan))
            .y_desc("θ_val / θ_true [-]"),
    )?;
    category_labels(root, &chart, sub, lo)?;
    chart.draw_series(DashedLineSeries::new(
        vec![(-0.5, 1.0), (k as f64 - 0.5, 1.0)],
        10,
        6,
        BLACK.stroke_width(2),
    ))?;
    for (i, s) in summaries.iter().enumerate() {
        draw_crosses(
            root,
            &chart,
            idx,
            style::for_label(labels[i], i),
            i,
            summaries.len(),
            s,
        )?;
    }
    Ok(())
}

/// The crosses of the `i`-th of `g` algorithms (summary `s`, style `st`) at the parameters
/// `idx`: a marker at the mean, a vertical arm of ± one s.d. and a short horizontal arm.
fn draw_crosses(
    root: &Area<'_>,
    chart: &Chart<'_>,
    idx: &[usize],
    st: SeriesStyle,
    i: usize,
    g: usize,
    s: &RatioSummary,
) -> Result<()> {
    let g = g.max(1);
    let width = 0.7 / g as f64;
    let c = st.colour;
    let arm = 0.35 * width;
    for (x0, &j) in idx.iter().enumerate() {
        let (m, sd) = (s.mean[j], s.sd[j]);
        if !m.is_finite() {
            continue;
        }
        let x = x0 as f64 + slot_offset(i, g, width);
        let sd = if sd.is_finite() { sd } else { 0.0 };
        // The arms in pixels, so that a dashed (non-Euler) series is dashed on screen.
        let px = |p: (f64, f64)| chart.backend_coord(&p);
        let arms = [
            (px((x, m - sd)), px((x, m + sd))),
            (px((x - arm, m)), px((x + arm, m))),
        ];
        for a in arms {
            for seg in arm_segments(a, st.dashed) {
                root.draw(&PathElement::new(seg, c.stroke_width(3)))?;
            }
        }
        root.draw(&marker(st, px((x, m))))?;
    }
    Ok(())
}

/// Parameters grouped for separate panels, in order of first appearance: stiffnesses `k…`,
/// dampings `c…`, and the rest (the hysteresis parameters β, γ, n of SPEC §1). Empty groups are
/// left out.
pub(crate) fn parameter_groups(names: &[String]) -> Vec<(String, Vec<usize>)> {
    let numbered = crate::metrics::in_group;
    let mut groups: Vec<(String, Vec<usize>)> = vec![
        ("stiffness".into(), Vec::new()),
        ("damping".into(), Vec::new()),
        ("hysteresis".into(), Vec::new()),
    ];
    for (j, name) in names.iter().enumerate() {
        let g = if numbered(name, 'k') {
            0
        } else if numbered(name, 'c') {
            1
        } else {
            2
        };
        groups[g].1.push(j);
    }
    groups.retain(|(_, idx)| !idx.is_empty());
    groups
}

/// Quartiles (linear interpolation between order statistics) of sorted finite values.
fn quartiles(sorted: &[f64]) -> Option<[f64; 5]> {
    if sorted.is_empty() {
        return None;
    }
    let q = |p: f64| {
        let h = p * (sorted.len() - 1) as f64;
        let (i, f) = (h.floor() as usize, h.fract());
        let next = sorted[(i + 1).min(sorted.len() - 1)];
        sorted[i] + f * (next - sorted[i])
    };
    Some([
        sorted[0],
        q(0.25),
        q(0.5),
        q(0.75),
        sorted[sorted.len() - 1],
    ])
}

/// State-error figure (Fig. 6 (b), SPEC §7): the distribution over runs of the online-state
/// NRMSE, per state (x axis) and algorithm (colour): a box from the lower to the upper quartile
/// with the median, whiskers to the smallest and largest run, and every run as a dot. One run of
/// each algorithm can rank them either way; the distributions show whether the difference is
/// systematic. Failed runs and runs without online errors are skipped and counted in the legend.
pub fn state_errors(groups: &[(&str, Vec<&RunRecord>)], path: &Path, title: &str) -> Result<()> {
    let names = online_state_names(groups);
    if names.is_empty() {
        bail!(
            "state-error figure {}: no run has online state errors",
            path.display()
        );
    }
    let errors = state_error_values(groups, &names);
    // Every drawn value (every run) is inside the axis.
    let top =
        finite_range(errors.values.iter().flatten().flatten().copied()).map_or(1.0, |(_, hi)| hi);
    let top = if top > 0.0 { 1.05 * top } else { 1.0 };

    let n = names.len();
    let entries = state_error_legend(groups, &errors);
    let (_, legend_h) = legend_layout(&entries);

    let (root, body, legend) = open_figure(path, 760 + legend_h, title, legend_h)?;
    let mut chart = ChartBuilder::on(&body)
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..top)?;
    draw_mesh(
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .y_label_formatter(&|v| tick(*v, top))
            .x_desc("state")
            .y_desc("online NRMSE [-]"),
    )?;
    category_labels(&root, &chart, &names, 0.0)?;

    let g = groups.len().max(1);
    let width = 0.8 / g as f64;
    for (i, per_state) in errors.values.iter().enumerate() {
        let c = style::for_label(groups[i].0, i).colour;
        for (j, v) in per_state.iter().enumerate() {
            let x = j as f64 + slot_offset(i, g, width);
            draw_box(&mut chart, x, 0.4 * width, c, v)?;
        }
    }
    finish(&root, &legend, &entries, path)
}

/// The online states of the usable runs, in order of first appearance over all records.
fn online_state_names(groups: &[(&str, Vec<&RunRecord>)]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for (_, runs) in groups {
        for r in runs.iter().filter(|r| !r.is_failure()) {
            for name in r.online_states.iter().flat_map(|s| &s.names) {
                if !names.contains(name) {
                    names.push(name.clone());
                }
            }
        }
    }
    names
}

/// The online state errors of every algorithm, and how many of its runs were used and skipped.
struct StateErrors {
    /// `values[i][j]`: the NRMSE of state j in every usable run of algorithm i.
    values: Vec<Vec<Vec<f64>>>,
    used: Vec<usize>,
    skipped: Vec<usize>,
}

/// The finite NRMSE of each state `names` in the usable runs (not failed, with online errors)
/// of every algorithm.
fn state_error_values(groups: &[(&str, Vec<&RunRecord>)], names: &[String]) -> StateErrors {
    let mut values: Vec<Vec<Vec<f64>>> = Vec::new();
    let mut used = Vec::new();
    let mut skipped = Vec::new();
    for (_, runs) in groups {
        let usable: Vec<_> = runs
            .iter()
            .filter(|r| !r.is_failure())
            .filter_map(|r| r.online_states.as_ref())
            .collect();
        values.push(
            names
                .iter()
                .map(|name| {
                    usable
                        .iter()
                        .filter_map(|s| {
                            s.names
                                .iter()
                                .position(|n| n == name)
                                .and_then(|p| s.errors.get(p))
                                .map(|e| e.nrmse)
                        })
                        .filter(|v| v.is_finite())
                        .collect()
                })
                .collect(),
        );
        used.push(usable.len());
        skipped.push(runs.len() - usable.len());
    }
    StateErrors {
        values,
        used,
        skipped,
    }
}

/// The state-error figure's legend: each algorithm with the runs it used and skipped, and what
/// a box, its whiskers and its dots mean.
fn state_error_legend(
    groups: &[(&str, Vec<&RunRecord>)],
    errors: &StateErrors,
) -> Vec<(Swatch, String)> {
    let mut entries: Vec<(Swatch, String)> = groups
        .iter()
        .enumerate()
        .map(|(i, (label, _))| {
            let mut text = format!("{label} (n = {}", errors.used[i]);
            if errors.skipped[i] > 0 {
                text.push_str(&format!(", {} skipped", errors.skipped[i]));
            }
            text.push(')');
            (Swatch::Bar(style::for_label(label, i).colour), text)
        })
        .collect();
    entries.push((
        Swatch::Line(BLACK),
        "box: quartiles and median; whiskers: min–max; dots: runs".to_string(),
    ));
    entries
}

/// One box of the state-error figure at `x`, `half` wide on each side, in colour `c`: the
/// quartiles of the runs' values `v` with the median, whiskers to min and max, and every run as
/// a dot (nothing without values).
fn draw_box(chart: &mut Chart<'_>, x: f64, half: f64, c: RGBColor, v: &[f64]) -> Result<()> {
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    let Some([min, q1, med, q3, max]) = quartiles(&sorted) else {
        return Ok(());
    };
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x - half, q1), (x + half, q3)],
        c.mix(0.35).filled(),
    )))?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x - half, q1), (x + half, q3)],
        c.stroke_width(2),
    )))?;
    for (a, b) in [(min, q1), (q3, max)] {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(x, a), (x, b)],
            c.stroke_width(2),
        )))?;
    }
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(x - half, med), (x + half, med)],
        BLACK.stroke_width(3),
    )))?;
    // Runs as dots, spread deterministically across the box's width.
    let m = v.len().max(1) as f64;
    chart.draw_series(v.iter().enumerate().map(|(k, &y)| {
        let jitter = ((k as f64 + 0.5) / m - 0.5) * 1.6 * half;
        Circle::new((x + jitter, y), 2, c.filled())
    }))?;
    Ok(())
}

/// One line of a [`time_series`] panel.
pub(crate) struct Series<'a> {
    pub label: String,
    pub t: &'a [f64],
    pub y: &'a [f64],
    /// Index into the palette; `None` draws in black.
    pub colour: Option<usize>,
}

/// One panel of a [`time_series`] figure.
pub(crate) struct Panel<'a> {
    pub caption: String,
    pub y_desc: String,
    pub series: Vec<Series<'a>>,
    /// Horizontal reference lines (e.g. ±2 for normalised innovations), dashed.
    pub reference: Vec<f64>,
}

/// Time-series figure: panels stacked vertically, lines against t, every drawn value inside the
/// axes; non-finite values leave gaps. Legend entries are taken from the first panel.
pub(crate) fn time_series(panels: &[Panel<'_>], path: &Path, title: &str) -> Result<()> {
    if panels.is_empty() {
        bail!("time-series figure {}: no panels", path.display());
    }
    let (t0, t1) = padded(
        finite_range(
            panels
                .iter()
                .flat_map(|p| p.series.iter().flat_map(|s| s.t.iter().copied())),
        )
        .unwrap_or((0.0, 1.0)),
    );
    let colour_of = |s: &Series<'_>| s.colour.map_or(BLACK, colour);
    let entries: Vec<(Swatch, String)> = panels[0]
        .series
        .iter()
        .map(|s| (Swatch::Line(colour_of(s)), s.label.clone()))
        .collect();
    let (_, legend_h) = legend_layout(&entries);
    let height = 60 + legend_h + 300 * panels.len() as u32;
    let (root, grid, legend) = open_figure(path, height, title, legend_h)?;
    let areas = grid.split_evenly((panels.len(), 1));
    for (panel, area) in panels.iter().zip(&areas) {
        let values = panel
            .series
            .iter()
            .flat_map(|s| s.y.iter().copied())
            .chain(panel.reference.iter().copied());
        let (lo, hi) = padded(finite_range(values).unwrap_or((-1.0, 1.0)));
        let mut chart = panel_chart(area, &panel.caption, 80, t0..t1, lo..hi)?;
        let (tspan, yspan) = (t1 - t0, hi - lo);
        draw_mesh(
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_desc(panel.y_desc.clone())
                .x_labels(8)
                .y_labels(5)
                .x_label_formatter(&|v| tick(*v, tspan))
                .y_label_formatter(&|v| tick(*v, yspan)),
        )?;
        for r in &panel.reference {
            chart.draw_series(DashedLineSeries::new(
                vec![(t0, *r), (t1, *r)],
                10,
                6,
                BLACK.stroke_width(1),
            ))?;
        }
        for s in &panel.series {
            let n = s.t.len().min(s.y.len());
            let ok = |k: usize| s.t[k].is_finite() && s.y[k].is_finite();
            for seg in segments(n, ok) {
                let points: Vec<(f64, f64)> = seg.map(|k| (s.t[k], s.y[k])).collect();
                chart.draw_series(LineSeries::new(points, colour_of(s).stroke_width(2)))?;
            }
        }
    }
    finish(&root, &legend, &entries, path)
}

/// Autocorrelation figure: for each channel a panel of the sample autocorrelation at lags
/// 1, 2, … as stems, with the ±`bound` band of a white sequence dashed (1.96/√n for 95%).
pub(crate) fn autocorrelation(
    channels: &[(String, Vec<f64>)],
    bound: f64,
    path: &Path,
    title: &str,
) -> Result<()> {
    if channels.is_empty() {
        bail!("autocorrelation figure {}: no channels", path.display());
    }
    let entries = vec![
        (
            Swatch::Line(colour(0)),
            "sample autocorrelation".to_string(),
        ),
        (
            Swatch::Dashed(BLACK),
            format!("±{bound:.3}: 95% band of a white sequence"),
        ),
    ];
    let (_, legend_h) = legend_layout(&entries);
    let height = 60 + legend_h + 260 * channels.len() as u32;
    let (root, grid, legend) = open_figure(path, height, title, legend_h)?;
    let areas = grid.split_evenly((channels.len(), 1));
    for ((name, rho), area) in channels.iter().zip(&areas) {
        let lags = rho.len().max(1) as f64;
        let (lo, hi) = padded(
            finite_range(rho.iter().copied().chain([bound, -bound, 0.0])).unwrap_or((-1.0, 1.0)),
        );
        // Ticks of ±0.025 take six characters: a y label area of 96 px keeps them off the
        // axis description, and six of them fit the panel's height without touching.
        let mut chart = panel_chart(area, name, 96, 0.0..lags + 0.5, lo..hi)?;
        let yspan = hi - lo;
        draw_mesh(
            chart
                .configure_mesh()
                .x_desc("lag [steps]")
                .y_desc("autocorrelation [-]")
                .y_labels(6)
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&|v| tick(*v, yspan)),
        )?;
        for b in [bound, -bound] {
            chart.draw_series(DashedLineSeries::new(
                vec![(0.0, b), (lags + 0.5, b)],
                10,
                6,
                BLACK.stroke_width(1),
            ))?;
        }
        for (k, r) in rho.iter().enumerate().filter(|(_, r)| r.is_finite()) {
            let x = (k + 1) as f64;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x, 0.0), (x, *r)],
                colour(0).stroke_width(3),
            )))?;
        }
    }
    finish(&root, &legend, &entries, path)
}

/// Checks that `path` is a non-empty SVG document: it opens with `<svg` or `<?xml` and closes
/// with `</svg>`.
pub fn validate_svg(path: &Path) -> Result<()> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading figure {}", path.display()))?;
    let body = text.trim();
    if body.is_empty() {
        bail!("figure {} is empty", path.display());
    }
    if !(body.starts_with("<svg") || body.starts_with("<?xml")) {
        bail!(
            "figure {} does not start with an SVG or XML header",
            path.display()
        );
    }
    if !body.contains("<svg") || !body.ends_with("</svg>") {
        bail!("figure {} is not closed by </svg>", path.display());
    }
    Ok(())
}

/// One group (an algorithm) of a [`category_panels`] figure: per category, a mean and the
/// half-width of its error bar (NaN: nothing drawn for that category).
pub struct CategoryGroup {
    pub label: String,
    pub mean: Vec<f64>,
    pub half_width: Vec<f64>,
}

/// One panel of a [`category_panels`] figure.
pub struct CategoryPanel {
    pub caption: String,
    pub y_desc: String,
    pub groups: Vec<CategoryGroup>,
}

/// Means with error bars per category (e.g. per ground motion), one marker and colour per
/// group, side by side within a category; panels stacked vertically; the axes hold every
/// drawn value, error bars included.
pub fn category_panels(
    categories: &[String],
    panels: &[CategoryPanel],
    path: &Path,
    title: &str,
) -> Result<()> {
    if panels.is_empty() || categories.is_empty() {
        bail!("category figure {}: nothing to draw", path.display());
    }
    let entries: Vec<(Swatch, String)> = panels[0]
        .groups
        .iter()
        .enumerate()
        .map(|(i, g)| {
            (
                Swatch::Marker(style::for_label(&g.label, i)),
                g.label.clone(),
            )
        })
        .collect();
    let (_, legend_h) = legend_layout(&entries);
    let height = 60 + legend_h + 320 * panels.len() as u32;
    let (root, grid, legend) = open_figure(path, height, title, legend_h)?;
    let areas = grid.split_evenly((panels.len(), 1));
    let n = categories.len();
    for (panel, area) in panels.iter().zip(&areas) {
        let values = panel.groups.iter().flat_map(|g| {
            g.mean
                .iter()
                .zip(&g.half_width)
                .flat_map(|(m, h)| [m - h.max(0.0), m + h.max(0.0), *m])
        });
        let (lo, hi) = padded(finite_range(values).unwrap_or((0.0, 1.0)));
        let mut chart = panel_chart(area, &panel.caption, 80, -0.5..(n as f64 - 0.5), lo..hi)?;
        let yspan = hi - lo;
        let names = categories.to_vec();
        draw_mesh(
            chart
                .configure_mesh()
                .y_desc(panel.y_desc.clone())
                .x_labels(n)
                .y_labels(5)
                .x_label_formatter(&|v| {
                    let i = v.round();
                    if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                        names[i as usize].clone()
                    } else {
                        String::new()
                    }
                })
                .y_label_formatter(&|v| tick(*v, yspan)),
        )?;
        let width = 0.6 / panel.groups.len().max(1) as f64;
        for (gi, g) in panel.groups.iter().enumerate() {
            let st = style::for_label(&g.label, gi);
            let c = st.colour;
            for (ci, (m, h)) in g.mean.iter().zip(&g.half_width).enumerate() {
                if !m.is_finite() {
                    continue;
                }
                let x = ci as f64 - 0.3 + width * (gi as f64 + 0.5);
                if h.is_finite() {
                    chart.draw_series(LineSeries::new(
                        vec![(x, m - h), (x, m + h)],
                        c.stroke_width(2),
                    ))?;
                }
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, *m)) + marker(st, (0, 0)),
                ))?;
            }
        }
    }
    finish(&root, &legend, &entries, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_of_the_paper_parameters() {
        assert_eq!(param_unit("k1"), "[1/s²]");
        assert_eq!(param_unit("c3"), "[1/s]");
        assert_eq!(param_unit("beta"), "[1/m^n]");
        assert_eq!(param_unit("gamma2"), "[1/m^n]");
        assert_eq!(param_unit("n"), "[-]");
        assert_eq!(param_unit("cx"), "[-]");
    }

    #[test]
    fn grids_are_near_square() {
        assert_eq!(grid_dims(9), (3, 3));
        assert_eq!(grid_dims(1), (1, 1));
        assert_eq!(grid_dims(2), (1, 2));
        assert_eq!(grid_dims(5), (2, 3));
        assert_eq!(grid_dims(12), (3, 4));
    }

    #[test]
    fn segments_split_at_gaps() {
        let v = [1.0, f64::NAN, 2.0, 3.0, f64::INFINITY, 4.0];
        assert_eq!(
            segments(v.len(), |k| v[k].is_finite()),
            vec![0..1, 2..4, 5..6]
        );
        assert!(segments(0, |_| true).is_empty());
    }

    #[test]
    fn ranges_are_never_degenerate() {
        assert_eq!(finite_range([f64::NAN, f64::INFINITY]), None);
        let (lo, hi) = padded((2.0, 2.0));
        assert!(lo < 2.0 && hi > 2.0);
        let (lo, hi) = padded((0.0, 0.0));
        assert!(lo < 0.0 && hi > 0.0);
        assert_eq!(padded((0.0, 10.0)), (-0.5, 10.5));
    }

    #[test]
    fn ticks_follow_the_span() {
        assert_eq!(tick(8.0, 10.0), "8");
        assert_eq!(tick(0.25, 0.5), "0.25");
        assert_eq!(tick(-0.0001, 1.0), "0.0");
    }
}
