//! A smoothed elastic–perfectly-plastic law:
//!
//! `ṙ = δv − ρ ℓ(δv, r) |r|^m`,  `ℓ = δv` while loading (`δv·r > 0`), `ℓ = 0` otherwise,
//!
//! linear in θ = (ρ), nonlinear in φ = (m). On loading `ṙ = δv (1 − ρ|r|^m)`: the element
//! stiffens from `k` (at `r = 0`) down to zero as `|r|` approaches the yield value
//! `r_y = ρ^(−1/m)` (the force `k r` then stays at `k r_y`: perfectly plastic); on unloading
//! `ṙ = δv` (elastic, slope `k`), which is what makes it hysteretic. The exponent m sets how sharp
//! the elastic–plastic transition is (m → ∞: the bilinear elastic–perfectly-plastic element). It
//! is the Bouc–Wen law with β = γ = ρ/2 and n = m written with its own parameters, one linear and
//! one nonlinear; the tests use that identity as an independent check of the simulator and of the
//! partitions built on it.
//!
//! Domain: ρ ≥ 0, m ≥ 1 (as Bouc–Wen's n: `|r|^(m−1)` stays bounded at `r = 0`). Prior:
//! ρ ~ U(0, 6), m ~ U(1, 5).

use super::{sgn, HysteresisLaw, LawError};
use crate::priors::{Prior, PriorError};
use core_filters::real::Real;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// A smoothed elastic–perfectly-plastic element.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Plastic {
    /// 0-based element index (element 0 links the ground to storey 1).
    pub storey: usize,
    /// Softening coefficient ρ = r_y^(−m) (≥ 0).
    pub rho: f64,
    /// Sharpness exponent (≥ 1).
    pub m: f64,
}

/// Prior of one element's (ρ, m), independent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlasticPrior {
    /// 0-based storey of the element.
    pub storey: usize,
    pub rho: Prior,
    pub m: Prior,
}

/// `(−ℓ|r|^m, 𝟙[δv·r > 0]|r|^m, −ℓ m|r|^(m−1) sgn(r))` at one particle, the signs taken here
/// so that no lane of a pack is negated (a negated zero keeps its sign in `f64` only).
#[inline]
fn terms(dv: f64, r: f64, m: f64) -> [f64; 3] {
    if dv * r > 0.0 {
        let a = r.abs();
        let p = a.powf(m - 1.0);
        [-(dv * p * a), p * a, -(dv * m * p * sgn(r))]
    } else {
        [0.0; 3]
    }
}

/// The smoothed elastic–perfectly-plastic law: θ = (ρ), φ = (m), `g₀ = δv`, `g₁ = −ℓ|r|^m`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PlasticLaw;

impl HysteresisLaw for PlasticLaw {
    const NAME: &'static str = "elastic–plastic";
    const LINEAR: &'static [&'static str] = &["rho"];
    const NONLINEAR: &'static [&'static str] = &["m"];

    type Element = Plastic;
    type Prior = PlasticPrior;

    #[inline]
    fn basis<T: Real>(&self, dv: T, r: T, phi: &[T], g: &mut [T]) {
        let [t, _, _] = T::per_lane([dv, r, phi[0]], |[dv, r, m]| terms(dv, r, m));
        g[0] = dv;
        g[1] = t;
    }

    #[inline]
    fn rate<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> T {
        let [t, _, _] = T::per_lane([dv, r, phi[0]], |[dv, r, m]| terms(dv, r, m));
        dv + theta[0] * t
    }

    /// `∂ṙ/∂δv = 1 − ρ 𝟙[δv·r > 0]|r|^m`, `∂ṙ/∂r = −ρ ℓ m|r|^(m−1) sgn(r)` (the loading
    /// indicator's jump at `δv·r = 0` taken from the unloading side).
    #[inline]
    fn rate_partials<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> (T, T) {
        let [_, a, b] = T::per_lane([dv, r, phi[0]], |[dv, r, m]| terms(dv, r, m));
        (T::splat(1.0) - theta[0] * a, theta[0] * b)
    }

    fn element(storey: usize, params: &[f64]) -> Plastic {
        Plastic {
            storey,
            rho: params[0],
            m: params[1],
        }
    }

    fn storey(element: &Plastic) -> usize {
        element.storey
    }

    fn params(element: &Plastic, out: &mut [f64]) {
        out.copy_from_slice(&[element.rho, element.m]);
    }

    fn validate(el: &Plastic) -> Result<(), LawError> {
        for (what, value) in [("rho", el.rho), ("m", el.m)] {
            if !value.is_finite() {
                return Err(LawError::NonFinite {
                    law: Self::NAME,
                    storey: el.storey,
                    what,
                    value,
                });
            }
        }
        let out_of_range = |what, value, requirement| LawError::OutOfRange {
            law: Self::NAME,
            storey: el.storey,
            what,
            value,
            requirement,
        };
        if el.rho < 0.0 {
            return Err(out_of_range("softening rho", el.rho, "≥ 0"));
        }
        if el.m < 1.0 {
            return Err(out_of_range("exponent m", el.m, "≥ 1"));
        }
        Ok(())
    }

    /// The yield value `ρ^(−1/m)` when `ρ > 0`.
    fn saturation(el: &Plastic) -> Option<f64> {
        (el.rho > 0.0).then(|| el.rho.powf(-1.0 / el.m))
    }

    fn default_prior(storey: usize) -> PlasticPrior {
        PlasticPrior {
            storey,
            rho: Prior::Uniform { lo: 0.0, hi: 6.0 },
            m: Prior::Uniform { lo: 1.0, hi: 5.0 },
        }
    }

    fn prior_storey(prior: &PlasticPrior) -> usize {
        prior.storey
    }

    fn validate_prior(prior: &PlasticPrior, names: &[String]) -> Result<(), PriorError> {
        prior.rho.validate(&names[0], true)?;
        prior.m.validate(&names[1], true)
    }

    fn sample_prior<G: Rng + ?Sized>(prior: &PlasticPrior, rng: &mut G, out: &mut [f64]) {
        out[0] = prior.rho.sample(rng);
        out[1] = prior.m.sample(rng);
    }

    fn sample_nonlinear<G: Rng + ?Sized>(prior: &PlasticPrior, rng: &mut G, out: &mut [f64]) {
        out[0] = prior.m.sample(rng);
    }

    fn nonlinear_prior(prior: &PlasticPrior, i: usize) -> &Prior {
        debug_assert_eq!(i, 0, "one nonlinear parameter");
        &prior.m
    }

    fn prior_moments(prior: &PlasticPrior, mean: &mut [f64], var: &mut [f64]) {
        for (i, p) in [prior.rho, prior.m].iter().enumerate() {
            (mean[i], var[i]) = p.moments();
        }
    }

    fn fix_prior(prior: &mut PlasticPrior, i: usize, value: f64) {
        let _ = Self::set_prior(prior, i, Prior::Fixed { value });
    }

    fn set_prior(prior: &mut PlasticPrior, i: usize, scalar: Prior) -> bool {
        match i {
            0 => prior.rho = scalar,
            _ => prior.m = scalar,
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::bouc_wen::bouc_wen_rate;
    use core_filters::real::Pack;

    /// Points on both branches (loading δv·r > 0, unloading δv·r < 0) and at r = 0.
    const PTS: [(f64, f64, f64, f64); 5] = [
        (0.7, 0.3, 2.0, 2.0),
        (-1.2, -0.45, 1.5, 1.3),
        (0.4, -0.2, 0.5, 1.0),
        (-0.3, 0.55, 3.0, 4.2),
        (0.9, 0.0, 1.0, 1.0),
    ];

    #[test]
    fn it_is_bouc_wen_with_beta_equal_gamma() {
        let law = PlasticLaw;
        for &(dv, r, rho, m) in &PTS {
            let rate = law.rate(dv, r, &[rho], &[m]);
            let bw = bouc_wen_rate(dv, r, rho / 2.0, rho / 2.0, m);
            assert!((rate - bw).abs() < 1e-14, "{rate} vs {bw}");
            let mut g = [0.0; 2];
            law.basis(dv, r, &[m], &mut g);
            assert_eq!((g[0] + rho * g[1]).to_bits(), rate.to_bits());
            // Unloading is elastic.
            if dv * r <= 0.0 {
                assert_eq!(rate, dv);
            }
        }
    }

    #[test]
    fn partials_by_central_differences_and_packs_bit_for_bit() {
        let law = PlasticLaw;
        let h = 1e-6;
        for &(dv, r, rho, m) in &PTS[..4] {
            let f = |dv: f64, r: f64| law.rate(dv, r, &[rho], &[m]);
            let (d_dv, d_r) = law.rate_partials(dv, r, &[rho], &[m]);
            let fd_dv = (f(dv + h, r) - f(dv - h, r)) / (2.0 * h);
            let fd_r = (f(dv, r + h) - f(dv, r - h)) / (2.0 * h);
            assert!((d_dv - fd_dv).abs() < 1e-7, "{d_dv} vs {fd_dv}");
            assert!((d_r - fd_r).abs() < 1e-7, "{d_r} vs {fd_r}");
        }
        let lane = |f: fn(&(f64, f64, f64, f64)) -> f64| Pack::from_lanes(|i| f(&PTS[i]));
        let (dv, r, rho, m) = (lane(|p| p.0), lane(|p| p.1), lane(|p| p.2), lane(|p| p.3));
        let rate = law.rate(dv, r, &[rho], &[m]);
        let (a, b) = law.rate_partials(dv, r, &[rho], &[m]);
        for (i, &(dv, r, rho, m)) in PTS[..4].iter().enumerate() {
            let (sa, sb) = law.rate_partials(dv, r, &[rho], &[m]);
            let scalar = [law.rate(dv, r, &[rho], &[m]), sa, sb];
            for (p, v) in [rate, a, b].iter().zip(scalar) {
                assert_eq!(p.lane(i).to_bits(), v.to_bits());
            }
        }
    }

    #[test]
    fn the_domain_and_the_prior() {
        let el = Plastic {
            storey: 1,
            rho: 4.0,
            m: 2.0,
        };
        assert_eq!(PlasticLaw::validate(&el), Ok(()));
        assert_eq!(PlasticLaw::saturation(&el), Some(0.5));
        let e = PlasticLaw::validate(&Plastic { m: 0.9, ..el }).unwrap_err();
        assert_eq!(
            e.to_string(),
            "elastic–plastic element at storey 1: exponent m = 0.9 must be ≥ 1"
        );
        assert!(PlasticLaw::validate(&Plastic { rho: -1.0, ..el }).is_err());
        assert!(PlasticLaw::validate(&Plastic {
            rho: f64::NAN,
            ..el
        })
        .is_err());
        let mut p = PlasticLaw::default_prior(1);
        let (mut mean, mut var) = ([0.0; 2], [0.0; 2]);
        PlasticLaw::prior_moments(&p, &mut mean, &mut var);
        assert_eq!(mean, [3.0, 3.0]);
        assert!((var[0] - 3.0).abs() < 1e-12 && (var[1] - 16.0 / 12.0).abs() < 1e-12);
        PlasticLaw::fix_prior(&mut p, 1, 2.5);
        assert_eq!(p.m, Prior::Fixed { value: 2.5 });
    }
}
