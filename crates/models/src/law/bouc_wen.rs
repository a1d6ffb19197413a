//! The Bouc–Wen law (SPEC eq. 22): `ṙ = δv − β|δv||r|^(n−1) r − γ δv |r|^n`, linear in
//! θ = (β, γ), nonlinear in φ = (n).
//!
//! Everything specific to it lives here: the rate and its partials, the parameter names
//! (`beta`, `gamma`, `n`), the element record [`BoucWen`] and its validation (finite values,
//! `n ≥ 1`), the saturation bound `(1/(β+γ))^(1/n)`, and the prior [`BoucWenPrior`] of SPEC §3
//! — (β, γ) uniform on the triangle {0 ≤ β ≤ 5, |γ| ≤ β}, n ~ U(1, 5) — with its moments
//! (β: mean 10/3, variance 25/18; γ: mean 0, variance 25/6), from which the marginalised filters
//! build the Gaussian prior of (β, γ).

use super::{sgn, HysteresisLaw, LawError};
use crate::priors::{BetaGammaPrior, Prior, PriorError};
use core_filters::real::Real;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// A Bouc–Wen hysteretic element replacing the linear spring of one element of the chain.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoucWen {
    /// 0-based element index (element 0 links the ground to storey 1).
    pub storey: usize,
    pub beta: f64,
    pub gamma: f64,
    /// Exponent; `n ≥ 1` is required (see [`BoucWenLaw::validate`]).
    pub n: f64,
}

/// Prior of one Bouc–Wen element's parameters (a filter configuration's `prior.elements`
/// entry: `storey`, `beta_gamma`, `n`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoucWenPrior {
    /// 0-based storey of the element.
    pub storey: usize,
    pub beta_gamma: BetaGammaPrior,
    pub n: Prior,
}

/// `|r|^(n−1) r` and `|r|^n`, the two nonlinear terms of SPEC eq. 22 (`n ≥ 1`, so both are
/// finite and zero at `r = 0`, including `n = 1` where `0^0 = 1` multiplies `r = 0`).
#[inline]
fn bw_terms(r: f64, n: f64) -> (f64, f64) {
    let (t1, t2, _) = bw_powers(r, n);
    (t1, t2)
}

/// [`bw_terms`] and `|r|^(n−1)` itself, from one power (what the partials need as well).
#[inline]
fn bw_powers(r: f64, n: f64) -> (f64, f64, f64) {
    let a = r.abs();
    let pow_nm1 = a.powf(n - 1.0);
    (pow_nm1 * r, pow_nm1 * a, pow_nm1)
}

/// Bouc–Wen rate `ṙ = δv − β|δv||r|^(n−1) r − γ δv |r|^n` (SPEC eq. 22), through
/// [`BoucWenLaw::rate`] (the one implementation of the law).
#[inline]
pub fn bouc_wen_rate(dv: f64, r: f64, beta: f64, gamma: f64, n: f64) -> f64 {
    BoucWenLaw.rate(dv, r, &[beta, gamma], &[n])
}

/// The Bouc–Wen law (SPEC eq. 22): θ = (β, γ), φ = (n),
/// `g₀ = δv`, `g₁ = −|δv||r|^(n−1) r`, `g₂ = −δv|r|^n`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BoucWenLaw;

impl BoucWenLaw {
    /// `(|r|^(n−1) r, |r|^n)`, lane by lane through the scalar [`bw_terms`].
    #[inline]
    fn terms<T: Real>(r: T, n: T) -> (T, T) {
        let [a, b] = T::per_lane([r, n], |[r, n]| {
            let (a, b) = bw_terms(r, n);
            [a, b]
        });
        (a, b)
    }

    /// `[|r|^(n−1) r, |r|^n, n|r|^(n−1), sgn δv, sgn r]`, lane by lane, from one power.
    #[inline]
    fn partial_terms<T: Real>(dv: T, r: T, n: T) -> [T; 5] {
        T::per_lane([dv, r, n], |[dv, r, n]| {
            let (t1, t2, pow_nm1) = bw_powers(r, n);
            [t1, t2, n * pow_nm1, sgn(dv), sgn(r)]
        })
    }

    /// `g = (δv, −|δv| t₁, −δv t₂)` from `t₁ = |r|^(n−1) r`, `t₂ = |r|^n` (the basis, written
    /// once for [`HysteresisLaw::basis`] and [`HysteresisLaw::basis_and_partials`]).
    #[inline(always)]
    fn write_basis<T: Real>(dv: T, t1: T, t2: T, g: &mut [T]) {
        g[0] = dv;
        g[1] = -(dv.abs() * t1);
        g[2] = -(dv * t2);
    }

    /// [`HysteresisLaw::rate_partials`] from [`BoucWenLaw::partial_terms`].
    #[inline]
    fn partials_of<T: Real>(dv: T, theta: &[T], [t1, t2, np, sdv, sr]: [T; 5]) -> (T, T) {
        let (beta, gamma) = (theta[0], theta[1]);
        let d_dv = T::splat(1.0) - beta * sdv * t1 - gamma * t2;
        let d_r = -(beta * dv.abs() * np) - gamma * dv * np * sr;
        (d_dv, d_r)
    }
}

impl HysteresisLaw for BoucWenLaw {
    const NAME: &'static str = "Bouc–Wen";
    const LINEAR: &'static [&'static str] = &["beta", "gamma"];
    const NONLINEAR: &'static [&'static str] = &["n"];

    type Element = BoucWen;
    type Prior = BoucWenPrior;

    #[inline]
    fn basis<T: Real>(&self, dv: T, r: T, phi: &[T], g: &mut [T]) {
        let (t1, t2) = Self::terms(r, phi[0]);
        Self::write_basis(dv, t1, t2, g);
    }

    #[inline]
    fn rate<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> T {
        let (t1, t2) = Self::terms(r, phi[0]);
        dv - theta[0] * dv.abs() * t1 - theta[1] * dv * t2
    }

    /// `∂ṙ/∂δv = 1 − β sgn(δv)|r|^(n−1) r − γ|r|^n`,
    /// `∂ṙ/∂r = −β|δv| n|r|^(n−1) − γ δv n|r|^(n−1) sgn(r)` (`d(|r|^(n−1) r)/dr = n|r|^(n−1)` for
    /// `n ≥ 1`; `sgn(0) = 0`, the derivative of `|·|` at its kink taken as 0).
    #[inline]
    fn rate_partials<T: Real>(&self, dv: T, r: T, theta: &[T], phi: &[T]) -> (T, T) {
        Self::partials_of(dv, theta, Self::partial_terms(dv, r, phi[0]))
    }

    /// One power of |r| for both (Storvik's linearisation asks for both at one point).
    #[inline]
    fn basis_and_partials<T: Real>(
        &self,
        dv: T,
        r: T,
        theta: &[T],
        phi: &[T],
        g: &mut [T],
    ) -> (T, T) {
        let terms = Self::partial_terms(dv, r, phi[0]);
        Self::write_basis(dv, terms[0], terms[1], g);
        Self::partials_of(dv, theta, terms)
    }

    fn element(storey: usize, params: &[f64]) -> BoucWen {
        BoucWen {
            storey,
            beta: params[0],
            gamma: params[1],
            n: params[2],
        }
    }

    fn storey(element: &BoucWen) -> usize {
        element.storey
    }

    fn params(element: &BoucWen, out: &mut [f64]) {
        out.copy_from_slice(&[element.beta, element.gamma, element.n]);
    }

    /// Every parameter finite, and `n ≥ 1`: for `n < 1`, `|r|^(n−1)` is unbounded at `r = 0`,
    /// so the right-hand side is not Lipschitz at the origin (the start of every simulation),
    /// uniqueness of the solution is lost and the filters' Jacobians blow up. The prior (SPEC §3,
    /// `n ~ U(1, 5)`) never goes below 1.
    fn validate(bw: &BoucWen) -> Result<(), LawError> {
        for (what, value) in [("beta", bw.beta), ("gamma", bw.gamma), ("n", bw.n)] {
            if !value.is_finite() {
                return Err(LawError::NonFinite {
                    law: Self::NAME,
                    storey: bw.storey,
                    what,
                    value,
                });
            }
        }
        if bw.n < 1.0 {
            return Err(LawError::OutOfRange {
                law: Self::NAME,
                storey: bw.storey,
                what: "exponent n",
                value: bw.n,
                requirement: "≥ 1",
            });
        }
        Ok(())
    }

    /// `(1/(β+γ))^(1/n)` when `β + γ > 0` (otherwise `r` is unbounded).
    fn saturation(bw: &BoucWen) -> Option<f64> {
        let s = bw.beta + bw.gamma;
        (s > 0.0).then(|| (1.0 / s).powf(1.0 / bw.n))
    }

    /// SPEC §3: (β, γ) uniform on the triangle {0 ≤ β ≤ 5, |γ| ≤ β}, n ~ U(1, 5).
    fn default_prior(storey: usize) -> BoucWenPrior {
        BoucWenPrior {
            storey,
            beta_gamma: BetaGammaPrior::Triangle { beta_max: 5.0 },
            n: Prior::Uniform { lo: 1.0, hi: 5.0 },
        }
    }

    fn prior_storey(prior: &BoucWenPrior) -> usize {
        prior.storey
    }

    /// The triangle's hyper-parameters; n's prior with non-negative support.
    fn validate_prior(prior: &BoucWenPrior, names: &[String]) -> Result<(), PriorError> {
        prior.beta_gamma.validate()?;
        prior.n.validate(&names[2], true)
    }

    /// β and γ jointly, then n.
    fn sample_prior<G: Rng + ?Sized>(prior: &BoucWenPrior, rng: &mut G, out: &mut [f64]) {
        let (b, g) = prior.beta_gamma.sample(rng);
        out[0] = b;
        out[1] = g;
        out[2] = prior.n.sample(rng);
    }

    fn sample_nonlinear<G: Rng + ?Sized>(prior: &BoucWenPrior, rng: &mut G, out: &mut [f64]) {
        out[0] = prior.n.sample(rng);
    }

    fn nonlinear_prior(prior: &BoucWenPrior, i: usize) -> &Prior {
        debug_assert_eq!(i, 0, "one nonlinear parameter");
        &prior.n
    }

    fn prior_moments(prior: &BoucWenPrior, mean: &mut [f64], var: &mut [f64]) {
        let (mb, mg, vb, vg) = prior.beta_gamma.moments();
        let (m, v) = prior.n.moments();
        mean.copy_from_slice(&[mb, mg, m]);
        var.copy_from_slice(&[vb, vg, v]);
    }

    /// Fixing β or γ alone keeps the other's conditional prior on the triangle.
    fn fix_prior(prior: &mut BoucWenPrior, i: usize, value: f64) {
        match i {
            0 => prior.beta_gamma = prior.beta_gamma.fix_beta(value),
            1 => prior.beta_gamma = prior.beta_gamma.fix_gamma(value),
            _ => prior.n = Prior::Fixed { value },
        }
    }

    /// Only n has a scalar prior (β and γ share [`BoucWenPrior::beta_gamma`]).
    fn set_prior(prior: &mut BoucWenPrior, i: usize, scalar: Prior) -> bool {
        if i == 2 {
            prior.n = scalar;
        }
        i == 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hysteresis_law_basis_partials_and_packs() {
        use core_filters::real::Pack;
        let law = BoucWenLaw;
        let pts = [
            (0.7, 0.3, 2.0, 1.0, 2.0),
            (-1.2, -0.45, 1.5, -0.7, 1.3),
            (0.4, -0.2, 0.5, 0.5, 1.0),
            (-0.3, 0.55, 3.0, -2.5, 4.2),
        ];
        for &(dv, r, b, g, n) in &pts {
            // The basis recombines to the rate, and the rate is the simulator's.
            let mut basis = [0.0; 3];
            law.basis(dv, r, &[n], &mut basis);
            let rate = law.rate(dv, r, &[b, g], &[n]);
            assert!((basis[0] + b * basis[1] + g * basis[2] - rate).abs() < 1e-14);
            assert_eq!(rate, bouc_wen_rate(dv, r, b, g, n));
            let element = BoucWenLaw::element(0, &[b, g, n]);
            assert_eq!(rate.to_bits(), law.element_rate(&element, dv, r).to_bits());
            // Partials by central differences (smooth away from δv = 0 and r = 0).
            let (d_dv, d_r) = law.rate_partials(dv, r, &[b, g], &[n]);
            let h = 1e-6;
            let fd_dv = (law.rate(dv + h, r, &[b, g], &[n]) - law.rate(dv - h, r, &[b, g], &[n]))
                / (2.0 * h);
            let fd_r = (law.rate(dv, r + h, &[b, g], &[n]) - law.rate(dv, r - h, &[b, g], &[n]))
                / (2.0 * h);
            assert!((d_dv - fd_dv).abs() < 1e-7, "{d_dv} vs {fd_dv}");
            assert!((d_r - fd_r).abs() < 1e-7, "{d_r} vs {fd_r}");
            // Both at once (one power of |r|): bit for bit what the two calls give.
            let mut both = [0.0; 3];
            let (a_dv, a_r) = law.basis_and_partials(dv, r, &[b, g], &[n], &mut both);
            assert_eq!(both.map(f64::to_bits), basis.map(f64::to_bits));
            assert_eq!(
                (a_dv.to_bits(), a_r.to_bits()),
                (d_dv.to_bits(), d_r.to_bits())
            );
        }
        // A pack of the four points is the scalar evaluation of each lane, bit for bit.
        let lane = |f: fn(&(f64, f64, f64, f64, f64)) -> f64| Pack::from_lanes(|i| f(&pts[i]));
        let (dv, r, b, g, n) = (
            lane(|p| p.0),
            lane(|p| p.1),
            lane(|p| p.2),
            lane(|p| p.3),
            lane(|p| p.4),
        );
        let mut basis = [Pack::splat(0.0); 3];
        law.basis(dv, r, &[n], &mut basis);
        let rate = law.rate(dv, r, &[b, g], &[n]);
        let (d_dv, d_r) = law.rate_partials(dv, r, &[b, g], &[n]);
        let mut both = [Pack::splat(0.0); 3];
        let (b_dv, b_r) = law.basis_and_partials(dv, r, &[b, g], &[n], &mut both);
        for (i, &(dv, r, b, g, n)) in pts.iter().enumerate() {
            let pairs = [
                (both[1], basis[1]),
                (both[2], basis[2]),
                (b_dv, d_dv),
                (b_r, d_r),
            ];
            for (x, y) in pairs {
                assert_eq!(x.lane(i).to_bits(), y.lane(i).to_bits());
            }
            let mut s = [0.0; 3];
            law.basis(dv, r, &[n], &mut s);
            let (sd, sr) = law.rate_partials(dv, r, &[b, g], &[n]);
            let scalar = [s[0], s[1], s[2], law.rate(dv, r, &[b, g], &[n]), sd, sr];
            let packed = [basis[0], basis[1], basis[2], rate, d_dv, d_r];
            for (p, v) in packed.iter().zip(scalar) {
                assert_eq!(p.lane(i).to_bits(), v.to_bits());
            }
        }
    }

    #[test]
    fn bouc_wen_at_zero_is_finite_for_n_equal_one() {
        assert_eq!(bouc_wen_rate(0.7, 0.0, 2.0, 1.0, 1.0), 0.7);
        assert_eq!(bouc_wen_rate(0.7, 0.0, 2.0, 1.0, 2.0), 0.7);
    }

    #[test]
    fn the_record_round_trips_and_is_validated() {
        let bw = BoucWen {
            storey: 3,
            beta: 2.0,
            gamma: -1.0,
            n: 1.5,
        };
        let mut p = [0.0; 3];
        BoucWenLaw::params(&bw, &mut p);
        assert_eq!(BoucWenLaw::element(3, &p), bw);
        assert_eq!(BoucWenLaw::validate(&bw), Ok(()));
        let low = BoucWen { n: 0.5, ..bw };
        let e = BoucWenLaw::validate(&low).unwrap_err();
        assert_eq!(
            e.to_string(),
            "Bouc–Wen element at storey 3: exponent n = 0.5 must be ≥ 1"
        );
        let nan = BoucWen {
            gamma: f64::NAN,
            ..bw
        };
        assert!(matches!(
            BoucWenLaw::validate(&nan),
            Err(LawError::NonFinite { what: "gamma", .. })
        ));
        // The record's JSON form is the data sets' and configurations' (field names kept).
        let json = serde_json::to_string(&bw).unwrap();
        assert_eq!(json, r#"{"storey":3,"beta":2.0,"gamma":-1.0,"n":1.5}"#);
        let prior = serde_json::to_string(&BoucWenLaw::default_prior(0)).unwrap();
        assert_eq!(
            prior,
            r#"{"storey":0,"beta_gamma":{"kind":"triangle","beta_max":5.0},"n":{"kind":"uniform","lo":1.0,"hi":5.0}}"#
        );
    }
}
