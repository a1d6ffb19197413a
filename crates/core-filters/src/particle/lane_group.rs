//! The Gaussians `N(μ, C)` of a group of four particles in SIMD lanes, as the marginalized
//! filters that process their particles four at a time (Storvik, MLN-RBPF) hold them: gathered
//! from the particles' ancestors, updated in lanes ([`crate::kalman::lanes`]), and written back to
//! the particles whose lanes took the scalar update's straight path.

use nalgebra::{SMatrix, SVector};
use wide::f64x4;

use crate::kalman::lanes::{gather_mat, gather_vec, scatter_all, LaneMat, LaneVec, LANES};

/// The moments of a lane group, with the spares that lanes without a particle write to.
#[derive(Debug, Clone)]
pub struct LaneMoments<const N: usize> {
    pub mu: LaneVec<N>,
    pub cov: LaneMat<N, N>,
    spare_mu: [SVector<f64, N>; LANES],
    spare_cov: [SMatrix<f64, N, N>; LANES],
}

impl<const N: usize> Default for LaneMoments<N> {
    fn default() -> Self {
        Self {
            mu: [f64x4::ZERO; N],
            cov: [[f64x4::ZERO; N]; N],
            spare_mu: [SVector::zeros(); LANES],
            spare_cov: [SMatrix::zeros(); LANES],
        }
    }
}

impl<const N: usize> LaneMoments<N> {
    /// Gathers lane `b` from particle `sources[b]` of `mu` and `cov`; lanes past the end of
    /// `sources` (a group of fewer than four) repeat its first particle.
    pub fn gather(
        &mut self,
        mu: &[SVector<f64, N>],
        cov: &[SMatrix<f64, N, N>],
        sources: &[usize],
    ) {
        let source = |b: usize| sources[if b < sources.len() { b } else { 0 }];
        gather_mat(&mut self.cov, std::array::from_fn(|b| &cov[source(b)]));
        gather_vec(&mut self.mu, std::array::from_fn(|b| &mu[source(b)]));
    }

    /// Writes lane `b` to `mu[b]` and `cov[b]` (the group's particles) where `take[b]`, in one
    /// pass over the four lanes: a lane that does not take its result writes to a spare.
    pub fn write_back(
        &mut self,
        take: [bool; LANES],
        mu: &mut [SVector<f64, N>],
        cov: &mut [SMatrix<f64, N, N>],
    ) {
        if !take.contains(&true) {
            return;
        }
        let (mut mus, mut covs) = (mu.iter_mut(), cov.iter_mut());
        let (mut spare_mu, mut spare_cov) = (self.spare_mu.iter_mut(), self.spare_cov.iter_mut());
        let mu_out = std::array::from_fn(|b| match mus.next() {
            Some(own) if take[b] => own,
            _ => spare_mu.next().expect("four spares"),
        });
        let cov_out = std::array::from_fn(|b| match covs.next() {
            Some(own) if take[b] => own,
            _ => spare_cov.next().expect("four spares"),
        });
        scatter_all(std::array::from_ref(&self.mu), mu_out);
        scatter_all(&self.cov, cov_out);
    }
}
