//! Figures of a free run and a modal comparison, drawn from a record only:
//!
//! - `free_run.svg`: per channel the measured acceleration, the free run at θ_val and the
//!   pointwise 95 % predictive band (the posterior draws' spread, widened by the model error
//!   where the record has one) over the whole record, with the share of the record it covers,
//!   and below it the same enlarged on the window of strongest shaking (`zoom_window`); the
//!   band is shaded underneath and the free run drawn last, so that no line hides it;
//! - `transfer.svg`: per channel the measured |H1| (log scale) with the identified model's
//!   modes as dashed vertical lines and the peaks read from the data as dots; the legend is a
//!   strip below the panels, where it covers no curve;
//! - `shapes.svg`: per paired mode whose shape could be compared (two measured floors or more)
//!   the model's undamped mode shape over the floors with its 95 % range per floor, and the
//!   measured operating shape (quadrature picking) scaled onto it, the MAC in the caption.

use std::path::{Path, PathBuf};

use crate::error::{bail, Result};
use plotters::prelude::*;

use super::{shapes, FreeRun, ModalComparison, ModePair};
use crate::figures::{
    colour, draw_mesh, finish, finite_range, legend_layout, open_figure, padded, panel_chart_right,
    segments, tick, Area, Swatch,
};

/// Length (s) of the enlarged window of `free_run.svg`: at 3–20 Hz (the modes of the frames
/// and bridges the toolkit meets) 15 to 100 cycles, each wide enough on a 1200 px figure to
/// tell the measured from the predicted.
pub(crate) const ZOOM_S: f64 = 5.0;

/// Right margin (px) of the panels: half of the widest tick label ("100.0" at 16 px) and more,
/// for a tick on the axis's right end.
const RIGHT: u32 = 32;

/// Opacity of the predictive band's shade (the legend's swatch uses the same).
const BAND_ALPHA: f64 = 0.25;
/// Opacity of the zoom window's shade on the whole-record panels.
const WINDOW_ALPHA: f64 = 0.15;

/// The window of strongest shaking of a record: the `ZOOM_S`-second window `[t_i, t_i +
/// ZOOM_S]` in which the measured accelerations, squared and summed over every channel, add up
/// to the most (the earliest such window on a tie; non-finite values count 0). `None` when the
/// record is not longer than 2 × `ZOOM_S`: its panels already show every cycle.
pub(crate) fn zoom_window(t: &[f64], measured: &[Vec<f64>]) -> Option<(f64, f64)> {
    let (first, last) = (*t.first()?, *t.last()?);
    let span = last - first;
    if span.is_nan() || span <= 2.0 * ZOOM_S {
        return None;
    }
    let energy: Vec<f64> = (0..t.len())
        .map(|k| {
            measured
                .iter()
                .filter_map(|c| c.get(k))
                .filter(|v| v.is_finite())
                .map(|v| v * v)
                .sum()
        })
        .collect();
    // Two pointers over the sorted times: [i, j) is the window starting at t[i].
    let (mut best, mut best_sum) = (0, f64::NEG_INFINITY);
    let (mut j, mut sum) = (0, 0.0);
    for i in 0..t.len() {
        if t[i] + ZOOM_S > last {
            break;
        }
        while j < t.len() && t[j] <= t[i] + ZOOM_S {
            sum += energy[j];
            j += 1;
        }
        if sum > best_sum {
            (best, best_sum) = (i, sum);
        }
        sum -= energy[i];
    }
    Some((t[best], t[best] + ZOOM_S))
}

/// Indices of the samples of `t` from the last one at or before `a` to the first one at or
/// after `b` (so that the lines reach the window's edges).
fn indices_within(t: &[f64], (a, b): (f64, f64)) -> std::ops::Range<usize> {
    let start = t.iter().rposition(|v| *v <= a).unwrap_or(0);
    let end = t.iter().position(|v| *v >= b).map_or(t.len(), |k| k + 1);
    start..end.max(start)
}

/// What one panel of `free_run.svg` shows: channel `channel` on the samples `range`, the zoom
/// window `shade` marked (on the whole-record panels).
struct FreeRunPanel<'a> {
    caption: String,
    y_desc: String,
    channel: usize,
    range: std::ops::Range<usize>,
    x: (f64, f64),
    shade: Option<(f64, f64)>,
    f: &'a FreeRun,
}

/// Draws one panel of `free_run.svg`: the zoom window's shade, the band, the measured record
/// and the free run, in that order (each drawn over the ones before it).
fn free_run_panel(area: &Area<'_>, p: &FreeRunPanel<'_>) -> Result<()> {
    let (f, i, r) = (p.f, p.channel, p.range.clone());
    let with_band = has_band(f);
    let mut drawn: Vec<&[f64]> = vec![&f.measured[i][r.clone()], &f.simulated[i][r.clone()]];
    if with_band {
        drawn.extend([&f.band_lo[i][r.clone()], &f.band_hi[i][r.clone()]]);
    }
    let (lo, hi) =
        padded(finite_range(drawn.iter().flat_map(|s| s.iter().copied())).unwrap_or((-1.0, 1.0)));
    let (x0, x1) = p.x;
    let mut chart = panel_chart_right(area, &p.caption, 80, RIGHT, x0..x1, lo..hi)?;
    let (tspan, yspan) = (x1 - x0, hi - lo);
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc(p.y_desc.clone())
            .x_labels(8)
            .y_labels(5)
            .x_label_formatter(&|v| tick(*v, tspan))
            .y_label_formatter(&|v| tick(*v, yspan)),
    )?;
    if let Some((a, b)) = p.shade {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(a, lo), (b, hi)],
            colour(6).mix(WINDOW_ALPHA).filled(),
        )))?;
    }
    let t = &f.t[r.clone()];
    if with_band {
        let (blo, bhi) = (&f.band_lo[i][r.clone()], &f.band_hi[i][r.clone()]);
        let ok = |k: usize| t[k].is_finite() && blo[k].is_finite() && bhi[k].is_finite();
        for seg in segments(t.len(), ok) {
            let outline: Vec<(f64, f64)> = seg
                .clone()
                .map(|k| (t[k], bhi[k]))
                .chain(seg.rev().map(|k| (t[k], blo[k])))
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(
                outline,
                colour(2).mix(BAND_ALPHA).filled(),
            )))?;
        }
    }
    for (y, style) in [
        (&f.measured[i][r.clone()], BLACK.stroke_width(3)),
        (&f.simulated[i][r.clone()], colour(1).stroke_width(2)),
    ] {
        let ok = |k: usize| t[k].is_finite() && y[k].is_finite();
        for seg in segments(t.len(), ok) {
            let points: Vec<(f64, f64)> = seg.map(|k| (t[k], y[k])).collect();
            chart.draw_series(LineSeries::new(points, style))?;
        }
    }
    Ok(())
}

/// Whether the record's free run has a band for every channel.
fn has_band(f: &FreeRun) -> bool {
    let n = f.channels.len();
    f.band_lo.len() >= n && f.band_hi.len() >= n && n > 0
}

/// Samples every drawn series of `f` has (a record's series have the same length; a shorter one
/// is not read past).
fn common_len(f: &FreeRun) -> usize {
    let n = f.channels.len();
    let mut len = f.t.len();
    for s in f.measured[..n].iter().chain(&f.simulated[..n]) {
        len = len.min(s.len());
    }
    if has_band(f) {
        for s in f.band_lo[..n].iter().chain(&f.band_hi[..n]) {
            len = len.min(s.len());
        }
    }
    len
}

/// The caption of channel `i`'s whole-record panel: its fit, NRMSE and the band's coverage.
fn fit_caption(f: &FreeRun, i: usize) -> String {
    let c = &f.channels[i];
    format!(
        "{}: fit {:.1} %, NRMSE {:.3}{}{}",
        c.channel,
        c.fit_percent,
        c.nrmse,
        match &c.fit_draws {
            Some(p) if p.len() == 3 => format!(" (draws: {:.1} to {:.1} %)", p[0], p[2]),
            _ => String::new(),
        },
        c.coverage_percent
            .map_or(String::new(), |v| format!(", band covers {v:.1} %"))
    )
}

/// The legend of `free_run.svg`.
fn free_run_legend(f: &FreeRun, zoom: Option<(f64, f64)>) -> Vec<(Swatch, String)> {
    let mut entries = vec![
        (Swatch::Line(BLACK), "measured".to_string()),
        (
            Swatch::Line(colour(1)),
            match &f.discrepancy {
                Some(d) => format!(
                    "free run at θ_val with the discrepancy term ({} mode(s) beside the building)",
                    d.modes.len()
                ),
                None => "free run at θ_val".to_string(),
            },
        ),
    ];
    if has_band(f) {
        let what = if f.model_error.is_some() {
            "95 % predictive band (parameters + model error)"
        } else {
            "posterior draws, pointwise 95 %"
        };
        entries.push((Swatch::Band(colour(2), BAND_ALPHA), what.to_string()));
    }
    if zoom.is_some() {
        entries.push((
            Swatch::Band(colour(6), WINDOW_ALPHA),
            format!(
                "enlarged below: the {ZOOM_S:.0} s of strongest shaking (largest sum of measured² over all channels)"
            ),
        ));
    }
    entries
}

/// Draws `free_run.svg`: per channel a panel of the whole record and, when the record is
/// longer than 2 × `ZOOM_S`, one of its window of strongest shaking (`zoom_window`) below.
pub fn free_run(f: &FreeRun, out: &Path, who: &str) -> Result<PathBuf> {
    let n = f.channels.len();
    if n == 0 || f.measured.len() < n || f.simulated.len() < n {
        bail!("the record's free run has no channels to draw");
    }
    let len = common_len(f);
    let t = &f.t[..len];
    let zoom = zoom_window(t, &f.measured[..n]);
    let entries = free_run_legend(f, zoom);
    let (_, legend_h) = legend_layout(&entries);
    let rows = if zoom.is_some() { 2 * n } else { n };
    let path = out.join("free_run.svg");
    // The figure borrows its file's path until it is written; `path` is returned.
    let file = path.clone();
    let (root, grid, legend) = open_figure(
        &file,
        60 + legend_h + 280 * rows as u32,
        &format!("{who}: free run from rest under the measured ground motion"),
        legend_h,
    )?;
    let areas = grid.split_evenly((rows, 1));
    let whole = padded(finite_range(t.iter().copied()).unwrap_or((0.0, 1.0)));
    let mut areas = areas.iter();
    for i in 0..n {
        let name = &f.channels[i].channel;
        let mut panel = FreeRunPanel {
            caption: fit_caption(f, i),
            y_desc: format!("{name} [m/s²]"),
            channel: i,
            range: 0..len,
            x: whole,
            shade: zoom,
            f,
        };
        free_run_panel(areas.next().expect("a panel per row"), &panel)?;
        if let Some((a, b)) = zoom {
            panel.caption = format!("{name}, {a:.1} to {b:.1} s (shaded above), enlarged");
            panel.range = indices_within(t, (a, b));
            panel.x = (a, b);
            panel.shade = None;
            free_run_panel(areas.next().expect("a panel per row"), &panel)?;
        }
    }
    finish(&root, &legend, &entries, &file)?;
    Ok(path)
}

/// Draws one panel of `transfer.svg`: channel `name`'s |H1| on a log scale, the model's modes
/// in the band and the data's peaks.
fn transfer_panel(area: &Area<'_>, m: &ModalComparison, name: &str, mag: &[f64]) -> Result<()> {
    let f0 = m.frequency_hz[0];
    let f1 = *m.frequency_hz.last().expect("two bins");
    let logs: Vec<f64> = mag
        .iter()
        .map(|v| if *v > 0.0 { v.log10() } else { f64::NAN })
        .collect();
    let (lo, hi) = match finite_range(logs.iter().copied()) {
        Some((lo, hi)) if lo < hi => (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)),
        _ => (-1.0, 1.0),
    };
    let caption = format!("{name}: |H1| of floor / ground (absolute accelerations)");
    let mut chart = panel_chart_right(area, &caption, 80, RIGHT, f0..f1, lo..hi)?;
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("f [Hz]")
            .y_desc("log₁₀ |H1| [-]"),
    )?;
    let pts: Vec<(f64, f64)> = m
        .frequency_hz
        .iter()
        .zip(&logs)
        .filter(|(_, v)| v.is_finite())
        .map(|(f, v)| (*f, *v))
        .collect();
    chart.draw_series(LineSeries::new(pts, BLACK.stroke_width(2)))?;
    for f in modes_in_band(m) {
        chart.draw_series(DashedLineSeries::new(
            vec![(f, lo), (f, hi)],
            8,
            5,
            colour(1).stroke_width(2),
        ))?;
    }
    let peak_pts: Vec<(f64, f64)> = m
        .peaks
        .iter()
        .filter_map(|p| {
            let b = m
                .frequency_hz
                .iter()
                .position(|f| *f >= p.frequency_hz)
                .unwrap_or(logs.len() - 1);
            logs.get(b)
                .filter(|v| v.is_finite())
                .map(|v| (p.frequency_hz, *v))
        })
        .collect();
    chart.draw_series(
        peak_pts
            .iter()
            .map(|p| Circle::new(*p, 6, colour(0).filled())),
    )?;
    Ok(())
}

/// The model's natural frequencies inside the band of the transfer functions.
fn modes_in_band(m: &ModalComparison) -> impl Iterator<Item = f64> + '_ {
    let f0 = m.frequency_hz[0];
    let f1 = *m.frequency_hz.last().expect("two bins");
    m.modes
        .iter()
        .map(|mode| mode.frequency_hz)
        .filter(move |f| *f >= f0 && *f <= f1)
}

/// Draws `transfer.svg`: a panel per channel, the legend in a strip below them.
pub fn transfer(m: &ModalComparison, out: &Path, who: &str) -> Result<PathBuf> {
    if m.channels.is_empty() || m.frequency_hz.len() < 2 {
        bail!("the record holds no transfer functions");
    }
    let mut entries = vec![(Swatch::Line(BLACK), "measured |H1| (Welch)".to_string())];
    if modes_in_band(m).next().is_some() {
        entries.push((
            Swatch::Dashed(colour(1)),
            "identified model's modes (linearised)".to_string(),
        ));
    }
    if !m.peaks.is_empty() {
        entries.push((
            Swatch::Dot(colour(0)),
            "peaks read from the data (summed over floors)".to_string(),
        ));
    }
    let (_, legend_h) = legend_layout(&entries);
    let path = out.join("transfer.svg");
    // The figure borrows its file's path until it is written; `path` is returned.
    let file = path.clone();
    let (root, grid, legend) = open_figure(
        &file,
        60 + legend_h + 320 * m.channels.len() as u32,
        &format!("{who}: measured transfer functions and the model's modes"),
        legend_h,
    )?;
    let areas = grid.split_evenly((m.channels.len(), 1));
    for ((name, mag), area) in m.channels.iter().zip(&m.magnitude).zip(&areas) {
        transfer_panel(area, m, name, mag)?;
    }
    finish(&root, &legend, &entries, &file)?;
    Ok(path)
}

/// Most panels in one row of `shapes.svg`.
const SHAPES_PER_ROW: usize = 4;

/// The measured floors of a modal comparison's channels (named `a<floor>`).
fn channel_floors(m: &ModalComparison) -> Option<Vec<usize>> {
    m.channels
        .iter()
        .map(|c| c.strip_prefix('a').and_then(|f| f.parse().ok()))
        .collect()
}

/// The pairs `shapes.svg` draws: a model shape, an operating shape and a MAC.
fn shape_pairs(m: &ModalComparison) -> Vec<&ModePair> {
    m.pairs
        .iter()
        .filter(|p| p.mac.is_some() && !p.model_shape.is_empty() && !p.operating_shape.is_empty())
        .collect()
}

/// Draws one panel of `shapes.svg`: floor against shape component, the ground at 0.
fn shape_panel(area: &Area<'_>, p: &ModePair, floors: &[usize]) -> Result<()> {
    let n = p.model_shape.len();
    let measured = shapes::aligned(
        &shapes::on_floors(&p.model_shape, floors),
        &p.operating_shape,
    );
    let values = p
        .model_shape
        .iter()
        .chain(p.model_shape_95.iter().flatten())
        .chain(&measured)
        .copied()
        .chain([0.0]);
    let (x0, x1) = padded(finite_range(values).unwrap_or((-1.0, 1.0)));
    let caption = format!(
        "mode {} ({:.2} Hz): MAC {:.3}{}",
        p.mode,
        p.model_hz,
        p.mac.unwrap_or(f64::NAN),
        p.mac_95
            .map_or(String::new(), |[a, b]| format!(" [{a:.3}, {b:.3}]"))
    );
    let mut chart = panel_chart_right(area, &caption, 56, RIGHT, x0..x1, -0.3..n as f64 + 0.3)?;
    let span = x1 - x0;
    draw_mesh(
        chart
            .configure_mesh()
            .x_desc("shape [-]")
            .y_desc("floor")
            .x_labels(6)
            .x_label_formatter(&|v| tick(*v, span))
            .y_labels(n + 1)
            .y_label_formatter(&|v| format!("{v:.0}")),
    )?;
    for (j, [lo, hi]) in p.model_shape_95.iter().enumerate() {
        let y = (j + 1) as f64;
        chart.draw_series(LineSeries::new(
            vec![(*lo, y), (*hi, y)],
            colour(2).stroke_width(8),
        ))?;
    }
    let line: Vec<(f64, f64)> = std::iter::once((0.0, 0.0))
        .chain(
            p.model_shape
                .iter()
                .enumerate()
                .map(|(j, v)| (*v, (j + 1) as f64)),
        )
        .collect();
    chart.draw_series(LineSeries::new(line, colour(1).stroke_width(2)))?;
    chart.draw_series(
        measured
            .iter()
            .zip(floors)
            .filter(|(v, _)| v.is_finite())
            .map(|(v, f)| Circle::new((*v, *f as f64), 6, colour(0).filled())),
    )?;
    Ok(())
}

/// Draws `shapes.svg`: a panel per mode with a MAC, side by side, the legend below.
pub fn shapes(m: &ModalComparison, out: &Path, who: &str) -> Result<PathBuf> {
    let pairs = shape_pairs(m);
    let Some(floors) = channel_floors(m) else {
        bail!("the record's channels are not named by floor");
    };
    if pairs.is_empty() {
        bail!("the record holds no mode shape compared with a measured one");
    }
    let mut entries = vec![(
        Swatch::Line(colour(1)),
        "identified model's undamped mode shape (θ_val)".to_string(),
    )];
    if pairs.iter().any(|p| !p.model_shape_95.is_empty()) {
        entries.push((
            Swatch::Bar(colour(2)),
            "its central 95 % per floor over posterior draws".to_string(),
        ));
    }
    entries.push((
        Swatch::Dot(colour(0)),
        "measured operating shape (Im H1 at the paired peak), scaled onto the model's".to_string(),
    ));
    let (_, legend_h) = legend_layout(&entries);
    let path = out.join("shapes.svg");
    let file = path.clone();
    // At most `SHAPES_PER_ROW` panels side by side (each at least 300 px wide), as many rows
    // as that takes: a ten-storey building's ten modes in three rows.
    let cols = pairs.len().min(SHAPES_PER_ROW);
    let rows = pairs.len().div_ceil(cols);
    let (root, grid, legend) = open_figure(
        &file,
        60 + legend_h + 420 * rows as u32,
        &format!("{who}: mode shapes against the measured operating shapes"),
        legend_h,
    )?;
    let areas = grid.split_evenly((rows, cols));
    for (p, area) in pairs.iter().zip(&areas) {
        shape_panel(area, p, &floors)?;
    }
    finish(&root, &legend, &entries, &file)?;
    Ok(path)
}

/// Draws both figures of a record that has them; notes what is missing.
pub fn draw(
    free: Option<&FreeRun>,
    modal: Option<&ModalComparison>,
    out: &Path,
    who: &str,
    written: &mut Vec<PathBuf>,
    skipped: &mut Vec<String>,
) -> Result<()> {
    if free.is_none() && modal.is_none() {
        // A record of simulated data or of a sweep: validated against its truth instead.
        return Ok(());
    }
    match free {
        Some(f) => written.push(free_run(f, out, who)?),
        None => skipped.push(
            "free_run.svg: the record has no free run (field-data runs of `sysid filter` have one)"
                .into(),
        ),
    }
    match modal {
        Some(m) if !m.channels.is_empty() => {
            written.push(transfer(m, out, who)?);
            if shape_pairs(m).is_empty() {
                skipped.push(
                    "shapes.svg: no mode shape compared with a measured one (it needs two \
                     storeys or more, two measured floors or more and a paired peak)"
                        .into(),
                );
            } else {
                written.push(shapes(m, out, who)?);
            }
        }
        Some(m) => skipped.push(format!(
            "transfer.svg: no transfer functions ({})",
            m.errors.join("; ")
        )),
        None => skipped.push(
            "transfer.svg: the record has no modal comparison (field-data runs of `sysid filter` have one)"
                .into(),
        ),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_zoom_window_holds_the_strongest_shaking() {
        // 60 s at 10 Hz: quiet, a burst on channel 2 around t = 41 s, quiet.
        let t: Vec<f64> = (0..600).map(|k| k as f64 * 0.1).collect();
        let quiet = vec![0.1; t.len()];
        let burst: Vec<f64> = t
            .iter()
            .map(|t| if (40.0..42.0).contains(t) { 5.0 } else { 0.1 })
            .collect();
        let (a, b) = zoom_window(&t, &[quiet.clone(), burst]).unwrap();
        assert!((b - a - ZOOM_S).abs() < 1e-12);
        assert!(a <= 40.0 && b >= 41.9, "window {a}..{b}");
        // Non-finite values count 0; a record of 2 × ZOOM_S or less is drawn whole.
        let mut gaps = quiet.clone();
        gaps[10] = f64::NAN;
        assert!(zoom_window(&t, &[gaps]).is_some());
        assert_eq!(zoom_window(&t[..101], &[quiet[..101].to_vec()]), None);
        assert_eq!(zoom_window(&[], &[]), None);
    }

    #[test]
    fn window_indices_reach_its_edges() {
        let t: Vec<f64> = (0..10).map(|k| k as f64).collect();
        assert_eq!(indices_within(&t, (2.5, 5.5)), 2..7);
        assert_eq!(indices_within(&t, (2.0, 5.0)), 2..6);
        assert_eq!(indices_within(&t, (-1.0, 20.0)), 0..10);
    }
}
