//! Conditionally bilinear partition for MPF-EKF2 (SPEC §5.4 and §6).
//!
//! Sampled xⁿ = [ẋ1, r1, n] (ẋ1 and r1 dynamic, n static); marginalised
//! x^bl = [x1..xN, ẋ2..ẋN, k1..kN, c1..cN, β, γ] (NBL = 4N + 1; for N = 3 the indices of SPEC §6:
//! 0 x1, 1 x2, 2 x3, 3 ẋ2, 4 ẋ3, 5 k1, 6 k2, 7 k3, 8 c1, 9 c2, 10 c3, 11 β, 12 γ).
//!
//! Given xⁿ every map is at most bilinear in x^bl: the element force F_j (j ≥ 2) has the products
//! k_j·x and c_j·ẋ (ẋ1 is known, so c_2·ẋ1 is linear), F_1 = k1 r1 + c1 ẋ1 is linear, and
//! ṙ1 is affine in (β, γ). The Hessians are therefore constant — ±dt/m_j in the dynamics and
//! ±1/m_j in the measurement — and are built once as sparse entry lists.

use super::{check_dim, state_names, ChainCore, ChainPoint, FilterSpec, PartitionError};
use crate::priors::parameter_names;
use core_filters::model::{ConditionallyQuadratic, Layout, Slot, SparseHessians};
use nalgebra::{SMatrix, SVector};
use rand::Rng;

/// Number of sampled entries (ẋ1, r1, n).
pub const NN: usize = 3;
/// Number of dynamic sampled entries (ẋ1, r1).
pub const ND: usize = 2;

/// The Bouc–Wen chain partitioned for MPF-EKF2 (SPEC §5.4).
#[derive(Debug, Clone)]
pub struct MpfChain<const NBL: usize, const NY: usize> {
    spec: FilterSpec,
    core: ChainCore,
    sampled_hessians: SparseHessians,
    marginal_hessians: SparseHessians,
    observation_hessians: SparseHessians,
}

/// The paper's 3-storey chain: 13 marginalised entries, 3 channels.
pub type PaperMpf = MpfChain<13, 3>;

/// Index map of x^bl for N storeys.
#[derive(Debug, Clone, Copy)]
struct Index {
    n: usize,
}

impl Index {
    #[inline]
    fn x(self, j: usize) -> usize {
        j - 1
    }
    /// ẋ_j lives in x^bl for j ≥ 2; ẋ1 is sampled.
    #[inline]
    fn v(self, j: usize) -> Option<usize> {
        (j >= 2).then(|| self.n + j - 2)
    }
    #[inline]
    fn k(self, j: usize) -> usize {
        2 * self.n - 1 + j - 1
    }
    #[inline]
    fn c(self, j: usize) -> usize {
        3 * self.n - 1 + j - 1
    }
    #[inline]
    fn beta(self) -> usize {
        4 * self.n - 1
    }
    #[inline]
    fn gamma(self) -> usize {
        4 * self.n
    }
}

/// (xⁿ, x^bl) seen as a chain point.
struct Point<'a, const NBL: usize> {
    xn: &'a SVector<f64, NN>,
    m: &'a SVector<f64, NBL>,
    idx: Index,
}

impl<const NBL: usize> ChainPoint for Point<'_, NBL> {
    #[inline]
    fn x(&self, j: usize) -> f64 {
        self.m[self.idx.x(j)]
    }
    #[inline]
    fn v(&self, j: usize) -> f64 {
        match self.idx.v(j) {
            Some(i) => self.m[i],
            None => self.xn[0],
        }
    }
    #[inline]
    fn r1(&self) -> f64 {
        self.xn[1]
    }
    #[inline]
    fn k(&self, j: usize) -> f64 {
        self.m[self.idx.k(j)]
    }
    #[inline]
    fn c(&self, j: usize) -> f64 {
        self.m[self.idx.c(j)]
    }
    #[inline]
    fn beta(&self) -> f64 {
        self.m[self.idx.beta()]
    }
    #[inline]
    fn gamma(&self) -> f64 {
        self.m[self.idx.gamma()]
    }
    #[inline]
    fn n(&self) -> f64 {
        self.xn[2]
    }
}

impl<const NBL: usize, const NY: usize> MpfChain<NBL, NY> {
    /// Checks NBL = 4N + 1 and NY = N, validates the spec and builds the constant Hessians.
    pub fn new(spec: FilterSpec) -> Result<Self, PartitionError> {
        let n = spec.n_storeys();
        check_dim("NBL (marginalised block)", NBL, 4 * n + 1, n)?;
        check_dim("NY (channels)", NY, n, n)?;
        let core = ChainCore::new(&spec)?;
        let idx = Index { n };
        let dt = core.dt;
        // ψ_ẋ1 = ẋ1 + dt·a_1: Hessian of dt·a_1 (SPEC §6).
        let mut sampled_hessians = SparseHessians::new();
        push_acceleration_hessian(&core, idx, &mut sampled_hessians, 0, 1, dt);
        // φ for ẋ_j, j ≥ 2: ẋ_j + dt·a_j; displacements are affine, parameters identity.
        let mut marginal_hessians = SparseHessians::new();
        for j in 2..=n {
            let out = idx.v(j).expect("j >= 2");
            push_acceleration_hessian(&core, idx, &mut marginal_hessians, out, j, dt);
        }
        // y_j = a_j.
        let mut observation_hessians = SparseHessians::new();
        for j in 1..=n {
            push_acceleration_hessian(&core, idx, &mut observation_hessians, j - 1, j, 1.0);
        }
        Ok(Self {
            spec,
            core,
            sampled_hessians,
            marginal_hessians,
            observation_hessians,
        })
    }

    pub fn spec(&self) -> &FilterSpec {
        &self.spec
    }

    /// Number of storeys N.
    pub fn n_storeys(&self) -> usize {
        self.core.n
    }

    #[inline]
    fn idx(&self) -> Index {
        Index { n: self.core.n }
    }

    /// Adds `scale · ∂a_j/∂x^bl` (a_j the acceleration of storey j) to row `row` of `out`.
    #[inline]
    fn add_acceleration_gradient<const R: usize>(
        &self,
        p: &Point<'_, NBL>,
        out: &mut SMatrix<f64, R, NBL>,
        row: usize,
        j: usize,
        scale: f64,
    ) {
        let s = scale * self.core.inv_mass[j - 1];
        add_force_gradient(p, out, row, j, -s);
        if j < self.core.n {
            add_force_gradient(p, out, row, j + 1, s);
        }
    }
}

/// Adds `scale · ∂F_j/∂x^bl` at `p` to row `row` of `out`.
#[inline]
fn add_force_gradient<const R: usize, const NBL: usize>(
    p: &Point<'_, NBL>,
    out: &mut SMatrix<f64, R, NBL>,
    row: usize,
    j: usize,
    scale: f64,
) {
    let idx = p.idx;
    let (d, dv) = ChainCore::element_coefficients(p, j);
    out[(row, idx.k(j))] += scale * d;
    out[(row, idx.c(j))] += scale * dv;
    if j >= 2 {
        let (k, c) = (p.k(j), p.c(j));
        out[(row, idx.x(j))] += scale * k;
        out[(row, idx.x(j - 1))] -= scale * k;
        if let Some(i) = idx.v(j) {
            out[(row, i)] += scale * c;
        }
        if let Some(i) = idx.v(j - 1) {
            out[(row, i)] -= scale * c;
        }
    }
}

/// Pushes the constant Hessian of `scale · F_j` (j ≥ 2: k_j·(x_j − x_{j−1}) and
/// c_j·(ẋ_j − ẋ_{j−1}) with ẋ1 known) as output `out`. F_1 is linear in x^bl.
fn push_force_hessian(idx: Index, h: &mut SparseHessians, out: usize, j: usize, scale: f64) {
    if j < 2 {
        return;
    }
    h.push(out, idx.k(j), idx.x(j), scale);
    h.push(out, idx.k(j), idx.x(j - 1), -scale);
    if let Some(i) = idx.v(j) {
        h.push(out, idx.c(j), i, scale);
    }
    if let Some(i) = idx.v(j - 1) {
        h.push(out, idx.c(j), i, -scale);
    }
}

/// Pushes the Hessian of `scale · a_j`, a_j = (−F_j + F_{j+1}) / m_j − ü_g.
fn push_acceleration_hessian(
    core: &ChainCore,
    idx: Index,
    h: &mut SparseHessians,
    out: usize,
    j: usize,
    scale: f64,
) {
    let s = scale * core.inv_mass[j - 1];
    push_force_hessian(idx, h, out, j, -s);
    if j < core.n {
        push_force_hessian(idx, h, out, j + 1, s);
    }
}

impl<const NBL: usize, const NY: usize> ConditionallyQuadratic<NN, ND, NBL, NY>
    for MpfChain<NBL, NY>
{
    /// ẋ1 = r1 = 0, n drawn from its prior (SPEC §3).
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NN> {
        SVector::<f64, NN>::new(0.0, 0.0, self.spec.prior.n.sample(rng))
    }

    /// States exactly zero (zero variance); parameters from the moment-matched Gaussian of θ
    /// (SPEC §3) or the per-particle option.
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        rng: &mut G,
    ) -> (SVector<f64, NBL>, SMatrix<f64, NBL, NBL>) {
        let n = self.core.n;
        // Start-up only (once per particle), so the θ-sized scratch may allocate.
        let d = self.spec.prior.len();
        let (mut mean, mut var) = (vec![0.0; d], vec![0.0; d]);
        self.core
            .marginal_theta_prior(&self.spec, rng, &mut mean, &mut var);
        let mut m = SVector::<f64, NBL>::zeros();
        let mut p_diag = SVector::<f64, NBL>::zeros();
        // θ without n maps onto x^bl[2N−1..4N+1] in the same order (k, c, β, γ).
        let start = self.idx().k(1);
        m.rows_mut(start, 2 * n + 2)
            .copy_from_slice(&mean[..2 * n + 2]);
        p_diag
            .rows_mut(start, 2 * n + 2)
            .copy_from_slice(&var[..2 * n + 2]);
        (m, SMatrix::from_diagonal(&p_diag))
    }

    /// SPEC §6: ψ_ẋ1 = ẋ1 + dt·a_1 and ψ_r1 = r1 + dt·ṙ1 at (xⁿ_{k−1}, m) with ü_g,meas(k−1).
    fn sampled_dynamics(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, ND>, SMatrix<f64, ND, NBL>) {
        let dt = self.core.dt;
        let idx = self.idx();
        let p = Point { xn, m, idx };
        let ground = ChainCore::transition_ground(&self.spec.ug, k);
        let value = SVector::<f64, ND>::new(
            p.v(1) + dt * self.core.acceleration(&p, 1, ground),
            p.r1() + dt * ChainCore::r1_rate(&p),
        );
        let mut jac = SMatrix::<f64, ND, NBL>::zeros();
        self.add_acceleration_gradient(&p, &mut jac, 0, 1, dt);
        let (db, dg) = ChainCore::r1_rate_shape_gradient(&p);
        jac[(1, idx.beta())] = dt * db;
        jac[(1, idx.gamma())] = dt * dg;
        (value, jac)
    }

    /// SPEC §6: φ_bl = Euler map of x1..xN (x1 uses the sampled ẋ1 at k−1) and ẋ2..ẋN;
    /// parameters unchanged.
    fn marginal_dynamics(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, NBL>, SMatrix<f64, NBL, NBL>) {
        let n = self.core.n;
        let dt = self.core.dt;
        let idx = self.idx();
        let p = Point { xn, m, idx };
        let ground = ChainCore::transition_ground(&self.spec.ug, k);
        let mut value = *m;
        let mut jac = SMatrix::<f64, NBL, NBL>::identity();
        for j in 1..=n {
            value[idx.x(j)] = p.x(j) + dt * p.v(j);
            if let Some(i) = idx.v(j) {
                jac[(idx.x(j), i)] += dt;
                value[i] = p.v(j) + dt * self.core.acceleration(&p, j, ground);
                self.add_acceleration_gradient(&p, &mut jac, i, j, dt);
            }
        }
        (value, jac)
    }

    /// SPEC §6: accelerations at (xⁿ_k, m) with ü_g,meas(k).
    fn observation(
        &self,
        k: usize,
        xn: &SVector<f64, NN>,
        m: &SVector<f64, NBL>,
    ) -> (SVector<f64, NY>, SMatrix<f64, NY, NBL>) {
        let idx = self.idx();
        let p = Point { xn, m, idx };
        let ground = self.core.measurement_ground(&self.spec.ug, k);
        let value = SVector::<f64, NY>::from_fn(|i, _| self.core.acceleration(&p, i + 1, ground));
        let mut jac = SMatrix::<f64, NY, NBL>::zeros();
        for j in 1..=self.core.n {
            self.add_acceleration_gradient(&p, &mut jac, j - 1, j, 1.0);
        }
        (value, jac)
    }

    fn sampled_hessians(&self) -> &SparseHessians {
        &self.sampled_hessians
    }

    fn marginal_hessians(&self) -> &SparseHessians {
        &self.marginal_hessians
    }

    fn observation_hessians(&self) -> &SparseHessians {
        &self.observation_hessians
    }

    fn sampled_noise_sd(&self) -> SVector<f64, ND> {
        SVector::<f64, ND>::new(self.spec.q_vel_sd, self.spec.q_r_sd)
    }

    /// Displacements q_disp, ẋ2..ẋN q_vel, parameters 0 (SPEC §3).
    fn marginal_noise_sd(&self) -> SVector<f64, NBL> {
        let n = self.core.n;
        SVector::from_fn(|i, _| match i {
            i if i < n => self.spec.q_disp_sd,
            i if i < 2 * n - 1 => self.spec.q_vel_sd,
            _ => 0.0,
        })
    }

    fn measurement_cov(&self) -> SMatrix<f64, NY, NY> {
        SMatrix::from_diagonal(&SVector::from_column_slice(&self.spec.r_diag))
    }

    fn layout(&self) -> Layout {
        let n = self.core.n;
        let idx = self.idx();
        let mut params: Vec<Slot> = (1..=n).map(|j| Slot::Marginal(idx.k(j))).collect();
        params.extend((1..=n).map(|j| Slot::Marginal(idx.c(j))));
        params.extend([
            Slot::Marginal(idx.beta()),
            Slot::Marginal(idx.gamma()),
            Slot::Sampled(2),
        ]);
        let mut states: Vec<Slot> = (1..=n).map(|j| Slot::Marginal(idx.x(j))).collect();
        states.extend((1..=n).map(|j| idx.v(j).map_or(Slot::Sampled(0), Slot::Marginal)));
        states.push(Slot::Sampled(1));
        Layout {
            param_names: parameter_names(n),
            params,
            state_names: state_names(n),
            states,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::rng::stream;

    fn spec(n: usize) -> FilterSpec {
        FilterSpec::from_rms(
            0.005,
            vec![1.0; n],
            vec![0.5; 5],
            &vec![1.0; n],
            1.0,
            0.5,
            0.1,
        )
        .unwrap()
    }

    #[test]
    fn dimensions_are_checked() {
        assert!(PaperMpf::new(spec(3)).is_ok());
        assert!(MpfChain::<21, 5>::new(spec(5)).is_ok());
        assert!(MpfChain::<5, 1>::new(spec(1)).is_ok());
        assert!(matches!(
            PaperMpf::new(spec(5)),
            Err(PartitionError::DimensionMismatch {
                expected: 21,
                got: 13,
                ..
            })
        ));
    }

    #[test]
    fn layout_matches_spec_section_6_indices() {
        let l = PaperMpf::new(spec(3)).unwrap().layout();
        let expected_params = [5, 6, 7, 8, 9, 10, 11, 12].map(Slot::Marginal);
        assert_eq!(&l.params[..8], &expected_params);
        assert_eq!(l.params[8], Slot::Sampled(2));
        assert_eq!(
            l.states,
            [
                Slot::Marginal(0),
                Slot::Marginal(1),
                Slot::Marginal(2),
                Slot::Sampled(0),
                Slot::Marginal(3),
                Slot::Marginal(4),
                Slot::Sampled(1)
            ]
        );
    }

    #[test]
    fn priors_and_noise_levels() {
        let m = PaperMpf::new(spec(3)).unwrap();
        let mut rng = stream(3, 0, "test");
        let xn = m.sample_initial(&mut rng);
        assert!(xn[0] == 0.0 && xn[1] == 0.0 && (1.0..5.0).contains(&xn[2]));
        let (mu, cov) = m.sample_marginal_prior(&mut rng);
        let (mean, var) = m.spec().prior.moments();
        assert!(mu.rows(0, 5).iter().all(|&v| v == 0.0));
        for i in 0..8 {
            assert_eq!(mu[5 + i], mean[i]);
            assert_eq!(cov[(5 + i, 5 + i)], var[i]);
        }
        assert!((0..5).all(|i| cov[(i, i)] == 0.0));
        let q = m.marginal_noise_sd();
        assert_eq!([q[0], q[1], q[2]], [1e-6; 3]);
        assert!(q[3] > 0.0 && q[3] == q[4] && q[3] == m.sampled_noise_sd()[0]);
        assert!(q.rows(5, 8).iter().all(|&v| v == 0.0));
    }
}
