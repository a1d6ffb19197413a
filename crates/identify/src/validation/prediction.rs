//! The model-error part of the free run's predictive band (docs/validation.md, "The predictive
//! band").
//!
//! The band of θ drawn from the posterior says how far the prediction moves with the
//! parameters; it says nothing of how far the model itself is from the structure. On the
//! shake-table frame the parameter band is a line's width while the free run misses the floors
//! by a quarter of their motion (fit ≈ 75 %): a band of parameters alone covers a few per cent of
//! the record, not 95.
//!
//! The error e_j(t) = y_j(t) − ŷ_j(t) of the free run is modelled as scaling with the local
//! strength of the *predicted* motion: |e_j(t)| ≤ q_j·s_j(t) with probability 95 %, where
//!
//! - s_j(t)² = m_j(t) + (f_j · RMS ŷ_j)², where m_j(t) is the mean of ŷ_j² over a window of
//!   `PERIODS` periods of the model's lowest mode centred on t: an error that grows with the
//!   motion (a stiffness or damping slightly off) and one that does not (what the model does not
//!   represent at all, sensor noise), in a proportion f_j learned from the errors — the f_j of
//!   `FLOOR_GRID` that maximises the likelihood of e_j(t) ~ N(0, a²·s_j(t)²) with a² at its
//!   maximum for that f_j (on the shake-table frame's `northridge`, f ≈ 1.3–2.8: the error is
//!   nearly as large in the quiet parts as in the strong shaking);
//! - q_j is the 95 % quantile of |e_j|/s_j (no Gaussian shape assumed).
//!
//! Both are learned on samples that the θ behind ŷ was **not** fitted to: the held-out part of
//! the record where the held-out choice scored its candidates (`crate::choice`). Without such a
//! part they are learned on the identifying record itself (in-sample, so narrower than a new
//! record needs) and the record says so.
//!
//! s_j uses only ŷ — the model driven by the ground motion — so the same q_j gives a band on any
//! other record of the structure (`sysid validate`), where its coverage of the measured floors is
//! an honest test; there the parameters' part of the band draws θ of another record, shifted by
//! the spread between the identifying record's parts (`super::shifted_to_another`). No Gaussian
//! shape is assumed for the error (q_j is an empirical quantile); the two parts of the band are
//! added in quadrature, half-width by half-width.

use models::description::StructureDescription;

pub use crate::record::validation::{ErrorSource, ModelError};

/// The local scale's window, in periods of the model's lowest mode.
pub(crate) const PERIODS: f64 = 2.0;

/// The proportions f tried: 61 values from 0.01 to 10, evenly spaced in log f.
pub(crate) const FLOOR_GRID: (f64, f64, usize) = (0.01, 10.0, 61);

/// Coverage the band aims at.
pub(crate) const LEVEL: f64 = 0.95;

/// What the free run's band includes besides the parameters' spread.
#[derive(Debug, Clone, Copy)]
pub enum ErrorBand<'a> {
    /// Nothing: the parameters' spread only.
    Without,
    /// A model error learned on the record itself by θ_val (in-sample).
    InSample,
    /// A model error learned before (held out, or on the identifying record).
    Given(&'a ModelError),
}

/// Window (s) used when the model has no under-damped mode to take a period from.
pub(crate) const FALLBACK_WINDOW_S: f64 = 1.0;

/// The window of the local scale for building `d` with θ: `PERIODS` periods of its lowest
/// under-damped mode (linearised at rest), or `FALLBACK_WINDOW_S`.
pub(crate) fn window_seconds(d: &StructureDescription, theta: &[f64]) -> f64 {
    let n = d.storeys;
    if theta.len() < 2 * n + d.damping.extra_parameters() {
        return FALLBACK_WINDOW_S;
    }
    let alpha = d.damping.has_mass_term().then(|| theta[2 * n]);
    models::modal::modes_of_damped(&d.masses, &theta[..n], &theta[n..2 * n], alpha)
        .ok()
        .and_then(|m| m.modes.first().map(|m| m.frequency_hz))
        .filter(|f| f.is_finite() && *f > 0.0)
        .map_or(FALLBACK_WINDOW_S, |f| PERIODS / f)
}

/// The local scale s(t) of a predicted series `yhat` sampled at `dt` (see the module
/// documentation), over a centred window of `window_s` seconds (at least one sample), with the
/// constant part `floor` × RMS ŷ.
pub(crate) fn local_scale(yhat: &[f64], dt: f64, window_s: f64, floor: f64) -> Vec<f64> {
    let (m, rms) = mean_square(yhat, dt, window_s);
    let constant = (floor * rms).powi(2);
    m.iter().map(|v| (v + constant).sqrt()).collect()
}

/// m(t), the mean of ŷ² over a centred window of `window_s` seconds (at least one sample), and
/// the RMS of ŷ: the two parts of the local scale.
fn mean_square(yhat: &[f64], dt: f64, window_s: f64) -> (Vec<f64>, f64) {
    let n = yhat.len();
    if n == 0 {
        return (Vec::new(), 0.0);
    }
    let half = ((window_s / dt / 2.0).round() as usize).min(n);
    // Prefix sums of ŷ²: the window's mean in O(1) per sample.
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    let mut acc = 0.0;
    for v in yhat {
        acc += v * v;
        prefix.push(acc);
    }
    let m = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(n));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect();
    (m, (acc / n as f64).sqrt())
}

/// The proportion f of `FLOOR_GRID` under which the errors `y − ŷ` over samples `from..` are
/// most likely as N(0, a²·s(t)²), a² at its maximum-likelihood value mean(e²/s²) for each f.
/// m(t) is computed once; each f only changes the constant part of s².
pub(crate) fn learn_floor(y: &[f64], yhat: &[f64], dt: f64, window_s: f64, from: usize) -> f64 {
    let (lo, hi, count) = FLOOR_GRID;
    let n = y.len().min(yhat.len());
    let from = from.min(n);
    if from == n {
        return lo;
    }
    let (m, rms) = mean_square(&yhat[..n], dt, window_s);
    let samples = (n - from) as f64;
    let mut best = (f64::INFINITY, lo);
    for i in 0..count {
        let f = lo * (hi / lo).powf(i as f64 / (count - 1) as f64);
        let constant = (f * rms).powi(2);
        let a2 = (from..n)
            .map(|k| (y[k] - yhat[k]).powi(2) / (m[k] + constant))
            .sum::<f64>()
            / samples;
        // −2 log-likelihood up to constants: Σ log(a² s²) + (n − from).
        let nll = (from..n)
            .map(|k| (a2 * (m[k] + constant)).ln())
            .sum::<f64>();
        if nll < best.0 {
            best = (nll, f);
        }
    }
    best.1
}

/// q: the `LEVEL` quantile of |y − ŷ|/s over the samples `from..` of one channel (`None` with
/// fewer than 20 finite ratios).
pub(crate) fn error_quantile(y: &[f64], yhat: &[f64], scale: &[f64], from: usize) -> Option<f64> {
    let n = y.len().min(yhat.len()).min(scale.len());
    let mut z: Vec<f64> = (from.min(n)..n)
        .map(|k| (y[k] - yhat[k]).abs() / scale[k])
        .filter(|v| v.is_finite())
        .collect();
    if z.len() < 20 {
        return None;
    }
    z.sort_by(f64::total_cmp);
    Some(super::free_run::percentile_sorted(&z, LEVEL))
}

/// The model error of the free run `yhat` (per channel) against `measured`, learned on the
/// samples `from..` (`source` says which part that is), with window `window_s`; `None` when a
/// channel has too few samples there.
pub(crate) fn learn(
    channels: &[String],
    measured: &[Vec<f64>],
    yhat: &[Vec<f64>],
    dt: f64,
    window_s: f64,
    from: usize,
    source: ErrorSource,
) -> Option<ModelError> {
    let mut floor = Vec::with_capacity(measured.len());
    let mut quantile = Vec::with_capacity(measured.len());
    for (y, s) in measured.iter().zip(yhat) {
        let f = learn_floor(y, s, dt, window_s, from);
        quantile.push(error_quantile(
            y,
            s,
            &local_scale(s, dt, window_s, f),
            from,
        )?);
        floor.push(f);
    }
    Some(ModelError {
        source,
        channels: channels.to_vec(),
        window_s,
        floor,
        quantile,
    })
}

/// The predictive band at one point: the parameter band `[lo, hi]` around `yhat` (absent: none)
/// widened in quadrature by the model error's half-width `w`.
pub(crate) fn widen(yhat: f64, param: Option<(f64, f64)>, w: f64) -> (f64, f64) {
    let (below, above) = param.map_or((0.0, 0.0), |(lo, hi)| {
        ((yhat - lo).max(0.0), (hi - yhat).max(0.0))
    });
    (yhat - below.hypot(w), yhat + above.hypot(w))
}

/// Per cent of the points where `y` lies inside `[lo, hi]` (NaN without points).
pub(crate) fn coverage_percent(y: &[f64], lo: &[f64], hi: &[f64]) -> f64 {
    let n = y.len().min(lo.len()).min(hi.len());
    if n == 0 {
        return f64::NAN;
    }
    let inside = (0..n).filter(|&k| lo[k] <= y[k] && y[k] <= hi[k]).count();
    100.0 * inside as f64 / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_local_scale_follows_the_motion_and_never_vanishes() {
        // A burst of amplitude 2 between quiet stretches.
        let y: Vec<f64> = (0..400)
            .map(|k| {
                if (100..300).contains(&k) {
                    2.0 * (k as f64 * 0.3).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let s = local_scale(&y, 0.01, 0.2, 0.05);
        // Inside the burst: the RMS of a sine of amplitude 2, √2, plus the small constant part.
        assert!((s[200] - 2f64.sqrt()).abs() < 0.05, "{}", s[200]);
        let rms = (y.iter().map(|v| v * v).sum::<f64>() / 400.0).sqrt();
        assert!((s[0] - 0.05 * rms).abs() < 1e-12);
        assert!(s.iter().all(|v| *v > 0.0));
    }

    #[test]
    fn the_floor_is_learned_from_how_the_errors_scale() {
        // A prediction whose strength varies ten-fold; errors either proportional to the local
        // strength (f small) or of constant size (f large), signs alternating.
        let n = 4000;
        let dt = 0.01;
        let yhat: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                (1.0 + 9.0 * (t / 5.0).sin().powi(2)) * (2.0 * std::f64::consts::PI * 2.0 * t).sin()
            })
            .collect();
        let m = local_scale(&yhat, dt, 1.0, 0.0);
        let sign = |k: usize| if (k / 7).is_multiple_of(2) { 1.0 } else { -1.0 };
        let proportional: Vec<f64> = (0..n).map(|k| yhat[k] + 0.3 * m[k] * sign(k)).collect();
        let constant: Vec<f64> = (0..n).map(|k| yhat[k] + 0.3 * sign(k)).collect();
        let f_prop = learn_floor(&proportional, &yhat, dt, 1.0, 0);
        let f_const = learn_floor(&constant, &yhat, dt, 1.0, 0);
        assert!(f_prop < 0.05, "{f_prop}");
        assert!(f_const > 2.0, "{f_const}");
    }

    #[test]
    fn the_quantile_and_the_coverage_agree() {
        // Errors of a known distribution: |e|/s uniform on [0, 1) → the 95 % quantile is 0.95,
        // and a band of that half-width covers 95 % of the samples.
        let n = 2000;
        let yhat = vec![1.0; n];
        let s = vec![1.0; n];
        let y: Vec<f64> = (0..n)
            .map(|k| 1.0 + if k % 2 == 0 { 1.0 } else { -1.0 } * (k as f64 / n as f64))
            .collect();
        let q = error_quantile(&y, &yhat, &s, 0).unwrap();
        assert!((q - 0.95).abs() < 2e-3, "{q}");
        let (lo, hi): (Vec<f64>, Vec<f64>) = (0..n).map(|k| widen(yhat[k], None, q)).unzip();
        let c = coverage_percent(&y, &lo, &hi);
        assert!((c - 95.0).abs() < 0.2, "{c}");
        // Learned on the second half only: the errors there are the larger ones.
        let q2 = error_quantile(&y, &yhat, &s, n / 2).unwrap();
        assert!(q2 > q && q2 <= 1.0, "{q2}");
        assert!(error_quantile(&y[..10], &yhat, &s, 0).is_none());
    }

    #[test]
    fn widening_adds_half_widths_in_quadrature() {
        assert_eq!(widen(1.0, Some((0.0, 1.5)), 0.0), (0.0, 1.5));
        let (lo, hi) = widen(0.0, Some((-3.0, 1.0)), 4.0);
        assert!((lo + 5.0).abs() < 1e-12 && (hi - 17f64.sqrt()).abs() < 1e-12);
        // θ_val outside its own draws' band: the model error alone on that side.
        assert_eq!(widen(2.0, Some((0.0, 1.0)), 1.0), (2.0 - 5f64.sqrt(), 3.0));
    }
}
