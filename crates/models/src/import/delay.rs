//! A storey sensor whose clock runs late (or early) against the ground sensor's, measured and
//! removed.
//!
//! Separate loggers stamp their samples with their own clocks; a constant offset between two
//! clocks is a delay between the channels. Below its first mode a building moves with the ground
//! — the absolute acceleration of every storey is in phase with the ground's — so the phase of
//! the storey's transfer function from the ground at those frequencies is the delay's, `−ω·τ`,
//! up to the structure's own small lag (`2ζr³/(1−r²)` at `r = f/f₁` for one mode). A delay the
//! model does not know is lethal to an identification: at a mode of 22 Hz sampled at 120 Hz a
//! delay of 2.3 samples is a phase error of 150°, which the filter can only explain with
//! negative damping or a wrong stiffness (the stiff one-storey frame in
//! `docs/real-frame.md`, "Clock delays", measured 19.2–19.5 ms on each of its six records).
//!
//! [`measure`] fits `τ` to the phase of the whole record's cross-spectrum, averaged over blocks
//! of [`BLOCK`] adjacent frequencies, at the blocks below half the first mode where the coherence
//! exceeds [`MIN_COHERENCE`], weighted by the inverse of the phase estimate's variance. The
//! record is padded with as many zeros as it has samples, so its cross-spectrum is that of the
//! linear convolution the structure performs: a Welch estimate instead cuts the record into
//! segments, and each segment cuts off a lightly damped structure's response to the motion
//! before it — on the stiff stand-in's table records (`experiments/real/stiff_standin.py`,
//! modes from 9.2 Hz, ζ 0.7 %) segments of 256 samples put 0.14–0.39 ms of lag into the
//! estimate that is not there, a record-specific error no amount of averaging over the noise
//! removes. The delay is
//! removed ([`Delay::removed`]) only where it is unambiguous: larger than a quarter sample,
//! than `MARGIN` (3) standard errors and than `MARGIN` times the lag a mode with
//! `ZETA_BOUND` (10 %) damping would put into the same fit. Removing it advances the storey's
//! samples by `τ` with a band-limited (FFT) shift — linear interpolation would cut the
//! amplitude of a mode near the Nyquist frequency by 15 % — and drops the samples at the ends
//! that the shift leaves without data.

use rustfft::{num_complex::Complex64, FftPlanner};
use std::f64::consts::PI;

/// Coherence above which a frequency enters the fit.
pub const MIN_COHERENCE: f64 = 0.9;
/// Damping ratio of the structure's own lag the rule allows for (a generous one: 10 %).
pub(crate) const ZETA_BOUND: f64 = 0.1;
/// How many standard errors, and how many times the structure's possible lag, a delay must
/// exceed to be removed.
pub(crate) const MARGIN: f64 = 3.0;
/// Blocks of frequencies a fit needs.
pub(crate) const MIN_BINS: usize = 5;
/// Residual phase (rad, RMS) above which the phase is not a straight line: no delay measured.
pub(crate) const MAX_RESIDUAL: f64 = 0.15;

/// A measured delay of one channel against the ground.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Delay {
    /// The channel's delay (s): positive when it lags the ground.
    pub seconds: f64,
    /// Its standard error (s).
    pub standard_error: f64,
    /// The delay a mode of `ZETA_BOUND` (10 %) damping at `first_mode_hz` would put into the fit (s).
    pub structural_bound: f64,
    /// The first mode the band is set by (Hz) and the band fitted (Hz).
    pub first_mode_hz: f64,
    pub band_hz: (f64, f64),
    /// Blocks of [`BLOCK`] frequencies in the fit.
    pub bins: usize,
    /// Whether the rule removed it.
    pub removed: bool,
}

impl Delay {
    /// The rule: unambiguous against the sampling, the estimate's noise and the structure's lag.
    fn decide(&mut self, dt: f64) {
        let t = self.seconds.abs();
        self.removed =
            t > 0.25 * dt && t > MARGIN * self.standard_error && t > MARGIN * self.structural_bound;
    }
}

/// Adjacent frequencies per block of the whole record's cross-spectrum: 16 bins of the record
/// padded to twice its length average about 8 independent frequencies, at a resolution of
/// 8/(n·dt) — that of a Welch estimate with segments of n/8 samples.
pub const BLOCK: usize = 16;

/// One block of the whole record's spectra: its frequency (Hz, the centroid of its bins weighted
/// by |G|·|Y|, where a linear phase puts the block's phase), the ground's auto-spectrum, the
/// channel's and the cross-spectrum conj(G)·Y, summed over the block.
struct Block {
    hz: f64,
    gg: f64,
    yy: f64,
    gy: Complex64,
}

/// The blocks of [`BLOCK`] bins of the spectra of `ground` and `y` (mean removed, zero-padded to
/// twice the length), from the lowest frequency up (the zero frequency left out).
fn blocks(dt: f64, ground: &[f64], y: &[f64]) -> Vec<Block> {
    let n = ground.len().min(y.len());
    let m = 2 * n;
    let mut planner = FftPlanner::new();
    let fft = planner.plan_fft_forward(m);
    let spectrum = |x: &[f64]| -> Vec<Complex64> {
        let mean = x.iter().sum::<f64>() / n as f64;
        let mut buf: Vec<Complex64> = x
            .iter()
            .map(|v| Complex64::new(v - mean, 0.0))
            .chain(std::iter::repeat(Complex64::new(0.0, 0.0)))
            .take(m)
            .collect();
        fft.process(&mut buf);
        buf
    };
    let (g, v) = (spectrum(&ground[..n]), spectrum(&y[..n]));
    let df = 1.0 / (m as f64 * dt);
    (1..m / 2)
        .collect::<Vec<_>>()
        .chunks_exact(BLOCK)
        .map(|bins| {
            let mut b = Block {
                hz: 0.0,
                gg: 0.0,
                yy: 0.0,
                gy: Complex64::new(0.0, 0.0),
            };
            let mut weight = 0.0;
            for &k in bins {
                let w = g[k].norm() * v[k].norm();
                b.hz += w * k as f64 * df;
                weight += w;
                b.gg += g[k].norm_sqr();
                b.yy += v[k].norm_sqr();
                b.gy += g[k].conj() * v[k];
            }
            b.hz = if weight > 0.0 {
                b.hz / weight
            } else {
                (bins[0] + bins[BLOCK - 1]) as f64 * 0.5 * df
            };
            b
        })
        .collect()
}

/// Welch estimates at the bins `1..nper/2`: ground auto-spectrum, the channel's, and the
/// cross-spectrum conj(G)·Y.
struct Spectra {
    gg: Vec<f64>,
    yy: Vec<f64>,
    gy: Vec<Complex64>,
}

fn spectra(ground: &[f64], y: &[f64], nper: usize) -> Spectra {
    let mut planner = FftPlanner::new();
    let fft = planner.plan_fft_forward(nper);
    let hann: Vec<f64> = (0..nper)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / nper as f64).cos())
        .collect();
    let bins = nper / 2;
    let mut s = Spectra {
        gg: vec![0.0; bins],
        yy: vec![0.0; bins],
        gy: vec![Complex64::new(0.0, 0.0); bins],
    };
    let window = |x: &[f64]| -> Vec<Complex64> {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let mut w: Vec<Complex64> = x
            .iter()
            .zip(&hann)
            .map(|(v, h)| Complex64::new((v - mean) * h, 0.0))
            .collect();
        fft.process(&mut w);
        w
    };
    let step = nper / 2;
    let mut start = 0;
    while start + nper <= ground.len() {
        let g = window(&ground[start..start + nper]);
        let v = window(&y[start..start + nper]);
        for b in 1..bins {
            s.gg[b] += g[b].norm_sqr();
            s.yy[b] += v[b].norm_sqr();
            s.gy[b] += g[b].conj() * v[b];
        }
        start += step;
    }
    s
}

/// The phase lag of a storey's absolute acceleration behind the ground's for one mode of
/// damping `zeta` at `r = f/f₁ < 1` (rad, ≥ 0).
fn structural_lag(r: f64, zeta: f64) -> f64 {
    let a = (2.0 * zeta * r).atan();
    let b = (2.0 * zeta * r).atan2(1.0 - r * r);
    (b - a).max(0.0)
}

/// The segment length of the Welch estimates: a power of two with at least 8 half-overlapping
/// segments, fine enough below a low mode; `None` for a record too short.
fn segment(n: usize) -> Option<usize> {
    let cap = 4096.min(n / 8);
    (cap >= 64).then(|| 1usize << (usize::BITS - 1 - cap.leading_zeros()))
}

/// The first mode (Hz): the peak of the top storey's transfer function from the ground
/// (`top`: its absolute acceleration, on the ground's grid), where the first mode dominates.
pub(crate) fn first_mode(dt: f64, ground: &[f64], top: &[f64]) -> Option<f64> {
    let n = ground.len().min(top.len());
    let nper = segment(n)?;
    let s = spectra(&ground[..n], &top[..n], nper);
    let h = |b: usize| {
        if s.gg[b] > 0.0 {
            s.gy[b].norm() / s.gg[b]
        } else {
            0.0
        }
    };
    let peak = (1..nper / 2).max_by(|&a, &b| h(a).total_cmp(&h(b)))?;
    Some(peak as f64 / (nper as f64 * dt))
}

/// The delay of `y` against `ground` (same grid, step `dt`) from the phase below half the
/// first mode `f1` (Hz, estimated from the ground and top storey records), or `None` where the record does not show one (too
/// short, too few coherent frequencies, or a phase that is not a straight line).
pub fn measure(dt: f64, ground: &[f64], y: &[f64], f1: f64) -> Option<Delay> {
    // A record as short as a Welch estimate would refuse is refused here too.
    segment(ground.len().min(y.len()))?;
    // Blocks below half the first mode with a coherent phase, unwrapped from the lowest up.
    let mut pts: Vec<(f64, f64, f64)> = Vec::new(); // (ω, phase, weight)
    let mut previous: Option<f64> = None;
    for b in blocks(dt, ground, y) {
        if b.hz >= 0.5 * f1 {
            break;
        }
        let d = b.gg * b.yy;
        let c = if d > 0.0 { b.gy.norm_sqr() / d } else { 0.0 };
        if c < MIN_COHERENCE {
            continue;
        }
        let mut phase = b.gy.arg();
        if let Some(p) = previous {
            phase += 2.0 * PI * ((p - phase) / (2.0 * PI)).round();
        }
        previous = Some(phase);
        // The phase estimate's variance is ∝ (1 − γ²)/γ².
        let w = c / (1.0 - c).max(1e-6);
        pts.push((2.0 * PI * b.hz, phase, w));
    }
    if pts.len() < MIN_BINS {
        return None;
    }
    let sww: f64 = pts.iter().map(|&(w, _, c)| c * w * w).sum();
    let tau = -pts.iter().map(|&(w, p, c)| c * w * p).sum::<f64>() / sww;
    let sw: f64 = pts.iter().map(|&(_, _, c)| c).sum();
    let rss: f64 = pts.iter().map(|&(w, p, c)| c * (p + w * tau).powi(2)).sum();
    if (rss / sw).sqrt() > MAX_RESIDUAL {
        return None;
    }
    let se = (rss / (pts.len() - 1) as f64 / sww).sqrt();
    let bound = pts
        .iter()
        .map(|&(w, _, c)| c * w * structural_lag(w / (2.0 * PI * f1), ZETA_BOUND))
        .sum::<f64>()
        / sww;
    let mut d = Delay {
        seconds: tau,
        standard_error: se,
        structural_bound: bound,
        first_mode_hz: f1,
        band_hz: (pts[0].0 / (2.0 * PI), pts[pts.len() - 1].0 / (2.0 * PI)),
        bins: pts.len(),
        removed: false,
    };
    d.decide(dt);
    Some(d)
}

/// `x` advanced by `shift` samples (`y[n] = x(n + shift)`), band-limited: the spectrum of the
/// zero-padded signal turned by `e^{iω·shift}`. Samples the shift pulls in from beyond the ends
/// are meaningless; the caller drops them.
pub fn advance(x: &[f64], shift: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return x.to_vec();
    }
    // The line through the end values is shifted exactly; what remains starts and ends at
    // zero, so the zero padding adds no step for the spectrum to ring at.
    let slope = (x[n - 1] - x[0]) / (n - 1) as f64;
    let line = |t: f64| x[0] + slope * t;
    let m = (2 * n).next_power_of_two();
    let mut planner = FftPlanner::new();
    let forward = planner.plan_fft_forward(m);
    let inverse = planner.plan_fft_inverse(m);
    let mut buf: Vec<Complex64> = x
        .iter()
        .enumerate()
        .map(|(i, &v)| Complex64::new(v - line(i as f64), 0.0))
        .chain(std::iter::repeat(Complex64::new(0.0, 0.0)))
        .take(m)
        .collect();
    forward.process(&mut buf);
    for (k, z) in buf.iter_mut().enumerate() {
        // Signed frequency index; the Nyquist bin keeps a real factor.
        let kk = if k <= m / 2 {
            k as f64
        } else {
            k as f64 - m as f64
        };
        let a = 2.0 * PI * kk * shift / m as f64;
        *z *= if 2 * k == m {
            Complex64::new(a.cos(), 0.0)
        } else {
            Complex64::from_polar(1.0, a)
        };
    }
    inverse.process(&mut buf);
    buf[..n]
        .iter()
        .enumerate()
        .map(|(i, z)| z.re / m as f64 + line(i as f64 + shift))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-storey frame (f₁, ζ) under broadband ground motion, absolute acceleration, its
    /// sensor `lag` samples late, with 2 % noise.
    fn frame(f1: f64, zeta: f64, dt: f64, lag: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
        frame_run(f1, zeta, dt, lag, n, 0, None, 0.02)
    }

    /// [`frame`] with the ground motion and noise of run `run`, the ground motion's amplitude
    /// modulated by `bursts` (Gaussian envelopes of s.d. 0.4 s at random times: an earthquake's
    /// or a table's uneven shaking) and the sensor's noise `noise` of the response's RMS.
    #[allow(clippy::too_many_arguments)]
    fn frame_run(
        f1: f64,
        zeta: f64,
        dt: f64,
        lag: f64,
        n: usize,
        run: u64,
        bursts: Option<usize>,
        noise: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        use rand::Rng;
        let mut rng = core_filters::rng::stream(7, run, "clock-delay-test");
        // Band-limited white ground motion (a moving average of white noise).
        let white: Vec<f64> = (0..n + 8).map(|_| rng.random::<f64>() - 0.5).collect();
        let mut ug: Vec<f64> = (0..n).map(|k| white[k..k + 4].iter().sum()).collect();
        if let Some(count) = bursts {
            let length = n as f64 * dt;
            let centres: Vec<f64> = (0..count)
                .map(|_| length * (0.05 + 0.85 * rng.random::<f64>()))
                .collect();
            for (k, u) in ug.iter_mut().enumerate() {
                let t = k as f64 * dt;
                *u *= centres
                    .iter()
                    .map(|c| (-0.5 * ((t - c) / 0.4).powi(2)).exp())
                    .sum::<f64>();
            }
        }
        // Semi-implicit Euler, 400 sub-steps per sample (its velocity and displacement are half
        // a sub-step apart: 0.01 ms at 120 Hz).
        let (w, sub) = (2.0 * PI * f1, 400);
        let h = dt / sub as f64;
        let (mut x, mut v) = (0.0, 0.0);
        let mut abs = Vec::with_capacity(n);
        for k in 0..n {
            // The ground motion interpolated over the interval before sample k (held, it
            // would delay or advance the response by half a sample).
            let u0 = if k > 0 { ug[k - 1] } else { 0.0 };
            for i in 0..sub {
                let u = u0 + (ug[k] - u0) * (i as f64 + 0.5) / sub as f64;
                v += h * (-u - 2.0 * zeta * w * v - w * w * x);
                x += h * v;
            }
            abs.push(-2.0 * zeta * w * v - w * w * x);
        }
        let late = advance(&abs, -lag);
        let rms = (abs.iter().map(|a| a * a).sum::<f64>() / n as f64).sqrt();
        let y = late
            .iter()
            .map(|a| a + noise * rms * (rng.random::<f64>() - 0.5) * 12f64.sqrt())
            .collect();
        (ug, y)
    }

    #[test]
    fn a_band_limited_advance_undoes_a_delay_inside_the_record() {
        let x: Vec<f64> = (0..512)
            .map(|k| (0.3 * k as f64).sin() + 0.5 * (1.1 * k as f64).cos())
            .collect();
        let late = advance(&x, -2.35);
        let back = advance(&late, 2.35);
        // Away from the ends, where the shifts pulled in padding.
        for k in 40..470 {
            assert!((back[k] - x[k]).abs() < 0.02, "{k}: {} {}", back[k], x[k]);
        }
        // A whole-sample advance is a shift.
        let one = advance(&x, 1.0);
        for k in 40..470 {
            assert!((one[k] - x[k + 1]).abs() < 0.02);
        }
    }

    #[test]
    fn a_stiff_frame_sensor_2_3_samples_late_is_measured_and_removed() {
        let dt = 1.0 / 120.0;
        let (ug, y) = frame(22.0, 0.01, dt, 2.34, 2560);
        let f1 = first_mode(dt, &ug, &y).expect("a mode");
        let d = measure(dt, &ug, &y, f1).expect("measured");
        assert!((d.seconds / dt - 2.34).abs() < 0.1, "{d:?}");
        assert!(d.removed, "{d:?}");
        assert!((d.first_mode_hz - 22.0).abs() < 1.0, "{d:?}");
    }

    #[test]
    fn a_late_sensor_on_a_frame_whose_first_mode_is_low_in_a_short_record() {
        // A first mode at 7.8 Hz leaves the band below 3.9 Hz: about 8 bins of a 21 s record.
        let dt = 1.0 / 120.0;
        let (ug, y) = frame(7.8, 0.02, dt, 2.34, 2560);
        let f1 = first_mode(dt, &ug, &y).expect("a mode");
        let d = measure(dt, &ug, &y, f1).expect("measured");
        assert!((d.seconds / dt - 2.34).abs() < 0.15, "{d:?}");
        assert!(d.removed, "{d:?}");
    }

    /// A lightly damped stiff frame rings for seconds after each burst of an uneven shaking;
    /// a Welch segment of a short record cuts that response off, and its phase with it. On 12
    /// nearly noise-free records (0.1 % noise) the whole record's estimate finds the delay, less
    /// the structure's own lag (its ζ is known here), with an RMS error of 0.021 ms (at most
    /// 0.046); Welch segments of 256 samples missed it on the same records by 0.17 ms RMS (at
    /// most 0.34). The bounds leave room for the simulation's own skew (0.01 ms) and the noise.
    #[test]
    fn the_delay_of_a_lightly_damped_frame_under_uneven_shaking_is_found_to_a_thirtieth_of_a_ms() {
        let (dt, f1, zeta, lag) = (1.0 / 120.0, 9.2, 0.007, 2.34);
        let mut errors = Vec::new();
        for run in 0..12 {
            let (ug, y) = frame_run(f1, zeta, dt, lag, 2560, run, Some(6), 0.001);
            let d = measure(dt, &ug, &y, f1).expect("measured");
            // The lag the structure itself puts into the fit: ∝ ζ at these frequencies.
            let own = d.structural_bound * zeta / ZETA_BOUND;
            let error = d.seconds - lag * dt - own;
            errors.push(error);
        }
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        let worst = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        assert!(
            rms < 3e-5 && worst < 6e-5,
            "RMS {:.4} ms, worst {:.4} ms",
            rms * 1e3,
            worst * 1e3
        );
    }

    #[test]
    fn a_sensor_on_time_is_left_alone_even_with_much_damping() {
        let dt = 1.0 / 120.0;
        for (f1, zeta) in [(22.0, 0.01), (3.7, 0.1), (8.0, 0.05)] {
            let (ug, y) = frame(f1, zeta, dt, 0.0, 12000);
            let f1 = first_mode(dt, &ug, &y).expect("a mode");
            let d = measure(dt, &ug, &y, f1).expect("measured");
            assert!(!d.removed, "{f1} {zeta}: {d:?}");
            assert!(d.seconds.abs() < 0.25 * dt, "{f1} {zeta}: {d:?}");
        }
    }

    #[test]
    fn the_structures_own_lag_is_zero_at_rest_and_grows_towards_the_mode() {
        assert_eq!(structural_lag(0.0, 0.1), 0.0);
        let (a, b) = (structural_lag(0.25, 0.1), structural_lag(0.5, 0.1));
        assert!(a > 0.0 && b > a, "{a} {b}");
        // 2ζr³/(1−r²) for small ζ: 0.0333 at r = 0.5, ζ = 0.1.
        assert!((b - 0.0333).abs() < 0.002, "{b}");
    }
}
