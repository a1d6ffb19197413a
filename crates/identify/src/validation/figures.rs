//! Figures of a free run and a modal comparison, drawn from a record only:
//!
//! - `free_run.svg`: per channel the measured acceleration, the free run at θ_val and the
//!   pointwise 95 % predictive band (its two edges: the posterior draws' spread, widened by the
//!   model error where the record has one), with the share of the record it covers;
//! - `transfer.svg`: per channel the measured |H1| (log scale) with the identified model's
//!   modes as dashed vertical lines and the peaks read from the data as dots.

use std::path::{Path, PathBuf};

use crate::error::{bail, Context, Result};
use plotters::prelude::*;

use super::{FreeRun, ModalComparison};
use crate::figures::{self, colour, Panel, Series, CAPTION_SIZE, DESC_SIZE, FONT, LABEL_SIZE};

/// Draws `free_run.svg`.
pub fn free_run(f: &FreeRun, out: &Path, who: &str) -> Result<PathBuf> {
    let with_band = !f.band_lo.is_empty();
    let panels: Vec<Panel<'_>> = f
        .channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut series = vec![
                Series {
                    label: "measured".into(),
                    t: &f.t,
                    y: &f.measured[i],
                    colour: None,
                },
                Series {
                    label: "free run at θ_val".into(),
                    t: &f.t,
                    y: &f.simulated[i],
                    colour: Some(1),
                },
            ];
            if with_band {
                let what = if f.model_error.is_some() {
                    "95 % predictive band (parameters + model error)"
                } else {
                    "posterior draws, pointwise 95 %"
                };
                for (edge, y) in [("lower", &f.band_lo[i]), ("upper", &f.band_hi[i])] {
                    series.push(Series {
                        label: format!("{what}, {edge} edge"),
                        t: &f.t,
                        y,
                        colour: Some(2),
                    });
                }
            }
            Panel {
                caption: format!(
                    "{}: fit {:.1} %, NRMSE {:.3}{}{}",
                    c.channel,
                    c.fit_percent,
                    c.nrmse,
                    match &c.fit_draws {
                        Some(p) if p.len() == 3 =>
                            format!(" (draws: {:.1} to {:.1} %)", p[0], p[2]),
                        _ => String::new(),
                    },
                    c.coverage_percent
                        .map_or(String::new(), |v| format!(", band covers {v:.1} %"))
                ),
                y_desc: format!("{} [m/s²]", c.channel),
                series,
                reference: Vec::new(),
            }
        })
        .collect();
    let path = out.join("free_run.svg");
    figures::time_series(
        &panels,
        &path,
        &format!("{who}: free run from rest under the measured ground motion"),
    )?;
    Ok(path)
}

/// Draws `transfer.svg`.
pub fn transfer(m: &ModalComparison, out: &Path, who: &str) -> Result<PathBuf> {
    if m.channels.is_empty() || m.frequency_hz.len() < 2 {
        bail!("the record holds no transfer functions");
    }
    let path = out.join("transfer.svg");
    let height = 80 + 320 * m.channels.len() as u32;
    let file = path.clone();
    let root = SVGBackend::new(&file, (figures::WIDTH, height)).into_drawing_area();
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(60);
    title.titled(
        &format!("{who}: measured transfer functions and the model's modes"),
        (FONT, figures::TITLE_SIZE),
    )?;
    let areas = body.split_evenly((m.channels.len(), 1));
    let f0 = m.frequency_hz[0];
    let f1 = *m.frequency_hz.last().expect("two bins");
    for ((name, mag), area) in m.channels.iter().zip(&m.magnitude).zip(&areas) {
        let logs: Vec<f64> = mag
            .iter()
            .map(|v| if *v > 0.0 { v.log10() } else { f64::NAN })
            .collect();
        let (lo, hi) = logs
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let (lo, hi) = if lo < hi {
            (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
        } else {
            (-1.0, 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{name}: |H1| of floor / ground (absolute accelerations)"),
                (FONT, CAPTION_SIZE),
            )
            .margin(8)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d(f0..f1, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("f [Hz]")
            .y_desc("log₁₀ |H1| [-]")
            .label_style((FONT, LABEL_SIZE))
            .axis_desc_style((FONT, DESC_SIZE))
            .light_line_style(WHITE)
            .draw()?;
        let pts: Vec<(f64, f64)> = m
            .frequency_hz
            .iter()
            .zip(&logs)
            .filter(|(_, v)| v.is_finite())
            .map(|(f, v)| (*f, *v))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, BLACK.stroke_width(2)))?
            .label("measured |H1| (Welch)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        let mut labelled = false;
        for mode in &m.modes {
            let f = mode.frequency_hz;
            if f < f0 || f > f1 {
                continue;
            }
            let s = chart.draw_series(DashedLineSeries::new(
                vec![(f, lo), (f, hi)],
                8,
                5,
                colour(1).stroke_width(2),
            ))?;
            if !labelled {
                s.label("identified model's modes (linearised)")
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour(1).stroke_width(2))
                    });
                labelled = true;
            }
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
        chart
            .draw_series(
                peak_pts
                    .iter()
                    .map(|p| Circle::new(*p, 6, colour(0).filled())),
            )?
            .label("peaks read from the data (summed over floors)")
            .legend(|(x, y)| Circle::new((x + 10, y), 6, colour(0).filled()));
        chart
            .configure_series_labels()
            .label_font((FONT, LABEL_SIZE))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
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
        Some(m) if !m.channels.is_empty() => written.push(transfer(m, out, who)?),
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
