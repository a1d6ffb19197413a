//! A check for swapped storey files: in a shear frame the first mode's shape grows with height,
//! so at the first natural frequency each storey's transfer function from the ground must be
//! larger than the storey's below. A reversed pair is the mark of two files given to the wrong
//! storeys (the shake table's `bonus-event` is such a record), but a storey may be ill-measured
//! for other reasons, so the import asks rather than refuses.
//!
//! The transfer functions are Welch H1 estimates (Hann segments, half overlap) computed by a
//! direct DFT: a handful of segments of at most 1024 samples is enough to find the first mode,
//! and a bounded cost needs no FFT.

const MAX_SEGMENT: usize = 1024;
const MAX_SEGMENTS: usize = 16;
/// Storey channels beyond this are not checked (the cost grows with each).
const MAX_CHANNELS: usize = 40;

/// |H1(f)| of each output against `input` at the bins `1..nper/2` of segments of `nper`.
fn transfer_magnitudes(input: &[f64], outputs: &[&[f64]], nper: usize) -> Vec<Vec<f64>> {
    let bins = nper / 2;
    let hann: Vec<f64> = (0..nper)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / nper as f64).cos())
        .collect();
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..nper)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / nper as f64;
            (a.cos(), a.sin())
        })
        .unzip();
    let step = nper / 2;
    let starts: Vec<usize> = (0..=(input.len() - nper) / step)
        .map(|s| s * step)
        .collect();
    let every = starts.len().div_ceil(MAX_SEGMENTS);
    let dft = |x: &[f64]| -> Vec<(f64, f64)> {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let w: Vec<f64> = x.iter().zip(&hann).map(|(v, h)| (v - mean) * h).collect();
        (1..bins)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in w.iter().enumerate() {
                    let j = (k * i) % nper;
                    re += v * cos[j];
                    im -= v * sin[j];
                }
                (re, im)
            })
            .collect()
    };
    let mut sxx = vec![0.0; bins - 1];
    let mut sxy = vec![vec![(0.0, 0.0); bins - 1]; outputs.len()];
    for &s in starts.iter().step_by(every) {
        let x = dft(&input[s..s + nper]);
        for (b, (re, im)) in x.iter().enumerate() {
            sxx[b] += re * re + im * im;
        }
        for (o, out) in outputs.iter().enumerate() {
            let y = dft(&out[s..s + nper]);
            for (b, ((xr, xi), (yr, yi))) in x.iter().zip(&y).enumerate() {
                // conj(X)·Y
                sxy[o][b].0 += xr * yr + xi * yi;
                sxy[o][b].1 += xr * yi - xi * yr;
            }
        }
    }
    sxy.iter()
        .map(|s| {
            s.iter()
                .zip(&sxx)
                .map(|((re, im), xx)| {
                    if *xx > 0.0 {
                        (re * re + im * im).sqrt() / xx
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// A warning when, at the first mode (the peak of the top storey's transfer function from the
/// ground), a storey's transfer function is smaller than the one of the storey below it.
pub(crate) fn swapped_storeys_warning(
    dt: f64,
    ground: &[f64],
    sensors: &[usize],
    storeys: &[Vec<f64>],
) -> Option<String> {
    if storeys.len() < 2 || storeys.len() > MAX_CHANNELS {
        return None;
    }
    // The largest power of two within a quarter of the record: at least 7 half-overlapping
    // segments to average.
    let cap = MAX_SEGMENT.min(ground.len() / 4);
    if cap < 64 {
        return None;
    }
    let nper = 1usize << (usize::BITS - 1 - cap.leading_zeros());
    let outs: Vec<&[f64]> = storeys.iter().map(Vec::as_slice).collect();
    let h = transfer_magnitudes(ground, &outs, nper);
    let top = h.last()?;
    let peak = (0..top.len()).max_by(|&a, &b| top[a].total_cmp(&top[b]))?;
    let at = |j: usize| {
        let lo = peak.saturating_sub(1);
        let hi = (peak + 1).min(top.len() - 1);
        h[j][lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64
    };
    let f = (peak + 1) as f64 / (nper as f64 * dt);
    let reversed: Vec<String> = (1..storeys.len())
        .filter(|&j| at(j) < at(j - 1))
        .map(|j| {
            format!(
                "storey {} ({:.1}) below storey {} ({:.1})",
                sensors[j],
                at(j),
                sensors[j - 1],
                at(j - 1)
            )
        })
        .collect();
    (!reversed.is_empty()).then(|| {
        format!(
            "at the first mode ({f:.2} Hz, the peak of the top storey's transfer function from \
             the ground) the response does not grow with height: {}; a shear frame's first \
             mode does, so check that these storeys' files are not swapped",
            reversed.join(", ")
        )
    })
}
