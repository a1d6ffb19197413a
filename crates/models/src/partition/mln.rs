//! Mixed linear/nonlinear partition for MLN-RBPF and Storvik (SPEC §5.2–5.3).
//!
//! Sampled u = [x1..xN, ẋ1..ẋN, r1, n] (NU = 2N + 2); marginalised z = [k1..kN, c1..cN, β, γ]
//! (NZ = 2N + 2). With everything on the right at k−1:
//!
//! ```text
//! u_k = f(u) + F(u) z + v_u,        y_k = h(u_k) + H(u_k) z + η
//! f(u) = [x_j + dt ẋ_j,  ẋ_j − dt ü_g,  r1 + dt ẋ1,  n]
//! H(u): row j = (−∂F_j/∂z + ∂F_{j+1}/∂z) / m_j      (F_j the element forces, linear in z)
//! F(u): velocity rows = dt·H(u) rows; r1 row = dt·[0…0, −|ẋ1||r1|^(n−1) r1, −ẋ1|r1|^n]
//! ```
//!
//! The linked rows (NL = N + 1) are the N velocity rows and the r1 row; displacement rows and the
//! copied n row do not depend on z.

use super::{check_dim, state_names, ChainCore, ChainPoint, FilterSpec, PartitionError};
use crate::priors::parameter_names;
use core_filters::model::{ConditionallyLinear, Layout, Slot};
use nalgebra::{SMatrix, SVector};
use rand::Rng;

/// The Bouc–Wen chain partitioned for MLN-RBPF / Storvik (SPEC §5.2).
#[derive(Debug, Clone)]
pub struct MlnChain<const NU: usize, const NZ: usize, const NL: usize, const NY: usize> {
    spec: FilterSpec,
    core: ChainCore,
}

/// The paper's 3-storey chain: u (8), z (8), 4 linked rows, 3 channels.
pub type PaperMln = MlnChain<8, 8, 4, 3>;

/// (u, z) seen as a chain point.
struct Point<'a, const NU: usize, const NZ: usize> {
    u: &'a SVector<f64, NU>,
    z: &'a SVector<f64, NZ>,
    n: usize,
}

impl<const NU: usize, const NZ: usize> ChainPoint for Point<'_, NU, NZ> {
    #[inline]
    fn x(&self, j: usize) -> f64 {
        self.u[j - 1]
    }
    #[inline]
    fn v(&self, j: usize) -> f64 {
        self.u[self.n + j - 1]
    }
    #[inline]
    fn r1(&self) -> f64 {
        self.u[2 * self.n]
    }
    #[inline]
    fn k(&self, j: usize) -> f64 {
        self.z[j - 1]
    }
    #[inline]
    fn c(&self, j: usize) -> f64 {
        self.z[self.n + j - 1]
    }
    #[inline]
    fn beta(&self) -> f64 {
        self.z[2 * self.n]
    }
    #[inline]
    fn gamma(&self) -> f64 {
        self.z[2 * self.n + 1]
    }
    #[inline]
    fn n(&self) -> f64 {
        self.u[2 * self.n + 1]
    }
}

impl<const NU: usize, const NZ: usize, const NL: usize, const NY: usize> MlnChain<NU, NZ, NL, NY> {
    /// Checks NU = NZ = 2N + 2, NL = N + 1, NY = N and validates the spec.
    pub fn new(spec: FilterSpec) -> Result<Self, PartitionError> {
        let n = spec.n_storeys();
        check_dim("NU (sampled block)", NU, 2 * n + 2, n)?;
        check_dim("NZ (marginalised block)", NZ, 2 * n + 2, n)?;
        check_dim("NL (linked rows)", NL, n + 1, n)?;
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

    /// H(u) (NY × NZ): the acceleration rows as linear functions of z, without the ground term.
    /// SPEC §5.2; `scale` multiplies every entry (dt for the velocity rows of F).
    #[inline]
    fn write_force_rows<const R: usize>(
        &self,
        u: &SVector<f64, NU>,
        scale: f64,
        out: &mut SMatrix<f64, R, NZ>,
    ) {
        let n = self.core.n;
        // z does not enter the coefficients of F_j; any z works for the point.
        let z = SVector::<f64, NZ>::zeros();
        let p = Point { u, z: &z, n };
        for j in 1..=n {
            let s = scale * self.core.inv_mass[j - 1];
            let (d, dv) = ChainCore::element_coefficients(&p, j);
            out[(j - 1, j - 1)] -= s * d;
            out[(j - 1, n + j - 1)] -= s * dv;
            if j < n {
                let (d, dv) = ChainCore::element_coefficients(&p, j + 1);
                out[(j - 1, j)] += s * d;
                out[(j - 1, n + j)] += s * dv;
            }
        }
    }

    /// Adds `scale · ∂F_j/∂u` (at z) to row `row` of `out`.
    #[inline]
    fn add_force_gradient_u(
        &self,
        out: &mut SMatrix<f64, NY, NU>,
        row: usize,
        j: usize,
        scale: f64,
        z: &SVector<f64, NZ>,
    ) {
        let n = self.core.n;
        let (k, c) = (z[j - 1], z[n + j - 1]);
        if j == 1 {
            // F_1 = k1 r1 + c1 ẋ1.
            out[(row, 2 * n)] += scale * k;
            out[(row, n)] += scale * c;
        } else {
            // F_j = k_j (x_j − x_{j−1}) + c_j (ẋ_j − ẋ_{j−1}).
            out[(row, j - 1)] += scale * k;
            out[(row, j - 2)] -= scale * k;
            out[(row, n + j - 1)] += scale * c;
            out[(row, n + j - 2)] -= scale * c;
        }
    }
}

#[allow(non_snake_case)]
impl<const NU: usize, const NZ: usize, const NL: usize, const NY: usize>
    ConditionallyLinear<NU, NZ, NL, NY> for MlnChain<NU, NZ, NL, NY>
{
    /// Zero states, n drawn from its prior (SPEC §3).
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, NU> {
        let mut u = SVector::<f64, NU>::zeros();
        u[2 * self.core.n + 1] = self.spec.prior.n.sample(rng);
        u
    }

    /// Moment-matched Gaussian of z (SPEC §3), or the per-particle option. z is the prefix of θ.
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        rng: &mut G,
    ) -> (SVector<f64, NZ>, SMatrix<f64, NZ, NZ>) {
        // Start-up only (once per particle), so the θ-sized scratch may allocate.
        let d = self.spec.prior.len();
        let (mut mean, mut var) = (vec![0.0; d], vec![0.0; d]);
        self.core
            .marginal_theta_prior(&self.spec, rng, &mut mean, &mut var);
        let mu = SVector::<f64, NZ>::from_column_slice(&mean[..NZ]);
        let cov = SMatrix::from_diagonal(&SVector::<f64, NZ>::from_column_slice(&var[..NZ]));
        (mu, cov)
    }

    /// The N velocity rows and the r1 row.
    fn linked_rows(&self) -> [usize; NL] {
        let n = self.core.n;
        std::array::from_fn(|i| n + i)
    }

    /// SPEC §5.2: f(u_{k−1}) with ü_g,meas(k−1) and the linked rows of F(u_{k−1}).
    fn transition(
        &self,
        k: usize,
        u: &SVector<f64, NU>,
    ) -> (SVector<f64, NU>, SMatrix<f64, NL, NZ>) {
        let n = self.core.n;
        let dt = self.core.dt;
        let ground = ChainCore::transition_ground(&self.spec.ug, k);
        let z = SVector::<f64, NZ>::zeros();
        let p = Point { u, z: &z, n };
        let mut f = *u;
        for j in 1..=n {
            f[j - 1] = p.x(j) + dt * p.v(j);
            f[n + j - 1] = p.v(j) + dt * ground;
        }
        f[2 * n] = p.r1() + dt * p.v(1);
        // f[2n + 1] = n is copied.
        let mut F = SMatrix::<f64, NL, NZ>::zeros();
        self.write_force_rows(u, dt, &mut F);
        let (db, dg) = ChainCore::r1_rate_shape_gradient(&p);
        F[(n, 2 * n)] = dt * db;
        F[(n, 2 * n + 1)] = dt * dg;
        (f, F)
    }

    fn process_noise_sd(&self) -> SVector<f64, NU> {
        let n = self.core.n;
        SVector::from_fn(|i, _| match i {
            i if i < n => self.spec.q_disp_sd,
            i if i < 2 * n => self.spec.q_vel_sd,
            i if i == 2 * n => self.spec.q_r_sd,
            _ => 0.0,
        })
    }

    /// SPEC §5.2: h(u_k) = ground term with ü_g,meas(k), H(u_k).
    fn observation(
        &self,
        k: usize,
        u: &SVector<f64, NU>,
    ) -> (SVector<f64, NY>, SMatrix<f64, NY, NZ>) {
        let h = SVector::repeat(self.core.measurement_ground(&self.spec.ug, k));
        let mut H = SMatrix::<f64, NY, NZ>::zeros();
        self.write_force_rows(u, 1.0, &mut H);
        (h, H)
    }

    /// SPEC §5.3 (iii): ∂/∂u [H(u) z + h(u)]; h does not depend on u and the n column is zero.
    fn observation_jacobian_u(
        &self,
        _k: usize,
        _u: &SVector<f64, NU>,
        z: &SVector<f64, NZ>,
    ) -> SMatrix<f64, NY, NU> {
        let n = self.core.n;
        let mut J = SMatrix::<f64, NY, NU>::zeros();
        for j in 1..=n {
            let s = self.core.inv_mass[j - 1];
            self.add_force_gradient_u(&mut J, j - 1, j, -s, z);
            if j < n {
                self.add_force_gradient_u(&mut J, j - 1, j + 1, s, z);
            }
        }
        J
    }

    fn measurement_cov(&self) -> SMatrix<f64, NY, NY> {
        SMatrix::from_diagonal(&SVector::from_column_slice(&self.spec.r_diag))
    }

    fn layout(&self) -> Layout {
        let n = self.core.n;
        let mut params: Vec<Slot> = (0..2 * n + 2).map(Slot::Marginal).collect();
        params.push(Slot::Sampled(2 * n + 1));
        Layout {
            param_names: parameter_names(n),
            params,
            state_names: state_names(n),
            states: (0..2 * n + 1).map(Slot::Sampled).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::partition::MarginalPrior;
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
        assert!(PaperMln::new(spec(3)).is_ok());
        assert!(MlnChain::<12, 12, 6, 5>::new(spec(5)).is_ok());
        assert!(matches!(
            MlnChain::<12, 12, 5, 5>::new(spec(5)),
            Err(PartitionError::DimensionMismatch {
                what: "NL (linked rows)",
                ..
            })
        ));
        assert!(PaperMln::new(spec(4)).is_err());
    }

    #[test]
    fn layout_and_linked_rows_for_the_paper_chain() {
        let m = PaperMln::new(spec(3)).unwrap();
        assert_eq!(m.linked_rows(), [3, 4, 5, 6]);
        let l = m.layout();
        assert_eq!(l.params[0], Slot::Marginal(0));
        assert_eq!(l.params[7], Slot::Marginal(7));
        assert_eq!(l.params[8], Slot::Sampled(7));
        assert_eq!(l.param_names[8], "n");
        assert_eq!(l.states[3], Slot::Sampled(3));
    }

    #[test]
    fn marginal_prior_is_moment_matched_or_per_particle() {
        let m = PaperMln::new(spec(3)).unwrap();
        let mut rng = stream(2, 0, "test");
        let (mu, cov) = m.sample_marginal_prior(&mut rng);
        let (mean, var) = m.spec().prior.moments();
        for i in 0..8 {
            assert_eq!(mu[i], mean[i]);
            assert_eq!(cov[(i, i)], var[i]);
        }
        assert_eq!(cov.sum() - cov.trace(), 0.0);
        let u0 = m.sample_initial(&mut rng);
        assert!(u0.rows(0, 7).iter().all(|&v| v == 0.0) && (1.0..5.0).contains(&u0[7]));

        let mut s = spec(3);
        s.marginal_prior = MarginalPrior::PerParticle { rel_sd: 0.1 };
        s.prior.fix("k2", 8.0).unwrap();
        let m = PaperMln::new(s).unwrap();
        let (a, ca) = m.sample_marginal_prior(&mut rng);
        let (b, _) = m.sample_marginal_prior(&mut rng);
        assert_ne!(a[0], b[0], "per-particle means differ between draws");
        assert_eq!(
            (a[1], ca[(1, 1)]),
            (8.0, 0.0),
            "a fixed parameter keeps variance 0"
        );
        assert!((ca[(0, 0)] - (0.1 * a[0]).powi(2)).abs() < 1e-15);
    }
}
