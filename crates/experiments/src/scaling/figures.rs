//! The scaling study's two figures, drawn from the cells: the cost per particle-step against
//! the marginalised dimension (log–log, one fitted line per algorithm) and the stiffness and
//! damping errors against the storey count.

use std::path::Path;

use crate::error::{bail, Context, Result};
use plotters::prelude::*;

use super::{is_reference, Cell, CostFit};
use identify::figures::{style, CAPTION_SIZE, DESC_SIZE, FONT, LABEL_SIZE, TITLE_SIZE, WIDTH};
use identify::pipeline::Algorithm;

fn label_of(name: &str) -> &'static str {
    name.parse::<Algorithm>().map_or("?", |a| a.label())
}

/// The decades spanning `[lo, hi]` (positive), one decade of margin where the data touch.
fn log_span(lo: f64, hi: f64) -> (f64, f64) {
    let lo = 10f64.powf((lo * 0.8).log10().floor());
    let hi = 10f64.powf((hi * 1.25).log10().ceil());
    (lo, hi)
}

fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(())
}

/// The legend of a chart's labelled series, boxed in its upper left corner.
fn series_labels<'a>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>,
) -> Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, DESC_SIZE))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Cost per particle-step (µs) against the marginalised dimension, log–log; the bootstrap PF,
/// which marginalises nothing, against its sampled dimension. The legend gives each fitted
/// slope.
pub fn cost(fits: &[CostFit], path: &Path) -> Result<()> {
    let all: Vec<(f64, f64)> = fits.iter().flat_map(|f| f.points.clone()).collect();
    if all.is_empty() {
        bail!("cost figure {}: no cell has timed runs", path.display());
    }
    let (x0, x1) = log_span(
        all.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
        all.iter().map(|p| p.0).fold(0.0, f64::max),
    );
    let (y0, y1) = log_span(
        all.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
        all.iter().map(|p| p.1).fold(0.0, f64::max),
    );
    create_parent(path)?;
    let root = SVGBackend::new(path, (WIDTH, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Cost per particle-step against the marginalised dimension",
            (FONT, TITLE_SIZE),
        )
        .margin(20)
        .x_label_area_size(70)
        .y_label_area_size(100)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("marginalised dimension n (bootstrap PF: sampled dimension)")
        .y_desc(if fits.iter().all(|f| f.cpu) {
            "CPU µs per particle-step"
        } else {
            "µs per particle-step (wall time where CPU time is missing)"
        })
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, LABEL_SIZE))
        .draw()?;
    for f in fits {
        let c = style::for_label(&f.algorithm, 0).colour;
        let label = match f.slope {
            Some(s) => format!("{}: slope {s:.2}", label_of(&f.algorithm)),
            None => format!("{} (one size: no slope)", label_of(&f.algorithm)),
        };
        chart
            .draw_series(
                f.points
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 7, c.filled())),
            )?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 10, y), 7, c.filled()));
        if let (Some(s), Some(b)) = (f.slope, f.intercept) {
            let xs = f.points.iter().map(|p| p.0);
            let (lo, hi) = (
                xs.clone().fold(f64::INFINITY, f64::min),
                xs.fold(0.0, f64::max),
            );
            let line: Vec<(f64, f64)> = (0..=20)
                .map(|i| {
                    let x = lo * (hi / lo).powf(i as f64 / 20.0);
                    (x, (b + s * x.ln()).exp())
                })
                .collect();
            chart.draw_series(LineSeries::new(line, c.stroke_width(2)))?;
        }
    }
    // A reference line of slope 2 through the MPF-EKF2's smallest point.
    if let Some(&(x, y)) = fits
        .iter()
        .find(|f| f.algorithm == Algorithm::MpfEkf2.name())
        .and_then(|f| f.points.first())
    {
        let grey = RGBColor(120, 120, 120);
        let line: Vec<(f64, f64)> = (0..=20)
            .map(|i| {
                let xi = x * (x1 / x).powf(i as f64 / 20.0);
                (xi, y * (xi / x).powi(2))
            })
            .filter(|p| p.1 <= y1)
            .collect();
        chart
            .draw_series(DashedLineSeries::new(line, 6, 6, grey.stroke_width(2)))?
            .label("n² (reference)")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(2))
            });
    }
    series_labels(&mut chart)?;
    root.present()?;
    Ok(())
}

/// Mean relative error of k and of c (%, log scale) against the storey count, one line per
/// algorithm, for the chains with hysteresis at the base and every storey measured; error bars
/// of ± one run-to-run s.d. (clipped at the axis bottom).
pub(crate) fn accuracy(cells: &[Cell], path: &Path) -> Result<()> {
    let reference: Vec<&Cell> = cells
        .iter()
        .filter(|c| is_reference(c) && c.runs > c.failed)
        .collect();
    if reference.is_empty() {
        bail!(
            "accuracy figure {}: no cell has completed runs",
            path.display()
        );
    }
    let values = reference
        .iter()
        .flat_map(|c| [c.k_error_mean, c.c_error_mean])
        .filter(|v| v.is_finite() && *v > 0.0)
        .map(|v| 100.0 * v);
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let (y0, y1) = log_span(lo, hi);
    let n_max = reference.iter().map(|c| c.storeys).max().unwrap_or(3) as f64;
    create_parent(path)?;
    let root = SVGBackend::new(path, (WIDTH, 760)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        "Identification error against the storey count (Bouc–Wen at storey 1, every storey measured)",
        (FONT, CAPTION_SIZE),
    )?;
    let panels = root.split_evenly((1, 2));
    for (panel, (group, desc)) in panels.iter().zip([
        ('k', "stiffness k: mean relative error (%)"),
        ('c', "damping c: mean relative error (%)"),
    ]) {
        let mut chart = ChartBuilder::on(panel)
            .margin(20)
            .x_label_area_size(60)
            .y_label_area_size(90)
            .build_cartesian_2d((2.5..n_max * 1.3).log_scale(), (y0..y1).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("storeys N")
            .y_desc(desc)
            .axis_desc_style((FONT, DESC_SIZE))
            .label_style((FONT, LABEL_SIZE))
            .draw()?;
        for a in Algorithm::ALL {
            let mut pts: Vec<(f64, f64, f64)> = reference
                .iter()
                .filter(|c| c.algorithm == a.name())
                .map(|c| {
                    let (m, s) = if group == 'k' {
                        (c.k_error_mean, c.k_error_sd)
                    } else {
                        (c.c_error_mean, c.c_error_sd)
                    };
                    (c.storeys as f64, 100.0 * m, 100.0 * s)
                })
                .filter(|p| p.1.is_finite() && p.1 > 0.0)
                .collect();
            if pts.is_empty() {
                continue;
            }
            pts.sort_by(|p, q| p.0.total_cmp(&q.0));
            let c = style::algorithm_colour(a);
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|p| (p.0, p.1)),
                    c.stroke_width(3),
                ))?
                .label(a.label())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                });
            chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 6, c.filled())))?;
            chart.draw_series(pts.iter().filter(|p| p.2 > 0.0).map(|p| {
                let bottom = (p.1 - p.2).max(y0);
                let top = (p.1 + p.2).min(y1);
                PathElement::new(vec![(p.0, bottom), (p.0, top)], c.stroke_width(2))
            }))?;
        }
        series_labels(&mut chart)?;
    }
    root.present()?;
    Ok(())
}
