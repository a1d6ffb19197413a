//! Filter partitions of the general shear chain on run-time dimensions (SPEC §5, §9), for forward
//! Euler and semi-implicit (symplectic) Euler, implementing the capability traits of
//! `core_filters::smc::model`. Derivations: `docs/partitions.md`, `docs/discretisation.md`.
//!
//! The chain is data ([`ChainSpec`]): a [`crate::building::Building`] (N storeys with masses,
//! hysteretic elements at any storeys), sensors at any storeys ([`crate::sensors`]). Every
//! partition evaluates forces and accelerations through the building's one force kernel and the
//! hysteresis law through [`crate::law::HysteresisLaw`], the same code as the truth simulator.
//! Specs, priors and partitions are generic over the law (`…Of<L>`, monomorphised); the names
//! without `Of` are the Bouc–Wen chain's.
//!
//! - [`augmented::AugmentedChainOf`]: bootstrap PF (`StateSpace`, SPEC §5.1), Euler, symplectic,
//!   RK4;
//! - [`mln::MlnChainOf`]: MLN-RBPF and Storvik (`ConditionallyLinear`, SPEC §5.2–5.3);
//! - [`mpf::MpfChainOf`]: MPF-EKF2 (`ConditionallyQuadratic`, SPEC §5.4, §6).
//!
//! θ = [k1..kN, c1..cN, (α with the storey+mass damping form, [`crate::structure::Damping`]),
//! then per hysteretic element in storey order the law's linear then nonlinear parameters
//! (Bouc–Wen: β, γ, n)]; states
//! x1..xN, v1..vN, `r<s>` (names from [`crate::structure::theta_names`] and
//! [`crate::structure::state_names`]). The transition to step k uses `ug[k−1]`, the measurement
//! at k uses `ug[k]` (SPEC §3).
//!
//! ```
//! use core_filters::smc::model::ConditionallyQuadratic;
//! use models::building::{Building, Damping};
//! use models::filtering::{ChainSpec, MpfChain, RmsLevels};
//! use models::sensors::{MeasurementKind, SensorLayout};
//!
//! // A 7-storey chain, Bouc–Wen elements at storeys 1 and 4 (0-based 0 and 3), sensors at 2, 4, 7.
//! let building = Building::new(vec![1.0; 7], vec![0, 3], Damping::Storey)?;
//! let sensors = SensorLayout::new(7, &[2, 4, 7], MeasurementKind::Relative)?;
//! let rms = RmsLevels { acc: vec![2.0; 3], ug: 3.0, drift_velocity: vec![0.5; 2] };
//! let spec = ChainSpec::from_rms(0.005, building, sensors, vec![0.0; 11], &rms, 0.1)?;
//! let mpf = MpfChain::new(spec)?;
//! // Sampled: v1, v3, v4 (the drift velocities of the two elements), r1, r4, n1, n4.
//! assert_eq!(mpf.dims().nn, 7);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod augmented;
pub mod discretisation;
pub mod mln;
pub mod mpf;
pub mod prior;
pub mod spec;
pub mod substeps;

pub use augmented::{AugmentedChain, AugmentedChainOf};
pub use discretisation::Discretisation;
pub use mln::{MlnChain, MlnChainOf};
pub use mpf::{MpfChain, MpfChainOf};
pub use prior::{ChainPrior, ChainPriorOf, ElementPrior, MarginalPrior};
pub use spec::{
    ChainSpec, ChainSpecOf, ColouredNoise, Regressors, RmsLevels, SpecError, MAX_SUBSTEPS,
    SPEC_R_NOISE_FRACTION,
};

use crate::law::{HysteresisLaw, MAX_LINEAR};
use crate::structure::{state_names, theta_names_damped, ChainView};
use core_filters::linalg::Sparse;
use core_filters::model::{Layout, Slot};
use core_filters::real::Real;
use core_filters::rng::StreamRng;
use core_filters::smc::rejuvenation::{StaticParam, Support};

use crate::priors::Prior;

/// A law's basis `[g₀, g₁, …]` in a stack array: the first `1 + L::NLIN` entries are used.
pub(crate) type Basis<T> = [T; 1 + MAX_LINEAR];

/// A zero [`Basis`].
#[inline(always)]
pub(crate) fn zero_basis<T: Real>() -> Basis<T> {
    [T::splat(0.0); 1 + MAX_LINEAR]
}

/// The law's linear-parameter count, checked at compile time (for each law a partition is built
/// with) against the stack array [`Basis`].
#[inline(always)]
pub(crate) const fn nlin<L: HysteresisLaw>() -> usize {
    const {
        assert!(
            L::NLIN <= MAX_LINEAR,
            "a law's linear parameters exceed MAX_LINEAR"
        )
    };
    L::NLIN
}

/// The support of a scalar prior, `None` for a point mass.
fn prior_support(p: &Prior) -> Option<Support> {
    match *p {
        Prior::Uniform { lo, hi } => Some(Support::Interval { lo, hi }),
        Prior::LogNormal { log_sd, .. } if log_sd > 0.0 => Some(Support::Above { lo: 0.0 }),
        Prior::LogNormal { .. } | Prior::Fixed { .. } => None,
    }
}

/// The variables a gradient of the storey forces is taken with respect to, by their columns, as
/// [`ChainCore::write_force_gradient`] asks for them. `F_j = k_j d_j + c_j δv_j`, with
/// `d_j = x_j − x_{j−1}` (or `r_e` for the hysteretic element `e` at storey `j`) and
/// `δv_j = v_j − v_{j−1}`; with mass damping the acceleration also has `−α v_j`
/// ([`ChainCore::write_acceleration_gradient`]). A quantity is not a variable unless its method
/// says so. A partition whose variables are fixed by construction answers with constants, so
/// that the compiler removes the branches of the variables it does not have.
pub(crate) trait ForceColumns {
    /// Columns of `k_1` and `c_1` when θ's stiffnesses and dampings are variables (`k_j` at
    /// `k + j`, `c_j` at `c + j`).
    #[inline(always)]
    fn theta(&self) -> Option<(usize, usize)> {
        None
    }
    /// Whether the displacements are variables (`x_j` at column `j`).
    #[inline(always)]
    fn displacements(&self) -> bool {
        false
    }
    /// Column of `r_1` when the hysteretic variables are (`r_e` at `r + e`).
    #[inline(always)]
    fn hysteretic(&self) -> Option<usize> {
        None
    }
    /// Column of storey `j`'s velocity when it is a variable.
    #[inline(always)]
    fn velocity(&self, _j: usize) -> Option<usize> {
        None
    }
    /// Column of α when the chain has mass damping and θ is a variable.
    #[inline(always)]
    fn alpha(&self) -> Option<usize> {
        None
    }
}

/// What every partition shares: the validated spec (whose building is the force kernel) and
/// precomputed constants.
#[derive(Debug, Clone)]
pub(crate) struct ChainCore<L: HysteresisLaw> {
    pub spec: ChainSpecOf<L>,
    pub law: L,
    /// Storeys N.
    pub n: usize,
    /// Hysteretic elements E.
    pub ne: usize,
    /// The filter's time step: `spec.dt / substeps`.
    pub dt: f64,
    /// Transitions per measurement interval ([`ChainSpec::substeps`]).
    pub substeps: usize,
    /// `ü_g,meas` on the filter's grid (`spec.ug` itself when `substeps` is 1; otherwise
    /// interpolated linearly, `K·substeps + 1` samples): index `k·substeps` is sample `k`.
    pub ug: Vec<f64>,
    /// Process-noise s.d. per filter step (the spec's over `√substeps`).
    pub q_disp: f64,
    pub q_vel: f64,
    pub q_r: Vec<f64>,
    /// `1/m_j`.
    pub inv_mass: Vec<f64>,
    /// 0-based measured storeys.
    pub sensors: Vec<usize>,
    /// Moment-matched θ means and variances (SPEC §3), θ order.
    pub theta_mean: Vec<f64>,
    pub theta_var: Vec<f64>,
}

impl<L: HysteresisLaw> ChainCore<L> {
    pub fn new(spec: ChainSpecOf<L>) -> Result<Self, SpecError> {
        spec.validate()?;
        let (theta_mean, theta_var) = spec.prior.moments();
        let m = spec.substeps;
        let noise = 1.0 / (m as f64).sqrt();
        Ok(Self {
            n: spec.n_storeys(),
            ne: spec.building.hysteretic().len(),
            dt: spec.dt / m as f64,
            substeps: m,
            ug: crate::ground_between::refine(&spec.ug, spec.dt, m, spec.ground_between),
            q_disp: spec.q_disp * noise,
            q_vel: spec.q_vel * noise,
            q_r: spec.q_r.iter().map(|q| q * noise).collect(),
            inv_mass: spec.building.masses().iter().map(|m| 1.0 / m).collect(),
            sensors: spec.sensors.storeys().to_vec(),
            theta_mean,
            theta_var,
            law: L::default(),
            spec,
        })
    }

    /// Ground term of the transition to filter step k: `−ü_g,meas(k−1)` (filter steps: the
    /// samples when `substeps` is 1, the sub-steps otherwise).
    #[inline]
    #[track_caller]
    pub(crate) fn transition_ground(&self, k: usize) -> f64 {
        assert!(k >= 1, "the transition to step k needs k >= 1");
        -self.ug[k - 1]
    }

    /// Ground term of the measurement at filter step k (relative: `−ü_g,meas(k)`, absolute: 0).
    #[inline]
    pub(crate) fn measurement_ground(&self, k: usize) -> f64 {
        self.spec.sensors.ground(self.ug[k])
    }

    /// The sampled block at the start (SPEC §3): zero states, and each element's nonlinear
    /// parameters (Bouc–Wen: n) drawn from its prior into `out[n_index(e)..]`, in element order.
    pub fn sample_initial(
        &self,
        rng: &mut StreamRng,
        out: &mut [f64],
        n_index: impl Fn(usize) -> usize,
    ) {
        out.fill(0.0);
        for (e, el) in self.spec.prior.elements.iter().enumerate() {
            let i = n_index(e);
            L::sample_nonlinear(el, rng, &mut out[i..i + L::NNONLIN]);
        }
    }

    /// The static entries of the sampled block (each element's n at `n_index(e)`) with the
    /// support of the prior the chain actually uses (`spec.prior`, after any fixing, data scaling
    /// or user prior): `[lo, hi]` for `U(lo, hi)`, `(0, ∞)` for a log-normal; a point mass
    /// (fixed, or a log-normal of log-s.d. 0) is left out, it has nothing to move.
    pub fn static_params(&self, n_index: impl Fn(usize) -> usize) -> Vec<StaticParam> {
        self.spec
            .prior
            .elements
            .iter()
            .enumerate()
            .flat_map(|(e, el)| {
                let first = n_index(e);
                (0..L::NNONLIN).filter_map(move |i| {
                    prior_support(L::nonlinear_prior(el, i)).map(|support| StaticParam {
                        index: first + i,
                        support,
                    })
                })
            })
            .collect()
    }

    /// `R` (column-major, diagonal): the white part of the measurement noise (all of it without
    /// coloured noise, `(1 − share)·r_diag` with it).
    pub fn measurement_cov(&self) -> Vec<f64> {
        let m = self.sensors.len();
        let white = 1.0 - self.spec.coloured_noise.map_or(0.0, |c| c.share);
        let mut r = vec![0.0; m * m];
        for (i, v) in self.spec.r_diag.iter().enumerate() {
            r[i + i * m] = white * *v;
        }
        r
    }

    /// Refuses coloured measurement noise and regressors for a partition that has no Gaussian
    /// part to carry them.
    pub fn no_gaussian_extras(&self, partition: &'static str) -> Result<(), SpecError> {
        if self.spec.coloured_noise.is_some() {
            return Err(SpecError::Invalid {
                field: "coloured_noise",
                reason: format!(
                    "the {partition} partition has no state for coloured measurement noise; \
                     use the MPF-EKF2"
                ),
            });
        }
        if self.spec.regressors.is_some() {
            return Err(SpecError::Invalid {
                field: "regressors",
                reason: format!(
                    "the {partition} partition has no Gaussian part for the regressors' \
                     coefficients; use the MPF-EKF2"
                ),
            });
        }
        Ok(())
    }

    /// Writes `s · ∂F_j/∂w` at the point `p` into row `row`, `w` the variables `vars`: the one
    /// force gradient of the partitions. The entries come in a fixed order (θ, deformation,
    /// velocities) that depends on `j` and `vars` only, so the pattern is the same at every call;
    /// a quantity that is not needed is not read (`p` may lack θ or the states).
    // Always inlined: the partitions' transitions call it once per row, and left to the
    // optimiser it stayed a call whose branches on the declared columns ran every time
    // (docs/performance.md, "Speed across builds").
    #[inline(always)]
    pub(crate) fn write_force_gradient<T: Real>(
        &self,
        out: &mut Sparse<T>,
        row: usize,
        j: usize,
        p: &impl ChainView<T>,
        vars: &impl ForceColumns,
        s: T,
    ) {
        if let Some((k0, c0)) = vars.theta() {
            let (d, dv) = self.spec.building.element_coordinates(p, j);
            out.add(row, k0 + j, s * d);
            out.add(row, c0 + j, s * dv);
        }
        match (self.spec.building.element_at(j), vars.hysteretic()) {
            (Some(e), Some(r0)) => out.add(row, r0 + e, s * p.k(j)),
            (None, _) if vars.displacements() => {
                let k = s * p.k(j);
                out.add(row, j, k);
                if j > 0 {
                    out.add(row, j - 1, -k);
                }
            }
            _ => {}
        }
        let below = if j > 0 { vars.velocity(j - 1) } else { None };
        if vars.velocity(j).is_some() || below.is_some() {
            let c = s * p.c(j);
            if let Some(i) = vars.velocity(j) {
                out.add(row, i, c);
            }
            if let Some(i) = below {
                out.add(row, i, -c);
            }
        }
    }

    /// Writes `scale · ∂a_j/∂w` (`a_j = ground + (F_{j+1} − F_j)/m_j`, `− α v_j` with mass
    /// damping) into row `row`.
    // Always inlined: the partitions' transitions call it once per row, and left to the
    // optimiser it stayed a call whose branches on the declared columns ran every time
    // (docs/performance.md, "Speed across builds").
    #[inline(always)]
    pub(crate) fn write_acceleration_gradient<T: Real>(
        &self,
        out: &mut Sparse<T>,
        row: usize,
        j: usize,
        p: &impl ChainView<T>,
        vars: &impl ForceColumns,
        scale: T,
    ) {
        let s = scale * T::splat(self.inv_mass[j]);
        self.write_force_gradient(out, row, j, p, vars, -s);
        if j + 1 < self.n {
            self.write_force_gradient(out, row, j + 1, p, vars, s);
        }
        if self.spec.building.damping().has_mass_term() {
            if let Some(a) = vars.alpha() {
                out.add(row, a, -(scale * p.v(j)));
            }
            if let Some(i) = vars.velocity(j) {
                out.add(row, i, -(scale * p.alpha()));
            }
        }
    }

    /// Whether the chain has the mass-proportional damping term.
    #[inline]
    pub fn mass_damping(&self) -> bool {
        self.spec.building.damping().has_mass_term()
    }

    /// Index of α in θ (`2N`), when the chain has mass damping.
    #[inline]
    pub(crate) fn theta_alpha(&self) -> Option<usize> {
        self.mass_damping().then_some(2 * self.n)
    }

    /// Index of the first θ entry of element `e` (Bouc–Wen: β_e) in θ.
    #[inline]
    pub(crate) fn theta_element(&self, e: usize) -> usize {
        2 * self.n + self.spec.building.damping().extra_parameters() + L::NPARAMS * e
    }

    /// Mean and variance of the Gaussian prior of θ for one particle (SPEC §3): moment-matched,
    /// or per-particle means drawn from the prior with variances `(rel_sd·mean)²` (zero for a
    /// point mass). Start-up only.
    pub(crate) fn theta_prior(&self, rng: &mut StreamRng) -> (Vec<f64>, Vec<f64>) {
        match self.spec.marginal_prior {
            MarginalPrior::MomentMatched => (self.theta_mean.clone(), self.theta_var.clone()),
            MarginalPrior::PerParticle { rel_sd } => {
                let mut mean = vec![0.0; self.theta_mean.len()];
                self.spec.prior.sample_into(rng, &mut mean);
                let var = mean
                    .iter()
                    .zip(&self.theta_var)
                    .map(|(m, v0)| if *v0 > 0.0 { (rel_sd * m).powi(2) } else { 0.0 })
                    .collect();
                (mean, var)
            }
        }
    }

    /// Whether the scheme is symplectic Euler (`false`: forward Euler), the two schemes of the
    /// MLN and MPF partitions; any other is refused for `partition`.
    pub fn symplectic(&self, partition: &'static str) -> Result<bool, SpecError> {
        match self.spec.discretisation {
            Discretisation::Euler => Ok(false),
            Discretisation::Symplectic => Ok(true),
            discretisation => Err(SpecError::Unsupported {
                partition,
                discretisation,
            }),
        }
    }

    /// The physical support of the marginalised stiffnesses, dampings and α (each ≥ 0) when the
    /// spec asks for it ([`ChainSpecOf::physical_support`]), from θ's slots `params`: with
    /// every c_j ≥ 0 and α ≥ 0 the damping matrix Σ c_j e_j e_jᵀ + αM is positive semidefinite.
    pub fn lower_bounds(&self, params: &[Slot]) -> Vec<core_filters::linalg::LowerBound> {
        if !self.spec.physical_support {
            return Vec::new();
        }
        let na = self.spec.building.damping().extra_parameters();
        params[..2 * self.n + na]
            .iter()
            .filter_map(|s| match *s {
                Slot::Marginal(index) => {
                    Some(core_filters::linalg::LowerBound { index, bound: 0.0 })
                }
                Slot::Sampled(_) => None,
            })
            .collect()
    }

    /// A partition's layout: θ's slots (in θ order) and the states' slots, with the
    /// structure's names.
    pub fn layout(&self, params: Vec<Slot>, states: Vec<Slot>) -> Layout {
        Layout {
            param_names: self.theta_names(),
            params,
            state_names: self.state_names(),
            states,
        }
    }

    /// Appends the slots of every element's θ entries in θ order: its linear parameters at
    /// `linear(e) + i` of the marginal block, its nonlinear ones (Bouc–Wen: n) at
    /// `n_index(e) + i` of the sampled block (the MLN and MPF partitions).
    pub(crate) fn push_element_slots(
        &self,
        params: &mut Vec<Slot>,
        linear: impl Fn(usize) -> usize,
        n_index: impl Fn(usize) -> usize,
    ) {
        for e in 0..self.ne {
            params.extend((0..L::NLIN).map(|i| Slot::Marginal(linear(e) + i)));
            params.extend((0..L::NNONLIN).map(|i| Slot::Sampled(n_index(e) + i)));
        }
    }

    pub fn theta_names(&self) -> Vec<String> {
        let b = &self.spec.building;
        theta_names_damped::<L>(self.n, b.hysteretic(), b.damping())
    }

    pub fn state_names(&self) -> Vec<String> {
        state_names(self.n, self.spec.building.hysteretic())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::building::{Building, Damping};
    use crate::sensors::{MeasurementKind, SensorLayout};

    fn spec(discretisation: Discretisation) -> ChainSpec {
        let building = Building::new(vec![1.0; 3], vec![0], Damping::Storey).unwrap();
        let sensors = SensorLayout::new(3, &[1, 2, 3], MeasurementKind::Relative).unwrap();
        let rms = RmsLevels {
            acc: vec![2.0; 3],
            ug: 3.0,
            drift_velocity: vec![0.5],
        };
        let ug = vec![0.0; 11];
        let mut spec = ChainSpec::from_rms(0.005, building, sensors, ug, &rms, 0.1).unwrap();
        spec.discretisation = discretisation;
        spec
    }

    /// The MLN and MPF partitions take forward and symplectic Euler and refuse RK4 by their
    /// own name; the augmented state takes all three.
    #[test]
    fn the_conditional_partitions_take_the_two_euler_schemes_only() {
        use Discretisation::{Euler, Rk4, Symplectic};
        for (d, symplectic) in [(Euler, false), (Symplectic, true)] {
            let core = ChainCore::new(spec(d)).unwrap();
            assert_eq!(core.symplectic("any"), Ok(symplectic));
            assert!(MlnChain::new(spec(d)).is_ok() && MpfChain::new(spec(d)).is_ok());
        }
        for (partition, refused) in [
            ("MLN-RBPF/Storvik", MlnChain::new(spec(Rk4)).err()),
            ("MPF-EKF2", MpfChain::new(spec(Rk4)).err()),
        ] {
            let want = SpecError::Unsupported {
                partition,
                discretisation: Rk4,
            };
            assert_eq!(refused, Some(want));
        }
        assert!(AugmentedChain::new(spec(Rk4)).is_ok());
    }

    /// The MLN and MPF partitions declare each element's n, at its slot of the sampled block,
    /// with the support of the prior the chain uses; a point mass is not declared; the augmented
    /// state declares nothing.
    #[test]
    fn the_static_parameters_are_the_exponents_with_their_priors_supports() {
        use core_filters::model::Slot;
        use core_filters::smc::model::Partition;
        let n_slot = |layout: Layout| match layout.params[layout.param_names.len() - 1] {
            Slot::Sampled(i) => i,
            Slot::Marginal(_) => panic!("n is sampled"),
        };
        let with_n = |n: Prior| {
            let mut s = spec(Discretisation::Symplectic);
            s.prior.elements[0].n = n;
            s
        };
        for (prior, support) in [
            (
                Prior::Uniform { lo: 1.0, hi: 5.0 },
                Some(Support::Interval { lo: 1.0, hi: 5.0 }),
            ),
            (
                Prior::Uniform { lo: 1.5, hi: 2.5 },
                Some(Support::Interval { lo: 1.5, hi: 2.5 }),
            ),
            (
                Prior::LogNormal {
                    median: 2.0,
                    log_sd: 0.3,
                },
                Some(Support::Above { lo: 0.0 }),
            ),
            (
                Prior::LogNormal {
                    median: 2.0,
                    log_sd: 0.0,
                },
                None,
            ),
            (Prior::Fixed { value: 2.0 }, None),
        ] {
            let mpf = MpfChain::new(with_n(prior)).unwrap();
            let mln = MlnChain::new(with_n(prior)).unwrap();
            for (got, index) in [
                (mpf.static_params(), n_slot(mpf.layout())),
                (mln.static_params(), n_slot(mln.layout())),
            ] {
                let want: Vec<StaticParam> = support
                    .map(|support| StaticParam { index, support })
                    .into_iter()
                    .collect();
                assert_eq!(got, want, "{prior:?}");
            }
            assert!(AugmentedChain::new(with_n(prior))
                .unwrap()
                .static_params()
                .is_empty());
        }
        // The default prior of the spec is SPEC §3's n ~ U(1, 5).
        let mpf = MpfChain::new(spec(Discretisation::Euler)).unwrap();
        assert_eq!(
            mpf.static_params()[0].support,
            Support::Interval { lo: 1.0, hi: 5.0 }
        );
    }
}
