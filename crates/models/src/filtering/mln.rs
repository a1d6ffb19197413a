//! Mixed linear/nonlinear partition of the general chain for MLN-RBPF and Storvik
//! (SPEC §5.2–5.3 generalised, §9; derivation in `docs/partitions.md`).
//!
//! Sampled `u = [x1..xN, v1..vN, r_e…, n_e…]` (2N + 2E); marginalised
//! `z = [k1..kN, c1..cN, (β_e, γ_e)…]` (2N + 2E) — for Bouc–Wen; for any law
//! ([`HysteresisLaw`]) u holds each element's nonlinear parameters where n is, and z its linear
//! ones where (β, γ) are. Given `u`, every acceleration is linear in `z`
//! (`F_j = k_j d_j + c_j δv_j`) and every hysteretic rate is affine in `(β_e, γ_e)`
//! (`ṙ = g₀ + β g₁ + γ g₂`), so:
//!
//! - Euler, one stage (rows x, v, r; linked: v and r rows):
//!   `x' = x + dt v`, `v' = v − dt ü_g + dt·H_v(u) z`, `r' = r + dt g₀ + dt [g₁ g₂] (β, γ)`;
//! - symplectic, stage 0 = v rows (all linked, as Euler); stage 1 = x rows (unlinked,
//!   `x + dt v_new`) and r rows (linked, `r + dt(g₀ + β g₁ + γ g₂)` at `δv_new`), which is again
//!   affine in `(β, γ)` because the new velocities are sampled before it.
//!
//! The n rows are set by no stage (copied).
//!
//! The storey+mass damping form is refused ([`SpecError::DampingUnsupported`]): α would be one
//! more column of z whose `−α v_j` enters the v rows and the observation's u-Jacobian, which this
//! partition does not carry; the MPF-EKF2 and the bootstrap PF have it.

use super::{nlin, zero_basis, Basis, ChainCore, ChainSpecOf, ForceColumns, SpecError};
use crate::building::Building;
use crate::law::{BoucWenLaw, HysteresisLaw};
use crate::structure::ChainView;
use core_filters::linalg::Sparse;
use core_filters::model::{Layout, Slot};
use core_filters::real::Real;
use core_filters::rng::StreamRng;
use core_filters::smc::model::{ConditionallyLinear, LinearDims, Marginalised, Partition, Stage};
use core_filters::smc::rejuvenation::StaticParam;

/// The chain partitioned for MLN-RBPF / Storvik, its elements following the law `L`.
#[derive(Debug, Clone)]
pub struct MlnChainOf<L: HysteresisLaw> {
    core: ChainCore<L>,
    stages: Vec<Stage>,
    noise_sd: Vec<f64>,
    symplectic: bool,
}

/// The Bouc–Wen chain partitioned for MLN-RBPF / Storvik.
pub type MlnChain = MlnChainOf<BoucWenLaw>;

/// `u` (and optionally `z`) as a chain point.
struct View<'a, T> {
    u: &'a [T],
    z: &'a [T],
    n: usize,
}

impl<T: Real> ChainView<T> for View<'_, T> {
    #[inline(always)]
    fn x(&self, j: usize) -> T {
        self.u[j]
    }
    #[inline(always)]
    fn v(&self, j: usize) -> T {
        self.u[self.n + j]
    }
    #[inline(always)]
    fn r(&self, e: usize) -> T {
        self.u[2 * self.n + e]
    }
    #[inline(always)]
    fn k(&self, j: usize) -> T {
        self.z[j]
    }
    #[inline(always)]
    fn c(&self, j: usize) -> T {
        self.z[self.n + j]
    }
}

/// z = `[k, c, …]` as the variables of a force gradient (the rows of `F` and `H`).
struct ThetaColumns {
    n: usize,
}

impl ForceColumns for ThetaColumns {
    #[inline(always)]
    fn theta(&self) -> Option<(usize, usize)> {
        Some((0, self.n))
    }
}

/// u = `[x, v, r, …]` as the variables of a force gradient (Storvik's `J_u`).
struct StateColumns {
    n: usize,
}

impl ForceColumns for StateColumns {
    #[inline(always)]
    fn displacements(&self) -> bool {
        true
    }
    #[inline(always)]
    fn hysteretic(&self) -> Option<usize> {
        Some(2 * self.n)
    }
    #[inline(always)]
    fn velocity(&self, j: usize) -> Option<usize> {
        Some(self.n + j)
    }
}

impl<L: HysteresisLaw> MlnChainOf<L> {
    /// Validates the spec; Euler and symplectic only (RK4 is not linear in z given `u`).
    pub fn new(spec: ChainSpecOf<L>) -> Result<Self, SpecError> {
        let core = ChainCore::new(spec)?;
        core.no_gaussian_extras("MLN-RBPF/Storvik")?;
        if core.substeps != 1 {
            return Err(SpecError::SubstepsUnsupported {
                partition: "MLN-RBPF/Storvik",
            });
        }
        if core.mass_damping() {
            return Err(SpecError::DampingUnsupported {
                partition: "MLN-RBPF/Storvik",
                damping: core.spec.building.damping(),
                reason: "α is not a column of its conditionally linear block",
            });
        }
        let (n, ne) = (core.n, core.ne);
        let symplectic = core.symplectic("MLN-RBPF/Storvik")?;
        let x_rows = 0..n;
        let v_rows = n..2 * n;
        let r_rows = 2 * n..2 * n + ne;
        let stages = if symplectic {
            vec![
                Stage {
                    rows: v_rows.clone().collect(),
                    linked: v_rows.collect(),
                },
                Stage {
                    rows: x_rows.chain(r_rows.clone()).collect(),
                    linked: r_rows.collect(),
                },
            ]
        } else {
            vec![Stage {
                rows: (0..2 * n + ne).collect(),
                linked: v_rows.chain(r_rows).collect(),
            }]
        };
        let mut noise_sd = vec![core.q_disp; n];
        noise_sd.extend(std::iter::repeat_n(core.q_vel, n));
        noise_sd.extend_from_slice(&core.q_r);
        noise_sd.extend(std::iter::repeat_n(0.0, L::NNONLIN * ne));
        Ok(Self {
            core,
            stages,
            noise_sd,
            symplectic,
        })
    }

    pub fn spec(&self) -> &ChainSpecOf<L> {
        &self.core.spec
    }

    /// Column of β_e (the element's first linear parameter) in z.
    #[inline]
    fn beta_col(&self, e: usize) -> usize {
        2 * self.core.n + L::NLIN * e
    }

    /// Index of n_e (the element's first nonlinear parameter) in u.
    #[inline]
    fn n_index(&self, e: usize) -> usize {
        2 * self.core.n + self.core.ne + L::NNONLIN * e
    }

    /// The nonlinear parameters φ of element `e` in `u`.
    #[inline(always)]
    fn phi<'a, T: Real>(&self, e: usize, u: &'a [T]) -> &'a [T] {
        let i = self.n_index(e);
        &u[i..i + L::NNONLIN]
    }

    /// Writes `scale · ∂a_j/∂z` at `u` into row `row` (`∂F_j/∂k_j = d_j`, `∂F_j/∂c_j = δv_j`).
    #[inline(always)]
    fn write_acceleration_row<T: Real>(
        &self,
        out: &mut Sparse<T>,
        row: usize,
        j: usize,
        u: &[T],
        scale: T,
    ) {
        let view = View {
            u,
            z: &[],
            n: self.core.n,
        };
        let vars = ThetaColumns { n: self.core.n };
        self.core
            .write_acceleration_gradient(out, row, j, &view, &vars, scale);
    }

    /// Drift velocity of the element at storey `j` from the velocities in `u`.
    #[inline]
    fn drift_velocity<T: Real>(&self, u: &[T], j: usize) -> T {
        Building::drift_velocity(
            &View {
                u,
                z: &[],
                n: self.core.n,
            },
            j,
        )
    }

    /// `[g₀, g₁, g₂]` (Bouc–Wen; `1 + NLIN` entries) of element `e` at drift velocity `dv`,
    /// `r_e` and `n_e` from `u_prev`.
    #[inline]
    fn basis<T: Real>(&self, e: usize, dv: T, u_prev: &[T]) -> Basis<T> {
        let mut g = zero_basis();
        let r = u_prev[2 * self.core.n + e];
        let phi = self.phi(e, u_prev);
        self.core.law.basis(dv, r, phi, &mut g[..1 + nlin::<L>()]);
        g
    }
}

impl<L: HysteresisLaw> Partition for MlnChainOf<L> {
    /// Zero states, each n_e drawn from its prior (SPEC §3).
    fn sample_initial(&self, rng: &mut StreamRng, u: &mut [f64]) {
        self.core.sample_initial(rng, u, |e| self.n_index(e));
    }

    fn measurement_cov(&self) -> Vec<f64> {
        self.core.measurement_cov()
    }

    /// k, c, β, γ marginal (z order), n_e sampled; states sampled.
    /// Each element's n, with the support of its prior.
    fn static_params(&self) -> Vec<StaticParam> {
        self.core.static_params(|e| self.n_index(e))
    }

    fn layout(&self) -> Layout {
        let (n, ne) = (self.core.n, self.core.ne);
        let mut params: Vec<Slot> = (0..2 * n).map(Slot::Marginal).collect();
        self.core
            .push_element_slots(&mut params, |e| self.beta_col(e), |e| self.n_index(e));
        self.core
            .layout(params, (0..2 * n + ne).map(Slot::Sampled).collect())
    }
}

/// Writes `dt · ∂ṙ/∂θ = dt [g₁ …]` (the law's `nlin` linear parameters, from column `b`) into
/// row `row`.
#[inline(always)]
fn write_rate_row<T: Real>(
    out: &mut Sparse<T>,
    row: usize,
    b: usize,
    dt: T,
    g: &Basis<T>,
    nlin: usize,
) {
    for i in 0..nlin {
        out.add(row, b + i, dt * g[1 + i]);
    }
}

#[allow(non_snake_case)]
impl<L: HysteresisLaw> ConditionallyLinear for MlnChainOf<L> {
    fn dims(&self) -> LinearDims {
        let (n, ne) = (self.core.n, self.core.ne);
        LinearDims {
            nu: 2 * n + ne + L::NNONLIN * ne,
            nz: 2 * n + L::NLIN * ne,
            ny: self.core.sensors.len(),
        }
    }

    fn stages(&self) -> &[Stage] {
        &self.stages
    }

    fn process_noise_sd(&self) -> &[f64] {
        &self.noise_sd
    }

    /// SPEC §5.2: stage `stage` of the transition to k (module docs).
    fn transition<T: Real>(
        &self,
        stage: usize,
        k: usize,
        u_prev: &[T],
        u_new: &[T],
        f: &mut [T],
        F: &mut Sparse<T>,
    ) {
        let n = self.core.n;
        let dt = T::splat(self.core.dt);
        let ground = T::splat(self.core.transition_ground(k));
        let hyst = self.core.spec.building.hysteretic();
        match (self.symplectic, stage) {
            (false, 0) => {
                for j in 0..n {
                    f[j] = u_prev[j] + dt * u_prev[n + j];
                    f[n + j] = u_prev[n + j] + dt * ground;
                    self.write_acceleration_row(F, j, j, u_prev, dt);
                }
                for (e, &j) in hyst.iter().enumerate() {
                    let g = self.basis(e, self.drift_velocity(u_prev, j), u_prev);
                    f[2 * n + e] = u_prev[2 * n + e] + dt * g[0];
                    let b = self.beta_col(e);
                    write_rate_row(F, n + e, b, dt, &g, L::NLIN);
                }
            }
            (true, 0) => {
                for j in 0..n {
                    f[j] = u_prev[n + j] + dt * ground;
                    self.write_acceleration_row(F, j, j, u_prev, dt);
                }
            }
            (true, 1) => {
                for j in 0..n {
                    f[j] = u_prev[j] + dt * u_new[n + j];
                }
                for (e, &j) in hyst.iter().enumerate() {
                    let g = self.basis(e, self.drift_velocity(u_new, j), u_prev);
                    f[n + e] = u_prev[2 * n + e] + dt * g[0];
                    let b = self.beta_col(e);
                    write_rate_row(F, e, b, dt, &g, L::NLIN);
                }
            }
            _ => panic!("no stage {stage}"),
        }
    }

    /// `h(u_k)` = the ground term with ü_g,meas(k); `H(u_k)` = `∂a_s/∂z` per sensor storey s.
    fn observation<T: Real>(&self, k: usize, u: &[T], h: &mut [T], H: &mut Sparse<T>) {
        let ground = T::splat(self.core.measurement_ground(k));
        for (i, &s) in self.core.sensors.iter().enumerate() {
            h[i] = ground;
            self.write_acceleration_row(H, i, s, u, T::splat(1.0));
        }
    }

    /// `∂/∂u [H(u) z + h]`: row i = `∂a_s/∂u` at z; the n columns are zero.
    fn observation_jacobian_u<T: Real>(&self, _k: usize, _u: &[T], z: &[T], J: &mut Sparse<T>) {
        let n = self.core.n;
        let view = View { u: &[], z, n };
        let vars = StateColumns { n };
        for (i, &s) in self.core.sensors.iter().enumerate() {
            self.core
                .write_acceleration_gradient(J, i, s, &view, &vars, T::splat(1.0));
        }
    }

    /// `∂u_k/∂z` along the sampled path at z. Euler: the linked rows of F. Symplectic: v rows
    /// `F_v`; x rows `dt·F_v`; r rows `F_r + dt·∂ṙ/∂δv·(F_v[j] − F_v[j−1])`.
    // Always inlined into Storvik's step: left to the optimiser, it stopped being inlined
    // after unrelated edits elsewhere and Storvik ran 5.9 % (s.e. 0.9 %) slower
    // (docs/performance.md, "Speed across builds").
    #[inline(always)]
    fn transition_sensitivity<T: Real>(
        &self,
        _k: usize,
        u_prev: &[T],
        u_new: &[T],
        z: &[T],
        S: &mut Sparse<T>,
    ) {
        let n = self.core.n;
        let dt = T::splat(self.core.dt);
        let hyst = self.core.spec.building.hysteretic();
        if self.symplectic {
            for j in 0..n {
                self.write_acceleration_row(S, n + j, j, u_prev, dt);
                self.write_acceleration_row(S, j, j, u_prev, dt * dt);
            }
            for (e, &j) in hyst.iter().enumerate() {
                let dv = self.drift_velocity(u_new, j);
                let b = self.beta_col(e);
                let row = 2 * n + e;
                // The basis and ∂ṙ/∂δv at one point: the law computes their common terms once.
                let mut g = zero_basis();
                let (d_dv, _) = self.core.law.basis_and_partials(
                    dv,
                    u_prev[row],
                    &z[b..b + L::NLIN],
                    self.phi(e, u_prev),
                    &mut g[..1 + nlin::<L>()],
                );
                write_rate_row(S, row, b, dt, &g, L::NLIN);
                let coef = dt * d_dv;
                self.write_acceleration_row(S, row, j, u_prev, coef * dt);
                if j > 0 {
                    self.write_acceleration_row(S, row, j - 1, u_prev, -(coef * dt));
                }
            }
        } else {
            for j in 0..n {
                self.write_acceleration_row(S, n + j, j, u_prev, dt);
            }
            for (e, &j) in hyst.iter().enumerate() {
                let g = self.basis(e, self.drift_velocity(u_prev, j), u_prev);
                let b = self.beta_col(e);
                write_rate_row(S, 2 * n + e, b, dt, &g, L::NLIN);
            }
        }
    }
}

impl<L: HysteresisLaw> Marginalised for MlnChainOf<L> {
    fn lower_bounds(&self) -> Vec<core_filters::linalg::LowerBound> {
        self.core.lower_bounds(&self.layout().params)
    }

    /// θ's prior without the n's (z is θ with every nonlinear parameter removed), diagonal.
    fn marginal_prior(&self, rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        let (n, ne) = (self.core.n, self.core.ne);
        let (m, v) = self.core.theta_prior(rng);
        let nz = 2 * n + L::NLIN * ne;
        cov.fill(0.0);
        let mut i = 0;
        for t in 0..m.len() {
            // Per element θ holds its linear parameters, then its nonlinear ones (n).
            let is_n = t >= 2 * n && (t - 2 * n) % L::NPARAMS >= L::NLIN;
            if !is_n {
                mean[i] = m[t];
                cov[i + i * nz] = v[t];
                i += 1;
            }
        }
        debug_assert_eq!(i, nz);
    }
}
