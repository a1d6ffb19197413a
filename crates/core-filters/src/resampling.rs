//! Resampling schemes over one shared inverse-CDF kernel (STYLE lesson 4; SPEC §3).
//!
//! Every scheme has the same signature: given normalised weights `w` it writes `M = ancestors.len()`
//! ancestor indices into a buffer the caller owns, drawing from the generator it is given. The
//! schemes differ only in how they produce the sorted points `u_1 ≤ … ≤ u_M` in `[0, 1)` that the
//! kernel `inverse_cdf` maps through the cumulative weights:
//! - systematic: `u_j = (j + U) / M`, one uniform (the default, SPEC §3);
//! - stratified: `u_j = (j + U_j) / M`, one uniform per stratum;
//! - multinomial: `M` sorted i.i.d. uniforms, generated already sorted from exponential spacings;
//! - residual: `⌊M w_i⌋` deterministic copies, the remainder drawn multinomially from the residual
//!   weights.
//!
//! All are unbiased: the expected number of offspring of particle `i` is `M w_i`.

use rand::Rng;
use rand_distr::{Distribution, Exp1};
use serde::{Deserialize, Serialize};

/// The resampling scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Scheme {
    #[default]
    Systematic,
    Stratified,
    Multinomial,
    Residual,
}

impl Scheme {
    pub const ALL: [Scheme; 4] = [
        Scheme::Systematic,
        Scheme::Stratified,
        Scheme::Multinomial,
        Scheme::Residual,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Scheme::Systematic => "systematic",
            Scheme::Stratified => "stratified",
            Scheme::Multinomial => "multinomial",
            Scheme::Residual => "residual",
        }
    }
}

impl std::str::FromStr for Scheme {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Scheme::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| {
                format!("unknown resampling scheme `{s}` (expected systematic, stratified, multinomial or residual)")
            })
    }
}

/// When and how to resample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ResamplePolicy {
    pub scheme: Scheme,
    /// Resample only when `ESS < ess_threshold · Np`; `None` resamples at every step (SPEC §3).
    pub ess_threshold: Option<f64>,
}

impl Default for ResamplePolicy {
    fn default() -> Self {
        Self {
            scheme: Scheme::Systematic,
            ess_threshold: None,
        }
    }
}

impl ResamplePolicy {
    /// Whether to resample at a step with effective sample size `ess` among `np` particles.
    pub(crate) fn should_resample(&self, ess: f64, np: usize) -> bool {
        match self.ess_threshold {
            None => true,
            Some(t) => ess < t * np as f64,
        }
    }
}

/// A resampler owning the scratch it needs, so that resampling allocates nothing after set-up.
#[derive(Debug, Clone)]
pub struct Resampler {
    scheme: Scheme,
    scratch: Vec<f64>,
}

impl Resampler {
    /// A resampler for up to `capacity` particles.
    pub fn new(scheme: Scheme, capacity: usize) -> Self {
        Self {
            scheme,
            scratch: Vec::with_capacity(capacity + 1),
        }
    }

    pub fn scheme(&self) -> Scheme {
        self.scheme
    }

    /// Writes `ancestors.len()` ancestor indices drawn according to the normalised weights `w`.
    pub fn resample<G: Rng + ?Sized>(&mut self, w: &[f64], ancestors: &mut [usize], rng: &mut G) {
        let m = ancestors.len();
        assert!(!w.is_empty() && m > 0, "resampling needs particles");
        match self.scheme {
            Scheme::Systematic => {
                let u: f64 = rng.random();
                inverse_cdf(w, ancestors, |j| (j as f64 + u) / m as f64);
            }
            Scheme::Stratified => {
                inverse_cdf(w, ancestors, |j| {
                    (j as f64 + rng.random::<f64>()) / m as f64
                });
            }
            Scheme::Multinomial => {
                sorted_uniforms(m, &mut self.scratch, rng);
                let s = &self.scratch;
                inverse_cdf(w, ancestors, |j| s[j]);
            }
            Scheme::Residual => self.residual(w, ancestors, rng),
        }
    }

    fn residual<G: Rng + ?Sized>(&mut self, w: &[f64], ancestors: &mut [usize], rng: &mut G) {
        let m = ancestors.len();
        let mf = m as f64;
        // Deterministic part: ⌊M w_i⌋ copies of particle i.
        let mut filled = 0;
        for (i, &wi) in w.iter().enumerate() {
            let copies = ((mf * wi).floor() as usize).min(m - filled);
            for a in &mut ancestors[filled..filled + copies] {
                *a = i;
            }
            filled += copies;
        }
        let rest = m - filled;
        if rest == 0 {
            return;
        }
        // Random part: `rest` multinomial draws from the residual weights M w_i − ⌊M w_i⌋.
        // The residual weights are stored after the sorted uniforms in the scratch buffer.
        sorted_uniforms(rest, &mut self.scratch, rng);
        let total: f64 = w.iter().map(|&wi| mf * wi - (mf * wi).floor()).sum();
        let (u, tail) = (&self.scratch[..rest], &mut ancestors[filled..]);
        if total <= 0.0 {
            // Round-off left no residual mass: fall back to the weights themselves.
            inverse_cdf(w, tail, |j| u[j]);
            return;
        }
        inverse_cdf_by(
            w.len(),
            |i| (mf * w[i] - (mf * w[i]).floor()) / total,
            tail,
            |j| u[j],
        );
    }
}

/// `M` sorted uniforms on `[0, 1)` in O(M), from normalised cumulative sums of `M + 1` exponential
/// spacings (the order statistics of uniforms have this law), written into `buf`.
fn sorted_uniforms<G: Rng + ?Sized>(m: usize, buf: &mut Vec<f64>, rng: &mut G) {
    buf.clear();
    let mut acc = 0.0;
    for _ in 0..m {
        let e: f64 = Exp1.sample(rng);
        acc += e;
        buf.push(acc);
    }
    let e: f64 = Exp1.sample(rng);
    let total = acc + e;
    for x in buf.iter_mut() {
        *x /= total;
    }
}

/// The shared kernel: maps sorted points `u(0) ≤ u(1) ≤ …` in `[0, 1)` through the cumulative
/// weights and writes the ancestor of each point. Indices never point at a zero-weight particle,
/// even when the cumulative sum falls short of 1 by round-off.
pub(crate) fn inverse_cdf(w: &[f64], ancestors: &mut [usize], u: impl FnMut(usize) -> f64) {
    inverse_cdf_by(w.len(), |i| w[i], ancestors, u)
}

fn inverse_cdf_by(
    n: usize,
    weight: impl Fn(usize) -> f64,
    ancestors: &mut [usize],
    mut u: impl FnMut(usize) -> f64,
) {
    let last = (0..n).rev().find(|&i| weight(i) > 0.0).unwrap_or(n - 1);
    let mut i = 0;
    let mut cum = weight(0);
    for (j, a) in ancestors.iter_mut().enumerate() {
        let uj = u(j);
        while uj >= cum && i < last {
            i += 1;
            cum += weight(i);
        }
        *a = i;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream;

    #[test]
    fn degenerate_weights_give_valid_ancestors() {
        let mut rng = stream(1, 0, "test");
        for scheme in Scheme::ALL {
            for hot in [0, 3, 9] {
                let mut w = vec![0.0; 10];
                w[hot] = 1.0;
                let mut r = Resampler::new(scheme, 10);
                let mut a = vec![usize::MAX; 10];
                for _ in 0..50 {
                    r.resample(&w, &mut a, &mut rng);
                    assert!(a.iter().all(|&x| x == hot), "{scheme:?} hot={hot}: {a:?}");
                }
            }
        }
    }

    #[test]
    fn ancestors_are_sorted_and_in_range() {
        let mut rng = stream(2, 0, "test");
        let w: Vec<f64> = (1..=7).map(|i| i as f64 / 28.0).collect();
        for scheme in Scheme::ALL {
            let mut r = Resampler::new(scheme, 13);
            let mut a = vec![0; 13];
            r.resample(&w, &mut a, &mut rng);
            assert!(a.iter().all(|&x| x < 7));
            if scheme != Scheme::Residual {
                assert!(a.windows(2).all(|p| p[0] <= p[1]), "{scheme:?}");
            }
        }
    }

    #[test]
    fn parse_names() {
        for s in Scheme::ALL {
            assert_eq!(s.name().parse::<Scheme>().unwrap(), s);
        }
        assert!("bogus".parse::<Scheme>().is_err());
    }
}
