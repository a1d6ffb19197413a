//! The N-storey shear chain with hysteretic elements (SPEC §1: Bouc–Wen).
//!
//! Storeys are numbered `0..N` in code (1-based `1..=N` in names and files). Element `j` links
//! storey `j−1` to storey `j`, storey `−1` being the ground, so element 0 is the ground element.
//! Coordinates are relative to the ground. With `d_j = x_j − x_{j−1}` and `δv_j = v_j − v_{j−1}`
//! (`x_{−1} = v_{−1} = 0`), the force carried by element `j` is
//!
//! - linear element:    `f_j = k_j d_j + c_j δv_j`,
//! - hysteretic element: `f_j = k_j r_j + c_j δv_j`, `ṙ_j` given by the element's
//!   [`HysteresisLaw`] (`crate::law`); for Bouc–Wen
//!   `ṙ_j = δv_j − β|δv_j||r_j|^(n−1) r_j − γ δv_j |r_j|^n` (SPEC eq. 22; the dashpot stays linear),
//!
//! and storey `j` obeys `m_j ẍ_j = −m_j ü_g − f_j + f_{j+1}` (`f_N = 0`). For the paper's
//! three-storey chain with unit masses this is exactly SPEC §1.
//!
//! **Damping form** ([`Damping`]). `storey` (the default, SPEC §1): the per-storey dashpots
//! above only. `storey+mass`: besides them a mass-proportional term, storey `j` gaining the
//! force `−α m_j v_j` (`v_j` relative to the ground), so `C = αM + C_storey`; it contains
//! Rayleigh damping (`c_j = β_R k_j`). α ≥ 0 is one more parameter, placed in θ right after
//! `c_1..c_N` and named `alpha`.
//!
//! One physics source: the forces and accelerations are evaluated by one kernel, that of the
//! [`Building`] (over any `ChainView` of a point), and the hysteretic rate by one
//! implementation of a [`HysteresisLaw`] ([`BoucWenLaw`] for the toolkit's chains); the truth
//! simulator ([`ShearChainOf::rhs`]) and every filter partition (`crate::filtering`) use both,
//! generic over one particle (`f64`) or a SIMD pack of particles, and over the law.
//!
//! State layout: `[x_1..x_N, v_1..v_N, r_e for each hysteretic element in order]`.
//! Parameter vector θ: `[k_1..k_N, c_1..c_N, (α with mass damping), then the law's parameters
//! per hysteretic element]` (Bouc–Wen: β, γ, n), which for the paper is
//! `[k1 k2 k3 c1 c2 c3 β γ n]`.

use crate::building::{Building, BuildingError};
pub use crate::law::bouc_wen::{bouc_wen_rate, BoucWen, BoucWenLaw};
pub use crate::law::{HysteresisLaw, LawError};
use core_filters::real::Real;
use thiserror::Error;

/// The damping form is part of the building; re-exported beside the θ layout it shapes.
pub use crate::building::{Damping, UnknownDamping};

/// Name of the mass-proportional damping coefficient α in θ.
pub const ALPHA_NAME: &str = "alpha";

/// Impossible structure definitions.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum StructureError {
    #[error(transparent)]
    Building(#[from] BuildingError),
    #[error("{what} has {found} entries, expected {expected}")]
    WrongLength {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    /// `storey` is 1-based (`k1` is storey 1's stiffness).
    #[error("{what} of storey {storey} must be non-negative and finite, got {value}")]
    NegativeCoefficient {
        what: &'static str,
        storey: usize,
        value: f64,
    },
    /// An element's parameters outside its law's domain (Bouc–Wen: finite, `n ≥ 1`).
    #[error(transparent)]
    Law(#[from] LawError),
    #[error("mass-proportional damping alpha must be non-negative and finite, got {0}")]
    NegativeAlpha(f64),
}

/// An N-storey shear chain (SPEC §1): a [`Building`] with its parameters, validated at
/// construction; its hysteretic elements follow the law `L`.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearChainOf<L: HysteresisLaw> {
    /// Masses, hysteretic storeys and damping form; also the force kernel shared with the
    /// filter partitions.
    building: Building,
    k: Vec<f64>,
    c: Vec<f64>,
    /// Mass-proportional damping coefficient α ([`Damping::StoreyMass`]); `None` for
    /// [`Damping::Storey`].
    alpha: Option<f64>,
    /// The hysteretic elements' parameters, in the order of [`Building::hysteretic`].
    elements: Vec<L::Element>,
    law: L,
}

/// The chain with Bouc–Wen elements (SPEC §1), the toolkit's chain.
pub type ShearChain = ShearChainOf<BoucWenLaw>;

/// A point of the chain (states and parameters) seen through one representation's storage.
/// Storeys `j` and elements are 0-based; `r(e)` is the hysteretic variable of element `e` (in
/// the order of [`Building::hysteretic`]).
pub(crate) trait ChainView<T: Real> {
    fn x(&self, j: usize) -> T;
    fn v(&self, j: usize) -> T;
    fn r(&self, e: usize) -> T;
    fn k(&self, j: usize) -> T;
    fn c(&self, j: usize) -> T;
    /// Mass-proportional damping α; read only when the building has the mass term
    /// ([`Damping::StoreyMass`]).
    fn alpha(&self) -> T {
        T::splat(0.0)
    }
}

/// The force kernel: the building (masses, hysteretic elements, damping form) is everything it
/// needs besides the point. The one implementation of the chain's forces and accelerations
/// (SPEC §1): the truth simulator ([`ShearChain::rhs`]) and every filter partition
/// (`crate::filtering`) evaluate them here.
impl Building {
    /// Drift velocity `δv_j = v_j − v_{j−1}` (`v_{−1} = 0`).
    #[inline]
    pub(crate) fn drift_velocity<T: Real>(p: &impl ChainView<T>, j: usize) -> T {
        if j == 0 {
            p.v(0)
        } else {
            p.v(j) - p.v(j - 1)
        }
    }

    /// `(d_j, δv_j)` with `F_j = k_j d_j + c_j δv_j`: `d_j = r_e` for a hysteretic element, the
    /// drift `x_j − x_{j−1}` otherwise.
    #[inline]
    pub(crate) fn element_coordinates<T: Real>(&self, p: &impl ChainView<T>, j: usize) -> (T, T) {
        let d = match self.element_at(j) {
            Some(e) => p.r(e),
            None if j == 0 => p.x(0),
            None => p.x(j) - p.x(j - 1),
        };
        (d, Self::drift_velocity(p, j))
    }

    /// Force `F_j = k_j d_j + c_j δv_j` carried by element `j`.
    #[inline]
    pub(crate) fn force<T: Real>(&self, p: &impl ChainView<T>, j: usize) -> T {
        let (d, dv) = self.element_coordinates(p, j);
        p.k(j) * d + p.c(j) * dv
    }

    /// `a_j = ground + (F_{j+1} − F_j) / m_j` (`F_N = 0`), minus `α v_j` with mass damping:
    /// the relative acceleration for `ground = −ü_g`.
    #[inline]
    pub(crate) fn acceleration<T: Real>(&self, p: &impl ChainView<T>, j: usize, ground: T) -> T {
        let f = self.force(p, j);
        let f_next = if j + 1 < self.storeys() {
            self.force(p, j + 1)
        } else {
            T::splat(0.0)
        };
        let a = ground + (f_next - f) / T::splat(self.masses()[j]);
        self.mass_damped(p, j, a)
    }

    /// `a − α v_j` with the mass term, `a` itself otherwise (bit for bit: the default form
    /// evaluates exactly what it did before the term existed).
    #[inline(always)]
    fn mass_damped<T: Real>(&self, p: &impl ChainView<T>, j: usize, a: T) -> T {
        if self.damping().has_mass_term() {
            Self::minus_mass_term(p, j, a)
        } else {
            a
        }
    }

    /// `a − α v_j`: storey j's mass-proportional damping force −α m_j v_j over m_j.
    #[inline(always)]
    fn minus_mass_term<T: Real>(p: &impl ChainView<T>, j: usize, a: T) -> T {
        a - p.alpha() * p.v(j)
    }

    /// Every storey's acceleration, each element force evaluated once; `out` has length N.
    #[inline]
    pub(crate) fn accelerations<T: Real>(&self, p: &impl ChainView<T>, ground: T, out: &mut [T]) {
        // The damping form is decided once, not per storey: the loop without the mass term is
        // the bootstrap PF's hot path and stays free of a branch it never takes.
        if self.damping().has_mass_term() {
            self.accelerations_of::<T, true>(p, ground, out)
        } else {
            self.accelerations_of::<T, false>(p, ground, out)
        }
    }

    /// [`Self::accelerations`] with the mass term `− α v_j` present or not (`MASS`).
    #[inline(always)]
    fn accelerations_of<T: Real, const MASS: bool>(
        &self,
        p: &impl ChainView<T>,
        ground: T,
        out: &mut [T],
    ) {
        let n = self.storeys();
        let mut f = self.force(p, 0);
        for (j, (o, &m)) in out.iter_mut().zip(self.masses()).enumerate() {
            let f_next = if j + 1 < n {
                self.force(p, j + 1)
            } else {
                T::splat(0.0)
            };
            let a = ground + (f_next - f) / T::splat(m);
            *o = if MASS {
                Self::minus_mass_term(p, j, a)
            } else {
                a
            };
            f = f_next;
        }
    }
}

/// Names of θ for N storeys and hysteretic elements at `hysteretic` (0-based, element order):
/// `k1..kN`, `c1..cN`, then per element the law's linear then nonlinear parameter names, bare
/// for a single element (`beta`, `gamma`, `n`: the paper's notation) or suffixed by the 1-based
/// storey for several (`beta4`).
pub fn theta_names<L: HysteresisLaw>(n_storeys: usize, hysteretic: &[usize]) -> Vec<String> {
    theta_names_damped::<L>(n_storeys, hysteretic, Damping::Storey)
}

/// [`theta_names`] for damping form `damping`: with [`Damping::StoreyMass`], `alpha` follows
/// `c1..cN`.
pub(crate) fn theta_names_damped<L: HysteresisLaw>(
    n_storeys: usize,
    hysteretic: &[usize],
    damping: Damping,
) -> Vec<String> {
    let mut names: Vec<String> = (1..=n_storeys).map(|j| format!("k{j}")).collect();
    names.extend((1..=n_storeys).map(|j| format!("c{j}")));
    if damping.has_mass_term() {
        names.push(ALPHA_NAME.to_string());
    }
    let single = hysteretic.len() == 1;
    for &j in hysteretic {
        let s = if single {
            String::new()
        } else {
            (j + 1).to_string()
        };
        for p in L::LINEAR.iter().chain(L::NONLINEAR) {
            names.push(format!("{p}{s}"));
        }
    }
    names
}

/// Names of the states: `x1..xN`, `v1..vN`, `r<s>` per hysteretic element (1-based storey).
pub fn state_names(n_storeys: usize, hysteretic: &[usize]) -> Vec<String> {
    let mut names: Vec<String> = (1..=n_storeys).map(|j| format!("x{j}")).collect();
    names.extend((1..=n_storeys).map(|j| format!("v{j}")));
    names.extend(hysteretic.iter().map(|j| format!("r{}", j + 1)));
    names
}

/// A state vector `[x, v, r]` of an `n`-storey chain with its parameters: the point of a
/// [`ShearChain`], and of the bootstrap PF's augmented state (`crate::filtering::augmented`).
pub(crate) struct StateView<'a> {
    pub s: &'a [f64],
    pub n: usize,
    pub k: &'a [f64],
    pub c: &'a [f64],
    /// α (read only with the mass-proportional damping term).
    pub alpha: f64,
}

impl ChainView<f64> for StateView<'_> {
    #[inline]
    fn x(&self, j: usize) -> f64 {
        self.s[j]
    }
    #[inline]
    fn v(&self, j: usize) -> f64 {
        self.s[self.n + j]
    }
    #[inline]
    fn r(&self, e: usize) -> f64 {
        self.s[2 * self.n + e]
    }
    #[inline]
    fn k(&self, j: usize) -> f64 {
        self.k[j]
    }
    #[inline]
    fn c(&self, j: usize) -> f64 {
        self.c[j]
    }
    #[inline]
    fn alpha(&self) -> f64 {
        self.alpha
    }
}

impl ShearChain {
    /// A validated chain with Bouc–Wen elements. `masses`, `k`, `c` have one entry per storey;
    /// `bouc_wen` lists the hysteretic elements in the order their `r` appears in the state
    /// (increasing storeys).
    pub fn new(
        masses: Vec<f64>,
        k: Vec<f64>,
        c: Vec<f64>,
        bouc_wen: Vec<BoucWen>,
    ) -> Result<Self, StructureError> {
        Self::with_elements(masses, k, c, bouc_wen)
    }

    /// The Bouc–Wen elements' parameters ([`ShearChainOf::elements`]).
    pub fn bouc_wen(&self) -> &[BoucWen] {
        &self.elements
    }
}

impl<L: HysteresisLaw> ShearChainOf<L> {
    /// A validated chain whose hysteretic elements follow the law `L`. `masses`, `k`, `c` have
    /// one entry per storey; `elements` lists the hysteretic elements in the order their `r`
    /// appears in the state (increasing storeys).
    pub fn with_elements(
        masses: Vec<f64>,
        k: Vec<f64>,
        c: Vec<f64>,
        elements: Vec<L::Element>,
    ) -> Result<Self, StructureError> {
        let storeys = elements.iter().map(L::storey).collect();
        let building = Building::new(masses, storeys, Damping::Storey)?;
        Self::on(building, k, c, elements)
    }

    /// The chain of `building` (per-storey damping) with the element parameters `elements`,
    /// whose storeys are the building's hysteretic storeys.
    fn on(
        building: Building,
        k: Vec<f64>,
        c: Vec<f64>,
        elements: Vec<L::Element>,
    ) -> Result<Self, StructureError> {
        let n = building.storeys();
        for (what, v) in [("k", &k), ("c", &c)] {
            if v.len() != n {
                return Err(StructureError::WrongLength {
                    what,
                    expected: n,
                    found: v.len(),
                });
            }
        }
        for (what, v) in [("stiffness k", &k), ("damping c", &c)] {
            for (j, &x) in v.iter().enumerate() {
                if !(x >= 0.0 && x.is_finite()) {
                    // Storeys are numbered from 1, as θ names them (`k1` is storey 1's).
                    return Err(StructureError::NegativeCoefficient {
                        what,
                        storey: j + 1,
                        value: x,
                    });
                }
            }
        }
        for el in &elements {
            L::validate(el)?;
        }
        Ok(Self {
            building,
            k,
            c,
            alpha: None,
            elements,
            law: L::default(),
        })
    }

    /// The chain of `building` with parameters θ in the order of [`ShearChainOf::theta`] (for
    /// its damping form and hysteretic storeys), validated.
    pub fn from_theta(building: &Building, theta: &[f64]) -> Result<Self, StructureError> {
        let n = building.storeys();
        let a = building.damping().extra_parameters();
        let expected = 2 * n + a + L::NPARAMS * building.hysteretic().len();
        if theta.len() != expected {
            return Err(StructureError::WrongLength {
                what: "theta",
                expected,
                found: theta.len(),
            });
        }
        let elements = building
            .hysteretic()
            .iter()
            .zip(theta[2 * n + a..].chunks_exact(L::NPARAMS))
            .map(|(&storey, p)| L::element(storey, p))
            .collect();
        let chain = Self::on(
            building.clone().with_damping(Damping::Storey),
            theta[..n].to_vec(),
            theta[n..2 * n].to_vec(),
            elements,
        )?;
        match building.damping() {
            Damping::Storey => Ok(chain),
            Damping::StoreyMass => chain.with_mass_damping(theta[2 * n]),
        }
    }

    /// The same chain with mass-proportional damping `α M` besides its per-storey dashpots
    /// ([`Damping::StoreyMass`]); `alpha` must be non-negative and finite.
    pub(crate) fn with_mass_damping(mut self, alpha: f64) -> Result<Self, StructureError> {
        if !(alpha >= 0.0 && alpha.is_finite()) {
            return Err(StructureError::NegativeAlpha(alpha));
        }
        self.alpha = Some(alpha);
        self.building = self.building.with_damping(Damping::StoreyMass);
        Ok(self)
    }

    /// The damping form.
    pub fn damping_form(&self) -> Damping {
        self.building.damping()
    }

    /// Mass-proportional damping α (`None` for the per-storey form).
    pub fn alpha(&self) -> Option<f64> {
        self.alpha
    }

    /// Number of storeys N.
    pub fn storeys(&self) -> usize {
        self.building.storeys()
    }

    /// State dimension `2N + (number of hysteretic elements)`.
    pub fn dim(&self) -> usize {
        2 * self.building.storeys() + self.elements.len()
    }

    pub fn masses(&self) -> &[f64] {
        self.building.masses()
    }

    pub fn stiffness(&self) -> &[f64] {
        &self.k
    }

    pub fn damping(&self) -> &[f64] {
        &self.c
    }

    /// The hysteretic elements' parameters, in state order.
    pub fn elements(&self) -> &[L::Element] {
        &self.elements
    }

    /// Index of `r_e` (hysteretic element `e`) in the state vector.
    pub fn r_index(&self, element: usize) -> usize {
        assert!(
            element < self.elements.len(),
            "no hysteretic element {element}"
        );
        2 * self.building.storeys() + element
    }

    /// The masses, hysteretic storeys and damping form (the force kernel shared with the
    /// partitions).
    pub fn building(&self) -> &Building {
        &self.building
    }

    #[track_caller]
    fn check_state(&self, state: &[f64]) {
        assert_eq!(state.len(), self.dim(), "state has the wrong length");
    }

    /// Relative accelerations `ẍ_j = −ü_g + (−f_j + f_{j+1}) / m_j` (SPEC §1), written to `out`
    /// (length N). No allocation.
    #[track_caller]
    pub fn relative_accelerations(&self, state: &[f64], ug: f64, out: &mut [f64]) {
        self.check_state(state);
        let n = self.building.storeys();
        assert_eq!(out.len(), n, "output has the wrong length");
        let view = StateView {
            s: state,
            n,
            k: &self.k,
            c: &self.c,
            alpha: self.alpha.unwrap_or(0.0),
        };
        self.building.accelerations(&view, -ug, out);
    }

    /// Continuous right-hand side `dstate = g(state, ü_g)` (SPEC §1). No allocation.
    #[track_caller]
    pub fn rhs(&self, state: &[f64], ug: f64, dstate: &mut [f64]) {
        self.check_state(state);
        assert_eq!(dstate.len(), state.len(), "derivative has the wrong length");
        let n = self.building.storeys();
        dstate[..n].copy_from_slice(&state[n..2 * n]);
        self.relative_accelerations(state, ug, &mut dstate[n..2 * n]);
        for (e, el) in self.elements.iter().enumerate() {
            let j = L::storey(el);
            let vm = if j == 0 { 0.0 } else { state[n + j - 1] };
            let dv = state[n + j] - vm;
            dstate[2 * n + e] = self.law.element_rate(el, dv, state[2 * n + e]);
        }
    }

    /// Forward-Euler map of SPEC §3: `out = state + dt · g(state, ü_g(k−1))`. No allocation.
    #[track_caller]
    pub fn euler_step(&self, state: &[f64], ug_prev: f64, dt: f64, out: &mut [f64]) {
        self.rhs(state, ug_prev, out);
        for (o, s) in out.iter_mut().zip(state) {
            *o = s + dt * *o;
        }
    }

    /// Restoring force `k_j r_j` of hysteretic element `element` (the hysteresis loop plots it
    /// against the element's relative displacement).
    #[track_caller]
    pub fn restoring_force(&self, state: &[f64], element: usize) -> f64 {
        self.check_state(state);
        let j = L::storey(&self.elements[element]);
        self.k[j] * state[self.r_index(element)]
    }

    /// Relative displacement `x_j − x_{j−1}` across hysteretic element `element`.
    #[track_caller]
    pub fn element_drift(&self, state: &[f64], element: usize) -> f64 {
        self.check_state(state);
        let j = L::storey(&self.elements[element]);
        state[j] - if j == 0 { 0.0 } else { state[j - 1] }
    }

    /// The bound of `|r|` of element `element` under continued loading, when its law gives one
    /// (Bouc–Wen: `(1/(β+γ))^(1/n)` when `β + γ > 0`; otherwise `r` is unbounded and `None` is
    /// returned).
    pub fn saturation(&self, element: usize) -> Option<f64> {
        L::saturation(&self.elements[element])
    }

    /// Parameter vector θ: `[k_1..k_N, c_1..c_N, (α), then the law's parameters per element]`
    /// (Bouc–Wen: β, γ, n).
    pub fn theta(&self) -> Vec<f64> {
        let ne = self.elements.len();
        let mut t = Vec::with_capacity(2 * self.storeys() + 1 + L::NPARAMS * ne);
        t.extend_from_slice(&self.k);
        t.extend_from_slice(&self.c);
        t.extend(self.alpha);
        for el in &self.elements {
            let at = t.len();
            t.resize(at + L::NPARAMS, 0.0);
            L::params(el, &mut t[at..]);
        }
        t
    }

    /// Names of θ, in the order of [`ShearChainOf::theta`]: `k1..kN`, `c1..cN`, then the law's
    /// parameter names — `beta`, `gamma`, `n` for a single Bouc–Wen element (the paper's
    /// notation), `beta<s>`, `gamma<s>`, `n<s>` (1-based storey `s`) for several.
    pub fn theta_names(&self) -> Vec<String> {
        theta_names_damped::<L>(
            self.storeys(),
            self.building.hysteretic(),
            self.damping_form(),
        )
    }

    /// Names of the state entries: `x1..xN`, `v1..vN`, `r<s>` per hysteretic element (1-based
    /// storey `s`).
    pub fn state_names(&self) -> Vec<String> {
        state_names(self.storeys(), self.building.hysteretic())
    }

    /// The same building (masses, hysteretic storeys and damping form) with parameters θ in the
    /// order of [`ShearChainOf::theta`], validated (e.g. for the validation run with θ_val,
    /// SPEC §7).
    pub fn with_theta(&self, theta: &[f64]) -> Result<Self, StructureError> {
        Self::from_theta(&self.building, theta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> ShearChain {
        ShearChain::new(
            vec![1.0; 3],
            vec![8.0; 3],
            vec![0.25; 3],
            vec![BoucWen {
                storey: 0,
                beta: 2.0,
                gamma: 1.0,
                n: 2.0,
            }],
        )
        .unwrap()
    }

    /// Two storeys of mass `mass` (k = 3, 5; c = 0.1, 0.2), a Bouc–Wen element (β = γ = 0.5,
    /// n = 1.5) at the upper one.
    fn upper_storey_element(mass: f64) -> ShearChain {
        ShearChain::new(
            vec![mass; 2],
            vec![3.0, 5.0],
            vec![0.1, 0.2],
            vec![BoucWen {
                storey: 1,
                beta: 0.5,
                gamma: 0.5,
                n: 1.5,
            }],
        )
        .unwrap()
    }

    #[test]
    fn rhs_matches_spec_equations() {
        // SPEC §1 written out by hand for the paper's chain, at an arbitrary state.
        let ch = paper();
        let s = [0.1, -0.2, 0.35, 0.7, -0.4, 0.25, 0.3];
        let ug = 1.3;
        let (k, c, b, g, n): (f64, f64, f64, f64, f64) = (8.0, 0.25, 2.0, 1.0, 2.0);
        let (x1, x2, x3, v1, v2, v3, r1) = (s[0], s[1], s[2], s[3], s[4], s[5], s[6]);
        let a1 = -ug - k * r1 + k * (x2 - x1) - c * v1 + c * (v2 - v1);
        let a2 = -ug + k * (x1 - x2) + k * (x3 - x2) + c * (v1 - v2) + c * (v3 - v2);
        let a3 = -ug + k * (x2 - x3) + c * (v2 - v3);
        let rd = v1 - b * v1.abs() * f64::abs(r1).powf(n - 1.0) * r1 - g * v1 * r1.abs().powf(n);
        let mut d = [0.0; 7];
        ch.rhs(&s, ug, &mut d);
        let want = [v1, v2, v3, a1, a2, a3, rd];
        for i in 0..7 {
            assert!(
                (d[i] - want[i]).abs() < 1e-14,
                "entry {i}: {} vs {}",
                d[i],
                want[i]
            );
        }
        let mut e = [0.0; 7];
        ch.euler_step(&s, ug, 0.005, &mut e);
        for i in 0..7 {
            assert!((e[i] - (s[i] + 0.005 * want[i])).abs() < 1e-15);
        }
        assert!((ch.restoring_force(&s, 0) - 8.0 * r1).abs() < 1e-15);
    }

    #[test]
    fn mass_damping_adds_minus_alpha_v_to_each_storey() {
        // Storey j gains −α m_j v_j, so a_j gains −α v_j; the rest is the per-storey chain.
        let (m, k, c) = (
            vec![1.0, 1.5, 0.7],
            vec![8.0, 6.0, 5.0],
            vec![0.25, 0.1, 0.3],
        );
        let plain = ShearChain::new(m.clone(), k.clone(), c.clone(), vec![]).unwrap();
        let damped = plain.clone().with_mass_damping(0.6).unwrap();
        let s = [0.1, -0.2, 0.35, 0.7, -0.4, 0.25];
        let (mut d0, mut d1) = ([0.0; 6], [0.0; 6]);
        plain.rhs(&s, 1.3, &mut d0);
        damped.rhs(&s, 1.3, &mut d1);
        assert_eq!(d0[..3], d1[..3]);
        for j in 0..3 {
            let want = d0[3 + j] - 0.6 * s[3 + j];
            assert!((d1[3 + j] - want).abs() < 1e-14, "storey {j}");
        }
        assert_eq!(damped.damping_form(), Damping::StoreyMass);
        assert_eq!(damped.theta(), [8.0, 6.0, 5.0, 0.25, 0.1, 0.3, 0.6]);
        assert_eq!(
            damped.theta_names(),
            ["k1", "k2", "k3", "c1", "c2", "c3", "alpha"]
        );
        assert_eq!(damped.with_theta(&damped.theta()).unwrap(), damped);
        assert!(damped.with_theta(&plain.theta()).is_err());
        // A Bouc–Wen element's parameters follow α.
        let bw = upper_storey_element(1.0).with_mass_damping(0.0).unwrap();
        let t = [3.0, 5.0, 0.1, 0.2, 0.4, 1.0, -0.5, 2.0];
        let again = bw.with_theta(&t).unwrap();
        assert_eq!(again.theta(), t);
        assert_eq!(again.alpha(), Some(0.4));
        assert_eq!(again.bouc_wen()[0].n, 2.0);
        assert_eq!(
            plain.clone().with_mass_damping(-0.1),
            Err(StructureError::NegativeAlpha(-0.1))
        );
        assert!(plain.with_mass_damping(f64::NAN).is_err());
        assert_eq!("storey+mass".parse::<Damping>(), Ok(Damping::StoreyMass));
        assert_eq!("storey".parse::<Damping>(), Ok(Damping::Storey));
        assert!("rayleigh".parse::<Damping>().is_err());
    }

    #[test]
    fn names_theta_and_saturation() {
        let ch = paper();
        assert_eq!(ch.theta(), vec![8., 8., 8., 0.25, 0.25, 0.25, 2., 1., 2.]);
        assert_eq!(
            ch.theta_names(),
            ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"]
        );
        assert_eq!(ch.state_names(), ["x1", "x2", "x3", "v1", "v2", "v3", "r1"]);
        assert!((ch.saturation(0).unwrap() - (1.0f64 / 3.0).sqrt()).abs() < 1e-15);
        let again = ch.with_theta(&ch.theta()).unwrap();
        assert_eq!(again, ch);
    }

    #[test]
    fn validation_rejects_impossible_values() {
        let bw = |storey, n| BoucWen {
            storey,
            beta: 1.0,
            gamma: 0.5,
            n,
        };
        let ok = |m: Vec<f64>, k: Vec<f64>, c: Vec<f64>, b| ShearChain::new(m, k, c, b);
        let building_field = |r: Result<ShearChain, StructureError>| match r {
            Err(StructureError::Building(e)) => e.field,
            other => panic!("{other:?}"),
        };
        assert_eq!(building_field(ok(vec![], vec![], vec![], vec![])), "masses");
        assert!(matches!(
            ok(vec![1.0; 2], vec![1.0], vec![0.0; 2], vec![]),
            Err(StructureError::WrongLength { what: "k", .. })
        ));
        assert_eq!(
            building_field(ok(vec![1.0, 0.0], vec![1.0; 2], vec![0.0; 2], vec![])),
            "masses"
        );
        // Storeys numbered from 1, as θ names them: k2 is storey 2's, c1 storey 1's.
        let e = ok(vec![1.0; 2], vec![1.0, -1.0], vec![0.0; 2], vec![]).unwrap_err();
        assert!(matches!(
            e,
            StructureError::NegativeCoefficient { storey: 2, .. }
        ));
        assert_eq!(
            e.to_string(),
            "stiffness k of storey 2 must be non-negative and finite, got -1"
        );
        assert!(matches!(
            ok(vec![1.0; 2], vec![1.0; 2], vec![f64::NAN, 0.0], vec![]),
            Err(StructureError::NegativeCoefficient { storey: 1, .. })
        ));
        assert_eq!(
            building_field(ok(
                vec![1.0; 2],
                vec![1.0; 2],
                vec![0.0; 2],
                vec![bw(2, 2.0)]
            )),
            "hysteretic"
        );
        let twice = vec![bw(1, 2.0), bw(1, 2.0)];
        assert_eq!(
            building_field(ok(vec![1.0; 2], vec![1.0; 2], vec![0.0; 2], twice)),
            "hysteretic"
        );
        assert!(matches!(
            ok(vec![1.0; 2], vec![1.0; 2], vec![0.0; 2], vec![bw(0, 0.5)]),
            Err(StructureError::Law(LawError::OutOfRange {
                what: "exponent n",
                ..
            }))
        ));
        assert!(matches!(
            ok(
                vec![1.0; 2],
                vec![1.0; 2],
                vec![0.0; 2],
                vec![bw(0, f64::NAN)]
            ),
            Err(StructureError::Law(LawError::NonFinite { what: "n", .. }))
        ));
        assert!(paper().with_theta(&[1.0; 4]).is_err());
    }

    #[test]
    fn bouc_wen_at_upper_storey_uses_relative_velocity() {
        let ch = upper_storey_element(2.0);
        let s = [0.1, 0.4, 0.2, -0.3, 0.15];
        let mut d = [0.0; 5];
        ch.rhs(&s, 0.5, &mut d);
        let f0 = 3.0 * 0.1 + 0.1 * 0.2;
        let f1 = 5.0 * 0.15 + 0.2 * (-0.3 - 0.2);
        assert!((d[2] - (-0.5 + (f1 - f0) / 2.0)).abs() < 1e-15);
        assert!((d[3] - (-0.5 - f1 / 2.0)).abs() < 1e-15);
        assert!((d[4] - bouc_wen_rate(-0.5, 0.15, 0.5, 0.5, 1.5)).abs() < 1e-15);
        assert!((ch.element_drift(&s, 0) - 0.3).abs() < 1e-15);
    }
}
