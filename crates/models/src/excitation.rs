//! Ground motions (SPEC §2): the vendored El Centro 1940 N-S record, Kanai–Tajimi /
//! Clough–Penzien filtered white noise, harmonic input. Accelerations are in m/s², sampled
//! uniformly from `t = 0`.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// Standard gravity used to convert records in g (SPEC §2).
pub const G: f64 = 9.81;

/// Time step of the data and of the filters (SPEC §2–3).
pub(crate) const DEFAULT_DT: f64 = 0.005;

/// Amplitude scale of El Centro in the paper preset (SPEC §2).
pub(crate) const EL_CENTRO_SCALE: f64 = 3.0;

/// A uniformly sampled ground acceleration, `acc[k]` at `t = k·dt`, in m/s².
#[derive(Debug, Clone, PartialEq)]
pub struct GroundMotion {
    pub dt: f64,
    pub acc: Vec<f64>,
}

impl GroundMotion {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.acc.len()
    }

    pub fn is_empty(&self) -> bool {
        self.acc.is_empty()
    }

    /// Duration `(len − 1)·dt`.
    pub fn duration(&self) -> f64 {
        self.acc.len().saturating_sub(1) as f64 * self.dt
    }

    /// Sample times.
    pub fn times(&self) -> Vec<f64> {
        (0..self.acc.len()).map(|k| k as f64 * self.dt).collect()
    }

    /// Linear interpolation onto the grid `k·new_dt` covering the same duration. The number of
    /// samples is `floor(duration/new_dt) + 1`, with a relative slack of 1e-9 so that
    /// 31.18 s / 0.005 s gives 6236 intervals despite rounding. That many samples are
    /// allocated: callers bound them first with [`crate::limits::samples_for_duration`] (as
    /// [`crate::dataset::ground_motion`] does).
    #[track_caller]
    pub fn resample_linear(&self, new_dt: f64) -> GroundMotion {
        assert!(new_dt > 0.0, "new_dt must be positive");
        if self.acc.len() < 2 {
            return GroundMotion {
                dt: new_dt,
                acc: self.acc.clone(),
            };
        }
        let intervals = (self.duration() / new_dt * (1.0 + 1e-9)).floor() as usize;
        let last = self.acc.len() - 1;
        let acc = (0..=intervals)
            .map(|i| {
                let pos = i as f64 * new_dt / self.dt;
                let j = (pos.floor() as usize).min(last - 1);
                let frac = (pos - j as f64).clamp(0.0, 1.0);
                self.acc[j] + frac * (self.acc[j + 1] - self.acc[j])
            })
            .collect();
        GroundMotion { dt: new_dt, acc }
    }

    /// Every sample multiplied by `factor`.
    pub fn scaled(&self, factor: f64) -> GroundMotion {
        GroundMotion {
            dt: self.dt,
            acc: self.acc.iter().map(|a| a * factor).collect(),
        }
    }

    /// The samples with `t ≤ duration` (a relative slack of 1e-9 absorbs rounding); never more
    /// than the record holds, whatever `duration` is.
    pub fn truncated(&self, duration: f64) -> GroundMotion {
        let keep =
            (((duration / self.dt) * (1.0 + 1e-9)).floor().max(0.0) as usize).saturating_add(1);
        GroundMotion {
            dt: self.dt,
            acc: self.acc[..keep.min(self.acc.len())].to_vec(),
        }
    }

    /// Peak ground acceleration `max |ü_g|`.
    pub fn pga(&self) -> f64 {
        self.acc.iter().fold(0.0, |m, a| m.max(a.abs()))
    }

    /// Root mean square over all samples.
    pub fn rms(&self) -> f64 {
        rms(&self.acc)
    }
}

/// Root mean square of a slice (0 for an empty slice).
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// `a·sin(ω t)` sampled at `k·dt` for `t ≤ duration` (SPEC §2 harmonic input). The
/// `floor(duration/dt) + 1` samples are allocated: callers bound them first with
/// [`crate::limits::samples_for_duration`].
pub fn harmonic(amplitude: f64, omega: f64, duration: f64, dt: f64) -> GroundMotion {
    assert!(dt > 0.0, "dt must be positive");
    let n = ((duration / dt) * (1.0 + 1e-9)).floor().max(0.0) as usize + 1;
    GroundMotion {
        dt,
        acc: (0..n)
            .map(|k| amplitude * (omega * k as f64 * dt).sin())
            .collect(),
    }
}

/// Parameters of the Kanai–Tajimi / Clough–Penzien filtered white noise (SPEC §2).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KanaiTajimi {
    /// Ground filter frequency ω_g (rad/s) and damping ζ_g.
    pub omega_g: f64,
    pub zeta_g: f64,
    /// Clough–Penzien high-pass frequency ω_f (rad/s) and damping ζ_f.
    pub omega_f: f64,
    pub zeta_f: f64,
    /// Target peak ground acceleration (m/s²).
    pub pga: f64,
}

impl Default for KanaiTajimi {
    /// SPEC §2 values; the target PGA is the PGA of El Centro at scale 1 (0.31882 g), so that the
    /// `scale` of a data set plays the same role for both records.
    fn default() -> Self {
        Self {
            omega_g: 15.6,
            zeta_g: 0.6,
            omega_f: 1.5,
            zeta_f: 0.6,
            pga: 0.31882 * G,
        }
    }
}

/// Shinozuka–Sato envelope `e(t) = 4(exp(−0.25t) − exp(−0.5t))` (peak 1 at t = 4 ln 2).
pub fn envelope(t: f64) -> f64 {
    4.0 * ((-0.25 * t).exp() - (-0.5 * t).exp())
}

/// Clough–Penzien filtered white noise with the Shinozuka–Sato envelope, scaled to
/// `params.pga` (SPEC §2). White noise `w` (piecewise constant, variance 1/dt per step) drives
/// the Kanai–Tajimi filter `ẍ_g + 2ζ_gω_g ẋ_g + ω_g² x_g = w`, whose output
/// `a_1 = ω_g² x_g + 2ζ_gω_g ẋ_g` drives the high-pass `ẍ_f + 2ζ_fω_f ẋ_f + ω_f² x_f = a_1`; the
/// ground acceleration is `e(t)·ẍ_f`, i.e. the transfer function
/// `(ω_g² + 2ζ_gω_g s)/(s² + 2ζ_gω_g s + ω_g²) · s²/(s² + 2ζ_fω_f s + ω_f²)`. Each step is
/// integrated with RK4 (ω_g·dt = 0.08 at dt = 0.005 s, well inside RK4's accurate range).
/// Callers bound the `floor(duration/dt) + 1` samples first with
/// [`crate::limits::samples_for_duration`].
pub(crate) fn kanai_tajimi<R: Rng + ?Sized>(
    params: &KanaiTajimi,
    duration: f64,
    dt: f64,
    rng: &mut R,
) -> GroundMotion {
    assert!(dt > 0.0, "dt must be positive");
    let n = ((duration / dt) * (1.0 + 1e-9)).floor().max(0.0) as usize + 1;
    let p = *params;
    // State [x_g, ẋ_g, x_f, ẋ_f].
    let deriv = |s: &[f64; 4], w: f64| -> ([f64; 4], f64) {
        let xg_dd = w - 2.0 * p.zeta_g * p.omega_g * s[1] - p.omega_g * p.omega_g * s[0];
        let a1 = p.omega_g * p.omega_g * s[0] + 2.0 * p.zeta_g * p.omega_g * s[1];
        let xf_dd = a1 - 2.0 * p.zeta_f * p.omega_f * s[3] - p.omega_f * p.omega_f * s[2];
        ([s[1], xg_dd, s[3], xf_dd], xf_dd)
    };
    let mut s = [0.0; 4];
    let mut acc = Vec::with_capacity(n);
    acc.push(0.0);
    let sd = (1.0 / dt).sqrt();
    for k in 1..n {
        let z: f64 = StandardNormal.sample(rng);
        let w = sd * z;
        let add = |s: &[f64; 4], d: &[f64; 4], h: f64| std::array::from_fn(|i| s[i] + h * d[i]);
        let (d1, _) = deriv(&s, w);
        let (d2, _) = deriv(&add(&s, &d1, 0.5 * dt), w);
        let (d3, _) = deriv(&add(&s, &d2, 0.5 * dt), w);
        let (d4, _) = deriv(&add(&s, &d3, dt), w);
        s = std::array::from_fn(|i| s[i] + dt / 6.0 * (d1[i] + 2.0 * d2[i] + 2.0 * d3[i] + d4[i]));
        // Output acceleration at t_k with the input of the step just taken (zero-order hold).
        let (_, a) = deriv(&s, w);
        acc.push(envelope(k as f64 * dt) * a);
    }
    let gm = GroundMotion { dt, acc };
    let peak = gm.pga();
    if peak > 0.0 {
        gm.scaled(p.pga / peak)
    } else {
        gm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::rng::{purpose, stream};

    #[test]
    fn truncate_scale_harmonic() {
        let h = harmonic(3.0, 4.0, 31.18, 0.005);
        assert_eq!(h.len(), 6237);
        assert!((h.acc[100] - 3.0 * (4.0f64 * 0.5).sin()).abs() < 1e-12);
        let t = h.truncated(1.0);
        assert_eq!(t.len(), 201);
        assert_eq!(h.truncated(f64::INFINITY).len(), h.len());
        assert_eq!(h.truncated(1e300).len(), h.len());
        assert_eq!(h.scaled(2.0).acc[7], 2.0 * h.acc[7]);
        assert!((rms(&[3.0, -4.0]) - (12.5f64).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn kanai_tajimi_reproducible_and_scaled() {
        let p = KanaiTajimi::default();
        let a = kanai_tajimi(&p, 20.0, 0.005, &mut stream(3, 0, purpose::EXCITATION));
        let b = kanai_tajimi(&p, 20.0, 0.005, &mut stream(3, 0, purpose::EXCITATION));
        let c = kanai_tajimi(&p, 20.0, 0.005, &mut stream(4, 0, purpose::EXCITATION));
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(a.len(), 4001);
        assert!((a.pga() - p.pga).abs() < 1e-12);
        // The envelope shapes the record: the late tail (e(20) ≈ 0.02) is much weaker than the
        // strong phase around the envelope's peak.
        let strong = rms(&a.acc[400..800]);
        let tail = rms(&a.acc[3600..]);
        assert!(tail < 0.2 * strong, "strong {strong}, tail {tail}");
    }
}
