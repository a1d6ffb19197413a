//! The discrepancy term: room for what the shear model cannot represent (docs/validation.md,
//! "A discrepancy term").
//!
//! A few linear modes driven by the measured ground motion, added to the physical model's free
//! run channel by channel. Mode `m` is the single-degree-of-freedom oscillator
//! `q̈ + 2ζ_m ω_m q̇ + ω_m² q = −ü_g` (the one-storey chain of unit mass, simulated exactly as the
//! free run of a linear building is, [`models::integrate::first_order_hold`]); channel `i`
//! receives `a_im·ω_m² q + b_im·ω_m q̇` — any strictly proper second-order transfer function with
//! the mode's poles, so a mode that couples to the channels with any phase (a torsional partner,
//! an appendage, a split mode) is representable. Given the frequencies and damping ratios the
//! coefficients are linear least squares; the frequencies and damping ratios are found mode after
//! mode (a grid, then a local search) on the part of the record the choice identifies on, and the
//! number of modes is chosen by the free-run fit of the part it held out ([`choose`]).
//!
//! The discrepancy is a black box beside the physics: it does not change θ, its modes are not the
//! building's, and the record keeps the physical model's own fit beside the one with it.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::free_run::fit_percent;
pub use crate::record::validation::{Discrepancy, DiscrepancyMode};

/// How the discrepancy's modes are searched and chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Search {
    /// At most this many modes are tried.
    pub max_modes: usize,
    /// Held-out free-run fit (points, mean over channels) each mode must gain to be kept: the
    /// choice maximises `score(M) − mode_cost·M`.
    pub mode_cost: f64,
    /// The damping ratios a mode may take.
    pub damping: (f64, f64),
    /// After a mode is added, search every mode's frequency and damping again (else only the
    /// new one's).
    pub refine_all: bool,
}

/// The search `sysid filter` uses ([`choose`]). On records of the filter's own class a fitted
/// mode fits noise and loses held-out fit (`crates/experiments/tests/discrepancy.rs`; the unit
/// test on white noise keeps no mode even without a cost), so the cost of 0.5 points is a margin
/// against a mode that gains by chance, set before any measurement; the other settings were
/// chosen on the development structures of `crates/experiments/examples/discrepancy_dev.rs`
/// (docs/validation.md).
pub const SEARCH: Search = Search {
    max_modes: 8,
    mode_cost: 0.5,
    damping: (0.0005, 0.5),
    refine_all: true,
};
/// Frequencies tried for a new mode, log-spaced between [`lowest_hz`] and [`highest_hz`].
const GRID_FREQUENCIES: usize = 160;
/// Damping ratios tried for a new mode before the local search.
const GRID_DAMPING: [f64; 3] = [0.005, 0.02, 0.06];
/// Halvings of the local search's steps.
const REFINE_HALVINGS: usize = 8;

/// The lowest frequency a discrepancy mode may take: five periods in `seconds` of record.
fn lowest_hz(seconds: f64) -> f64 {
    5.0 / seconds
}

/// The highest: 80 % of the Nyquist frequency.
fn highest_hz(dt: f64) -> f64 {
    0.4 / dt
}

/// The two regressors of mode (`f_hz`, `zeta`) under `ug`: `ω² q` and `ω q̇`
/// ([`models::integrate::oscillator_basis`], the exact free run of the one-storey chain).
pub use models::integrate::oscillator_basis as mode_basis;

/// y − ŷ per channel.
fn residuals_of(measured: &[Vec<f64>], simulated: &[Vec<f64>]) -> Vec<Vec<f64>> {
    measured
        .iter()
        .zip(simulated)
        .map(|(y, s)| y.iter().zip(s).map(|(a, b)| a - b).collect())
        .collect()
}

/// The free-run fit of each channel of `measured` over the samples `from..`: of `simulated`,
/// with the term `d` added when given.
pub fn held_out_fits(
    d: Option<&Discrepancy>,
    measured: &[Vec<f64>],
    simulated: &[Vec<f64>],
    (ug, dt): (&[f64], f64),
    from: usize,
) -> Vec<f64> {
    let add = d.map(|d| contribution(d, ug, dt));
    measured
        .iter()
        .zip(simulated)
        .enumerate()
        .map(|(c, (y, s))| {
            let yhat: Vec<f64> = match &add {
                Some(a) => s.iter().zip(&a[c]).map(|(x, e)| x + e).collect(),
                None => s.clone(),
            };
            fit_percent(&y[from..], &yhat[from..])
        })
        .collect()
}

/// The points per sample interval on which mode `f_hz` is simulated on a record sampled at `dt`:
/// one where the mode lies within [`highest_hz`] of the record (as wherever it was found), else
/// as many as bring it within that bound on the finer grid. Within a billionth of the bound
/// counts as within: a mode the search put at its bound on one record is at the bound of
/// another of the same rate whose step was computed an ulp apart (or read back from a record's
/// time series).
fn points_per_sample(f_hz: f64, dt: f64) -> usize {
    (f_hz / highest_hz(dt) - 1e-9).ceil().max(1.0) as usize
}

/// The modes of `d` above 80 % of the Nyquist frequency of a record sampled at `dt` (the search's
/// own bound): possible on a record sampled more slowly than the one they were found on.
pub fn above_band(d: &Discrepancy, dt: f64) -> Vec<DiscrepancyMode> {
    d.modes
        .iter()
        .filter(|m| points_per_sample(m.frequency_hz, dt) > 1)
        .copied()
        .collect()
}

/// What [`contribution`] does, on a record sampled at `dt`, with the modes of `d` above its band
/// ([`above_band`]), as `sysid validate` says it; `None` when every mode is within the band.
pub fn above_band_note(d: &Discrepancy, dt: f64) -> Option<String> {
    let above = above_band(d, dt);
    (!above.is_empty()).then(|| {
        format!(
            "the discrepancy mode(s) at {} Hz lie above 80 % of the record's Nyquist frequency \
             ({:.1} Hz): simulated on its ground motion band-limited between its samples, on a \
             grid fine enough to hold them (docs/validation.md)",
            above
                .iter()
                .map(|m| format!("{:.2}", m.frequency_hz))
                .collect::<Vec<_>>()
                .join(", "),
            highest_hz(dt)
        )
    })
}

/// The discrepancy's contribution to each of its channels under `ug`.
///
/// A mode above the record's band — found on a record sampled faster — is what it was there: a
/// transfer function of the ground motion, whose motion between this record's samples is the
/// band-limited one (`models::ground_between`). Its basis is simulated on that reconstruction,
/// with as many points per sample as bring the mode within the search's bound, and read at the
/// samples. Stepped at the record's own rate instead, a lightly damped mode above the Nyquist
/// frequency resonates with the images of the input's content that the linear input between
/// samples carries (80 Hz on a record of 100 Hz: with the image of its 20 Hz content) and rings
/// at its alias: on the Lake Crowley bent the records kept out were predicted at −73.7 / −26.5 /
/// −195.9 % so, 21.8 / 26.9 / 30.3 % without the mode and 38.0 / 42.3 / 47.8 % with it simulated
/// here (docs/real-frame.md).
pub fn contribution(d: &Discrepancy, ug: &[f64], dt: f64) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; ug.len()]; d.channels.len()];
    for (m, mode) in d.modes.iter().enumerate() {
        let [q, qd] = match points_per_sample(mode.frequency_hz, dt) {
            1 => mode_basis(mode.frequency_hz, mode.damping_ratio, ug, dt),
            per => {
                let fine = models::ground_between::refine(
                    ug,
                    dt,
                    per,
                    models::ground_between::GroundBetween::BandLimited,
                );
                let at_samples = |v: Vec<f64>| v.into_iter().step_by(per).collect::<Vec<_>>();
                let [q, qd] = mode_basis(
                    mode.frequency_hz,
                    mode.damping_ratio,
                    &fine,
                    dt / per as f64,
                );
                [at_samples(q), at_samples(qd)]
            }
        };
        for (c, series) in out.iter_mut().enumerate() {
            let [a, b] = d.coefficients[c][m];
            for (k, v) in series.iter_mut().enumerate() {
                *v += a * q[k] + b * qd[k];
            }
        }
    }
    out
}

/// Least-squares coefficients of the columns `basis` (over rows `..rows`) for each residual,
/// with a ridge of 1e-10 of the Gram matrix's mean diagonal (a mode the record does not excite
/// then gets coefficients near zero instead of a singular system).
fn least_squares(basis: &[&[f64]], residuals: &[Vec<f64>], rows: usize) -> Vec<Vec<f64>> {
    let p = basis.len();
    let mut gram = DMatrix::<f64>::zeros(p, p);
    for i in 0..p {
        for j in 0..=i {
            let g: f64 = basis[i][..rows]
                .iter()
                .zip(&basis[j][..rows])
                .map(|(a, b)| a * b)
                .sum();
            gram[(i, j)] = g;
            gram[(j, i)] = g;
        }
    }
    let ridge = 1e-10 * (gram.trace() / p as f64).max(f64::MIN_POSITIVE);
    for i in 0..p {
        gram[(i, i)] += ridge;
    }
    let Some(chol) = gram.cholesky() else {
        return vec![vec![0.0; p]; residuals.len()];
    };
    residuals
        .iter()
        .map(|r| {
            let rhs = DVector::from_iterator(
                p,
                basis
                    .iter()
                    .map(|b| b[..rows].iter().zip(&r[..rows]).map(|(x, y)| x * y).sum()),
            );
            chol.solve(&rhs).iter().copied().collect()
        })
        .collect()
}

/// Modes with the coefficients fitted over the rows the search uses.
struct Fitted {
    modes: Vec<DiscrepancyMode>,
    /// Per channel, `[a_1, b_1, a_2, b_2, …]`.
    coefficients: Vec<Vec<f64>>,
}

impl Fitted {
    /// The discrepancy these modes and coefficients make for `channels`.
    fn discrepancy(&self, channels: &[String]) -> Discrepancy {
        Discrepancy {
            channels: channels.to_vec(),
            modes: self.modes.clone(),
            coefficients: self
                .coefficients
                .iter()
                .map(|c| c.chunks(2).map(|ab| [ab[0], ab[1]]).collect())
                .collect(),
        }
    }
}

/// The columns of the bases `basis`, mode after mode.
fn columns(basis: &[[Vec<f64>; 2]]) -> Vec<&[f64]> {
    basis
        .iter()
        .flat_map(|[q, qd]| [q.as_slice(), qd.as_slice()])
        .collect()
}

/// `modes` with coefficients fitted to `residuals` over rows `..rows`.
fn fit_modes(
    modes: Vec<DiscrepancyMode>,
    residuals: &[Vec<f64>],
    rows: usize,
    ug: &[f64],
    dt: f64,
) -> Fitted {
    let basis: Vec<[Vec<f64>; 2]> = modes
        .iter()
        .map(|m| mode_basis(m.frequency_hz, m.damping_ratio, &ug[..rows], dt))
        .collect();
    let coefficients = least_squares(&columns(&basis), residuals, rows);
    Fitted {
        modes,
        coefficients,
    }
}

/// Σ a·b in eight interleaved partial sums (so that the compiler vectorises it: the search's
/// cost is mostly these products), then the tail.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// The normal equations of the modes found so far on the residuals over the search's rows:
/// their bases, Gram matrix and products with each residual, so that the cost of one mode
/// changed or added ([`Normal::cost_with`]) takes two passes over the rows, not a least-squares
/// fit from scratch.
struct Normal<'a> {
    residuals: &'a [Vec<f64>],
    rows: usize,
    basis: Vec<[Vec<f64>; 2]>,
    /// Gram matrix of the columns (two per mode, in mode order).
    gram: DMatrix<f64>,
    /// Column × residual products, one column per channel.
    rhs: DMatrix<f64>,
    /// Each residual's sum of squares.
    rr: Vec<f64>,
}

impl<'a> Normal<'a> {
    fn new(residuals: &'a [Vec<f64>], rows: usize) -> Self {
        Normal {
            rr: residuals
                .iter()
                .map(|r| dot(&r[..rows], &r[..rows]))
                .collect(),
            residuals,
            rows,
            basis: Vec::new(),
            gram: DMatrix::zeros(0, 0),
            rhs: DMatrix::zeros(0, residuals.len()),
        }
    }

    /// The Gram matrix and products with mode `at`'s columns replaced by `new` (`at` one past
    /// the last mode: added).
    fn with(&self, at: usize, new: &[Vec<f64>; 2]) -> (DMatrix<f64>, DMatrix<f64>) {
        let m = self.basis.len().max(at + 1);
        let (p, c) = (2 * m, self.residuals.len());
        let mut gram = DMatrix::zeros(p, p);
        let old = 2 * self.basis.len();
        gram.view_mut((0, 0), (old, old)).copy_from(&self.gram);
        let mut rhs = DMatrix::zeros(p, c);
        rhs.view_mut((0, 0), (old, c)).copy_from(&self.rhs);
        let rows = self.rows;
        for (k, col) in new.iter().enumerate() {
            let i = 2 * at + k;
            for (mm, b) in self.basis.iter().enumerate() {
                if mm == at {
                    continue;
                }
                for (kk, other) in b.iter().enumerate() {
                    let g = dot(&col[..rows], &other[..rows]);
                    gram[(i, 2 * mm + kk)] = g;
                    gram[(2 * mm + kk, i)] = g;
                }
            }
            for (kk, other) in new.iter().enumerate() {
                gram[(i, 2 * at + kk)] = dot(&col[..rows], &other[..rows]);
            }
            for (ch, r) in self.residuals.iter().enumerate() {
                rhs[(i, ch)] = dot(&col[..rows], &r[..rows]);
            }
        }
        (gram, rhs)
    }

    /// Σ over channels of the share of each residual's sum of squares left by the least-squares
    /// fit of `gram`, `rhs` (`rᵀr − bᵀβ`, with the ridge of [`least_squares`]).
    fn cost_of(&self, mut gram: DMatrix<f64>, rhs: &DMatrix<f64>) -> f64 {
        let p = gram.nrows();
        let ridge = 1e-10 * (gram.trace() / p as f64).max(f64::MIN_POSITIVE);
        for i in 0..p {
            gram[(i, i)] += ridge;
        }
        let Some(chol) = gram.cholesky() else {
            return f64::INFINITY;
        };
        let beta = chol.solve(rhs);
        self.rr
            .iter()
            .enumerate()
            .map(|(ch, &rr)| {
                if rr > 0.0 {
                    let explained = rhs.column(ch).dot(&beta.column(ch));
                    (rr - explained) / rr
                } else {
                    0.0
                }
            })
            .sum()
    }

    /// The cost with mode `at`'s basis replaced by (or, one past the last, added as) `new`.
    fn cost_with(&self, at: usize, new: &[Vec<f64>; 2]) -> f64 {
        let (gram, rhs) = self.with(at, new);
        self.cost_of(gram, &rhs)
    }

    /// Mode `at`'s basis replaced by (or added as) `new`.
    fn set(&mut self, at: usize, new: [Vec<f64>; 2]) {
        let (gram, rhs) = self.with(at, &new);
        (self.gram, self.rhs) = (gram, rhs);
        if at == self.basis.len() {
            self.basis.push(new);
        } else {
            self.basis[at] = new;
        }
    }
}

/// A local search on (ln f, ln ζ) of `modes[i]` for each `i` in `which`, the other modes held
/// (`normal`: the normal equations of every mode, kept up to date): from steps of `step_f` in
/// ln f and 0.5 in ln ζ, each mode moved to the best of its four neighbours while one is
/// cheaper, the steps halved [`REFINE_HALVINGS`] times; returns the cost reached.
fn refine(
    modes: &mut [DiscrepancyMode],
    normal: &mut Normal<'_>,
    which: std::ops::Range<usize>,
    (mut c, step_f): (f64, f64),
    search: &Search,
    (ug, dt): (&[f64], f64),
) -> f64 {
    let rows = normal.rows;
    let (lo, hi) = (lowest_hz(rows as f64 * dt), highest_hz(dt));
    let (mut step_f, mut step_z) = (step_f, 0.5_f64);
    for _ in 0..REFINE_HALVINGS {
        let mut moved = true;
        while moved {
            moved = false;
            for i in which.clone() {
                let m = modes[i];
                let moves: Vec<DiscrepancyMode> =
                    [(step_f, 0.0), (-step_f, 0.0), (0.0, step_z), (0.0, -step_z)]
                        .iter()
                        .map(|&(df, dz)| DiscrepancyMode {
                            frequency_hz: m.frequency_hz * f64::exp(df),
                            damping_ratio: m.damping_ratio * f64::exp(dz),
                        })
                        .filter(|n| {
                            (lo..=hi).contains(&n.frequency_hz)
                                && (search.damping.0..=search.damping.1).contains(&n.damping_ratio)
                        })
                        .collect();
                // The neighbours side by side, the cheapest (the first of equals) taken: the
                // same for any thread count.
                let tried: Vec<(f64, [Vec<f64>; 2])> = moves
                    .par_iter()
                    .map(|n| {
                        let b = mode_basis(n.frequency_hz, n.damping_ratio, &ug[..rows], dt);
                        (normal.cost_with(i, &b), b)
                    })
                    .collect();
                let mut best: Option<(f64, [Vec<f64>; 2], DiscrepancyMode)> = None;
                for ((c2, b), n) in tried.into_iter().zip(moves) {
                    if best.as_ref().is_none_or(|(bc, _, _)| c2 < *bc) {
                        best = Some((c2, b, n));
                    }
                }
                if let Some((c2, b, n)) = best {
                    if c2 < c {
                        (c, moved) = (c2, true);
                        modes[i] = n;
                        normal.set(i, b);
                    }
                }
            }
        }
        step_f /= 2.0;
        step_z /= 2.0;
    }
    c
}

/// `known` and one more mode, the one that leaves the least of `residuals` over rows `..rows`:
/// the best of a grid of frequencies and damping ratios, then a local search on
/// (ln f, ln ζ) of it alone — and, with `search.refine_all`, a second answer: then of every
/// mode together. Searching every mode fits the identified part better but can overfit it (two
/// lightly damped modes 1 % apart cancelling each other on the shake-table frame), so the
/// held-out part decides between the two ([`choose`]).
fn add_mode(
    known: &[DiscrepancyMode],
    search: &Search,
    residuals: &[Vec<f64>],
    rows: usize,
    ug: &[f64],
    dt: f64,
) -> Vec<Fitted> {
    let (lo, hi) = (lowest_hz(rows as f64 * dt), highest_hz(dt));
    let ratio = (hi / lo).ln() / (GRID_FREQUENCIES - 1) as f64;
    let mut normal = Normal::new(residuals, rows);
    for (i, m) in known.iter().enumerate() {
        normal.set(
            i,
            mode_basis(m.frequency_hz, m.damping_ratio, &ug[..rows], dt),
        );
    }
    // The grid side by side on every core, collected in order: the first least cost is the
    // same for any thread count.
    let grid: Vec<(f64, f64)> = (0..GRID_FREQUENCIES)
        .flat_map(|i| GRID_DAMPING.map(|z| (lo * (ratio * i as f64).exp(), z)))
        .filter(|&(_, z)| (search.damping.0..=search.damping.1).contains(&z))
        .collect();
    let new = known.len();
    let costs: Vec<f64> = grid
        .par_iter()
        .map(|&(f, z)| normal.cost_with(new, &mode_basis(f, z, &ug[..rows], dt)))
        .collect();
    let mut best: Option<(f64, f64, f64)> = None;
    for (&(f, z), &c) in grid.iter().zip(&costs) {
        if best.is_none_or(|(_, _, b)| c < b) {
            best = Some((f, z, c));
        }
    }
    let (f, z, c) = best.expect("the grid is not empty");
    let mut modes = known.to_vec();
    modes.push(DiscrepancyMode {
        frequency_hz: f,
        damping_ratio: z,
    });
    normal.set(new, mode_basis(f, z, &ug[..rows], dt));
    let on = (ug, dt);
    let c = refine(
        &mut modes,
        &mut normal,
        new..new + 1,
        (c, ratio),
        search,
        on,
    );
    let alone = fit_modes(modes.clone(), residuals, rows, ug, dt);
    if !(search.refine_all && new > 0) {
        return vec![alone];
    }
    refine(
        &mut modes,
        &mut normal,
        0..new + 1,
        (c, ratio / 4.0),
        search,
        on,
    );
    vec![alone, fit_modes(modes, residuals, rows, ug, dt)]
}

/// One number of discrepancy modes and how well it predicted the held-out part.
pub use crate::plan::DiscrepancyCandidate;
pub use crate::plan::DiscrepancyChoice;

/// Chooses the discrepancy of a free run `simulated` (per channel, over the whole record) of
/// `measured`: 0 to `search.max_modes` modes, each found on the samples `..from` and their
/// coefficients fitted there, scored by the free-run fit of the samples `from..` with the
/// discrepancy added; the number kept maximises the mean held-out fit less `search.mode_cost`
/// per mode. `None` when the parts are too short to fit a mode.
pub fn choose(
    search: &Search,
    channels: &[String],
    measured: &[Vec<f64>],
    simulated: &[Vec<f64>],
    ug: &[f64],
    dt: f64,
    from: usize,
) -> Option<DiscrepancyChoice> {
    let n = ug.len();
    if from < 4 * (2 * search.max_modes)
        || n <= from
        || lowest_hz(from as f64 * dt) >= highest_hz(dt)
    {
        return None;
    }
    let residuals = residuals_of(measured, simulated);
    let held_out = |d: Option<&Discrepancy>| held_out_fits(d, measured, simulated, (ug, dt), from);
    let mut candidates = vec![DiscrepancyCandidate::new(
        Discrepancy::none(channels),
        held_out(None),
    )];
    let mut modes = Vec::new();
    for _ in 0..search.max_modes {
        // The new mode refined alone, or every mode (when searched): the better on the
        // held-out part is the candidate and the start of the next (the first of equals).
        let tried: Vec<DiscrepancyCandidate> = add_mode(&modes, search, &residuals, from, ug, dt)
            .into_iter()
            .enumerate()
            .map(|(i, fitted)| {
                let d = fitted.discrepancy(channels);
                let fits = held_out(Some(&d));
                DiscrepancyCandidate {
                    every_mode_refined: i == 1,
                    ..DiscrepancyCandidate::new(d, fits)
                }
            })
            .collect();
        let best = tried
            .into_iter()
            .reduce(|a, b| match (a.score, b.score) {
                (_, None) => a,
                (None, Some(_)) => b,
                (Some(x), Some(y)) => {
                    if y > x {
                        b
                    } else {
                        a
                    }
                }
            })
            .expect("add_mode answers at least once");
        modes = best.discrepancy.modes.clone();
        candidates.push(best);
    }
    let chosen = candidates
        .iter()
        .enumerate()
        .filter_map(|(m, c)| c.score.map(|s| (m, s - search.mode_cost * m as f64)))
        .fold(None, |acc: Option<(usize, f64)>, (m, s)| match acc {
            Some((_, b)) if b >= s => acc,
            _ => Some((m, s)),
        })
        .map_or(0, |(m, _)| m);
    Some(DiscrepancyChoice {
        identified_samples: from,
        held_out_samples: n - from,
        mode_cost: search.mode_cost,
        candidates,
        chosen,
    })
}

/// The chosen modes refitted: their coefficients fitted to the residual of the free run
/// `simulated` over the samples `..rows` (a run's discrepancy: every sample of the record).
pub fn refit(
    modes: &[DiscrepancyMode],
    channels: &[String],
    measured: &[Vec<f64>],
    simulated: &[Vec<f64>],
    (ug, dt): (&[f64], f64),
    rows: usize,
) -> Discrepancy {
    let residuals = residuals_of(measured, simulated);
    fit_modes(modes.to_vec(), &residuals, rows, ug, dt).discrepancy(channels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::building::{Building, Damping};
    use models::structure::ShearChain;

    fn ground(n: usize, dt: f64) -> Vec<f64> {
        // A deterministic broadband input: a sum of incommensurate sines.
        (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                (0..40)
                    .map(|j| {
                        let f = 0.3 + 0.37 * j as f64;
                        (2.0 * std::f64::consts::PI * f * t + j as f64 * 1.3).sin()
                    })
                    .sum()
            })
            .collect()
    }

    #[test]
    fn a_modes_basis_is_the_exact_free_run_of_its_one_storey_chain() {
        let (n, dt) = (3000, 0.01);
        let ug = ground(n, dt);
        let (f, z) = (4.2, 0.03);
        let [q, qd] = mode_basis(f, z, &ug, dt);
        let w = 2.0 * std::f64::consts::PI * f;
        let building = Building::new(vec![1.0], vec![], Damping::Storey).unwrap();
        let chain = ShearChain::from_theta(&building, &[w * w, 2.0 * z * w]).unwrap();
        let t = models::integrate::simulate_linear_exact(&chain, &ug, dt).unwrap();
        let scale = q.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        for k in 0..n {
            assert!(
                (q[k] - w * w * t.state(k)[0]).abs() <= 1e-12 * scale,
                "q at {k}"
            );
            assert!(
                (qd[k] - w * t.state(k)[1]).abs() <= 1e-12 * scale,
                "q̇ at {k}"
            );
        }
        assert!(scale > 0.0);
    }

    #[test]
    fn a_mode_in_the_residual_is_found_and_its_coefficients_recovered() {
        let (n, dt) = (4000, 0.01);
        let ug = ground(n, dt);
        let truth = Discrepancy {
            channels: vec!["a1".into(), "a2".into()],
            modes: vec![DiscrepancyMode {
                frequency_hz: 6.3,
                damping_ratio: 0.02,
            }],
            coefficients: vec![vec![[0.3, -0.1]], vec![[-0.2, 0.05]]],
        };
        let add = contribution(&truth, &ug, dt);
        let simulated = vec![ug.clone(), ug.iter().map(|u| 0.5 * u).collect()];
        let measured: Vec<Vec<f64>> = simulated
            .iter()
            .zip(&add)
            .map(|(s, a)| s.iter().zip(a).map(|(x, y)| x + y).collect())
            .collect();
        let choice = choose(
            &SEARCH,
            &truth.channels,
            &measured,
            &simulated,
            &ug,
            dt,
            2500,
        )
        .unwrap();
        assert_eq!(choice.chosen, 1, "{choice:?}");
        let m = &choice.candidates[1].discrepancy.modes[0];
        assert!((m.frequency_hz - 6.3).abs() < 0.01, "{m:?}");
        assert!((m.damping_ratio - 0.02).abs() < 0.002, "{m:?}");
        let d = refit(
            &choice.candidates[1].discrepancy.modes,
            &truth.channels,
            &measured,
            &simulated,
            (&ug, dt),
            ug.len(),
        );
        for (got, want) in d.coefficients.iter().zip(&truth.coefficients) {
            for (g, w) in got[0].iter().zip(&want[0]) {
                assert!((g - w).abs() < 0.01 * w.abs().max(0.05), "{got:?} {want:?}");
            }
        }
        // The held-out fit with the mode is near perfect; without it, it is not.
        let with = choice.candidates[1].score.unwrap();
        let without = choice.candidates[0].score.unwrap();
        assert!(with > 99.0 && without < 90.0, "{with} {without}");
    }

    #[test]
    fn white_noise_in_the_residual_chooses_no_mode() {
        use rand::Rng;
        let (n, dt) = (4000, 0.01);
        let ug = ground(n, dt);
        let mut rng = core_filters::rng::stream(3, 0, "discrepancy test");
        let simulated = vec![ug.clone(), ug.iter().map(|u| 0.5 * u).collect::<Vec<_>>()];
        let measured: Vec<Vec<f64>> = simulated
            .iter()
            .map(|s| {
                s.iter()
                    .map(|x| x + 0.3 * (rng.random::<f64>() - 0.5))
                    .collect()
            })
            .collect();
        let names = vec!["a1".to_string(), "a2".to_string()];
        let choice = choose(&SEARCH, &names, &measured, &simulated, &ug, dt, 2500).unwrap();
        assert_eq!(choice.chosen, 0, "{choice:?}");
    }

    #[test]
    fn a_mode_above_a_records_band_is_simulated_as_it_was_where_it_was_found() {
        let mode = |f: f64, z: f64| DiscrepancyMode {
            frequency_hz: f,
            damping_ratio: z,
        };
        // Found on a record of 200 Hz (the search's bound there is 80 Hz, which it may reach):
        // a mode within the band and one at the bound, lightly damped, as on the Lake Crowley
        // bent.
        let d = Discrepancy {
            channels: vec!["a1".into()],
            modes: vec![mode(6.14, 0.026), mode(80.0, 0.0005)],
            coefficients: vec![vec![[0.36, 0.01], [-1.19, -4.31]]],
        };
        let (fine_dt, n) = (0.005, 4000);
        // The same motion recorded at 200 Hz and at 100 Hz: from rest, as a record starts before
        // the shaking (the band-limited reconstruction of a record that starts at a jump rings
        // where it starts), with content at 20 Hz as the bridge's records have — its image in
        // the slow record's linear input is at 80 Hz.
        let fast: Vec<f64> = ground(n, fine_dt)
            .iter()
            .enumerate()
            .map(|(k, v)| {
                let t = k as f64 * fine_dt;
                let taper = t.min(1.0) * ((n - 1 - k) as f64 * fine_dt).min(1.0);
                taper * (v + 2.0 * (2.0 * std::f64::consts::PI * 20.0 * t).sin())
            })
            .collect();
        let slow: Vec<f64> = fast.iter().step_by(2).copied().collect();
        assert!(above_band(&d, fine_dt).is_empty());
        assert_eq!(above_band(&d, 2.0 * fine_dt), vec![mode(80.0, 0.0005)]);
        assert_eq!(above_band_note(&d, fine_dt), None);
        let note = above_band_note(&d, 0.01).unwrap();
        assert!(
            note.contains("80.00 Hz") && note.contains("(40.0 Hz)"),
            "{note}"
        );
        // The mode at 80 Hz alone, where it was found: the term as the search fitted it.
        let high = Discrepancy {
            channels: vec!["a1".into()],
            modes: vec![mode(80.0, 0.0005)],
            coefficients: vec![vec![[-1.19, -4.31]]],
        };
        let reference: Vec<f64> = contribution(&high, &fast, fine_dt)[0]
            .iter()
            .step_by(2)
            .copied()
            .collect();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let off = |v: &[f64]| {
            let e: Vec<f64> = v.iter().zip(&reference).map(|(a, b)| a - b).collect();
            rms(&e) / rms(&reference)
        };
        // On the slower record: the same prediction at its samples (measured 6.4e-4 RMS; the
        // band-limited reconstruction of the slow record is the fast one to 2e-5 RMS here),
        // where stepping the mode at the slow rate rings at its 20 Hz alias and misses by more
        // than the prediction itself (measured 47 times).
        let slow_dt = 2.0 * fine_dt;
        let now = contribution(&high, &slow, slow_dt);
        assert!(off(&now[0]) < 1e-3, "{}", off(&now[0]));
        let [q, qd] = mode_basis(80.0, 0.0005, &slow, slow_dt);
        let stepped: Vec<f64> = (0..slow.len())
            .map(|k| -1.19 * q[k] - 4.31 * qd[k])
            .collect();
        assert!(off(&stepped) > 1.0, "{}", off(&stepped));
        // A mode within the band is stepped at the record's rate as before; each mode is
        // simulated on its own, so the whole term is the sum of the two.
        let whole = contribution(&d, &slow, slow_dt);
        let [q6, qd6] = mode_basis(6.14, 0.026, &slow, slow_dt);
        for k in 0..slow.len() {
            let sum = 0.36 * q6[k] + 0.01 * qd6[k] + now[0][k];
            assert!((whole[0][k] - sum).abs() <= 1e-9 * (1.0 + sum.abs()));
        }
    }
}
