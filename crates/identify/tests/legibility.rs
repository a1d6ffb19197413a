//! Legibility of the figures, checked on the drawn figures: each SVG is rendered to pixels with
//! resvg and its elements are read back. The renderer is built without text support (the fonts a
//! machine has vary, and a test must not depend on them), so no check reads the pixels of text;
//! a text's extent is estimated from its position, anchor, font size and length at
//! [`EM_PER_CHAR_CHECK`] em per character.
//!
//! What is checked, on figures drawn from synthetic records shaped like the shake-table frame's
//! (three floors, 100 s, bursts of shaking, a wide predictive band, a noisy transfer function
//! up to the band's end):
//! - every text lies inside the image, and no two texts overlap (a caption wider than its panel
//!   runs into its neighbour or past the figure's edge, where a viewer cuts it);
//! - nothing is drawn under any text: with the text left out, the pixels of every text's extent
//!   are white (a legend inside a panel sits on the curves, and its labels would fail);
//! - the free run at θ_val shows its own colour at ≥ 90 % of its points in the rendered PNG (a
//!   band drawn over it hides it);
//! - every channel's free run is also drawn at ≥ 2 px per sample (100 s in one panel are a
//!   solid blob; the window of strongest shaking, enlarged, shows each cycle).
//!
//! Set `FIGURE_PNG_DIR` to also write the rendered PNGs (without text) there, to look at them.

use std::path::{Path, PathBuf};

use identify::figures::convergence;
use identify::observe::Trace;
use identify::record::validation::{ChannelFit, FreeRun, Integrator, ModalComparison};
use identify::record::{RunRecord, Timing};
use identify::validation::figures::{free_run, shapes, transfer};
use identify::validation::spectral::Peak;
use models::modal::Mode;
use models::sensors::MeasurementKind;
use resvg::tiny_skia::{Pixmap, Transform};
use resvg::usvg;

/// Estimated advance of one character, in em: about DejaVu Sans's average (0.55–0.6 em over
/// the figures' labels), among the widest sans-serif fonts a viewer may pick.
const EM_PER_CHAR_CHECK: f64 = 0.6;

/// A channel value at least this far below 255 makes a pixel "not white" (anti-aliased edges of
/// a curve 1 px away from a text's extent stay above it).
const WHITE_MIN: u8 = 240;

/// The free run's colour (the palette's second, `#D55E00`) and how far (max over RGB) a
/// rendered pixel may be from it to count as showing it.
const FREE_RUN_RGB: (u8, u8, u8) = (0xD5, 0x5E, 0x00);
const COLOUR_TOLERANCE: i32 = 40;

/// A fresh output directory, removed when the guard is dropped.
fn out_dir() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("legibility-test-")
        .tempdir()
        .unwrap()
}

// ---------------------------------------------------------------------------------------------
// Reading and rendering a figure
// ---------------------------------------------------------------------------------------------

/// An axis-aligned box in px: x0 ≤ x ≤ x1, y0 ≤ y ≤ y1.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Bounds {
    fn overlaps(&self, o: &Bounds) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    fn shrunk(&self, by: f64) -> Bounds {
        Bounds {
            x0: self.x0 + by,
            y0: self.y0 + by,
            x1: self.x1 - by,
            y1: self.y1 - by,
        }
    }
}

/// One `<text>` element and its estimated extent.
#[derive(Debug)]
struct TextBox {
    text: String,
    bounds: Bounds,
}

/// A figure: its SVG text, its elements and its pixels rendered without text.
struct Figure {
    name: String,
    width: f64,
    height: f64,
    texts: Vec<TextBox>,
    /// `<polyline>`s: stroke colour (`#RRGGBB`) and points.
    polylines: Vec<(String, Vec<(f64, f64)>)>,
    pixels: Pixmap,
}

fn attr(n: &roxmltree::Node<'_, '_>, name: &str) -> Option<f64> {
    n.attribute(name).and_then(|v| v.trim().parse().ok())
}

/// The extent of a `<text>` as plotters' SVG backend writes it: `x`, `y`, a `dy` that places
/// the text's top (`0.76em`), centre (`0.5ex`) or bottom (`-0.5ex`) at `y`, `text-anchor` and an
/// optional `rotate(a, x, y)`.
fn text_box(n: &roxmltree::Node<'_, '_>) -> Option<TextBox> {
    let text = n.text()?.trim().to_string();
    let (x, y, size) = (attr(n, "x")?, attr(n, "y")?, attr(n, "font-size")?);
    let w = text.chars().count() as f64 * EM_PER_CHAR_CHECK * size;
    let (dx0, dx1) = match n.attribute("text-anchor").unwrap_or("start") {
        "middle" => (-w / 2.0, w / 2.0),
        "end" => (-w, 0.0),
        _ => (0.0, w),
    };
    // Glyphs reach about 0.76 em above the baseline and 0.24 em below it.
    let (dy0, dy1) = match n.attribute("dy").unwrap_or("") {
        "0.76em" => (0.0, size),
        "0.5ex" => (-0.5 * size, 0.5 * size),
        "-0.5ex" => (-size, 0.0),
        other => panic!("text '{text}': unknown dy '{other}'"),
    };
    let angle = n
        .attribute("transform")
        .and_then(|t| t.strip_prefix("rotate("))
        .and_then(|t| t.split(',').next())
        .and_then(|a| a.trim().parse::<f64>().ok())
        .unwrap_or(0.0)
        .to_radians();
    let (c, s) = (angle.cos(), angle.sin());
    let corners = [(dx0, dy0), (dx0, dy1), (dx1, dy0), (dx1, dy1)]
        .map(|(dx, dy)| (x + dx * c - dy * s, y + dx * s + dy * c));
    let xs = corners.map(|p| p.0);
    let ys = corners.map(|p| p.1);
    let min = |v: [f64; 4]| v.into_iter().fold(f64::INFINITY, f64::min);
    let max = |v: [f64; 4]| v.into_iter().fold(f64::NEG_INFINITY, f64::max);
    Some(TextBox {
        text,
        bounds: Bounds {
            x0: min(xs),
            y0: min(ys),
            x1: max(xs),
            y1: max(ys),
        },
    })
}

fn points(list: &str) -> Vec<(f64, f64)> {
    list.split_whitespace()
        .filter_map(|p| {
            let (x, y) = p.split_once(',')?;
            Some((x.parse().ok()?, y.parse().ok()?))
        })
        .collect()
}

/// Reads and renders the figure at `path`.
fn figure(path: &Path) -> Figure {
    let svg = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&svg).unwrap();
    let root = doc.root_element();
    let texts = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| text_box(&n))
        .collect();
    let polylines = doc
        .descendants()
        .filter(|n| n.has_tag_name("polyline"))
        .map(|n| {
            (
                n.attribute("stroke").unwrap_or("").to_uppercase(),
                points(n.attribute("points").unwrap_or("")),
            )
        })
        .collect();
    // No fonts are loaded (and the text feature is off): the text is left out of the pixels.
    let tree = usvg::Tree::from_str(&svg, &usvg::Options::default()).unwrap();
    let size = tree.size().to_int_size();
    let mut pixels = Pixmap::new(size.width(), size.height()).unwrap();
    resvg::render(&tree, Transform::default(), &mut pixels.as_mut());
    if let Some(dir) = std::env::var_os("FIGURE_PNG_DIR") {
        let name = path.file_stem().unwrap().to_string_lossy();
        pixels
            .save_png(PathBuf::from(dir).join(format!("{name}.png")))
            .unwrap();
    }
    Figure {
        name: path.file_name().unwrap().to_string_lossy().into_owned(),
        width: attr(&root, "width").unwrap(),
        height: attr(&root, "height").unwrap(),
        texts,
        polylines,
        pixels,
    }
}

/// RGB of pixel (x, y) (opaque: the figures fill a white background).
fn rgb(p: &Pixmap, x: i64, y: i64) -> Option<(u8, u8, u8)> {
    if x < 0 || y < 0 {
        return None;
    }
    p.pixel(x as u32, y as u32)
        .map(|c| (c.red(), c.green(), c.blue()))
}

// ---------------------------------------------------------------------------------------------
// The checks
// ---------------------------------------------------------------------------------------------

/// Guards against text cut at the figure's edge (a caption wider than its panel at the right
/// end of a row): every text's extent lies inside the image.
fn texts_outside_the_image(f: &Figure) -> Vec<String> {
    f.texts
        .iter()
        .filter(|t| {
            let b = t.bounds;
            b.x0 < -0.5 || b.y0 < -0.5 || b.x1 > f.width + 0.5 || b.y1 > f.height + 0.5
        })
        .map(|t| format!("'{}' at {:?}", t.text, t.bounds))
        .collect()
}

/// Guards against texts running into each other (neighbouring captions, crowded tick labels):
/// no two texts' extents overlap (shrunk by 1 px, so that touching is allowed).
fn overlapping_texts(f: &Figure) -> Vec<String> {
    let mut out = Vec::new();
    for (i, a) in f.texts.iter().enumerate() {
        for b in &f.texts[i + 1..] {
            if a.bounds.shrunk(1.0).overlaps(&b.bounds.shrunk(1.0)) {
                out.push(format!("'{}' and '{}'", a.text, b.text));
            }
        }
    }
    out
}

/// Guards against text drawn over curves, bands or markers (a legend inside a panel, a caption
/// on the data): the non-white pixels inside each text's extent (shrunk by 2 px, for the
/// anti-aliased edge of a neighbouring line) in the rendering without text, per text.
fn drawing_under_texts(f: &Figure) -> Vec<(String, usize)> {
    f.texts
        .iter()
        .filter_map(|t| {
            let b = t.bounds.shrunk(2.0);
            let mut count = 0;
            for y in b.y0.ceil() as i64..=b.y1.floor() as i64 {
                for x in b.x0.ceil() as i64..=b.x1.floor() as i64 {
                    if rgb(&f.pixels, x, y).is_some_and(|(r, g, b)| r.min(g).min(b) < WHITE_MIN) {
                        count += 1;
                    }
                }
            }
            (count > 0).then(|| (t.text.clone(), count))
        })
        .collect()
}

/// Every legibility check on text; panics naming the figure and what failed.
fn assert_texts_legible(f: &Figure) {
    let outside = texts_outside_the_image(f);
    let overlaps = overlapping_texts(f);
    let under = drawing_under_texts(f);
    eprintln!(
        "{}: {} text(s) outside the image, {} overlapping pair(s), {} non-white px under {} text(s)",
        f.name,
        outside.len(),
        overlaps.len(),
        under.iter().map(|(_, n)| n).sum::<usize>(),
        under.len()
    );
    assert!(
        outside.is_empty(),
        "{}: text cut at the edge: {outside:?}",
        f.name
    );
    assert!(
        overlaps.is_empty(),
        "{}: texts overlap: {overlaps:?}",
        f.name
    );
    assert!(
        under.is_empty(),
        "{}: drawing under text (text, non-white px): {under:?}",
        f.name
    );
}

fn near(c: (u8, u8, u8), want: (u8, u8, u8)) -> bool {
    let d = |a: u8, b: u8| (a as i32 - b as i32).abs();
    d(c.0, want.0).max(d(c.1, want.1)).max(d(c.2, want.2)) <= COLOUR_TOLERANCE
}

/// The polylines of the free run (its colour; not the legend's two-point swatch) with, for each,
/// the share of its points where the free run's colour shows (in one of the four pixels that
/// meet at the point: a 2 px line centred there covers them all, whatever its direction) and
/// its horizontal px per sample.
fn free_run_lines(f: &Figure) -> Vec<(f64, f64)> {
    let stroke = format!(
        "#{:02X}{:02X}{:02X}",
        FREE_RUN_RGB.0, FREE_RUN_RGB.1, FREE_RUN_RGB.2
    );
    f.polylines
        .iter()
        .filter(|(s, pts)| *s == stroke && pts.len() > 2)
        .map(|(_, pts)| {
            let shown = pts
                .iter()
                .filter(|(x, y)| {
                    let (x, y) = (x.round() as i64, y.round() as i64);
                    [(x - 1, y - 1), (x, y - 1), (x - 1, y), (x, y)]
                        .iter()
                        .any(|&(x, y)| rgb(&f.pixels, x, y).is_some_and(|c| near(c, FREE_RUN_RGB)))
                })
                .count();
            let (lo, hi) = pts
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p.0), hi.max(p.0))
                });
            (
                shown as f64 / pts.len() as f64,
                (hi - lo) / (pts.len() - 1) as f64,
            )
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Synthetic records shaped like the shake-table frame's
// ---------------------------------------------------------------------------------------------

/// A deterministic noise in [−1, 1] (no random stream: the figures are the same every run).
fn noise(k: usize, c: usize) -> f64 {
    let h = (k as u64 + 1)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(c as u64 * 0xBF58_476D_1CE4_E5B9);
    ((h >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

/// Three bursts of shaking (at 20, 38 and 56 s, decaying over 4 s) on a low ambient level from
/// 10 s, as the frame's `northridge` record.
fn envelope(t: f64) -> f64 {
    let ambient = if t > 10.0 { 1.0 } else { 0.0 };
    [(20.0, 15.0), (38.0, 16.0), (56.0, 17.0)]
        .iter()
        .map(|&(t0, a)| {
            if t >= t0 {
                a * (-(t - t0) / 4.0).exp()
            } else {
                0.0
            }
        })
        .sum::<f64>()
        + ambient
}

/// A free run of three floors over 100 s at 50 Hz: the model's response is the measured one
/// slightly off in phase and amplitude; the band's edges are the spread of two phase-shifted
/// draws widened by a model error, so that they oscillate with the response, as a pointwise
/// band of draws does.
fn synthetic_free_run() -> FreeRun {
    let t: Vec<f64> = (0..5000).map(|k| k as f64 * 0.02).collect();
    let wave = |t: f64, shift: f64, c: usize| {
        let w = 2.0 * std::f64::consts::PI;
        envelope(t) * ((w * 3.7 * t + shift + c as f64).sin() + 0.4 * (w * 11.1 * t + shift).sin())
    };
    let channel = |c: usize| {
        let measured: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(k, &t)| wave(t, 0.0, c) + 0.3 * noise(k, c))
            .collect();
        let simulated: Vec<f64> = t.iter().map(|&t| 0.9 * wave(t, 0.15, c)).collect();
        let (a, b): (Vec<f64>, Vec<f64>) = t
            .iter()
            .map(|&t| (0.8 * wave(t, -0.3, c), wave(t, 0.5, c)))
            .unzip();
        let spread = |t: f64| 0.5 + 0.15 * envelope(t);
        let lo = (0..t.len())
            .map(|k| a[k].min(b[k]) - spread(t[k]))
            .collect();
        let hi = (0..t.len())
            .map(|k| a[k].max(b[k]) + spread(t[k]))
            .collect();
        (measured, simulated, lo, hi)
    };
    let (mut measured, mut simulated, mut band_lo, mut band_hi) = (vec![], vec![], vec![], vec![]);
    let mut channels = Vec::new();
    for c in 0..3 {
        let (m, s, lo, hi) = channel(c);
        measured.push(m);
        simulated.push(s);
        band_lo.push(lo);
        band_hi.push(hi);
        channels.push(ChannelFit {
            channel: format!("a{}", c + 1),
            fit_percent: 67.7 + c as f64,
            nrmse: 0.323,
            physical_fit_percent: None,
            fit_draws: Some(vec![35.5, 60.0, 67.7]),
            coverage_percent: Some(93.5),
        });
    }
    FreeRun {
        method: "synthetic".into(),
        integrator: Integrator::Rk4,
        measurement: MeasurementKind::Absolute,
        channels,
        band: None,
        band_error: None,
        model_error: None,
        discrepancy: None,
        every: 1,
        t,
        measured,
        simulated,
        band_lo,
        band_hi,
    }
}

/// Transfer functions of three floors from 0.1 to 60 Hz: three resonances (3.7, 11.1, 16.5 Hz)
/// over a floor falling from 1 to 0.05 with ±0.4 decades of noise, which reaches the upper
/// right of each panel as the measured |H1| of the frame does.
fn synthetic_modal() -> ModalComparison {
    let f: Vec<f64> = (1..=600).map(|k| k as f64 * 0.1).collect();
    let modes = [3.7, 11.1, 16.5];
    let magnitude = (0..3)
        .map(|c| {
            f.iter()
                .enumerate()
                .map(|(k, &f)| {
                    let peaks: f64 = modes
                        .iter()
                        .map(|&m| 1.0 / (((f / m).powi(2) - 1.0).powi(2) + 0.002).sqrt())
                        .sum();
                    let floor = 10f64.powf(-1.3 * (f / 60.0) + 0.4 * noise(k, c));
                    peaks / (1.0 + f) + floor
                })
                .collect()
        })
        .collect();
    ModalComparison {
        modes: modes
            .iter()
            .map(|&m| Mode {
                frequency_hz: m * 0.99,
                damped_hz: m * 0.99,
                damping_ratio: 0.01,
            })
            .collect(),
        frequency_hz: f,
        channels: (1..=3).map(|c| format!("a{c}")).collect(),
        magnitude,
        peaks: modes
            .iter()
            .map(|&m| Peak {
                frequency_hz: m,
                magnitude: 10.0,
            })
            .collect(),
        ..ModalComparison::default()
    }
}

/// The parameters of the README's 5-storey building with one Bouc–Wen element: a 4 × 4 grid
/// of panels 300 px wide.
const NAMES: [&str; 13] = [
    "k1", "k2", "k3", "k4", "k5", "c1", "c2", "c3", "c4", "c5", "beta", "gamma", "n",
];

/// A run whose trace relaxes to the truth, with γ's s.d. so wide that its band is clipped (its
/// panel's caption says so: the longest caption of the figure, in the grid's last column).
fn synthetic_run() -> RunRecord {
    let truth: Vec<f64> = NAMES
        .iter()
        .map(|n| match n.as_bytes()[0] {
            b'k' => 8.0,
            b'c' => 0.25,
            _ => 2.0,
        })
        .collect();
    let mut record = RunRecord {
        experiment: "legibility".into(),
        algorithm: "mpf-ekf2".into(),
        seed: 1,
        run: 0,
        particles: 500,
        param_names: NAMES.iter().map(|s| s.to_string()).collect(),
        theta_true: Some(truth.clone()),
        rel_error: None,
        theta_val: truth.clone(),
        window: 10,
        theta_sd_final: truth.clone(),
        loglik: -1.0,
        steps_total: 100,
        steps_completed: 100,
        ess_min: 500.0,
        ess_mean: 500.0,
        distinct_sampled: Default::default(),
        failures: Default::default(),
        failure: None,
        health: core_filters::Health::default(),
        online_states: None,
        validation: None,
        config: serde_json::json!({}),
        versions: identify::record::Versions::current(),
        fingerprint: None,
        trace: Trace::default(),
        timing: Timing {
            wall_s: 1.0,
            particle_steps_per_s: 1.0,
            validation_s: 0.0,
            realtime_factor: None,
            plan_s: None,
            threads: None,
            particle_blocks: false,
        },
        warnings: Vec::new(),
        credible: Vec::new(),
        theta_correlation: Vec::new(),
        segment_spread: None,
        innovation_checks: Vec::new(),
        residuals: None,
        free_run: None,
        modal: None,
        pool_left_out: vec![],
        plan: None,
        one_gaussian_filter: false,
    };
    for k in 0..=100 {
        let t = k as f64 * 0.3;
        let relax = 1.0 + 0.5 * (-t / 3.0).exp();
        let tr = &mut record.trace;
        tr.t.push(t);
        tr.param_mean
            .push(truth.iter().map(|v| v * relax).collect());
        tr.param_sd.push(
            NAMES
                .iter()
                .zip(&truth)
                .map(|(n, v)| if *n == "gamma" { 5.0 } else { 0.1 * v })
                .collect(),
        );
        tr.ess.push(500.0);
    }
    record
}

// ---------------------------------------------------------------------------------------------
// The tests
// ---------------------------------------------------------------------------------------------

#[test]
fn transfer_legend_covers_no_curve() {
    let dir = out_dir();
    let path = transfer(&synthetic_modal(), dir.path(), "mpf-ekf2 (seed 1, run 0)").unwrap();
    let f = figure(&path);
    // The legend's labels are among the texts: the pixels under them are blank (no curve, no
    // legend box over one), and every text fits.
    assert!(f.texts.iter().any(|t| t.text == "measured |H1| (Welch)"));
    assert_texts_legible(&f);
}

#[test]
fn shapes_are_legible_with_their_intervals() {
    // The frame's three modes, each shape with a 95 % range of ±0.08 per floor and a measured
    // operating shape a little off it; the longest caption ("mode 2 (11.10 Hz): MAC 0.990
    // [0.981, 0.995]") in a third of the width.
    let mut m = synthetic_modal();
    let shapes_of = [[0.44, 0.83, 1.0], [1.0, 0.35, -0.7], [-0.7, 1.0, -0.5]];
    m.pairs = shapes_of
        .iter()
        .enumerate()
        .map(|(i, phi)| identify::validation::ModePair {
            mode: i + 1,
            model_hz: m.modes[i].frequency_hz,
            damping_ratio: 0.01,
            measured_hz: Some(m.peaks[i].frequency_hz),
            difference_percent: Some(-1.0),
            excitation_db: Some(-3.0),
            model_hz_95: None,
            damping_ratio_95: None,
            model_shape: phi.to_vec(),
            model_shape_95: phi.iter().map(|v| [v - 0.08, v + 0.08]).collect(),
            operating_shape: phi.iter().map(|v| -2.0 * v + 0.05).collect(),
            mac: Some(0.99),
            mac_95: Some([0.981, 0.995]),
        })
        .collect();
    let dir = out_dir();
    let path = shapes(&m, dir.path(), "mpf-ekf2 (seed 1, run 0)").unwrap();
    let f = figure(&path);
    assert!(f
        .texts
        .iter()
        .any(|t| t.text.starts_with("mode 2 (") && t.text.contains("MAC 0.990 [0.981, 0.995]")));
    assert_texts_legible(&f);
    // Ten storeys, ten compared modes: four panels a row, every text still legible.
    let mut ten = m.clone();
    ten.channels = (1..=10).map(|c| format!("a{c}")).collect();
    ten.pairs = (0..10)
        .map(|r| {
            let phi: Vec<f64> = (1..=10)
                .map(|j| ((j * (2 * r + 1)) as f64 * std::f64::consts::PI / 21.0).sin())
                .collect();
            identify::validation::ModePair {
                mode: r + 1,
                model_hz: 1.5 * (2 * r + 1) as f64,
                model_shape_95: phi.iter().map(|v| [v - 0.05, v + 0.05]).collect(),
                operating_shape: phi.iter().map(|v| 3.0 * v).collect(),
                model_shape: phi,
                ..m.pairs[1].clone()
            }
        })
        .collect();
    let path = shapes(&ten, dir.path(), "mpf-ekf2 (seed 1, run 0)").unwrap();
    let f = figure(&path);
    assert!(f.texts.iter().any(|t| t.text.starts_with("mode 10 (")));
    assert_texts_legible(&f);
    // Without a compared shape there is no figure, and the reason is given.
    let err = shapes(&synthetic_modal(), dir.path(), "x").unwrap_err();
    assert!(err.to_string().contains("no mode shape"), "{err}");
}

#[test]
fn free_run_is_visible_over_its_band_and_enlarged_where_it_shakes() {
    let dir = out_dir();
    let run = synthetic_free_run();
    let path = free_run(&run, dir.path(), "mpf-ekf2 (seed 1, run 0)").unwrap();
    let f = figure(&path);
    let lines = free_run_lines(&f);
    eprintln!("free-run lines (share of points showing its colour, px per sample): {lines:?}");
    assert!(!lines.is_empty(), "no free-run line in {}", f.name);
    // Guards the draw order: the free run is drawn over the band (and the measured record), so
    // its colour shows at (almost) every point; 10 % allow for its own crossings' anti-aliasing.
    for (shown, _) in &lines {
        assert!(
            *shown >= 0.9,
            "the free run shows its colour at {:.0} % of its points (≥ 90 % wanted): {lines:?}",
            100.0 * shown
        );
    }
    // Guards the zoomed window: every channel's free run is also drawn at ≥ 2 px per sample.
    let resolved = lines.iter().filter(|(_, px)| *px >= 2.0).count();
    assert!(
        resolved >= run.channels.len(),
        "{resolved} of {} channels drawn at ≥ 2 px per sample: {lines:?}",
        run.channels.len()
    );
    assert_texts_legible(&f);
}

#[test]
fn convergence_captions_fit_their_panels() {
    let dir = out_dir();
    let run = synthetic_run();
    let path = dir.path().join("convergence.svg");
    convergence(
        &[("mpf-ekf2", &run)],
        &path,
        "mpf-ekf2 (seed 1, run 0): posterior mean ± 2 s.d.",
    )
    .unwrap();
    let f = figure(&path);
    assert!(
        f.texts
            .iter()
            .any(|t| t.text == "gamma [1/m^n] (bands clipped)"),
        "the clipped panel's caption"
    );
    assert_texts_legible(&f);
}
