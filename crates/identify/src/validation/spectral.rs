//! Measured floor/ground transfer functions (Welch's H1 estimate) and their peaks.
//!
//! For each measured floor, with x the measured ground acceleration and y the floor's absolute
//! acceleration (relative channels plus ü_g), H1(f) = P_xy(f) / P_xx(f): cross- and auto-spectra
//! averaged over segments of L samples (L the largest power of two ≤ K/4, at most 8192, so at
//! least seven segments), Hann window, 50 % overlap, each segment's mean removed. Uncorrelated
//! noise on y does not bias H1. The FFT is a plain iterative radix-2 routine (`fft`), tested
//! against the direct DFT.
//!
//! Peaks are read from the sum over channels of |H1| (each floor sees every mode, with the
//! weight of its mode shape), only where H1 means something: where the ground motion has energy
//! — P_xx within 30 dB of its largest value, up to the bin below the Nyquist frequency (a stiff
//! frame sampled at 120 Hz has its third mode near 40 Hz, above half the Nyquist frequency) — and
//! where at least one
//! floor's magnitude-squared coherence γ² = |P_xy|²/(P_xx P_yy) with the ground is ≥ 0.5 (the
//! response there is mostly driven by the measured ground motion, not noise). The local maxima
//! there, the N largest (N storeys) kept and reported by increasing frequency, each refined by a
//! parabola through the three bins around it. Known limits: a mode whose half-power bandwidth
//! 2ζf is narrower than the resolution is smeared (its coherence too); a weak mode can lose to a
//! noise bump that passes both tests.

use thiserror::Error;

pub use crate::record::validation::Peak;

/// Shortest record for a transfer function: 8 segments of 32 samples.
pub(crate) const MIN_SAMPLES: usize = 128;
/// Longest segment.
pub const MAX_SEGMENT: usize = 8192;
/// The ground motion's band: P_xx above this fraction of its largest value (30 dB).
pub(crate) const BAND_FRACTION: f64 = 1e-3;
/// A peak needs this coherence on at least one channel, at its bin or a neighbour (and no larger
/// maximum within three bins): at a lightly damped mode whose half-power band is about
/// one bin wide, the Welch estimate's resolution bias lowers the coherence at the peak itself (the stiff one-storey frame, ζ ≈ 0.5 % at 22.0 Hz,
/// bins of 0.23 Hz: 0.40 at the peak, 0.77 one bin above, 0.98 three bins off; docs/real-frame.md).
pub(crate) const MIN_COHERENCE: f64 = 0.5;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpectralError {
    #[error(
        "the record has {0} samples: too short for a transfer-function estimate (at least {MIN_SAMPLES})"
    )]
    TooShort(usize),
    #[error("the measured ground acceleration is zero: no transfer function")]
    NoInput,
}

crate::error::domain_error!(SpectralError);

/// In-place radix-2 FFT of (re, im), length a power of two: X_k = Σ x_n e^{−2πikn/L}.
pub(crate) fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    assert!(n.is_power_of_two() && im.len() == n, "FFT length");
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let ang = -std::f64::consts::TAU / len as f64;
        for start in (0..n).step_by(len) {
            for k in 0..len / 2 {
                let (s, c) = (ang * k as f64).sin_cos();
                let (a, b) = (start + k, start + k + len / 2);
                let tr = re[b] * c - im[b] * s;
                let ti = re[b] * s + im[b] * c;
                re[b] = re[a] - tr;
                im[b] = im[a] - ti;
                re[a] += tr;
                im[a] += ti;
            }
        }
        len <<= 1;
    }
}

/// Welch H1 estimates of several outputs against one input.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferEstimate {
    /// Segment length L and number of segments averaged.
    pub segment: usize,
    pub segments: usize,
    /// Frequency resolution 1/(L·dt) in Hz.
    pub resolution_hz: f64,
    /// Bin frequencies 0..=L/2 (Hz).
    pub frequency_hz: Vec<f64>,
    /// |H1| per output channel, per bin.
    pub magnitude: Vec<Vec<f64>>,
    /// Im H1 per output channel, per bin: the quadrature response the operating shapes are read
    /// from ([`operating_shape`]).
    pub quadrature: Vec<Vec<f64>>,
    /// P_xx per bin (input auto-spectrum, arbitrary scale).
    pub pxx: Vec<f64>,
    /// Magnitude-squared coherence per output channel, per bin.
    pub coherence: Vec<Vec<f64>>,
}

/// The segment length for K samples.
pub(crate) fn segment_length(k: usize) -> Result<usize, SpectralError> {
    if k < MIN_SAMPLES {
        return Err(SpectralError::TooShort(k));
    }
    let mut l = 32;
    while l * 2 <= k / 4 && l * 2 <= MAX_SEGMENT {
        l *= 2;
    }
    Ok(l)
}

/// Welch H1 of each of `ys` against `x` (all sampled at `dt`).
pub fn welch_h1(x: &[f64], ys: &[Vec<f64>], dt: f64) -> Result<TransferEstimate, SpectralError> {
    let k = ys.iter().map(Vec::len).fold(x.len(), usize::min);
    let l = segment_length(k)?;
    let hop = l / 2;
    let window: Vec<f64> = (0..l)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / l as f64).cos())
        .collect();
    let bins = l / 2 + 1;
    let spectrum = |v: &[f64], start: usize| -> (Vec<f64>, Vec<f64>) {
        let seg = &v[start..start + l];
        let mean = seg.iter().sum::<f64>() / l as f64;
        let mut re: Vec<f64> = seg
            .iter()
            .zip(&window)
            .map(|(a, w)| (a - mean) * w)
            .collect();
        let mut im = vec![0.0; l];
        fft(&mut re, &mut im);
        (re, im)
    };
    let mut pxx = vec![0.0; bins];
    let mut pxy = vec![(vec![0.0; bins], vec![0.0; bins]); ys.len()];
    let mut pyy = vec![vec![0.0; bins]; ys.len()];
    let mut segments = 0;
    let mut start = 0;
    while start + l <= k {
        let (xr, xi) = spectrum(x, start);
        for b in 0..bins {
            pxx[b] += xr[b] * xr[b] + xi[b] * xi[b];
        }
        for ((y, (pr, pi)), py) in ys.iter().zip(pxy.iter_mut()).zip(pyy.iter_mut()) {
            let (yr, yi) = spectrum(y, start);
            for b in 0..bins {
                py[b] += yr[b] * yr[b] + yi[b] * yi[b];
                // conj(X)·Y
                pr[b] += xr[b] * yr[b] + xi[b] * yi[b];
                pi[b] += xr[b] * yi[b] - xi[b] * yr[b];
            }
        }
        segments += 1;
        start += hop;
    }
    if pxx.iter().all(|p| *p == 0.0) {
        return Err(SpectralError::NoInput);
    }
    // H1 = P_xy / P_xx per bin (NaN where the input has no power): its modulus and its
    // imaginary part.
    let h1 = |part: fn(f64, f64) -> f64| -> Vec<Vec<f64>> {
        pxy.iter()
            .map(|(pr, pi)| {
                (0..bins)
                    .map(|b| {
                        if pxx[b] > 0.0 {
                            part(pr[b], pi[b]) / pxx[b]
                        } else {
                            f64::NAN
                        }
                    })
                    .collect()
            })
            .collect()
    };
    let magnitude = h1(f64::hypot);
    let quadrature = h1(|_, im| im);
    let coherence = pxy
        .iter()
        .zip(&pyy)
        .map(|((pr, pi), py)| {
            (0..bins)
                .map(|b| {
                    let den = pxx[b] * py[b];
                    if den > 0.0 {
                        (pr[b] * pr[b] + pi[b] * pi[b]) / den
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let df = 1.0 / (l as f64 * dt);
    Ok(TransferEstimate {
        segment: l,
        segments,
        resolution_hz: df,
        frequency_hz: (0..bins).map(|b| b as f64 * df).collect(),
        magnitude,
        quadrature,
        pxx,
        coherence,
    })
}

/// The operating shape at `f_hz` by quadrature picking: per channel, Im H1 at the nearest bin.
/// The floor's absolute acceleration is its motion relative to the ground plus ü_g (whose H1
/// against itself is 1, real); near a lightly damped mode r the relative motion's transfer
/// function is φ_r·Γ_r/(2iζ_r) — imaginary — plus the other modes' off-resonance terms, nearly
/// real. So Im H1 is the mode's shape φ_r on the measured floors, times one real factor, with
/// little of the others (on a simulated three-storey chain the third mode's MAC with its true
/// shape is 0.994 this way and 0.941 with the complex H1 − 1). `None` outside the estimate's bins
/// or where a channel's H1 is not finite.
pub fn operating_shape(t: &TransferEstimate, f_hz: f64) -> Option<Vec<f64>> {
    if !(f_hz.is_finite() && f_hz >= 0.0 && t.resolution_hz > 0.0) {
        return None;
    }
    let b = (f_hz / t.resolution_hz).round() as usize;
    t.quadrature
        .iter()
        .map(|h| h.get(b).copied().filter(|im| im.is_finite()))
        .collect()
}

/// The bins where the ground motion has energy (P_xx ≥ [`BAND_FRACTION`]·max), from the second
/// bin up to the one below the Nyquist frequency.
pub(crate) fn in_band(t: &TransferEstimate) -> Vec<bool> {
    let max = t.pxx.iter().cloned().fold(0.0_f64, f64::max);
    let n = t.pxx.len();
    (0..n)
        .map(|b| b >= 2 && b + 1 < n && t.pxx[b] >= BAND_FRACTION * max)
        .collect()
}

/// The ground motion's power near `f_hz` (the largest P_xx within two bins) relative to its
/// strongest bin, in dB; `None` outside the estimate's bins or without power.
pub(crate) fn excitation_db(t: &TransferEstimate, f_hz: f64) -> Option<f64> {
    let max = t.pxx.iter().cloned().fold(0.0_f64, f64::max);
    if !(max > 0.0 && f_hz.is_finite() && f_hz >= 0.0) {
        return None;
    }
    let b = (f_hz / t.resolution_hz).round() as usize;
    if b >= t.pxx.len() {
        return None;
    }
    let near = t.pxx[b.saturating_sub(2)..(b + 3).min(t.pxx.len())]
        .iter()
        .cloned()
        .fold(0.0_f64, f64::max);
    Some(10.0 * (near / max).log10())
}

/// The `count` largest local maxima of Σ_c |H1_c| inside the ground motion's band where at least
/// one channel's coherence is at least `MIN_COHERENCE` at the peak or a neighbouring bin and no
/// larger maximum lies within three bins, by increasing frequency.
pub fn peaks(t: &TransferEstimate, count: usize) -> Vec<Peak> {
    let n = t.frequency_hz.len();
    let sum: Vec<f64> = (0..n)
        .map(|b| t.magnitude.iter().map(|m| m[b]).sum::<f64>())
        .collect();
    let band = in_band(t);
    let mut found: Vec<Peak> = (1..n.saturating_sub(1))
        .filter(|&b| band[b] && sum[b] > sum[b - 1] && sum[b] >= sum[b + 1])
        .filter(|&b| {
            let coherent = |lo: usize, hi: usize| {
                t.coherence
                    .iter()
                    .any(|c| c[lo..=hi].iter().any(|&v| v >= MIN_COHERENCE))
            };
            coherent(b, b) || coherent(b - 1, b + 1)
        })
        // A maximum with a larger one within three bins is that peak split by noise, not a
        // mode of its own.
        .filter(|&b| {
            let (lo, hi) = (b.saturating_sub(3), (b + 3).min(n - 1));
            (lo..=hi).all(|j| sum[j] <= sum[b] || sum[j].is_nan())
        })
        .filter(|&b| sum[b].is_finite() && sum[b - 1].is_finite() && sum[b + 1].is_finite())
        .map(|b| {
            let (a, c, e) = (sum[b - 1], sum[b], sum[b + 1]);
            let den = a - 2.0 * c + e;
            let shift = if den < 0.0 { 0.5 * (a - e) / den } else { 0.0 };
            Peak {
                frequency_hz: (b as f64 + shift.clamp(-0.5, 0.5)) * t.resolution_hz,
                magnitude: c,
            }
        })
        .collect();
    found.sort_by(|a, b| b.magnitude.total_cmp(&a.magnitude));
    found.truncate(count);
    found.sort_by(|a, b| a.frequency_hz.total_cmp(&b.frequency_hz));
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fft_is_the_dft() {
        let n = 64;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 7 % 13) as f64).sin() + 0.1 * i as f64)
            .collect();
        let (mut re, mut im) = (x.clone(), vec![0.0; n]);
        fft(&mut re, &mut im);
        for k in 0..n {
            let (mut dr, mut di) = (0.0, 0.0);
            for (j, v) in x.iter().enumerate() {
                let a = -std::f64::consts::TAU * (k * j) as f64 / n as f64;
                dr += v * a.cos();
                di += v * a.sin();
            }
            assert!(
                (re[k] - dr).abs() < 1e-10 && (im[k] - di).abs() < 1e-10,
                "bin {k}"
            );
        }
    }

    #[test]
    fn a_peak_with_its_coherence_one_bin_off_is_kept_a_split_or_incoherent_one_is_not() {
        // Local maxima of |H1| at bins 10, 13 and 30: the first with coherence 0.4 at the peak
        // and 0.8 one bin above (a sharp resonance's resolution bias), the second coherent but
        // smaller than the first three bins away (the first split by noise), the third
        // incoherent everywhere near it (noise).
        let n = 40;
        let magnitude: Vec<f64> = (0..n)
            .map(|b| {
                1.0 + 5.0 / (1.0 + (b as f64 - 10.0).powi(2))
                    + 4.0 / (1.0 + (b as f64 - 30.0).powi(2))
                    + if b == 13 { 0.6 } else { 0.0 }
            })
            .collect();
        let coherence: Vec<f64> = (0..n)
            .map(|b| match b {
                10 => 0.4,
                11 => 0.8,
                29..=31 => 0.2,
                _ => 0.95,
            })
            .collect();
        let t = TransferEstimate {
            segment: 2 * (n - 1),
            segments: 8,
            resolution_hz: 0.25,
            frequency_hz: (0..n).map(|b| b as f64 * 0.25).collect(),
            magnitude: vec![magnitude],
            quadrature: Vec::new(),
            pxx: vec![1.0; n],
            coherence: vec![coherence],
        };
        let p = peaks(&t, 2);
        assert_eq!(p.len(), 1, "{p:?}");
        assert!((p[0].frequency_hz - 2.5).abs() < 0.13, "{p:?}");
    }

    #[test]
    fn h1_of_a_known_filter_and_its_peak() {
        // y = x filtered by a lightly damped oscillator (exact discrete recursion of a resonator
        // at 5 Hz): the summed |H1| peaks at 5 Hz within one bin.
        let dt = 0.01;
        let k = 20_000;
        let mut rng = core_filters::rng::stream(7, 0, "test");
        let x: Vec<f64> = (0..k)
            .map(|_| rand::Rng::random::<f64>(&mut rng) - 0.5)
            .collect();
        let (f0, zeta) = (5.0_f64, 0.02_f64);
        let w = std::f64::consts::TAU * f0;
        let r = (-zeta * w * dt).exp();
        let (a1, a2) = (
            2.0 * r * (w * dt * (1.0 - zeta * zeta).sqrt()).cos(),
            -r * r,
        );
        let mut y = vec![0.0; k];
        for i in 2..k {
            y[i] = a1 * y[i - 1] + a2 * y[i - 2] + x[i];
        }
        let t = welch_h1(&x, &[y], dt).unwrap();
        assert_eq!(t.segment, 4096);
        let p = peaks(&t, 1);
        let fd = f0 * (1.0 - zeta * zeta).sqrt();
        assert_eq!(p.len(), 1);
        assert!(
            (p[0].frequency_hz - fd).abs() < t.resolution_hz,
            "{} vs {fd}",
            p[0].frequency_hz
        );
        assert!(matches!(
            welch_h1(&x[..100], &[x[..100].to_vec()], dt),
            Err(SpectralError::TooShort(100))
        ));
    }
}
