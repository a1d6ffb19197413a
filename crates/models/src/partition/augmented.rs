//! Augmented-state partition for the bootstrap particle filter (SPEC §5.1).
//!
//! x = [x1..xN, ẋ1..ẋN, r1, θ] with θ = [k1..kN, c1..cN, β, γ, n], NX = 4N + 4 (16 for the
//! paper's 3-storey chain), NY = N. θ is static and carries no process noise.

use super::{check_dim, state_names, ChainCore, ChainPoint, FilterSpec, PartitionError};
use crate::priors::parameter_names;
use core_filters::model::{Layout, Slot, StateSpace};
use nalgebra::{SMatrix, SVector};
use rand::Rng;

/// The Bouc–Wen chain as one augmented state (SPEC §5.1).
#[derive(Debug, Clone)]
pub struct AugmentedChain<const NX: usize, const NY: usize> {
    spec: FilterSpec,
    core: ChainCore,
}

/// The paper's 3-storey chain: 16 states, 3 channels.
pub type PaperAugmented = AugmentedChain<16, 3>;

struct Point<'a, const NX: usize> {
    x: &'a SVector<f64, NX>,
    n: usize,
}

impl<const NX: usize> ChainPoint for Point<'_, NX> {
    #[inline]
    fn x(&self, j: usize) -> f64 {
        self.x[j - 1]
    }
    #[inline]
    fn v(&self, j: usize) -> f64 {
        self.x[self.n + j - 1]
    }
    #[inline]
    fn r1(&self) -> f64 {
        self.x[2 * self.n]
    }
    #[inline]
    fn k(&self, j: usize) -> f64 {
        self.x[2 * self.n + j]
    }
    #[inline]
    fn c(&self, j: usize) -> f64 {
        self.x[3 * self.n + j]
    }
    #[inline]
    fn beta(&self) -> f64 {
        self.x[4 * self.n + 1]
    }
    #[inline]
    fn gamma(&self) -> f64 {
        self.x[4 * self.n + 2]
    }
    #[inline]
    fn n(&self) -> f64 {
        self.x[4 * self.n + 3]
    }
}

impl<const NX: usize, const NY: usize> AugmentedChain<NX, NY> {
    /// Checks NX = 4N + 4 and NY = N against the spec's N and validates the spec.
    pub fn new(spec: FilterSpec) -> Result<Self, PartitionError> {
        let n = spec.n_storeys();
        check_dim("NX (augmented state)", NX, 4 * n + 4, n)?;
        check_dim("NY (channels)", NY, n, n)?;
        let core = ChainCore::new(&spec)?;
        Ok(Self { spec, core })
    }

    pub fn spec(&self) -> &FilterSpec {
        &self.spec
    }

    /// Number of storeys N.
    pub fn n_storeys(&self) -> usize {
        self.core.n
    }
}

impl<const NX: usize, const NY: usize> StateSpace<NX, NY> for AugmentedChain<NX, NY> {
    /// Zero states, θ drawn from its prior (SPEC §3).
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NX> {
        let mut x = SVector::<f64, NX>::zeros();
        let theta_start = 2 * self.core.n + 1;
        self.spec
            .prior
            .sample_into(rng, &mut x.as_mut_slice()[theta_start..]);
        x
    }

    /// Forward-Euler map from k−1 to k with ü_g,meas(k−1) (SPEC §3); θ copied.
    fn propagate(&self, k: usize, x: &SVector<f64, NX>) -> SVector<f64, NX> {
        let n = self.core.n;
        let dt = self.core.dt;
        let p = Point { x, n };
        let ground = ChainCore::transition_ground(&self.spec.ug, k);
        let mut next = *x;
        for j in 1..=n {
            next[j - 1] = p.x(j) + dt * p.v(j);
            next[n + j - 1] = p.v(j) + dt * self.core.acceleration(&p, j, ground);
        }
        next[2 * n] = p.r1() + dt * ChainCore::r1_rate(&p);
        next
    }

    fn process_noise_sd(&self) -> SVector<f64, NX> {
        let n = self.core.n;
        SVector::from_fn(|i, _| match i {
            i if i < n => self.spec.q_disp_sd,
            i if i < 2 * n => self.spec.q_vel_sd,
            i if i == 2 * n => self.spec.q_r_sd,
            _ => 0.0,
        })
    }

    /// Accelerations at step k with ü_g,meas(k) (SPEC §2: relative, or absolute as an option).
    fn measure(&self, k: usize, x: &SVector<f64, NX>) -> SVector<f64, NY> {
        let p = Point { x, n: self.core.n };
        let ground = self.core.measurement_ground(&self.spec.ug, k);
        SVector::from_fn(|i, _| self.core.acceleration(&p, i + 1, ground))
    }

    fn measurement_cov(&self) -> SMatrix<f64, NY, NY> {
        SMatrix::from_diagonal(&SVector::from_column_slice(&self.spec.r_diag))
    }

    fn layout(&self) -> Layout {
        let n = self.core.n;
        Layout {
            param_names: parameter_names(n),
            params: (0..2 * n + 3)
                .map(|i| Slot::Sampled(2 * n + 1 + i))
                .collect(),
            state_names: state_names(n),
            states: (0..2 * n + 1).map(Slot::Sampled).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::rng::stream;

    fn spec(n: usize) -> FilterSpec {
        let masses = vec![1.0; n];
        FilterSpec::from_rms(0.005, masses, vec![0.5; 5], &vec![1.0; n], 1.0, 0.5, 0.1).unwrap()
    }

    #[test]
    fn dimensions_are_checked() {
        assert!(PaperAugmented::new(spec(3)).is_ok());
        assert!(matches!(
            PaperAugmented::new(spec(2)),
            Err(PartitionError::DimensionMismatch {
                expected: 12,
                got: 16,
                ..
            })
        ));
        assert!(AugmentedChain::<24, 5>::new(spec(5)).is_ok());
        assert!(AugmentedChain::<24, 4>::new(spec(5)).is_err());
    }

    #[test]
    fn initial_state_is_zero_with_theta_from_prior() {
        let m = PaperAugmented::new(spec(3)).unwrap();
        let mut rng = stream(1, 0, "test");
        let x = m.sample_initial(&mut rng);
        assert!(x.rows(0, 7).iter().all(|&v| v == 0.0));
        assert!(x.rows(7, 6).iter().all(|&v| v > 0.0));
        assert!(x[13] >= 0.0 && x[14].abs() <= x[13] && (1.0..5.0).contains(&x[15]));
        let sd = m.process_noise_sd();
        assert_eq!(sd[0], 1e-6);
        assert!(sd[3] > 0.0 && sd[6] > 0.0);
        assert!(sd.rows(7, 9).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn layout_names_every_slot() {
        let l = PaperAugmented::new(spec(3)).unwrap().layout();
        assert_eq!(l.param_names[6], "beta");
        assert_eq!(l.params[0], Slot::Sampled(7));
        assert_eq!(l.params[8], Slot::Sampled(15));
        assert_eq!(l.state_names, ["x1", "x2", "x3", "v1", "v2", "v3", "r1"]);
        assert_eq!(l.states[6], Slot::Sampled(6));
    }
}
