//! Priors of θ for a chain with any number of hysteretic elements (SPEC §3 per parameter).
//!
//! θ = [k1..kN, c1..cN, (α with mass-proportional damping), then per hysteretic element in
//! storey order the law's parameters (Bouc–Wen: β, γ, n)]. Defaults:
//! k_j ~ LogNormal(median 10, log-sd 0.3), c_j ~ LogNormal(0.4, 0.5), per element the law's
//! default prior ([`HysteresisLaw::default_prior`]; Bouc–Wen: (β, γ) uniform on the triangle
//! {0 ≤ β ≤ 5, |γ| ≤ β} and n ~ U(1, 5)). Every parameter can be overridden, or fixed (a point
//! mass) by name. The Monte-Carlo tests of its moments and draws are in [`crate::priors`],
//! beside the scalar priors.

use crate::law::{BoucWenLaw, HysteresisLaw};
use crate::priors::{Prior, PriorError};
use crate::structure::{theta_names_damped, Damping};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Prior of one hysteretic (Bouc–Wen) element's parameters.
pub use crate::law::BoucWenPrior as ElementPrior;

/// Prior of the whole θ of a chain whose elements follow the law `L`, independent across
/// parameters (and across elements; within an element as the law states: Bouc–Wen's β, γ
/// jointly).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, bound = "")]
pub struct ChainPriorOf<L: HysteresisLaw> {
    pub k: Vec<Prior>,
    pub c: Vec<Prior>,
    /// Prior of the mass-proportional damping α: present exactly when the chain has the
    /// [`Damping::StoreyMass`] form (absent, nothing is written: the default form's prior is
    /// unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<Prior>,
    /// One per hysteretic element, in storey order.
    pub elements: Vec<L::Prior>,
}

/// The prior of a chain with Bouc–Wen elements (SPEC §3).
pub type ChainPrior = ChainPriorOf<BoucWenLaw>;

/// The damping ratio of the fundamental mode that the default prior of the mass-proportional
/// damping α is centred on: α = 2·ζ_α·ω₁ gives the first mode ζ_α from αM alone
/// (`ζ = α/(2ω)` for pure mass damping). Half of the 2 % assumed at ω₁ elsewhere
/// (`experiments::scaled_prior`), the other half being left to the per-storey dashpots.
pub const ALPHA_DAMPING_RATIO: f64 = 0.01;
/// Log-s.d. of the default α prior: wider than c's (0.7), since how the damping is shared
/// between αM and the dashpots is not known beforehand.
pub const ALPHA_LOG_SD: f64 = 1.0;

/// The default prior of α for a structure whose fundamental circular frequency is `omega1`
/// (rad/s): LogNormal(median 2·[`ALPHA_DAMPING_RATIO`]·ω₁, log-s.d. [`ALPHA_LOG_SD`]).
pub fn alpha_prior(omega1: f64) -> Prior {
    Prior::LogNormal {
        median: 2.0 * ALPHA_DAMPING_RATIO * omega1,
        log_sd: ALPHA_LOG_SD,
    }
}

/// Prior median over the true value in SPEC §3: 10 / 8 for k, 0.4 / 0.25 for c.
pub(crate) const K_PRIOR_RATIO: f64 = 1.25;
pub(crate) const C_PRIOR_RATIO: f64 = 1.6;

impl<L: HysteresisLaw> ChainPriorOf<L> {
    /// SPEC §3 defaults for N storeys and hysteretic elements at the 0-based `hysteretic` storeys
    /// (each with its law's default prior).
    pub fn paper(n_storeys: usize, hysteretic: &[usize]) -> Self {
        Self {
            k: vec![
                Prior::LogNormal {
                    median: 10.0,
                    log_sd: 0.3
                };
                n_storeys
            ],
            c: vec![
                Prior::LogNormal {
                    median: 0.4,
                    log_sd: 0.5
                };
                n_storeys
            ],
            alpha: None,
            elements: hysteretic.iter().map(|&s| L::default_prior(s)).collect(),
        }
    }

    /// SPEC §3's priors carried to a structure with other storey values: each k_j and c_j prior
    /// keeps its log-s.d. and sits where SPEC §3's sits relative to the paper's truth (median
    /// 10 for k = 8, i.e. 1.25 k_j; 0.4 for c = 0.25, i.e. 1.6 c_j); the law's parameters as
    /// SPEC §3 (they do not depend on the storey values). `k`, `c`: the structure's per-storey
    /// values.
    pub(crate) fn relative_to(k: &[f64], c: &[f64], hysteretic: &[usize]) -> Self {
        let mut p = Self::paper(k.len(), hysteretic);
        for (prior, &kj) in p.k.iter_mut().zip(k) {
            *prior = Prior::LogNormal {
                median: K_PRIOR_RATIO * kj,
                log_sd: 0.3,
            };
        }
        for (prior, &cj) in p.c.iter_mut().zip(c) {
            *prior = Prior::LogNormal {
                median: C_PRIOR_RATIO * cj,
                log_sd: 0.5,
            };
        }
        p
    }

    pub fn n_storeys(&self) -> usize {
        self.k.len()
    }

    /// The damping form θ describes: [`Damping::StoreyMass`] exactly when α has a prior.
    pub fn damping(&self) -> Damping {
        if self.alpha.is_some() {
            Damping::StoreyMass
        } else {
            Damping::Storey
        }
    }

    /// Index of the first element parameter (β_0) in θ: `2N`, or `2N + 1` with α.
    #[inline]
    pub(crate) fn element_offset(&self) -> usize {
        2 * self.n_storeys() + self.damping().extra_parameters()
    }

    /// 0-based storeys of the elements, in order.
    pub(crate) fn hysteretic_storeys(&self) -> Vec<usize> {
        self.elements.iter().map(L::prior_storey).collect()
    }

    /// Number of parameters 2N (+ 1 with α) + (the law's parameter count)·E (3E for Bouc–Wen).
    pub fn len(&self) -> usize {
        self.element_offset() + L::NPARAMS * self.elements.len()
    }

    /// Whether θ is empty (never: N ≥ 1 is checked by [`ChainPrior::validate`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Names of θ in order (as [`crate::structure::theta_names`], with `alpha` after the
    /// dampings when α has a prior).
    pub fn names(&self) -> Vec<String> {
        theta_names_damped::<L>(self.n_storeys(), &self.hysteretic_storeys(), self.damping())
    }

    /// Checks every hyper-parameter; k, c and α must have non-negative support, each element's
    /// prior as its law requires (Bouc–Wen: n with non-negative support).
    pub fn validate(&self) -> Result<(), PriorError> {
        let n = self.n_storeys();
        if self.c.len() != n {
            return Err(PriorError::WrongLength {
                which: "c",
                expected: n,
                got: self.c.len(),
            });
        }
        let names = self.names();
        for (j, p) in self.k.iter().enumerate() {
            p.validate(&names[j], true)?;
        }
        for (j, p) in self.c.iter().enumerate() {
            p.validate(&names[n + j], true)?;
        }
        if let Some(p) = &self.alpha {
            p.validate(&names[2 * n], true)?;
        }
        let e0 = self.element_offset();
        let np = L::NPARAMS;
        for (e, el) in self.elements.iter().enumerate() {
            L::validate_prior(el, &names[e0 + np * e..e0 + np * (e + 1)])?;
        }
        Ok(())
    }

    /// Makes parameter `name` (as in [`ChainPriorOf::names`]) a point mass at `value`. For an
    /// element's parameter the law decides ([`HysteresisLaw::fix_prior`]): fixing Bouc–Wen's β
    /// or γ alone keeps the other's conditional prior on the triangle (`BetaGammaPrior`). On
    /// error the prior is unchanged.
    pub fn fix(&mut self, name: &str, value: f64) -> Result<(), PriorError> {
        let i = self.names().iter().position(|s| s == name).ok_or_else(|| {
            PriorError::UnknownParameter {
                name: name.to_string(),
            }
        })?;
        self.set(i, |slot| match slot {
            Slot::Scalar(p) => *p = Prior::Fixed { value },
            Slot::Element(el, i) => L::fix_prior(el, i, value),
        })
    }

    /// Replaces the prior of scalar parameter `name` (k, c, α, or an element parameter whose
    /// law gives it a scalar prior: Bouc–Wen's n; for β, γ set [`ElementPrior::beta_gamma`]). On
    /// error the prior is unchanged.
    pub fn set_prior(&mut self, name: &str, prior: Prior) -> Result<(), PriorError> {
        let unknown = || PriorError::UnknownParameter {
            name: name.to_string(),
        };
        let i = self
            .names()
            .iter()
            .position(|s| s == name)
            .ok_or_else(unknown)?;
        let mut ok = true;
        let r = self.set(i, |slot| match slot {
            Slot::Scalar(p) => *p = prior,
            Slot::Element(el, i) => ok = L::set_prior(el, i, prior),
        });
        if ok {
            r
        } else {
            Err(unknown())
        }
    }

    fn set(&mut self, i: usize, f: impl FnOnce(Slot<'_, L>)) -> Result<(), PriorError> {
        let n = self.n_storeys();
        let e0 = self.element_offset();
        let mut next = self.clone();
        let slot = if i < n {
            Slot::Scalar(&mut next.k[i])
        } else if i < 2 * n {
            Slot::Scalar(&mut next.c[i - n])
        } else if i < e0 {
            Slot::Scalar(
                next.alpha
                    .as_mut()
                    .expect("θ has α exactly when its prior does"),
            )
        } else {
            let np = L::NPARAMS;
            Slot::Element(&mut next.elements[(i - e0) / np], (i - e0) % np)
        };
        f(slot);
        next.validate()?;
        *self = next;
        Ok(())
    }

    /// Writes one draw of θ into `out` (length [`ChainPrior::len`]) without allocating.
    pub(crate) fn sample_into<G: Rng + ?Sized>(&self, rng: &mut G, out: &mut [f64]) {
        let n = self.n_storeys();
        assert_eq!(out.len(), self.len(), "θ buffer has the wrong length");
        for (o, p) in out[..n].iter_mut().zip(&self.k) {
            *o = p.sample(rng);
        }
        for (o, p) in out[n..2 * n].iter_mut().zip(&self.c) {
            *o = p.sample(rng);
        }
        if let Some(p) = &self.alpha {
            out[2 * n] = p.sample(rng);
        }
        let e0 = self.element_offset();
        let np = L::NPARAMS;
        for (e, el) in self.elements.iter().enumerate() {
            L::sample_prior(el, rng, &mut out[e0 + np * e..e0 + np * (e + 1)]);
        }
    }

    /// Means and variances of θ (SPEC §3 moment matching; all components uncorrelated).
    pub fn moments(&self) -> (Vec<f64>, Vec<f64>) {
        let mut mean = Vec::with_capacity(self.len());
        let mut var = Vec::with_capacity(self.len());
        for p in self.k.iter().chain(&self.c).chain(&self.alpha) {
            let (m, v) = p.moments();
            mean.push(m);
            var.push(v);
        }
        for el in &self.elements {
            let at = mean.len();
            mean.resize(at + L::NPARAMS, 0.0);
            var.resize(at + L::NPARAMS, 0.0);
            L::prior_moments(el, &mut mean[at..], &mut var[at..]);
        }
        (mean, var)
    }
}

enum Slot<'a, L: HysteresisLaw> {
    Scalar(&'a mut Prior),
    /// Parameter `i` (0-based within the element) of an element's prior.
    Element(&'a mut L::Prior, usize),
}

#[cfg(test)]
mod priors_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::rng::stream;

    #[test]
    fn single_element_prior_is_named_like_the_paper() {
        let p = ChainPrior::paper(3, &[0]);
        assert_eq!(
            p.names(),
            ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"]
        );
    }

    #[test]
    fn relative_prior_sits_where_the_papers_sits() {
        // At the paper's values it is the paper's prior, to the bit.
        assert_eq!(
            ChainPrior::relative_to(&[8.0; 3], &[0.25; 3], &[0]),
            ChainPrior::paper(3, &[0])
        );
        // Elsewhere: medians 1.25 k and 1.6 c, same log-s.d.s, same β, γ, n.
        let p = ChainPrior::relative_to(&[2000.0, 1000.0], &[4.0, 2.0], &[1]);
        let paper = ChainPrior::paper(2, &[1]);
        assert_eq!(
            p.k[1],
            Prior::LogNormal {
                median: 1250.0,
                log_sd: 0.3
            }
        );
        assert_eq!(
            p.c[0],
            Prior::LogNormal {
                median: 6.4,
                log_sd: 0.5
            }
        );
        assert_eq!(p.elements, paper.elements);
        // Prior mean over the truth is the paper's ratio for every storey.
        let (mean, _) = p.moments();
        let (pm, _) = paper.moments();
        assert!((mean[0] / 2000.0 - pm[0] / 8.0).abs() < 1e-12);
        assert!((mean[3] / 2.0 - pm[3] / 0.25).abs() < 1e-12);
    }

    #[test]
    fn mass_damping_puts_alpha_after_the_dampings() {
        let alpha = Prior::LogNormal {
            median: 0.5,
            log_sd: 0.7,
        };
        let mut p = ChainPrior::paper(3, &[0]);
        p.alpha = Some(alpha);
        assert_eq!(p.damping(), Damping::StoreyMass);
        assert_eq!(p.len(), 10);
        assert_eq!(
            p.names(),
            ["k1", "k2", "k3", "c1", "c2", "c3", "alpha", "beta", "gamma", "n"]
        );
        let (mean, var) = p.moments();
        assert_eq!((mean[6], var[6]), alpha.moments());
        assert_eq!(mean[7..], ChainPrior::paper(3, &[0]).moments().0[6..]);
        let mut rng = stream(3, 0, "t");
        let mut th = vec![0.0; 10];
        p.sample_into(&mut rng, &mut th);
        assert!(th[6] > 0.0 && (1.0..5.0).contains(&th[9]) && th[8].abs() <= th[7]);
        p.fix("alpha", 0.3).unwrap();
        assert_eq!(p.alpha, Some(Prior::Fixed { value: 0.3 }));
        assert!(p.fix("alpha", -0.3).is_err(), "α must be non-negative");
        p.fix("n", 2.0).unwrap();
        assert_eq!(p.elements[0].n, Prior::Fixed { value: 2.0 });
        // Without the mass term there is no α to fix.
        assert!(matches!(
            ChainPrior::paper(3, &[0]).fix("alpha", 0.3),
            Err(PriorError::UnknownParameter { .. })
        ));
    }

    #[test]
    fn several_elements_are_named_by_storey_and_fixable() {
        let mut p = ChainPrior::paper(7, &[0, 3]);
        assert_eq!(p.len(), 20);
        let names = p.names();
        assert_eq!(
            &names[14..],
            ["beta1", "gamma1", "n1", "beta4", "gamma4", "n4"]
        );
        p.fix("gamma4", 0.5).unwrap();
        p.fix("n1", 2.0).unwrap();
        p.fix("k7", 8.0).unwrap();
        let (mean, var) = p.moments();
        assert_eq!((mean[6], var[6]), (8.0, 0.0));
        assert_eq!((mean[18], var[18]), (0.5, 0.0));
        assert_eq!((mean[16], var[16]), (2.0, 0.0));
        assert!(var[17] > 0.0, "β4 keeps its conditional prior");
        let before = p.clone();
        assert!(matches!(
            p.fix("beta", 1.0),
            Err(PriorError::UnknownParameter { .. })
        ));
        assert!(p.fix("k1", -1.0).is_err());
        assert!(p.set_prior("beta1", Prior::Fixed { value: 1.0 }).is_err());
        assert_eq!(p, before);
        p.set_prior("c2", Prior::Uniform { lo: 0.1, hi: 0.5 })
            .unwrap();
        assert_eq!(p.c[1], Prior::Uniform { lo: 0.1, hi: 0.5 });
        let mut rng = stream(2, 0, "t");
        let mut th = vec![0.0; 20];
        for _ in 0..200 {
            p.sample_into(&mut rng, &mut th);
            assert!(th[14] >= 0.0 && th[15].abs() <= th[14]);
            assert!(th[17] >= 0.5 && (1.0..5.0).contains(&th[19]));
            assert_eq!(th[18], 0.5);
        }
    }
}

/// Gaussian prior of the marginalised block (SPEC §3).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MarginalPrior {
    /// One Gaussian moment-matched to the priors, identical for all particles.
    #[default]
    MomentMatched,
    /// Per-particle means drawn from the true priors, covariance diag((rel_sd·mean)²) where
    /// `mean` is the particle's drawn mean. Parameters with a point-mass prior keep variance 0.
    /// Note that a draw of γ close to 0 gets a correspondingly small variance.
    PerParticle { rel_sd: f64 },
}
